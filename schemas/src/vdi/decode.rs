//! Reading a VDI file ([`VolumetricDepthImage::decode`]): the header and the three planes
//! read and checked in the file's order, then every supersegment converted and checked in
//! bands of rows of lists at once, each band into its own part of the image. Native builds
//! run the bands on rayon's threads; the web build one after the other.

use std::borrow::Cow;

use half::f16;

use super::{
    Band, ColourFormat, Compression, DepthFormat, MAX_HEADER_BYTES, VDI_MAGIC, VdiError, VdiHeader,
    VolumetricDepthImage, ZSTD_MAGIC, bands, check_header, check_slot, dequantise, try_in_order,
    used_slots,
};

impl VolumetricDepthImage {
    /// Reads a VDI file (the layout in the module documentation); `source` (the file name or
    /// URL) starts every error message.
    ///
    /// It never panics on any input, and allocates at most what the header's sizes imply
    /// (bounded by [`super::MAX_VDI_SLOTS`]) beside what the input itself holds: an LZ4 plane's
    /// announced size is checked before it is decompressed.
    ///
    /// # Errors
    /// A [`VdiError`] for the first of the checks in the module documentation that fails.
    pub fn decode(bytes: &[u8], source: &str) -> Result<Self, VdiError> {
        let file = source;
        if bytes.get(..VDI_MAGIC.len()) != Some(&VDI_MAGIC[..]) {
            return Err(VdiError::BadMagic {
                file: file.to_owned(),
            });
        }
        let mut reader = Reader {
            bytes: &bytes[VDI_MAGIC.len()..],
            file,
        };
        let length = u32::from_le_bytes(reader.array(|| "header length".to_owned())?);
        if length > MAX_HEADER_BYTES {
            return Err(VdiError::HeaderTooLong {
                file: file.to_owned(),
                length: u64::from(length),
            });
        }
        let json = reader.take(u64::from(length), || "header".to_owned())?;
        let header: VdiHeader =
            serde_json::from_slice(json).map_err(|source| VdiError::BadHeader {
                file: file.to_owned(),
                source,
            })?;
        let shape = check_header(&header, file)?;
        let compression = header.compression;
        let counts = reader.plane("counts", compression, shape.lists, 1)?;
        let used = used_slots(&counts, &header, file)?;
        let colour = reader.plane(
            "colour",
            compression,
            used * header.colour.slot_bytes(),
            header.colour.value_bytes(),
        )?;
        let depth = reader.plane(
            "depth",
            compression,
            used * header.depth.slot_bytes(),
            header.depth.value_bytes(),
        )?;
        if !reader.bytes.is_empty() {
            return Err(VdiError::Trailing {
                file: file.to_owned(),
                extra: reader.bytes.len() as u64,
            });
        }
        let mut image = Self::new(header);
        image.counts.copy_from_slice(&counts);
        image.read_slots(&colour, &depth, file)?;
        Ok(image)
    }

    /// Fills the supersegments, for the counts already set, from the raw `colour` and `depth`
    /// planes (exactly the slots the counts imply), converted to the image's types (colour in
    /// half floats, depth in `f32`) and checked as [`check_slot`] checks them.
    ///
    /// # Errors
    /// The [`VdiError`] of the first slot, in the file's order, that fails a check.
    fn read_slots(&mut self, colour: &[u8], depth: &[u8], file: &str) -> Result<(), VdiError> {
        let header = &self.header;
        let (colour_bytes, depth_bytes) = (header.colour.slot_bytes(), header.depth.slot_bytes());
        let used = colour.len() / colour_bytes;
        self.colour = vec![[f16::ZERO; 4]; used];
        self.depth = vec![[0.0; 2]; used];
        let (mut colour_rest, mut depth_rest) = (&mut self.colour[..], &mut self.depth[..]);
        let mut parts = Vec::new();
        for band in bands(&self.counts, header.width as usize) {
            let (c, c_rest) = colour_rest.split_at_mut(band.slots);
            let (d, d_rest) = depth_rest.split_at_mut(band.slots);
            (colour_rest, depth_rest) = (c_rest, d_rest);
            let slots = band.first_slot..band.first_slot + band.slots;
            let colour_in = &colour[slots.start * colour_bytes..slots.end * colour_bytes];
            let depth_in = &depth[slots.start * depth_bytes..slots.end * depth_bytes];
            parts.push((band, colour_in, depth_in, c, d));
        }
        try_in_order(parts, |(band, colour_in, depth_in, c, d)| {
            read_band(header, &band, (colour_in, depth_in), (c, d), file)
        })
    }
}

