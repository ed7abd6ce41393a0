//! Writing a VDI file ([`VolumetricDepthImage::encode`]): every supersegment checked as the
//! reader would check it and converted to the header's formats, in bands of rows of lists at
//! once, then the three planes compressed at once. Native builds run the bands and planes on
//! rayon's threads; the web build one after the other.

use std::borrow::Cow;

use super::{
    Band, ColourFormat, Compression, DepthFormat, ENCODING, MAX_HEADER_BYTES, VDI_MAGIC, VdiError,
    VolumetricDepthImage, ZSTD_LEVEL, bands, check_header, check_slot, join, quantise,
    try_in_order, used_slots,
};

impl VolumetricDepthImage {
    /// The image as a VDI file (the layout in the module documentation).
    ///
    /// # Errors
    /// A [`VdiError`] naming `VDI to encode` when the image is one
    /// [`VolumetricDepthImage::decode`] would refuse: a header out of range, arrays of other
    /// lengths than the header implies, a count above N_S, or a used slot with a non-finite
    /// value, a colour below 0, an opacity outside `[0, 1]`, depths not
    /// `0 ≤ front ≤ back`, or a front before the back of the slot before it in its list. With
    /// several bad slots, the first in the file's order.
    pub fn encode(&self) -> Result<Vec<u8>, VdiError> {
        let header = &self.header;
        let shape = check_header(header, ENCODING)?;
        let length_error = |array, length, expected: usize| VdiError::Length {
            file: ENCODING.to_owned(),
            array,
            length,
            expected: expected as u64,
        };
        if self.counts.len() != shape.lists {
            return Err(length_error("counts", self.counts.len(), shape.lists));
        }
        let slots = used_slots(&self.counts, header, ENCODING)?;
        for (array, length) in [("colour", self.colour.len()), ("depth", self.depth.len())] {
            if length != slots {
                return Err(length_error(array, length, slots));
            }
        }
        let json = serde_json::to_vec(header).expect("a checked VDI header always serializes");
        let header_length = json.len() as u64;
        if header_length > u64::from(MAX_HEADER_BYTES) {
            return Err(VdiError::HeaderTooLong {
                file: ENCODING.to_owned(),
                length: header_length,
            });
        }
        let (colour, depth) = self.slot_planes(slots)?;
        // The colour and depth planes are the work; the counts go beside them.
        let compression = header.compression;
        let ((counts, colour), depth) = join(
            || {
                join(
                    || stored_plane(&self.counts, compression, 1),
                    || stored_plane(&colour, compression, header.colour.value_bytes()),
                )
            },
            || stored_plane(&depth, compression, header.depth.value_bytes()),
        );
        let mut out =
            Vec::with_capacity(12 + json.len() + 24 + counts.len() + colour.len() + depth.len());
        out.extend_from_slice(&VDI_MAGIC);
        out.extend_from_slice(&(json.len() as u32).to_le_bytes());
        out.extend_from_slice(&json);
        for plane in [&counts, &colour, &depth] {
            out.extend_from_slice(&(plane.len() as u64).to_le_bytes());
            out.extend_from_slice(plane);
        }
        Ok(out)
    }

    /// The colour and depth planes, uncompressed, of the `slots` supersegments the counts
    /// imply (the arrays hold exactly those): in bands of [`super::BAND_ROWS`] rows, each written
    /// into its own part of the planes.
    ///
    /// # Errors
    /// The [`VdiError`] of the first slot, in the file's order, that `decode` would refuse.
    fn slot_planes(&self, slots: usize) -> Result<(Vec<u8>, Vec<u8>), VdiError> {
        let header = &self.header;
        let (colour_bytes, depth_bytes) = (header.colour.slot_bytes(), header.depth.slot_bytes());
        let mut colour = vec![0; slots * colour_bytes];
        let mut depth = vec![0; slots * depth_bytes];
        let mut parts = Vec::new();
        let (mut colour_rest, mut depth_rest) = (&mut colour[..], &mut depth[..]);
        for band in bands(&self.counts, header.width as usize) {
            let (c, c_rest) = colour_rest.split_at_mut(band.slots * colour_bytes);
            let (d, d_rest) = depth_rest.split_at_mut(band.slots * depth_bytes);
            (colour_rest, depth_rest) = (c_rest, d_rest);
            parts.push((band, c, d));
        }
        try_in_order(parts, |(band, c, d)| self.encode_band(&band, c, d))?;
        Ok((colour, depth))
    }

