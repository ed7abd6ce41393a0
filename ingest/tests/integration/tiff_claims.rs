//! TIFF files whose headers claim more than the file holds (enormous planes, strips past the
//! end, value lists of billions of entries): `ingest convert` must refuse them with an error
//! naming the file and the claim, exit 1, and leave no store behind, instead of aborting on
//! an allocation. The files are built by hand, classic and BigTIFF, so every claim is exact.

use std::path::Path;

use crate::common::{arg, ingest, ingest_ok};

const SHORT: u16 = 3;
const LONG: u16 = 4;
const LONG8: u16 = 16;

/// One directory entry: tag, type and values.
struct Entry {
    tag: u16,
    kind: u16,
    /// Values, or a claimed count with no values (a lying entry).
    values: Vec<u64>,
    claimed_count: Option<u64>,
}

fn entry(tag: u16, kind: u16, values: &[u64]) -> Entry {
    Entry {
        tag,
        kind,
        values: values.to_vec(),
        claimed_count: None,
    }
}

/// One page: 16-bit grey strips, described by what the header claims.
#[derive(Clone)]
struct Page {
    width: u64,
    height: u64,
    rows_per_strip: u64,
    compression: u64,
    /// `(offset from the start of the pixel data, byte count)` of each strip.
    strips: Vec<(u64, u64)>,
    /// Claim this many StripByteCounts values while storing only the real ones.
    claimed_strip_count: Option<u64>,
}

/// A valid page of `width × height` uint16 pixels in one uncompressed strip at `offset`.
fn page(width: u64, height: u64, offset: u64) -> Page {
    Page {
        width,
        height,
        rows_per_strip: height,
        compression: 1,
        strips: vec![(offset, width * height * 2)],
        claimed_strip_count: None,
    }
}

/// Builds a little-endian TIFF (BigTIFF when `big`): header, then `data` (the pixel data every
/// page's strips point into), then one directory per page, each followed by its out-of-line
/// values.
fn build(big: bool, pages: &[Page], data: &[u8]) -> Vec<u8> {
    let header = if big { 16 } else { 8 };
    let mut out = Vec::new();
    out.extend(b"II");
    if big {
        out.extend(43u16.to_le_bytes());
        out.extend(8u16.to_le_bytes());
        out.extend(0u16.to_le_bytes());
        out.extend(0u64.to_le_bytes()); // first IFD, patched below
    } else {
        out.extend(42u16.to_le_bytes());
        out.extend(0u32.to_le_bytes());
    }
    out.extend(data);
    let offset_kind = if big { LONG8 } else { LONG };
    let mut previous_link = if big { 8 } else { 4 };
    for p in pages {
        if out.len() % 2 == 1 {
            out.push(0);
        }
        let ifd = out.len() as u64;
        if big {
            out[previous_link..previous_link + 8].copy_from_slice(&ifd.to_le_bytes());
        } else {
            out[previous_link..previous_link + 4].copy_from_slice(&(ifd as u32).to_le_bytes());
        }
        let offsets: Vec<u64> = p.strips.iter().map(|s| s.0 + header).collect();
        let counts: Vec<u64> = p.strips.iter().map(|s| s.1).collect();
        let mut counts_entry = entry(279, offset_kind, &counts);
        counts_entry.claimed_count = p.claimed_strip_count;
        let entries = [
            entry(256, LONG, &[p.width]),
            entry(257, LONG, &[p.height]),
            entry(258, SHORT, &[16]),
            entry(259, SHORT, &[p.compression]),
            entry(262, SHORT, &[1]),
            entry(273, offset_kind, &offsets),
            entry(277, SHORT, &[1]),
            entry(278, LONG, &[p.rows_per_strip]),
            counts_entry,
            entry(339, SHORT, &[1]),
        ];
        let (entry_len, inline) = if big { (20, 8) } else { (12, 4) };
        let count_len = if big { 8 } else { 2 };
        let link_len = if big { 8 } else { 4 };
        let mut extra_at = ifd + count_len + entries.len() as u64 * entry_len + link_len;
        let mut extra = Vec::new();
        if big {
            out.extend((entries.len() as u64).to_le_bytes());
        } else {
            out.extend((entries.len() as u16).to_le_bytes());
        }
        for e in &entries {
            let size = match e.kind {
                SHORT => 2,
                LONG => 4,
                _ => 8,
            };
            let mut bytes = Vec::new();
            for &v in &e.values {
                bytes.extend(&v.to_le_bytes()[..size]);
            }
            let count = e.claimed_count.unwrap_or(e.values.len() as u64);
            out.extend(e.tag.to_le_bytes());
            out.extend(e.kind.to_le_bytes());
            if big {
                out.extend(count.to_le_bytes());
            } else {
                out.extend((count as u32).to_le_bytes());
            }
            if bytes.len() <= inline && e.claimed_count.is_none() {
                bytes.resize(inline, 0);
                out.extend(&bytes);
            } else {
                out.extend(&extra_at.to_le_bytes()[..inline]);
                extra_at += bytes.len() as u64;
                extra.extend(bytes);
            }
        }
        previous_link = out.len();
        out.extend(vec![0; link_len as usize]);
        out.extend(extra);
    }
    out
}

