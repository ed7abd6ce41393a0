//! The renderer's settings, [`RenderOptions`]: image size, cache budget, level of detail, step,
//! octree depth, request cap, level bounds, skipping and substitution, and the method.

use super::method::Method;

/// Renderer settings.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOptions {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Brick cache budget in bytes.
    pub cache_bytes: u64,
    /// LOD bias, `log2` of the pixel footprint scale: positive picks coarser levels. The
    /// default −1 (voxels of half a pixel footprint) sits on the benchmark's time-error front.
    pub lod_bias: f32,
    /// Step length as a fraction of the smallest voxel edge of the level in use.
    pub step_factor: f32,
    /// Octree leaf depth; `None` picks leaves of about [`Self::leaf_voxels`] voxels.
    pub octree_depth: Option<u32>,
    /// Target leaf edge in level-0 voxels when `octree_depth` is `None`.
    pub leaf_voxels: u64,
    /// Depth traversal starts at (and never restarts above).
    pub start_depth: u32,
    /// Most brick requests the shader records per frame.
    pub max_requests: u32,
    /// `(finest, coarsest)` level bounds per rendered channel, in scene order; missing
    /// entries allow every level.
    pub level_bounds: Vec<(u32, u32)>,
    /// Skip nodes empty under the transfer functions and integrate homogeneous nodes in
    /// closed form; `false` is the "no skipping" baseline (every node is sampled).
    pub empty_space_skipping: bool,
    /// Substitute a missing brick from another resident level (coarser first); `false`
    /// leaves the sample empty, as a page-table-only renderer would.
    pub substitution: bool,
    /// Traversal method: ours or a baseline.
    pub method: Method,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            width: 256,
            height: 256,
            cache_bytes: 256 << 20,
            lod_bias: -1.0,
            step_factor: 0.5,
            octree_depth: None,
            leaf_voxels: 8,
            start_depth: 0,
            max_requests: 4096,
            level_bounds: Vec::new(),
            empty_space_skipping: true,
            substitution: true,
            method: Method::Residency,
        }
    }
}
