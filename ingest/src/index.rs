//! `ingest index`: adds region metadata to an OME-Zarr image written by another tool,
//! reading each level once and never rewriting its data.
//!
//! Bricks are the store's own chunks (inner chunks when sharded). The metadata arrays are
//! written first; the image group's attributes are replaced last, through a temporary file
//! and a rename, so an interrupted run leaves the store as it was.

use std::path::Path;
use std::sync::{Arc, Mutex};

use anyhow::{Context, Result, bail};
use residency_schemas::REGIONS_KEY;
use serde_json::Value;
use zarrs::array::{Array, ArraySubset};

use crate::convert::SlabSink;
use crate::inspect::read_image_attributes;
use crate::region_writer::{LevelRegions, write_region_metadata};
use crate::regions::{CellGrid, ChannelAccumulator, LevelHistograms};
use crate::sample_format::{Sample, SampleFormat};
use crate::store::{OmeZarrVersion, Store, StoreWriter};
use crate::with_sample_type;

/// One level of the existing store.
struct ExistingLevel {
    path: String,
    array: Array<Store>,
    /// Shape `z, y, x`.
    shape: [u64; 3],
}

fn format_of(meta: &Value, shown: &str) -> Result<SampleFormat> {
    let name = match meta["zarr_format"].as_u64() {
        Some(3) => meta["data_type"].as_str().unwrap_or("").to_string(),
        _ => {
            let d = meta["dtype"].as_str().unwrap_or("");
            match d.trim_start_matches(['<', '|', '=']) {
                "u1" => "uint8",
                "u2" => "uint16",
                "i2" => "int16",
                "u4" => "uint32",
                "i4" => "int32",
                "f4" => "float32",
                _ => d,
            }
            .to_string()
        }
    };
    SampleFormat::parse(&name).with_context(|| format!("{shown}: unsupported sample format"))
}

/// The brick shape (`z, y, x`): inner chunks when sharded, chunks otherwise.
fn brick_of(meta: &Value) -> Option<[u64; 3]> {
    let chunk = match meta["zarr_format"].as_u64() {
        Some(3) => {
            let sharded = meta["codecs"]
                .as_array()
                .and_then(|c| c.iter().find(|c| c["name"] == "sharding_indexed"));
            match sharded {
                Some(s) => s["configuration"]["chunk_shape"].clone(),
                None => meta["chunk_grid"]["configuration"]["chunk_shape"].clone(),
            }
        }
        _ => meta["chunks"].clone(),
    };
    let v: Vec<u64> = serde_json::from_value(chunk).ok()?;
    let n = v.len();
    (n >= 3).then(|| [v[n - 3], v[n - 2], v[n - 1]])
}

/// Indexes the image at `path` and returns a short report.
pub fn index(path: &Path) -> Result<String> {
    let shown = path.display().to_string();
    let (_, version, ome) = read_image_attributes(path)?;
    let version = if version == "0.4" {
        OmeZarrVersion::V04
    } else {
        OmeZarrVersion::V05
    };
    let ms = &ome["multiscales"][0];
    let axes: Vec<String> = ms["axes"]
        .as_array()
        .into_iter()
        .flatten()
        .map(|a| a["name"].as_str().unwrap_or("").to_string())
        .collect();
    let n = axes.len();
    if n < 3 || axes[n - 3..] != ["z", "y", "x"] {
        bail!("{shown}: axes {axes:?} do not end in z, y, x");
    }
    let store = Arc::new(crate::store::StagingStore::new(path)?);
    let mut levels = Vec::new();
    let mut format = None;
    let mut brick = None;
    let mut channels = 1u64;
    for ds in ms["datasets"].as_array().into_iter().flatten() {
        let p = ds["path"]
            .as_str()
            .context("dataset without path")?
            .to_string();
        let array = Array::open(store.clone(), &format!("/{p}"))
            .with_context(|| format!("{shown}: cannot open level {p}"))?;
        let shape = array.shape().to_vec();
        if shape.len() != n {
            bail!(
                "{shown}: level {p} has {} dimensions but {n} axes",
                shape.len()
            );
        }
        for (a, &s) in axes[..n - 3].iter().zip(&shape) {
            match a.as_str() {
                "c" => channels = s,
                _ if s == 1 => {}
                other => {
                    bail!("{shown}: axis '{other}' has {s} entries; only c, z, y, x can be indexed")
                }
            }
        }
        let meta = serde_json::to_value(array.metadata())?;
        let f = format_of(&meta, &shown)?;
        if format.is_some_and(|g| g != f) {
            bail!("{shown}: levels have different data types");
        }
        format = Some(f);
        brick = brick.or_else(|| brick_of(&meta));
        levels.push(ExistingLevel {
            path: p,
            shape: [shape[n - 3], shape[n - 2], shape[n - 1]],
            array,
        });
    }
    let format = format.with_context(|| format!("{shown}: no levels"))?;
    let brick = brick.with_context(|| format!("{shown}: cannot tell the chunk shape"))?;
    let labels: Vec<String> = (0..channels as usize)
        .map(|c| {
            ome["omero"]["channels"][c]["label"]
                .as_str()
                .map_or(format!("Channel {c}"), str::to_string)
        })
        .collect();
    with_sample_type!(format, T => index_typed::<T>(path, version, &levels, channels as usize, brick, &labels))
}

