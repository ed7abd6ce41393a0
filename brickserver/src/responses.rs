//! Answers for stored files: the bytes verbatim, with `ETag` / `If-None-Match`, single
//! `Range` requests, `Cache-Control` and `Content-Type` suited to Zarr keys.

use std::io::Write as _;
use std::time::UNIX_EPOCH;

use axum::body::{Body, Bytes};
use axum::http::{HeaderMap, HeaderName, HeaderValue, Response, StatusCode, header};
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

/// The range a request's `Range` field asks of a file of `len` bytes ([`parse_range`];
/// [`RangeRequest::Whole`] without one).
pub(crate) fn range_of(headers: &HeaderMap, len: u64) -> RangeRequest {
    headers
        .get(header::RANGE)
        .and_then(|v| v.to_str().ok())
        .map_or(RangeRequest::Whole, |v| parse_range(v, len))
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
pub(crate) fn if_none_match(headers: &HeaderMap, etag: &str) -> bool {
    let mut values = headers.get_all(header::IF_NONE_MATCH).iter();
    let Some(first) = values.next() else {
        return false;
    };
    // A revalidation usually sends back the one `ETag` it was given: the same bytes match
    // (under the weak comparison too) without parsing or allocating anything.
    if first.as_bytes() == etag.as_bytes() && values.next().is_none() {
        return true;
    }
    let Some(condition) = headers.typed_get::<IfNoneMatch>() else {
        return false;
    };
    etag.parse::<ETag>()
        .is_ok_and(|tag| !condition.precondition_passes(&tag))
}

/// The `304 Not Modified` answer for key `key` when `If-None-Match` matches `etag`; checked
/// before the file is read, so revalidations cost no read ([`FileHead::not_modified`]).
pub(crate) fn not_modified(key: &str, etag: &str, headers: &HeaderMap) -> Option<Response<Body>> {
    if_none_match(headers, etag)
        .then(|| FileHead::not_modified(etag, is_metadata(key)).response(Body::empty()))
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
    let range = range_of(headers, len);
    let part = match range {
        RangeRequest::Part(start, end) => bytes.slice(start as usize..end as usize),
        RangeRequest::Whole => bytes,
        RangeRequest::Unsatisfiable => Bytes::new(),
    };
    part_response(part, len, range, etag, key)
}

/// The answer for `part`, the bytes `range` picks out of a stored file of `len` bytes served
/// as Zarr key `key` ([`FileHead::part`]).
pub(crate) fn part_response(
    part: Bytes,
    len: u64,
    range: RangeRequest,
    etag: &str,
    key: &str,
) -> Response<Body> {
    FileHead::part(len, range, etag, is_metadata(key)).response(Body::from(part))
}

/// The status and header fields of an answer for a stored file, without its body: the
/// router's `Response` is built from it, and a connection that sends a chunk file itself
/// (`crate::http1`) writes it straight into the answer's head, with nothing allocated, so the
/// two cannot differ.
#[derive(Clone, Copy, Debug)]
pub(crate) struct FileHead<'a> {
    /// `200`, `206`, `304` or `416`.
    status: StatusCode,
    /// The file's `ETag`.
    etag: &'a str,
    /// Whether the key is a metadata document (its `Content-Type` and `Cache-Control`).
    metadata: bool,
    /// The file's length and the range answered; `None` for a `304`, which repeats only what
    /// RFC 9110 asks of it (`ETag`, `Cache-Control`; the connection adds `Date`).
    range: Option<(u64, RangeRequest)>,
}

/// A header field's value as [`FileHead::fields`] gives it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum FieldValue<'a> {
    /// A constant (not copied into a `Response`).
    Static(&'static str),
    /// Text of the answer's own.
    Text(&'a [u8]),
}

impl FieldValue<'_> {
    /// The value's bytes.
    pub(crate) fn as_bytes(&self) -> &[u8] {
        match self {
            Self::Static(text) => text.as_bytes(),
            Self::Text(bytes) => bytes,
        }
    }
}

impl<'a> FileHead<'a> {
    /// The head of the answer for bytes `range` of a stored file of `len` bytes with `etag`,
    /// a metadata document or not ([`is_metadata`]): `206` (with `Content-Range`) for a
    /// part, `416` (with an empty body) for an unsatisfiable range, `200` for the whole file.
    pub(crate) fn part(len: u64, range: RangeRequest, etag: &'a str, metadata: bool) -> Self {
        let status = match range {
            RangeRequest::Whole => StatusCode::OK,
            RangeRequest::Part(..) => StatusCode::PARTIAL_CONTENT,
            RangeRequest::Unsatisfiable => StatusCode::RANGE_NOT_SATISFIABLE,
        };
        Self {
            status,
            etag,
            metadata,
            range: Some((len, range)),
        }
    }

    /// The head of the `304 Not Modified` answer for a file with `etag`, a metadata document
    /// or not.
    pub(crate) fn not_modified(etag: &'a str, metadata: bool) -> Self {
        Self {
            status: StatusCode::NOT_MODIFIED,
            etag,
            metadata,
            range: None,
        }
    }

    /// The answer's status.
    pub(crate) fn status(&self) -> StatusCode {
        self.status
    }

