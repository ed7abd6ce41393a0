//! OME-Zarr metadata shared by every source: the image group's attributes (`multiscales`,
//! `omero`, and the `residency` region metadata) and each level's array metadata (Zarr v3
//! `zarr.json` or v2 `.zarray`), turned into a [`VolumeInfo`] whatever the transport.

use anyhow::{Context, Result, bail, ensure};
use residency_schemas::{REGIONS_KEY, RegionMetadata};
use serde_json::Value;

use super::{ChannelDisplay, LevelInfo, MinMaxGrid, SampleType, VolumeInfo};

/// Zarr format of a store.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ZarrFormat {
    /// Zarr v2 (OME-Zarr 0.4): `.zattrs`, `.zarray`.
    V2,
    /// Zarr v3 (OME-Zarr 0.5): `zarr.json`.
    V3,
}

impl ZarrFormat {
    /// Key of the image group's attributes document.
    pub fn group_key(self) -> &'static str {
        match self {
            Self::V2 => ".zattrs",
            Self::V3 => "zarr.json",
        }
    }

    /// Key of an array's metadata document, relative to the array.
    pub fn array_key(self) -> &'static str {
        match self {
            Self::V2 => ".zarray",
            Self::V3 => "zarr.json",
        }
    }
}

/// Which axis of the arrays is which: the last three are always `z, y, x`; before them at most
/// one `c` axis, and any other leading axis (such as `t`) must have a single entry.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AxisLayout {
    /// Axis names, in array order.
    pub names: Vec<String>,
    /// Index of the `c` axis, if any.
    pub channel_axis: Option<usize>,
}

impl AxisLayout {
    /// The chunk (or inner chunk) indices of brick `brick` (`z, y, x`) of channel `channel`.
    pub fn chunk_indices(&self, channel: u64, brick: [u64; 3]) -> Vec<u64> {
        let n = self.names.len();
        let mut idx = vec![0; n];
        if let Some(c) = self.channel_axis {
            idx[c] = channel;
        }
        idx[n - 3..].copy_from_slice(&brick);
        idx
    }
}

/// The image group's OME metadata.
#[derive(Clone, Debug, PartialEq)]
pub struct OmeGroup {
    /// Zarr format the attributes came from.
    pub format: ZarrFormat,
    /// Axes of every level.
    pub axes: AxisLayout,
    /// `multiscales[0].datasets[].path`, finest first.
    pub level_paths: Vec<String>,
    /// `scale` of each level, `z, y, x` (physical units per voxel).
    pub level_scales: Vec<[f64; 3]>,
    /// `omero.channels[]`: label and display hints, possibly fewer than the channels.
    pub omero: Vec<(Option<String>, ChannelDisplay)>,
    /// The `residency` region metadata, if the store has it.
    pub regions: Option<RegionMetadata>,
}

/// What the viewer needs from one level's array metadata.
#[derive(Clone, Debug, PartialEq)]
pub struct ArrayDescription {
    /// Full array shape, in the order of [`AxisLayout::names`].
    pub shape: Vec<u64>,
    /// Sample format.
    pub sample_type: SampleType,
    /// Brick shape `z, y, x`: the inner chunk when sharded, the chunk otherwise.
    pub brick_shape: [u64; 3],
    /// Chunk (or inner chunk) extent along the leading axes, which must all be 1.
    pub leading_chunk: Vec<u64>,
    /// Fill value.
    pub fill_value: f64,
}

