//! Checks of what a TIFF page claims about its pixel data, made before any buffer is sized
//! from those claims.
//!
//! A page's header gives its width, height and sample layout, and where its strips or tiles
//! lie; decoding needs a buffer of `width × height × samples` first. A corrupt or malicious
//! header can claim a plane of terabytes in a file of a few hundred bytes, and allocating it
//! would abort the process. So every page is checked first against what its file can hold:
//!
//! - every strip or tile must lie inside the file;
//! - the decoder must have the page's codec (none, LZW, Deflate, PackBits or JPEG), or it
//!   would fail only after the plane was allocated; CCITT Group 4, which encodes only 1-bit
//!   images (no sample type here), is refused;
//! - uncompressed, the plane must fit in the file;
//! - compressed, the plane must fit in what its strips or tiles can decode to: each codec has
//!   a largest expansion (PackBits 64×: two bytes give at most 128; Deflate 1032×, zlib's
//!   documented limit; LZW 4096 bytes per code of at least 9 bits, since its table has 4096
//!   entries and each is at most one byte longer than an earlier one);
//! - and in every case the plane must fit in this machine's physical memory (the only bound
//!   for codecs without one, such as JPEG).

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use tiff::decoder::{ChunkType, Decoder};
use tiff::tags::Tag;

use super::error::{PlaneClaim, SourceError};
use crate::sample_format::SampleType;

/// What one page claims: its plane and its strips or tiles.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct PageClaims {
    /// Width and height in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Samples per pixel.
    pub samples: usize,
    /// Sample format.
    pub format: SampleType,
    /// TIFF `Compression` code.
    pub compression: u16,
    /// `"strip"` or `"tile"`.
    pub chunk: &'static str,
    /// Offset and byte count of each strip or tile.
    pub chunks: Vec<(u64, u64)>,
}

/// Largest number of bytes `compressed` bytes of `compression` can decode to, for the codecs
/// that have a bound (see the module documentation).
fn max_decoded(compression: u16, compressed: u128) -> Option<u128> {
    match compression {
        // PackBits.
        32773 => Some(compressed * 64),
        // Deflate (Adobe and old).
        8 | 32946 => Some(compressed * 1032),
        // LZW.
        5 => Some((compressed * 8).div_ceil(9) * 4096),
        _ => None,
    }
}

fn codec_name(compression: u16) -> String {
    match compression {
        5 => "LZW".into(),
        7 => "JPEG".into(),
        8 | 32946 => "Deflate".into(),
        32773 => "PackBits".into(),
        c => format!("compression {c}"),
    }
}

impl PageClaims {
    /// Reads the current page's claims from its tags.
    pub(super) fn read(
        decoder: &mut Decoder<BufReader<File>>,
        format: SampleType,
        samples: usize,
    ) -> tiff::TiffResult<Self> {
        let (width, height) = decoder.dimensions()?;
        let compression = decoder
            .find_tag_unsigned::<u16>(Tag::Compression)?
            .unwrap_or(1);
        let (chunk, offsets, counts) = match decoder.get_chunk_type() {
            ChunkType::Strip => ("strip", Tag::StripOffsets, Tag::StripByteCounts),
            ChunkType::Tile => ("tile", Tag::TileOffsets, Tag::TileByteCounts),
        };
        let offsets = decoder.get_tag_u64_vec(offsets)?;
        let counts = decoder.get_tag_u64_vec(counts)?;
        Ok(Self {
            width,
            height,
            samples,
            format,
            compression,
            chunk,
            chunks: offsets.into_iter().zip(counts).collect(),
        })
    }

    /// Bytes of the decoded plane.
    pub(super) fn plane_bytes(&self) -> u128 {
        u128::from(self.width)
            * u128::from(self.height)
            * self.samples as u128
            * self.format.bytes() as u128
    }

