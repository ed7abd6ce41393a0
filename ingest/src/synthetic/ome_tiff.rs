//! Writing a synthetic scene as one BigTIFF OME-TIFF per channel, plane by plane.
//!
//! Planes are rendered in parallel in batches (a few planes of every channel at a time, so
//! memory is bounded by the plane size and never by the depth of the stack), then appended to
//! the channel files in z order. Files are written under a `.partial` name and renamed into
//! place once complete, so an interrupted run never leaves a complete-looking channel behind.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use rayon::prelude::*;
use tiff::encoder::{TiffEncoder, TiffKindBig, colortype};
use tiff::tags::Tag;

use super::error::SampleError;
use crate::sample_format::SampleType;

/// One z-plane (`y, x` in C order) of one channel, in the channel's sample type.
pub(crate) enum PlaneData {
    /// 8-bit unsigned samples.
    U8(Vec<u8>),
    /// 16-bit unsigned samples.
    U16(Vec<u16>),
    /// 32-bit float samples.
    F32(Vec<f32>),
}

impl PlaneData {
    fn format(&self) -> SampleType {
        match self {
            Self::U8(_) => SampleType::U8,
            Self::U16(_) => SampleType::U16,
            Self::F32(_) => SampleType::F32,
        }
    }
}

/// A channel of a synthetic scene: its file stem, its name in the OME-XML and its sample type.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct ChannelSpec {
    /// File name without `.ome.tif`.
    pub file_stem: String,
    /// Channel (and image) name in the OME-XML.
    pub name: String,
    /// Sample type of every plane.
    pub format: SampleType,
}

impl ChannelSpec {
    /// The channels of one volume seen through `count` transfer functions, all in `format`:
    /// a lone channel is `density` in `STEM.ome.tif`; several are `density` then
    /// `name(k)` for channel `k ≥ 1`, each in `STEM-KK-NAME.ome.tif`.
    pub(crate) fn transfer_channels(
        stem: &str,
        format: SampleType,
        count: usize,
        name: impl Fn(usize) -> String,
    ) -> Vec<Self> {
        if count == 1 {
            return vec![Self {
                file_stem: stem.into(),
                name: "density".into(),
                format,
            }];
        }
        (0..count)
            .map(|k| {
                let name = if k == 0 {
                    "density".to_string()
                } else {
                    name(k)
                };
                Self {
                    file_stem: format!("{stem}-{k:02}-{name}"),
                    name,
                    format,
                }
            })
            .collect()
    }
}

/// A synthetic volume that renders any z-plane of all its channels on its own.
pub(crate) trait Scene: Sync {
    /// Extent `z, y, x` in voxels.
    fn shape(&self) -> [u64; 3];
    /// Physical voxel size `z, y, x` in micrometres.
    fn voxel_size(&self) -> [f64; 3];
    /// The channels, in order.
    fn channels(&self) -> Vec<ChannelSpec>;
    /// Plane `z` of every channel, in channel order, each of [`ChannelSpec::format`].
    fn render_plane(&self, z: u64) -> Vec<PlaneData>;
}

/// OME data type name of a sample format.
fn ome_type(format: SampleType) -> &'static str {
    match format {
        SampleType::F32 => "float",
        other => other.zarr_name(),
    }
}

/// The OME-XML of a single-channel stack, stored in the first page's `ImageDescription`.
fn ome_xml(shape: [u64; 3], voxel_size: [f64; 3], name: &str, kind: &str) -> String {
    let [z, y, x] = shape;
    let [pz, py, px] = voxel_size;
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?><OME xmlns="http://www.openmicroscopy.org/Schemas/OME/2016-06"><Image ID="Image:0" Name="{name}"><Pixels ID="Pixels:0" DimensionOrder="XYZCT" Type="{kind}" SizeX="{x}" SizeY="{y}" SizeZ="{z}" SizeC="1" SizeT="1" PhysicalSizeX="{px}" PhysicalSizeY="{py}" PhysicalSizeZ="{pz}" PhysicalSizeXUnit="&#xB5;m" PhysicalSizeYUnit="&#xB5;m" PhysicalSizeZUnit="&#xB5;m"><Channel ID="Channel:0:0" Name="{name}" SamplesPerPixel="1"/><TiffData/></Pixels></Image></OME>"#
    )
}

/// Memory for one batch of rendered planes (all channels), above which batches shrink.
const BATCH_BYTES: u64 = 256 << 20;

/// Planes rendered per batch: up to 16, fewer when the planes are large, but at least one
/// per worker thread so every core has work.
fn batch_planes(bytes_per_z: u64) -> u64 {
    let threads = rayon::current_num_threads() as u64;
    (BATCH_BYTES / bytes_per_z.max(1)).clamp(threads.clamp(1, 16), 16)
}

