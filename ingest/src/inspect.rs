//! `ingest inspect`: a human-readable report of an OME-Zarr store.

use std::fmt::Write;
use std::path::Path;
use std::sync::Arc;

use anyhow::{Context, Result};
use residency_schemas::{REGIONS_KEY, RegionMetadata};
use serde_json::Value;
use zarrs::array::Array;
use zarrs::filesystem::FilesystemStore;

/// Reads the image group's attributes (Zarr v3 `zarr.json` or v2 `.zattrs`) and returns
/// them with the OME-Zarr version and the OME block (`ome` in 0.5, the root in 0.4).
pub fn read_image_attributes(path: &Path) -> Result<(Value, String, Value)> {
    let shown = path.display();
    let v3 = path.join("zarr.json");
    let (attrs, v3_store) = if v3.exists() {
        let doc: Value = serde_json::from_slice(
            &std::fs::read(&v3).with_context(|| format!("{shown}: cannot read zarr.json"))?,
        )
        .with_context(|| format!("{shown}: zarr.json is not valid JSON"))?;
        (doc["attributes"].clone(), true)
    } else {
        let file = path.join(".zattrs");
        let bytes = std::fs::read(&file)
            .with_context(|| format!("{shown}: not an OME-Zarr image (no zarr.json or .zattrs)"))?;
        (
            serde_json::from_slice(&bytes)
                .with_context(|| format!("{shown}: .zattrs is not valid JSON"))?,
            false,
        )
    };
    let ome = if v3_store {
        attrs["ome"].clone()
    } else {
        attrs.clone()
    };
    let version = ome["version"]
        .as_str()
        .or_else(|| ome["multiscales"][0]["version"].as_str())
        .unwrap_or(if v3_store { "0.5" } else { "0.4" })
        .to_string();
    if ome["multiscales"].as_array().is_none_or(|m| m.is_empty()) {
        anyhow::bail!("{shown}: no OME-Zarr multiscales metadata");
    }
    Ok((attrs, version, ome))
}

/// The `ingest inspect` report for the store at `path`.
pub fn inspect(path: &Path) -> Result<String> {
    let shown = path.display();
    let (attrs, version, ome) = read_image_attributes(path)?;
    let store =
        Arc::new(FilesystemStore::new(path).with_context(|| format!("{shown}: cannot open"))?);
    let ms = &ome["multiscales"][0];
    let mut out = String::new();
    writeln!(out, "{shown}: OME-Zarr {version}")?;
    let axes: Vec<String> = ms["axes"]
        .as_array()
        .into_iter()
        .flatten()
        .map(|a| match a["unit"].as_str() {
            Some(u) => format!("{} ({u})", a["name"].as_str().unwrap_or("?")),
            None => a["name"].as_str().unwrap_or("?").to_string(),
        })
        .collect();
    writeln!(out, "axes: {}", axes.join(", "))?;
    for ds in ms["datasets"].as_array().into_iter().flatten() {
        let p = ds["path"].as_str().unwrap_or("?");
        let array = Array::open(store.clone(), &format!("/{p}"))
            .with_context(|| format!("{shown}: cannot open level {p}"))?;
        let meta = serde_json::to_value(array.metadata())?;
        let scale = ds["coordinateTransformations"]
            .as_array()
            .and_then(|t| t.iter().find(|t| t["type"] == "scale"))
            .map(|t| t["scale"].to_string())
            .unwrap_or_default();
        let (chunks, codecs) = if meta["zarr_format"] == 3 {
            let chunk = meta["chunk_grid"]["configuration"]["chunk_shape"].to_string();
            let codecs: Vec<String> = meta["codecs"]
                .as_array()
                .into_iter()
                .flatten()
                .map(|c| {
                    if c["name"] == "sharding_indexed" {
                        let inner: Vec<String> = c["configuration"]["codecs"]
                            .as_array()
                            .into_iter()
                            .flatten()
                            .map(codec_name)
                            .collect();
                        format!(
                            "sharding(bricks {}: {})",
                            c["configuration"]["chunk_shape"],
                            inner.join(" + ")
                        )
                    } else {
                        codec_name(c)
                    }
                })
                .collect();
            (chunk, codecs.join(" + "))
        } else {
            let c = &meta["compressor"];
            (
                meta["chunks"].to_string(),
                format!(
                    "{} {}",
                    c["id"].as_str().unwrap_or("none"),
                    c["cname"].as_str().unwrap_or("")
                ),
            )
        };
        writeln!(
            out,
            "level {p}: shape {:?} {} chunks {chunks} codecs {codecs} scale {scale}",
            array.shape(),
            array.data_type()
        )?;
    }
    let channels = ome["omero"]["channels"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    match serde_json::from_value::<RegionMetadata>(attrs[REGIONS_KEY].clone()) {
        Ok(regions) => {
            let datasets = ms["datasets"].as_array().map_or(0, Vec::len);
            let covered = ms["datasets"]
                .as_array()
                .into_iter()
                .flatten()
                .filter(|d| regions.levels.iter().any(|l| d["path"] == l.image.as_str()))
                .count();
            writeln!(
                out,
                "region metadata: {} levels (covers {covered} of {datasets} image levels), cells {:?} (+{} halo), bricks {:?}, {} histogram bins",
                regions.levels.len(),
                regions.cell_shape,
                regions.halo,
                regions.brick_shape,
                regions.histogram_bins
            )?;
            for l in &regions.levels {
                writeln!(
                    out,
                    "  level {}: {} min/max grids (finest {:?}), bricks written {}, empty {}",
                    l.image,
                    l.minmax.len(),
                    l.minmax.first().map(|g| g.grid_shape).unwrap_or_default(),
                    l.bricks_written,
                    l.bricks_empty
                )?;
            }
            for c in &regions.channels {
                let p = |x: f64| {
                    c.percentiles
                        .iter()
                        .find(|q| q.percent == x)
                        .map_or("-".into(), |q| format!("{}", q.value))
                };
                writeln!(
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
                )?;
            }
        }
        Err(_) => {
            for c in channels {
                writeln!(
                    out,
                    "channel '{}': window {}",
                    c["label"].as_str().unwrap_or("?"),
                    c["window"]
                )?;
            }
            writeln!(
                out,
                "region metadata: none (run `ingest index {shown}` to add it)"
            )?;
        }
    }
    Ok(out)
}

fn codec_name(c: &Value) -> String {
    let name = c["name"].as_str().unwrap_or("?");
    match name {
        "blosc" => format!(
            "blosc({}, shuffle {})",
            c["configuration"]["cname"].as_str().unwrap_or("?"),
            c["configuration"]["shuffle"]
        ),
        other => other.to_string(),
    }
}
