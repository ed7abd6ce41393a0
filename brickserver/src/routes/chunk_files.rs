//! Chunk keys of folder stores: the requests a viewer makes most, answered straight from the
//! connection (`crate::http1`) without the router, the file sent with `sendfile` from the
//! page cache, never copied through this process, as nginx does. The answer (status and
//! header fields) is the one the router's `GET /NAME/KEY` gives, built by the same functions;
//! this module also holds what both share: the remembered `ETag`s that answer revalidations
//! without a system call, and opening a key with its `304`.

use std::fs::{File, Metadata};
use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::body::{Body, Bytes};
use axum::http::{HeaderMap, HeaderValue, Method, Response, header};
use residency_schemas::server::bearer_token_matches;

use super::state::AppState;
use crate::dataset_store::Keys;
use crate::responses::{
    RangeRequest, etag_of, is_metadata, not_modified, parse_range, part_response,
};
use crate::store_keys::{KeyError, RootDir};

/// How long a remembered chunk `ETag` answers revalidations without a look at the file (as
/// nginx's `open_file_cache_valid`): chunks are immutable, but a store may be replaced.
pub(crate) const ETAG_VALID: Duration = Duration::from_mins(1);

/// A borrowed key of [`AppState::etags`] (dataset index, raw key): hashes and compares as the
/// owned `(usize, String)`, so a look-up allocates nothing.
#[derive(Hash)]
struct EtagKey<'a>(usize, &'a str);

impl quick_cache::Equivalent<(usize, String)> for EtagKey<'_> {
    fn equivalent(&self, key: &(usize, String)) -> bool {
        self.0 == key.0 && self.1 == key.1
    }
}

/// The paths under `/NAME/` that are the server's API, not Zarr keys.
const API_PATHS: [&str; 4] = ["regions", "minmax", "bricks", "view"];

/// The `304` for a revalidation of chunk `raw_key` of dataset `index` whose `ETag` was seen
/// in the last [`ETAG_VALID`] and matches: no system call at all.
pub(crate) fn remembered_not_modified(
    state: &AppState,
    index: usize,
    raw_key: &str,
    headers: &HeaderMap,
) -> Option<Response<Body>> {
    if is_metadata(raw_key) || !headers.contains_key(header::IF_NONE_MATCH) {
        return None;
    }
    let (etag, seen) = state.etags.get(&EtagKey(index, raw_key))?;
    if seen.elapsed() >= ETAG_VALID {
        return None;
    }
    not_modified(raw_key, &etag, headers)
}

/// A key of a folder store, opened.
pub(crate) enum OpenedKey {
    /// `If-None-Match` matched: the `304`.
    NotModified(Response<Body>),
    /// The file, its metadata and its `ETag`.
    File(File, Metadata, String),
}

/// Opens key `raw_key` of dataset `index` beneath its folder `root`, remembers a chunk's
/// `ETag`, and answers `304` when the request's `If-None-Match` matches it.
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
    let (file, meta) = root.open_key(raw_key)?;
    let etag = etag_of(&meta);
    // Remembered anew when unknown, changed, or seen more than half its validity ago (an
    // insert costs more than the look-up, and most chunks are asked for again).
    let known = state.etags.get(&EtagKey(index, raw_key));
    let fresh = known.is_some_and(|(t, seen)| *t == *etag && seen.elapsed() < ETAG_VALID / 2);
    if !is_metadata(raw_key) && !fresh {
        state.etags.insert(
            (index, raw_key.to_string()),
            (etag.as_str().into(), Instant::now()),
        );
    }
    Ok(match not_modified(raw_key, &etag, headers) {
        Some(answer) => OpenedKey::NotModified(answer),
        None => OpenedKey::File(file, meta, etag),
    })
}

/// A direct answer: the response's head, and the file bytes `start..end` that follow it.
pub(crate) struct ChunkAnswer {
    /// Status and header fields (its body is empty: the bytes come from the file).
    pub(crate) response: Response<Body>,
    /// The file and the bytes of it to send; `None` for `304` and `416`.
    pub(crate) body: Option<(File, u64, u64)>,
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
        let Keys::Folder(root) = &state.stores[index].keys else {
            return None;
        };
        if let Some(answer) = remembered_not_modified(state, index, raw_key, headers) {
            return Some(ChunkAnswer {
                response: answer,
                body: None,
            });
        }
        let (file, meta, etag) = match open_folder_key(state, index, root, raw_key, headers).ok()? {
            OpenedKey::NotModified(answer) => {
                return Some(ChunkAnswer {
                    response: answer,
                    body: None,
                });
            }
            OpenedKey::File(file, meta, etag) => (file, meta, etag),
        };
        let len = meta.len();
        let range = headers
            .get(header::RANGE)
            .and_then(|v| v.to_str().ok())
            .map_or(RangeRequest::Whole, |v| parse_range(v, len));
        let mut response = part_response(Bytes::new(), len, range, &etag, raw_key);
        if range == RangeRequest::Unsatisfiable {
            // Its body is empty, and says so, as the router's answer does.
            response
                .headers_mut()
                .insert(header::CONTENT_LENGTH, HeaderValue::from(0));
        }
        let body = match range {
            RangeRequest::Whole => Some((file, 0, len)),
            RangeRequest::Part(start, end) => Some((file, start, end)),
            RangeRequest::Unsatisfiable => None,
        };
        if let Some((file, start, end)) = &body
            && !in_page_cache(file, *start, *end)
        {
            // `sendfile` would wait for the disk on a thread that serves other connections:
            // the router reads what is cached and moves the rest to the blocking pool.
            return None;
        }
        Some(ChunkAnswer { response, body })
    }
}

