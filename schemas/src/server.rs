//! The JSON answers of `brickserver`'s own API (the Zarr keys it serves are the store's own
//! documents). Each type is described by a JSON Schema in `schemas/json/`.

use schemars::JsonSchema;
use serde::{Deserialize, Deserializer, Serialize};

/// `GET /datasets` (and `GET /` but for a browser): the served datasets.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(
    title = "Served datasets",
    description = "`GET /datasets` of brickserver (and `GET /` but for a browser): the datasets \
        it serves, with links that open each in the Residency web viewer, neuroglancer and \
        vizarr."
)]
#[schemars(deny_unknown_fields)]
pub struct DatasetList {
    /// One entry per dataset, in the order given on the command line.
    pub datasets: Vec<DatasetEntry>,
}

/// One served dataset.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct DatasetEntry {
    /// URL name: the store is served under `/NAME/`.
    #[schemars(regex(pattern = r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$"))]
    pub name: String,
    /// URL of the store's root.
    pub url: String,
    /// Link opening the dataset in the Residency web viewer (`{base}/NAME/view`).
    pub view: String,
    /// Link opening the store in neuroglancer, with each channel's display range and colour.
    pub neuroglancer: String,
    /// Link opening the store in vizarr.
    pub vizarr: String,
}

/// An axis-aligned box of voxels of one level, `x, y, z` order, `max` exclusive.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct VoxelBox {
    /// First voxel, `x, y, z`.
    pub min: [u64; 3],
    /// One past the last voxel, `x, y, z`.
    pub max: [u64; 3],
}

/// `GET /NAME/regions?level=L&channel=C&min=x,y,z&max=x,y,z`: the range and histogram of a
/// box, answered from the stored region metadata.
///
/// Contract: the answer covers the smallest union of stored cells (for `min`/`max`) and of
/// bricks (for `histogram`) that contains the box, reported in `minmax_box` and
/// `histogram.box`. It is never narrower than the truth, and exact (`*_exact: true`) when the
/// box is aligned to that granularity (or ends at the level's edge).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(
    title = "Region query answer",
    description = "`GET /NAME/regions?level=L&channel=C&min=x,y,z&max=x,y,z` of brickserver: the \
        value range and histogram of a box of voxels of one level, answered from the stored \
        region metadata without decoding bricks. The answer covers the smallest union of stored \
        cells (min/max) and bricks (histogram) containing the box: never narrower than the \
        truth, and exact when the box is aligned to that granularity or ends at the level's \
        edge."
)]
#[schemars(deny_unknown_fields)]
pub struct RegionAnswer {
    /// Dataset name.
    pub dataset: String,
    /// Pyramid level.
    pub level: usize,
    /// Channel.
    pub channel: usize,
    /// The box asked for.
    #[serde(rename = "box")]
    pub query: VoxelBox,
    /// Smallest non-NaN value in `minmax_box`; `null` when there is none. An infinity is
    /// written as `"Infinity"` or `"-Infinity"` (see [`crate::float`]).
    #[serde(with = "crate::float::option")]
    #[schemars(schema_with = "crate::float::option::json_schema")]
    pub min: Option<f64>,
    /// Largest non-NaN value in `minmax_box`; `null` when there is none. An infinity is
    /// written as `"Infinity"` or `"-Infinity"` (see [`crate::float`]).
    #[serde(with = "crate::float::option")]
    #[schemars(schema_with = "crate::float::option::json_schema")]
    pub max: Option<f64>,
    /// The voxels `min` and `max` were taken over: the box widened to whole cells.
    pub minmax_box: VoxelBox,
    /// Whether `minmax_box` equals the box, so `min`/`max` are exactly the box's range.
    /// Stores of layout `0.1` have only haloed cells, and are never exact.
    pub minmax_exact: bool,
    /// Value histogram of the box.
    pub histogram: RegionHistogram,
}

/// The histogram part of a [`RegionAnswer`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct RegionHistogram {
    /// Bin edges of the channel (as in the region metadata): bin `i` counts values `v` with
    /// `edges[i] <= v < edges[i + 1]`. An infinite edge is written as `null`.
    #[serde(deserialize_with = "edges_with_infinities")]
    #[schemars(with = "Vec<Option<f64>>", length(min = 2))]
    pub edges: Vec<f64>,
    /// Counts per bin.
    pub counts: Vec<u64>,
    /// Non-NaN voxels counted: the sum of `counts`.
    pub voxels: u64,
    /// The voxels counted: the box widened to whole bricks.
    #[serde(rename = "box")]
    pub covered: VoxelBox,
    /// Whether `box` equals the box asked for, so the counts are exact.
    pub exact: bool,
}

/// The error answer of the API endpoints.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(
    title = "API error",
    description = "Error answer of brickserver's API endpoints (/NAME/regions, /NAME/minmax, \
        /NAME/bricks)."
)]
#[schemars(deny_unknown_fields)]
pub struct ApiError {
    /// What went wrong, naming the dataset, key or parameter.
    #[schemars(length(min = 1))]
    pub error: String,
}

/// Whether an `Authorization` header's value presents `token` as our servers ask for it
/// (`Bearer TOKEN`, brickserver's `--token-file` and `viewer serve`'s `--serve-token-file`).
/// The comparison takes constant time, so the token cannot be guessed byte by byte from
/// timings (only its length can be learnt).
pub fn bearer_token_matches(authorization: Option<&str>, token: &str) -> bool {
    use subtle::ConstantTimeEq;
    authorization
        .and_then(|v| v.strip_prefix("Bearer "))
        .is_some_and(|given| bool::from(given.as_bytes().ct_eq(token.as_bytes())))
}

/// Reads ascending bin edges where JSON `null` stands for an infinity (serde_json writes
/// infinities as `null`): `-inf` first, `+inf` anywhere else.
///
/// # Errors
/// When the value is not a list of numbers and `null`s.
pub fn edges_with_infinities<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
    let raw = Vec::<Option<f64>>::deserialize(d)?;
    Ok(raw
        .iter()
        .enumerate()
        .map(|(i, e)| match e {
            Some(v) => *v,
            None if i == 0 => f64::NEG_INFINITY,
            None => f64::INFINITY,
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn infinite_edges_round_trip_through_null() {
        let h = RegionHistogram {
            edges: vec![f64::NEG_INFINITY, 0.0, f64::INFINITY],
            counts: vec![1, 2],
            voxels: 3,
            covered: VoxelBox {
                min: [0; 3],
                max: [1; 3],
            },
            exact: true,
        };
        let text = serde_json::to_string(&h).unwrap();
        assert!(text.contains("\"edges\":[null,0.0,null]"), "{text}");
        assert_eq!(serde_json::from_str::<RegionHistogram>(&text).unwrap(), h);
    }

    #[test]
    fn a_bearer_token_matches_only_as_bearer_and_whole() {
        assert!(bearer_token_matches(Some("Bearer s3cret"), "s3cret"));
        assert!(!bearer_token_matches(Some("Bearer s3cre"), "s3cret"));
        assert!(!bearer_token_matches(Some("Bearer s3cretx"), "s3cret"));
        assert!(!bearer_token_matches(Some("bearer s3cret"), "s3cret"));
        assert!(!bearer_token_matches(Some("s3cret"), "s3cret"));
        assert!(!bearer_token_matches(None, "s3cret"));
    }
}
