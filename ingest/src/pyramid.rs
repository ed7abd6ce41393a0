//! The multiscale pyramid plan: which axes each level halves, and the shapes that result.
//!
//! Downsampling is anisotropy-aware: at each level, an axis is halved only when its current
//! voxel spacing is within a factor of √2 of the finest spacing among the axes still longer
//! than one voxel. A light-sheet stack with 4× coarser z is first halved in y and x only,
//! until the voxels are nearly isotropic, and then in all three axes.

/// One level of the pyramid.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LevelPlan {
    /// Extent `z, y, x` in voxels.
    pub shape: [u64; 3],
    /// Downsampling step from the previous level, `z, y, x` (each 1 or 2; all 1 for level 0).
    pub step: [u64; 3],
    /// Downsampling factor relative to level 0, `z, y, x`.
    pub factor: [u64; 3],
    /// Physical voxel size `z, y, x`.
    pub voxel_size: [f64; 3],
}

/// Plans the levels for a volume of `shape` with `voxel_size`, stopping when a level fits in
/// one brick, or after `max_levels` levels when given (never past a 1×1×1 level).
pub fn plan_levels(
    shape: [u64; 3],
    voxel_size: [f64; 3],
    brick: [u64; 3],
    max_levels: Option<usize>,
) -> Vec<LevelPlan> {
    let mut levels = vec![LevelPlan {
        shape,
        step: [1; 3],
        factor: [1; 3],
        voxel_size,
    }];
    loop {
        let last = levels.last().expect("level 0");
        let fits = (0..3).all(|i| last.shape[i] <= brick[i]);
        match max_levels {
            Some(n) if levels.len() >= n => break,
            None if fits => break,
            _ => {}
        }
        let finest = (0..3)
            .filter(|&i| last.shape[i] > 1)
            .map(|i| last.voxel_size[i])
            .fold(f64::INFINITY, f64::min);
        if !finest.is_finite() {
            break;
        }
        let step: [u64; 3] = std::array::from_fn(|i| {
            let halve = last.shape[i] > 1
                && last.voxel_size[i] <= finest * std::f64::consts::SQRT_2 * (1.0 + 1e-9);
            if halve { 2 } else { 1 }
        });
        levels.push(LevelPlan {
            shape: std::array::from_fn(|i| last.shape[i].div_ceil(step[i])),
            step,
            factor: std::array::from_fn(|i| last.factor[i] * step[i]),
            voxel_size: std::array::from_fn(|i| last.voxel_size[i] * step[i] as f64),
        });
    }
    levels
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn isotropic_volumes_halve_every_axis_until_one_brick() {
        let l = plan_levels([256, 256, 256], [1.0; 3], [64; 3], None);
        assert_eq!(l.len(), 3);
        assert_eq!(l[2].shape, [64, 64, 64]);
        assert_eq!(l[2].factor, [4, 4, 4]);
    }

    #[test]
    fn coarse_z_waits_for_xy_to_catch_up() {
        let l = plan_levels([100, 1000, 1000], [4.0, 1.0, 1.0], [64; 3], None);
        assert_eq!(l[1].step, [1, 2, 2]);
        assert_eq!(l[2].step, [1, 2, 2]);
        assert_eq!(l[3].step, [2, 2, 2]);
        assert_eq!(l[2].voxel_size, [4.0, 4.0, 4.0]);
        assert!(l.last().unwrap().shape.iter().all(|&s| s <= 64));
    }

    #[test]
    fn odd_shapes_round_up_and_flat_axes_stay() {
        let l = plan_levels([1, 33, 65], [1.0; 3], [8; 3], Some(3));
        assert_eq!(l.len(), 3);
        assert_eq!(l[1].shape, [1, 17, 33]);
        assert_eq!(l[2].shape, [1, 9, 17]);
        assert_eq!(l[1].step, [1, 2, 2]);
    }
}