/// Writes `scene` into `dir`, one `STEM.ome.tif` per channel, and returns the file paths in
/// channel order.
pub(crate) fn write_scene(
    dir: &Path,
    scene: &dyn Scene,
    progress: bool,
) -> Result<Vec<PathBuf>, SampleError> {
    std::fs::create_dir_all(dir).map_err(|source| SampleError::CreateFolder {
        path: dir.to_path_buf(),
        source,
    })?;
    let shape = scene.shape();
    let voxel_size = scene.voxel_size();
    let channels = scene.channels();
    let paths: Vec<PathBuf> = channels
        .iter()
        .map(|c| dir.join(format!("{}.ome.tif", c.file_stem)))
        .collect();
    let partial: Vec<PathBuf> = paths
        .iter()
        .map(|p| p.with_extension("tif.partial"))
        .collect();
    let open = |p: &PathBuf| -> Result<TiffEncoder<BufWriter<File>, TiffKindBig>, SampleError> {
        let f = File::create(p).map_err(|source| SampleError::CreateFile {
            path: p.clone(),
            source,
        })?;
        TiffEncoder::new_big(BufWriter::with_capacity(1 << 20, f)).map_err(|source| {
            SampleError::StartTiff {
                path: p.clone(),
                source,
            }
        })
    };
    let mut encoders: Vec<_> = partial.iter().map(open).collect::<Result<_, _>>()?;
    let [depth, ny, nx] = shape;
    let bar = if progress {
        ProgressBar::with_draw_target(Some(depth), ProgressDrawTarget::stderr())
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template("{spinner} sample [{elapsed_precise}] [{wide_bar}] {pos}/{len} planes {per_sec} ETA {eta}")
            .expect("template"),
    );
    let bytes_per_z = channels
        .iter()
        .map(|c| c.format.bytes() as u64 * ny * nx)
        .sum();
    let batch = batch_planes(bytes_per_z);
    let descriptions: Vec<String> = channels
        .iter()
        .map(|c| ome_xml(shape, voxel_size, &c.name, ome_type(c.format)))
        .collect();
    let mut z0 = 0;
    while z0 < depth {
        let planes: Vec<Vec<PlaneData>> = (z0..(z0 + batch).min(depth))
            .into_par_iter()
            .map(|z| scene.render_plane(z))
            .collect();
        for (dz, plane) in planes.into_iter().enumerate() {
            let first = z0 == 0 && dz == 0;
            for (c, data) in plane.iter().enumerate() {
                debug_assert_eq!(data.format(), channels[c].format);
                let description = first.then_some(descriptions[c].as_str());
                write_page(&mut encoders[c], [ny, nx], description, data).map_err(|source| {
                    SampleError::WritePage {
                        path: paths[c].clone(),
                        source,
                    }
                })?;
            }
            bar.inc(1);
        }
        z0 += batch;
    }
    drop(encoders);
    for (p, f) in partial.iter().zip(&paths) {
        std::fs::rename(p, f).map_err(|source| SampleError::MoveIntoPlace {
            path: f.clone(),
            source,
        })?;
    }
    bar.finish_and_clear();
    Ok(paths)
}

/// Appends one page; the first page of a file also carries the OME-XML.
fn write_page(
    encoder: &mut TiffEncoder<BufWriter<File>, TiffKindBig>,
    [ny, nx]: [u64; 2],
    description: Option<&str>,
    data: &PlaneData,
) -> tiff::TiffResult<()> {
    macro_rules! image {
        ($ct:ty, $d:expr) => {{
            let mut img = encoder.new_image::<$ct>(nx as u32, ny as u32)?;
            if let Some(text) = description {
                img.encoder().write_tag(Tag::ImageDescription, text)?;
            }
            img.write_data($d)?;
        }};
    }
    match data {
        PlaneData::U8(d) => image!(colortype::Gray8, d),
        PlaneData::U16(d) => image!(colortype::Gray16, d),
        PlaneData::F32(d) => image!(colortype::Gray32Float, d),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn batches_are_bounded_by_memory_and_feed_every_thread() {
        let threads = rayon::current_num_threads().clamp(1, 16) as u64;
        assert_eq!(batch_planes(1), 16);
        assert_eq!(batch_planes(BATCH_BYTES / 16), 16);
        assert_eq!(batch_planes(BATCH_BYTES / 4), 4.max(threads));
        assert_eq!(batch_planes(BATCH_BYTES * 8), threads);
    }

    #[test]
    fn ome_xml_names_the_type_and_voxel_size() {
        let xml = ome_xml(
            [3, 4, 5],
            [1.0, 0.325, 0.325],
            "dapi",
            ome_type(SampleType::F32),
        );
        assert!(xml.contains(r#"Name="dapi""#), "{xml}");
        assert!(
            xml.contains(r#"Type="float" SizeX="5" SizeY="4" SizeZ="3""#),
            "{xml}"
        );
        assert!(xml.contains(r#"PhysicalSizeX="0.325" PhysicalSizeY="0.325" PhysicalSizeZ="1""#));
    }
}
