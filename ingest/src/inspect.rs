//! `ingest inspect`: a human-readable report of an OME-Zarr store, in a local folder or an
//! object store.

use std::fmt::Write;
use std::path::PathBuf;

use residency_schemas::zarr::SHARDING_CODEC;
use residency_store::location::{LocationError, ObjectStoreOptions, StoreLocation};
use residency_store::pyramid::{Pyramid, PyramidError};
use zarrs::array::ArrayMetadata;
use zarrs::metadata::v3::MetadataV3;
use zarrs::metadata_ext::chunk_grid::regular::RegularChunkGridConfiguration;
use zarrs::metadata_ext::codec::blosc::BloscCodecConfiguration;
use zarrs::metadata_ext::codec::sharding::ShardingCodecConfiguration;

/// Why a store cannot be inspected. Messages name the store; errors of the pyramid reader
/// are its own, unchanged.
#[derive(Debug, thiserror::Error)]
pub enum InspectError {
    /// The path is not a folder.
    #[error("{}: not an OME-Zarr image (no zarr.json or .zattrs)", path.display())]
    NotAnImage {
        /// The path.
        path: PathBuf,
    },
    /// The store cannot be opened (a folder zarrs refuses, an object store out of reach).
    #[error(transparent)]
    Open(#[from] LocationError),
    /// The pyramid reader refuses the store.
    #[error(transparent)]
    Pyramid(#[from] PyramidError),
}

/// A list of numbers as compact JSON (`[1,64,64,64]`).
fn json_list(v: &[impl serde::Serialize]) -> String {
    serde_json::to_string(v).unwrap_or_default()
}

/// A serde enum's JSON name without quotes (`lz4`).
fn json_name(v: &impl serde::Serialize) -> String {
    serde_json::to_string(v)
        .unwrap_or_default()
        .trim_matches('"')
        .to_string()
}

/// One codec as shown in the report: `blosc(lz4, shuffle "shuffle")`, or its name.
fn codec_name(codec: &MetadataV3) -> String {
    match codec.to_configuration::<BloscCodecConfiguration>() {
        Ok(BloscCodecConfiguration::V1(c)) if codec.name() == "blosc" => format!(
            "blosc({}, shuffle {})",
            json_name(&c.cname),
            serde_json::to_string(&c.shuffle).unwrap_or_default()
        ),
        _ => codec.name().to_string(),
    }
}

/// The chunk shape and codecs of an array, as shown in the report.
fn chunks_and_codecs(metadata: &ArrayMetadata) -> (String, String) {
    match metadata {
        ArrayMetadata::V3(m) => {
            let chunk = m
                .chunk_grid
                .to_configuration::<RegularChunkGridConfiguration>()
                .map_or_else(
                    |_| m.chunk_grid.name().to_string(),
                    |c| json_list(&c.chunk_shape),
                );
            let codecs: Vec<String> = m
                .codecs
                .iter()
                .map(
                    |c| match c.to_configuration::<ShardingCodecConfiguration>() {
                        Ok(ShardingCodecConfiguration::V1(s)) if c.name() == SHARDING_CODEC => {
                            let inner: Vec<String> = s.codecs.iter().map(codec_name).collect();
                            format!(
                                "sharding(bricks {}: {})",
                                json_list(&s.chunk_shape),
                                inner.join(" + ")
                            )
                        }
                        _ => codec_name(c),
                    },
                )
                .collect();
            (chunk, codecs.join(" + "))
        }
        ArrayMetadata::V2(m) => {
            let (id, cname) = m
                .compressor
                .as_ref()
                .map_or(("none".into(), String::new()), |c| {
                    let cname = c
                        .configuration()
                        .get("cname")
                        .and_then(|v| v.as_str())
                        .unwrap_or_default()
                        .to_string();
                    (c.id().to_string(), cname)
                });
            (json_list(&m.chunks), format!("{id} {cname}"))
        }
    }
}

/// The `ingest inspect` report for the store at `location`.
///
/// # Errors
/// When the store cannot be opened or is not an OME-Zarr image the pyramid reader accepts.
pub fn inspect(
    location: &StoreLocation,
    options: &ObjectStoreOptions,
) -> Result<String, InspectError> {
    let shown = location.to_string();
    if let Some(path) = location.folder()
        && !path.is_dir()
    {
        return Err(InspectError::NotAnImage {
            path: path.to_path_buf(),
        });
    }
    let store = location.open_readable(options)?;
    let pyramid = Pyramid::open(store, &shown)?;
    let attributes = &pyramid.attributes;
    let image = attributes.image();
    let version = image
        .version
        .clone()
        .unwrap_or_else(|| attributes.version.as_str().to_string());
    let mut out = String::new();
    let _ = writeln!(out, "{shown}: OME-Zarr {version}");
    let axes: Vec<String> = image
        .axes
        .iter()
        .map(|a| match &a.unit {
            Some(u) => format!("{} ({u})", a.name),
            None => a.name.clone(),
        })
        .collect();
    let _ = writeln!(out, "axes: {}", axes.join(", "));
    for (level, dataset) in pyramid.levels.iter().zip(&image.datasets) {
        let (chunks, codecs) = chunks_and_codecs(level.array.metadata());
        let scale = dataset.scale().map(json_list).unwrap_or_default();
        let _ = writeln!(
            out,
            "level {}: shape {:?} {} chunks {chunks} codecs {codecs} scale {scale}",
            level.path,
            level.array.shape(),
            level.description.sample_type
        );
    }
    if let Some(regions) = &attributes.regions {
        let datasets = image.datasets.len();
        let covered = image
            .datasets
            .iter()
            .filter(|d| regions.levels.iter().any(|l| d.path == l.image))
            .count();
        let _ = writeln!(
            out,
            "region metadata: {} levels (covers {covered} of {datasets} image levels), cells {:?} (+{} halo), bricks {:?}, {} histogram bins",
            regions.levels.len(),
            regions.cell_shape,
            regions.halo,
            regions.brick_shape,
            regions.histogram_bins
        );
        for l in &regions.levels {
            let _ = writeln!(
                out,
                "  level {}: {} min/max grids (finest {:?}), bricks written {}, empty {}",
                l.image,
                l.minmax.len(),
                l.minmax.first().map(|g| g.grid_shape).unwrap_or_default(),
                l.bricks_written,
                l.bricks_empty
            );
        }
        for c in &regions.channels {
            let p = |x: f64| {
                c.percentiles
                    .iter()
                    .find(|q| q.percent == x)
                    .map_or("-".into(), |q| format!("{}", q.value))
            };
            let _ = writeln!(
                out,
                "channel '{}': min {} max {} mean {} nan {} p1 {} p50 {} p99.9 {}",
                c.label,
                c.min.map_or("-".into(), |v| v.to_string()),
                c.max.map_or("-".into(), |v| v.to_string()),
                c.mean.map_or("-".into(), |v| format!("{v:.3}")),
                c.nan_voxels,
                p(1.0),
                p(50.0),
                p(99.9)
            );
        }
    } else {
        for c in attributes.omero.iter().flat_map(|o| &o.channels) {
            let window = c.window.as_ref().map_or("null".into(), |w| {
                serde_json::to_string(w).unwrap_or_default()
            });
            let _ = writeln!(
                out,
                "channel '{}': window {window}",
                c.label.as_deref().unwrap_or("?"),
            );
        }
        let _ = writeln!(
            out,
            "region metadata: none (run `ingest index {shown}` to add it)"
        );
    }
    Ok(out)
}
