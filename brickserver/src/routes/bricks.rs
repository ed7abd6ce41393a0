//! `GET /NAME/bricks`: many bricks in one framed binary document.

use std::sync::Arc;

use aide::transform::TransformOperation;
use axum::body::{Body, Bytes};
use axum::extract::{Path, Query, RawQuery, State};
use axum::http::{Response, StatusCode, header};
use axum::response::IntoResponse;
use residency_schemas::wire::{BRICKS_MAGIC, BRICKS_MEDIA_TYPE, BrickEncoding, encode_framed};
use schemars::JsonSchema;

use super::api_error::{api_error, load_failed, no_dataset};
use super::params::DatasetPath;
use super::state::{AppState, blocking, load_arrays, loaded};
use crate::bricks::{BatchError, BrickAt, BrickCache, batch_document, parse_batch, read_bricks};
use crate::cache::{CacheKey, Cached};
use crate::openapi::{answer, api_errors, binary, responses, with_content};

/// The query of `/NAME/bricks` as documented; the handler parses the raw query itself
/// ([`parse_batch`]), to name what is wrong with it.
#[derive(JsonSchema)]
#[expect(
    dead_code,
    reason = "only its schema is used, to document the query parse_batch reads"
)]
pub(super) struct BatchQuery {
    /// Bricks as L,C,z,y,x separated by ';' (level, channel, brick coordinates).
    b: String,
    #[serde(default = "stored")]
    encoding: BrickEncoding,
}

/// The encoding of bricks when the query names none.
fn stored() -> BrickEncoding {
    BrickEncoding::Stored
}

/// The documentation of `GET /NAME/bricks`.
pub(super) fn docs(op: TransformOperation<'_>) -> TransformOperation<'_> {
    let op = op
        .summary("Many bricks in one framed binary document")
        .description(
            "Framing: 8 bytes 'RSBRICKS', little-endian u32 header length, JSON header (schema \
             BrickBatchHeader), payload. An unreadable or corrupt brick is an `error` entry \
             naming its key; the other bricks are still answered.",
        )
        .input::<Query<BatchQuery>>();
    let batch = with_content(
        answer("The batch"),
        BRICKS_MEDIA_TYPE,
        binary(BRICKS_MEDIA_TYPE),
    );
    let op = responses(op, [(200, batch)]);
    api_errors(
        op,
        &[
            (400, "Malformed request"),
            (404, "No such dataset"),
            (
                413,
                "Too many bricks, or too many decoded bytes, in one batch",
            ),
            (500, "Image arrays unreadable"),
        ],
    )
}

/// The answer to a refused batch: 413 over a cap, 400 otherwise.
fn batch_error(e: &BatchError) -> Response<Body> {
    let status = if e.is_over_limit() {
        StatusCode::PAYLOAD_TOO_LARGE
    } else {
        StatusCode::BAD_REQUEST
    };
    api_error(status, e.to_string())
}

/// `GET /NAME/bricks`.
pub(super) async fn bricks(
    State(state): State<Arc<AppState>>,
    Path(DatasetPath { name }): Path<DatasetPath>,
    RawQuery(query): RawQuery,
) -> Response<Body> {
    let Some(index) = state.index_of(&name) else {
        return no_dataset(&name);
    };
    let (list, encoding) = match parse_batch(query.as_deref().unwrap_or(""), &state.batch) {
        Ok(b) => b,
        Err(e) => return batch_error(&e),
    };
    let arrays = loaded(&state, index, |l| &l.arrays, load_arrays);
    // The generation of the dataset the arrays read: a batch caches their bricks under it.
    let (generation, arrays) = match arrays.await {
        Ok(a) => a,
        Err(e) => return load_failed(&e),
    };
    if let Err(e) = state.batch.check_bytes(list.len(), arrays.brick_bytes()) {
        return batch_error(&e);
    }
    let bricks: Arc<[BrickAt]> = list.into();
    let cache = Arc::new(BatchCache {
        state: state.clone(),
        dataset: index,
        generation,
        raw: encoding == BrickEncoding::Raw,
    });
    let results = read_bricks(arrays.clone(), bricks.clone(), encoding, cache).await;
    let body = blocking(move || {
        let (header, payload) = batch_document(&arrays, &bricks, encoding, results);
        for e in header.bricks.iter().filter_map(|b| b.error.as_deref()) {
            tracing::error!(dataset = %name, "{e}");
        }
        encode_framed(BRICKS_MAGIC, &header, &payload)
    })
    .await;
    ([(header::CONTENT_TYPE, BRICKS_MEDIA_TYPE)], body).into_response()
}

/// A batch's bricks in the server's memory cache: those of one dataset, stored or raw.
struct BatchCache {
    state: Arc<AppState>,
    dataset: usize,
    /// The generation of the dataset its arrays read ([`super::state::Served::generation`]).
    generation: u64,
    raw: bool,
}

impl BatchCache {
    fn key(&self, at: &BrickAt) -> CacheKey {
        CacheKey::Brick {
            dataset: self.dataset,
            generation: self.generation,
            at: (at.level, at.channel, at.brick),
            raw: self.raw,
        }
    }
}

impl BrickCache for BatchCache {
    fn get(&self, at: &BrickAt) -> Option<Bytes> {
        self.state.cache.get(&self.key(at)).map(|hit| hit.bytes)
    }

    fn keep(&self, at: &BrickAt, bytes: Bytes) {
        let cached = Cached { bytes, etag: None };
        self.state.cache.insert(self.key(at), cached);
    }
}