/// Parses the image group's attributes document (`zarr.json` of Zarr v3, whose `attributes`
/// hold `ome` and `residency`; or `.zattrs` of Zarr v2). `source` names the document in
/// errors.
pub fn parse_group(format: ZarrFormat, document: &[u8], source: &str) -> Result<OmeGroup> {
    let doc: Value =
        serde_json::from_slice(document).with_context(|| format!("{source}: not valid JSON"))?;
    let attrs = match format {
        ZarrFormat::V3 => {
            ensure!(
                doc["node_type"] == "group",
                "{source}: not a Zarr group (node_type {})",
                doc["node_type"]
            );
            &doc["attributes"]
        }
        ZarrFormat::V2 => &doc,
    };
    let ome = if attrs["ome"].is_object() {
        &attrs["ome"]
    } else {
        attrs
    };
    let ms = ome["multiscales"]
        .get(0)
        .with_context(|| format!("{source}: no OME-Zarr multiscales metadata"))?;
    let names: Vec<String> = ms["axes"]
        .as_array()
        .with_context(|| format!("{source}: multiscales has no axes"))?
        .iter()
        .map(|a| {
            a["name"]
                .as_str()
                .or_else(|| a.as_str())
                .map(str::to_string)
                .with_context(|| format!("{source}: axis without a name: {a}"))
        })
        .collect::<Result<_>>()?;
    let n = names.len();
    ensure!(
        n >= 3 && names[n - 3..] == ["z", "y", "x"],
        "{source}: axes {names:?} do not end in z, y, x"
    );
    let channel_axis = names[..n - 3].iter().position(|a| a == "c");
    let datasets = ms["datasets"]
        .as_array()
        .filter(|d| !d.is_empty())
        .with_context(|| format!("{source}: multiscales has no datasets"))?;
    let mut level_paths = Vec::new();
    let mut level_scales = Vec::new();
    for ds in datasets {
        let path = ds["path"]
            .as_str()
            .with_context(|| format!("{source}: dataset without a path: {ds}"))?;
        let scale: Vec<f64> = ds["coordinateTransformations"]
            .as_array()
            .and_then(|t| t.iter().find(|t| t["type"] == "scale"))
            .and_then(|t| serde_json::from_value(t["scale"].clone()).ok())
            .with_context(|| format!("{source}: dataset '{path}' has no scale transformation"))?;
        ensure!(
            scale.len() == n,
            "{source}: dataset '{path}' has a scale of {} entries for {n} axes",
            scale.len()
        );
        let zyx = [scale[n - 3], scale[n - 2], scale[n - 1]];
        ensure!(
            zyx.iter().all(|s| s.is_finite() && *s > 0.0),
            "{source}: dataset '{path}' has a non-positive scale {zyx:?}"
        );
        level_paths.push(path.to_string());
        level_scales.push(zyx);
    }
    let omero = ome["omero"]["channels"]
        .as_array()
        .into_iter()
        .flatten()
        .map(|c| {
            let w = &c["window"];
            let pair = |a: &str, b: &str| Some([w[a].as_f64()?, w[b].as_f64()?]);
            let display = ChannelDisplay {
                color: c["color"].as_str().and_then(hex_colour),
                window: pair("start", "end"),
                range: pair("min", "max"),
                median: None,
            };
            (c["label"].as_str().map(str::to_string), display)
        })
        .collect();
    let regions = match attrs.get(REGIONS_KEY) {
        None | Some(Value::Null) => None,
        Some(r) => Some(
            serde_json::from_value::<RegionMetadata>(r.clone())
                .with_context(|| format!("{source}: malformed '{REGIONS_KEY}' region metadata"))?,
        ),
    };
    Ok(OmeGroup {
        format,
        axes: AxisLayout {
            names,
            channel_axis,
        },
        level_paths,
        level_scales,
        omero,
        regions,
    })
}

/// A `RRGGBB` hex colour (sRGB, as in `omero`) as linear RGB.
fn hex_colour(hex: &str) -> Option<[f64; 3]> {
    let hex = hex.trim_start_matches('#');
    if hex.len() != 6 || !hex.is_ascii() {
        return None;
    }
    let mut rgb = [0.0; 3];
    for (i, v) in rgb.iter_mut().enumerate() {
        let byte = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).ok()?;
        *v = srgb_to_linear(byte as f64 / 255.0);
    }
    Some(rgb)
}

