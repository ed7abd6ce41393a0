//! HTTP/1.1 connections, served here rather than by hyper so that chunk files can go to the
//! socket with `sendfile` (hyper only writes bytes it holds): request heads are parsed with
//! `httparse`; a GET or HEAD of a chunk of a folder store is answered by `routes::chunk_files`
//! without reading the file into memory, as is a revalidation of an object store's chunk whose
//! `ETag` it knows (a `304`); every other request goes to the router, and its
//! response is written back here. Keep-alive, pipelined requests, HTTP/1.0 clients, a
//! header-read timeout (a slow or idle client cannot hold a connection forever) and graceful
//! shutdown (a request being answered is finished) are handled here.

use std::fmt::Write as _;
use std::io;
use std::os::fd::AsRawFd;
use std::pin::Pin;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use axum::Router;
use axum::body::{Body, HttpBody};
use axum::http::header::{self, HeaderMap, HeaderName, HeaderValue};
use axum::http::{Method, Request, Response, StatusCode, Version};
use axum::response::IntoResponse;
use bytes::{Bytes, BytesMut};
use hyper::service::Service as _;
use hyper_util::service::TowerToHyperService;
use tokio::io::{AsyncReadExt, AsyncWriteExt, Interest};
use tokio::net::TcpStream;
use tokio::sync::watch;

use crate::metrics::Metrics;
use crate::page_cache;
use crate::routes::{self, AppState, ChunkAnswer, DirectChunks, ServerOptions};

/// The longest request head (request line and header fields) read: longer ones get a `431`.
const MAX_HEAD: usize = 64 << 10;
/// The most header fields in a request: more get a `431`.
const MAX_FIELDS: usize = 100;
/// The largest request body read (no route takes one; a body is read and passed on so that
/// the connection stays in step): larger ones get a `413` and the connection is closed.
const MAX_BODY: u64 = 1 << 20;
/// A response body up to this size is sent in the same write as its head.
const COALESCE: usize = 64 << 10;

/// What a connection serves: the router, and the direct path for chunk files.
#[derive(Clone)]
pub struct App {
    /// Every request the direct path does not answer.
    pub(crate) router: Router,
    /// Chunk keys answered without the router: a folder store's with `sendfile`, an object
    /// store's revalidations.
    pub(crate) chunks: DirectChunks,
    /// Where both record what they answer.
    pub(crate) metrics: Arc<Metrics>,
}

impl App {
    /// What the listener serves for `state`'s datasets: the router, and the direct path for
    /// chunk keys of folder stores, which adds the same CORS fields as the router (read from
    /// the router's CORS layer's answer to a `GET`).
    pub async fn new(state: Arc<AppState>, options: &ServerOptions) -> Self {
        let router = routes::router(state.clone(), options);
        let probe = Request::get("/")
            .body(Body::empty())
            .expect("a valid request");
        let with_cors = Router::new()
            .route("/", axum::routing::get(|| async {}))
            .layer(routes::cors());
        let answer = match TowerToHyperService::new(with_cors).call(probe).await {
            Ok(answer) => answer,
            Err(never) => match never {},
        };
        let mut cors = Vec::new();
        for (name, value) in answer.headers() {
            if name.as_str().starts_with("access-control-") || name == header::VARY {
                cors.extend_from_slice(name.as_str().as_bytes());
                cors.extend_from_slice(b": ");
                cors.extend_from_slice(value.as_bytes());
                cors.extend_from_slice(b"\r\n");
            }
        }
        Self {
            router,
            chunks: DirectChunks::new(state.clone(), options.token.as_deref(), cors),
            metrics: state.metrics.clone(),
        }
    }
}

/// A parsed request head. The target and the header fields' values are slices of the bytes
/// read, shared, not copied.
#[derive(Debug)]
struct Head {
    /// The method.
    method: Method,
    /// The request target as sent: path and query, still percent-encoded (UTF-8, as
    /// `httparse` checks).
    target: Bytes,
    /// HTTP/1.0 or HTTP/1.1.
    version: Version,
    /// The header fields.
    headers: HeaderMap,
    /// The body's length (`Content-Length`; 0 without one).
    body_len: u64,
}

