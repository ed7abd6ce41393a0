//! TIFF stacks: multi-page, BigTIFF, striped or tiled, any compression the `tiff` crate
//! decodes (none, LZW, Deflate, PackBits), with ImageJ hyperstack and OME-TIFF metadata.

use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::Path;

use tiff::decoder::{Decoder, Limits};
use tiff::tags::Tag;

use super::error::SourceError;
use super::mapped::MappedPlane;
use super::tiff_claims::PageClaims;
use super::tiff_metadata::{StackLayout, normalise_unit, parse_imagej, parse_ome_xml};
use super::volume::{PlaneRegion, SourceInfo, VolumeSource};
use crate::sample_format::{PlaneOut, SampleType};

/// A TIFF file holding a z-stack of one or more channels.
pub struct TiffSource {
    info: SourceInfo,
    decoder: Decoder<BufReader<File>>,
    layout: StackLayout,
    samples_per_pixel: usize,
    file: TiffFile,
    /// The page and region decoded last.
    decoded: DecodedRegion,
    /// The most that decoding any page holds.
    unit: DecodeUnit,
}

/// The region of a plane decoded last (native byte order, samples interleaved), kept so the
/// channels of one page (RGB samples) decode it once.
#[derive(Default)]
pub(super) struct DecodedRegion {
    /// Which plane (a page, or a slice) and region `pixels` holds.
    held: Option<(u64, PlaneRegion)>,
    pixels: Vec<u8>,
    /// One decoded strip or tile, while a region is gathered.
    chunk: Vec<u8>,
}

impl DecodedRegion {
    /// Whether it holds `region` of plane `plane`.
    pub(super) fn holds(&self, plane: u64, region: PlaneRegion) -> bool {
        self.held == Some((plane, region))
    }

    /// Decodes `region` of the decoder's current page (`page` of `path`, with `samples` and
    /// `extent` checked against the stack's) as the region of plane `plane`: see
    /// [`decode_region`]. Into `into` when given (the destination's own bytes, then held
    /// nowhere here), else into the region kept here.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn decode(
        &mut self,
        plane: u64,
        decoder: &mut Decoder<BufReader<File>>,
        path: &Path,
        page: u64,
        file: TiffFile,
        samples: (SampleType, usize),
        extent: [u64; 2],
        region: PlaneRegion,
        into: Option<&mut [u8]>,
    ) -> Result<(), SourceError> {
        self.held = None;
        let held_elsewhere = into.is_some();
        let (pixels, chunk) = (&mut self.pixels, &mut self.chunk);
        let into = if let Some(destination) = into {
            destination
        } else {
            pixels.resize(region.area() as usize * samples.1 * samples.0.bytes(), 0);
            pixels
        };
        decode_region(
            decoder, path, page, file, samples, extent, region, into, chunk,
        )?;
        if !held_elsewhere {
            self.held = Some((plane, region));
        }
        Ok(())
    }

    /// Fills `out` with sample `sample` of every pixel of `samples` of the region held.
    pub(super) fn fill(
        &self,
        out: &mut PlaneOut<'_>,
        format: SampleType,
        samples: usize,
        sample: usize,
    ) {
        out.fill_from_bytes(&self.pixels, format, NATIVE_BIG_ENDIAN, samples, sample);
    }
}

/// What the checks of a TIFF file's claims need to know about it.
#[derive(Clone, Copy, Debug)]
pub(super) struct TiffFile {
    /// Length of the file in bytes.
    pub len: u64,
    /// Physical memory of the machine, when known.
    pub memory: Option<u64>,
}

