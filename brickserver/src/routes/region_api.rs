//! The region API: `GET /NAME/regions` (value range and histogram of a box) and
//! `GET /NAME/minmax` (the min/max hierarchy of a channel), from the stored region metadata.

use std::sync::Arc;

use aide::transform::TransformOperation;
use axum::body::Body;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Path, Query, State};
use axum::http::{Response, StatusCode, header};
use axum::response::{IntoResponse, Json};
use residency_schemas::server::RegionAnswer;
use residency_schemas::wire::MINMAX_MEDIA_TYPE;
use schemars::JsonSchema;
use serde::Deserialize;

use super::api_error::{api_error, load_failed, no_dataset};
use super::params::DatasetPath;
use super::state::{AppState, load_regions, loaded};
use crate::openapi::{answer, api_errors, binary, json, responses, with_content};
use crate::regions::{QueryError, RegionIndex};

/// A level or channel index: a non-negative integer.
fn index_schema(schema: &mut schemars::Schema) {
    schema.remove("format");
}

/// Query of `/NAME/regions`.
#[derive(Deserialize, JsonSchema)]
pub(super) struct RegionParams {
    #[schemars(transform = index_schema)]
    level: usize,
    #[schemars(transform = index_schema)]
    channel: usize,
    /// First voxel x,y,z of the level.
    #[schemars(regex(pattern = r"^[0-9]+,[0-9]+,[0-9]+$"))]
    min: String,
    /// One past the last voxel x,y,z (exclusive).
    #[schemars(regex(pattern = r"^[0-9]+,[0-9]+,[0-9]+$"))]
    max: String,
}

/// Query of `/NAME/minmax`.
#[derive(Deserialize, JsonSchema)]
pub(super) struct MinMaxParams {
    #[schemars(transform = index_schema)]
    channel: usize,
}

/// The documentation of `GET /NAME/regions`.
pub(super) fn regions_docs(op: TransformOperation<'_>) -> TransformOperation<'_> {
    let op = op
        .summary("Value range and histogram of a box of voxels, from the stored region metadata")
        .description(
            "Never narrower than the truth; exact for a box aligned to the stored cells \
             (min/max, 8 voxels at the finest grid) and bricks (histogram), or ending at the \
             level's edge. The answer states the boxes it covers.",
        );
    let op = responses(op, [(200, json::<RegionAnswer>("The answer"))]);
    api_errors(
        op,
        &[
            (
                400,
                "Malformed query, level or channel out of range, or box outside the level",
            ),
            (404, "No such dataset, or no region metadata"),
            (500, "Region metadata unreadable"),
        ],
    )
}

/// The documentation of `GET /NAME/minmax`.
pub(super) fn minmax_docs(op: TransformOperation<'_>) -> TransformOperation<'_> {
    let op = op
        .summary(
            "The whole conservative min/max hierarchy of one channel, every level and grid, in \
             one framed binary document",
        )
        .description(
            "Framing: 8 bytes 'RSMINMAX', little-endian u32 header length, JSON header (schema \
             MinMaxHierarchyHeader), payload.",
        );
    let document = with_content(
        answer("The document"),
        MINMAX_MEDIA_TYPE,
        binary(MINMAX_MEDIA_TYPE),
    );
    let op = responses(op, [(200, document)]);
    api_errors(
        op,
        &[
            (400, "Malformed query or channel out of range"),
            (404, "No such dataset, or no region metadata"),
            (500, "Region metadata unreadable"),
        ],
    )
}

/// Parses `x,y,z`, the value of query parameter `what`.
fn parse_xyz(what: &'static str, text: &str) -> Result<[u64; 3], QueryError> {
    let not_xyz = || QueryError::NotXyz {
        parameter: what,
        text: text.to_string(),
    };
    let v: Vec<u64> = text
        .split(',')
        .map(|s| s.trim().parse::<u64>())
        .collect::<Result<_, _>>()
        .map_err(|_| not_xyz())?;
    v.try_into().map_err(|_| not_xyz())
}

/// The region index of a dataset, or the error answer.
async fn region_index(
    state: &Arc<AppState>,
    name: &str,
) -> Result<Arc<RegionIndex>, Response<Body>> {
    let index = state.index_of(name).ok_or_else(|| no_dataset(name))?;
    let regions = loaded(state, index, |l| &l.regions, load_regions);
    match regions.await {
        Ok(Some(r)) => Ok(r),
        Ok(None) => Err(api_error(
            StatusCode::NOT_FOUND,
            format!(
                "dataset '{name}' has no region metadata (add it with `ingest index`); \
                 min/max and histograms are unknown"
            ),
        )),
        Err(e) => Err(load_failed(&e)),
    }
}

/// The parsed query (or a 400 saying what was `expected`) and the dataset's region index.
async fn api_input<T>(
    state: &Arc<AppState>,
    name: &str,
    params: Result<Query<T>, QueryRejection>,
    expected: &str,
) -> Result<(T, Arc<RegionIndex>), Response<Body>> {
    let Query(p) = params.map_err(|e| {
        api_error(
            StatusCode::BAD_REQUEST,
            format!("{}; expected {expected}", e.body_text()),
        )
    })?;
    Ok((p, region_index(state, name).await?))
}

/// `GET /NAME/regions`.
pub(super) async fn regions(
    State(state): State<Arc<AppState>>,
    Path(DatasetPath { name }): Path<DatasetPath>,
    params: Result<Query<RegionParams>, QueryRejection>,
) -> Response<Body> {
    let (p, index) = match api_input(
        &state,
        &name,
        params,
        "level=L&channel=C&min=x,y,z&max=x,y,z",
    )
    .await
    {
        Ok(got) => got,
        Err(r) => return r,
    };
    let bounds = parse_xyz("min", &p.min).and_then(|a| Ok((a, parse_xyz("max", &p.max)?)));
    let (min, max) = match bounds {
        Ok(b) => b,
        Err(e) => return api_error(StatusCode::BAD_REQUEST, e.to_string()),
    };
    match index.query(&name, p.level, p.channel, min, max) {
        Ok(answer) => Json(answer).into_response(),
        Err(e) => api_error(StatusCode::BAD_REQUEST, e.to_string()),
    }
}

/// `GET /NAME/minmax`.
pub(super) async fn minmax(
    State(state): State<Arc<AppState>>,
    Path(DatasetPath { name }): Path<DatasetPath>,
    params: Result<Query<MinMaxParams>, QueryRejection>,
) -> Response<Body> {
    let (p, index) = match api_input(&state, &name, params, "channel=C").await {
        Ok(got) => got,
        Err(r) => return r,
    };
    match index.minmax_document(p.channel) {
        Ok(doc) => (
            [
                (header::CONTENT_TYPE, MINMAX_MEDIA_TYPE),
                (header::CACHE_CONTROL, "public, no-cache"),
            ],
            doc,
        )
            .into_response(),
        Err(e) => api_error(StatusCode::BAD_REQUEST, e.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coordinates_parse_or_say_what_is_wrong() {
        assert_eq!(parse_xyz("min", "1, 2,3"), Ok([1, 2, 3]));
        for text in ["0,0", "0,0,0,0", "a,b,c", "-1,0,0", ""] {
            assert_eq!(
                parse_xyz("max", text).unwrap_err().to_string(),
                format!("max '{text}' is not three integers x,y,z")
            );
        }
    }
}
