//! The real `brickserver` binary: its flags (`--viewer-dir`, `--public-url`) reach the
//! library, and the viewer's default folder is `web` beside the executable.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Command, Stdio};

use residency_schemas::server::DatasetList;

use crate::common::{page_with, v3_store, viewer_dir};

/// A running `brickserver serve` (killed when dropped) and its address.
struct Served {
    child: Child,
    addr: String,
}

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Starts `exe serve ARGS --bind 127.0.0.1:0` and waits until it listens.
fn start(exe: &Path, args: &[&str]) -> Served {
    let mut child = Command::new(exe)
        .arg("serve")
        .args(args)
        .args(["--bind", "127.0.0.1:0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("start brickserver");
    let stdout = child.stdout.take().unwrap();
    for line in BufReader::new(stdout).lines() {
        let line = line.unwrap();
        if let Some(url) = line.strip_prefix("listening on http://") {
            return Served {
                child,
                addr: url.to_string(),
            };
        }
    }
    let _ = child.kill();
    let _ = child.wait();
    panic!("brickserver did not start");
}

/// `GET path` over HTTP/1.0 (no chunking, the server closes): status, headers, body.
fn get(addr: &str, path: &str, headers: &[&str]) -> (u16, String, Vec<u8>) {
    let mut stream = TcpStream::connect(addr).unwrap();
    let mut request = format!("GET {path} HTTP/1.0\r\nHost: {addr}\r\n");
    for h in headers {
        request.push_str(h);
        request.push_str("\r\n");
    }
    request.push_str("\r\n");
    stream.write_all(request.as_bytes()).unwrap();
    let mut answer = Vec::new();
    stream.read_to_end(&mut answer).unwrap();
    let split = answer
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("a header block");
    let head = String::from_utf8(answer[..split].to_vec()).unwrap();
    let status = head.split(' ').nth(1).unwrap().parse().unwrap();
    (status, head, answer[split + 4..].to_vec())
}

fn arg(path: &Path) -> &str {
    path.to_str().unwrap()
}

#[test]
fn flags_reach_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let store = v3_store(dir.path(), "cells");
    let web = viewer_dir(dir.path());
    let exe = Path::new(env!("CARGO_BIN_EXE_brickserver"));
    let served = start(
        exe,
        &[
            arg(&store),
            "--viewer-dir",
            arg(&web),
            "--public-url",
            "https://data.example.org/lab/",
        ],
    );
    let (status, head, body) = get(&served.addr, "/cells/view", &[]);
    assert_eq!(status, 200);
    assert!(
        head.contains("content-type: text/html; charset=utf-8"),
        "{head}"
    );
    assert_eq!(String::from_utf8(body).unwrap(), page_with("../viewer/"));
    let (status, head, body) = get(&served.addr, "/viewer/residency_viewer_bg.wasm", &[]);
    assert_eq!(status, 200);
    assert!(head.contains("content-type: application/wasm"), "{head}");
    assert_eq!(body, crate::common::WASM);
    let (status, _, body) = get(&served.addr, "/datasets", &["X-Forwarded-Host: other"]);
    assert_eq!(status, 200);
    let list: DatasetList = serde_json::from_slice(&body).unwrap();
    assert_eq!(list.datasets[0].url, "https://data.example.org/lab/cells/");
    assert_eq!(
        list.datasets[0].view,
        "https://data.example.org/lab/cells/view"
    );
}

#[test]
fn the_default_viewer_folder_is_web_beside_the_executable() {
    let dir = tempfile::tempdir().unwrap();
    let store = v3_store(dir.path(), "cells");
    // A copy of the binary in a folder of its own, so `web` beside it is ours.
    let bin = dir.path().join("bin");
    std::fs::create_dir(&bin).unwrap();
    let exe = bin.join("brickserver");
    std::fs::copy(env!("CARGO_BIN_EXE_brickserver"), &exe).unwrap();
    {
        let served = start(&exe, &[arg(&store)]);
        let (status, _, body) = get(&served.addr, "/cells/view", &[]);
        assert_eq!(status, 503);
        assert_eq!(
            String::from_utf8(body).unwrap(),
            format!(
                "the web viewer is not built: run scripts/build-web.sh, or pass --viewer-dir \
                 (looked for index.html in {})\n",
                bin.join("web").display()
            )
        );
    }
    viewer_dir(&bin);
    let served = start(&exe, &[arg(&store)]);
    let (status, _, body) = get(&served.addr, "/cells/view", &[]);
    assert_eq!(status, 200);
    assert_eq!(String::from_utf8(body).unwrap(), page_with("../viewer/"));
    // Links follow the request's Host without --public-url.
    let (_, _, body) = get(&served.addr, "/datasets", &[]);
    let list: DatasetList = serde_json::from_slice(&body).unwrap();
    assert_eq!(
        list.datasets[0].view,
        format!("http://{}/cells/view", served.addr)
    );
}

#[test]
fn bad_flags_and_names_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let store = v3_store(dir.path(), "cells");
    let exe = env!("CARGO_BIN_EXE_brickserver");
    let run = |args: &[&str]| {
        let out = Command::new(exe).arg("serve").args(args).output().unwrap();
        assert!(!out.status.success(), "{args:?}");
        String::from_utf8(out.stderr).unwrap()
    };
    let err = run(&[arg(&store), "--public-url", "data.example.org"]);
    assert!(
        err.contains("public URL 'data.example.org': expected http:// or https://"),
        "{err}"
    );
    let pair = format!("viewer={}", store.display());
    let err = run(&["--name", &pair]);
    assert!(err.contains("dataset name 'viewer' is not usable"), "{err}");
}

/// Without `--bind` the server listens on loopback port 8000, as the README says: only this
/// machine reaches it unless told otherwise.
#[test]
fn the_default_address_is_loopback_port_8000() {
    let out = Command::new(env!("CARGO_BIN_EXE_brickserver"))
        .args(["serve", "--help"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let help = String::from_utf8(out.stdout).unwrap();
    let bind = help
        .lines()
        .skip_while(|l| !l.trim_start().starts_with("--bind"))
        .take_while(|l| !l.trim_start().starts_with("--name"))
        .collect::<Vec<_>>()
        .join(" ");
    assert!(bind.contains("[default: 127.0.0.1:8000]"), "{help}");
}