impl Head {
    /// The request target as text.
    fn target(&self) -> &str {
        std::str::from_utf8(&self.target).unwrap_or_default()
    }
}

/// What reading a request head gave.
#[derive(Debug)]
enum Step {
    /// A complete head.
    Head(Head),
    /// The client closed the connection, stayed silent past the timeout between requests, or
    /// the server is shutting down: close without an answer.
    Close,
    /// A head that cannot be served: answer this status with this message, then close.
    Refuse(StatusCode, &'static str),
}

/// Serves requests on `stream` until the client closes it, a request asks to close it, the
/// header timeout passes or `shutdown` turns true between requests.
///
/// # Errors
/// The I/O error that ended the connection (a client that breaks off, a file that shrank
/// while it was being sent).
pub(crate) async fn connection(
    mut stream: TcpStream,
    app: App,
    header_timeout: Duration,
    mut shutdown: watch::Receiver<bool>,
) -> io::Result<()> {
    let mut buf = BytesMut::with_capacity(8 << 10);
    let mut out = Vec::with_capacity(1 << 10);
    let mut scratch = Scratch::default();
    // The header timeout's timer and the wait for shutdown, made once per connection: a new
    // timer and a new wait on the shared channel for every request would each be registered
    // and removed again per request; the timer is moved on instead (which, to a later
    // deadline, touches no timer wheel).
    let mut timer = std::pin::pin!(tokio::time::sleep(header_timeout));
    let stopping = shutdown.clone();
    let mut stopped = std::pin::pin!(async move {
        // A closed channel (the server gone) stops the connection as well.
        let _ = shutdown.changed().await;
    });
    // When the connection became ready for its next request: the header timeout counts from
    // here (the moment the last answer was recorded, so the clock is not read again for it).
    let mut ready = Instant::now();
    loop {
        let waits = Waits {
            deadline: ready + header_timeout,
            timer: timer.as_mut(),
            stopping: &stopping,
            stopped: stopped.as_mut(),
        };
        let step = read_head(&mut stream, &mut buf, &mut scratch, waits);
        let head = match step.await? {
            Step::Head(head) => head,
            Step::Close => return Ok(()),
            Step::Refuse(status, why) => {
                let answer = (status, why).into_response();
                write_response(
                    &mut stream,
                    &mut out,
                    answer,
                    &Method::GET,
                    Version::HTTP_11,
                    false,
                )
                .await?;
                let now = Instant::now();
                app.metrics.record(status, Some(why.len() as u64), now, now);
                return stream.shutdown().await;
            }
        };
        let started = Instant::now();
        let keep_alive = keeps_alive(&head) && !*stopping.borrow();
        let body = read_body(&mut stream, &mut buf, head.body_len).await?;
        let direct = (head.body_len == 0)
            .then(|| {
                app.chunks
                    .answer(&head.method, head.target(), &head.headers, started)
            })
            .flatten();
        // The answer's moment for its `Date`: the request's start, unless it waited for the
        // disk.
        let (direct, now) = match direct {
            Some(answer) if !answer.cached => (
                read_into_page_cache(answer, &app.metrics).await,
                Instant::now(),
            ),
            direct => (direct, started),
        };
        let keep_alive = if let Some(answer) = direct {
            out.clear();
            let file_head = answer.head();
            let status = file_head.status();
            // With the CORS fields the router's layer adds to every answer.
            let cors = app.chunks.cors();
            write_head(
                &mut out,
                status,
                head.version,
                keep_alive,
                cors,
                now,
                |out| {
                    file_head
                        .fields(|name, value| write_field(out, name.as_str(), value.as_bytes()));
                    false
                },
            );
            let sent = match answer.body() {
                Some((open, start, end)) if head.method != Method::HEAD => {
                    // The head waits for the file's first bytes (unless there are none).
                    send_head(&stream, &out, end > start).await?;
                    send_file(&stream, &open.file, start, end).await?;
                    Some(end - start)
                }
                _ => {
                    stream.write_all(&out).await?;
                    None
                }
            };
            ready = Instant::now();
            app.metrics.record(status, sent, started, ready);
            scratch.fields = head.headers;
            scratch.fields.clear();
            keep_alive
        } else {
            let (method, version) = (head.method.clone(), head.version);
            let (response, keep_alive) = match to_request(head, body) {
                Ok(request) => {
                    let service = TowerToHyperService::new(app.router.clone());
                    match service.call(request).await {
                        Ok(response) => (response, keep_alive),
                        Err(never) => match never {},
                    }
                }
                Err(why) => ((StatusCode::BAD_REQUEST, why).into_response(), false),
            };
            let keep_alive = write_response(
                &mut stream,
                &mut out,
                response,
                &method,
                version,
                keep_alive,
            )
            .await?;
            ready = Instant::now();
            keep_alive
        };
        if !keep_alive {
            return stream.shutdown().await;
        }
    }
}

/// `answer` once the page cache holds the bytes it sends, read into it on a blocking thread
/// (`page_cache::fill`, counted in `metrics`); `None` when they cannot be read: the router
/// then reads the key and answers its error.
async fn read_into_page_cache(answer: ChunkAnswer, metrics: &Metrics) -> Option<ChunkAnswer> {
    let (open, start, end) = answer.body()?;
    let file = Arc::clone(open);
    let filled = tokio::task::spawn_blocking(move || page_cache::fill(&file.file, start, end));
    match filled.await {
        Ok(Ok(())) => {
            metrics.chunks_read_from_disk.inc();
            open.saw_cached(start, end, Instant::now());
            Some(answer)
        }
        Ok(Err(e)) => {
            tracing::debug!("chunk not read into the page cache: {e}");
            None
        }
        // The runtime is shutting down.
        Err(_) => None,
    }
}

/// What reading a request head waits for besides the client: the header timeout, and the
/// server shutting down.
struct Waits<'a, S> {
    /// When the head must be complete.
    deadline: Instant,
    /// The connection's timer for it.
    timer: Pin<&'a mut tokio::time::Sleep>,
    /// Whether the server is shutting down.
    stopping: &'a watch::Receiver<bool>,
    /// The connection's wait for the server to start shutting down.
    stopped: Pin<&'a mut S>,
}

