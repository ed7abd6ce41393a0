//! Chunk keys: the requests a viewer makes most, answered straight from the connection
//! (`crate::http1`) without the router. A chunk of a folder store is sent with `sendfile` from
//! the page cache, never copied through this process, as nginx does; a revalidation of an
//! object store's chunk whose `ETag` was seen within [`REVALIDATE`] gets its `304` without a
//! request to the store. The answer (status and header fields) is the one the router's
//! `GET /NAME/KEY` gives, built by the same functions; this module also holds what both share:
//! opening a key (or finding it among the files held open, `crate::open_files`) with its
//! `304`, and an object's `ETag` as last seen ([`known_object_etag`]).

use std::sync::Arc;
use std::time::Instant;

use axum::http::{HeaderMap, Method, header};
use residency_schemas::server::bearer_token_matches;

use super::state::{AppState, REVALIDATE};
use crate::dataset_store::Keys;
use crate::open_files::{BorrowedKey, OpenFile};
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

/// The `ETag` of chunk `raw_key` of dataset `index`, an object store's, when the request's
/// `If-None-Match` matches it and it was seen within [`REVALIDATE`] of `now`: the request is
/// answered `304` without asking the store (as a file held open is, `open_folder_key`).
/// Metadata documents are always asked for.
pub(crate) fn known_object_etag(
    state: &AppState,
    index: usize,
    raw_key: &str,
    headers: &HeaderMap,
    now: Instant,
) -> Option<Arc<str>> {
    if is_metadata(raw_key) || !headers.contains_key(header::IF_NONE_MATCH) {
        return None;
    }
    let (etag, seen) = state.etags.get(&BorrowedKey(index, raw_key))?;
    (now.saturating_duration_since(seen) < REVALIDATE && if_none_match(headers, &etag))
        .then_some(etag)
}

/// What a direct answer is of.
enum Answered {
    /// A chunk file of a folder store, and the range answered (`Whole` for a `200`), or
    /// `None` for a `304`.
    File(Arc<OpenFile>, Option<RangeRequest>),
    /// A chunk of an object store revalidated ([`known_object_etag`]): a `304` with this
    /// `ETag`.
    Revalidated(Arc<str>),
}

/// A direct answer: what it is of, and whether the page cache holds the bytes to send.
pub(crate) struct ChunkAnswer {
    /// The file and range, or the object store's `ETag`.
    answered: Answered,
    /// Whether the page cache holds all the bytes to send ([`OpenFile::cached`]; always for a
    /// `HEAD` and a `304`): if not, they are read into it on a blocking thread before they are
    /// sent, so that `sendfile` never waits for the disk on a thread that serves other
    /// connections.
    pub(crate) cached: bool,
}

impl ChunkAnswer {
    /// The answer's status and header fields: those of the router's answer to the same
    /// request (`routes::zarr`), from the same [`FileHead`].
    pub(crate) fn head(&self) -> FileHead<'_> {
        // The direct path answers chunk keys only, never a metadata document.
        match &self.answered {
            Answered::File(open, None) => FileHead::not_modified(&open.etag, false),
            Answered::File(open, Some(range)) => {
                FileHead::part(open.len, *range, &open.etag, false)
            }
            Answered::Revalidated(etag) => FileHead::not_modified(etag, false),
        }
    }

    /// The file to send after the head, and its bytes `start..end`; `None` for a `304` and a
    /// `416`.
    pub(crate) fn body(&self) -> Option<(&Arc<OpenFile>, u64, u64)> {
        let Answered::File(open, Some(range)) = &self.answered else {
            return None;
        };
        match *range {
            RangeRequest::Whole => Some((open, 0, open.len)),
            RangeRequest::Part(start, end) => Some((open, start, end)),
            RangeRequest::Unsatisfiable => None,
        }
    }
}

/// The direct path for chunk keys: a folder store's, and an object store's revalidations.
#[derive(Clone)]
pub(crate) struct DirectChunks {
    state: Arc<AppState>,
    /// The bearer token the router's layer asks for, if any.
    token: Option<Arc<str>>,
    /// The CORS header fields the router's layer adds to a simple `GET`, each ending in
    /// CRLF.
    cors: Arc<[u8]>,
}

