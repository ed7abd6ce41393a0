//! The format model every Residency crate shares, with no I/O: serde types for the JSON
//! documents Residency writes, serves or reads, the binary formats beside them, and the
//! descriptions the programs make of them.
//!
//! Each document type here is described by a JSON Schema in `schemas/json/`, generated from
//! the type by `schemars` ([`generate`]); the tests check that documents produced by the real
//! binaries validate against those schemas.
//!
//! The central document is [`RegionMetadata`], stored by `ingest` in the attributes of the
//! OME-Zarr image group under the key [`REGIONS_KEY`]. It describes the min/max grids and
//! the per-brick histograms that `ingest` writes as ordinary Zarr arrays inside the group.
//! [`server`] holds the JSON answers of `brickserver`'s API, and [`wire`] its binary
//! documents (the min/max hierarchy and brick batches). [`vdi`] is the file format of volumetric
//! depth images (a JSON header and compressed planes), which the viewer generates and renders.
//! [`scene`] is the scene file the viewer reads: the camera, each channel's transfer function
//! and the compositing rule that every renderer of ours follows; [`names`] the enums named on
//! command lines and in files, with the one error for an unknown name. [`volume`] is a
//! volume as a renderer sees it before fetching a brick, made from a store's OME-Zarr metadata.

pub mod dataset;
pub mod error_chain;
pub mod float;
pub mod generate;
pub mod names;
pub mod ome;
pub mod sample_kind;
pub mod sample_type;
pub mod scene;
pub mod server;
pub mod vdi;
pub mod volume;
pub mod wire;
pub mod zarr;

pub use error_chain::error_chain;
pub use sample_kind::SampleKind;
pub use sample_type::SampleType;
/// `strum`, for [`strum_names!`]'s expansion in other crates.
#[doc(hidden)]
pub use strum;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Attribute key of the region metadata in the image group's attributes.
pub const REGIONS_KEY: &str = "residency";

/// Version of the region-metadata layout described by [`RegionMetadata`].
pub const REGIONS_VERSION: &str = "0.2";

/// Number of histogram bins per brick and channel.
pub const HISTOGRAM_BINS: usize = 64;

/// Region metadata: where the min/max grids and histograms of every pyramid level live,
/// and how to read them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(
    title = "Residency region metadata",
    description = "Stored by `ingest` under the `residency` key of the OME-Zarr image group's \
        attributes. Describes the conservative min/max grids and per-brick histograms written as \
        Zarr arrays under the group's `residency/` subgroup."
)]
#[schemars(deny_unknown_fields)]
pub struct RegionMetadata {
    /// Layout version, [`REGIONS_VERSION`] (stores of layout `0.1` are still read).
    #[schemars(extend("enum" = ["0.1", REGIONS_VERSION]))]
    pub version: String,
    /// Path of the group, relative to the image group, holding the metadata arrays.
    pub path: String,
    /// Edge of a min/max cell in voxels of its own level, `z, y, x`.
    pub cell_shape: [u64; 3],
    /// Voxels added on every side of a cell when computing its min/max, so that any
    /// trilinear sample whose position lies inside the cell reads only voxels the range covers.
    pub halo: u64,
    /// Brick (inner chunk) shape of the image arrays, `z, y, x`.
    pub brick_shape: [u64; 3],
    /// Number of histogram bins per brick and channel.
    #[schemars(range(min = 1))]
    pub histogram_bins: usize,
    /// One entry per pyramid level, finest first.
    #[schemars(length(min = 1))]
    pub levels: Vec<RegionLevel>,
    /// One entry per channel, in channel order.
    #[schemars(length(min = 1))]
    pub channels: Vec<ChannelStatistics>,
}

