//! Reading every plane of a volume source, as `ingest convert` does.

use residency_ingest::sample_format::Sample;
use residency_ingest::source::VolumeSource;
use residency_ingest::with_sample_type;

/// Planes above this size are not read.
///
/// The TIFF claims checks (`ingest/src/source/tiff_claims.rs`) bound a compressed plane by
/// what its codec can expand its bytes to, except for JPEG, which has no such bound: for it
/// the limit is the machine's physical memory, by design. For inputs of at most 64 KiB (the
/// targets' `-max_len`) the bounded codecs allow at most 239 MB (LZW, 4096 bytes per 9-bit
/// code), so only JPEG can give a larger plane, and
/// allocating it would trip the fuzzer's allocation limit on every such input. The harness
/// skips such planes; `docs/fuzzing.md` records this as a known, accepted limit.
pub const UNBOUNDED_CODEC_PLANE_BYTES: u64 = 256 << 20;

/// Reads every plane of every channel of `source` into one plane buffer sized from its
/// `info()`, as the converter does, ignoring read errors (a refused plane is a correct answer
/// to a corrupt file; a panic, an abort or an allocation over the limits is not).
///
/// Returns the number of planes read successfully.
pub fn read_all(source: &mut dyn VolumeSource) -> u64 {
    let info = source.info().clone();
    let [depth, h, w] = info.shape;
    let pixels = h.checked_mul(w).expect("plane pixels overflow u64");
    // Per page, all channels together (the decoder's buffer holds interleaved samples).
    let page_bytes = pixels
        .saturating_mul(info.format.bytes() as u64)
        .saturating_mul(info.channels as u64);
    if page_bytes > UNBOUNDED_CODEC_PLANE_BYTES {
        return 0;
    }
    let pixels = usize::try_from(pixels).expect("plane pixels overflow usize");
    let mut ok = 0;
    with_sample_type!(info.format, T => {
        let mut plane = vec![<T as Default>::default(); pixels];
        for channel in 0..info.channels {
            for z in 0..depth {
                if source.read_plane(channel, z, T::plane_out(&mut plane)).is_ok() {
                    ok += 1;
                }
            }
        }
    });
    ok
}
