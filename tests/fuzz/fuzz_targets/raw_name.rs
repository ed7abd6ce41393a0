//! Raw volumes (`ingest/src/source/raw.rs`): the `name_XxYxZ_dtype.raw` name parser on any
//! file name (not only UTF-8), then `RawSource::open` with fuzzed `--dims` / `--dtype` /
//! `--header-bytes` options on a small file of that name, and every plane it agrees to read.
#![no_main]

use std::ffi::OsStr;
use std::os::unix::ffi::OsStrExt;
use std::path::Path;

use arbitrary::Arbitrary;
use libfuzzer_sys::fuzz_target;
use residency_fuzz::{planes, scratch};
use residency_ingest::source::{RawOptions, RawSource, parse_raw_name};
use residency_schemas::SampleType;

#[derive(Arbitrary, Debug)]
struct Input {
    /// A path (any bytes; its last component is the file name).
    name: Vec<u8>,
    dims: Option<[u64; 3]>,
    format: Option<u8>,
    big_endian: bool,
    header_bytes: u64,
    /// File length: this % 4096.
    length: u16,
}

fuzz_target!(|input: Input| {
    let path = Path::new(OsStr::from_bytes(&input.name));
    let parsed = parse_raw_name(path);
    if let Some(([x, y, z], format)) = parsed {
        assert!(x > 0 && y > 0 && z > 0, "{path:?} gave zero dims");
        // What the parser accepts, it accepts again when written canonically.
        let canonical = format!("v_{x}x{y}x{z}_{format}.raw");
        assert_eq!(
            parse_raw_name(Path::new(&canonical)),
            Some(([x, y, z], format)),
            "{path:?} vs {canonical}"
        );
    }
    // Open a small file of that name, if it is a usable file name.
    let Some(file_name) = path.file_name() else {
        return;
    };
    let bytes = file_name.as_bytes();
    if bytes.is_empty() || bytes.len() > 200 || bytes.contains(&0) {
        return;
    }
    let dir = scratch::empty_dir("raw");
    let file = dir.join(file_name);
    let length = (input.length % 4096) as usize;
    let content: Vec<u8> = (0..length).map(|i| (i * 7 + 3) as u8).collect();
    if std::fs::write(&file, &content).is_err() {
        return;
    }
    let options = RawOptions {
        dims: input.dims,
        format: input
            .format
            .map(|f| SampleType::ALL[f as usize % SampleType::ALL.len()]),
        big_endian: input.big_endian,
        header_bytes: input.header_bytes,
    };
    if let Ok(mut source) = RawSource::open(&file, &options) {
        planes::read_all(&mut source);
    }
});