/// Reads until `buf` holds a complete request head (with [`parse_head`]), waiting until
/// `waits.deadline` at most; closes instead when the server shuts down while no request has begun.
async fn read_head<S: Future<Output = ()>>(
    stream: &mut TcpStream,
    buf: &mut BytesMut,
    scratch: &mut Scratch,
    waits: Waits<'_, S>,
) -> io::Result<Step> {
    let Waits {
        deadline,
        mut timer,
        stopping,
        mut stopped,
    } = waits;
    timer.as_mut().reset(deadline.into());
    loop {
        if !buf.is_empty() {
            match parse_head(buf, scratch) {
                Ok(Some(head)) => return Ok(Step::Head(head)),
                Ok(None) if buf.len() >= MAX_HEAD => {
                    return Ok(Step::Refuse(
                        StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
                        "request head too large\n",
                    ));
                }
                Ok(None) => {}
                Err((status, why)) => return Ok(Step::Refuse(status, why)),
            }
        }
        if buf.is_empty() && *stopping.borrow() {
            return Ok(Step::Close);
        }
        buf.reserve(8 << 10);
        tokio::select! {
            read = stream.read_buf(buf) => {
                if read? == 0 {
                    return Ok(Step::Close);
                }
            }
            () = timer.as_mut() => return Ok(Step::Close),
            () = stopped.as_mut(), if buf.is_empty() => return Ok(Step::Close),
        }
    }
}

