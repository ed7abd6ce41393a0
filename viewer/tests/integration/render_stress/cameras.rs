//! Far and near cameras, and grazing rays along brick, leaf and node faces.

use super::*;

/// A camera `diagonals` volume diagonals away from the centre of an `n`³ volume, along an
/// oblique direction, with a field of view that makes the volume's diagonal the image height.
fn far_scene(n: u64, diagonals: f64) -> Scene {
    let half = n as f64 / 2.0;
    let centre = [half; 3];
    let diag = 3.0f64.sqrt() * n as f64;
    let d = diagonals * diag;
    let dir: [f64; 3] = [0.8, -0.5, 0.33];
    let n = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
    let eye = std::array::from_fn(|i| centre[i] + d * dir[i] / n);
    let mut cam = camera(eye, centre);
    cam.fov_y_degrees = 2.0 * (0.5 * diag / d).atan().to_degrees();
    scene(cam, shell_style(), [0.0, 0.0, 0.1])
}

fn far_camera(n: u64, diagonals: f64, psnr: f64, ssim: f64, max_abs: f64) {
    let src = shell_n(n);
    let s = far_scene(n, diagonals);
    let reference = reference(src.as_ref(), &s, 32, 32);
    assert!(reference.pixels.iter().filter(|p| p[0] > 0.2).count() > 150);
    for method in METHODS {
        let label = format!("far-{n}-{diagonals:e}-{}", method.name());
        let g = gpu_render(&label, src.clone(), &s, options(32, 32, method), false);
        let m = compare(&label, &g, &reference);
        assert_metrics(&label, &m, psnr, ssim, max_abs);
    }
}

/// A camera 100 volume diagonals (5540 voxels) from the 32³ [`shell`], field of view 0.01 rad,
/// for every method: PSNR ≥ 55 dB, SSIM ≥ 0.999, max abs ≤ 0.01 (measured 61.8 dB, 0.99988,
/// 0.0040 for each of the five: as good as a near view of this volume).
#[test]
fn far_camera_100_diagonals_matches_the_reference() {
    far_camera(32, 100.0, 55.0, 0.999, 0.01);
}

/// A camera 10⁴ volume diagonals (4.8·10⁵ voxels) from a 28³ shell, whose box lies inside the
/// octree root (32³), field of view 10⁻⁴ rad: PSNR ≥ 48 dB, SSIM ≥ 0.999, max abs ≤ 0.05
/// (measured 51.5 dB, 0.99971, 0.037; 50.3 dB when rays started from the eye rather than from
/// the view point near the volume).
#[test]
fn far_camera_1e4_diagonals_volume_inside_the_root_matches_the_reference() {
    far_camera(28, 1e4, 48.0, 0.999, 0.05);
}

/// A camera 10⁴ volume diagonals from the 32³ [`shell`], whose faces are the octree root's;
/// thresholds as for the 28³ volume.
///
/// Measured 61.6 dB.
///
/// Regression: rays entering through a face of the octree root were dropped (background)
/// once the eye was about 10³ diagonals away. The shader started a ray at
/// `eye + dir·(t_enter + nudge)` in f32 leaf units; the product's rounding error (about
/// |eye| · 2⁻²⁴ leaf units) exceeded the nudge, so the start landed outside the root and the
/// ray ended at once (measured PSNR 12.3 dB, half the volume missing). The start is clamped
/// onto the face it entered through (and now starts from a view point near the volume).
#[test]
fn far_camera_1e4_diagonals_volume_filling_the_root_matches_the_reference() {
    far_camera(32, 1e4, 48.0, 0.999, 0.05);
}

/// A camera 10⁶ volume diagonals (5.5·10⁷ voxels) from a 28³ shell, field of view 10⁻⁶ rad,
/// for every method: as good as at 10⁴ diagonals, PSNR ≥ 48 dB, SSIM ≥ 0.999, max abs ≤ 0.05
/// (measured 51.5 dB, 0.99971, 0.037 for each of the five; SparseLeap's and rasterize's boxes
/// are projected relative to the view point, so the far eye costs them nothing either).
///
/// Regression: this rendered at 19.6 dB (SSIM 0.81, max abs 0.98), shifted by voxels and
/// blocky. Rays started at `eye + dir·t_enter` in f32 from an eye 6.9·10⁶ leaves away (ulp
/// 0.5 leaf = 4 voxels), and the per-pixel change of direction (3·10⁻⁸ rad) is below f32's
/// resolution of a unit vector's components (6·10⁻⁸). Rays now start from the plane through a
/// view point placed near the volume in f64 on the CPU, where the per-pixel offset is a
/// fraction of the volume and a direction error of 10⁻⁷ moves a sample by 10⁻⁵ voxel.
#[test]
fn far_camera_1e6_diagonals_matches_the_reference() {
    far_camera(28, 1e6, 48.0, 0.999, 0.05);
}

