//! The renderer's fixed capacities, shared by the shader contract, the scene tables and the
//! errors that name them.

/// Most channels rendered at once (the shader keeps one value per channel in registers, each
/// channel's level in 8 bits of a `vec4<u32>` (the contract's `CHANNEL_LEVELS`), and a node's
/// class word holds an empty and a constant bit per channel).
pub const MAX_CHANNELS: usize = 16;

/// Most pyramid levels a volume may have: the octree's 16-bit residency masks hold one bit
/// per level, and the scene uniforms one entry.
pub use crate::octree::MAX_LEVELS;
