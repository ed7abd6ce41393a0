//! Where a volume comes from: its description (levels, bricks, channels, region metadata) and
//! its bricks, from a brick server over HTTP or from a local OME-Zarr store, behind one trait.
//!
//! - [`local`]: [`LocalSource`], a local OME-Zarr store read with zarrs (native);
//! - [`server`]: the `brickserver` protocol (URLs, metadata, batched bricks, framed min/max),
//!   with no I/O of its own;
//! - [`http`]: [`HttpSource`], that protocol over blocking HTTP (native; the web viewer
//!   speaks it through the browser's `fetch`);
//! - [`regions`]: whether a store's region metadata can drive culling.
//!
//! The volume's description itself ([`VolumeInfo`]) and its making from the OME-Zarr metadata
//! are `residency_schemas::volume`'s, re-exported here.

use std::path::PathBuf;
use std::sync::Arc;

use residency_schemas::ome::OmeError;
use residency_schemas::sample_type::PartialSample;
use residency_schemas::wire::{BrickEncoding, WireError};
use residency_schemas::zarr::ArrayMetadataError;
#[cfg(not(target_arch = "wasm32"))]
use residency_store::pyramid::PyramidError;

#[cfg(not(target_arch = "wasm32"))]
pub mod http;
#[cfg(not(target_arch = "wasm32"))]
pub mod local;
pub mod regions;
pub mod server;

#[cfg(not(target_arch = "wasm32"))]
pub use http::{HttpSource, read_token_file};
#[cfg(not(target_arch = "wasm32"))]
pub use local::LocalSource;

pub use residency_schemas::SampleType;
pub use residency_schemas::volume::{
    BrickKey, ChannelDisplay, LevelInfo, MinMaxGrid, VolumeError, VolumeInfo,
};