/// Cameras within 10⁻³ voxel of a face, for every method: just in front of the x = 0 face,
/// exactly on it, just inside the x = 16 brick face, exactly on the corner of eight bricks
/// (16, 16, 16), and just outside the far x = 32 face looking back; each with a 70° field of
/// view, so that the outer rays meet the face at grazing angles. Against the reference:
/// PSNR ≥ 50 dB, SSIM ≥ 0.999, max abs ≤ 0.01 (measured ≥ 53.9 dB, ≥ 0.99972, ≤ 0.0040: the
/// ordinary accuracy of a converged render of this volume; nothing is lost or doubled in the
/// first 10⁻³ voxel).
#[test]
fn near_cameras_match_the_reference() {
    let src = shell();
    let cases: [(&str, [f64; 3], [f64; 3]); 5] = [
        ("front", [-1e-3, 13.3, 17.9], [30.0, 16.0, 15.0]),
        ("on-face", [0.0, 13.3, 17.9], [30.0, 16.0, 15.0]),
        ("inside", [16.0 + 1e-3, 13.3, 17.9], [0.0, 16.0, 15.0]),
        ("corner", [16.0, 16.0, 16.0], [3.0, 30.0, 9.0]),
        ("behind", [32.0 + 1e-3, 18.4, 11.2], [0.0, 16.0, 15.0]),
    ];
    for (name, eye, target) in cases {
        let mut cam = camera(eye, target);
        cam.fov_y_degrees = 70.0;
        let s = scene(cam, shell_style(), [0.0, 0.0, 0.1]);
        let reference = reference(src.as_ref(), &s, 32, 32);
        for method in METHODS {
            let label = format!("near-{name}-{}", method.name());
            let g = gpu_render(&label, src.clone(), &s, options(32, 32, method), false);
            let m = compare(&label, &g, &reference);
            assert_metrics(&label, &m, 50.0, 0.999, 0.01);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Grazing rays
// ---------------------------------------------------------------------------------------------

/// u8 48³, bricks 16³, leaves 8³ (octree root 64³): a value that jumps across the brick face
/// x = 16 and on a checkerboard of 8-voxel leaf cells in x and z, plus ripples in y.
fn faces() -> Arc<SyntheticSource> {
    Arc::new(SyntheticSource::new(
        SampleType::U8,
        [48, 48, 48],
        [1.0; 3],
        [16; 3],
        8,
        1,
        |_, [x, y, z]| {
            60.0 + 50.0 * ((x / 8 + z / 8) % 2) as f64
                + if x >= 16 { 60.0 } else { 0.0 }
                + 25.0 * (0.37 * y as f64 + 0.2 * z as f64).sin()
        },
    ))
}

/// A camera at `(x, −25, z)` looking along +y (tilted by `tilt` radians towards +x), with up
/// = +x: in an odd image the central row's rays lie in the plane through the eye normal to x
/// (exactly `x` when `tilt` is 0), the central column's in the plane `z`.
fn grazing_camera(x: f64, z: f64, tilt: f64) -> Camera {
    Camera {
        eye: [x, -25.0, z],
        target: [x + 100.0 * tilt.sin(), -25.0 + 100.0 * tilt.cos(), z],
        up: [1.0, 0.0, 0.0],
        fov_y_degrees: 50.0,
    }
}

/// Rays exactly on brick, leaf and node faces and along their edges: the central row of a
/// 31×31 image runs in the plane x = X and the central column in z = Z, for (X, Z) on a brick
/// and depth-1 node face (16, 32), leaf faces inside a brick (8, 24), the volume's lower face
/// and a brick face (0, 16), the volume's upper faces (48, 48: outside, the box is half-open
/// like every cell); and rays at ±10⁻⁶ rad to the x = 16 face, crossing it inside the volume.
/// The data jump across x = 16 and across the 8-voxel leaf cells, so a ray attributed to the
/// wrong side shows. Every method, against the reference: PSNR ≥ 45 dB, SSIM ≥ 0.999, max abs
/// ≤ 0.04 (measured ≥ 48.7 dB, ≥ 0.99955, ≤ 0.028, the same for all methods), and along the
/// central row and column, where a crack would be, max abs ≤ 0.03 (measured ≤ 0.016).
#[test]
fn grazing_rays_along_brick_and_node_faces_match_the_reference() {
    let src = faces();
    let cases: [(&str, f64, f64, f64); 6] = [
        ("brick-16-node-32", 16.0, 32.0, 0.0),
        ("leaf-8-24", 8.0, 24.0, 0.0),
        ("outer-0-brick-16", 0.0, 16.0, 0.0),
        ("outer-48-48", 48.0, 48.0, 0.0),
        ("tilt-1e-6", 16.0 - 3e-5, 32.0, 1e-6),
        ("tilt-minus-1e-6", 16.0 + 3e-5, 32.0, -1e-6),
    ];
    let (w, h) = (31usize, 31usize);
    for (name, x, z, tilt) in cases {
        let s = scene(
            grazing_camera(x, z, tilt),
            vec![style(0, [0.9, 0.7, 0.3], &[(50.0, 0.0), (200.0, 0.35)])],
            [0.0, 0.0, 0.15],
        );
        let reference = reference(src.as_ref(), &s, w, h);
        for method in METHODS {
            let label = format!("grazing-{name}-{}", method.name());
            let g = gpu_render(
                &label,
                src.clone(),
                &s,
                options(w as u32, h as u32, method),
                false,
            );
            let m = compare(&label, &g, &reference);
            let mut line = 0.0f32;
            for i in 0..w {
                for p in [h / 2 * w + i, i * w + w / 2] {
                    for c in 0..3 {
                        line = line.max((g.img.pixels[p][c] - reference.pixels[p][c]).abs());
                    }
                }
            }
            eprintln!("{label}: central row and column max abs {line:.5}");
            assert!(line <= 0.03, "{label}: central row/column error {line}");
            assert_metrics(&label, &m, 45.0, 0.999, 0.04);
        }
    }
}
