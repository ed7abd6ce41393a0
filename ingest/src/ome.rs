//! The OME-Zarr image metadata `ingest` writes: `multiscales` (axes, scale and translation per
//! level) and `omero` (channel labels, colours and display windows), as the typed model of
//! `residency_schemas::ome`.

use residency_schemas::RegionMetadata;
use residency_schemas::ome::{
    Axis, CoordinateTransformation, Dataset, DownsamplingMethod, ImageAttributes, Multiscale,
    OmeZarrVersion, Omero, OmeroChannel, OmeroRenderingDefaults, OmeroWindow,
};

use crate::pyramid::LevelPlan;

/// Default channel colours (hex RGB), cycled.
pub const CHANNEL_COLOURS: [&str; 7] = [
    "00FFFF", "FF00FF", "FFFF00", "00FF00", "FF0000", "0000FF", "FFFFFF",
];

/// Display settings of one channel.
#[derive(Clone, Debug, PartialEq)]
pub struct ChannelDisplay {
    /// Label.
    pub label: String,
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
    /// Window start (a low robust percentile).
    pub start: f64,
    /// Window end (a high robust percentile).
    pub end: f64,
}

/// The multiscale entry for `levels`. Each level's translation places its voxel centres at the
/// centre of the level-0 voxels they average.
#[must_use]
pub fn multiscale(
    version: OmeZarrVersion,
    name: &str,
    levels: &[LevelPlan],
    unit: Option<&str>,
) -> Multiscale {
    let space = |axis: &str| Axis {
        name: axis.to_string(),
        kind: Some("space".into()),
        unit: unit.map(str::to_string),
    };
    let base = levels[0].voxel_size;
    let datasets = levels
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let scale = vec![1.0, l.voxel_size[0], l.voxel_size[1], l.voxel_size[2]];
            let shift: [f64; 3] =
                std::array::from_fn(|a| (l.factor[a] as f64 - 1.0) / 2.0 * base[a]);
            let mut transforms = vec![CoordinateTransformation::Scale { scale }];
            if shift.iter().any(|&s| s != 0.0) {
                transforms.push(CoordinateTransformation::Translation {
                    translation: vec![0.0, shift[0], shift[1], shift[2]],
                });
            }
            Dataset {
                path: i.to_string(),
                coordinate_transformations: transforms,
            }
        })
        .collect();
    Multiscale {
        name: Some(name.to_string()),
        axes: vec![
            Axis {
                name: "c".into(),
                kind: Some("channel".into()),
                unit: None,
            },
            space("z"),
            space("y"),
            space("x"),
        ],
        datasets,
        kind: Some("mean".into()),
        metadata: Some(DownsamplingMethod {
            description: Some(
                "mean of the level-0 voxels each voxel covers, from exact sums, rounded once"
                    .into(),
            ),
            method: Some("residency-ingest".into()),
            version: Some(env!("CARGO_PKG_VERSION").into()),
        }),
        version: (version == OmeZarrVersion::V04).then(|| "0.4".into()),
    }
}

/// The `omero` block for `channels` of a volume `depth` planes deep.
#[must_use]
pub fn omero(channels: &[ChannelDisplay], depth: u64) -> Omero {
    Omero {
        channels: channels
            .iter()
            .enumerate()
            .map(|(i, c)| OmeroChannel {
                label: Some(c.label.clone()),
                color: Some(CHANNEL_COLOURS[i % CHANNEL_COLOURS.len()].into()),
                window: Some(OmeroWindow {
                    min: Some(c.min),
                    max: Some(c.max),
                    start: Some(c.start),
                    end: Some(c.end),
                }),
                active: Some(true),
                coefficient: Some(1.0),
                family: Some("linear".into()),
                inverted: Some(false),
            })
            .collect(),
        rdefs: Some(OmeroRenderingDefaults {
            model: "color".into(),
            default_z: depth / 2,
            default_t: 0,
        }),
    }
}

/// The image group's attributes: one multiscale, its `omero` block and the region metadata.
#[must_use]
pub fn image_attributes(
    version: OmeZarrVersion,
    multiscale: Multiscale,
    omero: Omero,
    regions: RegionMetadata,
) -> ImageAttributes {
    ImageAttributes {
        version,
        multiscales: vec![multiscale],
        omero: Some(omero),
        regions: Some(regions),
    }
}