/// Opens a TIFF decoder. Its limits let a tag's value list be as long as the file could hold
/// (one value per byte) and no longer, nor take more than half the machine's memory once
/// decoded, so a directory entry claiming billions of values is an error and not an
/// allocation; planes are checked separately ([`PageClaims`]) before they are decoded.
pub(super) fn open_decoder(
    path: &Path,
) -> Result<(Decoder<BufReader<File>>, TiffFile), SourceError> {
    let cannot_open = |source| SourceError::Open {
        path: path.to_path_buf(),
        source,
    };
    let file = File::open(path).map_err(cannot_open)?;
    let len = file.metadata().map_err(cannot_open)?.len();
    let memory = crate::memory::physical_memory();
    let mut limits = Limits::unlimited();
    let per_value = size_of::<tiff::decoder::ifd::Value>() as u64;
    let most = len
        .saturating_mul(per_value)
        .min(memory.map_or(u64::MAX, |m| m / 2));
    limits.decoding_buffer_size = usize::try_from(most).unwrap_or(usize::MAX);
    let decoder = Decoder::new(BufReader::new(file))
        .map_err(|e| SourceError::NotTiff {
            path: path.to_path_buf(),
            source: e.into(),
        })?
        .with_limits(limits);
    Ok((decoder, TiffFile { len, memory }))
}

/// Checks what the current page (`page` of `path`) claims about its pixel data against what
/// the file and the machine can hold (see [`PageClaims`]); returns what decoding it holds.
pub(super) fn check_page(
    decoder: &mut Decoder<BufReader<File>>,
    path: &Path,
    page: u64,
    file: TiffFile,
    format: SampleType,
    samples: usize,
) -> Result<DecodeUnit, SourceError> {
    let claims = PageClaims::read(decoder, format, samples).map_err(|e| SourceError::Strips {
        path: path.to_path_buf(),
        page,
        source: e.into(),
    })?;
    claims.check(path, page, file.len, file.memory)?;
    let (columns, rows) = decoder.chunk_dimensions();
    let predictor = tag_or_one(decoder, Tag::Predictor);
    Ok(DecodeUnit {
        decoded: if claims.compression == 1 && predictor == 1 {
            // Read where it lies, straight into the destination.
            0
        } else {
            u64::from(columns) * u64::from(rows) * (samples * format.bytes()) as u64
        },
        stored: if claims.compression == 1 {
            0
        } else {
            claims.chunks.iter().map(|&(_, n)| n).max().unwrap_or(0)
        },
    })
}

/// What decoding a page holds besides its destination: one strip or tile decoded (0 when
/// they are read where they lie, uncompressed) and one as stored (compressed).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct DecodeUnit {
    /// Bytes of a decoded strip or tile.
    pub decoded: u64,
    /// Bytes of the largest stored strip or tile.
    pub stored: u64,
}

impl DecodeUnit {
    /// The larger of each part of two units (the most any page of a file holds).
    pub(super) fn max(self, other: Self) -> Self {
        Self {
            decoded: self.decoded.max(other.decoded),
            stored: self.stored.max(other.stored),
        }
    }

    /// Bytes held while decoding.
    pub(super) fn bytes(self) -> u64 {
        self.decoded + self.stored
    }
}

/// The sample format of the current page, or an error naming what is unsupported.
pub(super) fn page_format(
    decoder: &mut Decoder<BufReader<File>>,
    path: &Path,
) -> Result<(SampleType, usize), SourceError> {
    let color = decoder
        .colortype()
        .map_err(|source| SourceError::PixelLayout {
            path: path.to_path_buf(),
            source,
        })?;
    let (bits, samples) = match color {
        tiff::ColorType::Gray(b) => (b, 1),
        tiff::ColorType::GrayA(b) => (b, 2),
        tiff::ColorType::RGB(b) => (b, 3),
        tiff::ColorType::RGBA(b) => (b, 4),
        tiff::ColorType::Multiband {
            bit_depth,
            num_samples,
        } => (bit_depth, num_samples as usize),
        colour => {
            return Err(SourceError::UnsupportedColour {
                path: path.to_path_buf(),
                colour,
            });
        }
    };
    let kind = decoder
        .find_tag_unsigned::<u16>(Tag::SampleFormat)
        .ok()
        .flatten()
        .unwrap_or(1);
    let format = match (kind, bits) {
        (1, 8) => SampleType::U8,
        (1, 16) => SampleType::U16,
        (2, 16) => SampleType::I16,
        (1, 32) => SampleType::U32,
        (2, 32) => SampleType::I32,
        (3, 32) => SampleType::F32,
        (k, b) => {
            let kind = match k {
                1 => "unsigned integer",
                2 => "signed integer",
                3 => "floating point",
                _ => "unknown",
            };
            return Err(SourceError::UnsupportedSamples {
                path: path.to_path_buf(),
                bits: b,
                kind,
            });
        }
    };
    Ok((format, samples))
}

