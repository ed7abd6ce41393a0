//! The paper's baselines (`Method::PageTable`, MRMCPT; `Method::Octree`, one node per brick)
//! and the no-skipping baseline render the same image as the residency octree and the f64
//! reference, and each does the work that defines it: the page table skips only whole empty
//! bricks and never substitutes, the octree needs every ancestor brick resident, and
//! `bricks_used` counts the working set a frame reads.

use std::collections::HashSet;
use std::sync::Arc;

use crate::render_common::*;
use residency_viewer::gpu::renderer::{Method, RenderOptions};
use residency_viewer::gpu::streaming::{Progressive, coarser_brick};
use residency_viewer::gpu::synthetic::SyntheticSource;
use residency_viewer::metrics;
use residency_viewer::scene::Scene;
use residency_viewer::source::{BrickSource, SampleType};

const METHODS: [Method; 5] = Method::ALL;

/// 32³ voxels in 16³ bricks (8 bricks, 2 levels): a blob of radius 3 in one octant of brick
/// (x 1, y 0, z 0) in channel 0 (so it fills one 8³ octree leaf of that brick), a shell around the volume centre in channel 1, and zero
/// elsewhere, so seven level-0 bricks of channel 0 hold only zeros.
fn one_blob(channels: usize) -> Arc<SyntheticSource> {
    Arc::new(SyntheticSource::new(
        SampleType::U16,
        [32, 32, 32],
        [1.0; 3],
        [16; 3],
        4,
        channels,
        |c, [x, y, z]| {
            let p = [x as f64 + 0.5, y as f64 + 0.5, z as f64 + 0.5];
            if c == 0 {
                let d2 = (p[0] - 20.0).powi(2) + (p[1] - 4.0).powi(2) + (p[2] - 4.0).powi(2);
                (20000.0 * (1.0 - d2 / 9.0)).max(0.0)
            } else {
                let r =
                    ((p[0] - 16.0).powi(2) + (p[1] - 16.0).powi(2) + (p[2] - 16.0).powi(2)).sqrt();
                (30000.0 * (1.0 - (r - 9.0).abs() / 2.0)).max(0.0)
            }
        },
    ))
}

fn scene(channels: usize) -> Scene {
    let colors = [[1.0, 0.6, 0.2], [0.2, 0.7, 1.0]];
    Scene {
        camera: camera([-30.0, -45.0, 40.0], [16.0, 16.0, 16.0]),
        channels: (0..channels)
            .map(|c| ramp(c, colors[c], 1000.0, 20000.0, 0.4))
            .collect(),
        background: [0.02, 0.02, 0.05],
        filter: residency_viewer::scene::Filter::Trilinear,
        mode: residency_viewer::scene::RenderMode::Dvr,
        clip: residency_viewer::scene::Clip::default(),
    }
}

fn options(method: Method) -> RenderOptions {
    RenderOptions {
        method,
        ..full_res(48, 48)
    }
}

fn total_samples(p: &Progressive) -> u64 {
    p.frames.last().expect("a frame").shader.samples
}

/// Every method, and the residency octree without skipping, converges at level 0 to the
/// reference (PSNR ≥ 40 dB, SSIM ≥ 0.99, the bar of `render_reference.rs`) for one and two
/// channels, with no brick left missing.
#[test]
fn every_method_matches_the_reference() {
    for channels in [1, 2] {
        let src = one_blob(channels);
        let s = scene(channels);
        let reference = reference(&src, &s, 48, 48);
        for (method, skipping) in METHODS
            .iter()
            .map(|&m| (m, true))
            .chain([(Method::Residency, false)])
        {
            let label = format!("{}-skip{skipping}-{channels}ch", method.name());
            let o = RenderOptions {
                empty_space_skipping: skipping,
                ..options(method)
            };
            let (p, img) = render(&src, &s, o, 30);
            let m = check(&label, &p, &img, &reference);
            assert!(p.converged, "{label}: {}", p.stop_reason);
            assert!(m.psnr_db >= 40.0, "{label}: PSNR {}", m.psnr_db);
            assert!(m.ssim >= 0.99, "{label}: SSIM {}", m.ssim);
        }
    }
}

