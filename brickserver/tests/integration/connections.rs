//! Connections as clients make them, over TCP to `serve` in process: chunk keys of a folder
//! store answered directly (with `sendfile`), and revalidations of an object store's chunks,
//! give the router's answer field for field and byte for byte; keep-alive, pipelining, HTTP/1.0, refused heads, the header timeout, metrics and
//! graceful shutdown; and the binary's way of serving, one thread per listener on one port.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use residency_brickserver::{
    App, AppState, ConnectionLimits, Dataset, Datasets, ServerOptions, serve, serve_on_threads,
    shared_port_listeners,
};
use residency_store::location::object_store::ObjectStoreExt as _;
use residency_store::location::object_store::memory::InMemory;
use residency_store::location::object_store::path::Path as ObjectPath;
use residency_store::location::{ObjectStoreOptions, StoreLocation};
use tokio::sync::oneshot;

use crate::common::{self, CHUNK, v3_store};

/// A server on a loopback port, in its own runtime; dropping it shuts it down gracefully.
struct Served {
    addr: String,
    stop: Option<oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
    router: axum::Router,
    runtime: Arc<tokio::runtime::Runtime>,
}

impl Served {
    /// Shuts the server down and waits until `serve` returns; how long that took.
    fn stop(&mut self) -> Duration {
        let started = Instant::now();
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(thread) = self.thread.take() {
            thread.join().unwrap();
        }
        started.elapsed()
    }

    /// The router's own answer to `GET path` with `headers`.
    fn router_get(&self, path: &str, headers: &[(&str, &str)]) -> common::Answer {
        self.runtime
            .block_on(common::get(&self.router, path, headers))
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        self.stop();
    }
}

/// A runtime of two worker threads for a server.
fn runtime() -> Arc<tokio::runtime::Runtime> {
    Arc::new(
        tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .unwrap(),
    )
}

/// Serves `stores` (NAME, path) on a loopback port with `limits`, on one runtime (`serve`).
fn start(stores: &[(&str, &Path)], options: ServerOptions, limits: ConnectionLimits) -> Served {
    start_with(stores, options, limits, None)
}

/// Serves `stores` as [`start`] does, or with `threads: Some(n)` as the binary does: `n`
/// threads with a runtime and a listener each on one port (`serve_on_threads`).
fn start_with(
    stores: &[(&str, &Path)],
    options: ServerOptions,
    limits: ConnectionLimits,
    threads: Option<usize>,
) -> Served {
    let runtime = runtime();
    let named: Vec<String> = stores
        .iter()
        .map(|(n, p)| format!("{n}={}", p.display()))
        .collect();
    let datasets = runtime.block_on(async {
        Datasets::from_args(&[], &named, &ObjectStoreOptions::default())
            .await
            .unwrap()
    });
    start_datasets(runtime, datasets, options, limits, threads)
}

/// Serves `datasets` on `runtime` as [`start_with`] does.
fn start_datasets(
    runtime: Arc<tokio::runtime::Runtime>,
    datasets: Datasets,
    options: ServerOptions,
    limits: ConnectionLimits,
    threads: Option<usize>,
) -> Served {
    let (app, router) = runtime.block_on(async {
        let state = Arc::new(AppState::new(datasets, &options).unwrap());
        let router = residency_brickserver::router(state.clone(), &options);
        let app = App::new(state, &options).await;
        (app, router)
    });
    let loopback = "127.0.0.1:0".parse().unwrap();
    let listeners = shared_port_listeners(loopback, threads.unwrap_or(1)).unwrap();
    let addr = listeners[0].local_addr().unwrap().to_string();
    let (stop, stopped) = oneshot::channel::<()>();
    let rt = runtime.clone();
    let metrics = Arc::new(residency_brickserver::metrics::Metrics::default());
    let stopped = async {
        let _ = stopped.await;
    };
    let thread = std::thread::spawn(move || match threads {
        Some(_) => rt
            .block_on(serve_on_threads(
                listeners, app, limits, metrics, 4, stopped,
            ))
            .unwrap(),
        None => rt.block_on(async {
            let [listener] = <[_; 1]>::try_from(listeners).unwrap();
            listener.set_nonblocking(true).unwrap();
            let listener = tokio::net::TcpListener::from_std(listener).unwrap();
            serve(listener, app, limits, metrics, stopped).await;
        }),
    });
    Served {
        addr,
        stop: Some(stop),
        thread: Some(thread),
        router,
        runtime,
    }
}

