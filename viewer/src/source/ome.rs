//! The viewer's description of a volume ([`VolumeInfo`]) from the format model of
//! `residency_schemas`: the image group's attributes ([`ImageAttributes`]: `multiscales`,
//! `omero`, region metadata) and each level's array metadata ([`ArrayDescription`]), whatever
//! the transport.

use residency_schemas::RegionMetadata;
use residency_schemas::ome::{ImageAttributes, PyramidLayout};
use residency_schemas::zarr::ArrayDescription;

use super::{ChannelDisplay, LevelInfo, MinMaxGrid, SourceError, VolumeInfo};

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

/// The description of a volume named `name` from its group attributes, its pyramid layout and
/// the array metadata of each level (in `layout.level_paths` order), with `minmax` left `None`
/// for the source to fill. Checks that the levels agree with each other and with the region
/// metadata, and that every leading axis but `c` has one entry.
///
/// # Errors
/// A [`SourceError`] whose message starts with `source` and names the first disagreement.
pub fn volume_info(
    name: &str,
    attributes: &ImageAttributes,
    layout: &PyramidLayout,
    arrays: &[ArrayDescription],
    source: &str,
) -> Result<VolumeInfo, SourceError> {
    if arrays.len() != layout.level_paths.len() {
        return Err(SourceError::LevelCount {
            store: source.to_string(),
            arrays: arrays.len(),
            datasets: layout.level_paths.len(),
        });
    }
    let n = layout.axis_names.len();
    let first = &arrays[0];
    let mut channels = 1;
    let mut levels = Vec::new();
    for ((a, path), scale) in arrays
        .iter()
        .zip(&layout.level_paths)
        .zip(&layout.level_scales)
    {
        if a.shape.len() != n {
            return Err(SourceError::LevelRank {
                store: source.to_string(),
                level: path.clone(),
                dimensions: a.shape.len(),
                axes: n,
            });
        }
        if a.sample_type != first.sample_type {
            return Err(SourceError::LevelType {
                store: source.to_string(),
                level: path.clone(),
                sample_type: a.sample_type,
                first: layout.level_paths[0].clone(),
                first_type: first.sample_type,
            });
        }
        if a.brick_shape() != first.brick_shape() {
            return Err(SourceError::LevelBricks {
                store: source.to_string(),
                level: path.as_str().into(),
                brick: a.brick_shape(),
                first: layout.level_paths[0].as_str().into(),
                first_brick: first.brick_shape(),
            });
        }
        for (i, axis) in layout.axis_names[..n - 3].iter().enumerate() {
            if a.leading_chunk()[i] != 1 {
                return Err(SourceError::LeadingChunk {
                    store: source.to_string(),
                    level: path.clone(),
                    chunk: a.leading_chunk()[i],
                    axis: axis.clone(),
                });
            }
            if Some(i) == layout.channel_axis {
                channels = a.shape[i];
            } else if a.shape[i] != 1 {
                return Err(SourceError::LeadingAxis {
                    store: source.to_string(),
                    axis: axis.clone(),
                    entries: a.shape[i],
                });
            }
        }
        let base = layout.level_scales[0];
        levels.push(LevelInfo {
            shape: a.zyx_shape(),
            factor: std::array::from_fn(|i| (scale[i] / base[i]).round().max(1.0) as u64),
        });
    }
    let regions = attributes.regions.as_ref();
    if let Some(r) = regions {
        if r.brick_shape != first.brick_shape() {
            return Err(SourceError::RegionBricks {
                store: source.to_string(),
                regions: r.brick_shape,
                arrays: first.brick_shape(),
            });
        }
        if r.levels.len() != levels.len() {
            return Err(SourceError::RegionLevelCount {
                store: source.to_string(),
                regions: r.levels.len(),
                levels: levels.len(),
            });
        }
        for ((rl, l), path) in r.levels.iter().zip(&mut levels).zip(&layout.level_paths) {
            if rl.image != *path || rl.shape != l.shape {
                return Err(SourceError::RegionLevel {
                    store: source.to_string(),
                    region_level: rl.image.as_str().into(),
                    region_shape: rl.shape,
                    level: path.as_str().into(),
                    shape: l.shape,
                });
            }
            l.factor = rl.factor;
        }
    }
    let omero: &[residency_schemas::ome::OmeroChannel] = attributes
        .omero
        .as_ref()
        .map_or(&[], |o| o.channels.as_slice());
    let display = (0..channels as usize)
        .map(|c| {
            let mut d = omero.get(c).map(channel_display).unwrap_or_default();
            if let Some(s) = regions.and_then(|r| r.channels.get(c)) {
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
            omero
                .get(c)
                .and_then(|o| o.label.clone())
                .or_else(|| regions.and_then(|r| r.channels.get(c).map(|s| s.label.clone())))
                .unwrap_or_else(|| format!("Channel {c}"))
        })
        .collect();
    Ok(VolumeInfo {
        name: name.to_string(),
        sample_type: first.sample_type,
        channels: labels,
        display,
        voxel_size: layout.level_scales[0],
        unit: layout.unit.clone(),
        brick_shape: first.brick_shape(),
        levels,
        minmax: None,
    })
}

/// The display hints of one `omero` channel: its colour, and its window's `start`/`end` and
/// `min`/`max` where both of a pair are given.
fn channel_display(c: &residency_schemas::ome::OmeroChannel) -> ChannelDisplay {
    let w = c.window.clone().unwrap_or_default();
    let pair = |a: Option<f64>, b: Option<f64>| Some([a?, b?]);
    ChannelDisplay {
        color: c.color.as_deref().and_then(hex_colour),
        window: pair(w.start, w.end),
        range: pair(w.min, w.max),
        median: None,
    }
}

/// One channel's min/max grid from the region metadata's description and its values: `gz·gy·gx`
/// minima followed by as many maxima.
///
/// # Errors
/// [`SourceError::MinMaxValues`], naming `source`, when `values` are not two per cell.
pub fn minmax_grid(
    cell_shape: [u64; 3],
    grid_shape: [u64; 3],
    values: &[f64],
    source: &str,
) -> Result<MinMaxGrid, SourceError> {
    let cells = grid_shape.iter().product::<u64>() as usize;
    if values.len() != 2 * cells {
        return Err(SourceError::MinMaxValues {
            store: source.to_string(),
            grid_shape,
            needed: 2 * cells,
            got: values.len(),
        });
    }
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
    use residency_schemas::SampleType;
    use residency_schemas::ome::ZarrFormat;

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

    fn array_v2(shape: [u64; 4]) -> ArrayDescription {
        let doc = format!(
            r#"{{"zarr_format": 2, "shape": {shape:?}, "chunks": [1, 8, 8, 8], "dtype": "<u2",
                "fill_value": 0, "order": "C", "compressor": null, "filters": null}}"#
        );
        ArrayDescription::parse(ZarrFormat::V2, doc.as_bytes(), "a").unwrap()
    }

    fn group() -> (ImageAttributes, PyramidLayout) {
        let a = ImageAttributes::parse(ZarrFormat::V2, GROUP_V2.as_bytes(), "s/.zattrs").unwrap();
        let layout = PyramidLayout::of(a.image(), "s/.zattrs").unwrap();
        (a, layout)
    }

    #[test]
    fn v2_group_and_arrays_give_the_volume() {
        let (g, layout) = group();
        let arrays = [array_v2([2, 10, 20, 20]), array_v2([2, 10, 10, 10])];
        let info = volume_info("vol", &g, &layout, &arrays, "s").unwrap();
        assert_eq!(info.sample_type, SampleType::U16);
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
    }

    #[test]
    fn disagreeing_levels_give_errors_naming_the_store() {
        let (g, layout) = group();
        let a0 = array_v2([2, 10, 20, 20]);
        let mut a1 = a0.clone();
        a1.sample_type = SampleType::F32;
        let e = volume_info("v", &g, &layout, &[a0.clone(), a1], "g").unwrap_err();
        assert_eq!(
            e.to_string(),
            "g: level '1' is float32 but level '0' is uint16"
        );
        let mut t = a0.clone();
        t.chunk[0] = 2;
        let e = volume_info("v", &g, &layout, &[t, a0], "g").unwrap_err();
        assert_eq!(
            e.to_string(),
            "g: level '0' has chunks of 2 along axis 'c'; one brick must hold one channel"
        );
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