/// With free level selection the three methods pick the same levels, so their converged
/// images agree with each other (PSNR ≥ 40 dB against the residency octree's).
#[test]
fn methods_agree_at_mixed_resolution() {
    let src = one_blob(2);
    let s = Scene {
        camera: camera([-90.0, -120.0, 100.0], [16.0, 16.0, 16.0]),
        ..scene(2)
    };
    let free = |method| RenderOptions {
        method,
        lod_bias: 1.0,
        ..RenderOptions {
            width: 48,
            height: 48,
            ..Default::default()
        }
    };
    let (p0, ours) = render(&src, &s, free(Method::Residency), 30);
    assert!(p0.converged, "{}", p0.stop_reason);
    let levels: HashSet<u32> = p0.request_log.iter().map(|k| k.level).collect();
    assert!(levels.contains(&1), "coarse level used: {levels:?}");
    for method in [Method::PageTable, Method::Octree] {
        let (p, img) = render(&src, &s, free(method), 30);
        assert!(p.converged, "{}: {}", method.name(), p.stop_reason);
        let m = metrics::compare(&img, &ours).unwrap();
        eprintln!("{} vs residency: {m:?}", method.name());
        assert!(m.psnr_db >= 40.0, "{}: {m:?}", method.name());
    }
}

/// The page table skips the seven all-zero bricks of channel 0 but samples the whole brick
/// holding the blob, where the residency octree also skips the empty 8³ leaves around the
/// blob. So it takes more samples than the residency octree and fewer than no skipping, it
/// reports the brick skips, and it never substitutes a missing brick.
#[test]
fn page_table_skips_only_whole_empty_bricks() {
    let src = one_blob(1);
    let s = scene(1);
    let (ours, _) = render(&src, &s, options(Method::Residency), 30);
    let (pt, _) = render(&src, &s, options(Method::PageTable), 30);
    let (naive, _) = render(
        &src,
        &s,
        RenderOptions {
            empty_space_skipping: false,
            ..options(Method::Residency)
        },
        30,
    );
    let (a, b, c) = (
        total_samples(&ours),
        total_samples(&pt),
        total_samples(&naive),
    );
    eprintln!("samples: residency {a}, page table {b}, no skipping {c}");
    assert!(2 * a < b, "residency {a} vs page table {b}");
    assert!(2 * b < c, "page table {b} vs no skipping {c}");
    let last = &pt.frames.last().unwrap().shader;
    assert!(last.empty_nodes_skipped > 0);
    assert_eq!(last.homogeneous_nodes, 0);
    assert!(pt.frames.iter().all(|f| f.shader.bricks_substituted == 0));
    // The page table samples the whole blob brick, and its samples near the brick's faces
    // read (and so request) the neighbouring all-zero bricks. The residency octree samples
    // only the blob's leaf, whose footprint reaches the neighbour across x = 16; that brick's
    // haloed range is transparent, so those samples are clear and it is never fetched.
    let level0 = |p: &Progressive| -> HashSet<[u64; 3]> {
        p.request_log
            .iter()
            .filter(|k| k.level == 0)
            .map(|k| k.brick)
            .collect()
    };
    assert_eq!(level0(&ours), HashSet::from([[0, 0, 1]]));
    assert!(level0(&pt).is_superset(&level0(&ours)));
    assert!(level0(&pt).len() > 2, "{:?}", level0(&pt));
}

/// The octree baseline descends from the coarsest level: its first frame requests only
/// coarsest-level bricks, every brick it fetches comes after its parent, and at level 0 it
/// needs the parents resident too, so its working set is larger than the residency octree's.
#[test]
fn octree_needs_every_ancestor_resident() {
    let src = one_blob(2);
    let s = scene(2);
    let at_level_0 = |method| RenderOptions {
        method,
        ..finest_wanted(48, 48)
    };
    let info = src.info().clone();
    let coarsest = info.levels.len() as u32 - 1;
    let (oct, img) = render(&src, &s, at_level_0(Method::Octree), 30);
    assert!(oct.converged, "{}", oct.stop_reason);
    assert!(oct.frames.len() >= 3, "one level per round trip");
    let first_round: Vec<_> = oct
        .request_log
        .iter()
        .take(oct.frames[0].bricks_fetched as usize)
        .collect();
    assert!(!first_round.is_empty());
    assert!(first_round.iter().all(|k| k.level == coarsest));
    let mut seen = HashSet::new();
    for k in &oct.request_log {
        if let Some(parent) = coarser_brick(&info, k) {
            assert!(seen.contains(&parent), "{k:?} fetched before {parent:?}");
        }
        seen.insert(*k);
    }
    let (ours, ours_img) = render(&src, &s, at_level_0(Method::Residency), 30);
    let used = |p: &Progressive| p.frames.last().unwrap().shader.bricks_used;
    eprintln!(
        "bricks used: octree {}, residency {}",
        used(&oct),
        used(&ours)
    );
    assert!(used(&oct) > used(&ours));
    let m = metrics::compare(&img, &ours_img).unwrap();
    assert!(m.psnr_db >= 40.0, "{m:?}");
}

