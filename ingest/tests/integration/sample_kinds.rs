//! `ingest sample --kind ...`: every kind of synthetic sample, read back with the `tiff`
//! crate (data type, extent, channels, metadata, determinism, the property the kind stands
//! for), and converted end to end with `ingest convert`.

use std::path::{Path, PathBuf};

use crate::common::{Stack, Voxels, arg, fnv64, ingest, ingest_ok, read_stack};

/// Runs `ingest sample` into `dir` with `extra` arguments; returns the files listed by its
/// `convert it with:` line (checking they are the files it listed above it).
fn sample(dir: &Path, extra: &[&str]) -> Vec<PathBuf> {
    let mut args = vec!["sample", "-o", arg(dir), "--quiet"];
    args.extend(extra);
    let stdout = ingest_ok(&args);
    let listed: Vec<PathBuf> = stdout
        .lines()
        .filter_map(|l| l.strip_prefix("  "))
        .map(PathBuf::from)
        .collect();
    let command = stdout
        .lines()
        .find_map(|l| l.strip_prefix("convert it with: ingest convert "))
        .expect("convert line");
    let files: Vec<PathBuf> = command
        .split(' ')
        .take_while(|a| *a != "-o")
        .map(PathBuf::from)
        .collect();
    assert_eq!(files, listed, "{stdout}");
    assert!(command.ends_with(" -o sample.ome.zarr"), "{command}");
    files
}

fn names(files: &[PathBuf]) -> Vec<String> {
    files
        .iter()
        .map(|f| f.file_name().unwrap().to_str().unwrap().to_string())
        .collect()
}

/// Every file's bytes.
fn contents(files: &[PathBuf]) -> Vec<Vec<u8>> {
    files.iter().map(|f| std::fs::read(f).unwrap()).collect()
}

/// Generates the same sample twice and checks the files are byte-identical.
fn assert_deterministic(dir: &Path, extra: &[&str]) -> Vec<PathBuf> {
    let a = sample(&dir.join("a"), extra);
    let b = sample(&dir.join("b"), extra);
    assert_eq!(names(&a), names(&b));
    assert!(contents(&a) == contents(&b), "two runs of {extra:?} differ");
    a
}

/// The `(min, max)` of each complete 8³ block of a stack.
fn block_ranges(stack: &Stack) -> Vec<(f64, f64)> {
    let [nz, ny, nx] = stack.shape;
    let v = stack.values();
    let mut out = Vec::new();
    for bz in 0..nz / 8 {
        for by in 0..ny / 8 {
            for bx in 0..nx / 8 {
                let mut range = (f64::INFINITY, f64::NEG_INFINITY);
                for z in bz * 8..bz * 8 + 8 {
                    for y in by * 8..by * 8 + 8 {
                        for x in bx * 8..bx * 8 + 8 {
                            let s = v[(z * ny + y) * nx + x];
                            range = (range.0.min(s), range.1.max(s));
                        }
                    }
                }
                out.push(range);
            }
        }
    }
    out
}

/// The physical voxel size `z, y, x` written in a stack's OME-XML.
fn ome_voxel_size(stack: &Stack) -> [String; 3] {
    ["Z", "Y", "X"].map(|a| {
        let key = format!("PhysicalSize{a}=\"");
        let start = stack.description.find(&key).expect("physical size") + key.len();
        let len = stack.description[start..].find('"').unwrap();
        stack.description[start..start + len].to_string()
    })
}

#[test]
fn fluorescence_is_unchanged_byte_for_byte() {
    // FNV-1a hashes of the files written before `--kind` existed.
    let expected: [(&str, &str, [u64; 3]); 2] = [
        (
            "8,16,16",
            "3",
            [0x29eb38e6c1c221b2, 0x51aab7d10465e9fd, 0x3c221dadbdff4046],
        ),
        (
            "17,31,29",
            "5",
            [0xc11d0831a06fcde3, 0x8893cc7c106132e1, 0x3d5c75742f5e6574],
        ),
    ];
    let dir = tempfile::tempdir().unwrap();
    for (size, seed, hashes) in expected {
        let plain = sample(&dir.path().join(size), &["--size", size, "--seed", seed]);
        assert_eq!(
            names(&plain),
            ["nuclei.ome.tif", "membranes.ome.tif", "filaments.ome.tif"]
        );
        let got: Vec<u64> = contents(&plain).iter().map(|b| fnv64(b)).collect();
        assert_eq!(got, hashes, "--size {size} --seed {seed}");
        let explicit = sample(
            &dir.path().join(format!("{size}-explicit")),
            &[
                "--kind",
                "fluorescence",
                "--channels",
                "3",
                "--size",
                size,
                "--seed",
                seed,
            ],
        );
        assert!(contents(&explicit) == contents(&plain));
    }
}

