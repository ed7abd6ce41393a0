//! The naive loader of the skipped-work comparison: the level a plain LOD rule picks for the
//! whole view (the shader's `footprint_level` and `channel_level` evaluated at the distance of
//! the volume centre), and every brick of that level whose box intersects the view frustum,
//! for every visible channel.
//! A loader without region metadata would fetch all of them.

use crate::gpu::renderer::RenderOptions;
use crate::scene::{Camera, Scene};
use crate::source::{BrickKey, VolumeInfo};

/// What the naive loader would fetch for one view.
#[derive(Clone, Debug, PartialEq)]
pub struct NaiveFetch {
    /// The level chosen for the whole view.
    pub level: u32,
    /// Bricks of that level intersecting the frustum, over all visible channels.
    pub bricks: Vec<BrickKey>,
}

/// The level the shader's `footprint_level` and `channel_level` pick at distance `t` from the
/// eye for a `height`-pixel image: the finest level (within `bounds`) whose voxel is at least
/// the pixel footprint `t · 2 tan(fov/2) / height · 2^lod_bias`.
pub fn choose_level(
    info: &VolumeInfo,
    camera: &Camera,
    options: &RenderOptions,
    bounds: (u32, u32),
    t: f64,
) -> u32 {
    let tan_half = (camera.fov_y_degrees.to_radians() / 2.0).tan();
    let target =
        t.max(0.0) * 2.0 * tan_half / options.height as f64 * (options.lod_bias as f64).exp2();
    let lmax = bounds.1.min(info.levels.len() as u32 - 1);
    let mut l = bounds.0.min(lmax);
    while l < lmax && info.voxel_edge(l as usize) < target {
        l += 1;
    }
    l
}

/// World box (`x, y, z` min and max) of brick `b` (`z, y, x`) of `level`, clipped to the volume.
pub fn brick_box(info: &VolumeInfo, level: usize, b: [u64; 3]) -> ([f64; 3], [f64; 3]) {
    let key = BrickKey {
        level: level as u32,
        channel: 0,
        brick: b,
    };
    let (v0, v1) = info.brick_box(&key, 0);
    let world = |v: [u64; 3]| std::array::from_fn(|w| v[2 - w] as f64 * info.voxel_size[2 - w]);
    (world(v0), world(v1))
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Whether the box `(lo, hi)` intersects the frustum of `camera` for an image of aspect
/// `aspect` (width / height): not entirely behind the eye nor outside any of the four side
/// planes (a conservative test: a box straddling a frustum corner may count as inside).
pub fn box_in_frustum(camera: &Camera, aspect: f64, lo: [f64; 3], hi: [f64; 3]) -> bool {
    let (f, r, u) = camera.basis();
    let th = (camera.fov_y_degrees.to_radians() / 2.0).tan();
    let tw = th * aspect;
    // Inward normals of the side planes through the eye.
    let planes = [
        std::array::from_fn(|i| f[i] * tw + r[i]),
        std::array::from_fn(|i| f[i] * tw - r[i]),
        std::array::from_fn(|i| f[i] * th + u[i]),
        std::array::from_fn(|i| f[i] * th - u[i]),
        f,
    ];
    let corners = (0..8).map(|k| {
        std::array::from_fn(|a| {
            let v = if k >> a & 1 == 1 { hi[a] } else { lo[a] };
            v - camera.eye[a]
        })
    });
    let corners: Vec<[f64; 3]> = corners.collect();
    planes
        .iter()
        .all(|n: &[f64; 3]| corners.iter().any(|c| dot(*n, *c) >= 0.0))
}

/// The naive loader's fetch list for `scene`'s camera: level by the LOD rule at the distance
/// of the volume centre, then every brick of it in the frustum, per visible channel.
pub fn naive_fetch(info: &VolumeInfo, scene: &Scene, options: &RenderOptions) -> NaiveFetch {
    let cam = &scene.camera;
    let centre = crate::defaults::volume_centre(info);
    let d: [f64; 3] = std::array::from_fn(|i| centre[i] - cam.eye[i]);
    let t = dot(d, d).sqrt();
    let bounds = options
        .level_bounds
        .first()
        .copied()
        .unwrap_or((0, info.levels.len() as u32 - 1));
    let level = choose_level(info, cam, options, bounds, t);
    let aspect = options.width as f64 / options.height as f64;
    let grid = info.brick_grid(level as usize);
    let mut bricks = Vec::new();
    let visible: Vec<u32> = scene
        .channels
        .iter()
        .filter(|c| c.visible)
        .map(|c| c.channel as u32)
        .collect();
    for bz in 0..grid[0] {
        for by in 0..grid[1] {
            for bx in 0..grid[2] {
                let b = [bz, by, bx];
                let (lo, hi) = brick_box(info, level as usize, b);
                if !box_in_frustum(cam, aspect, lo, hi) {
                    continue;
                }
                for &channel in &visible {
                    bricks.push(BrickKey {
                        level,
                        channel,
                        brick: b,
                    });
                }
            }
        }
    }
    NaiveFetch { level, bricks }
}

/// Whether `key` shows nothing under `scene`'s transfer function for its channel, in its mode: the
/// renderer's rule for a brick it never fetches ([`crate::gpu::renderer::is_clear`]), judged
/// by the brick's conservative range, so a brick counted here is certainly empty. A channel
/// without a style shows nothing.
pub fn transparent(info: &VolumeInfo, scene: &Scene, key: &BrickKey) -> bool {
    scene
        .channels
        .iter()
        .find(|c| c.channel == key.channel as usize)
        .is_none_or(|c| crate::gpu::renderer::is_clear(info, c, scene.mode, key, scene.filter))
}

/// Whether `key` holds the fill value (0) everywhere by its range, so that the store has no
/// chunk for it and nothing would be transferred.
pub fn fill_only(info: &VolumeInfo, key: &BrickKey) -> bool {
    let (lo, hi) = info.brick_range(key);
    lo > hi || (lo == 0.0 && hi == 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Camera;

    #[test]
    fn frustum_keeps_boxes_in_view_and_drops_those_behind() {
        let cam = Camera {
            eye: [0.0, 0.0, -10.0],
            target: [0.0, 0.0, 0.0],
            up: [0.0, -1.0, 0.0],
            fov_y_degrees: 30.0,
        };
        assert!(box_in_frustum(&cam, 1.0, [-1.0; 3], [1.0; 3]));
        assert!(!box_in_frustum(
            &cam,
            1.0,
            [-1.0, -1.0, -20.0],
            [1.0, 1.0, -12.0]
        ));
        assert!(!box_in_frustum(
            &cam,
            1.0,
            [50.0, -1.0, -1.0],
            [52.0, 1.0, 1.0]
        ));
    }
}
