//! Stores stay byte-identical from commit to commit: `ingest convert` of a fixed sample, in
//! each layout, must write the files it wrote when the expected digests below were taken. A
//! change that alters a single byte of a store (a chunk's encoding, the pyramid's rounding, the
//! region metadata, a metadata document's spelling) fails here, and whoever makes it on purpose
//! updates the digests with the reason in the commit. `RESIDENCY_PRINT_STORE_DIGESTS=1` prints
//! each layout's files and digests.

use std::path::{Path, PathBuf};

use crate::common::{arg, fnv64, ingest_ok};

/// Every file of the store at `root`, as `(path relative to root, bytes)`, in path order.
fn files(root: &Path) -> Vec<(String, Vec<u8>)> {
    let mut found = Vec::new();
    let mut folders = vec![PathBuf::from(root)];
    while let Some(folder) = folders.pop() {
        for entry in std::fs::read_dir(&folder).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                folders.push(path);
            } else {
                let relative = path.strip_prefix(root).unwrap().to_str().unwrap();
                found.push((relative.replace('\\', "/"), std::fs::read(&path).unwrap()));
            }
        }
    }
    found.sort();
    found
}

/// One digest of a whole store: FNV-1a over each file's path, length and bytes, in path order.
fn digest(files: &[(String, Vec<u8>)]) -> u64 {
    let mut all = Vec::new();
    for (path, bytes) in files {
        all.extend_from_slice(path.as_bytes());
        all.push(0);
        all.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
        all.extend_from_slice(bytes);
    }
    fnv64(&all)
}

#[test]
fn converted_stores_are_unchanged_byte_for_byte() {
    // (layout flags, files written, digest of the store), taken at the commit that added this
    // test: two channels of `ingest sample --size 17,40,36 --seed 7` (nuclei and membranes,
    // 16-bit OME-TIFF) converted with 8³ bricks.
    let expected: [(&[&str], usize, u64); 3] = [
        (&[], 251, 0x55db_81ab_11e5_9b17),
        (&["--shard", "16"], 154, 0x34ad_af5f_f805_4d0d),
        (&["--ome-zarr-version", "0.4"], 304, 0x041a_dcf3_64c9_299d),
    ];
    let dir = tempfile::tempdir().unwrap();
    let sample = dir.path().join("sample");
    let sample_args = ["--size", "17,40,36", "--seed", "7", "--quiet"];
    ingest_ok(&[&["sample", "-o", arg(&sample)][..], &sample_args].concat());
    let inputs = [
        sample.join("nuclei.ome.tif"),
        sample.join("membranes.ome.tif"),
    ];
    let print = std::env::var_os("RESIDENCY_PRINT_STORE_DIGESTS").is_some();
    let mut got = Vec::new();
    for (i, (flags, _, _)) in expected.iter().enumerate() {
        let out = dir.path().join(format!("s{i}.ome.zarr"));
        let mut args = vec!["convert", arg(&inputs[0]), arg(&inputs[1]), "-o", arg(&out)];
        args.extend(["--chunk", "8", "--quiet"]);
        args.extend_from_slice(flags);
        ingest_ok(&args);
        let written = files(&out);
        let store = (*flags, written.len(), digest(&written));
        if print {
            println!("{flags:?}: {} files, {:#018x}", store.1, store.2);
            for (path, bytes) in &written {
                println!("  {path} {} {:#018x}", bytes.len(), fnv64(bytes));
            }
        }
        got.push(store);
    }
    assert_eq!(got, expected);
}
