//! `viewer serve` end to end: the real binary, started with a token on a free port against a
//! store written by `ingest`, answers a VDI request with the very bytes `viewer vdi` writes for
//! the same scene, describes the dataset, refuses bad, oversized, unauthorised and too
//! frequent requests with their exact messages, supersedes a request waiting for the GPU, and
//! answers CORS preflights.

use std::io::{BufRead, BufReader, Read};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};

use crate::render_cli::{s, store, viewer, viewer_ok};
use residency_schemas::vdi::{Compression, VolumetricDepthImage};
use serde_json::{Value, json};

const TOKEN: &str = "s3cret-token";

/// A running `viewer serve`, killed when dropped.
struct Server {
    child: Child,
    base: String,
    /// Its stderr after the address line, for failure messages.
    log: Arc<Mutex<String>>,
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Server {
    /// Starts `viewer serve ARGS --bind 127.0.0.1:0` and reads the port it logs.
    fn start(args: &[&str]) -> Self {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_viewer"));
        if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
            cmd.env("XDG_RUNTIME_DIR", "/tmp");
        }
        let mut child = cmd
            .arg("serve")
            .args(args)
            .args(["--bind", "127.0.0.1:0"])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut stderr = BufReader::new(child.stderr.take().unwrap());
        let mut seen = String::new();
        let marker = "listening on http://127.0.0.1:";
        let port: u16 = loop {
            let mut line = String::new();
            let read = stderr.read_line(&mut line).unwrap();
            assert!(read > 0, "viewer serve ended before listening:\n{seen}");
            seen.push_str(&line);
            if let Some(at) = line.find(marker) {
                let digits: String = line[at + marker.len()..]
                    .chars()
                    .take_while(char::is_ascii_digit)
                    .collect();
                break digits.parse().unwrap();
            }
        };
        let log = Arc::new(Mutex::new(String::new()));
        let sink = Arc::clone(&log);
        std::thread::spawn(move || {
            let mut rest = String::new();
            let _ = stderr.read_to_string(&mut rest);
            sink.lock().unwrap().push_str(&rest);
        });
        let server = Self {
            child,
            base: format!("http://127.0.0.1:{port}"),
            log,
        };
        let (status, _, body) = server.call("GET", "/healthz", None, None);
        assert_eq!((status, body.as_slice()), (200, b"ok".as_slice()));
        server
    }

    /// `METHOD PATH` with an optional JSON body and bearer token: the status, the headers
    /// asked about and the body.
    fn call(
        &self,
        method: &str,
        path: &str,
        body: Option<&Value>,
        token: Option<&str>,
    ) -> (u16, ureq::http::HeaderMap, Vec<u8>) {
        let agent: ureq::Agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .build()
            .into();
        let mut request = ureq::http::Request::builder()
            .method(method)
            .uri(format!("{}{path}", self.base))
            .header("origin", "http://page.example");
        if let Some(t) = token {
            request = request.header("authorization", format!("Bearer {t}"));
        }
        let response = match body {
            Some(b) => agent.run(
                request
                    .header("content-type", "application/json")
                    .body(b.to_string())
                    .unwrap(),
            ),
            None => agent.run(request.body(()).unwrap()),
        };
        let mut response = response
            .unwrap_or_else(|e| panic!("{method} {path}: {e}\n{}", self.log.lock().unwrap()));
        let bytes = response
            .body_mut()
            .with_config()
            .limit(64 << 20)
            .read_to_vec()
            .unwrap();
        (
            response.status().as_u16(),
            response.headers().clone(),
            bytes,
        )
    }

    /// `POST /vdi` with the token.
    fn vdi(&self, body: &Value) -> (u16, ureq::http::HeaderMap, Vec<u8>) {
        self.call("POST", "/vdi", Some(body), Some(TOKEN))
    }

    /// `POST /vdi` that must fail: its status and JSON error message.
    fn refused(&self, body: &Value) -> (u16, String) {
        let (status, headers, bytes) = self.vdi(body);
        assert_eq!(headers["content-type"], "application/json", "{body}");
        let answer: Value = serde_json::from_slice(&bytes).unwrap();
        (status, answer["error"].as_str().unwrap().to_string())
    }
}