    /// Calls `field` with each header field, in order: `ETag`, `Cache-Control`, then (unless
    /// a `304`) `Accept-Ranges`, `Content-Type`, `Content-Range` (for a `206` or `416`) and
    /// `Content-Length` (of the body a `GET` gets; `0` for a `416`).
    pub(crate) fn fields(&self, mut field: impl FnMut(HeaderName, FieldValue<'_>)) {
        let (content_type, cache) = if self.metadata {
            ("application/json", CACHE_REVALIDATE)
        } else {
            ("application/octet-stream", CACHE_IMMUTABLE)
        };
        field(header::ETAG, FieldValue::Text(self.etag.as_bytes()));
        field(header::CACHE_CONTROL, FieldValue::Static(cache));
        let Some((len, range)) = self.range else {
            return;
        };
        field(header::ACCEPT_RANGES, FieldValue::Static("bytes"));
        field(header::CONTENT_TYPE, FieldValue::Static(content_type));
        // `Content-Range`, on the stack: at most `bytes A-B/C` of three 20-digit numbers.
        let mut text = std::io::Cursor::new([0u8; 72]);
        let sent = match range {
            RangeRequest::Whole => len,
            RangeRequest::Part(start, end) => {
                write!(text, "bytes {start}-{}/{len}", end - 1).expect("72 bytes suffice");
                end - start
            }
            RangeRequest::Unsatisfiable => {
                write!(text, "bytes */{len}").expect("72 bytes suffice");
                0
            }
        };
        if range != RangeRequest::Whole {
            let written = usize::try_from(text.position()).expect("at most 72");
            let value = &text.get_ref()[..written];
            field(header::CONTENT_RANGE, FieldValue::Text(value));
        }
        let mut number = itoa::Buffer::new();
        field(
            header::CONTENT_LENGTH,
            FieldValue::Text(number.format(sent).as_bytes()),
        );
    }

    /// The router's answer: this head, with `body`.
    pub(crate) fn response(&self, body: Body) -> Response<Body> {
        let mut response = Response::new(body);
        *response.status_mut() = self.status;
        let headers = response.headers_mut();
        self.fields(|name, value| {
            let value = match value {
                FieldValue::Static(text) => HeaderValue::from_static(text),
                FieldValue::Text(bytes) => {
                    HeaderValue::from_bytes(bytes).expect("an ETag, a range or a length")
                }
            };
            headers.append(name, value);
        });
        response
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
        // The same bytes as the `ETag` on one line match at once; on two lines, or beside
        // another field line, they match when the lines are read as RFC 9110's list.
        assert!(matches(&["\"a-1\"", "\"a-1\""]));
        assert!(matches(&["\"a-1\"", "garbage"]));
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

    /// `head`'s fields as text, in order.
    fn fields_of(head: &FileHead<'_>) -> Vec<(String, String)> {
        let mut fields = Vec::new();
        head.fields(|name, value| {
            let value = String::from_utf8(value.as_bytes().to_vec()).unwrap();
            fields.push((name.as_str().to_string(), value));
        });
        fields
    }

    #[test]
    fn file_heads_give_each_answer_its_fields_in_order_and_the_router_the_same() {
        let etag = "\"bf69-18e\"";
        let chunk = |rest: &[(&str, &str)]| {
            let mut fields = vec![
                ("etag", etag),
                ("cache-control", CACHE_IMMUTABLE),
                ("accept-ranges", "bytes"),
                ("content-type", "application/octet-stream"),
            ];
            fields.extend_from_slice(rest);
            fields
                .into_iter()
                .map(|(n, v)| (n.to_string(), v.to_string()))
                .collect::<Vec<_>>()
        };
        let cases = [
            (
                FileHead::part(49001, RangeRequest::Whole, etag, false),
                StatusCode::OK,
                chunk(&[("content-length", "49001")]),
            ),
            (
                FileHead::part(49001, RangeRequest::Part(100, 49001), etag, false),
                StatusCode::PARTIAL_CONTENT,
                chunk(&[
                    ("content-range", "bytes 100-49000/49001"),
                    ("content-length", "48901"),
                ]),
            ),
            (
                FileHead::part(49001, RangeRequest::Unsatisfiable, etag, false),
                StatusCode::RANGE_NOT_SATISFIABLE,
                chunk(&[("content-range", "bytes */49001"), ("content-length", "0")]),
            ),
            (
                FileHead::part(
                    u64::MAX,
                    RangeRequest::Part(u64::MAX - 2, u64::MAX),
                    etag,
                    false,
                ),
                StatusCode::PARTIAL_CONTENT,
                chunk(&[
                    (
                        "content-range",
                        "bytes 18446744073709551613-18446744073709551614/18446744073709551615",
                    ),
                    ("content-length", "2"),
                ]),
            ),
            (
                FileHead::not_modified(etag, false),
                StatusCode::NOT_MODIFIED,
                chunk(&[])[..2].to_vec(),
            ),
            (
                FileHead::not_modified(etag, true),
                StatusCode::NOT_MODIFIED,
                vec![
                    ("etag".into(), etag.into()),
                    ("cache-control".into(), CACHE_REVALIDATE.into()),
                ],
            ),
        ];
        for (head, status, fields) in cases {
            assert_eq!(head.status(), status);
            assert_eq!(fields_of(&head), fields);
            let response = head.response(Body::empty());
            assert_eq!(response.status(), status);
            let router: Vec<_> = response
                .headers()
                .iter()
                .map(|(n, v)| (n.as_str().to_string(), v.to_str().unwrap().to_string()))
                .collect();
            assert_eq!(router, fields);
        }
        let metadata = FileHead::part(17, RangeRequest::Whole, etag, true);
        assert_eq!(
            fields_of(&metadata)[1..4],
            [
                ("cache-control".to_string(), CACHE_REVALIDATE.to_string()),
                ("accept-ranges".to_string(), "bytes".to_string()),
                ("content-type".to_string(), "application/json".to_string()),
            ]
        );
    }

    #[test]
    fn metadata_keys() {
        assert!(is_metadata("0/zarr.json"));
        assert!(is_metadata(".zattrs"));
        assert!(!is_metadata("0/c/0/0/0/0"));
    }
}