/// A response read off a connection.
#[derive(Debug)]
struct Reply {
    status: u16,
    /// Header fields, names lowercased, in order.
    fields: Vec<(String, String)>,
    body: Vec<u8>,
}

impl Reply {
    fn field(&self, name: &str) -> Option<&str> {
        self.fields
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    }
}

/// Reads one response to a request with `method` (a `HEAD`'s has no body).
fn read_reply(reader: &mut BufReader<TcpStream>, method: &str) -> Reply {
    let mut line = String::new();
    reader.read_line(&mut line).unwrap();
    assert!(line.starts_with("HTTP/1.1 "), "status line {line:?}");
    let status = line[9..12].parse().unwrap();
    let mut fields = Vec::new();
    loop {
        let mut line = String::new();
        reader.read_line(&mut line).unwrap();
        let line = line.trim_end();
        if line.is_empty() {
            break;
        }
        let (name, value) = line.split_once(": ").expect("a field");
        fields.push((name.to_ascii_lowercase(), value.to_string()));
    }
    let mut reply = Reply {
        status,
        fields,
        body: Vec::new(),
    };
    if method == "HEAD" || status == 304 {
        return reply;
    }
    if reply.field("transfer-encoding") == Some("chunked") {
        loop {
            let mut size = String::new();
            reader.read_line(&mut size).unwrap();
            let size = usize::from_str_radix(size.trim_end(), 16).unwrap();
            let mut chunk = vec![0; size + 2];
            reader.read_exact(&mut chunk).unwrap();
            if size == 0 {
                break;
            }
            reply.body.extend_from_slice(&chunk[..size]);
        }
    } else if let Some(len) = reply.field("content-length") {
        let mut body = vec![0; len.parse().unwrap()];
        reader.read_exact(&mut body).unwrap();
        reply.body = body;
    } else {
        reader.read_to_end(&mut reply.body).unwrap();
    }
    reply
}

/// A connection to `served`, with a reader over it.
fn connect(served: &Served) -> (TcpStream, BufReader<TcpStream>) {
    let stream = TcpStream::connect(&served.addr).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    let reader = BufReader::new(stream.try_clone().unwrap());
    (stream, reader)
}

/// Sends `request` (a whole request head) on a new connection and reads the reply.
fn exchange(served: &Served, method: &str, request: &str) -> Reply {
    let (mut stream, mut reader) = connect(served);
    stream.write_all(request.as_bytes()).unwrap();
    read_reply(&mut reader, method)
}

/// Whether the server closed the connection (a read gives end of file).
fn closed(reader: &mut BufReader<TcpStream>) -> bool {
    let mut rest = Vec::new();
    matches!(reader.read_to_end(&mut rest), Ok(0))
}

fn served_store(dir: &Path) -> Served {
    let store = v3_store(dir, "cells");
    common::write(&store, "0/c/1/0/0/0", vec![7u8; 100_000]);
    common::write(&store, "0/c/2/0/0/0", Vec::new());
    start(
        &[("cells", &store)],
        ServerOptions::default(),
        ConnectionLimits::default(),
    )
}

/// The fields an answer over the wire has beyond the router's: `date`, `connection`.
fn router_fields(reply: &Reply) -> Vec<(String, String)> {
    reply
        .fields
        .iter()
        .filter(|(n, _)| n != "date" && n != "connection")
        .cloned()
        .collect()
}