/// The scene both `viewer vdi` (as `--scene`) and the request draw: `render_cli::VIEW`'s
/// camera and transfer functions.
fn scene() -> Value {
    json!({
        "camera": {"eye": [-30.0, -40.0, 70.0], "target": [20.0, 16.0, 24.0]},
        "channels": [
            {"channel": 0, "color": [1.0, 0.3, 0.1],
             "opacity": [{"value": 300.0, "opacity": 0.0}, {"value": 3000.0, "opacity": 0.2}]},
            {"channel": 1, "color": [0.1, 0.5, 1.0],
             "opacity": [{"value": 500.0, "opacity": 0.0}, {"value": 2500.0, "opacity": 0.1}]}
        ]
    })
}

fn header<'a>(headers: &'a ureq::http::HeaderMap, name: &str) -> &'a str {
    headers
        .get(name)
        .unwrap_or_else(|| panic!("no {name} in {headers:?}"))
        .to_str()
        .unwrap()
}

/// Writes `viewer vdi`'s VDI of `store` with the scene in `scene_file`, `size` (width, height),
/// N_S 12, level 0 only and `compression` to `out`.
fn write_vdi(
    store: &str,
    scene_file: &std::path::Path,
    size: (&str, &str),
    compression: &str,
    out: &std::path::Path,
) {
    viewer_ok(&[
        "vdi",
        "--store",
        store,
        "--scene",
        &s(scene_file),
        "--width",
        size.0,
        "--height",
        size.1,
        "--supersegments",
        "12",
        "--max-level",
        "0",
        "--compression",
        compression,
        "--out",
        &s(out),
    ]);
}

