//! Answers for stored files: the bytes verbatim, with `ETag` / `If-None-Match`, single
//! `Range` requests, `Cache-Control` and `Content-Type` suited to Zarr keys.

use std::time::UNIX_EPOCH;

use axum::body::{Body, Bytes};
use axum::http::{HeaderMap, HeaderValue, Response, StatusCode, header};
use headers::{ETag, HeaderMapExt, IfNoneMatch};
use http_range_header::RangeUnsatisfiableError;

/// `Cache-Control` for chunks and shards: immutable once written by `ingest`.
pub(crate) const CACHE_IMMUTABLE: &str = "public, max-age=31536000, immutable";
/// `Cache-Control` for metadata documents, which `ingest index` may update: revalidate.
pub(crate) const CACHE_REVALIDATE: &str = "public, no-cache";

/// Whether a key names a metadata document rather than chunk data.
pub(crate) fn is_metadata(key: &str) -> bool {
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

/// Reads a `Range` header value for a file of `len` bytes, with `http_range_header`'s
/// RFC 9110 parser: `bytes=a-b` (clipped to the file), `bytes=a-` and `bytes=-n` (the whole
/// file when `n` exceeds it) are one [`RangeRequest::Part`]; a range starting past the end,
/// `bytes=-0`, or any range of an empty file is [`RangeRequest::Unsatisfiable`]; anything
/// else (several ranges, another unit, a malformed or reversed range) is ignored, as RFC 9110
/// allows, and the whole file is answered.
pub fn parse_range(value: &str, len: u64) -> RangeRequest {
    let Ok(ranges) = http_range_header::parse_range_header(value.trim()) else {
        return RangeRequest::Whole;
    };
    if ranges.len() != 1 {
        return RangeRequest::Whole;
    }
    match ranges.validate(len) {
        Ok(valid) => valid.first().map_or(
            // Only a suffix range of an empty file validates to no range: nothing to send.
            RangeRequest::Unsatisfiable,
            |r| RangeRequest::Part(*r.start(), r.end() + 1),
        ),
        Err(RangeUnsatisfiableError::Unsatisfiable) => RangeRequest::Unsatisfiable,
        Err(_) => RangeRequest::Whole,
    }
}

/// The entity tag of a stored file: its length and modification time.
pub(crate) fn etag_of(meta: &std::fs::Metadata) -> String {
    let mtime = meta
        .modified()
        .ok()
        .and_then(|t| t.duration_since(UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_nanos());
    format!("\"{:x}-{:x}\"", meta.len(), mtime)
}

/// Whether the request's `If-None-Match` matches `etag` (RFC 9110 weak comparison, or `*`),
/// as the `headers` crate reads the header: every field line, a comma-separated list of
/// entity tags, malformed ones skipped.
fn if_none_match(headers: &HeaderMap, etag: &str) -> bool {
    let Some(condition) = headers.typed_get::<IfNoneMatch>() else {
        return false;
    };
    etag.parse::<ETag>()
        .is_ok_and(|tag| !condition.precondition_passes(&tag))
}

/// The `Content-Type` and `Cache-Control` of a key, as header values that are not copied
/// (`HeaderValue::from_static`: a chunk's answer allocates only for its `ETag` and length).
fn kind_of(key: &str) -> (HeaderValue, HeaderValue) {
    if is_metadata(key) {
        (
            HeaderValue::from_static("application/json"),
            HeaderValue::from_static(CACHE_REVALIDATE),
        )
    } else {
        (
            HeaderValue::from_static("application/octet-stream"),
            HeaderValue::from_static(CACHE_IMMUTABLE),
        )
    }
}

/// The `304 Not Modified` answer for key `key` when `If-None-Match` matches `etag`; checked
/// before the file is read, so revalidations cost no read. It carries what RFC 9110 asks a 304
/// to repeat of the 200 (`ETag`, `Cache-Control`; the connection adds `Date`), and nothing else.
pub(crate) fn not_modified(key: &str, etag: &str, headers: &HeaderMap) -> Option<Response<Body>> {
    if !if_none_match(headers, etag) {
        return None;
    }
    Some(
        Response::builder()
            .status(StatusCode::NOT_MODIFIED)
            .header(header::ETAG, etag)
            .header(header::CACHE_CONTROL, kind_of(key).1)
            .body(Body::empty())
            .expect("response"),
    )
}

/// The answer for a stored file's `bytes` served as Zarr key `key`: 206 or 416 for a
/// `Range`, 200 otherwise.
pub(crate) fn file_response(
    bytes: Bytes,
    etag: &str,
    key: &str,
    headers: &HeaderMap,
) -> Response<Body> {
    let len = bytes.len() as u64;
    let range = headers
        .get(header::RANGE)
        .and_then(|v| v.to_str().ok())
        .map_or(RangeRequest::Whole, |v| parse_range(v, len));
    let part = match range {
        RangeRequest::Part(start, end) => bytes.slice(start as usize..end as usize),
        RangeRequest::Whole => bytes,
        RangeRequest::Unsatisfiable => Bytes::new(),
    };
    part_response(part, len, range, etag, key)
}

/// The answer for `part`, the bytes `range` picks out of a stored file of `len` bytes served
/// as Zarr key `key`: 206 (with `Content-Range`) for a part, 416 for an unsatisfiable range,
/// 200 for the whole file.
pub(crate) fn part_response(
    part: Bytes,
    len: u64,
    range: RangeRequest,
    etag: &str,
    key: &str,
) -> Response<Body> {
    let (content_type, cache) = kind_of(key);
    let builder = Response::builder()
        .header(header::ETAG, etag)
        .header(header::CACHE_CONTROL, cache)
        .header(header::ACCEPT_RANGES, HeaderValue::from_static("bytes"))
        .header(header::CONTENT_TYPE, content_type);
    match range {
        RangeRequest::Unsatisfiable => builder
            .status(StatusCode::RANGE_NOT_SATISFIABLE)
            .header(header::CONTENT_RANGE, format!("bytes */{len}"))
            .body(Body::empty())
            .expect("response"),
        RangeRequest::Whole => builder
            .status(StatusCode::OK)
            .header(header::CONTENT_LENGTH, HeaderValue::from(len))
            .body(Body::from(part))
            .expect("response"),
        RangeRequest::Part(start, end) => builder
            .status(StatusCode::PARTIAL_CONTENT)
            .header(
                header::CONTENT_RANGE,
                format!("bytes {start}-{}/{len}", end - 1),
            )
            .header(header::CONTENT_LENGTH, HeaderValue::from(end - start))
            .body(Body::from(part))
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

    /// Edges where `http_range_header` decides differently from the hand-written parser it
    /// replaced (whose answer is in each comment), and edges it decides the same way.
    #[test]
    fn range_edges_of_the_rfc_9110_parser() {
        use RangeRequest::*;
        // The same as before.
        assert_eq!(parse_range("bytes=-200", 100), Part(0, 100));
        assert_eq!(parse_range("bytes=-0", 100), Unsatisfiable);
        assert_eq!(parse_range("bytes=0-", 0), Unsatisfiable);
        assert_eq!(parse_range("bytes=-5", 0), Unsatisfiable);
        assert_eq!(parse_range("bytes=200-300,400-500", 100), Whole);
        assert_eq!(parse_range(" bytes= 0-9 ", 100), Part(0, 10));
        assert_eq!(parse_range("bytes=00-09", 100), Part(0, 10));
        assert_eq!(parse_range("bytes=-", 100), Whole);
        assert_eq!(parse_range("bytes=5", 100), Whole);
        // The unit is case-insensitive (RFC 9110 §14.1); was Whole.
        assert_eq!(parse_range("Bytes=0-9", 100), Part(0, 10));
        // Empty list elements are allowed (RFC 9110 §5.6.1); was Whole.
        assert_eq!(parse_range("bytes=0-9,", 100), Part(0, 10));
        assert_eq!(parse_range("bytes=0-9, ", 100), Part(0, 10));
        // Whitespace inside a range and a plus sign are not RFC 9110 syntax; were Part(0, 10)
        // and Part(5, 10).
        assert_eq!(parse_range("bytes=0 - 9", 100), Whole);
        assert_eq!(parse_range("bytes=+5-9", 100), Whole);
        // A last position past u64 (or at u64::MAX) means "to the end"; were Whole and (by
        // overflow) Unsatisfiable.
        assert_eq!(
            parse_range("bytes=0-99999999999999999999", 100),
            Part(0, 100)
        );
        assert_eq!(
            parse_range("bytes=0-18446744073709551615", 100),
            Part(0, 100)
        );
    }

    fn with_if_none_match(values: &[&'static str]) -> HeaderMap {
        let mut headers = HeaderMap::new();
        for v in values {
            headers.append(header::IF_NONE_MATCH, HeaderValue::from_static(v));
        }
        headers
    }

    #[test]
    fn if_none_match_compares_weakly_and_accepts_any() {
        let etag = "\"a-1\"";
        let matches = |values: &[&'static str]| if_none_match(&with_if_none_match(values), etag);
        assert!(matches(&["\"a-1\""]));
        assert!(matches(&["W/\"a-1\""]));
        assert!(matches(&["*"]));
        assert!(matches(&["\"b-2\", W/\"a-1\""]));
        assert!(matches(&["\"b-2\"", "\"a-1\""]));
        assert!(matches(&["garbage, \"a-1\""]));
        assert!(!matches(&[]));
        assert!(!matches(&["\"b-2\""]));
        assert!(!matches(&["a-1"]));
        assert!(!matches(&["w/\"a-1\""]));
        // Edges the `headers` crate reads by RFC 9110 where the hand-written matcher did
        // not: `*` is only the whole field, and `W/` is one prefix (both matched before).
        assert!(!matches(&["\"b-2\", *"]));
        assert!(!matches(&["W/W/\"a-1\""]));
        assert!(not_modified("0/c/0", etag, &with_if_none_match(&["*"])).is_some());
        assert!(not_modified("0/c/0", etag, &HeaderMap::new()).is_none());
    }

    #[test]
    fn metadata_keys() {
        assert!(is_metadata("0/zarr.json"));
        assert!(is_metadata(".zattrs"));
        assert!(!is_metadata("0/c/0/0/0/0"));
    }
}
