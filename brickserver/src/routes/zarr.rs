//! `GET /NAME/KEY`: a Zarr key of a dataset's store, verbatim, from its folder or its object
//! store.
//!
//! Keys in a folder are read from the page cache on each request (as nginx does), so nothing
//! is copied twice; chunks of an object store are kept in the memory cache.

use std::sync::Arc;
use std::time::Instant;

use aide::transform::TransformOperation;
use axum::body::{Body, Bytes};
use axum::extract::{Path, State};
use axum::http::{HeaderMap, Response, StatusCode, Uri, header};
use axum::response::IntoResponse;
use residency_store::location::object_store::GetRange;
use schemars::json_schema;

use super::chunk_files::{OpenedKey, known_object_etag, open_folder_key};
use super::params::KeyPath;
use super::state::{AppState, REVALIDATE, blocking};
use crate::cache::{CacheKey, Cached};
use crate::dataset_store::{Keys, ObjectKeys, requested_range};
use crate::openapi::{answer, binary, responses, with_content};
use crate::responses::{
    FileHead, RangeRequest, file_response, is_metadata, not_modified, parse_range, part_response,
};
use crate::store_keys::{KeyError, RootDir, checked_key, read_cached};

/// The documentation of `GET /NAME/KEY`.
pub(super) fn docs(op: TransformOperation<'_>) -> TransformOperation<'_> {
    let op = op.summary("A Zarr key of the store, verbatim").description(
        "zarr.json, .zattrs, .zarray, chunk and shard keys, residency/ arrays. ETag with \
             If-None-Match (304), single Range (206/416), Cache-Control immutable for chunks \
             and no-cache for metadata, CORS. A missing chunk is a 404 (the fill value to Zarr \
             readers).",
    );
    let stored = with_content(
        answer("The stored bytes"),
        "application/json",
        json_schema!({"type": "object"}),
    );
    let stored = with_content(
        stored,
        "application/octet-stream",
        binary("application/octet-stream"),
    );
    responses(
        op,
        [
            (200, stored),
            (206, answer("A byte range of the stored bytes")),
            (304, answer("Not modified (If-None-Match matched the ETag)")),
            (
                400,
                answer(
                    "Refused key: '..', backslash, absolute path, NUL byte, empty segment, or a \
                     symlink leading out of the dataset",
                ),
            ),
            (
                404,
                answer("No such key (a missing chunk reads as the fill value)"),
            ),
            (416, answer("Range outside the file")),
            (
                500,
                answer("The key exists but cannot be read; the message names it"),
            ),
            (
                502,
                answer(
                    "The object store answered an error for the key; the message names the key \
                     and quotes the store's answer",
                ),
            ),
            (
                503,
                answer(
                    "The object store could not be reached (connection refused or reset, \
                     timeout), with Retry-After",
                ),
            ),
        ],
    )
}

/// `GET /NAME/KEY`.
pub(super) async fn serve_key(
    State(state): State<Arc<AppState>>,
    Path(KeyPath { name, .. }): Path<KeyPath>,
    uri: Uri,
    headers: HeaderMap,
) -> Response<Body> {
    let Some(index) = state.index_of(&name) else {
        return (StatusCode::NOT_FOUND, format!("no dataset '{name}'\n")).into_response();
    };
    // The raw, still percent-encoded key: everything after "/NAME/".
    let raw_key = uri
        .path()
        .splitn(3, '/')
        .nth(2)
        .unwrap_or_default()
        .to_string();
    let mut answer = read_key(&state, index, &raw_key, &headers).await;
    if matches!(answer, Err(KeyError::NotFound)) && state.reopen_if_replaced(index) {
        // A key of a folder swapped in since the last check (the old one already deleted).
        answer = read_key(&state, index, &raw_key, &headers).await;
    }
    match answer {
        Ok(response) => response,
        Err(KeyError::NotFound) => (
            StatusCode::NOT_FOUND,
            format!("no key '{raw_key}' in '{name}'\n"),
        )
            .into_response(),
        Err(KeyError::Refused(why)) => {
            (StatusCode::BAD_REQUEST, format!("refused: {why}\n")).into_response()
        }
        Err(KeyError::Unreadable(why)) => {
            let message = format!("cannot read key '{raw_key}' of '{name}': {why}");
            super::api_error::unreadable_key(&message, &*why)
        }
    }
}

/// Key `raw_key` of dataset `index` as served now, from its folder or its object store.
async fn read_key(
    state: &AppState,
    index: usize,
    raw_key: &str,
    headers: &HeaderMap,
) -> Result<Response<Body>, KeyError> {
    let served = state.served_owned(index);
    match &served.store.keys {
        Keys::Folder(root) => folder_key(state, index, root, raw_key, headers).await,
        Keys::Object(objects) => object_key(state, index, objects, raw_key, headers).await,
    }
}

/// Key `raw_key` of dataset `index`, read from its folder `root` (or the file held open).
async fn folder_key(
    state: &AppState,
    index: usize,
    root: &RootDir,
    raw_key: &str,
    headers: &HeaderMap,
) -> Result<Response<Body>, KeyError> {
    // Open beneath the dataset root and read what the page cache holds right here, as nginx
    // does; only a read that would wait for the disk moves to the blocking pool.
    let open = match open_folder_key(state, index, root, raw_key, headers, Instant::now())? {
        OpenedKey::NotModified(open) => {
            let head = FileHead::not_modified(&open.etag, is_metadata(raw_key));
            return Ok(head.response(Body::empty()));
        }
        OpenedKey::File(open) => open,
    };
    let len = open.len as usize;
    let (bytes, whole) = read_cached(&open.file, len);
    let bytes = if whole {
        bytes
    } else {
        let open = open.clone();
        blocking(move || {
            use std::os::unix::fs::FileExt;
            let mut bytes = bytes;
            let done = bytes.len();
            bytes.resize(len, 0);
            open.file
                .read_exact_at(&mut bytes[done..], done as u64)
                .map(|()| bytes)
                .map_err(|e| KeyError::Unreadable(e.into()))
        })
        .await?
    };
    Ok(file_response(
        Bytes::from(bytes),
        &open.etag,
        raw_key,
        headers,
    ))
}

/// Key `raw_key` of dataset `index`, read from the object store: a revalidation of a chunk
/// whose `ETag` was seen within [`REVALIDATE`] is answered without a request, a chunk read
/// whole within it from the memory cache; a `Range` becomes a ranged read, so a shard's
/// index and chunks are read without the rest of the shard.
async fn object_key(
    state: &AppState,
    index: usize,
    objects: &ObjectKeys,
    raw_key: &str,
    headers: &HeaderMap,
) -> Result<Response<Body>, KeyError> {
    let key = checked_key(raw_key)?;
    let chunk = !is_metadata(raw_key);
    if let Some(etag) = known_object_etag(state, index, raw_key, headers, Instant::now()) {
        return Ok(FileHead::not_modified(&etag, false).response(Body::empty()));
    }
    let cache_key = CacheKey::Object {
        dataset: index,
        key: raw_key.to_string(),
    };
    if chunk
        && let Some(Cached {
            bytes,
            etag: Some((etag, read)),
        }) = state.cache.get(&cache_key)
        && read.elapsed() < REVALIDATE
    {
        let answer = not_modified(raw_key, &etag, headers);
        return Ok(answer.unwrap_or_else(|| file_response(bytes, &etag, raw_key, headers)));
    }
    let range_header = headers.get(header::RANGE).and_then(|v| v.to_str().ok());
    let range = range_header.and_then(requested_range);
    let ranged = range.is_some();
    let part = match objects.get(&key, range).await {
        Ok(part) => part,
        Err(KeyError::Unreadable(_)) if let Some(value) = range_header.filter(|_| ranged) => {
            // The store refused the range (past the end, a suffix of nothing): answer as a
            // file of the object's length would be.
            let (len, etag) = objects.head(&key).await?;
            match parse_range(value, len) {
                RangeRequest::Part(start, end) => {
                    objects
                        .get(&key, Some(GetRange::Bounded(start..end)))
                        .await?
                }
                RangeRequest::Whole => objects.get(&key, None).await?,
                unsatisfiable @ RangeRequest::Unsatisfiable => {
                    return Ok(part_response(
                        Bytes::new(),
                        len,
                        unsatisfiable,
                        &etag,
                        raw_key,
                    ));
                }
            }
        }
        Err(e) => return Err(e),
    };
    let tag: Arc<str> = part.etag.as_str().into();
    if chunk {
        state
            .etags
            .insert((index, raw_key.to_string()), (tag.clone(), Instant::now()));
    }
    if let Some(answer) = not_modified(raw_key, &part.etag, headers) {
        return Ok(answer);
    }
    let whole = part.range == (0..part.size);
    if chunk && whole {
        let cached = Cached {
            bytes: part.bytes.clone(),
            etag: Some((tag, Instant::now())),
        };
        state.cache.insert(cache_key, cached);
    }
    let served = if ranged {
        RangeRequest::Part(part.range.start, part.range.end)
    } else {
        RangeRequest::Whole
    };
    Ok(part_response(
        part.bytes, part.size, served, &part.etag, raw_key,
    ))
}