fn index_typed<T: Sample>(
    path: &Path,
    version: OmeZarrVersion,
    levels: &[ExistingLevel],
    channels: usize,
    brick: [u64; 3],
    labels: &[String],
) -> Result<String> {
    let shown = path.display().to_string();
    let stats: Vec<Mutex<ChannelAccumulator>> = (0..channels)
        .map(|_| Mutex::new(ChannelAccumulator::default()))
        .collect();
    let mut gathered = Vec::new();
    for (i, level) in levels.iter().enumerate() {
        let [depth, ny, nx] = level.shape;
        let histograms = LevelHistograms::new(
            channels,
            std::array::from_fn(|a| level.shape[a].div_ceil(brick[a])),
        );
        let mut cells = CellGrid::<T>::for_shape(channels, level.shape);
        let sink = SlabSink {
            channels,
            shape: level.shape,
            brick,
            outer: brick,
            array: None,
            histograms: &histograms,
            stats: (i == 0).then_some(stats.as_slice()),
        };
        let (mut written, mut empty) = (0, 0);
        let dims = level.array.shape().len();
        let mut z0 = 0;
        while z0 < depth {
            let nz = brick[0].min(depth - z0);
            let mut ranges: Vec<std::ops::Range<u64>> = level.array.shape()[..dims - 3]
                .iter()
                .map(|&s| 0..s)
                .collect();
            ranges.extend([z0..z0 + nz, 0..ny, 0..nx]);
            let slab: Vec<T> = level
                .array
                .retrieve_array_subset(&ArraySubset::new_with_ranges(&ranges))
                .with_context(|| format!("{shown}: cannot read level {} at z {z0}", level.path))?;
            let (w, e) = sink.process(&slab, z0, nz, &mut cells)?;
            written += w;
            empty += e;
            z0 += nz;
        }
        gathered.push((cells, histograms, written, empty));
    }
    let stats: Vec<ChannelAccumulator> = stats
        .into_iter()
        .map(|m| m.into_inner().expect("stats"))
        .collect();
    let writer = StoreWriter::in_place(path, version)?;
    let region_levels: Vec<LevelRegions<'_, T>> = levels
        .iter()
        .zip(&gathered)
        .map(|(l, (cells, histograms, written, empty))| LevelRegions {
            image: l.path.clone(),
            shape: l.shape,
            factor: std::array::from_fn(|a| levels[0].shape[a].div_ceil(l.shape[a].max(1))),
            cells,
            histograms,
            written: *written,
            empty: *empty,
        })
        .collect();
    let (regions, _) = write_region_metadata(&writer, &region_levels, &stats, labels, brick)?;
    // The metadata arrays reach the disk before the attributes that point to them.
    crate::store::sync_file_system(path)?;
    writer.set_root_attribute(REGIONS_KEY, serde_json::to_value(&regions)?)?;
    Ok(format!(
        "indexed {shown}: {} levels, {} channels, bricks {:?}\n",
        levels.len(),
        channels,
        brick
    ))
}
