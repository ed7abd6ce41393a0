//! Why a store cannot be created, written or committed ([`StoreError`]).

use std::io;
use std::path::PathBuf;

use zarrs::array::ArrayCreateError;
use zarrs::filesystem::FilesystemStoreCreateError;
use zarrs::plugin::PluginCreateError;
use zarrs::storage::StorageError;

/// A store that cannot be created, written or committed, or array metadata zarrs refuses.
/// Messages name the store, file or array at fault; the underlying error, when there is one,
/// is the [`source`](std::error::Error::source).
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// The output exists and `--overwrite` was not given.
    #[error("{}: output already exists (pass --overwrite to replace it)", path.display())]
    OutputExists {
        /// The output.
        path: PathBuf,
    },
    /// The temporary folder an interrupted run left cannot be removed.
    #[error("{}: cannot remove the leftovers of an interrupted run", path.display())]
    RemoveLeftovers {
        /// The temporary folder.
        path: PathBuf,
        /// What the file system said.
        #[source]
        source: io::Error,
    },
    /// The temporary folder cannot be created.
    #[error("{}: cannot create output: cannot create {}", path.display(), partial.display())]
    CreateOutput {
        /// The output.
        path: PathBuf,
        /// The temporary folder.
        partial: PathBuf,
        /// What the file system said.
        #[source]
        source: io::Error,
    },
    /// zarrs cannot open a folder as a store.
    #[error("{}: cannot open as a Zarr store", path.display())]
    OpenStore {
        /// The folder.
        path: PathBuf,
        /// What zarrs said.
        #[source]
        source: FilesystemStoreCreateError,
    },
    /// A folder cannot be created.
    #[error("{}: cannot create", path.display())]
    CreateFolder {
        /// The folder.
        path: PathBuf,
        /// What the file system said.
        #[source]
        source: io::Error,
    },
    /// A metadata document cannot be read.
    #[error("{}: cannot read", path.display())]
    Read {
        /// The document.
        path: PathBuf,
        /// What the file system said.
        #[source]
        source: io::Error,
    },
    /// A metadata document is not JSON.
    #[error("{}: not valid JSON", path.display())]
    NotJson {
        /// The document.
        path: PathBuf,
        /// What the JSON parser said.
        #[source]
        source: serde_json::Error,
    },
    /// A file cannot be written.
    #[error("{}: cannot write", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// What the file system said.
        #[source]
        source: io::Error,
    },
    /// A document cannot be renamed over the one it replaces.
    #[error("{}: cannot replace", path.display())]
    Replace {
        /// The document replaced.
        path: PathBuf,
        /// What the file system said.
        #[source]
        source: io::Error,
    },
    /// The root attributes did not serialise to a JSON object.
    #[error("image attributes are a JSON object")]
    AttributesNotObject,
    /// A value that cannot be serialised as JSON.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// The Blosc compression level is out of range.
    #[error("blosc level {level}: {rejected:?}")]
    BloscLevel {
        /// The level asked for.
        level: u8,
        /// The level zarrs refused.
        rejected: u8,
    },
    /// zarrs cannot make the Blosc codec.
    #[error("the blosc codec")]
    BloscCodec(#[source] PluginCreateError),
    /// zarrs does not know the data type.
    #[error("the data type")]
    DataType(#[source] PluginCreateError),
    /// A chunk (or inner chunk) edge of 0.
    #[error("a chunk edge of 0")]
    ZeroChunkEdge,
    /// Sharding asked of Zarr v2.
    #[error("sharding needs Zarr v3: use --ome-zarr-version 0.5")]
    ShardingNeedsV3,
    /// zarrs refuses the array layout.
    #[error("array metadata")]
    ArrayMetadata(#[source] Box<ArrayCreateError>),
    /// zarrs cannot create an array from its metadata.
    #[error("{}: cannot create array {array}", path.display())]
    CreateArray {
        /// The store.
        path: PathBuf,
        /// The array's path in the store.
        array: String,
        /// What zarrs said.
        #[source]
        source: Box<ArrayCreateError>,
    },
    /// An array's metadata cannot be written.
    #[error("{}: cannot write metadata of {array}", path.display())]
    WriteArrayMetadata {
        /// The store.
        path: PathBuf,
        /// The array's path in the store.
        array: String,
        /// What the storage said.
        #[source]
        source: StorageError,
    },
    /// A folder cannot be opened to sync its file system.
    #[error("{}: cannot open to sync", path.display())]
    OpenToSync {
        /// The folder.
        path: PathBuf,
        /// What the file system said.
        #[source]
        source: io::Error,
    },
    /// `syncfs` failed.
    #[error("{}: cannot sync to disk", path.display())]
    Sync {
        /// The folder.
        path: PathBuf,
        /// What the system said.
        #[source]
        source: io::Error,
    },
    /// The previous output cannot be renamed aside.
    #[error("{}: cannot move the previous output aside", path.display())]
    MoveAside {
        /// The output.
        path: PathBuf,
        /// What the file system said.
        #[source]
        source: io::Error,
    },
    /// The finished store cannot be renamed to its final path.
    #[error("{}: cannot move the new store into place", path.display())]
    MoveIntoPlace {
        /// The output.
        path: PathBuf,
        /// What the file system said.
        #[source]
        source: io::Error,
    },
    /// The previous output, once moved aside, cannot be removed.
    #[error("{}: cannot remove the previous output", path.display())]
    RemovePrevious {
        /// Where it was moved.
        path: PathBuf,
        /// What the file system said.
        #[source]
        source: io::Error,
    },
    /// A file system error, in the system's own words (removing what an earlier commit moved
    /// aside and left behind).
    #[error(transparent)]
    Io(io::Error),
}