/// Decodes the current page of `decoder` into `buffer` (native byte order; as long as the
/// page's pixels), once [`check_page`] has found that the file can hold the plane it claims.
fn decode_page(
    decoder: &mut Decoder<BufReader<File>>,
    path: &Path,
    page: u64,
    file: TiffFile,
    format: SampleType,
    samples: usize,
    buffer: &mut [u8],
) -> Result<(), SourceError> {
    check_page(decoder, path, page, file, format, samples)?;
    decoder
        .read_image_bytes(buffer)
        .map_err(|source| SourceError::Decode {
            path: path.to_path_buf(),
            page,
            source,
        })
}

/// Decodes `region` of the current page (`page` of `path`, planes of `plane` = `y, x`
/// voxels) into `buffer` (as long as the region's pixels), as [`decode_page`] does the whole
/// page: rows of `region.nx` pixels of `samples` interleaved samples, in native byte order. A
/// region smaller than the page decodes only the strips or tiles it meets, each into `chunk`
/// first (uncompressed ones are read where they lie).
#[allow(clippy::too_many_arguments)]
fn decode_region(
    decoder: &mut Decoder<BufReader<File>>,
    path: &Path,
    page: u64,
    file: TiffFile,
    (format, samples): (SampleType, usize),
    plane: [u64; 2],
    region: PlaneRegion,
    buffer: &mut [u8],
    chunk: &mut Vec<u8>,
) -> Result<(), SourceError> {
    if region.is_whole(plane) {
        return decode_page(decoder, path, page, file, format, samples, buffer);
    }
    check_page(decoder, path, page, file, format, samples)?;
    let cannot_decode = |source| SourceError::Decode {
        path: path.to_path_buf(),
        page,
        source,
    };
    let pixel = samples * format.bytes();
    // Strips are chunks as wide as the page.
    let (cw, ch) = decoder.chunk_dimensions();
    let (cw, ch) = (u64::from(cw), u64::from(ch));
    let across = plane[1].div_ceil(cw);
    let [y1, x1] = region.end();
    if tag_or_one(decoder, Tag::Compression) == 1 && tag_or_one(decoder, Tag::Predictor) == 1 {
        // Uncompressed (ImageJ's and tifffile's one strip per page): read the region's row
        // segments where they lie, never the whole strip.
        let offsets = match decoder.get_chunk_type() {
            tiff::decoder::ChunkType::Strip => Tag::StripOffsets,
            tiff::decoder::ChunkType::Tile => Tag::TileOffsets,
        };
        let offsets = decoder.get_tag_u64_vec(offsets).map_err(cannot_decode)?;
        let big_endian = decoder.byte_order() == tiff::tags::ByteOrder::BigEndian;
        let file = decoder.inner();
        for ty in region.y0 / ch..y1.div_ceil(ch) {
            for tx in region.x0 / cw..x1.div_ceil(cw) {
                let offset = offsets
                    .get((ty * across + tx) as usize)
                    .copied()
                    .ok_or_else(|| {
                        cannot_decode(tiff::TiffError::FormatError(
                            tiff::TiffFormatError::InconsistentSizesEncountered,
                        ))
                    })?;
                let (cy0, cx0) = (ty * ch, tx * cw);
                let xs = region.x0.max(cx0)..x1.min(cx0 + cw);
                let n = (xs.end - xs.start) as usize * pixel;
                for y in region.y0.max(cy0)..y1.min(cy0 + ch) {
                    let at = offset + ((y - cy0) * cw + xs.start - cx0) * pixel as u64;
                    let dst = ((y - region.y0) * region.nx + xs.start - region.x0) as usize * pixel;
                    file.seek(SeekFrom::Start(at))
                        .and_then(|_| file.read_exact(&mut buffer[dst..dst + n]))
                        .map_err(|e| cannot_decode(tiff::TiffError::IoError(e)))?;
                }
            }
        }
        if big_endian != NATIVE_BIG_ENDIAN {
            for sample in buffer.chunks_exact_mut(format.bytes()) {
                sample.reverse();
            }
        }
        return Ok(());
    }
    for ty in region.y0 / ch..y1.div_ceil(ch) {
        for tx in region.x0 / cw..x1.div_ceil(cw) {
            let index = u32::try_from(ty * across + tx)
                .map_err(|_| cannot_decode(tiff::TiffError::LimitsExceeded))?;
            let (dw, dh) = decoder.chunk_data_dimensions(index);
            let (dw, dh) = (u64::from(dw), u64::from(dh));
            chunk.resize((dw * dh) as usize * pixel, 0);
            decoder
                .read_chunk_bytes(index, chunk)
                .map_err(cannot_decode)?;
            let (cy0, cx0) = (ty * ch, tx * cw);
            let xs = region.x0.max(cx0)..x1.min(cx0 + dw);
            let n = (xs.end - xs.start) as usize * pixel;
            for y in region.y0.max(cy0)..y1.min(cy0 + dh) {
                let src = ((y - cy0) * dw + xs.start - cx0) as usize * pixel;
                let dst = ((y - region.y0) * region.nx + xs.start - region.x0) as usize * pixel;
                buffer[dst..dst + n].copy_from_slice(&chunk[src..src + n]);
            }
        }
    }
    Ok(())
}

