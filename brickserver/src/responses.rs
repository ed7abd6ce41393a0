//! Answers for stored files: the bytes verbatim, with `ETag` / `If-None-Match`, single
//! `Range` requests, `Cache-Control` and `Content-Type` suited to Zarr keys.

use std::time::UNIX_EPOCH;

use axum::body::{Body, Bytes};
use axum::http::{HeaderMap, HeaderValue, Response, StatusCode, header};

/// `Cache-Control` for chunks and shards: immutable once written by `ingest`.
pub const CACHE_IMMUTABLE: &str = "public, max-age=31536000, immutable";
/// `Cache-Control` for metadata documents, which `ingest index` may update: revalidate.
pub const CACHE_REVALIDATE: &str = "public, no-cache";

/// Whether a key names a metadata document rather than chunk data.
pub fn is_metadata(key: &str) -> bool {
    let name = key.rsplit('/').next().unwrap_or(key);
    matches!(
        name,
        "zarr.json" | ".zattrs" | ".zarray" | ".zgroup" | ".zmetadata"
    )
}

/// A byte range of a file of `len` bytes, parsed from a `Range` header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RangeRequest {
    /// No usable range: answer the whole file (also for multi-range requests).
    Whole,
    /// Bytes `start..end` (end exclusive).
    Part(u64, u64),
    /// The range lies outside the file: 416.
    Unsatisfiable,
}

/// Parses `bytes=a-b`, `bytes=a-` and `bytes=-n` for a file of `len` bytes.
pub fn parse_range(value: &str, len: u64) -> RangeRequest {
    let Some(spec) = value.trim().strip_prefix("bytes=") else {
        return RangeRequest::Whole;
    };
    if spec.contains(',') {
        return RangeRequest::Whole;
    }
    let Some((a, b)) = spec.trim().split_once('-') else {
        return RangeRequest::Whole;
    };
    let (a, b) = (a.trim(), b.trim());
    let parsed = match (a.is_empty(), b.is_empty()) {
        (true, false) => b.parse::<u64>().ok().map(|n| (len.saturating_sub(n), len)),
        (false, true) => a.parse::<u64>().ok().map(|s| (s, len)),
        (false, false) => match (a.parse::<u64>(), b.parse::<u64>()) {
            (Ok(s), Ok(e)) if e >= s => Some((s, (e + 1).min(len))),
            _ => return RangeRequest::Whole,
        },
        (true, true) => return RangeRequest::Whole,
    };
    match parsed {
        Some((s, e)) if s < len && s < e => RangeRequest::Part(s, e),
        Some(_) => RangeRequest::Unsatisfiable,
        None => RangeRequest::Whole,
    }
}

/// The entity tag of a stored file: its length and modification time.
pub fn etag_of(meta: &std::fs::Metadata) -> String {
    let mtime = meta
        .modified()
        .ok()
        .and_then(|t| t.duration_since(UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_nanos());
    format!("\"{:x}-{:x}\"", meta.len(), mtime)
}

fn if_none_match(headers: &HeaderMap, etag: &str) -> bool {
    headers
        .get_all(header::IF_NONE_MATCH)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|t| {
            let t = t.trim();
            t == "*" || t.trim_start_matches("W/") == etag
        })
}

/// The `Cache-Control` and `Content-Type` of a key.
fn kind_of(key: &str) -> (&'static str, &'static str) {
    if is_metadata(key) {
        ("application/json", CACHE_REVALIDATE)
    } else {
        ("application/octet-stream", CACHE_IMMUTABLE)
    }
}

/// The `304 Not Modified` answer for key `key` when `If-None-Match` matches `etag`; checked
/// before the file is read, so revalidations cost no read.
pub fn not_modified(key: &str, etag: &str, headers: &HeaderMap) -> Option<Response<Body>> {
    if !if_none_match(headers, etag) {
        return None;
    }
    Some(
        Response::builder()
            .status(StatusCode::NOT_MODIFIED)
            .header(header::ETAG, etag)
            .header(header::CACHE_CONTROL, kind_of(key).1)
            .header(header::ACCEPT_RANGES, "bytes")
            .body(Body::empty())
            .expect("response"),
    )
}

/// The answer for a stored file's `bytes` served as Zarr key `key`: 206 or 416 for a
/// `Range`, 200 otherwise.
pub fn file_response(bytes: Bytes, etag: &str, key: &str, headers: &HeaderMap) -> Response<Body> {
    let len = bytes.len() as u64;
    let (content_type, cache) = kind_of(key);
    let builder = Response::builder()
        .header(header::ETAG, etag)
        .header(header::CACHE_CONTROL, cache)
        .header(header::ACCEPT_RANGES, "bytes")
        .header(header::CONTENT_TYPE, content_type);
    let range = headers
        .get(header::RANGE)
        .and_then(|v| v.to_str().ok())
        .map_or(RangeRequest::Whole, |v| parse_range(v, len));
    match range {
        RangeRequest::Unsatisfiable => builder
            .status(StatusCode::RANGE_NOT_SATISFIABLE)
            .header(header::CONTENT_RANGE, format!("bytes */{len}"))
            .body(Body::empty())
            .expect("response"),
        RangeRequest::Whole => builder
            .status(StatusCode::OK)
            .header(header::CONTENT_LENGTH, HeaderValue::from(len))
            .body(Body::from(bytes))
            .expect("response"),
        RangeRequest::Part(start, end) => builder
            .status(StatusCode::PARTIAL_CONTENT)
            .header(
                header::CONTENT_RANGE,
                format!("bytes {start}-{}/{len}", end - 1),
            )
            .header(header::CONTENT_LENGTH, HeaderValue::from(end - start))
            .body(Body::from(bytes.slice(start as usize..end as usize)))
            .expect("response"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges() {
        use RangeRequest::*;
        assert_eq!(parse_range("bytes=0-9", 100), Part(0, 10));
        assert_eq!(parse_range("bytes=90-", 100), Part(90, 100));
        assert_eq!(parse_range("bytes=-16", 100), Part(84, 100));
        assert_eq!(parse_range("bytes=95-200", 100), Part(95, 100));
        assert_eq!(parse_range("bytes=100-", 100), Unsatisfiable);
        assert_eq!(parse_range("bytes=0-1,5-6", 100), Whole);
        assert_eq!(parse_range("items=0-1", 100), Whole);
        assert_eq!(parse_range("bytes=9-3", 100), Whole);
    }

    #[test]
    fn metadata_keys() {
        assert!(is_metadata("0/zarr.json"));
        assert!(is_metadata(".zattrs"));
        assert!(!is_metadata("0/c/0/0/0/0"));
    }
}