/// The sRGB transfer function inverted: an sRGB-encoded value in `[0, 1]` as linear light.
pub fn srgb_to_linear(v: f64) -> f64 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Parses one level's array metadata (`zarr.json` or `.zarray`). `source` names the
/// document in errors.
pub fn parse_array(format: ZarrFormat, document: &[u8], source: &str) -> Result<ArrayDescription> {
    let meta: Value =
        serde_json::from_slice(document).with_context(|| format!("{source}: not valid JSON"))?;
    let shape: Vec<u64> = serde_json::from_value(meta["shape"].clone())
        .with_context(|| format!("{source}: no valid array shape"))?;
    let (type_name, chunk) = match format {
        ZarrFormat::V3 => {
            ensure!(
                meta["node_type"] == "array",
                "{source}: not a Zarr array (node_type {})",
                meta["node_type"]
            );
            let sharding = meta["codecs"]
                .as_array()
                .and_then(|c| c.iter().find(|c| c["name"] == "sharding_indexed"));
            let chunk = match sharding {
                Some(s) => s["configuration"]["chunk_shape"].clone(),
                None => meta["chunk_grid"]["configuration"]["chunk_shape"].clone(),
            };
            (
                meta["data_type"].as_str().unwrap_or_default().to_string(),
                chunk,
            )
        }
        ZarrFormat::V2 => {
            let d = meta["dtype"].as_str().unwrap_or_default();
            let name = match d.trim_start_matches(['<', '>', '|', '=']) {
                "u1" => "uint8",
                "u2" => "uint16",
                "i2" => "int16",
                "u4" => "uint32",
                "i4" => "int32",
                "f4" => "float32",
                _ => d,
            };
            (name.to_string(), meta["chunks"].clone())
        }
    };
    let sample_type = SampleType::from_zarr_name(&type_name)
        .with_context(|| format!("{source}: unsupported data type '{type_name}'"))?;
    let chunk: Vec<u64> =
        serde_json::from_value(chunk).with_context(|| format!("{source}: no valid chunk shape"))?;
    let n = shape.len();
    ensure!(
        n >= 3 && chunk.len() == n,
        "{source}: chunk shape {chunk:?} does not match array shape {shape:?}"
    );
    ensure!(
        chunk.iter().all(|&c| c > 0),
        "{source}: chunk shape {chunk:?} has a zero edge"
    );
    let fill_value = match &meta["fill_value"] {
        Value::Null => 0.0,
        Value::Number(v) => v.as_f64().unwrap_or(0.0),
        Value::String(s) => match s.as_str() {
            "NaN" => f64::NAN,
            "Infinity" => f64::INFINITY,
            "-Infinity" => f64::NEG_INFINITY,
            other => bail!("{source}: unsupported fill value '{other}'"),
        },
        other => bail!("{source}: unsupported fill value {other}"),
    };
    Ok(ArrayDescription {
        brick_shape: [chunk[n - 3], chunk[n - 2], chunk[n - 1]],
        leading_chunk: chunk[..n - 3].to_vec(),
        shape,
        sample_type,
        fill_value,
    })
}

/// The description of a volume named `name` from its group metadata and the array metadata of
/// each level (in `group.level_paths` order), with `minmax` left `None` for the source to fill.
/// Checks that the levels agree with each other and with the region metadata.
pub fn volume_info(
    name: &str,
    group: &OmeGroup,
    arrays: &[ArrayDescription],
    source: &str,
) -> Result<VolumeInfo> {
    ensure!(
        arrays.len() == group.level_paths.len(),
        "{source}: {} level arrays for {} datasets",
        arrays.len(),
        group.level_paths.len()
    );
    let n = group.axes.names.len();
    let first = &arrays[0];
    let mut channels = 1;
    let mut levels = Vec::new();
    for ((a, path), scale) in arrays
        .iter()
        .zip(&group.level_paths)
        .zip(&group.level_scales)
    {
        ensure!(
            a.shape.len() == n,
            "{source}: level '{path}' has {} dimensions for {n} axes",
            a.shape.len()
        );
        ensure!(
            a.sample_type == first.sample_type,
            "{source}: level '{path}' is {:?} but level '{}' is {:?}",
            a.sample_type,
            group.level_paths[0],
            first.sample_type
        );
        ensure!(
            a.brick_shape == first.brick_shape,
            "{source}: level '{path}' has bricks {:?} but level '{}' has {:?}",
            a.brick_shape,
            group.level_paths[0],
            first.brick_shape
        );
        for (i, axis) in group.axes.names[..n - 3].iter().enumerate() {
            ensure!(
                a.leading_chunk[i] == 1,
                "{source}: level '{path}' has chunks of {} along axis '{axis}'; one brick must \
                 hold one channel",
                a.leading_chunk[i]
            );
            if Some(i) == group.axes.channel_axis {
                channels = a.shape[i];
            } else {
                ensure!(
                    a.shape[i] == 1,
                    "{source}: axis '{axis}' has {} entries; only one is supported",
                    a.shape[i]
                );
            }
        }
        let base = group.level_scales[0];
        levels.push(LevelInfo {
            shape: [a.shape[n - 3], a.shape[n - 2], a.shape[n - 1]],
            factor: std::array::from_fn(|i| (scale[i] / base[i]).round().max(1.0) as u64),
        });
    }
    if let Some(r) = &group.regions {
        ensure!(
            r.brick_shape == first.brick_shape,
            "{source}: region metadata bricks {:?} differ from the arrays' {:?}",
            r.brick_shape,
            first.brick_shape
        );
        ensure!(
            r.levels.len() == levels.len(),
            "{source}: region metadata has {} levels, the image {}",
            r.levels.len(),
            levels.len()
        );
        for ((rl, l), path) in r.levels.iter().zip(&mut levels).zip(&group.level_paths) {
            ensure!(
                rl.image == *path && rl.shape == l.shape,
                "{source}: region metadata level '{}' {:?} does not match image level '{path}' {:?}",
                rl.image,
                rl.shape,
                l.shape
            );
            l.factor = rl.factor;
        }
    }
    let display = (0..channels as usize)
        .map(|c| {
            let mut d = group.omero.get(c).map(|o| o.1.clone()).unwrap_or_default();
            if let Some(s) = group.regions.as_ref().and_then(|r| r.channels.get(c)) {
                if let (Some(lo), Some(hi)) = (s.min, s.max) {
                    d.range = Some([lo, hi]);
                }
                d.median = s
                    .percentiles
                    .iter()
                    .find(|p| p.percent == 50.0)
                    .map(|p| p.value);
            }
            d
        })
        .collect();
    let labels = (0..channels as usize)
        .map(|c| {
            group
                .omero
                .get(c)
                .and_then(|o| o.0.clone())
                .or_else(|| {
                    group
                        .regions
                        .as_ref()
                        .and_then(|r| r.channels.get(c).map(|s| s.label.clone()))
                })
                .unwrap_or_else(|| format!("Channel {c}"))
        })
        .collect();
    Ok(VolumeInfo {
        name: name.to_string(),
        sample_type: first.sample_type,
        channels: labels,
        display,
        voxel_size: group.level_scales[0],
        brick_shape: first.brick_shape,
        levels,
        minmax: None,
    })
}

