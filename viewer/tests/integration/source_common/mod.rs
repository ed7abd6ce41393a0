//! Test stores for the source tests: raw volumes with known voxels, converted by the real
//! `ingest` library into OME-Zarr stores of any layout.

#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use residency_ingest::ConvertOptions;
use residency_ingest::store::OmeZarrVersion;

/// Level-0 shape `z, y, x` of the test volumes: not a multiple of the 8-voxel brick.
pub const SHAPE: [u64; 3] = [20, 24, 28];
/// Brick edge of the test stores.
pub const BRICK: u64 = 8;

/// Channel 0: a bright ball (up to 1000) in a volume of zeros, so whole bricks are empty.
pub fn ball(z: u64, y: u64, x: u64) -> u16 {
    let d2 = (z as f64 - 6.0).powi(2) + (y as f64 - 8.0).powi(2) + (x as f64 - 9.0).powi(2);
    if d2 < 36.0 {
        1000 - (d2 * 20.0) as u16
    } else {
        0
    }
}

/// Channel 1: a ramp over x, zero where `x < 8`.
pub fn ramp(z: u64, y: u64, x: u64) -> u16 {
    if x < 8 { 0 } else { (x * 10 + y + z) as u16 }
}

/// The voxels of a channel, `z`-major.
pub fn voxels(f: fn(u64, u64, u64) -> u16) -> Vec<u16> {
    let [nz, ny, nx] = SHAPE;
    let mut v = Vec::new();
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                v.push(f(z, y, x));
            }
        }
    }
    v
}

/// How to write a test store.
#[derive(Clone, Copy, Debug)]
pub enum Layout {
    /// OME-Zarr 0.5, one chunk per brick.
    V3,
    /// OME-Zarr 0.5, shards of 16³ holding 8³ bricks.
    V3Sharded,
    /// OME-Zarr 0.4 on Zarr v2.
    V2,
}

/// Converts the two test channels into `dir/NAME.ome.zarr`, voxel size `2, 0.5, 0.5`.
pub fn make_store(dir: &Path, name: &str, layout: Layout) -> PathBuf {
    let [nz, ny, nx] = SHAPE;
    let mut inputs = Vec::new();
    for (i, f) in [ball as fn(u64, u64, u64) -> u16, ramp]
        .into_iter()
        .enumerate()
    {
        let path = dir.join(format!("{name}-c{i}_{nx}x{ny}x{nz}_uint16.raw"));
        let bytes: Vec<u8> = voxels(f).iter().flat_map(|v| v.to_le_bytes()).collect();
        std::fs::write(&path, bytes).unwrap();
        inputs.push(path.to_str().unwrap().to_string());
    }
    let output = dir.join(format!("{name}.ome.zarr"));
    let mut options = ConvertOptions::new(inputs, output.clone());
    options.brick = [BRICK; 3];
    options.voxel_size = Some([2.0, 0.5, 0.5]);
    options.channel_names = vec!["ball".into(), "ramp".into()];
    match layout {
        Layout::V3 => {}
        Layout::V3Sharded => options.shard = Some([16; 3]),
        Layout::V2 => options.version = OmeZarrVersion::V04,
    }
    residency_ingest::convert(&options).unwrap();
    output
}

/// Removes the region metadata from a store (the attribute and its arrays).
pub fn strip_region_metadata(store: &Path) {
    let (file, v3) = if store.join("zarr.json").exists() {
        (store.join("zarr.json"), true)
    } else {
        (store.join(".zattrs"), false)
    };
    let mut doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&file).unwrap()).unwrap();
    let attrs = if v3 { &mut doc["attributes"] } else { &mut doc };
    attrs.as_object_mut().unwrap().remove("residency").unwrap();
    std::fs::write(&file, serde_json::to_vec(&doc).unwrap()).unwrap();
    std::fs::remove_dir_all(store.join("residency")).unwrap();
}

/// A release binary of the workspace, which must be built.
pub fn binary(name: &str) -> PathBuf {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../target/release")
        .join(name);
    assert!(
        path.exists(),
        "{} is not built: run `cargo build --release --bins` first",
        path.display()
    );
    path
}

/// A running `brickserver`, killed when dropped.
pub struct Server {
    child: Child,
    /// The server's base URL.
    pub url: String,
    // Kept open so that the server never writes to a closed pipe.
    _stdout: BufReader<std::process::ChildStdout>,
}

impl Server {
    /// Serves `stores` on a free loopback port.
    pub fn start(stores: &[&Path]) -> Self {
        Self::start_with(stores, &[])
    }

    /// Serves `stores` with extra `brickserver serve` options.
    pub fn start_with(stores: &[&Path], options: &[&str]) -> Self {
        let mut child = Command::new(binary("brickserver"))
            .arg("serve")
            .args(stores)
            .args(["--bind", "127.0.0.1:0"])
            .args(options)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut stdout = BufReader::new(child.stdout.take().unwrap());
        let url = loop {
            let mut line = String::new();
            assert!(
                stdout.read_line(&mut line).unwrap() > 0,
                "brickserver exited"
            );
            if let Some(url) = line.trim().strip_prefix("listening on ") {
                break url.to_string();
            }
        };
        Self {
            child,
            url,
            _stdout: stdout,
        }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