/// A tag of the current page that means 1 when absent (Compression, Predictor): its value.
fn tag_or_one(decoder: &mut Decoder<BufReader<File>>, tag: Tag) -> u16 {
    decoder
        .find_tag_unsigned::<u16>(tag)
        .ok()
        .flatten()
        .unwrap_or(1)
}

/// Whether decoded pages are big-endian (they are in native byte order).
const NATIVE_BIG_ENDIAN: bool = cfg!(target_endian = "big");

fn rational(value: tiff::decoder::ifd::Value) -> Option<f64> {
    use tiff::decoder::ifd::Value;
    match value {
        Value::Rational(n, d) if n > 0 && d > 0 => Some(d as f64 / n as f64),
        _ => None,
    }
}

impl TiffSource {
    /// Opens a TIFF file and works out its channel and z layout from its metadata.
    ///
    /// # Errors
    /// When the file cannot be opened or decoded, its sample format is not supported, a page
    /// claims more than the file or the machine can hold, or its ImageJ or OME metadata is
    /// unusable, describes several time points or more pages than the file has.
    pub fn open(path: &Path) -> Result<Self, SourceError> {
        let (mut decoder, file) = open_decoder(path)?;
        let (width, height) = decoder
            .dimensions()
            .map_err(|source| SourceError::ImageSize {
                path: path.to_path_buf(),
                source,
            })?;
        let (format, samples_per_pixel) = page_format(&mut decoder, path)?;
        let planar = decoder
            .find_tag_unsigned::<u16>(Tag::PlanarConfiguration)
            .ok()
            .flatten()
            .unwrap_or(1);
        if planar == 2 && samples_per_pixel > 1 {
            return Err(SourceError::PlanarSeparate {
                path: path.to_path_buf(),
                samples: samples_per_pixel,
            });
        }
        let description = decoder
            .get_tag_ascii_string(Tag::ImageDescription)
            .unwrap_or_default();
        let x_size = decoder
            .find_tag(Tag::XResolution)
            .ok()
            .flatten()
            .and_then(rational);
        let y_size = decoder
            .find_tag(Tag::YResolution)
            .ok()
            .flatten()
            .and_then(rational);
        // Every page's claims are checked now, before the converter sizes anything from them.
        let mut unit = check_page(&mut decoder, path, 0, file, format, samples_per_pixel)?;
        let mut pages = 1u64;
        while decoder.more_images() {
            decoder.next_image().map_err(|e| SourceError::Directory {
                path: path.to_path_buf(),
                page: pages,
                source: e.into(),
            })?;
            // Pages of another size or format are refused when read; check what they claim.
            if let Ok((format, samples)) = page_format(&mut decoder, path) {
                unit = unit.max(check_page(
                    &mut decoder,
                    path,
                    pages,
                    file,
                    format,
                    samples,
                )?);
            }
            pages += 1;
        }

        let (layout, xy_from_resolution) = if description.contains("<OME") {
            let layout = parse_ome_xml(&description).map_err(|source| SourceError::OmeTiff {
                path: path.to_path_buf(),
                source,
            })?;
            (layout, false)
        } else if let Some(layout) = parse_imagej(&description) {
            (layout, true)
        } else {
            let layout = StackLayout {
                channel_planes: 1,
                depth: pages,
                channel_stride: 0,
                z_stride: 1,
                time_points: 1,
                voxel_size: [None; 3],
                unit: None,
                channel_names: Vec::new(),
            };
            (layout, false)
        };
        if layout.time_points > 1 {
            return Err(SourceError::TimePoints {
                path: path.to_path_buf(),
                time_points: layout.time_points,
            });
        }
        // Found by fuzzing: ImageJ `slices=0` passed the page count with any channel count,
        // whose product with the samples per pixel then overflowed.
        if layout.depth == 0 {
            return Err(SourceError::NoPlanes {
                path: path.to_path_buf(),
            });
        }
        // In u128: metadata sizes may multiply past u64.
        let needed = layout.channel_planes as u128 * u128::from(layout.depth);
        if u128::from(pages) < needed {
            return Err(SourceError::MissingPages {
                path: path.to_path_buf(),
                needed,
                channels: layout.channel_planes,
                depth: layout.depth,
                pages,
            });
        }
        let mut voxel_size = layout.voxel_size;
        if xy_from_resolution {
            voxel_size[1] = voxel_size[1].or(y_size);
            voxel_size[2] = voxel_size[2].or(x_size);
        }
        let known = voxel_size.iter().any(Option::is_some);
        let voxel_size = known.then(|| voxel_size.map(|v| v.unwrap_or(1.0)));
        let channels = layout.channel_planes * samples_per_pixel;
        let channel_names = if layout.channel_names.len() == channels {
            layout.channel_names.clone()
        } else {
            Vec::new()
        };
        Ok(Self {
            info: SourceInfo {
                path: path.to_path_buf(),
                shape: [layout.depth, height as u64, width as u64],
                channels,
                format,
                voxel_size,
                unit: if known {
                    layout.unit.clone().or_else(|| normalise_unit("pixel"))
                } else {
                    None
                },
                channel_names,
            },
            decoder,
            layout,
            samples_per_pixel,
            file,
            decoded: DecodedRegion::default(),
            unit,
        })
    }
}