#[test]
fn chunks_sent_directly_are_the_routers_answers_field_for_field() {
    let dir = tempfile::tempdir().unwrap();
    let served = served_store(dir.path());
    let etag = served.router_get("/cells/0/c/0/0/0/0", &[]);
    let etag = etag.header("etag").to_string();
    // (method, extra request fields) for each kind of answer: 200, 206, 416, 304, HEAD.
    let cases: [(&str, &[(&str, &str)]); 5] = [
        ("GET", &[]),
        ("GET", &[("range", "bytes=4-9")]),
        ("GET", &[("range", "bytes=900-")]),
        ("GET", &[("if-none-match", etag.as_str())]),
        ("HEAD", &[]),
    ];
    for (method, fields) in cases {
        let mut request = format!("{method} /cells/0/c/0/0/0/0 HTTP/1.1\r\nHost: x\r\n");
        for (name, value) in fields {
            request.push_str(&[*name, ": ", *value, "\r\n"].concat());
        }
        request.push_str("\r\n");
        let direct = exchange(&served, method, &request);
        let routed = if method == "HEAD" {
            served.runtime.block_on(common::request(
                &served.router,
                "HEAD",
                "/cells/0/c/0/0/0/0",
                fields,
            ))
        } else {
            served.router_get("/cells/0/c/0/0/0/0", fields)
        };
        // A 304 announces no length on the wire (the router's says 0, which the connection
        // drops).
        let routed_fields: Vec<(String, String)> = routed
            .headers
            .iter()
            .filter(|(n, _)| routed.status != 304 || *n != "content-length")
            .map(|(n, v)| (n.to_string(), v.to_str().unwrap().to_string()))
            .collect();
        let mut wire = router_fields(&direct);
        let mut expected = routed_fields;
        wire.sort();
        expected.sort();
        assert_eq!(direct.status, routed.status.as_u16(), "{method} {fields:?}");
        assert_eq!(wire, expected, "{method} {fields:?}");
        assert_eq!(direct.body, routed.body, "{method} {fields:?}");
        assert!(direct.field("date").is_some());
    }
    // What each answered, exactly: the fields of a 200, and of a 304 only what RFC 9110 asks it
    // to repeat (no `Accept-Ranges`), with the CORS fields; no `Vary` (no answer depends on
    // the request's origin).
    let names =
        |reply: &Reply| -> Vec<String> { reply.fields.iter().map(|(n, _)| n.clone()).collect() };
    let whole = exchange(&served, "GET", "GET /cells/0/c/0/0/0/0 HTTP/1.1\r\n\r\n");
    assert_eq!((whole.status, whole.body.as_slice()), (200, CHUNK));
    assert_eq!(whole.field("access-control-allow-origin"), Some("*"));
    assert_eq!(
        names(&whole),
        [
            "etag",
            "cache-control",
            "accept-ranges",
            "content-type",
            "content-length",
            "date",
            "access-control-expose-headers",
            "access-control-allow-origin",
        ]
    );
    let revalidated = exchange(
        &served,
        "GET",
        &format!("GET /cells/0/c/0/0/0/0 HTTP/1.1\r\nIf-None-Match: {etag}\r\n\r\n"),
    );
    assert_eq!(revalidated.status, 304);
    assert_eq!(
        names(&revalidated),
        [
            "etag",
            "cache-control",
            "date",
            "access-control-expose-headers",
            "access-control-allow-origin",
        ]
    );
    let part = exchange(
        &served,
        "GET",
        "GET /cells/0/c/0/0/0/0 HTTP/1.1\r\nRange: bytes=4-9\r\n\r\n",
    );
    assert_eq!((part.status, part.body.as_slice()), (206, &CHUNK[4..10]));
    assert_eq!(part.field("content-range"), Some("bytes 4-9/39"));
    // A larger chunk, sent in more than one piece of the socket's buffer.
    let big = exchange(&served, "GET", "GET /cells/0/c/1/0/0/0 HTTP/1.1\r\n\r\n");
    assert_eq!(big.body, vec![7u8; 100_000]);
    // An empty chunk: its head alone (nothing follows it to carry it out), then the next
    // answer on the same connection.
    let (mut stream, mut reader) = connect(&served);
    stream
        .write_all(
            b"GET /cells/0/c/2/0/0/0 HTTP/1.1\r\n\r\nGET /cells/0/c/0/0/0/0 HTTP/1.1\r\n\r\n",
        )
        .unwrap();
    let empty = read_reply(&mut reader, "GET");
    assert_eq!(
        (empty.status, empty.field("content-length")),
        (200, Some("0"))
    );
    assert!(empty.body.is_empty());
    assert_eq!(read_reply(&mut reader, "GET").body, CHUNK);
}