/// `bricks_used` is the number of distinct resident bricks the last frame read: with the
/// whole 32³ volume in view at level 0 and no empty space (a ramp over every voxel), all 8
/// bricks of the one channel; after the frame that requests them, none were resident.
#[test]
fn bricks_used_counts_the_working_set() {
    let src = Arc::new(SyntheticSource::new(
        SampleType::U8,
        [32, 32, 32],
        [1.0; 3],
        [16; 3],
        4,
        1,
        |_, [x, y, z]| 40.0 + ((x + 2 * y + 3 * z) % 200) as f64,
    ));
    let s = Scene {
        camera: camera([-40.0, -50.0, 60.0], [16.0, 16.0, 16.0]),
        channels: vec![ramp(0, [1.0, 1.0, 1.0], 30.0, 240.0, 0.05)],
        background: [0.0; 3],
        filter: residency_viewer::scene::Filter::Trilinear,
        mode: residency_viewer::scene::RenderMode::Dvr,
        clip: residency_viewer::scene::Clip::default(),
    };
    for method in METHODS {
        let (p, _) = render(&src, &s, options(method), 30);
        assert!(p.converged, "{}", p.stop_reason);
        assert_eq!(p.frames[0].shader.bricks_used, 0, "{}", method.name());
        assert_eq!(
            p.frames.last().unwrap().shader.bricks_used,
            8,
            "{}",
            method.name()
        );
    }
}

/// The baselines' culling data is conservative: a brick's range holds every voxel of its
/// level within one voxel of its box (what a trilinear sample inside it reads), and its
/// subtree range also holds those of every finer level under its box. Checked for every
/// brick of a volume with odd sizes (partial edge bricks) against the voxels themselves.
#[test]
fn brick_ranges_bound_what_samples_read() {
    use residency_viewer::source::BrickKey;
    let src = SyntheticSource::new(
        SampleType::U16,
        [20, 40, 36],
        [1.0; 3],
        [8, 8, 8],
        4,
        1,
        |_, [x, y, z]| ((x * 37 + y * 11 + z * 5) % 97) as f64 * ((x + y) % 3) as f64,
    );
    let info = src.info().clone();
    let voxels_near = |level: usize, lo: [u64; 3], hi: [u64; 3]| {
        let s = info.levels[level].shape;
        let mut r = (f64::INFINITY, f64::NEG_INFINITY);
        for z in lo[0].saturating_sub(1)..(hi[0] + 1).min(s[0]) {
            for y in lo[1].saturating_sub(1)..(hi[1] + 1).min(s[1]) {
                for x in lo[2].saturating_sub(1)..(hi[2] + 1).min(s[2]) {
                    let v = src.value(0, level, [x, y, z]);
                    r = (r.0.min(v), r.1.max(v));
                }
            }
        }
        r
    };
    let mut checked = 0;
    for (l, level) in info.levels.iter().enumerate() {
        let grid = info.brick_grid(l);
        for bz in 0..grid[0] {
            for by in 0..grid[1] {
                for bx in 0..grid[2] {
                    let key = BrickKey {
                        level: l as u32,
                        channel: 0,
                        brick: [bz, by, bx],
                    };
                    let own = info.brick_range(&key);
                    let sub = info.subtree_range(&key);
                    for j in 0..=l {
                        let f: [u64; 3] =
                            std::array::from_fn(|a| level.factor[a] / info.levels[j].factor[a]);
                        let s = info.levels[j].shape;
                        let lo = std::array::from_fn(|a| key.brick[a] * info.brick_shape[a] * f[a]);
                        let hi = std::array::from_fn(|a| {
                            ((key.brick[a] + 1) * info.brick_shape[a] * f[a]).min(s[a])
                        });
                        let (a, b) = voxels_near(j, lo, hi);
                        assert!(
                            sub.0 <= a && b <= sub.1,
                            "{key:?} level {j}: {sub:?} vs {a}..{b}"
                        );
                        if j == l {
                            assert!(own.0 <= a && b <= own.1, "{key:?}: {own:?} vs {a}..{b}");
                        }
                        checked += 1;
                    }
                }
            }
        }
    }
    assert!(checked > 40, "{checked}");
}