/// Why a volume's description or one of its bricks cannot be had: a store or server that
/// cannot be reached or read, documents that do not agree, or a brick that does not exist or
/// cannot be read. Every message names the store, URL or brick at fault; errors of the format
/// model are theirs, unchanged.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// A brick key the volume does not have, or a description whose documents disagree.
    #[error(transparent)]
    Volume(#[from] VolumeError),
    /// A local store path that does not exist.
    #[error("{store}: no such store")]
    NoSuchStore {
        /// The store, as given.
        store: String,
    },
    /// A store that cannot be opened (a folder zarrs refuses, an object store out of reach).
    #[cfg(not(target_arch = "wasm32"))]
    #[error("{store}: cannot open")]
    CannotOpen {
        /// The store, as given.
        store: String,
        /// Why.
        #[source]
        source: Box<residency_store::location::LocationError>,
    },
    /// A local pyramid that cannot be opened.
    #[cfg(not(target_arch = "wasm32"))]
    #[error(transparent)]
    Pyramid(Box<PyramidError>),
    /// A brick of a local store that cannot be read or decoded.
    #[cfg(not(target_arch = "wasm32"))]
    #[error(
        "{store}: cannot read brick {:?} of channel {} at level {}",
        key.brick, key.channel, key.level
    )]
    ReadBrick {
        /// The store.
        store: String,
        /// The brick.
        key: BrickKey,
        /// What the pyramid reader said.
        #[source]
        source: Box<PyramidError>,
    },
    /// A min/max array of a local store's region metadata that cannot be opened.
    #[cfg(not(target_arch = "wasm32"))]
    #[error("{array}: cannot open the min/max array")]
    OpenMinMax {
        /// The array, `store/path`.
        array: String,
        /// What zarrs said.
        #[source]
        source: Box<zarrs::array::ArrayCreateError>,
    },
    /// A min/max array of the wrong shape.
    #[error("{array}: min/max array has shape {shape:?}, expected {expected:?}")]
    MinMaxShape {
        /// The array, `store/path`.
        array: String,
        /// Its shape.
        shape: Vec<u64>,
        /// The shape the region metadata implies, `c, 2, z, y, x`.
        expected: [u64; 5],
    },
    /// A min/max array whose values cannot be read.
    #[cfg(not(target_arch = "wasm32"))]
    #[error("{array}: cannot read the min/max array")]
    ReadMinMax {
        /// The array, `store/path`.
        array: String,
        /// What zarrs said.
        #[source]
        source: Box<zarrs::array::ArrayError>,
    },
    /// A bearer-token file that cannot be read.
    #[error("{}: cannot read the token", path.display())]
    TokenFile {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A brick server that cannot be reached (the transport's message follows, as the web
    /// page shows only this message).
    #[error("{url}: cannot reach the brick server: {source}")]
    Unreachable {
        /// The URL asked for.
        url: String,
        /// What the HTTP client (or the browser) said.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// A response whose body cannot be read.
    #[error("{url}: cannot read the response")]
    ReadResponse {
        /// The URL asked for.
        url: String,
        /// What the HTTP client said.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// No browser window to fetch from (web viewer).
    #[error("{url}: no browser window")]
    NoWindow {
        /// The URL asked for.
        url: String,
    },
    /// `fetch` answered with something other than a `Response` (web viewer).
    #[error("{url}: fetch did not answer with a response")]
    NotAResponse {
        /// The URL asked for.
        url: String,
    },
    /// A status other than 200 (or an expected 404).
    #[error("{url}: HTTP {status}: {message}")]
    Http {
        /// The URL asked for.
        url: String,
        /// The HTTP status.
        status: u16,
        /// The server's message.
        message: String,
    },
    /// A dataset the server does not have.
    #[error("{base}: no such dataset on the server (neither zarr.json nor .zattrs found)")]
    NoSuchDataset {
        /// The dataset's URL.
        base: String,
    },
    /// The image group's OME metadata is unusable.
    #[error(transparent)]
    Ome(#[from] OmeError),
    /// A level's array metadata is unusable.
    #[error(transparent)]
    ArrayMetadata(#[from] ArrayMetadataError),
    /// A min/max document that cannot be decoded.
    #[error("{url}: corrupt min/max document")]
    CorruptMinMax {
        /// The document's URL.
        url: String,
        /// Why.
        #[source]
        source: WireError,
    },
    /// A min/max document for another channel.
    #[error("{url}: min/max document is for channel {channel}")]
    MinMaxChannel {
        /// The document's URL.
        url: String,
        /// The channel it is for.
        channel: usize,
    },
    /// A min/max document of another sample type than the image.
    #[error("{url}: min/max values are {found} but the image is {}", image.zarr_name())]
    MinMaxType {
        /// The document's URL.
        url: String,
        /// Its sample type.
        found: SampleType,
        /// The image's.
        image: SampleType,
    },
    /// A min/max document of another number of levels than the image.
    #[error("{url}: min/max document has {levels} levels, the image {image_levels}")]
    MinMaxLevelCount {
        /// The document's URL.
        url: String,
        /// Its levels.
        levels: usize,
        /// The image's.
        image_levels: usize,
    },
    /// A min/max level that is not the image's level.
    #[error(
        "{url}: min/max level {level} {shape:?} does not match image level {index} {image_shape:?}"
    )]
    MinMaxLevel {
        /// The document's URL.
        url: String,
        /// The level the block says it is.
        level: usize,
        /// Its shape.
        shape: [u64; 3],
        /// The image level at its position.
        index: usize,
        /// That level's shape.
        image_shape: [u64; 3],
    },
    /// A min/max grid outside the document's payload.
    #[error(
        "{url}: min/max grid of level {level} at bytes {offset}+{length} runs past the \
         {payload}-byte payload"
    )]
    MinMaxGridRange {
        /// The document's URL.
        url: String,
        /// The level.
        level: usize,
        /// The grid's offset.
        offset: u64,
        /// Its length.
        length: u64,
        /// Bytes of the payload.
        payload: usize,
    },
    /// A min/max grid that is not a whole number of samples.
    #[error("{url}: corrupt min/max grid")]
    CorruptMinMaxGrid {
        /// The document's URL.
        url: String,
        /// Why.
        #[source]
        source: PartialSample,
    },
    /// A brick batch that cannot be decoded.
    #[error("{url}: corrupt brick batch")]
    CorruptBatch {
        /// The batch's URL, without its brick list.
        url: String,
        /// Why.
        #[source]
        source: WireError,
    },
    /// A brick batch of another encoding than asked for.
    #[error("{url}: asked for raw bricks, got {encoding:?}")]
    BatchEncoding {
        /// The batch's URL, without its brick list.
        url: String,
        /// The encoding answered.
        encoding: BrickEncoding,
    },
    /// A brick batch of another sample type than the image.
    #[error("{url}: bricks are {found} but the image is {}", image.zarr_name())]
    BatchType {
        /// The batch's URL, without its brick list.
        url: String,
        /// The bricks' sample type.
        found: SampleType,
        /// The image's.
        image: SampleType,
    },
    /// A brick batch of another brick shape than the image.
    #[error("{url}: bricks of {found:?}, expected {expected:?}")]
    BatchBrickShape {
        /// The batch's URL, without its brick list.
        url: String,
        /// The bricks' shape.
        found: [u64; 3],
        /// The image's.
        expected: [u64; 3],
    },
    /// A brick batch answering another number of bricks than asked for.
    #[error("{url}: {answered} bricks answered for {asked} asked")]
    BatchCount {
        /// The batch's URL, without its brick list.
        url: String,
        /// Bricks answered.
        answered: usize,
        /// Bricks asked for.
        asked: usize,
    },
    /// A brick batch answering another brick than asked for at a position.
    #[error("{url}: answered brick {level},{channel},{brick:?} where {key:?} was asked")]
    BatchOrder {
        /// The batch's URL, without its brick list.
        url: String,
        /// Level answered.
        level: u32,
        /// Channel answered.
        channel: u32,
        /// Brick answered, `z, y, x`.
        brick: [u64; 3],
        /// The brick asked for.
        key: BrickKey,
    },
    /// A brick the server could not read.
    #[error("{url}: brick {key:?}: the server could not read it: {reason}")]
    ServerBrick {
        /// The batch's URL, without its brick list.
        url: String,
        /// The brick.
        key: BrickKey,
        /// The server's reason.
        reason: String,
    },
    /// A brick whose bytes are not a whole brick inside the batch's payload.
    #[error(
        "{url}: brick {key:?} at bytes {offset}+{length} is not {expected} bytes inside the \
         {payload}-byte payload"
    )]
    BatchRange {
        /// The batch's URL, without its brick list.
        url: String,
        /// The brick.
        key: BrickKey,
        /// Its offset.
        offset: u64,
        /// Its length.
        length: u64,
        /// Bytes of one brick.
        expected: usize,
        /// Bytes of the payload.
        payload: usize,
    },
    /// A brick of a batch whose request or document failed as a whole; the message is that
    /// failure's, whole chain included.
    #[error("brick {key:?}: {}", crate::error_chain(&**batch))]
    Batch {
        /// The brick.
        key: BrickKey,
        /// Why the batch failed (shared by its bricks).
        batch: Arc<SourceError>,
    },
    /// A brick a source answered no result for.
    #[error("brick source returned too few results")]
    NoResult,
    /// A brick the synthetic source was told to fail (tests).
    #[error("synthetic: brick {key:?}: injected failure (404)")]
    InjectedFailure {
        /// The brick.
        key: BrickKey,
    },
}