#[test]
fn an_object_stores_revalidations_are_the_routers_answers_field_for_field() {
    // Dataset `cells` from an object store (in memory: the code path of an `s3://` dataset).
    let runtime = runtime();
    let objects = InMemory::new();
    runtime
        .block_on(objects.put(&ObjectPath::from("cells/0/c/0/0/0"), CHUNK.to_vec().into()))
        .unwrap();
    let datasets = Datasets(vec![Dataset {
        name: "cells".into(),
        location: StoreLocation::S3 {
            bucket: "bucket".into(),
            prefix: "cells".into(),
        },
        object_store: Some((Arc::new(objects), ObjectPath::from("cells"))),
    }]);
    let served = start_datasets(
        runtime,
        datasets,
        ServerOptions::default(),
        ConnectionLimits::default(),
        None,
    );
    let whole = exchange(&served, "GET", "GET /cells/0/c/0/0/0 HTTP/1.1\r\n\r\n");
    assert_eq!((whole.status, whole.body.as_slice()), (200, CHUNK));
    let etag = whole.field("etag").unwrap().to_string();
    // Within REVALIDATE of that read, a revalidation is answered on the connection (the
    // direct path, `routes::chunk_files`), with the router's fields.
    let request = format!("GET /cells/0/c/0/0/0 HTTP/1.1\r\nIf-None-Match: {etag}\r\n\r\n");
    let direct = exchange(&served, "GET", &request);
    let routed = served.router_get("/cells/0/c/0/0/0", &[("if-none-match", etag.as_str())]);
    assert_eq!((direct.status, routed.status.as_u16()), (304, 304));
    let mut expected: Vec<(String, String)> = routed
        .headers
        .iter()
        .filter(|(n, _)| *n != "content-length")
        .map(|(n, v)| (n.to_string(), v.to_str().unwrap().to_string()))
        .collect();
    let mut wire = router_fields(&direct);
    wire.sort();
    expected.sort();
    assert_eq!(wire, expected);
    let names: Vec<&str> = direct.fields.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        names,
        [
            "etag",
            "cache-control",
            "date",
            "access-control-expose-headers",
            "access-control-allow-origin",
        ]
    );
    assert_eq!(direct.field("etag"), Some(etag.as_str()));
    assert!(direct.body.is_empty());
    // Another tag is answered by the router, with the bytes.
    let other = exchange(
        &served,
        "GET",
        "GET /cells/0/c/0/0/0 HTTP/1.1\r\nIf-None-Match: \"other\"\r\n\r\n",
    );
    assert_eq!((other.status, other.body.as_slice()), (200, CHUNK));
}

#[test]
fn other_requests_reach_the_router_on_the_same_connection() {
    let dir = tempfile::tempdir().unwrap();
    let served = served_store(dir.path());
    let (mut stream, mut reader) = connect(&served);
    // Pipelined: a chunk (direct), metadata, a missing chunk and the listing (routed), and a
    // chunk again, in one write, answered in order.
    stream
        .write_all(
            b"GET /cells/0/c/0/0/0/0 HTTP/1.1\r\n\r\n\
              GET /cells/zarr.json HTTP/1.1\r\n\r\n\
              GET /cells/0/c/0/1/1/1 HTTP/1.1\r\n\r\n\
              GET /datasets HTTP/1.1\r\nAccept: application/json\r\n\r\n\
              GET /cells/0/c/0/0/0/0 HTTP/1.1\r\n\r\n",
        )
        .unwrap();
    let first = read_reply(&mut reader, "GET");
    assert_eq!((first.status, first.body.as_slice()), (200, CHUNK));
    let meta = read_reply(&mut reader, "GET");
    assert_eq!(meta.status, 200);
    assert_eq!(
        meta.body,
        std::fs::read(dir.path().join("cells.ome.zarr/zarr.json")).unwrap()
    );
    assert_eq!(meta.field("cache-control"), Some("public, no-cache"));
    let missing = read_reply(&mut reader, "GET");
    assert_eq!(missing.status, 404);
    assert_eq!(missing.body, b"no key '0/c/0/1/1/1' in 'cells'\n");
    let listing = read_reply(&mut reader, "GET");
    assert_eq!(listing.status, 200);
    assert!(String::from_utf8_lossy(&listing.body).contains("\"cells\""));
    let again = read_reply(&mut reader, "GET");
    assert_eq!((again.status, again.body.as_slice()), (200, CHUNK));
    // A query string goes to the router, which serves the key all the same.
    let queried = exchange(
        &served,
        "GET",
        "GET /cells/0/c/0/0/0/0?v=1 HTTP/1.1\r\n\r\n",
    );
    assert_eq!((queried.status, queried.body.as_slice()), (200, CHUNK));
}