    /// Checks and converts the supersegments of one band into its parts of the planes.
    ///
    /// # Errors
    /// The [`VdiError`] of the band's first slot that `decode` would refuse.
    fn encode_band(
        &self,
        band: &Band<'_>,
        colour: &mut [u8],
        depth: &mut [u8],
    ) -> Result<(), VdiError> {
        let header = &self.header;
        let width = header.width as usize;
        let mut colour_slots = colour.chunks_exact_mut(header.colour.slot_bytes());
        let mut depth_slots = depth.chunks_exact_mut(header.depth.slot_bytes());
        let mut start = band.first_slot;
        for (i, &count) in band.counts.iter().enumerate() {
            let index = band.first_list + i;
            let (x, y) = ((index % width) as u32, (index / width) as u32);
            for s in 0..usize::from(count) {
                let (c, d) = (self.colour[start + s], self.depth[start + s]);
                let previous_back = (s > 0).then(|| self.depth[start + s - 1][1]);
                check_slot(ENCODING, (x, y, s as u32), c, d, previous_back)?;
                let (Some(c_out), Some(d_out)) = (colour_slots.next(), depth_slots.next()) else {
                    unreachable!("a band's parts of the planes hold exactly its supersegments");
                };
                match header.colour {
                    ColourFormat::F16 => {
                        for (o, v) in c_out.chunks_exact_mut(2).zip(c) {
                            o.copy_from_slice(&v.to_le_bytes());
                        }
                    }
                    ColourFormat::F32 => {
                        for (o, v) in c_out.chunks_exact_mut(4).zip(c) {
                            o.copy_from_slice(&v.to_f32().to_le_bytes());
                        }
                    }
                }
                match header.depth {
                    DepthFormat::F32 => {
                        for (o, v) in d_out.chunks_exact_mut(4).zip(d) {
                            o.copy_from_slice(&v.to_le_bytes());
                        }
                    }
                    DepthFormat::U16 => {
                        for (o, v) in d_out.chunks_exact_mut(2).zip(d) {
                            o.copy_from_slice(&quantise(v, header.near, header.far).to_le_bytes());
                        }
                    }
                }
            }
            start += usize::from(count);
        }
        Ok(())
    }
}

/// One plane of values of `width` bytes as the file stores it: compressed as the header says.
fn stored_plane(raw: &[u8], compression: Compression, width: usize) -> Cow<'_, [u8]> {
    match compression {
        Compression::None => Cow::Borrowed(raw),
        Compression::Lz4 => Cow::Owned(lz4_flex::block::compress_prepend_size(raw)),
        Compression::ShuffledLz4 => {
            Cow::Owned(lz4_flex::block::compress_prepend_size(&shuffle(raw, width)))
        }
        // One frame, its header announcing the raw length (zstd's default for a single call).
        // The call fails only where its output buffer, sized by `ZSTD_compressBound`, is too
        // small, or the level out of range: neither can happen.
        Compression::ShuffledZstd => Cow::Owned(
            zstd::bulk::compress(&shuffle(raw, width), ZSTD_LEVEL)
                .expect("zstd compresses any bytes at a valid level into its bound"),
        ),
    }
}

/// `raw`'s bytes regrouped by their place in a value of `width` bytes (the shuffle of
/// [`Compression::ShuffledLz4`] and [`Compression::ShuffledZstd`]); `raw` holds whole values.
pub(super) fn shuffle(raw: &[u8], width: usize) -> Vec<u8> {
    let n = raw.len() / width;
    let mut out = vec![0; raw.len()];
    if n == 0 {
        return out;
    }
    // One pass over the values, each scattered to the `width` groups: the widths a VDI has
    // spelled out, so that the compiler sees fixed-size values.
    match width {
        2 => {
            let (first, second) = out.split_at_mut(n);
            for (value, (a, b)) in raw.chunks_exact(2).zip(first.iter_mut().zip(second)) {
                (*a, *b) = (value[0], value[1]);
            }
        }
        4 => {
            let mut groups = out.chunks_exact_mut(n);
            let (Some(g0), Some(g1), Some(g2), Some(g3)) =
                (groups.next(), groups.next(), groups.next(), groups.next())
            else {
                unreachable!("four groups of n bytes");
            };
            let quads = g0.iter_mut().zip(g1).zip(g2.iter_mut().zip(g3));
            for (value, ((a, b), (c, d))) in raw.chunks_exact(4).zip(quads) {
                (*a, *b, *c, *d) = (value[0], value[1], value[2], value[3]);
            }
        }
        _ => {
            for (i, value) in raw.chunks_exact(width).enumerate() {
                for (b, &byte) in value.iter().enumerate() {
                    out[b * n + i] = byte;
                }
            }
        }
    }
    out
}