/// Decoded voxels of a full brick (`brick_shape`, `z`-major; voxels past the volume's edge
/// hold the fill value).
#[derive(Clone, Debug, PartialEq)]
pub enum BrickVoxels {
    /// The brick equals the fill value (0) everywhere; nothing was transferred.
    Empty,
    /// Unsigned 8-bit samples.
    U8(Vec<u8>),
    /// Unsigned 16-bit samples.
    U16(Vec<u16>),
    /// Signed 16-bit samples.
    I16(Vec<i16>),
    /// Unsigned 32-bit samples.
    U32(Vec<u32>),
    /// Signed 32-bit samples.
    I32(Vec<i32>),
    /// 32-bit float samples.
    F32(Vec<f32>),
}

impl BrickVoxels {
    /// Voxel `index` (`z`-major within the brick) as `f64`; an [`BrickVoxels::Empty`] brick
    /// reads as the fill value 0.
    ///
    /// # Panics
    /// If `index` is outside a non-empty brick.
    pub fn value(&self, index: usize) -> f64 {
        match self {
            Self::Empty => 0.0,
            Self::U8(v) => v[index] as f64,
            Self::U16(v) => v[index] as f64,
            Self::I16(v) => v[index] as f64,
            Self::U32(v) => v[index] as f64,
            Self::I32(v) => v[index] as f64,
            Self::F32(v) => v[index] as f64,
        }
    }

    /// Number of samples held (0 for [`BrickVoxels::Empty`]).
    pub fn len(&self) -> usize {
        match self {
            Self::Empty => 0,
            Self::U8(v) => v.len(),
            Self::U16(v) => v.len(),
            Self::I16(v) => v.len(),
            Self::U32(v) => v.len(),
            Self::I32(v) => v.len(),
            Self::F32(v) => v.len(),
        }
    }