#[test]
fn pipelined_chunk_requests_keep_none_of_the_last_ones_fields() {
    let dir = tempfile::tempdir().unwrap();
    let served = served_store(dir.path());
    let etag = exchange(&served, "GET", "GET /cells/0/c/0/0/0/0 HTTP/1.1\r\n\r\n")
        .field("etag")
        .unwrap()
        .to_string();
    let (mut stream, mut reader) = connect(&served);
    // All answered directly, on one connection, each with the fields of its own request only:
    // a part, the whole, a revalidation, the whole again.
    let requests = format!(
        "GET /cells/0/c/0/0/0/0 HTTP/1.1\r\nRange: bytes=2-5\r\n\r\n\
         GET /cells/0/c/0/0/0/0 HTTP/1.1\r\n\r\n\
         GET /cells/0/c/0/0/0/0 HTTP/1.1\r\nIf-None-Match: {etag}\r\n\r\n\
         GET /cells/0/c/0/0/0/0 HTTP/1.1\r\n\r\n"
    );
    stream.write_all(requests.as_bytes()).unwrap();
    let part = read_reply(&mut reader, "GET");
    assert_eq!((part.status, part.body.as_slice()), (206, &CHUNK[2..6]));
    let names: Vec<_> = part.fields.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        names[..7],
        [
            "etag",
            "cache-control",
            "accept-ranges",
            "content-type",
            "content-range",
            "content-length",
            "date"
        ]
    );
    assert_eq!(
        part.field("content-range"),
        Some(format!("bytes 2-5/{}", CHUNK.len()).as_str())
    );
    let whole = read_reply(&mut reader, "GET");
    assert_eq!((whole.status, whole.body.as_slice()), (200, CHUNK));
    assert_eq!(whole.field("content-range"), None);
    let revalidated = read_reply(&mut reader, "GET");
    assert_eq!((revalidated.status, revalidated.body.len()), (304, 0));
    let again = read_reply(&mut reader, "GET");
    assert_eq!((again.status, again.body.as_slice()), (200, CHUNK));
    assert_eq!(again.field("etag"), Some(etag.as_str()));
}

#[test]
fn connections_close_when_asked_and_after_http_1_0() {
    let dir = tempfile::tempdir().unwrap();
    let served = served_store(dir.path());
    for (request, connection) in [
        ("GET /cells/0/c/0/0/0/0 HTTP/1.0\r\n\r\n", "close"),
        ("GET /cells/zarr.json HTTP/1.0\r\n\r\n", "close"),
        (
            "GET /cells/0/c/0/0/0/0 HTTP/1.1\r\nConnection: close\r\n\r\n",
            "close",
        ),
    ] {
        let (mut stream, mut reader) = connect(&served);
        stream.write_all(request.as_bytes()).unwrap();
        let reply = read_reply(&mut reader, "GET");
        assert_eq!(reply.status, 200, "{request}");
        assert_eq!(reply.field("connection"), Some(connection), "{request}");
        assert!(closed(&mut reader), "{request}");
    }
    // HTTP/1.0 with keep-alive stays open, and says so.
    let (mut stream, mut reader) = connect(&served);
    for _ in 0..2 {
        stream
            .write_all(b"GET /cells/0/c/0/0/0/0 HTTP/1.0\r\nConnection: keep-alive\r\n\r\n")
            .unwrap();
        let reply = read_reply(&mut reader, "GET");
        assert_eq!(reply.body, CHUNK);
        assert_eq!(reply.field("connection"), Some("keep-alive"));
    }
}

#[test]
fn heads_that_cannot_be_served_get_their_status_and_the_connection_closes() {
    let dir = tempfile::tempdir().unwrap();
    let served = served_store(dir.path());
    for (request, status, message) in [
        (
            "GET /cells/0/c/0/0/0/0 HTTP/1.1\r\nTransfer-Encoding: chunked\r\n\r\n0\r\n\r\n",
            411,
            "request bodies need a Content-Length\n",
        ),
        (
            "GET /x HTTP/1.1\r\nBad Field\r\n\r\n",
            400,
            "malformed request head\n",
        ),
        ("GET\0 / HTTP/1.1\r\n\r\n", 400, "malformed request head\n"),
    ] {
        let (mut stream, mut reader) = connect(&served);
        stream.write_all(request.as_bytes()).unwrap();
        let reply = read_reply(&mut reader, "GET");
        assert_eq!(
            (reply.status, String::from_utf8_lossy(&reply.body).as_ref()),
            (status, message),
            "{request:?}"
        );
        assert_eq!(reply.field("connection"), Some("close"));
        assert!(closed(&mut reader), "{request:?}");
    }
    // A request with a body (which no route reads) keeps the connection in step.
    let (mut stream, mut reader) = connect(&served);
    stream
        .write_all(
            b"GET /cells/0/c/0/0/0/0 HTTP/1.1\r\nContent-Length: 5\r\n\r\nhello\
              GET /cells/0/c/0/0/0/0 HTTP/1.1\r\n\r\n",
        )
        .unwrap();
    for _ in 0..2 {
        assert_eq!(read_reply(&mut reader, "GET").body, CHUNK);
    }
}

