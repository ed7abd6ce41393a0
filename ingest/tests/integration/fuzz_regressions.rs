//! Inputs found by fuzzing (tests/fuzz, `scripts/fuzz.sh`; see docs/fuzzing.md), minimised and
//! kept as regressions, end to end through `TiffSource`. Findings fixed inside a parser also
//! have a unit test beside it (`source::raw`, `source::tiff_claims`, `source::tiff_metadata`).
//!
//! Two TIFF files below made `tiff` 0.10.3 panic, so `ingest convert` died with a panic
//! instead of naming the corrupt file. Both bugs are fixed in `tiff` 0.11
//! (image-rs/image-tiff#305 and #306), which the workspace now uses; these tests keep them
//! fixed.

use std::path::Path;

use residency_ingest::source::{PlaneOut, TiffSource, VolumeSource};

/// A classic little-endian TIFF: `data` at offset 8, then one directory of `entries`
/// (`tag, type, count, value bytes`, in tag order), values over 4 bytes after it.
fn tiff(entries: &[(u16, u16, u32, Vec<u8>)], data: &[u8]) -> Vec<u8> {
    let mut body = data.to_vec();
    if body.len() % 2 == 1 {
        body.push(0);
    }
    let ifd = 8 + body.len() as u32;
    let mut extra_at = ifd + 2 + 12 * entries.len() as u32 + 4;
    let mut out = b"II*\0".to_vec();
    out.extend(ifd.to_le_bytes());
    out.extend(&body);
    out.extend((entries.len() as u16).to_le_bytes());
    let mut extra: Vec<u8> = Vec::new();
    for (tag, ty, count, value) in entries {
        out.extend(tag.to_le_bytes());
        out.extend(ty.to_le_bytes());
        out.extend(count.to_le_bytes());
        if value.len() <= 4 {
            let mut v = value.clone();
            v.resize(4, 0);
            out.extend(v);
        } else {
            out.extend(extra_at.to_le_bytes());
            extra_at += value.len() as u32;
            extra.extend(value);
        }
    }
    out.extend(0u32.to_le_bytes());
    out.extend(extra);
    out
}

const SHORT: u16 = 3;
const LONG: u16 = 4;

fn short(tag: u16, v: u16) -> (u16, u16, u32, Vec<u8>) {
    (tag, SHORT, 1, v.to_le_bytes().to_vec())
}

fn long(tag: u16, v: u32) -> (u16, u16, u32, Vec<u8>) {
    (tag, LONG, 1, v.to_le_bytes().to_vec())
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

/// Target tiff_file: a 1×1 page whose SampleFormat tag has no values.
#[test]
fn an_empty_sample_format_tag_is_an_error() {
    let file = tiff(
        &[
            short(256, 1),
            short(257, 1),
            short(258, 8),
            short(259, 1),
            short(262, 1),
            long(273, 8),
            short(277, 1),
            short(278, 1),
            long(279, 1),
            (339, SHORT, 0, Vec::new()),
        ],
        &[7],
    );
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "empty_sample_format.tif", &file);
    let error = TiffSource::open(&path).err().expect("refused").to_string();
    assert_eq!(
        error,
        format!("{}: not a readable TIFF file", path.display())
    );
}

/// Target tiff_structured: a 1×16 page in one LZW-compressed 16×16 tile of 256 zero bytes,
/// which decode to fewer bytes than the tile without an end code.
#[test]
fn an_lzw_tile_without_an_end_code_is_an_error() {
    let file = tiff(
        &[
            short(256, 1),
            short(257, 16),
            short(258, 8),
            short(259, 5),
            short(262, 1),
            short(277, 1),
            short(322, 16),
            short(323, 16),
            long(324, 8),
            long(325, 256),
        ],
        &[0; 256],
    );
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "lzw_no_end.tif", &file);
    let mut source = TiffSource::open(&path).expect("the claims are plausible");
    let mut plane = [0u8; 16];
    let error = source
        .read_plane(0, 0, PlaneOut::U8(&mut plane))
        .unwrap_err()
        .to_string();
    assert_eq!(
        error,
        format!(
            "{}: cannot decode page 0 (truncated or corrupt TIFF)",
            path.display()
        )
    );
}

/// Target tiff_file: 5 rows of 671088641 uint16 pixels (6.7 GB) under compression 43779,
/// which the decoder does not have, in a file of a few hundred bytes. Fixed in
/// `tiff_claims.rs`; before, the file opened and the converter allocated the plane.
#[test]
fn an_unknown_codec_is_refused_when_opened() {
    let file = tiff(
        &[
            long(256, 671_088_641),
            short(257, 5),
            short(258, 16),
            short(259, 43779),
            short(262, 1),
            long(273, 8),
            short(277, 1),
            long(278, 5),
            long(279, 82),
        ],
        &[0; 82],
    );
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "unknown_codec.tif", &file);
    let error = TiffSource::open(&path).err().expect("refused");
    assert_eq!(
        format!("{error:#}"),
        format!(
            "{0}: page 0: unsupported compression 43779 (supported: none, LZW, Deflate, \
             PackBits, JPEG)",
            path.display()
        )
    );
}

/// Target tiff_structured: an ImageJ description whose `channels × frames` passes 2^64. The
/// product overflowed in `parse_imagej` (and, wrapped to 0 as here, divided by zero even in
/// release builds); fixed there, the file is refused for its time points.
#[test]
fn imagej_sizes_beyond_u64_are_refused() {
    let mut description = b"ImageJ=1.54f\nchannels=4294967296\nframes=4294967296\n\0".to_vec();
    let count = description.len() as u32;
    let pixel_at = 8;
    let entries = [
        short(256, 1),
        short(257, 1),
        short(258, 8),
        short(259, 1),
        short(262, 1),
        (270, 2, count, std::mem::take(&mut description)),
        long(273, pixel_at),
        short(277, 1),
        short(278, 1),
        long(279, 1),
    ];
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "imagej_overflow.tif", &tiff(&entries, &[7]));
    let error = TiffSource::open(&path).err().expect("refused").to_string();
    assert_eq!(
        error,
        format!(
            "{}: has 4294967296 time points; ingest converts one time point per store (split \
             the series first)",
            path.display()
        )
    );
}

/// Target tiff_structured: ImageJ `slices=0` with 18374766782951156837 channels. No page was
/// needed, so the file opened, and `channels × samples per pixel` overflowed in
/// `TiffSource::open`; a volume without z planes is now refused.
#[test]
fn imagej_zero_slices_are_refused() {
    let mut description =
        b"ImageJ=1.54f\nimages=60\nchannels=18374766782951156837\nslices=0\n\0".to_vec();
    let count = description.len() as u32;
    let entries = [
        short(256, 1),
        short(257, 1),
        short(258, 8),
        short(259, 1),
        short(262, 2),
        (270, 2, count, std::mem::take(&mut description)),
        long(273, 8),
        short(277, 3),
        short(278, 1),
        long(279, 3),
    ];
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "imagej_zero_slices.tif",
        &tiff(&entries, &[1, 2, 3]),
    );
    let error = TiffSource::open(&path).err().expect("refused").to_string();
    assert_eq!(
        error,
        format!(
            "{}: metadata describes 0 z planes (corrupt metadata)",
            path.display()
        )
    );
}