/// The VDI `viewer serve` answers is byte for byte the file `viewer vdi` writes for the same
/// store, scene, size, N_S and renderer flags: both converge a fresh renderer over every brick
/// of level 0 and encode its VDI. A second request for the same view is answered from the live
/// renderer, its bricks still resident, with the same bytes; one that asks for `shuffled_zstd`
/// with the bytes `viewer vdi --compression shuffled_zstd` writes, the same image in fewer
/// bytes.
#[test]
fn serve_answers_the_vdi_viewer_vdi_writes_and_refuses_bad_requests() {
    let dir = tempfile::tempdir().unwrap();
    let store = s(&store(dir.path()));
    let token_file = dir.path().join("token");
    std::fs::write(&token_file, format!("  {TOKEN}\n")).unwrap();
    let scene_file = dir.path().join("scene.json");
    std::fs::write(&scene_file, scene().to_string()).unwrap();
    let vdi_file = dir.path().join("blob.vdi");
    let zstd_file = dir.path().join("zstd.vdi");
    for (file, compression) in [(&vdi_file, "shuffled_lz4"), (&zstd_file, "shuffled_zstd")] {
        write_vdi(&store, &scene_file, ("40", "32"), compression, file);
    }
    let server = Server::start(&[
        "--store",
        &store,
        "--max-level",
        "0",
        "--serve-token-file",
        &s(&token_file),
    ]);

    let request =
        json!({"scene": scene(), "width": 40, "height": 32, "supersegments": 12, "request": 7});
    let (status, headers, bytes) = server.vdi(&request);
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&bytes));
    assert_eq!(
        header(&headers, "content-type"),
        "application/x-residency-vdi"
    );
    assert_eq!(header(&headers, "x-residency-request"), "7");
    header(&headers, "x-residency-generation-ms")
        .parse::<u64>()
        .unwrap();
    assert_eq!(header(&headers, "access-control-allow-origin"), "*");
    assert_eq!(header(&headers, "timing-allow-origin"), "*");
    let exposed = header(&headers, "access-control-expose-headers");
    assert!(
        exposed.contains("x-residency-request") && exposed.contains("x-residency-generation-ms"),
        "{exposed}"
    );
    let image = VolumetricDepthImage::decode(&bytes, "answer").unwrap();
    let h = &image.header;
    assert_eq!(
        (h.width, h.height, h.supersegments, h.channels),
        (40, 32, 12, 2)
    );
    assert_eq!(h.dataset.as_deref(), Some("blob"));
    assert_eq!(h.camera.eye, [-30.0, -40.0, 70.0]);
    assert!(
        bytes == std::fs::read(&vdi_file).unwrap(),
        "differs from viewer vdi's file"
    );
    let (status, _, again) = server.vdi(&request);
    assert_eq!(status, 200);
    assert!(again == bytes, "the live renderer's second answer differs");
    let mut zstd_request = request.clone();
    zstd_request["compression"] = json!("shuffled_zstd");
    let (status, _, zstd_bytes) = server.vdi(&zstd_request);
    assert_eq!(status, 200);
    assert!(
        zstd_bytes == std::fs::read(&zstd_file).unwrap(),
        "differs from viewer vdi --compression shuffled_zstd's file"
    );
    let mut zstd_image = VolumetricDepthImage::decode(&zstd_bytes, "zstd answer").unwrap();
    assert_eq!(zstd_image.header.compression, Compression::ShuffledZstd);
    zstd_image.header.compression = Compression::ShuffledLz4;
    assert!(zstd_image == image, "the zstd answer holds another image");
    assert!(
        zstd_bytes.len() < bytes.len(),
        "{} {}",
        zstd_bytes.len(),
        bytes.len()
    );

    // A camera alone views the default scene (both channels, store colours).
    let camera = json!({"eye": [100.0, 16.0, 24.0], "target": [20.0, 16.0, 24.0]});
    let (status, headers, bytes) =
        server.vdi(&json!({"camera": camera, "width": 20, "height": 16}));
    assert_eq!(status, 200);
    assert!(headers.get("x-residency-request").is_none());
    let image = VolumetricDepthImage::decode(&bytes, "answer").unwrap();
    assert_eq!(
        (
            image.header.width,
            image.header.height,
            image.header.supersegments
        ),
        (20, 16, 20)
    );
    assert_eq!(image.header.camera.eye, [100.0, 16.0, 24.0]);

    // What a page needs to build cameras: the box is x 40, y 32, z 24 voxels of 1, 1, 2.
    let (status, _, body) = server.call("GET", "/info", None, Some(TOKEN));
    assert_eq!(status, 200);
    let info: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(info["dataset"], "blob");
    assert_eq!(info["extent"], json!([40.0, 32.0, 48.0]));
    assert_eq!(info["channels"].as_array().unwrap().len(), 2);
    assert!(info["levels"].as_u64().unwrap() >= 1);
    assert_eq!(info["scene"]["channels"].as_array().unwrap().len(), 2);
    assert_eq!(
        info["limits"],
        json!({"max_pixels": 2073600, "max_supersegments": 30, "max_requests_per_second": 20.0})
    );

    // Refusals, each with its exact message.
    let bad_camera = |camera: Value| json!({"camera": camera, "width": 4, "height": 4});
    let mut missing = scene();
    missing["channels"][1]["channel"] = json!(5);
    let cases = [
        (
            json!({"width": 4000, "height": 4000}),
            413,
            "4000 × 4000 = 16000000 pixels is over the limit of 2073600 pixels (--max-pixels)",
        ),
        (
            json!({"width": 4, "height": 4, "supersegments": 31}),
            413,
            "31 supersegments per pixel is over the limit of 30 (--max-supersegments)",
        ),
        (
            json!({"width": 0, "height": 4}),
            400,
            "width and height must be positive (got 0 × 4)",
        ),
        (
            bad_camera(json!({"eye": [1.0, 2.0, 3.0], "target": [1.0, 2.0, 3.0]})),
            400,
            "camera: eye and target must differ",
        ),
        (
            bad_camera(
                json!({"eye": [0.0, 0.0, 0.0], "target": [1.0, 0.0, 0.0], "fov_y_degrees": 0.0}),
            ),
            400,
            "camera: fov_y_degrees 0 must lie between 0 and 180 degrees",
        ),
        (
            json!({"scene": missing, "width": 4, "height": 4}),
            400,
            "scene: channel 5 does not exist (blob has 2 channels)",
        ),
        (
            json!({"scene": scene(), "camera": {"eye": [0.0, 0.0, 0.0], "target": [1.0, 0.0, 0.0]}, "width": 4, "height": 4}),
            400,
            "give a scene or a camera, not both",
        ),
        (
            json!({"width": 4, "height": 4, "colour": 1}),
            400,
            "request body is not a VDI request: unknown field `colour`, expected one of \
             `scene`, `camera`, `width`, `height`, `supersegments`, `request`, `compression` at \
             line 1 column 30",
        ),
        (
            json!({"width": 4, "height": 4, "compression": "brotli"}),
            400,
            "request body is not a VDI request: unknown variant `brotli`, expected one of `lz4`, \
             `none`, `shuffled_lz4`, `shuffled_zstd` at line 1 column 44",
        ),
    ];
    for (body, status, message) in cases {
        assert_eq!(
            server.refused(&body),
            (status, message.to_string()),
            "{body}"
        );
    }
    // An empty body, and a non-finite camera: JSON has no infinities, so it is a malformed
    // body.
    let (status, headers, bytes) = server.call("POST", "/vdi", None, Some(TOKEN));
    assert_eq!(status, 400, "{headers:?}");
    assert_eq!(
        serde_json::from_slice::<Value>(&bytes).unwrap()["error"],
        "request body is not a VDI request: EOF while parsing a value at line 1 column 0"
    );
    let raw = r#"{"camera": {"eye": [1e999, 0, 0], "target": [0, 0, 0]}, "width": 4, "height": 4}"#;
    let agent: ureq::Agent = ureq::Agent::config_builder()
        .http_status_as_error(false)
        .build()
        .into();
    let mut response = agent
        .post(format!("{}/vdi", server.base))
        .header("authorization", format!("Bearer {TOKEN}"))
        .send(raw)
        .unwrap();
    assert_eq!(response.status().as_u16(), 400);
    let answer: Value =
        serde_json::from_slice(&response.body_mut().read_to_vec().unwrap()).unwrap();
    assert_eq!(
        answer["error"],
        "request body is not a VDI request: number out of range at line 1 column 25"
    );

    // The token: missing or wrong is 401, as JSON; health checks and preflights need none.
    for token in [None, Some("wrong")] {
        let (status, headers, body) = server.call("POST", "/vdi", Some(&request), token);
        assert_eq!(status, 401);
        assert_eq!(header(&headers, "www-authenticate"), "Bearer");
        assert_eq!(
            serde_json::from_slice::<Value>(&body).unwrap(),
            json!({"error": "missing or wrong bearer token"})
        );
    }
    assert_eq!(server.call("GET", "/info", None, None).0, 401);
    let agent: ureq::Agent = ureq::Agent::config_builder()
        .http_status_as_error(false)
        .build()
        .into();
    let preflight = agent
        .options(format!("{}/vdi", server.base))
        .header("origin", "http://page.example")
        .header("access-control-request-method", "POST")
        .header(
            "access-control-request-headers",
            "authorization, content-type",
        )
        .call()
        .unwrap();
    assert_eq!(preflight.status().as_u16(), 200);
    let h = preflight.headers();
    assert_eq!(header(h, "access-control-allow-origin"), "*");
    assert!(header(h, "access-control-allow-methods").contains("POST"));

    // Only the latest request waiting for the GPU matters. Four requests 15 ms apart for a
    // new size: the first to arrive runs (a new renderer, every brick fetched again: far
    // longer than 45 ms), each later one takes the waiting one's place (409), and the last
    // to arrive, superseded by none, is answered too, whatever order they arrive in.
    let server = Arc::new(server);
    let answers: Vec<(u64, u16, String)> = std::thread::scope(|scope| {
        let threads: Vec<_> = (0..4u64)
            .map(|n| {
                let server = Arc::clone(&server);
                let body = json!({"scene": scene(), "width": 80, "height": 64, "supersegments": 12, "request": 100 + n});
                scope.spawn(move || {
                    std::thread::sleep(std::time::Duration::from_millis(15 * n));
                    let (status, headers, bytes) = server.vdi(&body);
                    assert_eq!(header(&headers, "x-residency-request"), (100 + n).to_string());
                    let error = if status == 200 {
                        String::new()
                    } else {
                        let v: Value = serde_json::from_slice(&bytes).unwrap();
                        v["error"].as_str().unwrap().to_string()
                    };
                    (n, status, error)
                })
            })
            .collect();
        threads.into_iter().map(|t| t.join().unwrap()).collect()
    });
    let answered = answers.iter().filter(|a| a.1 == 200).count();
    assert!(answered >= 2, "{answers:?}");
    assert!(
        answers
            .iter()
            .filter(|a| a.1 != 200)
            .all(|a| a.1 == 409 && a.2 == "superseded by a newer request"),
        "{answers:?}"
    );
    assert!(answers.iter().any(|a| a.1 == 409), "{answers:?}");

    // Over the rate (20 a second, a burst of 20): quick requests are refused with 429. Asked
    // until one is (a loaded machine may send fewer than 20 a second for a while), each bad
    // request refused before that with 400.
    let limited = "over the limit of 20 requests per second (--max-requests-per-second)";
    let mut statuses: Vec<(u16, String)> = Vec::new();
    let started = std::time::Instant::now();
    while statuses.len() < 1000 && !statuses.iter().any(|(s, _)| *s == 429) {
        statuses.push(server.refused(&json!({"width": 0, "height": 1})));
    }
    let elapsed = started.elapsed().as_secs_f64();
    let (last, before) = statuses.split_last().unwrap();
    assert_eq!((last.0, last.1.as_str()), (429, limited), "{statuses:?}");
    // No more let in than the burst and the rate allow in the time taken.
    assert!(
        before.len() as f64 <= 20.0 + 20.0 * elapsed + 1.0,
        "{} requests let in over {elapsed:.2} s",
        before.len()
    );
    assert!(before.iter().all(|(s, _)| *s == 400), "{statuses:?}");
}