impl DirectChunks {
    /// The direct path for `state`'s datasets, with the router's `token` and the
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
    /// store, or a revalidation of an object store's chunk [`known_object_etag`] answers, with
    /// the token if one is needed; `None` for every other request (and for errors, which the
    /// router answers with its messages).
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
        let root = match &served.store.keys {
            Keys::Folder(root) => root,
            Keys::Object(_) => {
                let etag = known_object_etag(state, index, raw_key, headers, now)?;
                return Some(ChunkAnswer {
                    answered: Answered::Revalidated(etag),
                    cached: true,
                });
            }
        };
        let open = match open_folder_key(state, index, root, raw_key, headers, now).ok()? {
            OpenedKey::NotModified(open) => {
                return Some(ChunkAnswer {
                    answered: Answered::File(open, None),
                    cached: true,
                });
            }
            OpenedKey::File(open) => open,
        };
        let range = range_of(headers, open.len);
        let mut answer = ChunkAnswer {
            answered: Answered::File(open, Some(range)),
            cached: true,
        };
        if *method != Method::HEAD
            && let Some((open, start, end)) = answer.body()
        {
            answer.cached = open.cached(start, end, now);
        }
        Some(answer)
    }
}

#[cfg(test)]
mod tests {
    use axum::body::Body;
    use axum::http::{HeaderValue, Request};
    use residency_store::location::StoreLocation;
    use residency_store::location::object_store::memory::InMemory;
    use residency_store::location::object_store::path::Path as ObjectPath;
    use residency_store::location::object_store::{ObjectStore, ObjectStoreExt};
    use tower::ServiceExt as _;

    use super::*;
    use crate::datasets::{Dataset, Datasets};
    use crate::routes::{ServerOptions, router};

    /// Dataset `cells`, an object store holding one chunk, served with `token`: the state,
    /// the router over it and the direct path.
    async fn object_dataset(token: Option<&str>) -> (Arc<AppState>, axum::Router, DirectChunks) {
        let objects = InMemory::new();
        objects
            .put(
                &ObjectPath::from("cells/0/c/0/0/0"),
                b"chunk".to_vec().into(),
            )
            .await
            .unwrap();
        let datasets = Datasets(vec![Dataset {
            name: "cells".into(),
            location: StoreLocation::S3 {
                bucket: "bucket".into(),
                prefix: "cells".into(),
            },
            object_store: Some((
                Arc::new(objects) as Arc<dyn ObjectStore>,
                ObjectPath::from("cells"),
            )),
        }]);
        let options = ServerOptions {
            token: token.map(str::to_string),
            ..ServerOptions::default()
        };
        let state = Arc::new(AppState::new(datasets, &options).unwrap());
        let direct = DirectChunks::new(state.clone(), token, Vec::new());
        (state.clone(), router(state, &options), direct)
    }

    /// The router's answer to `GET path` with `headers`: status and `ETag`.
    async fn routed(router: &axum::Router, path: &str, headers: &[(&str, &str)]) -> (u16, String) {
        let mut request = Request::get(path);
        for (name, value) in headers {
            request = request.header(*name, *value);
        }
        let request = request.body(Body::empty()).unwrap();
        let Ok(answer) = router.clone().oneshot(request).await;
        let etag = answer
            .headers()
            .get(header::ETAG)
            .map_or("", |v| v.to_str().unwrap());
        (answer.status().as_u16(), etag.to_string())
    }

    fn fields(pairs: &[(&str, &str)]) -> HeaderMap {
        let mut headers = HeaderMap::new();
        for (name, value) in pairs {
            headers.append(
                header::HeaderName::from_bytes(name.as_bytes()).unwrap(),
                HeaderValue::from_str(value).unwrap(),
            );
        }
        headers
    }

    /// The status and `ETag` of the direct answer, if there is one.
    fn direct_answer(
        direct: &DirectChunks,
        method: &Method,
        target: &str,
        pairs: &[(&str, &str)],
        now: Instant,
    ) -> Option<(u16, String)> {
        let answer = direct.answer(method, target, &fields(pairs), now)?;
        assert!(answer.body().is_none() && answer.cached);
        let mut etag = String::new();
        answer.head().fields(|name, value| {
            if name == header::ETAG {
                etag = String::from_utf8(value.as_bytes().to_vec()).unwrap();
            }
        });
        Some((answer.head().status().as_u16(), etag))
    }

