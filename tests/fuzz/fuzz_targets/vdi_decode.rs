//! VDI files (`schemas/src/vdi.rs`): `VolumetricDepthImage::decode` on any bytes, under the
//! allocation limit (no header, count, LZ4 size prefix or zstd frame header may make it
//! allocate past the format's bounds; zstd decodes into a buffer of the size the header
//! implies, its own context of fixed size coming from C's malloc, outside the limit). An image that decodes is read as a renderer does (every list's supersegments and
//! its composite, which must be finite), and must encode and decode back to itself.
#![no_main]

use libfuzzer_sys::fuzz_target;
// The allocation limit (`tests/fuzz/src/limits.rs`) is this crate's global allocator.
use residency_fuzz as _;
use residency_schemas::vdi::VolumetricDepthImage;

fuzz_target!(|data: &[u8]| {
    let Ok(image) = VolumetricDepthImage::decode(data, "fuzz.vdi") else {
        return;
    };
    for ((colour, depth), &count) in image.lists().zip(&image.counts) {
        assert_eq!((colour.len(), depth.len()), (count.into(), count.into()));
        let pixel = image.composite_list(colour);
        assert!(pixel.iter().all(|v| v.is_finite()), "{pixel:?}");
    }
    assert_eq!(image.lists().count(), image.counts.len());
    let bytes = image.encode().expect("a decoded VDI encodes");
    let back = VolumetricDepthImage::decode(&bytes, "re-encoded.vdi").expect("it decodes again");
    assert!(
        back == image,
        "decoding the encoded VDI gives another image"
    );
});