/// Flags that cannot bound a service fail before any GPU work, naming the flag.
#[test]
fn serve_refuses_bad_limits() {
    let out = viewer(&[
        "serve",
        "--store",
        "/nonexistent",
        "--max-supersegments",
        "65",
    ]);
    assert!(!out.status.success());
    assert_eq!(
        String::from_utf8_lossy(&out.stderr),
        "error: --max-supersegments 65 must lie between 1 and 64\n"
    );
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("token");
    std::fs::write(&empty, " \n").unwrap();
    let out = viewer(&[
        "serve",
        "--store",
        "/nonexistent",
        "--serve-token-file",
        &s(&empty),
    ]);
    assert_eq!(
        String::from_utf8_lossy(&out.stderr),
        format!("error: {}: token file is empty\n", empty.display())
    );
}

/// `viewer serve --server URL --dataset NAME` renders from the bricks brickserver serves: it
/// describes that dataset and answers the VDI `viewer vdi --store` writes for the same view,
/// byte for byte.
#[test]
fn serve_over_brickserver_answers_the_vdi_of_the_store() {
    let dir = tempfile::tempdir().unwrap();
    let store_path = store(dir.path());
    let bricks = crate::source_common::Server::start(&[&store_path]);
    let store = s(&store_path);
    let scene_file = dir.path().join("scene.json");
    std::fs::write(&scene_file, scene().to_string()).unwrap();
    let vdi_file = dir.path().join("blob.vdi");
    write_vdi(&store, &scene_file, ("24", "20"), "shuffled_lz4", &vdi_file);
    let token_file = dir.path().join("token");
    std::fs::write(&token_file, TOKEN).unwrap();
    let server = Server::start(&[
        "--server",
        &bricks.url,
        "--dataset",
        "blob",
        "--max-level",
        "0",
        "--serve-token-file",
        &s(&token_file),
    ]);
    let (status, _, body) = server.call("GET", "/info", None, Some(TOKEN));
    assert_eq!(status, 200);
    let info: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(info["dataset"], "blob");
    assert_eq!(info["extent"], json!([40.0, 32.0, 48.0]));
    let request = json!({"scene": scene(), "width": 24, "height": 20, "supersegments": 12});
    let (status, _, bytes) = server.vdi(&request);
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&bytes));
    assert!(
        bytes == std::fs::read(&vdi_file).unwrap(),
        "differs from viewer vdi --store's file"
    );
}
