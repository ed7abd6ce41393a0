//! Helpers shared by the `ingest` integration tests: running the real binary and reading
//! TIFF stacks back with the `tiff` crate.

#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

use tiff::decoder::{Decoder, DecodingResult};
use tiff::tags::Tag;

/// Runs the `ingest` binary built for these tests.
pub fn ingest(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ingest"))
        .args(args)
        .output()
        .expect("run ingest")
}

/// Runs `ingest` and returns its stdout, failing the test with its stderr when it fails.
pub fn ingest_ok(args: &[&str]) -> String {
    let out = ingest(args);
    assert!(
        out.status.success(),
        "ingest {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("utf-8 stdout")
}

/// A path as a `&str` argument.
pub fn arg(path: &Path) -> &str {
    path.to_str().expect("utf-8 path")
}

/// The samples of a TIFF stack, page after page.
#[derive(Debug, PartialEq)]
pub enum Voxels {
    /// 8-bit unsigned.
    U8(Vec<u8>),
    /// 16-bit unsigned.
    U16(Vec<u16>),
    /// 32-bit float.
    F32(Vec<f32>),
}

/// A TIFF stack read back: extent `z, y, x`, samples and the first page's description.
pub struct Stack {
    pub shape: [usize; 3],
    pub voxels: Voxels,
    pub description: String,
}

impl Stack {
    /// Every sample as `f64`.
    pub fn values(&self) -> Vec<f64> {
        match &self.voxels {
            Voxels::U8(v) => v.iter().map(|&x| f64::from(x)).collect(),
            Voxels::U16(v) => v.iter().map(|&x| f64::from(x)).collect(),
            Voxels::F32(v) => v.iter().map(|&x| f64::from(x)).collect(),
        }
    }

    /// The data type name.
    pub fn dtype(&self) -> &'static str {
        match &self.voxels {
            Voxels::U8(_) => "uint8",
            Voxels::U16(_) => "uint16",
            Voxels::F32(_) => "float32",
        }
    }
}

/// Reads every page of a single-sample TIFF stack.
pub fn read_stack(path: &Path) -> Stack {
    let file = std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut decoder = Decoder::new(std::io::BufReader::new(file)).expect("TIFF header");
    let description = decoder
        .get_tag_ascii_string(Tag::ImageDescription)
        .unwrap_or_default();
    let (w, h) = decoder.dimensions().unwrap();
    let mut voxels: Option<Voxels> = None;
    let mut pages = 0;
    loop {
        assert_eq!(decoder.dimensions().unwrap(), (w, h), "page {pages}");
        match (decoder.read_image().expect("page decodes"), &mut voxels) {
            (DecodingResult::U8(p), None) => voxels = Some(Voxels::U8(p)),
            (DecodingResult::U16(p), None) => voxels = Some(Voxels::U16(p)),
            (DecodingResult::F32(p), None) => voxels = Some(Voxels::F32(p)),
            (DecodingResult::U8(p), Some(Voxels::U8(v))) => v.extend(p),
            (DecodingResult::U16(p), Some(Voxels::U16(v))) => v.extend(p),
            (DecodingResult::F32(p), Some(Voxels::F32(v))) => v.extend(p),
            _ => panic!("{}: page {pages} has another sample type", path.display()),
        }
        pages += 1;
        if !decoder.more_images() {
            break;
        }
        decoder.next_image().unwrap();
    }
    Stack {
        shape: [pages, h as usize, w as usize],
        voxels: voxels.unwrap(),
        description,
    }
}

/// FNV-1a 64-bit hash of a byte string.
pub fn fnv64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}
