//! A region of interest 10⁷ voxels from the origin: no cracks, no jitter, exact steps along
//! the long axis.

use super::*;

/// Extent of [`FarRoi`] along x: past the leaf boundary 77·2¹⁷ (leaves of 2¹⁷ voxels).
const FAR_EXTENT: u64 = 77 * (1 << 17) + 64;
/// Edge of [`FarRoi`]'s min/max cells along x: one octree leaf at the default depth 7.
const FAR_CELL: u64 = 1 << 17;
/// Length of a region of interest along x.
const ROI: u64 = 48;

/// The pattern of a region of interest at `(lx, y, z)`, `lx` from its start: a checkerboard
/// of 16³ blocks (the bricks when the region starts on a brick boundary), a thin shell, and
/// ripples along x.
fn roi_value(lx: u64, y: u64, z: u64) -> f64 {
    let block = ((lx / 16 + y / 16 + z / 16) % 2) as f64;
    let d = [lx as f64 - 24.3, y as f64 - 15.6, z as f64 - 16.2];
    let r = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    (40.0
        + 50.0 * block
        + 120.0 * (-(r - 12.0) * (r - 12.0) / 1.5).exp()
        + 30.0 * (0.9 * lx as f64).sin().abs())
    .round()
}

/// Stripes across x (period 3.3 voxels, so values change by up to 170 per voxel along x),
/// slowly varying in y and z.
fn stripes_value(lx: u64, y: u64, z: u64) -> f64 {
    let phase = std::f64::consts::TAU * lx as f64 / 3.3;
    (130.0 + 90.0 * phase.sin() + 10.0 * (0.3 * y as f64 + 0.2 * z as f64).sin()).round()
}

/// A u8 volume of 32 × 32 × `extent` voxels (`z, y, x`), bricks 16³, one level, holding the
/// fill value 0 except for regions of interest of [`ROI`] voxels along x starting at each of
/// `starts`, where voxel `(x, y, z)` holds `pattern(x − start, y, z)`. Procedural (never held
/// in memory), with region metadata in cells of 32 × 32 × [`FAR_CELL`] voxels.
struct FarRoi {
    info: VolumeInfo,
    starts: Vec<u64>,
    pattern: fn(u64, u64, u64) -> f64,
}

impl FarRoi {
    fn new(extent: u64, starts: Vec<u64>, pattern: fn(u64, u64, u64) -> f64) -> Self {
        let cells = extent.div_ceil(FAR_CELL);
        let (mut min, mut max) = (Vec::new(), Vec::new());
        for g in 0..cells {
            // Haloed like the server's: the cell's voxels plus one on each side.
            let (lo, hi) = ((g * FAR_CELL).saturating_sub(1), (g + 1) * FAR_CELL + 1);
            let hit = starts.iter().any(|&s| s < hi && s + ROI > lo);
            min.push(0.0);
            max.push(if hit { 255.0 } else { 0.0 });
        }
        let info = VolumeInfo {
            name: "far-roi".into(),
            sample_type: SampleType::U8,
            channels: vec!["c0".into()],
            display: vec![ChannelDisplay::default()],
            voxel_size: [1.0; 3],
            unit: None,
            brick_shape: [16; 3],
            levels: vec![LevelInfo {
                shape: [32, 32, extent],
                factor: [1; 3],
            }],
            minmax: Some(vec![vec![vec![MinMaxGrid {
                cell_shape: [32, 32, FAR_CELL],
                grid_shape: [1, 1, cells],
                min,
                max,
            }]]]),
        };
        Self {
            info,
            starts,
            pattern,
        }
    }

    fn value(&self, [x, y, z]: [u64; 3]) -> f64 {
        match self.starts.iter().find(|&&s| x >= s && x < s + ROI) {
            Some(&s) => (self.pattern)(x - s, y, z),
            None => 0.0,
        }
    }
}

impl BrickSource for FarRoi {
    fn info(&self) -> &VolumeInfo {
        &self.info
    }

    fn fetch(
        &self,
        keys: &[BrickKey],
    ) -> Vec<Result<BrickVoxels, residency_viewer::source::SourceError>> {
        keys.iter()
            .map(|k| {
                self.info.check_key(k)?;
                let x0 = k.brick[2] * 16;
                if !self.starts.iter().any(|&s| s < x0 + 16 && s + ROI > x0) {
                    return Ok(BrickVoxels::Empty);
                }
                let mut v = Vec::with_capacity(16 * 16 * 16);
                for z in 0..16 {
                    for y in 0..16 {
                        for x in 0..16 {
                            let p = [x0 + x, k.brick[1] * 16 + y, k.brick[0] * 16 + z];
                            v.push(self.value(p) as u8);
                        }
                    }
                }
                Ok(BrickVoxels::U8(v))
            })
            .collect()
    }
}

