//! Chunk keys of folder stores: the requests a viewer makes most, answered straight from the
//! connection (`crate::http1`) without the router, the file sent with `sendfile` from the
//! page cache, never copied through this process, as nginx does. The answer (status and
//! header fields) is the one the router's `GET /NAME/KEY` gives, built by the same functions;
//! this module also holds what both share: opening a key (or finding it among the files held
//! open, `crate::open_files`) with its `304`.

use std::fs::File;
use std::sync::Arc;

use axum::body::{Body, Bytes};
use axum::http::{HeaderMap, HeaderValue, Method, Response, header};
use residency_schemas::server::bearer_token_matches;

use super::state::AppState;
use crate::dataset_store::Keys;
use crate::open_files::OpenFile;
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
    let open = Arc::new(OpenFile::new(file, &meta));
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
        let open = match open_folder_key(state, index, root, raw_key, headers).ok()? {
            OpenedKey::NotModified(answer) => {
                return Some(ChunkAnswer {
                    response: answer,
                    body: None,
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
        if let Some((open, start, end)) = &body
            && !in_page_cache(&open.file, *start, *end)
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
