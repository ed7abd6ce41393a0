//! [`VolumeInfo::from_ome`]: a volume's description from the OME-Zarr format model, the image
//! group's attributes ([`ImageAttributes`]: `multiscales`, `omero`, region metadata) and each
//! level's array metadata ([`ArrayDescription`]), whatever the transport; and
//! [`MinMaxGrid::from_values`], one min/max grid of the region metadata from its values.

use crate::ome::{ImageAttributes, OmeroChannel, PyramidLayout};
use crate::zarr::ArrayDescription;

use super::{ChannelDisplay, LevelInfo, MinMaxGrid, VolumeError, VolumeInfo};

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
fn srgb_to_linear(v: f64) -> f64 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

impl VolumeInfo {
    /// The description of a volume named `name` from its group attributes, its pyramid layout
    /// and the array metadata of each level (in `layout.level_paths` order), with `minmax` left
    /// `None` for the source to fill. Checks that the levels agree with each other and with the
    /// region metadata, and that every leading axis but `c` has one entry.
    ///
    /// # Errors
    /// A [`VolumeError`] whose message starts with `source` and names the first disagreement.
    pub fn from_ome(
        name: &str,
        attributes: &ImageAttributes,
        layout: &PyramidLayout,
        arrays: &[ArrayDescription],
        source: &str,
    ) -> Result<VolumeInfo, VolumeError> {
        if arrays.len() != layout.level_paths.len() {
            return Err(VolumeError::LevelCount {
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
                return Err(VolumeError::LevelRank {
                    store: source.to_string(),
                    level: path.clone(),
                    dimensions: a.shape.len(),
                    axes: n,
                });
            }
            if a.sample_type != first.sample_type {
                return Err(VolumeError::LevelType {
                    store: source.to_string(),
                    level: path.clone(),
                    sample_type: a.sample_type,
                    first: layout.level_paths[0].clone(),
                    first_type: first.sample_type,
                });
            }
            if a.brick_shape() != first.brick_shape() {
                return Err(VolumeError::LevelBricks {
                    store: source.to_string(),
                    level: path.as_str().into(),
                    brick: a.brick_shape(),
                    first: layout.level_paths[0].as_str().into(),
                    first_brick: first.brick_shape(),
                });
            }
            for (i, axis) in layout.axis_names[..n - 3].iter().enumerate() {
                if a.leading_chunk()[i] != 1 {
                    return Err(VolumeError::LeadingChunk {
                        store: source.to_string(),
                        level: path.clone(),
                        chunk: a.leading_chunk()[i],
                        axis: axis.clone(),
                    });
                }
                if Some(i) == layout.channel_axis {
                    channels = a.shape[i];
                } else if a.shape[i] != 1 {
                    return Err(VolumeError::LeadingAxis {
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
                return Err(VolumeError::RegionBricks {
                    store: source.to_string(),
                    regions: r.brick_shape,
                    arrays: first.brick_shape(),
                });
            }
            if r.levels.len() != levels.len() {
                return Err(VolumeError::RegionLevelCount {
                    store: source.to_string(),
                    regions: r.levels.len(),
                    levels: levels.len(),
                });
            }
            for ((rl, l), path) in r.levels.iter().zip(&mut levels).zip(&layout.level_paths) {
                if rl.image != *path || rl.shape != l.shape {
                    return Err(VolumeError::RegionLevel {
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
        let omero: &[OmeroChannel] = attributes
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
}

/// The display hints of one `omero` channel: its colour, and its window's `start`/`end` and
/// `min`/`max` where both of a pair are given.
fn channel_display(c: &OmeroChannel) -> ChannelDisplay {
    let w = c.window.clone().unwrap_or_default();
    let pair = |a: Option<f64>, b: Option<f64>| Some([a?, b?]);
    ChannelDisplay {
        color: c.color.as_deref().and_then(hex_colour),
        window: pair(w.start, w.end),
        range: pair(w.min, w.max),
        median: None,
    }
}

impl MinMaxGrid {
    /// One channel's min/max grid from the region metadata's description and its values:
    /// `gz·gy·gx` minima followed by as many maxima.
    ///
    /// # Errors
    /// [`VolumeError::MinMaxValues`], naming `source`, when `values` are not two per cell.
    pub fn from_values(
        cell_shape: [u64; 3],
        grid_shape: [u64; 3],
        values: &[f64],
        source: &str,
    ) -> Result<MinMaxGrid, VolumeError> {
        let cells = grid_shape.iter().product::<u64>() as usize;
        if values.len() != 2 * cells {
            return Err(VolumeError::MinMaxValues {
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
}

#[cfg(test)]
mod tests {
    use crate::SampleType;
    use crate::ome::ZarrFormat;
    use crate::ome::tests::GROUP_V2;

    use super::*;

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
        let info = VolumeInfo::from_ome("vol", &g, &layout, &arrays, "s").unwrap();
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
        let e = VolumeInfo::from_ome("v", &g, &layout, &[a0.clone(), a1], "g").unwrap_err();
        assert_eq!(
            e.to_string(),
            "g: level '1' is float32 but level '0' is uint16"
        );
        let mut t = a0.clone();
        t.chunk[0] = 2;
        let e = VolumeInfo::from_ome("v", &g, &layout, &[t, a0], "g").unwrap_err();
        assert_eq!(
            e.to_string(),
            "g: level '0' has chunks of 2 along axis 'c'; one brick must hold one channel"
        );
    }

    #[test]
    fn minmax_values_split_into_min_then_max() {
        let g = MinMaxGrid::from_values([8; 3], [1, 1, 2], &[1.0, 2.0, 3.0, 4.0], "m").unwrap();
        assert_eq!((g.min, g.max), (vec![1.0, 2.0], vec![3.0, 4.0]));
        let e = MinMaxGrid::from_values([8; 3], [1, 1, 2], &[1.0], "m").unwrap_err();
        assert_eq!(
            e.to_string(),
            "m: min/max grid [1, 1, 2] needs 4 values, got 1"
        );
    }
}
