//! TIFF stacks: multi-page, BigTIFF, striped or tiled, any compression the `tiff` crate
//! decodes (none, LZW, Deflate, PackBits), with ImageJ hyperstack and OME-TIFF metadata.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use anyhow::{Context, Result, bail};
use tiff::decoder::{Decoder, Limits};
use tiff::tags::Tag;

use super::tiff_claims::PageClaims;
use super::tiff_metadata::{StackLayout, normalise_unit, parse_imagej, parse_ome_xml};
use super::{PlaneOut, SourceInfo, VolumeSource};
use crate::sample_format::SampleType;

/// A TIFF file holding a z-stack of one or more channels.
pub struct TiffSource {
    info: SourceInfo,
    decoder: Decoder<BufReader<File>>,
    layout: StackLayout,
    samples_per_pixel: usize,
    file: TiffFile,
    /// Index of the page decoded in `page`.
    cached: Option<u64>,
    page: Vec<u8>,
}

/// What the checks of a TIFF file's claims need to know about it.
#[derive(Clone, Copy, Debug)]
pub(super) struct TiffFile {
    /// Length of the file in bytes.
    pub len: u64,
    /// Physical memory of the machine, when known.
    pub memory: Option<u64>,
}

/// Why the decoder refused a value list: the `tiff` crate's own words ("decoder limits
/// exceeded") do not say what was wrong with the file.
fn explain(error: tiff::TiffError) -> anyhow::Error {
    match error {
        tiff::TiffError::LimitsExceeded => anyhow::anyhow!(
            "a directory entry claims more values than the file holds (corrupt TIFF)"
        ),
        other => other.into(),
    }
}

/// Opens a TIFF decoder. Its limits let a tag's value list be as long as the file could hold
/// (one value per byte) and no longer, nor take more than half the machine's memory once
/// decoded, so a directory entry claiming billions of values is an error and not an
/// allocation; planes are checked separately ([`PageClaims`]) before they are decoded.
pub(super) fn open_decoder(path: &Path) -> Result<(Decoder<BufReader<File>>, TiffFile)> {
    let file = File::open(path).with_context(|| format!("{}: cannot open", path.display()))?;
    let len = file
        .metadata()
        .with_context(|| format!("{}: cannot open", path.display()))?
        .len();
    let memory = crate::memory::physical_memory();
    let mut limits = Limits::unlimited();
    let per_value = size_of::<tiff::decoder::ifd::Value>() as u64;
    let most = len
        .saturating_mul(per_value)
        .min(memory.map_or(u64::MAX, |m| m / 2));
    limits.decoding_buffer_size = usize::try_from(most).unwrap_or(usize::MAX);
    let decoder = Decoder::new(BufReader::new(file))
        .map_err(explain)
        .with_context(|| format!("{}: not a readable TIFF file", path.display()))?
        .with_limits(limits);
    Ok((decoder, TiffFile { len, memory }))
}

/// Checks what the current page (`page` of `path`) claims about its pixel data against what
/// the file and the machine can hold (see [`PageClaims`]).
pub(super) fn check_page(
    decoder: &mut Decoder<BufReader<File>>,
    path: &Path,
    page: u64,
    file: TiffFile,
    format: SampleType,
    samples: usize,
) -> Result<()> {
    PageClaims::read(decoder, format, samples)
        .map_err(explain)
        .with_context(|| {
            format!(
                "{}: cannot read the strips of page {page} (truncated or corrupt TIFF)",
                path.display()
            )
        })?
        .check(path, page, file.len, file.memory)
}

/// The sample format of the current page, or an error naming what is unsupported.
pub(super) fn page_format(
    decoder: &mut Decoder<BufReader<File>>,
    path: &Path,
) -> Result<(SampleType, usize)> {
    let color = decoder
        .colortype()
        .with_context(|| format!("{}: cannot read the pixel layout", path.display()))?;
    let (bits, samples) = match color {
        tiff::ColorType::Gray(b) => (b, 1),
        tiff::ColorType::GrayA(b) => (b, 2),
        tiff::ColorType::RGB(b) => (b, 3),
        tiff::ColorType::RGBA(b) => (b, 4),
        tiff::ColorType::Multiband {
            bit_depth,
            num_samples,
        } => (bit_depth, num_samples as usize),
        other => bail!(
            "{}: unsupported sample format: colour type {other:?}",
            path.display()
        ),
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
            bail!(
                "{}: unsupported sample format: {b}-bit {kind} (supported: 8/16/32-bit unsigned, 16/32-bit signed, 32-bit float)",
                path.display()
            )
        }
    };
    Ok((format, samples))
}

