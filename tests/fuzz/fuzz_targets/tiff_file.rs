//! The TIFF reader (`ingest/src/source/tiff*.rs`) on arbitrary bytes: the file header, every
//! IFD, the claims checks of `tiff_claims.rs` and the ImageJ / OME-XML metadata of
//! `tiff_metadata.rs`, then every plane the reader agrees to read. The bytes go to a file, as
//! `TiffSource` only opens paths.
#![no_main]

use libfuzzer_sys::fuzz_target;
use residency_fuzz::{known, planes, scratch};
use residency_ingest::source::TiffSource;

fuzz_target!(|data: &[u8]| {
    let path = scratch::file("input.tif", data);
    known::guarded(|| {
        if let Ok(mut source) = TiffSource::open(&path) {
            planes::read_all(&mut source);
        }
    });
});