impl TiffSource {
    /// The page holding the plane at depth `z` of channel `channel`.
    fn page_of(&self, channel: usize, z: u64) -> u64 {
        (channel / self.samples_per_pixel) as u64 * self.layout.channel_stride
            + z * self.layout.z_stride
    }

    /// Makes `page` the decoder's current page, once it is found to be of the first page's
    /// size and sample format; returns that format.
    fn seek_page(&mut self, page: u64) -> Result<SampleType, SourceError> {
        let path = &self.info.path;
        self.decoder
            .seek_to_image(page as usize)
            .map_err(|source| SourceError::Seek {
                path: path.clone(),
                page,
                source,
            })?;
        let (w, h) = self.decoder.dimensions().map_err(SourceError::Tiff)?;
        let [_, ey, ex] = self.info.shape;
        if (h as u64, w as u64) != (ey, ex) {
            return Err(SourceError::PageSize {
                path: path.clone(),
                page,
                width: w,
                height: h,
                expected: [ey, ex],
            });
        }
        let spp = self.samples_per_pixel;
        let (format, samples) = page_format(&mut self.decoder, path)?;
        if (format, samples) != (self.info.format, spp) {
            return Err(SourceError::PageFormat {
                path: path.clone(),
                page,
                samples,
                format,
                expected_samples: spp,
                expected_format: self.info.format,
            });
        }
        Ok(format)
    }
}

