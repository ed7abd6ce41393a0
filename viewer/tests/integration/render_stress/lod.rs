//! A transition between levels of detail along rays: no seam.

use super::*;

/// A terrain 96 × 24 voxels wide and 16 high (u8, bricks 8³, 5 levels): opaque-ish ground
/// below a height field, textured, empty above.
fn terrain() -> Arc<SyntheticSource> {
    Arc::new(SyntheticSource::new(
        SampleType::U8,
        [16, 24, 96],
        [1.0; 3],
        [8; 3],
        4,
        1,
        |_, [x, y, z]| {
            let (x, y, z) = (x as f64, y as f64, z as f64);
            let h = 7.0 + 2.5 * (0.21 * x).sin() * (0.33 * y).cos();
            if z < h {
                120.0 + 80.0 * (0.45 * x).sin() * (0.6 * y).sin()
            } else {
                0.0
            }
        },
    ))
}

/// A perspective view down the terrain's length, 48×32 pixels, levels chosen by distance
/// (`lod_bias` 0, levels 0–1): the bottom rows see ground 20 voxels away, the top rows ground
/// 100 voxels away, and the level-0/level-1 boundary (pixel footprint = 1 voxel, at 44 voxels)
/// crosses the image, so near rows are drawn from level 0, far rows from level 1, and rows in
/// between switch level along each ray. The reference has no level selection, so the render is
/// compared with renders of each level alone (level bounds (0, 0) and (1, 1)) as well as with
/// the level-0 reference:
/// - both levels are used (bricks of both fetched; rows where the levels differ include rows
///   equal to level 0 alone and rows equal to level 1 alone);
/// - no seam: each row's mean abs error against the reference is at most the larger of the two
///   single-level renders' errors in that row plus 0.005 (measured excess ≤ 0.0001), and every
///   pixel lies within [min, max] of the two single-level renders ± 0.05 (measured 0.028: a
///   ray that switches level samples at other positions than either, but a skipped or doubled
///   step at the switch would be a jump of 0.1–0.5);
/// - against the level-0 reference: PSNR ≥ 33 dB, SSIM ≥ 0.98, max abs ≤ 0.6 (measured
///   35.7 dB, 0.98872, 0.574, between level 0 alone, 45.8 dB, and level 1 alone, 30.9 dB,
///   max abs 0.574 at the terrain's silhouette, which level 1 moves).
#[test]
fn lod_transition_has_no_seam() {
    let src = terrain();
    let s = scene(
        camera([-6.0, 12.0, 22.0], [50.0, 12.0, 4.0]),
        vec![style(
            0,
            [0.5, 0.9, 0.4],
            &[(20.0, 0.0), (100.0, 0.6), (200.0, 0.95)],
        )],
        [0.1, 0.1, 0.2],
    );
    let (w, h) = (48usize, 32usize);
    // LOD bias 0 (a voxel per pixel footprint) puts the level-0/level-1 boundary mid-image.
    let with_levels = |lo: u32, hi: u32| RenderOptions {
        level_bounds: vec![(lo, hi)],
        lod_bias: 0.0,
        ..RenderOptions {
            width: w as u32,
            height: h as u32,
            ..Default::default()
        }
    };
    let reference = reference(src.as_ref(), &s, w, h);
    let lod = gpu_render("lod", src.clone(), &s, with_levels(0, 1), false);
    let log = src.fetch_log();
    assert!(log.iter().any(|k| k.level == 0) && log.iter().any(|k| k.level == 1));
    let l0 = gpu_render("lod-l0", src.clone(), &s, with_levels(0, 0), false);
    let l1 = gpu_render("lod-l1", src.clone(), &s, with_levels(1, 1), false);
    let m = compare("lod", &lod, &reference);
    compare("lod-l0", &l0, &reference);
    compare("lod-l1", &l1, &reference);
    let mut outside = 0.0f32;
    for i in 0..w * h {
        for c in 0..3 {
            let (a, b, v) = (
                l0.img.pixels[i][c],
                l1.img.pixels[i][c],
                lod.img.pixels[i][c],
            );
            outside = outside.max(a.min(b) - v).max(v - a.max(b));
        }
    }
    let row_err = |img: &RgbImage, y: usize| {
        (0..w)
            .map(|x| {
                let (p, q) = (img.pixels[y * w + x], reference.pixels[y * w + x]);
                (0..3).map(|c| (p[c] - q[c]).abs()).sum::<f32>() / 3.0
            })
            .sum::<f32>()
            / w as f32
    };
    let row_equal = |a: &RgbImage, b: &RgbImage, y: usize| {
        (0..w).all(|x| a.pixels[y * w + x] == b.pixels[y * w + x])
    };
    let (mut as_l0, mut as_l1, mut mixed) = (0, 0, 0);
    let mut worst_row = 0.0f32;
    for y in 0..h {
        let (e, e0, e1) = (
            row_err(&lod.img, y),
            row_err(&l0.img, y),
            row_err(&l1.img, y),
        );
        worst_row = worst_row.max(e - e0.max(e1));
        if !row_equal(&l0.img, &l1.img, y) {
            if row_equal(&lod.img, &l0.img, y) {
                as_l0 += 1;
            } else if row_equal(&lod.img, &l1.img, y) {
                as_l1 += 1;
            } else {
                mixed += 1;
            }
        }
    }
    eprintln!(
        "lod: rows as level 0 {as_l0}, as level 1 {as_l1}, mixed {mixed}; outside [l0, l1] by \
         {outside:.5}, worst row excess {worst_row:.5}"
    );
    assert!(
        as_l0 > 0 && as_l1 > 0,
        "rows as level 0: {as_l0}, as level 1: {as_l1}"
    );
    assert!(
        outside <= 0.05,
        "LOD pixel outside the two levels by {outside}"
    );
    assert!(
        worst_row <= 0.005,
        "a row's error exceeds both levels' by {worst_row}"
    );
    assert_metrics("lod", &m, 33.0, 0.98, 0.6);
}