/// Why a request head is refused: the status and the message answered.
type Refusal = (StatusCode, &'static str);

/// Where a part of a request head lies in it: a byte offset and a length.
#[derive(Clone, Copy, Debug)]
struct Span {
    at: usize,
    len: usize,
}

impl Span {
    /// Where `part`, a slice of `head`, lies in it (nowhere, an empty span, if it is not a
    /// slice of `head`).
    fn of(part: &[u8], head: &[u8]) -> Self {
        let at = (part.as_ptr() as usize).wrapping_sub(head.as_ptr() as usize);
        if at
            .checked_add(part.len())
            .is_some_and(|end| end <= head.len())
        {
            Self {
                at,
                len: part.len(),
            }
        } else {
            Self { at: 0, len: 0 }
        }
    }

    /// Its bytes' positions.
    fn range(self) -> std::ops::Range<usize> {
        self.at..self.at + self.len
    }
}

/// What a connection keeps from one request head to the next, so that parsing one allocates
/// nothing in the usual case (a request of standard header names after one the direct path
/// answered): the header map of that request (emptied), and where the fields lie in the head
/// being parsed. A request the router answers takes the map with it, and a name `http` does
/// not know is copied.
#[derive(Default)]
struct Scratch {
    /// The next head's header fields go here.
    fields: HeaderMap,
    /// Where each field's name and value lie in the head.
    spans: Vec<(Span, Span)>,
}

/// The request head at the start of `buf`, removed from it; `None` while it is incomplete.
/// Its header fields go into `scratch.fields` (emptied first), which the head takes: the
/// target and the field values are slices of the head's bytes, not copies.
fn parse_head(buf: &mut BytesMut, scratch: &mut Scratch) -> Result<Option<Head>, Refusal> {
    let bad = |why| (StatusCode::BAD_REQUEST, why);
    let mut parsed = [const { std::mem::MaybeUninit::uninit() }; MAX_FIELDS];
    let mut request = httparse::Request::new(&mut []);
    let len = match request.parse_with_uninit_headers(buf, &mut parsed) {
        Ok(httparse::Status::Complete(len)) => len,
        Ok(httparse::Status::Partial) => return Ok(None),
        Err(httparse::Error::TooManyHeaders) => {
            return Err((
                StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
                "too many header fields\n",
            ));
        }
        Err(_) => return Err(bad("malformed request head\n")),
    };
    let method = Method::from_bytes(request.method.unwrap_or_default().as_bytes())
        .map_err(|_| bad("malformed method\n"))?;
    let version = match request.version {
        Some(0) => Version::HTTP_10,
        _ => Version::HTTP_11,
    };
    // Where the target and each field lie, to take them from the head once it is split off.
    let read = &buf[..len];
    let target = Span::of(request.path.unwrap_or_default().as_bytes(), read);
    let spans = &mut scratch.spans;
    spans.clear();
    for field in request.headers.iter() {
        spans.push((
            Span::of(field.name.as_bytes(), read),
            Span::of(field.value, read),
        ));
    }
    let head = buf.split_to(len).freeze();
    let fields = &mut scratch.fields;
    fields.clear();
    fields.reserve(spans.len());
    for (name, value) in spans.iter() {
        let name = HeaderName::from_bytes(&head[name.range()])
            .map_err(|_| bad("malformed header field name\n"))?;
        let value = HeaderValue::from_maybe_shared(head.slice(value.range()))
            .map_err(|_| bad("malformed header field\n"))?;
        fields.append(name, value);
    }
    if fields.contains_key(header::TRANSFER_ENCODING) {
        // No route takes a body; one of unknown length cannot be skipped safely.
        return Err((
            StatusCode::LENGTH_REQUIRED,
            "request bodies need a Content-Length\n",
        ));
    }
    let mut lengths = fields.get_all(header::CONTENT_LENGTH).iter();
    let body_len = match (lengths.next(), lengths.next()) {
        (None, _) => 0,
        (Some(value), None) => value
            .to_str()
            .ok()
            .and_then(|v| v.trim().parse::<u64>().ok())
            .ok_or_else(|| bad("malformed Content-Length\n"))?,
        (Some(_), Some(_)) => return Err(bad("more than one Content-Length\n")),
    };
    if body_len > MAX_BODY {
        return Err((StatusCode::PAYLOAD_TOO_LARGE, "request body too large\n"));
    }
    Ok(Some(Head {
        method,
        target: head.slice(target.range()),
        version,
        headers: std::mem::take(fields),
        body_len,
    }))
}

/// Whether the connection stays open after answering `head`: HTTP/1.1 unless it says
/// `Connection: close`, HTTP/1.0 only if it says `Connection: keep-alive`.
fn keeps_alive(head: &Head) -> bool {
    let says = |token: &str| {
        head.headers.get_all(header::CONNECTION).iter().any(|v| {
            v.to_str()
                .is_ok_and(|v| v.split(',').any(|t| t.trim().eq_ignore_ascii_case(token)))
        })
    };
    match head.version {
        Version::HTTP_10 => says("keep-alive"),
        _ => !says("close"),
    }
}

/// The request's body: `len` bytes, from what `buf` holds and then the socket.
async fn read_body(stream: &mut TcpStream, buf: &mut BytesMut, len: u64) -> io::Result<Body> {
    if len == 0 {
        return Ok(Body::empty());
    }
    let len = len as usize;
    while buf.len() < len {
        buf.reserve(len - buf.len());
        if stream.read_buf(buf).await? == 0 {
            return Err(io::ErrorKind::UnexpectedEof.into());
        }
    }
    Ok(Body::from(buf.split_to(len).freeze()))
}

/// The router's request for `head`.
fn to_request(head: Head, body: Body) -> Result<Request<Body>, &'static str> {
    let mut request = Request::builder()
        .method(head.method)
        .uri(
            axum::http::Uri::from_maybe_shared(head.target)
                .map_err(|_| "malformed request target\n")?,
        )
        .version(head.version)
        .body(body)
        .map_err(|_| "malformed request target\n")?;
    *request.headers_mut() = head.headers;
    Ok(request)
}

