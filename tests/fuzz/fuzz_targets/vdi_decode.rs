//! VDI files (`schemas/src/vdi.rs`): `VolumetricDepthImage::decode` on any bytes, under the
//! allocation limit (no header, count or LZ4 size prefix may make it allocate past the format's
//! bounds). An image that decodes is read as a renderer does (every list's used slots and its
//! composite, which must be finite), and must encode and decode back to itself.
#![no_main]

use libfuzzer_sys::fuzz_target;
// The allocation limit (`tests/fuzz/src/limits.rs`) is this crate's global allocator.
use residency_fuzz as _;
use residency_schemas::vdi::VolumetricDepthImage;

fuzz_target!(|data: &[u8]| {
    let Ok(image) = VolumetricDepthImage::decode(data, "fuzz.vdi") else {
        return;
    };
    let header = &image.header;
    for y in 0..header.height {
        for x in 0..header.width {
            let (colour, depth) = image.list(x, y);
            let count = image.counts[(y * header.width + x) as usize];
            assert_eq!((colour.len(), depth.len()), (count.into(), count.into()));
            let pixel = image.composite(x, y);
            assert!(pixel.iter().all(|v| v.is_finite()), "{pixel:?}");
        }
    }
    let bytes = image.encode().expect("a decoded VDI encodes");
    let back = VolumetricDepthImage::decode(&bytes, "re-encoded.vdi").expect("it decodes again");
    assert!(
        back == image,
        "decoding the encoded VDI gives another image"
    );
});