/// Pixel data: `n` uint16 values 0, 1, 2, ...
fn ramp(n: u64) -> Vec<u8> {
    (0..n as u16).flat_map(u16::to_le_bytes).collect()
}

/// Converts `file`, expects exit code 1 and exactly `message` on stderr, and checks that
/// neither the store nor its partial folder exists afterwards.
fn refused(dir: &Path, file: &Path, message: &str) {
    let store = dir.join("out.ome.zarr");
    let out = ingest(&["convert", arg(file), "-o", arg(&store), "--quiet"]);
    assert_eq!(
        String::from_utf8_lossy(&out.stderr),
        format!("error: {}: {message}\n", file.display())
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(!store.exists(), "a failed run left {}", store.display());
    assert!(
        !dir.join(".out.ome.zarr.partial").exists(),
        "a failed run left its partial store"
    );
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

#[test]
fn hand_built_tiffs_convert_when_their_claims_hold() {
    // The control: the same builder, honest claims, converts and reads back exactly.
    let dir = tempfile::tempdir().unwrap();
    for big in [false, true] {
        let pages = [page(4, 3, 0), page(4, 3, 24), page(4, 3, 48)];
        let file = write(
            dir.path(),
            &format!("ok-{big}.tif"),
            &build(big, &pages, &ramp(36)),
        );
        let store = dir.path().join(format!("ok-{big}.ome.zarr"));
        let summary = ingest_ok(&["convert", arg(&file), "-o", arg(&store), "--quiet"]);
        assert!(summary.contains("(uint16)"), "{summary}");
        let root: serde_json::Value =
            serde_json::from_slice(&std::fs::read(store.join("zarr.json")).unwrap()).unwrap();
        let channel = &root["attributes"]["residency"]["channels"][0];
        assert_eq!(channel["min"], 0.0);
        assert_eq!(channel["max"], 35.0);
        assert_eq!(channel["voxels"], 36);
        let level0: serde_json::Value =
            serde_json::from_slice(&std::fs::read(store.join("0/zarr.json")).unwrap()).unwrap();
        assert_eq!(level0["shape"], serde_json::json!([1, 3, 3, 4]));
    }
}

#[test]
fn a_huge_uncompressed_plane_is_refused_before_it_is_allocated() {
    let dir = tempfile::tempdir().unwrap();
    for big in [false, true] {
        // 10⁶ × 10⁶ pixels of 16 bits in one strip: 2 TB claimed, 24 bytes stored.
        let mut huge = page(1_000_000, 1_000_000, 0);
        huge.strips = vec![(0, 24)];
        let bytes = build(big, &[huge], &ramp(12));
        let file = write(dir.path(), &format!("huge-{big}.tif"), &bytes);
        refused(
            dir.path(),
            &file,
            &format!(
                "page 0: plane 1000000×1000000 of uint16 needs 2000000000000 bytes, more than \
                 the whole file ({} bytes) although it is stored uncompressed (corrupt TIFF)",
                bytes.len()
            ),
        );
    }
}

#[test]
fn a_huge_compressed_plane_is_refused_by_the_codec_bound() {
    let dir = tempfile::tempdir().unwrap();
    for (compression, codec, most) in [
        (8, "Deflate", 24 * 1032),
        (5, "LZW", (24 * 8u64).div_ceil(9) * 4096),
        (32773, "PackBits", 24 * 64),
    ] {
        for big in [false, true] {
            let mut huge = page(100_000, 100_000, 0);
            huge.strips = vec![(0, 24)];
            huge.compression = compression;
            let file = write(
                dir.path(),
                &format!("{codec}-{big}.tif"),
                &build(big, &[huge], &ramp(12)),
            );
            refused(
                dir.path(),
                &file,
                &format!(
                    "page 0: plane 100000×100000 of uint16 needs 20000000000 bytes, more than its \
                     1 {codec}-compressed strip of 24 bytes can decode to (at most {most} bytes; \
                     corrupt TIFF)"
                ),
            );
        }
    }
}

#[test]
fn a_strip_past_the_end_of_the_file_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    for (big, count) in [(false, 4_000_000_000u64), (true, 1 << 40)] {
        let mut liar = page(4, 3, 0);
        liar.strips = vec![(0, count)];
        let bytes = build(big, &[liar], &ramp(12));
        let file = write(dir.path(), &format!("past-{big}.tif"), &bytes);
        let header = if big { 16 } else { 8 };
        refused(
            dir.path(),
            &file,
            &format!(
                "page 0: strip 0 claims {count} bytes at offset {header} but the file has only \
                 {} bytes (truncated or corrupt TIFF)",
                bytes.len()
            ),
        );
    }
}

#[test]
fn a_lie_on_a_later_page_is_found_before_converting() {
    let dir = tempfile::tempdir().unwrap();
    for big in [false, true] {
        let mut third = page(4, 3, 48);
        third.strips = vec![(48, 1 << 30)];
        let pages = [page(4, 3, 0), page(4, 3, 24), third];
        let bytes = build(big, &pages, &ramp(36));
        let file = write(dir.path(), &format!("later-{big}.tif"), &bytes);
        refused(
            dir.path(),
            &file,
            &format!(
                "page 2: strip 0 claims 1073741824 bytes at offset {} but the file has only {} \
                 bytes (truncated or corrupt TIFF)",
                48 + if big { 16 } else { 8 },
                bytes.len()
            ),
        );
    }
}

#[test]
fn a_directory_entry_claiming_billions_of_values_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    // 3 pages of 2³⁰ rows, one row per strip: StripByteCounts claims 2³⁰ values (in BigTIFF
    // 8 GiB of them in the file, 24 GiB decoded), but the file has a few hundred bytes.
    for big in [false, true] {
        let mut liar = page(4, 1 << 30, 0);
        liar.rows_per_strip = 1;
        liar.strips = vec![(0, 8)];
        liar.claimed_strip_count = Some(1 << 30);
        let first = build(big, &[liar.clone()], &ramp(12));
        let file = write(dir.path(), &format!("count0-{big}.tif"), &first);
        refused(
            dir.path(),
            &file,
            "not a readable TIFF file: a directory entry claims more values than the file holds \
             (corrupt TIFF)",
        );
        let later = build(big, &[page(4, 3, 0), liar], &ramp(12));
        let file = write(dir.path(), &format!("count1-{big}.tif"), &later);
        refused(
            dir.path(),
            &file,
            "cannot read the directory of page 1 (truncated or corrupt TIFF): a directory entry \
             claims more values than the file holds (corrupt TIFF)",
        );
    }
}