    /// Checks the claims of page `page` of `path`, a file of `file_len` bytes, on a machine
    /// with `memory` bytes of physical memory (when known).
    pub(super) fn check(
        &self,
        path: &Path,
        page: u64,
        file_len: u64,
        memory: Option<u64>,
    ) -> Result<(), SourceError> {
        for (i, &(offset, count)) in self.chunks.iter().enumerate() {
            if u128::from(offset) + u128::from(count) > u128::from(file_len) {
                return Err(SourceError::ChunkOutsideFile {
                    path: path.to_path_buf(),
                    page,
                    chunk: self.chunk,
                    index: i,
                    count,
                    offset,
                    file_len,
                });
            }
        }
        // CCITT Group 4 encodes 1-bit (bilevel) images only, and no sample type here is
        // 1-bit: a page claiming it decodes to noise, and its bytes have no bound on what they
        // expand to (found by fuzzing: 417 bytes claiming 65,280 16-bit samples per pixel
        // took seconds to decode).
        if self.compression == 4 {
            return Err(SourceError::BilevelCodec {
                path: path.to_path_buf(),
                page,
                bits: self.format.bytes() * 8,
            });
        }
        // A codec the decoder lacks fails only after the plane's buffer is allocated: refuse it
        // first, whatever the plane claims (found by fuzzing: 349 bytes claiming 6.7 GB).
        if !matches!(self.compression, 1 | 5 | 7 | 8 | 32773 | 32946) {
            return Err(SourceError::UnsupportedCompression {
                path: path.to_path_buf(),
                page,
                compression: self.compression,
            });
        }
        let needed = self.plane_bytes();
        let plane = || {
            Box::new(PlaneClaim {
                path: path.to_path_buf(),
                page,
                width: self.width,
                height: self.height,
                samples: self.samples,
                format: self.format,
                bytes: needed,
            })
        };
        if self.compression == 1 {
            if needed > u128::from(file_len) {
                return Err(SourceError::PlaneOverFile {
                    plane: plane(),
                    file_len,
                });
            }
        } else {
            let compressed: u128 = self.chunks.iter().map(|&(_, c)| u128::from(c)).sum();
            if let Some(most) = max_decoded(self.compression, compressed)
                && needed > most
            {
                return Err(SourceError::PlaneOverCodec {
                    plane: plane(),
                    chunks: self.chunks.len(),
                    codec: codec_name(self.compression),
                    chunk: self.chunk,
                    compressed,
                    most,
                });
            }
        }
        if let Some(memory) = memory
            && needed > u128::from(memory)
        {
            return Err(SourceError::PlaneOverMemory {
                plane: plane(),
                memory,
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn claims(width: u32, height: u32, compression: u16, chunks: Vec<(u64, u64)>) -> PageClaims {
        PageClaims {
            width,
            height,
            samples: 1,
            format: SampleType::U16,
            compression,
            chunk: "strip",
            chunks,
        }
    }

    fn error(c: &PageClaims, file_len: u64, memory: Option<u64>) -> String {
        c.check(Path::new("f.tif"), 3, file_len, memory)
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn a_plane_that_fits_passes() {
        let c = claims(100, 10, 1, vec![(8, 1000), (1008, 1000)]);
        assert_eq!(c.plane_bytes(), 2000);
        c.check(Path::new("f.tif"), 0, 2008, Some(4096)).unwrap();
        // Deflate: 2 bytes may decode to 2064.
        claims(100, 10, 8, vec![(8, 1), (9, 1)])
            .check(Path::new("f.tif"), 0, 10, None)
            .unwrap();
    }

    #[test]
    fn each_claim_is_refused_with_its_reason() {
        assert_eq!(
            error(
                &claims(100, 10, 1, vec![(8, 1000), (1008, 1001)]),
                2008,
                None
            ),
            "f.tif: page 3: strip 1 claims 1001 bytes at offset 1008 but the file has only 2008 \
             bytes (truncated or corrupt TIFF)"
        );
        assert_eq!(
            error(&claims(1_000_000, 1_000_000, 1, vec![(8, 24)]), 32, None),
            "f.tif: page 3: plane 1000000×1000000 of uint16 needs 2000000000000 bytes, more than \
             the whole file (32 bytes) although it is stored uncompressed (corrupt TIFF)"
        );
        assert_eq!(
            error(
                &claims(100, 100, 32773, vec![(8, 100), (108, 56)]),
                200,
                None
            ),
            "f.tif: page 3: plane 100×100 of uint16 needs 20000 bytes, more than its 2 \
             PackBits-compressed strips of 156 bytes can decode to (at most 9984 bytes; corrupt \
             TIFF)"
        );
        assert_eq!(
            error(&claims(1000, 1000, 5, vec![(8, 9)]), 200, None),
            "f.tif: page 3: plane 1000×1000 of uint16 needs 2000000 bytes, more than its 1 \
             LZW-compressed strip of 9 bytes can decode to (at most 32768 bytes; corrupt TIFF)"
        );
        let mut rgb = claims(4096, 4096, 7, vec![(8, 100)]);
        rgb.samples = 3;
        rgb.format = SampleType::U8;
        assert_eq!(
            error(&rgb, 200, Some(1 << 20)),
            "f.tif: page 3: plane 4096×4096×3 of uint8 needs 50331648 bytes, more than this \
             machine's memory (1048576 bytes)"
        );
        // Without a bound from the codec or the machine, JPEG is left to the decoder.
        rgb.check(Path::new("f.tif"), 3, 200, None).unwrap();
    }

    /// Found by fuzzing (tests/fuzz, target tiff_file): a 349-byte file claiming a 6.7 GB
    /// plane under an unknown compression passed the memory check, so the converter allocated
    /// the plane before the decoder refused the codec.
    #[test]
    fn an_unknown_codec_is_refused_before_any_allocation() {
        let c = claims(671_088_641, 5, 43779, vec![(256, 82)]);
        assert_eq!(
            error(&c, 349, Some(24 << 30)),
            "f.tif: page 3: unsupported compression 43779 (supported: none, LZW, Deflate, \
             PackBits, JPEG)"
        );
    }

    /// Found by fuzzing (target tiff_file): 417 bytes claiming a 7×5 plane of 65,280 16-bit
    /// samples per pixel, CCITT Group 4 compressed, took seconds to decode into noise.
    #[test]
    fn ccitt_group_4_is_refused_as_it_encodes_only_bilevel_images() {
        let mut c = claims(7, 5, 4, vec![(256, 82)]);
        c.samples = 65_280;
        assert_eq!(
            error(&c, 417, Some(24 << 30)),
            "f.tif: page 3: CCITT Group 4 compression encodes 1-bit (bilevel) images, and 16-bit \
             samples are not 1-bit (unsupported)"
        );
    }

    #[test]
    fn expansion_bounds_match_the_codecs() {
        assert_eq!(max_decoded(32773, 2), Some(128));
        assert_eq!(max_decoded(8, 1), Some(1032));
        assert_eq!(max_decoded(32946, 10), Some(10320));
        // 9 bytes hold 8 codes of 9 bits; 10 bytes hold a ninth, partial one.
        assert_eq!(max_decoded(5, 9), Some(8 * 4096));
        assert_eq!(max_decoded(5, 10), Some(9 * 4096));
        assert_eq!(max_decoded(7, 10), None);
    }
}
