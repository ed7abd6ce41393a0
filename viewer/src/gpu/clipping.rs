//! The scene's clipping ([`crate::scene::Clip`]) as the per-frame uniforms carry it: the box
//! and the planes in leaf units, which `volume_span` (`shaders/view.wgsl`) cuts each ray's span
//! by.

use super::contract::{CLIP_PLANE_SLOTS, Params};
use crate::scene::Scene;

/// The clip fields of [`Params`] for `scene` (the rest default): its box within the volume and
/// its planes (and `near`'s, from its camera), in leaf units of `leaf_world` world units per
/// leaf, for a volume of `voxels` level-0 voxels in leaves of `2^leaf_shift` voxels per axis.
pub(crate) fn clip_params(
    scene: &Scene,
    leaf_world: [f64; 3],
    voxels: [u64; 3],
    leaf_shift: [i32; 3],
) -> Params {
    let volume: [f64; 3] =
        std::array::from_fn(|a| voxels[a] as f64 / (leaf_shift[a] as f64).exp2());
    let (lo, hi) = match scene.clip.region {
        Some(b) => (
            std::array::from_fn(|a| (b.min[a] / leaf_world[a]).clamp(0.0, volume[a])),
            std::array::from_fn(|a| (b.max[a] / leaf_world[a]).clamp(0.0, volume[a])),
        ),
        None => ([0.0; 3], volume),
    };
    let mut planes = [[0.0f32; 4]; CLIP_PLANE_SLOTS];
    let world = scene.clip.planes_for(&scene.camera);
    for (slot, p) in planes.iter_mut().zip(&world) {
        // n · p_world = Σ n_a · leaf_a · p_leaf_a: the normal in leaf units, then unit length.
        let n: [f64; 3] = std::array::from_fn(|a| p.normal[a] * leaf_world[a]);
        let len = crate::scene::box_diagonal(n.map(f64::abs));
        let d: f64 = (0..3).map(|a| p.normal[a] * p.point[a]).sum();
        *slot = [
            (n[0] / len) as f32,
            (n[1] / len) as f32,
            (n[2] / len) as f32,
            (d / len) as f32,
        ];
    }
    Params {
        clip_lo: lo.map(|x: f64| x as f32),
        clip_hi: hi.map(|x: f64| x as f32),
        clip_plane_count: world.len().min(CLIP_PLANE_SLOTS) as u32,
        clip_planes: planes,
        ..Params::default()
    }
}
