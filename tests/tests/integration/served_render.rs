//! The demo's job (`scripts/demo.sh`) over HTTP, with the real binaries: `ingest` the sample, serve it with
//! `brickserver`, render it with `viewer render` through the server, render the same scene
//! with `viewer reference`, and compare them with `viewer compare`. The server's metrics show
//! the renderer used the batched brick endpoint and never decoded data itself for culling.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};

use residency_tests::{binary, run};

/// A running `brickserver`, stopped when dropped.
struct Server {
    child: Child,
    url: String,
}

impl Server {
    fn start(store: &str) -> Self {
        let mut child = Command::new(binary("brickserver"))
            .args(["serve", store, "--bind", "127.0.0.1:0"])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("start brickserver");
        let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
        let url = lines
            .by_ref()
            .map_while(Result::ok)
            .find_map(|l| l.strip_prefix("listening on ").map(str::to_string))
            .expect("brickserver announces its address");
        Self { child, url }
    }

    /// The body of `GET path`, over a raw connection.
    fn get(&self, path: &str) -> String {
        let host = self.url.trim_start_matches("http://");
        let mut s = TcpStream::connect(host).unwrap();
        write!(
            s,
            "GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
        )
        .unwrap();
        let mut text = String::new();
        s.read_to_string(&mut text).unwrap();
        text.split_once("\r\n\r\n").unwrap().1.to_string()
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The value of an OpenMetrics sample line `name value`.
fn metric(text: &str, name: &str) -> f64 {
    text.lines()
        .find_map(|l| l.strip_prefix(name).and_then(|v| v.trim().parse().ok()))
        .unwrap_or_else(|| panic!("{name} not in metrics:\n{text}"))
}

/// `ingest sample --size SIZE` in `dir`, its `channels` (sample file stems) converted into one
/// store of 16³ chunks, served by a new `brickserver`.
fn serve_sample(dir: &std::path::Path, size: &str, channels: &[&str]) -> Server {
    let p = |name: &str| dir.join(name).to_str().unwrap().to_string();
    run(
        "ingest",
        &["sample", "-o", &p("sample"), "--size", size, "--quiet"],
    );
    let store = p("sample.ome.zarr");
    let inputs: Vec<String> = channels
        .iter()
        .map(|c| p(&format!("sample/{c}.ome.tif")))
        .collect();
    let mut args: Vec<&str> = vec!["convert"];
    args.extend(inputs.iter().map(String::as_str));
    args.extend(["-o", &store, "--chunk", "16", "--quiet"]);
    run("ingest", &args);
    Server::start(&store)
}

/// Asserts, with `viewer compare`, that the image `gpu` matches `reference` as a converged
/// render does (PSNR ≥ 40 dB, SSIM ≥ 0.99).
fn assert_matches(label: &str, gpu: &str, reference: &str) {
    let out = run("viewer", &["compare", gpu, reference, "--json"]);
    let cmp: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let (psnr, ssim) = (
        cmp["psnr_db"].as_f64().unwrap_or(f64::INFINITY),
        cmp["ssim"].as_f64().unwrap(),
    );
    assert!(psnr >= 40.0 && ssim >= 0.99, "{label}: {cmp}");
}

#[test]
fn sample_served_and_rendered_on_the_gpu_matches_the_reference() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let server = serve_sample(dir.path(), "24,64,64", &["nuclei", "membranes"]);
    let scene = [
        "--server",
        &server.url,
        "--dataset",
        "sample",
        "--camera",
        "30,20,1.6",
        "--width",
        "64",
        "--height",
        "64",
    ];
    let (gpu, reference, stats) = (p("gpu.exr"), p("ref.exr"), p("stats.json"));
    let mut args = vec!["render"];
    args.extend(scene);
    args.extend(["--out", &gpu, "--stats", &stats, "--max-level", "0"]);
    run("viewer", &args);
    let mut args = vec!["reference"];
    args.extend(scene);
    args.extend(["--out", &reference]);
    run("viewer", &args);

    assert_matches("residency", &gpu, &reference);

    let stats: serde_json::Value = serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
    assert_eq!(stats["converged"], true, "{stats}");
    let fetched = stats["bricks_fetched"].as_u64().unwrap();
    assert!(fetched > 0);
    // Bricks came in batches: fewer batch requests than bricks, all answered 2xx.
    let metrics = server.get("/metrics");
    assert_eq!(
        metric(&metrics, "brickserver_requests_total{class=\"5xx\"}"),
        0.0
    );
    let misses = metric(&metrics, "brickserver_cache_misses_total");
    let hits = metric(&metrics, "brickserver_cache_hits_total");
    // Every brick the renderer and the reference fetched went through the batch endpoint's
    // cache (the reference reads level 0 again: hits).
    assert!(
        misses >= fetched as f64,
        "{misses} misses, {fetched} bricks"
    );
    assert!(hits > 0.0, "{metrics}");
}

/// `viewer render --method sparseleap` and `--method rasterize`, each with `--filter tricubic`,
/// through `brickserver`, match `viewer reference --filter tricubic` through the same server.
#[test]
fn seed_methods_with_tricubic_render_over_the_server() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let server = serve_sample(dir.path(), "16,48,48", &["nuclei"]);
    let scene = [
        "--server",
        &server.url,
        "--dataset",
        "sample",
        "--camera",
        "30,20,1.6",
        "--width",
        "48",
        "--height",
        "48",
        "--filter",
        "tricubic",
    ];
    let reference = p("ref.exr");
    let mut args = vec!["reference"];
    args.extend(scene);
    args.extend(["--out", &reference]);
    run("viewer", &args);
    for method in ["sparseleap", "rasterize"] {
        let (gpu, stats) = (p(&format!("{method}.exr")), p(&format!("{method}.json")));
        let mut args = vec!["render", "--method", method];
        args.extend(scene);
        args.extend(["--out", &gpu, "--stats", &stats, "--max-level", "0"]);
        run("viewer", &args);
        assert_matches(method, &gpu, &reference);
        let stats: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
        assert_eq!(stats["converged"], true, "{method}: {stats}");
        assert_eq!(stats["method"], method);
        let last = stats["frames"].as_array().unwrap().last().unwrap();
        assert!(
            last["segment_boxes"].as_u64().unwrap() > 0,
            "{method}: {last}"
        );
    }
}