/// Converts and checks the supersegments of one band, from its parts of the raw planes into
/// its parts of the image's.
///
/// # Errors
/// The [`VdiError`] of the band's first slot that fails a check.
fn read_band(
    header: &VdiHeader,
    band: &Band<'_>,
    (colour_in, depth_in): (&[u8], &[u8]),
    (colour, depth): (&mut [[f16; 4]], &mut [[f32; 2]]),
    file: &str,
) -> Result<(), VdiError> {
    let width = header.width as usize;
    let mut colour_in = colour_in.chunks_exact(header.colour.slot_bytes());
    let mut depth_in = depth_in.chunks_exact(header.depth.slot_bytes());
    let mut out = colour.iter_mut().zip(depth.iter_mut());
    for (i, &count) in band.counts.iter().enumerate() {
        let index = band.first_list + i;
        let (x, y) = ((index % width) as u32, (index / width) as u32);
        let mut previous_back = None;
        for s in 0..u32::from(count) {
            let (Some(c), Some(d), Some((c_out, d_out))) =
                (colour_in.next(), depth_in.next(), out.next())
            else {
                unreachable!("a band's parts of the planes hold exactly its supersegments");
            };
            let c = colour_of(header.colour, c);
            let d = depth_of(header.depth, d, header.near, header.far);
            check_slot(file, (x, y, s), c, d, previous_back)?;
            previous_back = Some(d[1]);
            (*c_out, *d_out) = (c, d);
        }
    }
    Ok(())
}

/// One slot's colour as the image holds it, from its bytes in the colour plane: half floats
/// as they are, `f32` rounded to the nearest half float.
#[inline]
fn colour_of(format: ColourFormat, bytes: &[u8]) -> [f16; 4] {
    match format {
        ColourFormat::F16 => {
            let b: &[u8; 8] = bytes.first_chunk().expect("an f16 colour slot is 8 bytes");
            std::array::from_fn(|i| f16::from_le_bytes([b[2 * i], b[2 * i + 1]]))
        }
        ColourFormat::F32 => f32s(bytes).map(f16::from_f32),
    }
}

/// The first `N` little-endian `f32` of `bytes` (a slot of at least `4·N` bytes).
#[inline]
fn f32s<const N: usize>(bytes: &[u8]) -> [f32; N] {
    std::array::from_fn(|i| {
        let b = bytes[4 * i..4 * i + 4].first_chunk().expect("4 bytes");
        f32::from_le_bytes(*b)
    })
}

/// One slot's front and back distances, from its bytes in the depth plane.
#[inline]
fn depth_of(format: DepthFormat, bytes: &[u8], near: f32, far: f32) -> [f32; 2] {
    match format {
        DepthFormat::F32 => f32s(bytes),
        DepthFormat::U16 => {
            let b: &[u8; 4] = bytes.first_chunk().expect("a u16 depth slot is 4 bytes");
            std::array::from_fn(|i| {
                dequantise(u16::from_le_bytes([b[2 * i], b[2 * i + 1]]), near, far)
            })
        }
    }
}

/// Reads the input front to back, refusing to run past its end.
struct Reader<'a> {
    bytes: &'a [u8],
    file: &'a str,
}

