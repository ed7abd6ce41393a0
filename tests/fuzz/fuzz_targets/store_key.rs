//! Store key resolution (`brickserver/src/store_keys.rs`): `resolve` and `RootDir::open_key`
//! on any raw (percent-encoded) key, in a dataset folder holding files, a folder, a symlink
//! inside, symlinks out of it (to a file and to a folder beside it) and a symlink loop. What
//! either grants must be a regular file inside the dataset.
#![no_main]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use residency_brickserver::store_keys::{RootDir, resolve};
use residency_fuzz::scratch;

fn fixture() -> &'static (PathBuf, RootDir) {
    static FIXTURE: OnceLock<(PathBuf, RootDir)> = OnceLock::new();
    FIXTURE.get_or_init(|| {
        let base = scratch::empty_dir("keys");
        let root = base.join("d.zarr");
        std::fs::create_dir_all(root.join("0/c/0/0")).unwrap();
        std::fs::write(root.join("zarr.json"), b"{}").unwrap();
        std::fs::write(root.join("0/zarr.json"), b"{}").unwrap();
        std::fs::write(root.join("0/c/0/0/0"), b"chunk").unwrap();
        std::fs::write(root.join("a b%.json"), b"odd").unwrap();
        std::fs::create_dir_all(base.join("outside")).unwrap();
        std::fs::write(base.join("outside/secret"), b"secret").unwrap();
        std::fs::write(base.join("secret"), b"secret").unwrap();
        let link = |target: &str, name: &str| {
            std::os::unix::fs::symlink(target, root.join(name)).unwrap();
        };
        link("zarr.json", "inside");
        link("../secret", "out");
        link("../outside", "outdir");
        link(base.join("secret").to_str().unwrap(), "abs");
        link("loop", "loop");
        let root = root.canonicalize().unwrap();
        let dir = RootDir::open(&root).unwrap();
        (root, dir)
    })
}

fn inside(root: &Path, path: &Path) -> bool {
    path.starts_with(root) && path.is_file()
}

fuzz_target!(|key: &str| {
    let (root, dir) = fixture();
    if let Ok(path) = resolve(root, key) {
        assert!(inside(root, &path), "resolve({key:?}) = {path:?}");
    }
    if let Ok((file, meta)) = dir.open_key(key) {
        use std::os::fd::AsRawFd;
        let real = std::fs::read_link(format!("/proc/self/fd/{}", file.as_raw_fd())).unwrap();
        assert!(
            meta.is_file() && inside(root, &real),
            "open_key({key:?}) opened {real:?}"
        );
    }
});