#[test]
fn fluorescence_has_exactly_three_channels() {
    let dir = tempfile::tempdir().unwrap();
    let out = ingest(&[
        "sample",
        "-o",
        arg(dir.path()),
        "--channels",
        "4",
        "--quiet",
    ]);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(
        String::from_utf8_lossy(&out.stderr),
        "error: --channels 4: the fluorescence sample has exactly 3 channels (nuclei, \
         membranes, filaments); use --kind cycif for many channels\n"
    );
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    for (kind, n) in [("cycif", "0"), ("sparse", "65")] {
        let out = ingest(&[
            "sample",
            "-o",
            arg(dir.path()),
            "--kind",
            kind,
            "--channels",
            n,
        ]);
        assert_eq!(out.status.code(), Some(1));
        assert_eq!(
            String::from_utf8_lossy(&out.stderr),
            format!("error: --channels {n}: must be between 1 and 64\n")
        );
    }
    let out = ingest(&[
        "sample",
        "-o",
        arg(dir.path()),
        "--kind",
        "dense",
        "--size",
        "0,4,4",
    ]);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(
        String::from_utf8_lossy(&out.stderr),
        "error: --size 0,4,4: every extent must be at least 1 voxel\n"
    );
}

#[test]
fn sparse_is_bone_and_soft_tissue_in_noisy_air() {
    let dir = tempfile::tempdir().unwrap();
    let files = assert_deterministic(dir.path(), &["--kind", "sparse", "--size", "48,96,96"]);
    assert_eq!(names(&files), ["sparse.ome.tif"]);
    let stack = read_stack(&files[0]);
    assert_eq!(stack.shape, [48, 96, 96]);
    assert_eq!(stack.dtype(), "uint16");
    assert_eq!(ome_voxel_size(&stack), ["1", "1", "1"]);
    assert!(stack.description.contains(r#"Name="density""#));
    let values = stack.values();
    // Air is a noise floor in 1..60, never 0 (the fill value), everywhere else.
    assert!(values.iter().all(|&v| v >= 1.0));
    let tissue = values.iter().filter(|&&v| v >= 60.0).count();
    // A small part of the voxels is specimen (bone and the soft tissue around it): at least
    // 0.5 %, at most 20 % at this size.
    assert!(
        tissue * 200 >= values.len() && tissue * 100 <= values.len() * 20,
        "{tissue} of {} voxels are specimen",
        values.len()
    );
    let blocks = block_ranges(&stack);
    // Most 8³ blocks hold only air: not empty of data, but transparent under a bone window.
    let empty = blocks.iter().filter(|r| r.0 >= 1.0 && r.1 < 60.0).count();
    assert!(
        empty * 2 > blocks.len(),
        "{empty} of {} blocks are air only",
        blocks.len()
    );
    // Bone, ribs and dense blobs: values span the three materials.
    let max = values.iter().copied().fold(0.0, f64::max);
    assert!((4000.0..=6000.0).contains(&max), "{max}");
    assert!(values.iter().any(|&v| (1000.0..2000.0).contains(&v)));
    // Soft tissue below every bone value, and more of it than bone shell.
    let soft = values
        .iter()
        .filter(|&&v| (100.0..400.0).contains(&v))
        .count();
    let shell = values
        .iter()
        .filter(|&&v| (1000.0..2000.0).contains(&v))
        .count();
    assert!(soft > shell, "{soft} soft-tissue voxels, {shell} bone");
    assert!(!values.iter().any(|&v| (400.0..1000.0).contains(&v)));
}

#[test]
fn sparse_channels_are_narrowing_windows_of_one_scan() {
    let dir = tempfile::tempdir().unwrap();
    let files = sample(
        dir.path(),
        &[
            "--kind",
            "sparse",
            "--size",
            "31,67,61",
            "--channels",
            "3",
            "--seed",
            "9",
        ],
    );
    assert_eq!(
        names(&files),
        [
            "sparse-00-density.ome.tif",
            "sparse-01-above2166.ome.tif",
            "sparse-02-above3333.ome.tif"
        ]
    );
    let stacks: Vec<Stack> = files.iter().map(|f| read_stack(f)).collect();
    let values: Vec<Vec<f64>> = stacks.iter().map(Stack::values).collect();
    for (k, s) in stacks.iter().enumerate() {
        assert_eq!(s.shape, [31, 67, 61]);
        assert_eq!(s.dtype(), "uint16");
        assert!(values[k].iter().any(|&v| v > 0.0), "channel {k} is empty");
    }
    for k in 1..3 {
        let threshold = [0.0, 2166.0, 3333.0][k];
        for (i, &v) in values[k].iter().enumerate() {
            let scan = values[0][i];
            // Below the window: exactly 0; inside: stretched, never 0.
            assert_eq!(
                v == 0.0,
                scan < threshold,
                "channel {k} voxel {i}: {scan} -> {v}"
            );
            // A monotone stretch: brighter voxels of the scan stay brighter.
            if scan >= threshold {
                let expect =
                    1 + (scan as u64 - threshold as u64) * 60_000 / (6000 - threshold as u64);
                assert_eq!(v, expect as f64);
            }
        }
    }
}

#[test]
fn dense_fills_every_block_with_varying_positive_values() {
    let dir = tempfile::tempdir().unwrap();
    let files = assert_deterministic(dir.path(), &["--kind", "dense", "--size", "40,48,56"]);
    assert_eq!(names(&files), ["dense.ome.tif"]);
    let stack = read_stack(&files[0]);
    assert_eq!(stack.shape, [40, 48, 56]);
    assert_eq!(stack.dtype(), "float32");
    assert_eq!(ome_voxel_size(&stack), ["1", "1", "1"]);
    assert!(stack.description.contains(r#"Type="float""#));
    let values = stack.values();
    assert!(
        values
            .iter()
            .all(|v| v.is_finite() && *v >= 0.05 && *v <= 1.2)
    );
    let blocks = block_ranges(&stack);
    assert_eq!(blocks.len(), 5 * 6 * 7);
    for (i, (lo, hi)) in blocks.iter().enumerate() {
        assert!(hi > lo, "block {i} is constant ({lo})");
    }
    // Heavy fluid above, light fluid below.
    let plane = 48 * 56;
    let mean = |z: usize| values[z * plane..(z + 1) * plane].iter().sum::<f64>() / plane as f64;
    assert!(mean(39) > mean(0) + 0.3, "{} vs {}", mean(39), mean(0));
}

#[test]
fn dense_channels_are_transfer_functions_of_one_field() {
    let dir = tempfile::tempdir().unwrap();
    let files = sample(
        dir.path(),
        &["--kind", "dense", "--size", "16,19,23", "--channels", "5"],
    );
    assert_eq!(
        names(&files),
        [
            "dense-00-density.ome.tif",
            "dense-01-heavy.ome.tif",
            "dense-02-light.ome.tif",
            "dense-03-interface.ome.tif",
            "dense-04-heavy2.ome.tif"
        ]
    );
    let stacks: Vec<Stack> = files.iter().map(|f| read_stack(f)).collect();
    let Voxels::F32(rho) = &stacks[0].voxels else {
        panic!("density is not float32")
    };
    for (k, s) in stacks.iter().enumerate() {
        assert_eq!(s.shape, [16, 19, 23]);
        let Voxels::F32(v) = &s.voxels else {
            panic!("channel {k} is not float32")
        };
        for (i, (&r, &x)) in rho.iter().zip(v).enumerate() {
            assert!(x > 0.0 && x.is_finite(), "channel {k} voxel {i}: {x}");
            // The channels are exact functions of the density (computed in f64 from the
            // unrounded density, hence the tolerance).
            let r = f64::from(r);
            let expect = match k {
                0 => r,
                1 => r * r,
                2 => 1.25 - r,
                3 => 0.05 + (-((r - 0.52) / 0.15).powi(2)).exp(),
                _ => r * r * r,
            };
            assert!(
                (f64::from(x) - expect).abs() < 1e-6,
                "channel {k} voxel {i}: {x} vs {expect}"
            );
        }
    }
}

#[test]
fn cycif_markers_are_bright_in_different_cells() {
    let dir = tempfile::tempdir().unwrap();
    let files = assert_deterministic(dir.path(), &["--kind", "cycif", "--size", "6,256,256"]);
    let panel = [
        "dapi", "keratin", "cd45", "cd3", "cd8", "cd4", "cd20", "cd68", "ki67", "ecad", "vimentin",
        "sma", "cd31", "foxp3", "pd1", "pdl1",
    ];
    let expected: Vec<String> = panel
        .iter()
        .enumerate()
        .map(|(k, m)| format!("cycif-{k:02}-{m}.ome.tif"))
        .collect();
    assert_eq!(names(&files), expected);
    let stacks: Vec<Stack> = files.iter().map(|f| read_stack(f)).collect();
    // Bright: well above the background (camera offset 60, noise up to 63, autofluorescence
    // 40).
    let bright: Vec<Vec<bool>> = stacks
        .iter()
        .map(|s| s.values().iter().map(|&v| v > 1000.0).collect())
        .collect();
    for (k, s) in stacks.iter().enumerate() {
        assert_eq!(s.shape, [6, 256, 256]);
        assert_eq!(s.dtype(), "uint16");
        assert_eq!(ome_voxel_size(s), ["1", "0.325", "0.325"]);
        assert!(s.description.contains(&format!(r#"Name="{}""#, panel[k])));
        let values = s.values();
        assert!(
            values.iter().all(|&v| v >= 60.0),
            "channel {k} below the offset"
        );
        let dim = values.iter().filter(|&&v| v <= 163.0).count();
        assert!(
            dim * 2 > values.len(),
            "channel {k}: background covers {dim} voxels"
        );
        assert!(
            bright[k].iter().any(|&b| b),
            "channel {k} ({}) is never bright",
            panel[k]
        );
        for j in 0..k {
            assert_ne!(
                bright[j], bright[k],
                "{} and {} are bright in the same voxels",
                panel[j], panel[k]
            );
        }
    }
    let overlap = |a: usize, b: usize| {
        bright[a]
            .iter()
            .zip(&bright[b])
            .filter(|(x, y)| **x && **y)
            .count()
    };
    // Mutually exclusive cell types never share a bright voxel...
    assert_eq!(overlap(3, 6), 0, "cd3 T cells vs cd20 B cells");
    assert_eq!(overlap(4, 5), 0, "cd8 vs cd4 T cells");
    assert_eq!(overlap(1, 2), 0, "keratin epithelium vs cd45 immune cells");
    assert_eq!(overlap(0, 3), 0, "nuclear DAPI vs membrane cd3");
    // ...while markers of the same cells' membranes do.
    assert!(overlap(2, 3) > 0, "cd45 and cd3 stain the same T cells");
}

#[test]
fn every_kind_works_at_tiny_and_prime_sizes() {
    let dir = tempfile::tempdir().unwrap();
    for kind in ["fluorescence", "sparse", "dense", "cycif"] {
        for size in ["8,16,16", "1,1,1", "7,13,11", "3,2,5"] {
            let out = dir.path().join(format!("{kind}-{size}"));
            let files = sample(
                &out,
                &[
                    "--kind",
                    kind,
                    "--size",
                    size,
                    "--channels",
                    if kind == "fluorescence" { "3" } else { "2" },
                ],
            );
            assert_eq!(files.len(), if kind == "fluorescence" { 3 } else { 2 });
            let shape: Vec<usize> = size.split(',').map(|v| v.parse().unwrap()).collect();
            for f in &files {
                assert_eq!(read_stack(f).shape.to_vec(), shape, "{}", f.display());
            }
        }
    }
}

#[test]
fn cycif_default_is_a_thin_stack_of_sixteen_markers() {
    let dir = tempfile::tempdir().unwrap();
    let stdout = ingest_ok(&[
        "sample",
        "-o",
        arg(dir.path()),
        "--kind",
        "cycif",
        "--quiet",
    ]);
    assert!(
        stdout.starts_with(
            "wrote the cycif sample stack (24 x 256 x 256 voxels, z,y,x; 16 channels):\n"
        ),
        "{stdout}"
    );
    let first = read_stack(&dir.path().join("cycif-00-dapi.ome.tif"));
    assert_eq!(first.shape, [24, 256, 256]);
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 16);
}

/// Converts the files a sample run listed and returns the root metadata of the store.
fn convert(files: &[PathBuf], store: &Path) -> (String, serde_json::Value) {
    let mut args = vec!["convert"];
    args.extend(files.iter().map(|f| arg(f)));
    args.extend(["-o", arg(store), "--chunk", "16", "--quiet"]);
    let summary = ingest_ok(&args);
    let root = serde_json::from_slice(&std::fs::read(store.join("zarr.json")).unwrap()).unwrap();
    (summary, root)
}

fn labels(root: &serde_json::Value) -> Vec<String> {
    root["attributes"]["ome"]["omero"]["channels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["label"].as_str().unwrap().to_string())
        .collect()
}

fn scale(root: &serde_json::Value) -> serde_json::Value {
    root["attributes"]["ome"]["multiscales"][0]["datasets"][0]["coordinateTransformations"][0]
        ["scale"]
        .clone()
}

fn level0(root: &serde_json::Value) -> (u64, u64) {
    let l = &root["attributes"]["residency"]["levels"][0];
    (
        l["bricks_written"].as_u64().unwrap(),
        l["bricks_empty"].as_u64().unwrap(),
    )
}

#[test]
fn every_kind_converts_to_a_store() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path();

    let files = sample(&p.join("fluorescence"), &["--size", "16,32,32"]);
    let (summary, root) = convert(&files, &p.join("fluorescence.ome.zarr"));
    assert!(summary.contains("(uint16)"), "{summary}");
    assert_eq!(labels(&root), ["nuclei", "membranes", "filaments"]);
    assert_eq!(scale(&root), serde_json::json!([1.0, 2.0, 0.5, 0.5]));

    let files = sample(
        &p.join("sparse"),
        &["--kind", "sparse", "--size", "48,64,64", "--channels", "2"],
    );
    let (summary, root) = convert(&files, &p.join("sparse.ome.zarr"));
    assert!(summary.contains("(uint16)"), "{summary}");
    assert_eq!(labels(&root), ["density", "above2750"]);
    assert_eq!(scale(&root), serde_json::json!([1.0, 1.0, 1.0, 1.0]));
    let (written, empty) = level0(&root);
    assert_eq!(written + empty, 2 * 3 * 4 * 4);
    assert!(
        empty > 0 && written > 0,
        "sparse: {written} written, {empty} empty"
    );

    let files = sample(
        &p.join("dense"),
        &["--kind", "dense", "--size", "32,32,48", "--channels", "2"],
    );
    let (summary, root) = convert(&files, &p.join("dense.ome.zarr"));
    assert!(summary.contains("(float32)"), "{summary}");
    assert_eq!(labels(&root), ["density", "heavy"]);
    assert_eq!(level0(&root), (2 * 2 * 2 * 3, 0), "dense: no empty brick");

    let files = sample(
        &p.join("cycif"),
        &["--kind", "cycif", "--size", "5,96,80", "--channels", "20"],
    );
    let (summary, root) = convert(&files, &p.join("cycif.ome.zarr"));
    assert!(summary.contains("(uint16)"), "{summary}");
    let l = labels(&root);
    assert_eq!(l.len(), 20);
    assert_eq!(l[..3], ["dapi", "keratin", "cd45"]);
    assert_eq!(l[16..], ["marker16", "marker17", "marker18", "marker19"]);
    assert_eq!(scale(&root), serde_json::json!([1.0, 1.0, 0.325, 0.325]));
}