    #[tokio::test]
    async fn an_object_stores_chunk_is_revalidated_directly_while_its_etag_is_fresh() {
        let (state, router, direct) = object_dataset(None).await;
        let key = "/cells/0/c/0/0/0";
        let now = Instant::now();
        // Nothing is known of the chunk before the store has been asked for it.
        assert_eq!(
            direct_answer(
                &direct,
                &Method::GET,
                key,
                &[("if-none-match", "\"x\"")],
                now
            ),
            None
        );
        let (status, etag) = routed(&router, key, &[]).await;
        assert_eq!(status, 200);
        assert!(etag.starts_with('"'), "{etag}");
        let matching = [("if-none-match", etag.as_str())];
        let now = Instant::now();
        let not_modified = Some((304, etag.clone()));
        assert_eq!(
            direct_answer(&direct, &Method::GET, key, &matching, now),
            not_modified
        );
        assert_eq!(
            direct_answer(&direct, &Method::HEAD, key, &matching, now),
            not_modified
        );
        // A list of tags that holds it, and `*`.
        let listed = format!("\"other\", {etag}");
        let listed = [("if-none-match", listed.as_str())];
        assert_eq!(
            direct_answer(&direct, &Method::GET, key, &listed, now),
            not_modified
        );
        let any = [("if-none-match", "*")];
        assert_eq!(
            direct_answer(&direct, &Method::GET, key, &any, now),
            not_modified
        );
        // The router gives the same answer.
        assert_eq!(routed(&router, key, &matching).await, (304, etag.clone()));
        // Everything else is the router's: another tag, no tag, another method, a query, a
        // metadata document, a key not read yet, another dataset's name, and the same
        // revalidation once REVALIDATE has passed since the tag was seen.
        let other = [("if-none-match", "\"other\"")];
        assert_eq!(direct_answer(&direct, &Method::GET, key, &other, now), None);
        assert_eq!(direct_answer(&direct, &Method::GET, key, &[], now), None);
        assert_eq!(
            direct_answer(&direct, &Method::POST, key, &matching, now),
            None
        );
        let queried = format!("{key}?v=1");
        assert_eq!(
            direct_answer(&direct, &Method::GET, &queried, &matching, now),
            None
        );
        state.etags.insert(
            (0, "zarr.json".to_string()),
            (etag.as_str().into(), Instant::now()),
        );
        let metadata = "/cells/zarr.json";
        assert_eq!(
            direct_answer(&direct, &Method::GET, metadata, &matching, now),
            None
        );
        let unread = "/cells/0/c/0/0/1";
        assert_eq!(
            direct_answer(&direct, &Method::GET, unread, &matching, now),
            None
        );
        let renamed = "/tissue/0/c/0/0/0";
        assert_eq!(
            direct_answer(&direct, &Method::GET, renamed, &matching, now),
            None
        );
        let later = now + REVALIDATE;
        assert_eq!(
            direct_answer(&direct, &Method::GET, key, &matching, later),
            None
        );
    }

    #[tokio::test]
    async fn an_object_stores_revalidation_needs_the_token_on_the_direct_path_too() {
        let (_, router, direct) = object_dataset(Some("secret")).await;
        let key = "/cells/0/c/0/0/0";
        let bearer = [("authorization", "Bearer secret")];
        let (status, etag) = routed(&router, key, &bearer).await;
        assert_eq!(status, 200);
        let now = Instant::now();
        let without = [("if-none-match", etag.as_str())];
        assert_eq!(
            direct_answer(&direct, &Method::GET, key, &without, now),
            None
        );
        assert_eq!(routed(&router, key, &without).await.0, 401);
        let wrong = [
            ("if-none-match", etag.as_str()),
            ("authorization", "Bearer guess"),
        ];
        assert_eq!(direct_answer(&direct, &Method::GET, key, &wrong, now), None);
        let with = [("if-none-match", etag.as_str()), bearer[0]];
        assert_eq!(
            direct_answer(&direct, &Method::GET, key, &with, now),
            Some((304, etag))
        );
    }
}