/// Where the current page of `decoder` (planes of `[ny, nx]` samples of `sample` bytes each)
/// keeps its pixels, when they are one run of bytes as they would be decoded: strips,
/// uncompressed, without a predictor, black is zero (the decoder inverts white-is-zero pages),
/// in the machine's byte order (or one-byte samples), each strip as long as its rows and
/// starting where the one before ends. Returns the run's offset and length.
fn stored_as_decoded(
    decoder: &mut Decoder<BufReader<File>>,
    [ny, nx]: [u64; 2],
    sample: u64,
) -> Option<(u64, u64)> {
    let big = decoder.byte_order() == tiff::tags::ByteOrder::BigEndian;
    let black_is_zero = decoder
        .find_tag_unsigned::<u16>(Tag::PhotometricInterpretation)
        .ok()
        .flatten()
        == Some(1);
    if (big != NATIVE_BIG_ENDIAN && sample > 1)
        || !black_is_zero
        || tag_or_one(decoder, Tag::Compression) != 1
        || tag_or_one(decoder, Tag::Predictor) != 1
        || decoder.get_chunk_type() != tiff::decoder::ChunkType::Strip
    {
        return None;
    }
    let rows_per_strip = u64::from(decoder.chunk_dimensions().1).max(1);
    let offsets = decoder.get_tag_u64_vec(Tag::StripOffsets).ok()?;
    let counts = decoder.get_tag_u64_vec(Tag::StripByteCounts).ok()?;
    if offsets.len() as u64 != ny.div_ceil(rows_per_strip) || counts.len() != offsets.len() {
        return None;
    }
    let first = *offsets.first()?;
    let mut end = first;
    for (i, (&offset, &count)) in offsets.iter().zip(&counts).enumerate() {
        let rows = rows_per_strip.min(ny - i as u64 * rows_per_strip);
        if offset != end || count != rows * nx * sample {
            return None;
        }
        end = offset.checked_add(count)?;
    }
    Some((first, end - first))
}

/// The current page of `decoder` (`page` of `path`, planes of `[ny, nx]` samples in `format`)
/// mapped from its file, when it is stored as it would be decoded (see [`stored_as_decoded`]).
pub(super) fn map_page(
    decoder: &mut Decoder<BufReader<File>>,
    path: &Path,
    file: TiffFile,
    [ny, nx]: [u64; 2],
    format: SampleType,
) -> Option<MappedPlane> {
    let sample = format.bytes();
    let stored = stored_as_decoded(decoder, [ny, nx], sample as u64)?;
    MappedPlane::map(decoder.inner().get_ref(), path, stored, file.len, sample)
}

impl VolumeSource for TiffSource {
    fn info(&self) -> &SourceInfo {
        &self.info
    }

    fn decoder_bytes(&self, _region: PlaneRegion) -> u64 {
        self.unit.bytes()
    }