#[test]
fn a_silent_client_is_closed_after_the_header_timeout() {
    let dir = tempfile::tempdir().unwrap();
    let store = v3_store(dir.path(), "cells");
    let limits = ConnectionLimits {
        header_timeout: Duration::from_millis(300),
        ..ConnectionLimits::default()
    };
    let served = start(&[("cells", &store)], ServerOptions::default(), limits);
    // Timed from before the connection: the server's timeout starts when it accepts, which
    // may be before `connect` returns here.
    let started = Instant::now();
    let (mut stream, mut reader) = connect(&served);
    stream
        .write_all(b"GET /cells/0/c/0/0/0/0 HTTP/1.1\r\nHo")
        .unwrap();
    assert!(closed(&mut reader));
    let waited = started.elapsed();
    assert!(waited >= Duration::from_millis(300), "{waited:?}");
    assert!(waited < Duration::from_secs(5), "{waited:?}");
}

#[test]
fn shutdown_closes_idle_connections_and_returns() {
    let dir = tempfile::tempdir().unwrap();
    let mut served = served_store(dir.path());
    let (mut stream, mut reader) = connect(&served);
    stream
        .write_all(b"GET /cells/0/c/0/0/0/0 HTTP/1.1\r\n\r\n")
        .unwrap();
    assert_eq!(read_reply(&mut reader, "GET").body, CHUNK);
    // The connection is idle, kept alive; shutting down closes it rather than waiting.
    let took = served.stop();
    assert!(took < Duration::from_secs(5), "{took:?}");
    assert!(closed(&mut reader));
}

#[test]
fn the_token_is_asked_for_on_the_direct_path_too() {
    let dir = tempfile::tempdir().unwrap();
    let store = v3_store(dir.path(), "cells");
    let options = ServerOptions {
        token: Some("s3cret".into()),
        ..ServerOptions::default()
    };
    let served = start(&[("cells", &store)], options, ConnectionLimits::default());
    let refused = exchange(&served, "GET", "GET /cells/0/c/0/0/0/0 HTTP/1.1\r\n\r\n");
    assert_eq!(refused.status, 401);
    assert_eq!(refused.body, b"missing or wrong bearer token\n");
    let wrong = exchange(
        &served,
        "GET",
        "GET /cells/0/c/0/0/0/0 HTTP/1.1\r\nAuthorization: Bearer nope\r\n\r\n",
    );
    assert_eq!(wrong.status, 401);
    let given = exchange(
        &served,
        "GET",
        "GET /cells/0/c/0/0/0/0 HTTP/1.1\r\nAuthorization: Bearer s3cret\r\n\r\n",
    );
    assert_eq!((given.status, given.body.as_slice()), (200, CHUNK));
}

#[test]
fn answers_of_both_paths_are_counted_in_the_metrics() {
    let dir = tempfile::tempdir().unwrap();
    let served = served_store(dir.path());
    let (mut stream, mut reader) = connect(&served);
    stream
        .write_all(
            b"GET /cells/0/c/0/0/0/0 HTTP/1.1\r\n\r\n\
              GET /cells/0/c/9/9/9/9 HTTP/1.1\r\n\r\n",
        )
        .unwrap();
    read_reply(&mut reader, "GET");
    read_reply(&mut reader, "GET");
    stream.write_all(b"GET /metrics HTTP/1.1\r\n\r\n").unwrap();
    let text = String::from_utf8(read_reply(&mut reader, "GET").body).unwrap();
    let count = |line: &str| {
        text.lines()
            .find_map(|l| l.strip_prefix(line))
            .unwrap_or_else(|| panic!("no {line} in\n{text}"))
            .trim()
            .to_string()
    };
    assert_eq!(count("brickserver_requests_total{class=\"2xx\"}"), "1");
    assert_eq!(count("brickserver_requests_total{class=\"4xx\"}"), "1");
    // The chunk's bytes and the 404's message.
    let bytes = CHUNK.len() + "no key '0/c/9/9/9/9' in 'cells'\n".len();
    assert_eq!(count("brickserver_response_bytes_total"), bytes.to_string());
}