/// The `cachestat` system call's number (the same on every architecture; Linux 6.5).
const SYS_CACHESTAT: libc::c_long = 451;

/// `struct cachestat_range`: the bytes asked about.
#[repr(C)]
struct CachestatRange {
    off: u64,
    len: u64,
}

/// `struct cachestat`: what the page cache holds of them (the kernel's field names).
#[repr(C)]
#[derive(Default)]
#[allow(clippy::struct_field_names)]
struct Cachestat {
    nr_cache: u64,
    nr_dirty: u64,
    nr_writeback: u64,
    nr_evicted: u64,
    nr_recently_evicted: u64,
}

/// The system's page size, the unit `cachestat` counts in (read once).
fn page_size() -> u64 {
    static PAGE: std::sync::OnceLock<u64> = std::sync::OnceLock::new();
    // SAFETY: `sysconf` only reads a system constant.
    *PAGE
        .get_or_init(|| u64::try_from(unsafe { libc::sysconf(libc::_SC_PAGESIZE) }).unwrap_or(4096))
}

/// Whether bytes `start..end` of `file` are all in the page cache (`cachestat`, one system
/// call), so that sending them cannot wait for the disk. Kernels without `cachestat` (before
/// 6.5) say yes: the file is sent as nginx sends it, reading the disk if it must.
fn in_page_cache(file: &File, start: u64, end: u64) -> bool {
    use std::os::fd::AsRawFd;
    if end <= start {
        return true;
    }
    let page = page_size();
    let range = CachestatRange {
        off: start / page * page,
        len: end.div_ceil(page) * page - start / page * page,
    };
    let mut stat = Cachestat::default();
    // SAFETY: an open descriptor, and pointers to structs of the layout the kernel reads
    // and writes.
    let done = unsafe {
        libc::syscall(
            SYS_CACHESTAT,
            file.as_raw_fd(),
            &raw const range,
            &raw mut stat,
            0,
        )
    };
    done != 0 || stat.nr_cache >= range.len / page
}

#[cfg(test)]
mod tests {
    use std::io::Write;
    use std::os::fd::AsRawFd;

    use super::*;

    #[test]
    fn borrowed_etag_keys_find_the_owned_ones() {
        let cache = quick_cache::sync::Cache::<(usize, String), u8>::new(16);
        cache.insert((3, "0/c/0/1/2/3".to_string()), 7);
        assert_eq!(cache.get(&EtagKey(3, "0/c/0/1/2/3")), Some(7));
        assert_eq!(cache.get(&EtagKey(2, "0/c/0/1/2/3")), None);
        assert_eq!(cache.get(&EtagKey(3, "0/c/0/1/2/4")), None);
    }

    #[test]
    fn pages_dropped_from_the_cache_are_seen_as_not_cached() {
        // Beside the sources, not in a /tmp that may be memory (where pages cannot drop).
        let mut file = tempfile::tempfile_in(env!("CARGO_MANIFEST_DIR")).unwrap();
        file.write_all(&vec![1u8; 64 << 10]).unwrap();
        file.sync_all().unwrap();
        assert!(in_page_cache(&file, 0, 64 << 10));
        // SAFETY: an open descriptor.
        let dropped =
            unsafe { libc::posix_fadvise(file.as_raw_fd(), 0, 0, libc::POSIX_FADV_DONTNEED) };
        assert_eq!(dropped, 0);
        assert!(!in_page_cache(&file, 0, 64 << 10));
        assert!(!in_page_cache(&file, 5000, 5001));
        assert!(in_page_cache(&file, 7, 7));
        let mut byte = [0u8];
        std::os::unix::fs::FileExt::read_exact_at(&file, &mut byte, 5000).unwrap();
        assert!(in_page_cache(&file, 5000, 5001));
    }
}
