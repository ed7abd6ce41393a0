//! OME-Zarr image metadata: `multiscales` (axes, scale and translation per level) and `omero`
//! (channel labels, colours and display windows).

use serde_json::{Value, json};

use crate::pyramid::LevelPlan;
use crate::store::OmeZarrVersion;

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

/// The `multiscales` entry for `levels`. Each level's translation places its voxel centres
/// at the centre of the level-0 voxels they average.
pub fn multiscale(
    version: OmeZarrVersion,
    name: &str,
    levels: &[LevelPlan],
    unit: Option<&str>,
) -> Value {
    let space = |axis: &str| match unit {
        Some(u) => json!({"name": axis, "type": "space", "unit": u}),
        None => json!({"name": axis, "type": "space"}),
    };
    let base = levels[0].voxel_size;
    let datasets: Vec<Value> = levels
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let scale = [1.0, l.voxel_size[0], l.voxel_size[1], l.voxel_size[2]];
            let shift: [f64; 3] =
                std::array::from_fn(|a| (l.factor[a] as f64 - 1.0) / 2.0 * base[a]);
            let mut transforms = vec![json!({"type": "scale", "scale": scale})];
            if shift.iter().any(|&s| s != 0.0) {
                transforms.push(json!({"type": "translation", "translation": [0.0, shift[0], shift[1], shift[2]]}));
            }
            json!({"path": i.to_string(), "coordinateTransformations": transforms})
        })
        .collect();
    let mut m = json!({
        "name": name,
        "axes": [{"name": "c", "type": "channel"}, space("z"), space("y"), space("x")],
        "datasets": datasets,
        "type": "mean",
        "metadata": {
            "description": "mean of the level-0 voxels each voxel covers, from exact sums, rounded once",
            "method": "residency-ingest",
            "version": env!("CARGO_PKG_VERSION"),
        },
    });
    if version == OmeZarrVersion::V04 {
        m["version"] = json!("0.4");
    }
    m
}

/// The `omero` block for `channels`.
pub fn omero(channels: &[ChannelDisplay], depth: u64) -> Value {
    let channels: Vec<Value> = channels
        .iter()
        .enumerate()
        .map(|(i, c)| {
            json!({
                "label": c.label,
                "color": CHANNEL_COLOURS[i % CHANNEL_COLOURS.len()],
                "window": {"min": c.min, "max": c.max, "start": c.start, "end": c.end},
                "active": true,
                "coefficient": 1.0,
                "family": "linear",
                "inverted": false,
            })
        })
        .collect();
    json!({
        "channels": channels,
        "rdefs": {"model": "color", "defaultZ": depth / 2, "defaultT": 0},
    })
}

/// The image group's attributes: OME metadata plus any extra top-level keys.
pub fn image_attributes(
    version: OmeZarrVersion,
    multiscale: Value,
    omero: Value,
    extra: Vec<(&str, Value)>,
) -> Value {
    let mut attrs = match version {
        OmeZarrVersion::V04 => json!({"multiscales": [multiscale], "omero": omero}),
        OmeZarrVersion::V05 => {
            json!({"ome": {"version": "0.5", "multiscales": [multiscale], "omero": omero}})
        }
    };
    for (k, v) in extra {
        attrs[k] = v;
    }
    attrs
}