/// The view of a region of interest starting at `x0`, the eye moved by `shift` along x.
fn roi_scene(x0: u64, shift: f64) -> Scene {
    let x0 = x0 as f64;
    scene(
        camera([x0 + 24.37 + shift, -30.2, 40.6], [x0 + 20.1, 16.3, 14.2]),
        vec![style(0, [1.0, 0.75, 0.35], &[(45.0, 0.0), (180.0, 0.45)])],
        [0.0, 0.0, 0.12],
    )
}

/// A region of interest 10⁷ voxels from the origin. The viewer has no volume origin (the
/// OME-Zarr `translation` is not read: `VolumeInfo` has none, and world space starts at voxel
/// 0), so the offset is modelled as the camera and the region sitting at x = 10⁷ inside a
/// volume 1.009·10⁷ voxels long, empty (fill value) elsewhere; 32 × 32 voxels across, since
/// page tables are dense. At the default octree depth (7) a leaf is 2¹⁷ voxels along x, so
/// positions there keep 2⁻⁷ voxel in the leaf's f32 offset, where f32 world coordinates would
/// keep 1 voxel. Two regions: one at x = 10⁷ (bricks aligned, inside one leaf) and one
/// straddling the leaf boundary 77·2¹⁷ = 10 092 544.
///
/// Checks, for every method, each region and each eye position (moved by 0, 0.05 and 0.3
/// voxel along x; all five methods measured the same):
/// - against the reference: PSNR ≥ 45 dB, SSIM ≥ 0.998, max abs ≤ 0.05 (measured ≥ 47.9 dB,
///   ≥ 0.9990, ≤ 0.039; the same region near the origin: 48.7 dB, 0.028). A crack along a
///   brick or leaf boundary, a line of wrong pixels, would exceed the maximum;
/// - against the same picture rendered near the origin (the region 40 voxels from it, with
///   empty space around it as far): max abs ≤ 0.02 (measured ≤ 0.010 inside the leaf, ≤ 0.016
///   across the leaf boundary, where a faint line shows: see
///   [`region_1e7_voxels_from_the_origin_steps_exactly_along_the_long_axis`]);
/// - jitter: moving the eye changes the far image as it changes the near one,
///   max |ΔGPU_far − ΔGPU_near| ≤ 0.03 (measured ≤ 0.012 inside the leaf, 0.024 across the
///   boundary; in f32 world coordinates, where 10⁷ has an ulp of 1 voxel, a 0.05-voxel move
///   would change nothing, a 0.3-voxel one jump by a voxel), and as it changes the reference,
///   max |ΔGPU_far − Δref| ≤ 0.05 (measured ≤ 0.024, near the origin too: the GPU samples at
///   the start of ½-voxel steps, the reference in the middle of ¼ steps, so a move shifts
///   their sampling phases differently).
#[test]
fn region_1e7_voxels_from_the_origin_has_no_cracks_or_jitter() {
    let far_starts = [10_000_000, 77 * (1 << 17) - 24];
    let far: Arc<dyn BrickSource> =
        Arc::new(FarRoi::new(FAR_EXTENT, far_starts.to_vec(), roi_value));
    // The same region 40 voxels from the origin, with empty space on both sides as far away.
    let near: Arc<dyn BrickSource> = Arc::new(FarRoi::new(ROI + 80, vec![40], roi_value));
    let shifts = [0.0, 0.05, 0.3];
    for method in METHODS {
        let render = |src: &Arc<dyn BrickSource>, x0: u64, shift: f64| {
            let s = roi_scene(x0, shift);
            let label = format!("roi-{x0}-{shift}-{}", method.name());
            let g = gpu_render(&label, src.clone(), &s, options(32, 32, method), false);
            let r = reference::render(src.as_ref(), &s, &ReferenceOptions::new(32, 32))
                .expect("reference");
            let m = compare(&label, &g, &r);
            assert!(
                r.pixels.iter().filter(|p| p[0] > 0.3).count() > 300,
                "{label}: the region must fill the picture"
            );
            assert_metrics(&label, &m, 45.0, 0.998, 0.05);
            (g.img, r)
        };
        let max_diff = |a: &RgbImage, b: &RgbImage, c: &RgbImage, d: &RgbImage| {
            let mut m = 0.0f32;
            for i in 0..a.pixels.len() {
                for k in 0..3 {
                    let x = (a.pixels[i][k] - b.pixels[i][k]) - (c.pixels[i][k] - d.pixels[i][k]);
                    m = m.max(x.abs());
                }
            }
            m
        };
        let blank = RgbImage::filled(32, 32, [0.0; 3]);
        let near_images: Vec<(RgbImage, RgbImage)> =
            shifts.iter().map(|&s| render(&near, 40, s)).collect();
        for x0 in far_starts {
            let images: Vec<(RgbImage, RgbImage)> =
                shifts.iter().map(|&s| render(&far, x0, s)).collect();
            for (k, shift) in shifts.iter().enumerate() {
                let twin = max_diff(&images[k].0, &near_images[k].0, &blank, &blank);
                eprintln!("roi-{x0}-{shift}: vs near twin max {twin:.5}");
                if k == 0 {
                    continue;
                }
                let (g, g0) = (&images[k].0, &images[0].0);
                let jitter = max_diff(g, g0, &near_images[k].0, &near_images[0].0);
                let against_ref = max_diff(g, g0, &images[k].1, &images[0].1);
                let change = max_diff(&images[k].1, &images[0].1, &blank, &blank);
                eprintln!(
                    "roi-{x0}-{shift}: jitter vs near {jitter:.5}, vs reference {against_ref:.5}, \
                 reference change {change:.5}"
                );
                assert!(
                    change > 0.005,
                    "roi-{x0}-{shift}: the move must change the picture"
                );
                assert!(jitter <= 0.03, "roi-{x0}-{shift}: jitter {jitter}");
                assert!(against_ref <= 0.05, "roi-{x0}-{shift}: {against_ref}");
            }
        }
    }
}

