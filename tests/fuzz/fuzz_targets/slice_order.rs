//! Slice folders (`ingest/src/source/slices.rs`): natural sorting of slice file names. Up to
//! 12 files with fuzzed names (any bytes but `/` and NUL) go in a folder, each a 1×1 TIFF
//! whose pixel is its index; `SliceFolderSource::from_dir` sorts them and every plane is read
//! back, so the order the source uses is observed, not assumed. It must be a permutation of the
//! TIFF files, and consistent: no later slice may sort before an earlier one.
#![no_main]

use std::cmp::Ordering;
use std::ffi::OsStr;
use std::os::unix::ffi::OsStrExt;

use libfuzzer_sys::fuzz_target;
use residency_fuzz::scratch;
use residency_fuzz::tiffgen::{Tiff, tag};
use residency_ingest::source::{PlaneOut, SliceFolderSource, VolumeSource};

fn slice_tiff(value: u8) -> Vec<u8> {
    let mut t = Tiff::new(false, false);
    let at = t.blob(&[value]);
    let e = vec![
        t.longs(tag::IMAGE_WIDTH, &[1]),
        t.longs(tag::IMAGE_LENGTH, &[1]),
        t.shorts(tag::BITS_PER_SAMPLE, &[8]),
        t.shorts(tag::COMPRESSION, &[1]),
        t.shorts(tag::PHOTOMETRIC, &[1]),
        t.offsets(tag::STRIP_OFFSETS, &[at]),
        t.shorts(tag::SAMPLES_PER_PIXEL, &[1]),
        t.longs(tag::ROWS_PER_STRIP, &[1]),
        t.offsets(tag::STRIP_BYTE_COUNTS, &[1]),
    ];
    t.ifd(e);
    t.finish()
}

fuzz_target!(|names: Vec<Vec<u8>>| {
    let dir = scratch::empty_dir("slices");
    let mut written: Vec<Vec<u8>> = Vec::new();
    for raw in names.iter().take(12) {
        let mut name: Vec<u8> = raw
            .iter()
            .take(120)
            .map(|&b| if b == b'/' || b == 0 { b'_' } else { b })
            .collect();
        // Most names get a TIFF extension, in the spellings the source accepts.
        match raw.first().copied().unwrap_or(0) % 5 {
            0 => name.extend_from_slice(b".tif"),
            1 => name.extend_from_slice(b".TIFF"),
            2 => name.extend_from_slice(b".tiff"),
            3 => name.extend_from_slice(b".Tif"),
            _ => {}
        }
        if name.is_empty() || name == b"." || name == b".." || written.contains(&name) {
            continue;
        }
        let index = written.len() as u8;
        if std::fs::write(dir.join(OsStr::from_bytes(&name)), slice_tiff(index)).is_err() {
            continue;
        }
        written.push(name);
    }
    let Ok(mut source) = SliceFolderSource::from_dir(&dir) else {
        return;
    };
    let depth = source.info().shape[0];
    let mut order = Vec::new();
    for z in 0..depth {
        let mut px = [0u8];
        source
            .read_plane(0, z, PlaneOut::U8(&mut px))
            .expect("every slice is a readable 1x1 TIFF");
        order.push(px[0] as usize);
    }
    let mut seen = order.clone();
    seen.sort_unstable();
    seen.dedup();
    assert_eq!(seen.len(), order.len(), "a slice was read twice: {order:?}");
    let shown: Vec<String> = order
        .iter()
        .map(|&i| {
            OsStr::from_bytes(&written[i])
                .to_string_lossy()
                .into_owned()
        })
        .collect();
    for i in 0..shown.len() {
        for j in i + 1..shown.len() {
            assert_ne!(
                natord::compare(&shown[i], &shown[j]),
                Ordering::Greater,
                "slice {i} {:?} sorts after slice {j} {:?}",
                shown[i],
                shown[j]
            );
        }
    }
});