    /// Whether no samples are held (the brick is [`BrickVoxels::Empty`]).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// A brick's samples of type `t` from their little-endian bytes.
    pub fn from_le_bytes(t: SampleType, bytes: &[u8]) -> Self {
        fn le<const N: usize, T>(bytes: &[u8], f: fn([u8; N]) -> T) -> Vec<T> {
            bytes
                .chunks_exact(N)
                .map(|b| f(b.try_into().expect("N bytes")))
                .collect()
        }
        match t {
            SampleType::U8 => Self::U8(bytes.to_vec()),
            SampleType::U16 => Self::U16(le(bytes, u16::from_le_bytes)),
            SampleType::I16 => Self::I16(le(bytes, i16::from_le_bytes)),
            SampleType::U32 => Self::U32(le(bytes, u32::from_le_bytes)),
            SampleType::I32 => Self::I32(le(bytes, i32::from_le_bytes)),
            SampleType::F32 => Self::F32(le(bytes, f32::from_le_bytes)),
        }
    }

    /// The brick as it is kept: [`BrickVoxels::Empty`] when every sample is `fill` (NaN
    /// matching NaN), else the samples.
    pub fn empty_if_all(self, fill: f64) -> Self {
        fn all<T: Copy + Into<f64>>(v: &[T], fill: f64) -> bool {
            v.iter().all(|&x| {
                let x: f64 = x.into();
                x == fill || (x.is_nan() && fill.is_nan())
            })
        }
        let only_fill = match &self {
            Self::Empty => true,
            Self::U8(v) => all(v, fill),
            Self::U16(v) => all(v, fill),
            Self::I16(v) => all(v, fill),
            Self::U32(v) => all(v, fill),
            Self::I32(v) => all(v, fill),
            Self::F32(v) => all(v, fill),
        };
        if only_fill { Self::Empty } else { self }
    }
}

#[cfg(not(target_arch = "wasm32"))]
impl From<PyramidError> for SourceError {
    fn from(e: PyramidError) -> Self {
        Self::Pyramid(Box::new(e))
    }
}

/// A source of volume metadata and bricks. Implementations are thread-safe; `fetch` blocks,
/// so callers run it on worker threads to overlap requests.
pub trait BrickSource: Send + Sync {
    /// The volume's description, loaded once.
    fn info(&self) -> &VolumeInfo;
    /// Fetches the given bricks, one result per key, in order. A brick that cannot be read
    /// gives an error naming it; the others are still returned.
    fn fetch(&self, keys: &[BrickKey]) -> Vec<Result<BrickVoxels, SourceError>>;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn little_endian_samples_become_typed_voxels() {
        let bytes = [0x01, 0x02, 0xff, 0xff];
        assert_eq!(
            BrickVoxels::from_le_bytes(SampleType::U8, &bytes),
            BrickVoxels::U8(vec![1, 2, 255, 255])
        );
        assert_eq!(
            BrickVoxels::from_le_bytes(SampleType::U16, &bytes),
            BrickVoxels::U16(vec![0x0201, 0xffff])
        );
        assert_eq!(
            BrickVoxels::from_le_bytes(SampleType::I16, &bytes),
            BrickVoxels::I16(vec![0x0201, -1])
        );
        assert_eq!(
            BrickVoxels::from_le_bytes(SampleType::I32, &bytes),
            BrickVoxels::I32(vec![-65023])
        );
        assert_eq!(
            BrickVoxels::from_le_bytes(SampleType::F32, &1.5f32.to_le_bytes()),
            BrickVoxels::F32(vec![1.5])
        );
    }

    #[test]
    fn a_brick_of_fill_is_kept_empty() {
        let nan = f64::NAN;
        assert_eq!(
            BrickVoxels::U16(vec![7, 7]).empty_if_all(7.0),
            BrickVoxels::Empty
        );
        assert_eq!(
            BrickVoxels::U16(vec![7, 8]).empty_if_all(7.0),
            BrickVoxels::U16(vec![7, 8])
        );
        assert_eq!(
            BrickVoxels::F32(vec![f32::NAN, f32::NAN]).empty_if_all(nan),
            BrickVoxels::Empty
        );
        let kept = BrickVoxels::F32(vec![f32::NAN, 0.0]).empty_if_all(nan);
        assert!(matches!(&kept, BrickVoxels::F32(v) if v[0].is_nan() && v[1] == 0.0));
        assert_eq!(
            BrickVoxels::F32(vec![-0.0]).empty_if_all(0.0),
            BrickVoxels::Empty
        );
        assert_eq!(
            BrickVoxels::I32(vec![]).empty_if_all(3.0),
            BrickVoxels::Empty
        );
    }
}