/// Stepping along the long axis far from the origin: [`stripes_value`] (sharp along x) at
/// x = 77·2¹⁷ − 48 (the upper half of a 2¹⁷-voxel leaf, where the leaf's f32 offset has an
/// ulp of 2⁻⁷ voxel), seen nearly along +y, so that the rays' x components range from 0 to
/// 0.35 across the image. The far render must match the same picture near the origin (the
/// region 40 voxels from it) to max abs ≤ 0.005 (what the f32 eye position far away allows:
/// 2⁻⁸ voxel times these stripes' slope), and the reference as well as the near render does:
/// PSNR ≥ 50 dB (near: 52.7 dB).
///
/// Measured: far 51.7 dB (near 52.7 dB), max |far − near| 0.0040.
///
/// Regression: far from the origin this was 42 dB, max abs 0.040, max |far − near| 0.033, in
/// the columns whose rays have |dir.x| in 0.02–0.08. The shader advanced `local += dir·dt` in
/// leaf units; with 2¹⁷-voxel leaves a ½-voxel step moved x by 0.5·|dir.x| voxel, a few ulps of
/// `local`, rounded the same way at every step: x drifted by up to half its true travel (and
/// did not move at all for |dir.x| < 2⁻⁷). Ray positions are now integer level-0 voxels plus
/// an f32 offset inside the voxel ("fine units").
#[test]
fn region_1e7_voxels_from_the_origin_steps_exactly_along_the_long_axis() {
    let x_far = 77 * (1 << 17) - 48;
    let far: Arc<dyn BrickSource> = Arc::new(FarRoi::new(FAR_EXTENT, vec![x_far], stripes_value));
    let near: Arc<dyn BrickSource> = Arc::new(FarRoi::new(ROI + 80, vec![40], stripes_value));
    let view = |x0: u64| {
        let eye = [x0 as f64 + 14.3, -8.0, 16.4];
        let mut cam = camera(eye, [eye[0] + 10.8, eye[1] + 60.0, eye[2]]);
        cam.fov_y_degrees = 20.0;
        let tf = style(0, [1.0, 0.75, 0.35], &[(45.0, 0.0), (220.0, 0.12)]);
        scene(cam, vec![tf], [0.0, 0.0, 0.12])
    };
    for method in METHODS {
        let mut images = Vec::new();
        for (name, src, x0) in [("near", &near, 40), ("far", &far, x_far)] {
            let label = format!("stripes-{name}-{}", method.name());
            let s = view(x0);
            let g = gpu_render(&label, src.clone(), &s, options(32, 32, method), false);
            let r = reference::render(src.as_ref(), &s, &ReferenceOptions::new(32, 32))
                .expect("reference");
            let m = compare(&label, &g, &r);
            assert!(m.psnr_db >= 50.0, "{label}: PSNR {}", m.psnr_db);
            images.push(g.img);
        }
        let twin = metrics::compare(&images[1], &images[0]).expect("compare");
        eprintln!("stripes: far vs near max {:.5}", twin.max_abs_error);
        assert!(
            twin.max_abs_error <= 0.005,
            "far vs near {}",
            twin.max_abs_error
        );
    }
}