/// One channel's min/max grid from the region metadata's description and its values: `gz·gy·gx`
/// minima followed by as many maxima.
pub fn minmax_grid(
    cell_shape: [u64; 3],
    grid_shape: [u64; 3],
    values: &[f64],
    source: &str,
) -> Result<MinMaxGrid> {
    let cells = grid_shape.iter().product::<u64>() as usize;
    ensure!(
        values.len() == 2 * cells,
        "{source}: min/max grid {grid_shape:?} needs {} values, got {}",
        2 * cells,
        values.len()
    );
    Ok(MinMaxGrid {
        cell_shape,
        grid_shape,
        min: values[..cells].to_vec(),
        max: values[cells..].to_vec(),
    })
}

/// Whether a store's region metadata can drive culling, warning when it cannot: it must be
/// present, and its min/max cells haloed by at least one voxel, since the renderer relies on
/// a cell's range holding every voxel a trilinear sample inside the cell reads.
pub fn usable_region_metadata(regions: Option<&RegionMetadata>, source: &str) -> bool {
    match regions {
        None => {
            warn_no_region_metadata(source);
            false
        }
        Some(r) if r.halo == 0 => {
            tracing::warn!(
                "{source}: the region metadata's min/max cells have no halo, so they do not bound \
                 trilinear samples; culling falls back to computing min/max from bricks (run \
                 `ingest index` on the store to rewrite it)"
            );
            false
        }
        Some(_) => true,
    }
}

