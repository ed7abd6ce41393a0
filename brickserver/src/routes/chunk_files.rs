//! Chunk keys of folder stores: the requests a viewer makes most, answered straight from the
//! connection (`crate::http1`) without the router, the file sent with `sendfile` from the
//! page cache, never copied through this process, as nginx does. The answer (status and
//! header fields) is the one the router's `GET /NAME/KEY` gives, built by the same functions;
//! this module also holds what both share: opening a key (or finding it among the files held
//! open, `crate::open_files`) with its `304`.

use std::sync::Arc;
use std::time::Instant;

use axum::http::{HeaderMap, Method, header};
use residency_schemas::server::bearer_token_matches;

use super::state::AppState;
use crate::dataset_store::Keys;
use crate::open_files::OpenFile;
use crate::responses::{FileHead, RangeRequest, if_none_match, is_metadata, range_of};
use crate::store_keys::{KeyError, RootDir};

/// The paths under `/NAME/` that are the server's API, not Zarr keys.
const API_PATHS: [&str; 4] = ["regions", "minmax", "bricks", "view"];

/// A key of a folder store, opened.
pub(crate) enum OpenedKey {
    /// `If-None-Match` matched the file's `ETag`: answer `304` ([`FileHead::not_modified`]).
    NotModified(Arc<OpenFile>),
    /// The file, with its length and `ETag`.
    File(Arc<OpenFile>),
}

/// Key `raw_key` of dataset `index` beneath its folder `root`, for a request that began at
/// `now`: a chunk from the files held open (`AppState::open_files`) while it is unchanged, else opened (and a chunk held open);
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
    now: Instant,
) -> Result<OpenedKey, KeyError> {
    let held = state
        .open_files
        .as_deref()
        .filter(|_| !is_metadata(raw_key) && !raw_key.contains('%'));
    if let Some(files) = held
        && let Some(open) = files.get(index, raw_key, now)
        && open.folder == root.identity()
    {
        if if_none_match(headers, &open.etag) {
            return Ok(OpenedKey::NotModified(open));
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
    Ok(if if_none_match(headers, &open.etag) {
        OpenedKey::NotModified(open)
    } else {
        OpenedKey::File(open)
    })
}

/// A direct answer: a chunk file, what is answered of it, and whether the page cache holds
/// the bytes to send.
pub(crate) struct ChunkAnswer {
    /// The chunk file.
    pub(crate) open: Arc<OpenFile>,
    /// `None` for a `304`, else the range answered (`Whole` for a `200`).
    range: Option<RangeRequest>,
    /// Whether the page cache holds all the bytes to send ([`OpenFile::cached`]; always for a
    /// `HEAD`): if not, they are read into it on a blocking thread before they are sent,
    /// so that `sendfile` never waits for the disk on a thread that serves other connections.
    pub(crate) cached: bool,
}

impl ChunkAnswer {
    /// The answer's status and header fields: those of the router's answer to the same
    /// request (`routes::zarr`), from the same [`FileHead`].
    pub(crate) fn head(&self) -> FileHead<'_> {
        // The direct path answers chunk keys only, never a metadata document.
        match self.range {
            None => FileHead::not_modified(&self.open.etag, false),
            Some(range) => FileHead::part(self.open.len, range, &self.open.etag, false),
        }
    }

    /// The bytes of the file to send after the head, `start..end`; `None` for a `304` and a
    /// `416`.
    pub(crate) fn body(&self) -> Option<(u64, u64)> {
        match self.range? {
            RangeRequest::Whole => Some((0, self.open.len)),
            RangeRequest::Part(start, end) => Some((start, end)),
            RangeRequest::Unsatisfiable => None,
        }
    }
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
        now: Instant,
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
        let served = state.served_at(index, now);
        let Keys::Folder(root) = &served.store.keys else {
            return None;
        };
        let open = match open_folder_key(state, index, root, raw_key, headers, now).ok()? {
            OpenedKey::NotModified(open) => {
                return Some(ChunkAnswer {
                    open,
                    range: None,
                    cached: true,
                });
            }
            OpenedKey::File(open) => open,
        };
        let range = range_of(headers, open.len);
        let mut answer = ChunkAnswer {
            open,
            range: Some(range),
            cached: true,
        };
        if *method != Method::HEAD
            && let Some((start, end)) = answer.body()
        {
            answer.cached = answer.open.cached(start, end, now);
        }
        Some(answer)
    }
}