/// Decodes the current page of `decoder` into `buffer` (native byte order), reusing its
/// memory, once [`check_page`] has found that the file can hold the plane it claims.
pub(super) fn decode_page(
    decoder: &mut Decoder<BufReader<File>>,
    path: &Path,
    page: u64,
    file: TiffFile,
    format: SampleType,
    samples: usize,
    buffer: &mut Vec<u8>,
) -> Result<()> {
    check_page(decoder, path, page, file, format, samples)?;
    let (w, h) = decoder.dimensions()?;
    buffer.resize(w as usize * h as usize * samples * format.bytes(), 0);
    decoder.read_image_bytes(buffer).with_context(|| {
        format!(
            "{}: cannot decode page {page} (truncated or corrupt TIFF)",
            path.display()
        )
    })
}

/// Whether decoded pages are big-endian (they are in native byte order).
pub(super) const NATIVE_BIG_ENDIAN: bool = cfg!(target_endian = "big");

fn rational(value: tiff::decoder::ifd::Value) -> Option<f64> {
    use tiff::decoder::ifd::Value;
    match value {
        Value::Rational(n, d) if n > 0 && d > 0 => Some(d as f64 / n as f64),
        _ => None,
    }
}

impl TiffSource {
    /// Opens a TIFF file and works out its channel and z layout from its metadata.
    pub fn open(path: &Path) -> Result<Self> {
        let shown = path.display().to_string();
        let (mut decoder, file) = open_decoder(path)?;
        let (width, height) = decoder
            .dimensions()
            .with_context(|| format!("{shown}: cannot read the image size"))?;
        let (format, samples_per_pixel) = page_format(&mut decoder, path)?;
        let planar = decoder
            .find_tag_unsigned::<u16>(Tag::PlanarConfiguration)
            .ok()
            .flatten()
            .unwrap_or(1);
        if planar == 2 && samples_per_pixel > 1 {
            bail!(
                "{shown}: unsupported sample format: planar-separate pages with {samples_per_pixel} samples per pixel"
            );
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
        check_page(&mut decoder, path, 0, file, format, samples_per_pixel)?;
        let mut pages = 1u64;
        while decoder.more_images() {
            decoder.next_image().map_err(explain).with_context(|| {
                format!(
                    "{shown}: cannot read the directory of page {pages} (truncated or corrupt TIFF)"
                )
            })?;
            // Pages of another size or format are refused when read; check what they claim.
            if let Ok((format, samples)) = page_format(&mut decoder, path) {
                check_page(&mut decoder, path, pages, file, format, samples)?;
            }
            pages += 1;
        }

        let (layout, xy_from_resolution) = if description.contains("<OME") {
            let layout =
                parse_ome_xml(&description).with_context(|| format!("{shown}: OME-TIFF"))?;
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
            bail!(
                "{shown}: has {} time points; ingest converts one time point per store (split the series first)",
                layout.time_points
            );
        }
        // Found by fuzzing: ImageJ `slices=0` passed the page count with any channel count,
        // whose product with the samples per pixel then overflowed.
        if layout.depth == 0 {
            bail!("{shown}: metadata describes 0 z planes (corrupt metadata)");
        }
        // In u128: metadata sizes may multiply past u64.
        let needed = layout.channel_planes as u128 * u128::from(layout.depth);
        if u128::from(pages) < needed {
            bail!(
                "{shown}: metadata describes {needed} pages ({} channels x {} z) but the file has only {pages} (truncated?)",
                layout.channel_planes,
                layout.depth
            );
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
            cached: None,
            page: Vec::new(),
        })
    }
}

impl VolumeSource for TiffSource {
    fn info(&self) -> &SourceInfo {
        &self.info
    }

    fn read_plane(&mut self, channel: usize, z: u64, mut out: PlaneOut<'_>) -> Result<()> {
        let spp = self.samples_per_pixel;
        let page = (channel / spp) as u64 * self.layout.channel_stride + z * self.layout.z_stride;
        let path = self.info.path.clone();
        let shown = path.display();
        if self.cached != Some(page) {
            self.cached = None;
            self.decoder.seek_to_image(page as usize).with_context(|| {
                format!("{shown}: cannot find page {page} (truncated or corrupt TIFF)")
            })?;
            let (w, h) = self.decoder.dimensions()?;
            let [_, ey, ex] = self.info.shape;
            if (h as u64, w as u64) != (ey, ex) {
                bail!("{shown}: page {page} is {w}x{h} pixels but page 0 is {ex}x{ey}");
            }
            let (format, samples) = page_format(&mut self.decoder, &path)?;
            if (format, samples) != (self.info.format, spp) {
                bail!(
                    "{shown}: page {page} holds {samples} x {format} samples per pixel but page 0 holds {spp} x {}",
                    self.info.format
                );
            }
            decode_page(
                &mut self.decoder,
                &path,
                page,
                self.file,
                format,
                spp,
                &mut self.page,
            )?;
            self.cached = Some(page);
        }
        out.fill_from_bytes(
            &self.page,
            self.info.format,
            NATIVE_BIG_ENDIAN,
            spp,
            channel % spp,
        );
        Ok(())
    }
}