/// Appends a head to `out`: the status line, the header fields `fields` writes (it says
/// whether they include a `Date`), a `Date` (of `now`) if not, the `Connection` field the
/// client needs to know whether the connection stays open, the fields `extra` (each ending in
/// CRLF) and the blank line.
fn write_head(
    out: &mut Vec<u8>,
    status: StatusCode,
    version: Version,
    keep_alive: bool,
    extra: &[u8],
    now: Instant,
    fields: impl FnOnce(&mut Vec<u8>) -> bool,
) {
    out.extend_from_slice(b"HTTP/1.1 ");
    out.extend_from_slice(status.as_str().as_bytes());
    out.push(b' ');
    out.extend_from_slice(status.canonical_reason().unwrap_or("").as_bytes());
    out.extend_from_slice(b"\r\n");
    if !fields(out) {
        write_field(out, "date", &http_date(now));
    }
    if !keep_alive {
        out.extend_from_slice(b"connection: close\r\n");
    } else if version == Version::HTTP_10 {
        out.extend_from_slice(b"connection: keep-alive\r\n");
    }
    out.extend_from_slice(extra);
    out.extend_from_slice(b"\r\n");
}

/// Appends the header field `name: value` and its CRLF to `out`.
fn write_field(out: &mut Vec<u8>, name: &str, value: &[u8]) {
    out.extend_from_slice(name.as_bytes());
    out.extend_from_slice(b": ");
    out.extend_from_slice(value);
    out.extend_from_slice(b"\r\n");
}