    fn map_plane(
        &mut self,
        channel: usize,
        z: u64,
        format: SampleType,
    ) -> Result<Option<MappedPlane>, SourceError> {
        if self.samples_per_pixel != 1 || format != self.info.format {
            return Ok(None);
        }
        self.seek_page(self.page_of(channel, z))?;
        let [_, ny, nx] = self.info.shape;
        let path = &self.info.path;
        Ok(map_page(
            &mut self.decoder,
            path,
            self.file,
            [ny, nx],
            format,
        ))
    }

    fn read_region(
        &mut self,
        channel: usize,
        z: u64,
        region: PlaneRegion,
        mut out: PlaneOut<'_>,
    ) -> Result<(), SourceError> {
        let spp = self.samples_per_pixel;
        let page = self.page_of(channel, z);
        let path = self.info.path.clone();
        if !self.decoded.holds(page, region) {
            let format = self.seek_page(page)?;
            let [_, ey, ex] = self.info.shape;
            // The page's samples are the destination's: decoded straight into it.
            let direct = spp == 1 && out.format() == format;
            self.decoded.decode(
                page,
                &mut self.decoder,
                &path,
                page,
                self.file,
                (format, spp),
                [ey, ex],
                region,
                direct.then(|| out.bytes_mut()),
            )?;
            if direct {
                return Ok(());
            }
        }
        self.decoded
            .fill(&mut out, self.info.format, spp, channel % spp);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use tiff::encoder::{Compression, DeflateLevel, TiffEncoder, colortype};

    use super::*;
    use crate::sample_format::Sample;

    /// Writes 3 pages of 20 × 33 u16 (several strips each, value = 1000·z + y·33 + x).
    fn write_stack(path: &Path, compression: Compression) {
        let file = std::io::BufWriter::new(File::create(path).unwrap());
        let mut encoder = TiffEncoder::new(file)
            .unwrap()
            .with_compression(compression);
        for z in 0..3u16 {
            let data: Vec<u16> = (0..20 * 33u16).map(|i| 1000 * z + i).collect();
            let mut image = encoder.new_image::<colortype::Gray16>(33, 20).unwrap();
            image.rows_per_strip(6).unwrap();
            image.write_data(&data).unwrap();
        }
    }

    fn read(source: &mut TiffSource, z: u64) -> Vec<u16> {
        let mut plane = vec![0u16; 20 * 33];
        source.read_plane(0, z, u16::plane_out(&mut plane)).unwrap();
        plane
    }

    #[test]
    fn uncompressed_pages_are_mapped_as_they_are_read() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("stack.tif");
        write_stack(&path, Compression::Uncompressed);
        let mut source = TiffSource::open(&path).unwrap();
        for z in [2, 0, 1] {
            let mapped = source.map_plane(0, z, SampleType::U16).unwrap().unwrap();
            assert!(mapped.in_place());
            assert_eq!(mapped.samples::<u16>(), read(&mut source, z));
            assert_eq!(mapped.samples::<u16>()[33], 1000 * z as u16 + 33);
        }
        // Another sample type than the file's is read and converted, never mapped.
        assert!(source.map_plane(0, 0, SampleType::F32).unwrap().is_none());
        // A page past the stack is the error reading it would give.
        let error = source.map_plane(0, 3, SampleType::U16).err().unwrap();
        assert!(
            error
                .to_string()
                .starts_with(&format!("{}:", path.display())),
            "{error}"
        );
    }

    #[test]
    fn compressed_pages_are_not_mapped() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("deflate.tif");
        write_stack(&path, Compression::Deflate(DeflateLevel::Fast));
        let mut source = TiffSource::open(&path).unwrap();
        assert!(source.map_plane(0, 1, SampleType::U16).unwrap().is_none());
        assert_eq!(read(&mut source, 1)[5], 1005);
    }
}