impl<'a> Reader<'a> {
    fn take(&mut self, needed: u64, what: impl FnOnce() -> String) -> Result<&'a [u8], VdiError> {
        let available = self.bytes.len() as u64;
        if needed > available {
            return Err(VdiError::Truncated {
                file: self.file.to_owned(),
                what: what(),
                needed,
                available,
            });
        }
        let (taken, rest) = self.bytes.split_at(needed as usize);
        self.bytes = rest;
        Ok(taken)
    }

    fn array<const N: usize>(
        &mut self,
        what: impl FnOnce() -> String,
    ) -> Result<[u8; N], VdiError> {
        let mut out = [0; N];
        out.copy_from_slice(self.take(N as u64, what)?);
        Ok(out)
    }

    /// One plane of values of `width` bytes, decompressed (and unshuffled), checked to be
    /// exactly `expected` bytes.
    fn plane(
        &mut self,
        plane: &'static str,
        compression: Compression,
        expected: usize,
        width: usize,
    ) -> Result<Cow<'a, [u8]>, VdiError> {
        let stored = u64::from_le_bytes(self.array(|| format!("length of the {plane} plane"))?);
        let data = self.take(stored, || format!("{plane} plane"))?;
        let file = self.file;
        match compression {
            Compression::None => {
                if data.len() != expected {
                    return Err(VdiError::PlaneSize {
                        file: file.to_owned(),
                        plane,
                        stored,
                        expected: expected as u64,
                    });
                }
                Ok(Cow::Borrowed(data))
            }
            Compression::Lz4 | Compression::ShuffledLz4 | Compression::ShuffledZstd => {
                let announced_size = |announced: u64| {
                    if announced == expected as u64 {
                        Ok(())
                    } else {
                        Err(VdiError::AnnouncedSize {
                            file: file.to_owned(),
                            plane,
                            announced,
                            expected: expected as u64,
                        })
                    }
                };
                let mut raw = Vec::new();
                let actual = if compression == Compression::ShuffledZstd {
                    let frame = |problem| VdiError::ZstdFrame {
                        file: file.to_owned(),
                        plane,
                        problem,
                    };
                    // Only a standard frame: not a skippable one (whose size reads as 0), nor
                    // the legacy formats the library may be built to read.
                    if !data.starts_with(&ZSTD_MAGIC) {
                        return Err(frame("it does not begin with zstd's magic number"));
                    }
                    let announced = zstd::zstd_safe::get_frame_content_size(data)
                        .map_err(|_| frame("its frame header is not a zstd frame header"))?
                        .ok_or_else(|| frame("its frame header does not announce its size"))?;
                    announced_size(announced)?;
                    if zstd::zstd_safe::find_frame_compressed_size(data).ok() != Some(data.len()) {
                        return Err(frame("it is not exactly one whole zstd frame"));
                    }
                    raw.resize(expected, 0);
                    zstd::bulk::decompress_to_buffer(data, &mut raw).map_err(|source| {
                        VdiError::Zstd {
                            file: file.to_owned(),
                            plane,
                            source,
                        }
                    })?
                } else {
                    let lz4 = |source| VdiError::Lz4 {
                        file: file.to_owned(),
                        plane,
                        source,
                    };
                    let (announced, block) =
                        lz4_flex::block::uncompressed_size(data).map_err(lz4)?;
                    announced_size(announced as u64)?;
                    raw.resize(expected, 0);
                    lz4_flex::block::decompress_into(block, &mut raw).map_err(lz4)?
                };
                if actual != expected {
                    return Err(VdiError::ShortPlane {
                        file: file.to_owned(),
                        plane,
                        actual: actual as u64,
                        expected: expected as u64,
                    });
                }
                if compression.shuffles() {
                    raw = unshuffle(&raw, width);
                }
                Ok(Cow::Owned(raw))
            }
        }
    }
}

/// The inverse of [`super::encode::shuffle`]: values of `width` bytes from their bytes
/// grouped by place.
pub(super) fn unshuffle(shuffled: &[u8], width: usize) -> Vec<u8> {
    let n = shuffled.len() / width;
    let mut out = vec![0; shuffled.len()];
    if n == 0 {
        return out;
    }
    // One pass over the values, each gathered from the `width` groups: the widths a VDI has
    // spelled out, so that the compiler sees fixed-size values.
    match width {
        2 => {
            let (first, second) = shuffled.split_at(n);
            for (value, (&a, &b)) in out.chunks_exact_mut(2).zip(first.iter().zip(second)) {
                value.copy_from_slice(&[a, b]);
            }
        }
        4 => {
            let mut groups = shuffled.chunks_exact(n);
            let (Some(g0), Some(g1), Some(g2), Some(g3)) =
                (groups.next(), groups.next(), groups.next(), groups.next())
            else {
                unreachable!("four groups of n bytes");
            };
            let quads = g0.iter().zip(g1).zip(g2.iter().zip(g3));
            for (value, ((&a, &b), (&c, &d))) in out.chunks_exact_mut(4).zip(quads) {
                value.copy_from_slice(&[a, b, c, d]);
            }
        }
        _ => {
            for (b, group) in shuffled.chunks_exact(n).take(width).enumerate() {
                for (value, &byte) in out.chunks_exact_mut(width).zip(group) {
                    value[b] = byte;
                }
            }
        }
    }
    out
}