/// Writes the router's `response` to a request with `method` and `version`: with the length
/// it announces or its body's exact size, else chunked (HTTP/1.1) or delimited by closing the
/// connection (HTTP/1.0). Returns whether the connection stays open.
async fn write_response(
    stream: &mut TcpStream,
    out: &mut Vec<u8>,
    mut response: Response<Body>,
    method: &Method,
    version: Version,
    mut keep_alive: bool,
) -> io::Result<bool> {
    let status = response.status();
    let no_body = *method == Method::HEAD
        || status.is_informational()
        || status == StatusCode::NO_CONTENT
        || status == StatusCode::NOT_MODIFIED;
    if status == StatusCode::NOT_MODIFIED {
        // A 304's length would be the representation's, not 0 (RFC 9110, 8.6): say none.
        response.headers_mut().remove(header::CONTENT_LENGTH);
    }
    let announced = response.headers().contains_key(header::CONTENT_LENGTH);
    let mut chunked = false;
    if !announced && !no_body {
        if let Some(len) = response.body().size_hint().exact() {
            response
                .headers_mut()
                .insert(header::CONTENT_LENGTH, HeaderValue::from(len));
        } else if version == Version::HTTP_11 {
            response.headers_mut().insert(
                header::TRANSFER_ENCODING,
                HeaderValue::from_static("chunked"),
            );
            chunked = true;
        } else {
            keep_alive = false;
        }
    }
    out.clear();
    write_head(
        out,
        status,
        version,
        keep_alive,
        b"",
        Instant::now(),
        |out| {
            for (name, value) in response.headers() {
                write_field(out, name.as_str(), value.as_bytes());
            }
            response.headers().contains_key(header::DATE)
        },
    );
    if no_body {
        stream.write_all(out).await?;
        return Ok(keep_alive);
    }
    let mut body = response.into_body();
    loop {
        let frame = std::future::poll_fn(|cx| Pin::new(&mut body).poll_frame(cx)).await;
        let Some(frame) = frame else { break };
        let frame = frame.map_err(io::Error::other)?;
        let Ok(data) = frame.into_data() else {
            continue;
        };
        if data.is_empty() {
            continue;
        }
        if chunked {
            let _ = write!(ChunkSize(out), "{:x}\r\n", data.len());
        }
        if out.len() + data.len() <= COALESCE {
            out.extend_from_slice(&data);
        } else {
            stream.write_all(out).await?;
            out.clear();
            stream.write_all(&data).await?;
        }
        if chunked {
            out.extend_from_slice(b"\r\n");
        }
    }
    if chunked {
        out.extend_from_slice(b"0\r\n\r\n");
    }
    if !out.is_empty() {
        stream.write_all(out).await?;
    }
    Ok(keep_alive)
}

/// `fmt::Write` into a byte buffer, for a chunk's size line.
struct ChunkSize<'a>(&'a mut Vec<u8>);

impl std::fmt::Write for ChunkSize<'_> {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        self.0.extend_from_slice(s.as_bytes());
        Ok(())
    }
}

