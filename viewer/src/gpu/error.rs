//! [`GpuError`], why the GPU side failed, and the messages it gives.

use super::limits::{MAX_CHANNELS, MAX_LEVELS};
use crate::octree::OctreeError;
use crate::source::{BrickKey, SampleType, SourceError};

/// Why no adapter was found, and what to do.
#[cfg(not(target_arch = "wasm32"))]
pub(crate) const NO_ADAPTER: &str = "no GPU adapter found (without a GPU, install Mesa's lavapipe Vulkan \
                          driver and set XDG_RUNTIME_DIR)";
#[cfg(target_arch = "wasm32")]
pub(crate) const NO_ADAPTER: &str = "this browser offers no WebGPU adapter (use a current Chrome, Edge or \
                          Firefox with WebGPU enabled, on a machine whose GPU it supports)";

/// Why the GPU side failed: no adapter or device, a buffer or texture over the device's
/// limits, a GPU validation or out-of-memory error, a readback that failed, or a brick that
/// cannot be uploaded. Messages name the buffer, brick or limit at fault; errors of the
/// octree and of brick sources are theirs, unchanged.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// No adapter (message: what to install or use).
    #[error("{}", NO_ADAPTER)]
    NoAdapter(#[source] wgpu::RequestAdapterError),
    /// The adapter would not open a device.
    #[error("cannot open a device on {adapter}")]
    NoDevice {
        /// The adapter's name.
        adapter: String,
        /// What wgpu said.
        #[source]
        source: wgpu::RequestDeviceError,
    },
    /// A validation or out-of-memory error raised by work checked with `Gpu::checked`. wgpu's
    /// error is kept as its text: it is neither `Send` nor `Sync` on the web, where this error
    /// also travels.
    #[error("{what}: GPU error: {message}")]
    Validation {
        /// The work, e.g. `rendering a frame`.
        what: String,
        /// What wgpu said.
        message: String,
    },
    /// A buffer over the device's storage-binding (or buffer) limit.
    #[error(
        "{what} needs {bytes} bytes, over the device's storage-buffer limit of {limit} bytes; \
         {hint}"
    )]
    BindingTooLarge {
        /// The buffer, e.g. `the image`.
        what: String,
        /// Bytes it needs.
        bytes: u64,
        /// The device's storage-binding limit.
        limit: u64,
        /// What to do instead.
        hint: String,
    },
    /// More bricks than 32-bit brick ids address.
    #[error("{total} bricks over all channels and levels: too many for 32-bit brick ids")]
    TooManyBricks {
        /// Bricks over all channels and levels.
        total: u64,
    },
    /// A brick larger than the device's 3D textures.
    #[error("brick {brick:?} exceeds the device's 3D texture limit {limit}")]
    BrickOverTextureLimit {
        /// The brick, `x, y, z`.
        brick: [u32; 3],
        /// The device's 3D texture limit per axis.
        limit: u32,
    },
    /// A cache budget smaller than one brick.
    #[error("cache of {cache_bytes} bytes holds no brick of {brick_bytes} bytes")]
    CacheTooSmall {
        /// The budget.
        cache_bytes: u64,
        /// Bytes of one brick.
        brick_bytes: u64,
    },
    /// An empty brick given to the cache (it takes no slot).
    #[error("an empty brick takes no cache slot")]
    EmptyBrickUpload,
    /// Voxels that are not a full brick of the cache's sample type.
    #[error(
        "brick has {samples} samples of the wrong type or count (expected {expected} of \
         {sample_type:?})"
    )]
    WrongBrick {
        /// Samples given.
        samples: usize,
        /// Samples of a brick.
        expected: usize,
        /// The cache's sample type.
        sample_type: SampleType,
    },
    /// A brick that could not be uploaded.
    #[error("brick {key:?}")]
    Upload {
        /// The brick.
        key: BrickKey,
        /// Why.
        #[source]
        source: Box<GpuError>,
    },
    /// A brick not in the rendered channels' page tables.
    #[error("brick {key:?} is not part of the rendered volume")]
    NotRendered {
        /// The brick.
        key: BrickKey,
    },
    /// A cache slot whose owner has no page-table key (a bug).
    #[error("cache slot owner has no key")]
    SlotWithoutKey,
    /// More pyramid levels than the renderer's tables hold.
    #[error(
        "{volume}: {levels} pyramid levels; the renderer draws volumes of at most {}",
        MAX_LEVELS
    )]
    TooManyLevels {
        /// The volume.
        volume: String,
        /// Its levels.
        levels: usize,
    },
    /// More channels drawn than the renderer draws at once.
    #[error("{channels} channels drawn; at most {} render at once", MAX_CHANNELS)]
    TooManyChannels {
        /// Channels drawn.
        channels: usize,
    },
    /// More visible channels than the renderer draws at once.
    #[error("{channels} visible channels; at most {} render at once", MAX_CHANNELS)]
    TooManyVisible {
        /// Visible channels.
        channels: usize,
    },
    /// An image without pixels.
    #[error("image size {width}×{height} is empty")]
    EmptyImage {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
    },
    /// Rays that did not finish within the renderer's pass limit.
    #[error("{suspended} rays still marching after {passes} passes of {steps} steps")]
    RaysStillMarching {
        /// Rays still suspended.
        suspended: u32,
        /// Passes run.
        passes: u32,
        /// Steps per pass.
        steps: u32,
    },
    /// A brick id the shader reported that no page table has (a bug).
    #[error("shader reported an unknown brick id {id}")]
    UnknownBrickId {
        /// The id.
        id: u32,
    },
    /// Waiting for the GPU failed.
    #[error("waiting for the GPU")]
    Poll(#[source] wgpu::PollError),
    /// A mode a method cannot draw: iso-surfaces need the crossings of consecutive samples,
    /// which ray segment lists do not keep across their segments.
    #[error(
        "--method {method} does not draw the {mode} mode (use residency, page-table or octree)"
    )]
    ModeMethod {
        /// The method.
        method: &'static str,
        /// The mode.
        mode: &'static str,
    },
    /// A scene whose clipping cannot be drawn.
    #[error(transparent)]
    Clip(#[from] crate::scene::ClipError),
    /// A volumetric depth image asked of a scene in a mode other than emission–absorption:
    /// supersegments are composited colour and opacity.
    #[error(
        "a volumetric depth image is generated in the dvr mode only (the scene's mode is {mode})"
    )]
    VdiMode {
        /// The scene's mode.
        mode: &'static str,
    },
    /// A supersegment count a volumetric depth image cannot have.
    #[error("--supersegments {supersegments}: a VDI has 1 to {max} supersegments per pixel")]
    Supersegments {
        /// The count asked for.
        supersegments: u32,
        /// The most the format allows.
        max: u32,
    },
    /// A readback buffer that could not be mapped.
    #[error("cannot read back GPU buffer {buffer}: {source}")]
    Readback {
        /// The buffer's position among those mapped.
        buffer: usize,
        /// What wgpu said.
        #[source]
        source: wgpu::BufferAsyncError,
    },
    /// The device was lost while a readback buffer was being mapped.
    #[error("cannot read back GPU buffer {buffer}: the device was lost")]
    DeviceLost {
        /// The buffer's position among those mapped.
        buffer: usize,
    },
    /// A mapped buffer's range that cannot be viewed.
    #[error(transparent)]
    MapRange(#[from] wgpu::MapRangeError),
    /// The limit probe's level 0 could not be read.
    #[error("{volume}: the probe's level 0")]
    ProbeLevel0 {
        /// The volume.
        volume: String,
        /// Why.
        #[source]
        source: Box<SourceError>,
    },
    /// The limit probe asked to draw no channel, or too many.
    #[error("the limit probe draws 1 to {} channels, not {channels}", MAX_CHANNELS)]
    ProbeChannels {
        /// Visible channels.
        channels: usize,
    },
    /// A level 0 over one 3D texture of the device.
    #[error(
        "{volume}: the limit probe needs one 3D texture of {}×{}×{} voxels (level 0 of \
         {channels} channels stacked in z), over the device's limit of {limit} per axis",
        size[0], size[1], size[2]
    )]
    ProbeTexture {
        /// The volume.
        volume: String,
        /// The texture, `x, y, z` (channels stacked in z).
        size: [u32; 3],
        /// Channels stacked.
        channels: usize,
        /// The device's 3D texture limit per axis.
        limit: u32,
    },
    /// A probe filter the device does not have.
    #[error("this device has no {filter} probe")]
    NoProbe {
        /// The filter's name.
        filter: &'static str,
    },
    /// The residency octree refused the volume or a brick.
    #[error(transparent)]
    Octree(#[from] OctreeError),
    /// A brick could not be fetched.
    #[error(transparent)]
    Source(Box<SourceError>),
}

impl From<SourceError> for GpuError {
    fn from(e: SourceError) -> Self {
        Self::Source(Box::new(e))
    }
}