#[test]
fn a_plane_larger_than_memory_is_refused_even_when_the_file_holds_it() {
    // A sparse file of 8 TiB whose one strip really holds a 2²¹ × 2²¹ uint16 plane: the file
    // can hold it, no machine this runs on can.
    let memory = residency_ingest::memory::physical_memory().expect("physical memory");
    let side = 1u64 << 21;
    let plane = side * side * 2;
    assert!(
        memory < plane,
        "this test needs less than {plane} bytes of memory"
    );
    let dir = tempfile::tempdir().unwrap();
    // The strip starts 4 KiB after the header, past the directory; the file is extended to
    // its end without writing it.
    let mut huge = page(side, side, 4096);
    huge.strips = vec![(4096, plane)];
    let bytes = build(true, &[huge], &[]);
    assert!(bytes.len() < 4096 + 16);
    let file = write(dir.path(), "sparse.tif", &bytes);
    std::fs::OpenOptions::new()
        .write(true)
        .open(&file)
        .unwrap()
        .set_len(16 + 4096 + plane)
        .unwrap();
    refused(
        dir.path(),
        &file,
        &format!(
            "page 0: plane 2097152×2097152 of uint16 needs 8796093022208 bytes, more than this \
             machine's memory ({memory} bytes)"
        ),
    );
}

