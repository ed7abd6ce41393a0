//! Chunk keys of folder stores: the requests a viewer makes most, answered straight from the
//! connection (`crate::http1`) without the router, the file sent with `sendfile` from the
//! page cache, never copied through this process, as nginx does. The answer (status and
//! header fields) is the one the router's `GET /NAME/KEY` gives, built by the same functions;
//! this module also holds what both share: opening a key (or finding it among the files held
//! open, `crate::open_files`) with its `304`.

use std::sync::Arc;

use axum::body::{Body, Bytes};
use axum::http::{HeaderMap, HeaderValue, Method, Response, header};
use residency_schemas::server::bearer_token_matches;

use super::state::AppState;
use crate::dataset_store::Keys;
use crate::open_files::OpenFile;
use crate::page_cache;
use crate::responses::{RangeRequest, is_metadata, not_modified, parse_range, part_response};
use crate::store_keys::{KeyError, RootDir};

/// The paths under `/NAME/` that are the server's API, not Zarr keys.
const API_PATHS: [&str; 4] = ["regions", "minmax", "bricks", "view"];

/// A key of a folder store, opened.
pub(crate) enum OpenedKey {
    /// `If-None-Match` matched: the `304`.
    NotModified(Response<Body>),
    /// The file, with its length and `ETag`.
    File(Arc<OpenFile>),
}

/// Key `raw_key` of dataset `index` beneath its folder `root`: a chunk from the files held
/// open (`AppState::open_files`) while it is unchanged, else opened (and a chunk held open);
/// `304` when the request's `If-None-Match` matches its `ETag`. A revalidation that matches
/// the `ETag` of a file held open is answered without a look at the file, as nginx answers
/// within `open_file_cache_valid`. Metadata documents, and keys spelt with percent-escapes
/// (each spelling would hold a file of its own), are opened every time.
///
/// # Errors
/// [`KeyError`] when the key is refused, missing or cannot be opened.
pub(crate) fn open_folder_key(
    state: &AppState,
    index: usize,
    root: &RootDir,
    raw_key: &str,
    headers: &HeaderMap,
) -> Result<OpenedKey, KeyError> {
    let held = state
        .open_files
        .as_deref()
        .filter(|_| !is_metadata(raw_key) && !raw_key.contains('%'));
    if let Some(files) = held
        && let Some(open) = files.get(index, raw_key)
        && open.folder == root.identity()
    {
        if let Some(answer) = not_modified(raw_key, &open.etag, headers) {
            return Ok(OpenedKey::NotModified(answer));
        }
        if open.unchanged() {
            return Ok(OpenedKey::File(open));
        }
        files.let_go(index, raw_key, &open);
    }
    let (file, meta) = root.open_key(raw_key)?;
    let open = Arc::new(OpenFile::new(file, &meta, root.identity()));
    if let Some(files) = held {
        files.insert(index, raw_key, open.clone());
    }
    Ok(match not_modified(raw_key, &open.etag, headers) {
        Some(answer) => OpenedKey::NotModified(answer),
        None => OpenedKey::File(open),
    })
}

/// A direct answer: the response's head, and the file bytes `start..end` that follow it.
pub(crate) struct ChunkAnswer {
    /// Status and header fields (its body is empty: the bytes come from the file).
    pub(crate) response: Response<Body>,
    /// The file and the bytes of it to send; `None` for `304` and `416`.
    pub(crate) body: Option<(Arc<OpenFile>, u64, u64)>,
    /// Whether the page cache holds all the bytes to send (`crate::page_cache::holds`; always
    /// for a `HEAD`): if not, they are read into it on a blocking thread before they are sent,
    /// so that `sendfile` never waits for the disk on a thread that serves other connections.
    pub(crate) cached: bool,
}

/// The direct path for chunk keys of folder stores.
#[derive(Clone)]
pub(crate) struct FolderChunks {
    state: Arc<AppState>,
    /// The bearer token the router's layer asks for, if any.
    token: Option<Arc<str>>,
    /// The CORS header fields the router's layer adds to a simple `GET`, each ending in
    /// CRLF.
    cors: Arc<[u8]>,
}

impl FolderChunks {
    /// The direct path for `state`'s folder datasets, with the router's `token` and the
    /// `cors` fields it adds.
    pub(crate) fn new(state: Arc<AppState>, token: Option<&str>, cors: Vec<u8>) -> Self {
        Self {
            state,
            token: token.map(Into::into),
            cors: cors.into(),
        }
    }

    /// The CORS header fields, each ending in CRLF.
    pub(crate) fn cors(&self) -> &[u8] {
        &self.cors
    }

    /// The answer to a request (without a body) with `method`, `target` (path and query as
    /// sent) and `headers`, if it is a `GET` or `HEAD` of an existing chunk key of a folder
    /// store, with the token if one is needed; `None` for every other request (and for errors,
    /// which the router answers with its messages).
    pub(crate) fn answer(
        &self,
        method: &Method,
        target: &str,
        headers: &HeaderMap,
    ) -> Option<ChunkAnswer> {
        if !(*method == Method::GET || *method == Method::HEAD) {
            return None;
        }
        let (name, raw_key) = target.strip_prefix('/')?.split_once('/')?;
        if raw_key.is_empty()
            || name.contains('%')
            || raw_key.contains('?')
            || API_PATHS.contains(&raw_key)
            || is_metadata(raw_key)
        {
            return None;
        }
        if let Some(token) = &self.token {
            let given = headers
                .get(header::AUTHORIZATION)
                .and_then(|v| v.to_str().ok());
            if !bearer_token_matches(given, token) {
                return None;
            }
        }
        let state = &*self.state;
        let index = state.index_of(name)?;
        let served = state.served(index);
        let Keys::Folder(root) = &served.store.keys else {
            return None;
        };
        let open = match open_folder_key(state, index, root, raw_key, headers).ok()? {
            OpenedKey::NotModified(answer) => {
                return Some(ChunkAnswer {
                    response: answer,
                    body: None,
                    cached: true,
                });
            }
            OpenedKey::File(open) => open,
        };
        let len = open.len;
        let range = headers
            .get(header::RANGE)
            .and_then(|v| v.to_str().ok())
            .map_or(RangeRequest::Whole, |v| parse_range(v, len));
        let mut response = part_response(Bytes::new(), len, range, &open.etag, raw_key);
        if range == RangeRequest::Unsatisfiable {
            // Its body is empty, and says so, as the router's answer does.
            response
                .headers_mut()
                .insert(header::CONTENT_LENGTH, HeaderValue::from(0));
        }
        let body = match range {
            RangeRequest::Whole => Some((open, 0, len)),
            RangeRequest::Part(start, end) => Some((open, start, end)),
            RangeRequest::Unsatisfiable => None,
        };
        let cached = *method == Method::HEAD
            || body
                .as_ref()
                .is_none_or(|(open, start, end)| page_cache::holds(&open.file, *start, *end));
        Some(ChunkAnswer {
            response,
            body,
            cached,
        })
    }
}