/// Writes `head` to `stream`; with `more`, flagged `MSG_MORE`: the kernel holds its partial
/// segment until the next write (the file's `sendfile`, whose last piece pushes), so that a
/// head and the start of its file leave in one segment (as nginx's `tcp_nopush` does), in one
/// system call instead of setting and clearing `TCP_CORK` around it.
///
/// # Errors
/// The socket's error.
async fn send_head(stream: &TcpStream, head: &[u8], more: bool) -> io::Result<()> {
    let flags = libc::MSG_NOSIGNAL | if more { libc::MSG_MORE } else { 0 };
    let mut written = 0;
    while written < head.len() {
        stream.writable().await?;
        let rest = &head[written..];
        let sent = stream.try_io(Interest::WRITABLE, || {
            // SAFETY: a valid socket, and a pointer to `rest.len()` readable bytes.
            let n =
                unsafe { libc::send(stream.as_raw_fd(), rest.as_ptr().cast(), rest.len(), flags) };
            usize::try_from(n).map_err(|_| io::Error::last_os_error())
        });
        match sent {
            Ok(n) => written += n,
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// Sends bytes `start..end` of `file` to `stream` with `sendfile`: from the page cache to
/// the socket, never through this process's memory. Its last piece pushes what
/// [`send_head`] held.
///
/// # Errors
/// The socket's error, or `UnexpectedEof` when the file is shorter than `end`.
async fn send_file(
    stream: &TcpStream,
    file: &std::fs::File,
    start: u64,
    end: u64,
) -> io::Result<()> {
    let mut offset = start as libc::off_t;
    let end = end as libc::off_t;
    while offset < end {
        stream.writable().await?;
        let sent = stream.try_io(Interest::WRITABLE, || {
            let count = (end - offset).min(1 << 30) as usize;
            // SAFETY: two open descriptors and a pointer to the offset, which the kernel
            // advances by what it sent.
            let n = unsafe {
                libc::sendfile(stream.as_raw_fd(), file.as_raw_fd(), &raw mut offset, count)
            };
            if n < 0 {
                Err(io::Error::last_os_error())
            } else {
                Ok(n)
            }
        });
        match sent {
            Ok(0) => {
                return Err(io::Error::new(
                    io::ErrorKind::UnexpectedEof,
                    "the file is shorter than when it was opened",
                ));
            }
            Ok(_) => {}
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// The `Date` field value at `now` (a moment just past: the request's start), formatted
/// once a second per thread: until the second it was formatted in ends, by the monotonic
/// clock, it is reused without reading the clock again.
fn http_date(now: Instant) -> [u8; 29] {
    thread_local! {
        static DATE: std::cell::Cell<Option<(Instant, [u8; 29])>> = const { std::cell::Cell::new(None) };
    }
    DATE.with(|cell| {
        if let Some((until, text)) = cell.get()
            && now < until
        {
            return text;
        }
        let wall = SystemTime::now();
        let into_second = wall
            .duration_since(SystemTime::UNIX_EPOCH)
            .map_or(Duration::ZERO, |d| {
                Duration::from_nanos(d.subsec_nanos().into())
            });
        // `now` is no later than the clock read just now, so `until` is no later than the end
        // of that second: a cached date is never one second behind.
        let until = now + Duration::from_secs(1).saturating_sub(into_second);
        let mut text = [0u8; 29];
        text.copy_from_slice(&httpdate::fmt_http_date(wall).as_bytes()[..29]);
        cell.set(Some((until, text)));
        text
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parsed(text: &str) -> Result<Option<Head>, Refusal> {
        let mut buf = BytesMut::from(text.as_bytes());
        parse_head(&mut buf, &mut Scratch::default())
    }

    fn refusal(text: &str) -> Refusal {
        match parsed(text) {
            Err(refusal) => refusal,
            Ok(_) => panic!("{text:?} was not refused"),
        }
    }

    #[test]
    fn heads_parse_with_their_fields_and_leave_what_follows() {
        let mut buf = BytesMut::from(
            &b"GET /d/0/c/0/0/0?x=1 HTTP/1.1\r\nHost: a\r\nX-Two: 1\r\nX-Two: 2\r\n\r\nGET /next"[..],
        );
        let read = buf.as_ptr() as usize..buf.as_ptr() as usize + buf.len();
        let head = parse_head(&mut buf, &mut Scratch::default())
            .unwrap()
            .unwrap();
        // The target and the values are the bytes read, not copies of them.
        let within = |bytes: &[u8]| read.contains(&(bytes.as_ptr() as usize));
        assert!(within(&head.target));
        assert!(head.headers.values().all(|v| within(v.as_bytes())));
        assert_eq!(head.method, Method::GET);
        assert_eq!(head.target(), "/d/0/c/0/0/0?x=1");
        assert_eq!(head.version, Version::HTTP_11);
        assert_eq!(head.body_len, 0);
        let twos: Vec<_> = head.headers.get_all("x-two").iter().collect();
        assert_eq!(twos, ["1", "2"]);
        assert_eq!(&buf[..], b"GET /next");
        assert!(
            parsed("GET /d/x HTTP/1.1\r\nHost: a\r\n")
                .unwrap()
                .is_none()
        );
    }

    #[test]
    fn a_connections_next_head_keeps_none_of_the_last_ones_fields() {
        let mut scratch = Scratch::default();
        let mut buf = BytesMut::from(
            &b"GET /d/0/c/0 HTTP/1.1\r\nRange: bytes=0-9\r\nX-A: 1\r\nIf-None-Match: \"t\"\r\n\r\n"
                [..],
        );
        let first = parse_head(&mut buf, &mut scratch).unwrap().unwrap();
        assert_eq!(first.headers.len(), 3);
        // Handed back as the direct path hands it back.
        scratch.fields = first.headers;
        scratch.fields.clear();
        buf.extend_from_slice(b"GET /d/0/c/1 HTTP/1.1\r\nHost: a\r\nX-E:\r\nX-F:   \r\n\r\n");
        let second = parse_head(&mut buf, &mut scratch).unwrap().unwrap();
        assert_eq!(second.target(), "/d/0/c/1");
        let fields: Vec<_> = second
            .headers
            .iter()
            .map(|(n, v)| (n.as_str(), v.to_str().unwrap()))
            .collect();
        assert_eq!(fields, [("host", "a"), ("x-e", ""), ("x-f", "")]);
        assert!(buf.is_empty());
    }

    #[test]
    fn heads_that_cannot_be_served_are_refused_with_the_reason() {
        assert_eq!(
            refusal("GET /x HTTP/1.1\r\nTransfer-Encoding: chunked\r\n\r\n"),
            (
                StatusCode::LENGTH_REQUIRED,
                "request bodies need a Content-Length\n"
            )
        );
        assert_eq!(
            refusal("GET /x HTTP/1.1\r\nContent-Length: 1\r\nContent-Length: 2\r\n\r\n"),
            (StatusCode::BAD_REQUEST, "more than one Content-Length\n")
        );
        assert_eq!(
            refusal("GET /x HTTP/1.1\r\nContent-Length: x\r\n\r\n"),
            (StatusCode::BAD_REQUEST, "malformed Content-Length\n")
        );
        assert_eq!(
            refusal("GET /x HTTP/1.1\r\nContent-Length: 1048577\r\n\r\n"),
            (StatusCode::PAYLOAD_TOO_LARGE, "request body too large\n")
        );
        assert_eq!(
            refusal("GET /x HTTP/1.1\r\nBad Name: x\r\n\r\n"),
            (StatusCode::BAD_REQUEST, "malformed request head\n")
        );
        let many = "X-Many: 1\r\n".repeat(MAX_FIELDS + 1);
        assert_eq!(
            refusal(&format!("GET /x HTTP/1.1\r\n{many}\r\n")),
            (
                StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
                "too many header fields\n"
            )
        );
    }

    #[test]
    fn keep_alive_follows_the_version_and_the_connection_field() {
        let keeps = |text: &str| keeps_alive(&parsed(text).unwrap().unwrap());
        assert!(keeps("GET / HTTP/1.1\r\n\r\n"));
        assert!(!keeps("GET / HTTP/1.1\r\nConnection: Close\r\n\r\n"));
        assert!(!keeps("GET / HTTP/1.1\r\nConnection: te, close\r\n\r\n"));
        assert!(!keeps("GET / HTTP/1.0\r\n\r\n"));
        assert!(keeps("GET / HTTP/1.0\r\nConnection: keep-alive\r\n\r\n"));
    }

    #[test]
    fn the_date_is_an_http_date_of_now() {
        let text = http_date(Instant::now());
        let text = std::str::from_utf8(&text).unwrap();
        let parsed = httpdate::parse_http_date(text).unwrap();
        let age = SystemTime::now().duration_since(parsed).unwrap();
        assert!(age < Duration::from_secs(2), "{text}");
    }
}