/// The warning a source logs for a store without region metadata.
pub fn warn_no_region_metadata(source: &str) {
    tracing::warn!(
        "{source}: no region metadata; culling falls back to computing min/max from bricks \
         (run `ingest index` on the store to add it)"
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    const GROUP_V2: &str = r#"{
        "multiscales": [{"version": "0.4", "axes": [
            {"name": "c", "type": "channel"}, {"name": "z", "type": "space"},
            {"name": "y", "type": "space"}, {"name": "x", "type": "space"}],
          "datasets": [
            {"path": "0", "coordinateTransformations": [{"type": "scale", "scale": [1, 2.0, 0.5, 0.5]}]},
            {"path": "1", "coordinateTransformations": [{"type": "scale", "scale": [1, 2.0, 1.0, 1.0]},
                                                        {"type": "translation", "translation": [0, 0, 0.25, 0.25]}]}]}],
        "omero": {"channels": [{"label": "dapi", "color": "FF8000",
                                "window": {"min": 0, "max": 100, "start": 5, "end": 90}}]}
    }"#;

    fn array_v2(shape: [u64; 4]) -> String {
        format!(
            r#"{{"zarr_format": 2, "shape": {shape:?}, "chunks": [1, 8, 8, 8], "dtype": "<u2",
                "fill_value": 0, "order": "C", "compressor": null, "filters": null}}"#
        )
    }

    #[test]
    fn v2_group_and_arrays_give_the_volume() {
        let g = parse_group(ZarrFormat::V2, GROUP_V2.as_bytes(), "s/.zattrs").unwrap();
        assert_eq!(g.axes.channel_axis, Some(0));
        assert_eq!(g.level_paths, ["0", "1"]);
        assert_eq!(g.level_scales, [[2.0, 0.5, 0.5], [2.0, 1.0, 1.0]]);
        assert_eq!(g.regions, None);
        let a0 = parse_array(ZarrFormat::V2, array_v2([2, 10, 20, 20]).as_bytes(), "a0").unwrap();
        let a1 = parse_array(ZarrFormat::V2, array_v2([2, 10, 10, 10]).as_bytes(), "a1").unwrap();
        assert_eq!(a0.sample_type, SampleType::U16);
        assert_eq!(a0.brick_shape, [8, 8, 8]);
        let info = volume_info("vol", &g, &[a0, a1], "s").unwrap();
        assert_eq!(info.channels, ["dapi", "Channel 1"]);
        assert_eq!(info.voxel_size, [2.0, 0.5, 0.5]);
        assert_eq!(
            info.levels,
            [
                LevelInfo {
                    shape: [10, 20, 20],
                    factor: [1, 1, 1]
                },
                LevelInfo {
                    shape: [10, 10, 10],
                    factor: [1, 2, 2]
                }
            ]
        );
        let orange = info.display[0].color.unwrap();
        assert_eq!(orange[0], 1.0);
        assert!((orange[1] - srgb_to_linear(128.0 / 255.0)).abs() < 1e-15);
        assert_eq!(orange[2], 0.0);
        assert_eq!(info.display[0].window, Some([5.0, 90.0]));
        assert_eq!(info.display[0].range, Some([0.0, 100.0]));
        assert_eq!(info.display[1], ChannelDisplay::default());
        assert_eq!(
            AxisLayout::chunk_indices(&g.axes, 1, [2, 3, 4]),
            [1, 2, 3, 4]
        );
    }

    #[test]
    fn bad_metadata_gives_errors_naming_the_document() {
        let e = parse_group(ZarrFormat::V2, b"{}", "http://h/d/.zattrs").unwrap_err();
        assert_eq!(
            e.to_string(),
            "http://h/d/.zattrs: no OME-Zarr multiscales metadata"
        );
        let e = parse_group(ZarrFormat::V3, b"{", "d/zarr.json").unwrap_err();
        assert_eq!(e.to_string(), "d/zarr.json: not valid JSON");
        let bad_axes = GROUP_V2.replace(r#""name": "x""#, r#""name": "w""#);
        let e = parse_group(ZarrFormat::V2, bad_axes.as_bytes(), "g").unwrap_err();
        assert_eq!(
            e.to_string(),
            r#"g: axes ["c", "z", "y", "w"] do not end in z, y, x"#
        );
        let f8 = array_v2([1, 8, 8, 8]).replace("<u2", "<f8");
        let e = parse_array(ZarrFormat::V2, f8.as_bytes(), "a").unwrap_err();
        assert_eq!(e.to_string(), "a: unsupported data type '<f8'");
        let g = parse_group(ZarrFormat::V2, GROUP_V2.as_bytes(), "g").unwrap();
        let a0 = parse_array(ZarrFormat::V2, array_v2([2, 10, 20, 20]).as_bytes(), "a0").unwrap();
        let mut a1 = a0.clone();
        a1.sample_type = SampleType::F32;
        let e = volume_info("v", &g, &[a0, a1], "g").unwrap_err();
        assert_eq!(e.to_string(), "g: level '1' is F32 but level '0' is U16");
    }

    #[test]
    fn minmax_values_split_into_min_then_max() {
        let g = minmax_grid([8; 3], [1, 1, 2], &[1.0, 2.0, 3.0, 4.0], "m").unwrap();
        assert_eq!((g.min, g.max), (vec![1.0, 2.0], vec![3.0, 4.0]));
        let e = minmax_grid([8; 3], [1, 1, 2], &[1.0], "m").unwrap_err();
        assert_eq!(
            e.to_string(),
            "m: min/max grid [1, 1, 2] needs 4 values, got 1"
        );
    }
}