/// Region metadata of one pyramid level.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct RegionLevel {
    /// Path of the image array of this level (as in `multiscales.datasets[].path`).
    pub image: String,
    /// Shape of this level, `z, y, x`.
    pub shape: [u64; 3],
    /// Downsampling factor of this level relative to level 0, `z, y, x`.
    pub factor: [u64; 3],
    /// Min/max grids, finest first. Grid `k` has cells of `cell_shape * 2^k` voxels of this
    /// level; each coarser grid is the min of mins and max of maxes of the finer one.
    #[schemars(length(min = 1))]
    pub minmax: Vec<MinMaxGrid>,
    /// Exact min/max grids, finest first, over the same cells as `minmax` but without the
    /// halo: each cell's range is that of its own voxels, so region queries over boxes
    /// aligned to the cells are exact. Absent (empty) in layout `0.1`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub range: Vec<MinMaxGrid>,
    /// Path of the `uint32` histogram array, shape `[c, bz, by, bx, bins]`.
    pub histogram: String,
    /// Bricks written for this level (all channels).
    pub bricks_written: u64,
    /// Bricks equal to the fill value everywhere, so not written.
    pub bricks_empty: u64,
}

/// One min/max grid: a Zarr array of shape `[c, 2, gz, gy, gx]` in the image's data type.
/// Index 0 of the second axis is the minimum, index 1 the maximum. For floating-point data,
/// NaN voxels are excluded, and a cell whose voxels are all NaN holds NaN.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct MinMaxGrid {
    /// Path of the array, relative to the image group.
    pub path: String,
    /// Edge of one cell in voxels of the level, `z, y, x`.
    pub cell_shape: [u64; 3],
    /// Number of cells, `z, y, x`.
    pub grid_shape: [u64; 3],
}

/// Whole-channel statistics over level 0.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct ChannelStatistics {
    /// Channel label, as in `omero.channels[].label`.
    pub label: String,
    /// Smallest value (NaN excluded). `null` when every voxel is NaN; an infinity is written
    /// as a string (see [`float`]).
    #[serde(with = "float::option")]
    #[schemars(schema_with = "float::option::json_schema")]
    pub min: Option<f64>,
    /// Largest value (NaN excluded). `null` when every voxel is NaN; an infinity is written
    /// as a string (see [`float`]).
    #[serde(with = "float::option")]
    #[schemars(schema_with = "float::option::json_schema")]
    pub max: Option<f64>,
    /// Mean of the non-NaN voxels. `null` when every voxel is NaN. With infinities it is
    /// `"Infinity"` or `"-Infinity"` (one sign present) or `"NaN"` (both present).
    #[serde(with = "float::option")]
    #[schemars(schema_with = "float::option::json_schema")]
    pub mean: Option<f64>,
    /// Number of voxels in the channel.
    pub voxels: u64,
    /// Number of NaN voxels (always 0 for integer data).
    pub nan_voxels: u64,
    /// Robust percentiles: the value below which the given fraction of non-NaN voxels lie.
    pub percentiles: Vec<Percentile>,
    /// Histogram bin edges shared by every brick of this channel, at every level: at most
    /// `histogram_bins + 1` ascending values. Bin `i` counts the voxels `v` with
    /// `edges[i] <= v < edges[i + 1]` (NaN is never counted; `+inf`, whose bin's upper edge
    /// is `+inf` itself, is counted in that bin). The edges cover the channel's whole range;
    /// bins past the last edge hold zero. Infinite edges are written as JSON `null`.
    #[serde(deserialize_with = "server::edges_with_infinities")]
    #[schemars(with = "Vec<Option<f64>>", length(min = 2))]
    pub histogram_edges: Vec<f64>,
}

/// A percentile of a channel's values.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct Percentile {
    /// Percent, in `[0, 100]`.
    #[schemars(range(min = 0, max = 100))]
    pub percent: f64,
    /// Value at that percentile (an infinity is written as a string, see [`float`]).
    #[serde(with = "float")]
    #[schemars(schema_with = "float::json_schema")]
    pub value: f64,
}