#[test]
fn a_stack_that_fits_no_column_of_the_memory_limit_is_refused_before_a_store_is_created() {
    // 64 pages that all point at one real (sparse) plane of 1 GiB: every page is honest, but
    // even the smallest columns hold more than --memory-limit allows.
    let side = 1u64 << 15;
    let plane = side * side;
    let dir = tempfile::tempdir().unwrap();
    let pages = vec![page(side, side, 1 << 16); 64];
    let bytes = build(false, &pages, &[]);
    let file = write(dir.path(), "deep.tif", &bytes);
    std::fs::OpenOptions::new()
        .write(true)
        .open(&file)
        .unwrap()
        .set_len(8 + (1 << 16) + 2 * plane)
        .unwrap();
    let store = dir.path().join("out.ome.zarr");
    let out = ingest(&[
        "convert",
        arg(&file),
        "-o",
        arg(&store),
        "--quiet",
        "--memory-limit",
        "64M",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let prefix = format!("error: {}: converting needs about ", store.display());
    assert!(stderr.starts_with(&prefix), "{stderr}");
    assert!(
        stderr.ends_with(
            "for the region metadata), more than --memory-limit 67108864 bytes; allow more \
             memory, or a smaller z edge of --chunk (and --shard) needs less\n"
        ),
        "{stderr}"
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(!store.exists());
    assert!(!dir.path().join(".out.ome.zarr.partial").exists());
}

#[test]
fn a_lying_slice_found_mid_conversion_leaves_no_store() {
    // A folder of single-page slices: the shape comes from the first, so the third slice's
    // claim is only checked when it is read, after the store has been started.
    let dir = tempfile::tempdir().unwrap();
    let slices = dir.path().join("slices");
    std::fs::create_dir(&slices).unwrap();
    for z in 0..40 {
        let mut p = page(4, 3, 0);
        if z == 37 {
            p.strips = vec![(0, 5_000_000_000)];
        }
        let bytes = build(z % 2 == 1, &[p], &ramp(12));
        std::fs::write(slices.join(format!("z{z}.tif")), bytes).unwrap();
    }
    let liar = slices.join("z37.tif");
    let len = std::fs::metadata(&liar).unwrap().len();
    let store = dir.path().join("out.ome.zarr");
    let out = ingest(&[
        "convert",
        arg(&slices),
        "-o",
        arg(&store),
        "--chunk",
        "8",
        "--quiet",
    ]);
    assert_eq!(
        String::from_utf8_lossy(&out.stderr),
        format!(
            "error: {}: page 0: strip 0 claims 5000000000 bytes at offset 16 but the file has \
             only {len} bytes (truncated or corrupt TIFF)\n",
            liar.display()
        )
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(!store.exists());
    assert!(!dir.path().join(".out.ome.zarr.partial").exists());
}