/// Drops the file at `path` from the page cache (written back first, so none of it stays
/// dirty), and checks that none of it is cached, trying again for a while.
fn drop_from_page_cache(path: &Path) {
    use std::os::fd::AsRawFd;
    let file = std::fs::File::open(path).unwrap();
    file.sync_all().unwrap();
    for _ in 0..200 {
        // SAFETY: an open descriptor.
        let dropped =
            unsafe { libc::posix_fadvise(file.as_raw_fd(), 0, 0, libc::POSIX_FADV_DONTNEED) };
        assert_eq!(dropped, 0);
        if cached_pages(&file) == 0 {
            return;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    panic!("{} stays in the page cache", path.display());
}

/// How many of `file`'s pages the page cache holds (`mincore` of a mapping of it, which reads
/// the cache without faulting pages in).
fn cached_pages(file: &std::fs::File) -> usize {
    use std::os::fd::AsRawFd;
    let len = usize::try_from(file.metadata().unwrap().len()).unwrap();
    // SAFETY: `sysconf` only reads a system constant.
    let page = usize::try_from(unsafe { libc::sysconf(libc::_SC_PAGESIZE) }).unwrap();
    let mut resident = vec![0u8; len.div_ceil(page)];
    // SAFETY: a read-only shared mapping of an open file, of its length, only passed to
    // `mincore` (never read through) and unmapped before returning; `resident` has a byte for
    // each of its pages.
    unsafe {
        let at = libc::mmap(
            std::ptr::null_mut(),
            len,
            libc::PROT_READ,
            libc::MAP_SHARED,
            file.as_raw_fd(),
            0,
        );
        assert_ne!(at, libc::MAP_FAILED);
        assert_eq!(libc::mincore(at, len, resident.as_mut_ptr()), 0);
        assert_eq!(libc::munmap(at, len), 0);
    }
    resident.iter().filter(|r| **r & 1 == 1).count()
}

#[test]
fn chunks_the_page_cache_dropped_are_read_in_then_sent_whole_and_in_part() {
    // Beside the sources, not in a /tmp that may be memory (where pages cannot drop).
    let dir = tempfile::tempdir_in(env!("CARGO_MANIFEST_DIR")).unwrap();
    let served = served_store(dir.path());
    // A chunk for each case, dropped before anything sent it (pages just sent may be held by
    // the socket's buffers for a while).
    let bytes: Vec<u8> = (0..300_000u32).map(|i| (i * 7 % 251) as u8).collect();
    for key in ["0/c/1/0/0/0", "0/c/1/0/0/1", "0/c/1/0/0/2"] {
        let chunk = dir.path().join("cells.ome.zarr").join(key);
        std::fs::write(&chunk, &bytes).unwrap();
        drop_from_page_cache(&chunk);
    }
    let (mut stream, mut reader) = connect(&served);
    let mut ask = |request: &str, method: &str| {
        stream.write_all(request.as_bytes()).unwrap();
        read_reply(&mut reader, method)
    };
    let read_from_disk = |ask: &mut dyn FnMut(&str, &str) -> Reply| {
        let text = String::from_utf8(ask("GET /metrics HTTP/1.1\r\n\r\n", "GET").body).unwrap();
        text.lines()
            .find_map(|l| l.strip_prefix("brickserver_chunks_read_from_disk_total "))
            .unwrap_or_else(|| panic!("no count of chunks read from disk in\n{text}"))
            .to_string()
    };
    let whole = ask("GET /cells/0/c/1/0/0/0 HTTP/1.1\r\n\r\n", "GET");
    assert_eq!((whole.status, whole.body == bytes), (200, true));
    assert_eq!(read_from_disk(&mut ask), "1");
    // Now cached: sent as it is.
    let again = ask("GET /cells/0/c/1/0/0/0 HTTP/1.1\r\n\r\n", "GET");
    assert_eq!((again.status, again.body == bytes), (200, true));
    assert_eq!(read_from_disk(&mut ask), "1");
    let part = ask(
        "GET /cells/0/c/1/0/0/1 HTTP/1.1\r\nRange: bytes=150000-150009\r\n\r\n",
        "GET",
    );
    assert_eq!(part.status, 206);
    assert_eq!(part.body, bytes[150_000..150_010]);
    assert_eq!(
        part.field("content-range"),
        Some("bytes 150000-150009/300000")
    );
    assert_eq!(read_from_disk(&mut ask), "2");
    // A `HEAD` sends no bytes, so reads none.
    let head = ask("HEAD /cells/0/c/1/0/0/2 HTTP/1.1\r\n\r\n", "HEAD");
    assert_eq!(
        (head.status, head.field("content-length")),
        (200, Some("300000"))
    );
    assert_eq!(read_from_disk(&mut ask), "2");
}

#[test]
fn a_store_replaced_whole_is_served_within_a_second_or_at_once_when_the_old_one_is_gone() {
    let dir = tempfile::tempdir().unwrap();
    let store = v3_store(&dir.path().join("served"), "cells");
    let served = start(
        &[("cells", &store)],
        ServerOptions::default(),
        ConnectionLimits::default(),
    );
    let get = |key: &str| {
        exchange(
            &served,
            "GET",
            &format!("GET /cells/{key} HTTP/1.1\r\n\r\n"),
        )
    };
    // The old store: its chunk (now held open), its metadata, and its image in the listing.
    assert_eq!(
        (get("0/c/0/0/0/0").status, get("0/c/0/0/0/0").body),
        (200, CHUNK.to_vec())
    );
    assert_eq!(get(".zattrs").status, 404);
    let listed = served.router_get("/datasets", &[]).text();
    assert!(
        listed.contains("DAPI") && !listed.contains("gray"),
        "{listed}"
    );
    // A new store (Zarr v2, one channel called gray) swapped into its place, the old one kept
    // beside it, as `ingest convert --overwrite` does before it deletes the old one.
    let new = common::v2_store(&dir.path().join("new"), "cells");
    common::write(&new, "0/0/0/0/0", b"the new store's chunk");
    std::fs::rename(&store, dir.path().join("served/old.ome.zarr")).unwrap();
    std::fs::rename(&new, &store).unwrap();
    std::thread::sleep(Duration::from_millis(1100));
    let chunk = get("0/0/0/0/0");
    assert_eq!(
        (chunk.status, chunk.body.as_slice()),
        (200, &b"the new store's chunk"[..])
    );
    assert_eq!(get("0/c/0/0/0/0").status, 404);
    assert_eq!(get("zarr.json").status, 404);
    assert_eq!(get(".zgroup").body, br#"{"zarr_format": 2}"#);
    let listed = served.router_get("/datasets", &[]).text();
    assert!(
        listed.contains("gray") && !listed.contains("DAPI"),
        "{listed}"
    );
    // Another swap, the old store deleted at once (as `ingest` does): a key missing beneath
    // the deleted folder sends the server to the new one before its next check.
    let third = v3_store(&dir.path().join("third"), "cells");
    common::write(&third, "0/c/0/0/0/0", b"the third store's chunk");
    std::fs::rename(&store, dir.path().join("served/second.ome.zarr")).unwrap();
    std::fs::rename(&third, &store).unwrap();
    std::fs::remove_dir_all(dir.path().join("served/second.ome.zarr")).unwrap();
    let chunk = get("0/c/0/0/0/0");
    assert_eq!(
        (chunk.status, chunk.body.as_slice()),
        (200, &b"the third store's chunk"[..])
    );
    assert_eq!(get(".zgroup").status, 404);
}

#[test]
fn threads_on_one_port_serve_every_connection_share_the_limit_and_stop() {
    let dir = tempfile::tempdir().unwrap();
    let store = v3_store(dir.path(), "cells");
    let limits = ConnectionLimits {
        max_connections: 24,
        ..ConnectionLimits::default()
    };
    let mut served = start_with(
        &[("cells", &store)],
        ServerOptions::default(),
        limits,
        Some(3),
    );
    // 24 connections kept open at once, spread by the kernel over the three listeners: each is
    // answered, twice (kept alive), with the chunk's bytes; one through the router.
    let mut open: Vec<_> = (0..24).map(|_| connect(&served)).collect();
    for (i, (stream, reader)) in open.iter_mut().enumerate() {
        let path = if i == 0 {
            "/cells/0/c/0/0/0/0?x=1"
        } else {
            "/cells/0/c/0/0/0/0"
        };
        for _ in 0..2 {
            stream
                .write_all(format!("GET {path} HTTP/1.1\r\n\r\n").as_bytes())
                .unwrap();
            let reply = read_reply(reader, "GET");
            assert_eq!((reply.status, reply.body.as_slice()), (200, CHUNK), "{i}");
        }
    }
    // The limit counts the connections of every thread: the 25th is refused.
    let refused = exchange(&served, "GET", "GET /cells/0/c/0/0/0/0 HTTP/1.1\r\n\r\n");
    assert_eq!(refused.status, 503);
    assert_eq!(refused.body, b"too many connections, retry\r\n");
    // Shutting down closes the idle connections of every thread and returns.
    let took = served.stop();
    assert!(took < Duration::from_secs(5), "{took:?}");
    for (_, reader) in &mut open {
        assert!(closed(reader));
    }
}
