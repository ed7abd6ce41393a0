//! `HttpSource` against the real `brickserver` binary: the same `VolumeInfo` and bricks as
//! `LocalSource` on the served store, for every layout, and clear errors. Needs the release
//! binaries (`cargo build --release --bins`).

use std::path::Path;
use std::process::Command;

use crate::source_common::{Layout, Server, binary, make_store, strip_region_metadata};
use residency_viewer::source::{BrickKey, BrickSource, HttpSource, LocalSource};

/// Every brick of every level and channel.
fn all_keys(src: &dyn BrickSource) -> Vec<BrickKey> {
    let info = src.info();
    let mut keys = Vec::new();
    for l in 0..info.levels.len() {
        let g = info.brick_grid(l);
        for c in 0..info.channels.len() as u32 {
            for z in 0..g[0] {
                for y in 0..g[1] {
                    for x in 0..g[2] {
                        keys.push(BrickKey {
                            level: l as u32,
                            channel: c,
                            brick: [z, y, x],
                        });
                    }
                }
            }
        }
    }
    keys
}

fn assert_same(http: &HttpSource, local: &LocalSource) {
    assert_eq!(http.info(), local.info());
    let keys = all_keys(local);
    let a: Vec<_> = http.fetch(&keys).into_iter().map(Result::unwrap).collect();
    let b: Vec<_> = local.fetch(&keys).into_iter().map(Result::unwrap).collect();
    assert_eq!(a, b);
}

#[test]
fn http_and_local_sources_agree_on_the_sample() {
    let dir = tempfile::tempdir().unwrap();
    let sample = dir.path().join("sample");
    let store = dir.path().join("sample.ome.zarr");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let run = |args: &[String]| {
        let out = Command::new(binary("ingest")).args(args).output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    run(&["sample", "-o", &s(&sample), "--size", "24,40,36", "--quiet"].map(String::from));
    let mut args = vec!["convert".to_string()];
    for c in ["nuclei", "membranes", "filaments"] {
        args.push(s(&sample.join(format!("{c}.ome.tif"))));
    }
    args.extend(["-o", &s(&store), "--chunk", "8", "--quiet"].map(String::from));
    run(&args);

    let server = Server::start(&[&store]);
    let http = HttpSource::open(&server.url, "sample").unwrap();
    let local = LocalSource::open(&store).unwrap();
    assert!(http.info().minmax.is_some());
    assert_eq!(http.info().channels, ["nuclei", "membranes", "filaments"]);
    // More bricks than one batch holds: the fetch is split, answered in order.
    assert!(
        all_keys(&local).len() > http.batch_size(),
        "{}",
        all_keys(&local).len()
    );
    assert_same(&http, &local);
}

#[test]
fn sharded_v2_and_bare_stores_read_the_same_over_http() {
    let dir = tempfile::tempdir().unwrap();
    let sharded = make_store(dir.path(), "sharded", Layout::V3Sharded);
    let v2 = make_store(dir.path(), "v2", Layout::V2);
    let bare = make_store(dir.path(), "bare", Layout::V3);
    strip_region_metadata(&bare);
    let server = Server::start(&[&sharded, &v2, &bare]);
    for (name, path) in [("sharded", &sharded), ("v2", &v2), ("bare", &bare)] {
        let http = HttpSource::open(&server.url, name).unwrap();
        assert_eq!(http.info().minmax.is_none(), name == "bare", "{name}");
        assert_same(&http, &LocalSource::open(path).unwrap());
    }
}

#[test]
fn errors_name_the_server_dataset_and_brick() {
    // Nothing listens on a port just released.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let e = HttpSource::open(&format!("http://127.0.0.1:{port}"), "vol").unwrap_err();
    assert!(
        e.to_string().starts_with(&format!(
            "http://127.0.0.1:{port}/vol/zarr.json: cannot reach the brick server: "
        )),
        "{e}"
    );

    let dir = tempfile::tempdir().unwrap();
    let store = make_store(dir.path(), "vol", Layout::V3);
    std::fs::write(store.join("0/c/1/0/1/1"), b"not blosc").unwrap();
    let server = Server::start(&[&store]);
    let e = HttpSource::open(&server.url, "nope").unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "{}/nope: no such dataset on the server (neither zarr.json nor .zattrs found)",
            server.url
        )
    );
    let http = HttpSource::open(&server.url, "vol").unwrap();
    let bad = BrickKey {
        level: 0,
        channel: 1,
        brick: [0, 1, 1],
    };
    let outside = BrickKey {
        level: 9,
        channel: 0,
        brick: [0, 0, 0],
    };
    let good = BrickKey {
        level: 0,
        channel: 1,
        brick: [0, 0, 1],
    };
    let mut got = http.fetch(&[bad, outside, good]).into_iter();
    let e = got.next().unwrap().unwrap_err().to_string();
    assert!(
        e.starts_with(&format!(
            "{}/vol/bricks?encoding=raw: brick {bad:?}: the server could not read it: ",
            server.url
        )),
        "{e}"
    );
    let e = got.next().unwrap().unwrap_err().to_string();
    assert_eq!(
        e,
        format!(
            "vol: brick {outside:?}: no level 9 ({} levels)",
            http.info().levels.len()
        )
    );
    let local = LocalSource::open(&store).unwrap();
    assert_eq!(
        got.next().unwrap().unwrap(),
        local.fetch(&[good]).pop().unwrap().unwrap()
    );
}

#[test]
fn a_server_with_a_token_needs_it() {
    let dir = tempfile::tempdir().unwrap();
    let store = make_store(dir.path(), "vol", Layout::V3);
    let token = dir.path().join("token");
    std::fs::write(&token, "s3cret\n").unwrap();
    let server = Server::start_with(&[&store], &["--token-file", token.to_str().unwrap()]);
    let e = HttpSource::open(&server.url, "vol").unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "{}/vol/zarr.json: HTTP 401: the server needs a token (--token-file)",
            server.url
        )
    );
    let e = HttpSource::open_with_token(&server.url, "vol", Some("wrong")).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "{}/vol/zarr.json: HTTP 401: the server refused the token",
            server.url
        )
    );
    // Reading the token file as the server does (`--token-file`): its text, trimmed.
    let token_text = residency_viewer::source::read_token_file(&token).unwrap();
    let http = HttpSource::open_with_token(&server.url, "vol", Some(&token_text)).unwrap();
    let local = LocalSource::open(&store).unwrap();
    assert_eq!(http.info(), local.info());
    let keys = all_keys(&local);
    let a: Vec<_> = http.fetch(&keys).into_iter().map(Result::unwrap).collect();
    let b: Vec<_> = local.fetch(&keys).into_iter().map(Result::unwrap).collect();
    assert_eq!(a, b);
}
