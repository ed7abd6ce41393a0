//! Writing Zarr stores: array and group metadata for Zarr v2 (OME-Zarr 0.4) and v3
//! (OME-Zarr 0.5), the blosc-lz4 codec, optional sharding, and the atomic
//! write-to-temporary-then-rename that keeps a half-written store from looking complete.

use std::io;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use residency_schemas::SampleType;
use residency_schemas::ome::ImageAttributes;
use serde::Serialize;
use serde_json::Value;
use zarrs::array::codec::array_to_bytes::sharding::{
    ShardingCodecBuilder, ShardingCodecOptions, SubchunkWriteOrder,
};
use zarrs::array::codec::{BloscCodec, BytesCodec, Crc32cCodec};
use zarrs::array::{Array, ArrayBuilder, ArrayCreateError, ArrayMetadata, CodecSpecificOptions};
use zarrs::filesystem::{FilesystemStore, FilesystemStoreCreateError};
use zarrs::metadata::ChunkKeySeparator;
use zarrs::metadata::v2::GroupMetadataV2;
use zarrs::metadata::v2::{ArrayMetadataV2, MetadataV2};
use zarrs::metadata::v3::FillValueMetadataV3;
use zarrs::metadata_ext::codec::blosc::{
    BloscCodecConfigurationNumcodecs, BloscCompressionLevel, BloscCompressor, BloscShuffleMode,
    BloscShuffleModeNumcodecs,
};
use zarrs::plugin::PluginCreateError;
use zarrs::storage::byte_range::ByteRangeIterator;
use zarrs::storage::{
    Bytes, MaybeBytesIterator, OffsetBytesIterator, ReadableStorageTraits, StorageError, StoreKey,
    StorePrefix, WritableStorageTraits,
};

pub use residency_schemas::ome::OmeZarrVersion;

/// Blosc compression level used for every array.
pub const BLOSC_CLEVEL: u8 = 5;

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
    #[error("blosc level {BLOSC_CLEVEL}: {rejected:?}")]
    BloscLevel {
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

/// Layout of one array: shape, chunking, data type.
#[derive(Clone, Debug, PartialEq)]
pub struct ArrayLayout {
    /// Array shape.
    pub shape: Vec<u64>,
    /// Zarr chunk shape (the shard shape when sharded).
    pub chunk: Vec<u64>,
    /// Inner chunk (brick) shape when sharded.
    pub inner_chunk: Option<Vec<u64>>,
    /// Data type.
    pub format: SampleType,
    /// Dimension names (Zarr v3 only).
    pub dimension_names: Option<Vec<&'static str>>,
}

/// The zarrs store type used throughout.
pub type Store = StagingStore;

/// A filesystem store for a store under construction. Whole values are written with a plain
/// write, without the per-file `fsync` of zarrs' [`FilesystemStore`]: the store is private
/// until [`StoreWriter::commit`] syncs the file system once and renames it into place.
/// Everything else is delegated to [`FilesystemStore`].
#[derive(Debug)]
pub struct StagingStore {
    root: PathBuf,
    inner: FilesystemStore,
}

impl StagingStore {
    /// A staging store rooted at `root`.
    ///
    /// # Errors
    /// When zarrs cannot open `root` as a store.
    pub fn new(root: &Path) -> Result<Self, StoreError> {
        Ok(Self {
            root: root.to_path_buf(),
            inner: FilesystemStore::new(root).map_err(|source| StoreError::OpenStore {
                path: root.to_path_buf(),
                source,
            })?,
        })
    }
}

impl ReadableStorageTraits for StagingStore {
    fn get_partial_many<'a>(
        &'a self,
        key: &StoreKey,
        byte_ranges: ByteRangeIterator<'a>,
    ) -> Result<MaybeBytesIterator<'a>, StorageError> {
        self.inner.get_partial_many(key, byte_ranges)
    }

    fn size_key(&self, key: &StoreKey) -> Result<Option<u64>, StorageError> {
        self.inner.size_key(key)
    }

    fn supports_get_partial(&self) -> bool {
        self.inner.supports_get_partial()
    }
}

impl WritableStorageTraits for StagingStore {
    fn set(&self, key: &StoreKey, value: Bytes) -> Result<(), StorageError> {
        let path = self.root.join(key.as_str());
        let io = |e: io::Error| StorageError::from(Arc::new(e));
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(io)?;
        }
        std::fs::write(&path, &value).map_err(io)
    }

    fn set_partial_many(
        &self,
        key: &StoreKey,
        offset_values: OffsetBytesIterator<'_>,
    ) -> Result<(), StorageError> {
        self.inner.set_partial_many(key, offset_values)
    }

    fn erase(&self, key: &StoreKey) -> Result<(), StorageError> {
        self.inner.erase(key)
    }

    fn erase_prefix(&self, prefix: &StorePrefix) -> Result<(), StorageError> {
        self.inner.erase_prefix(prefix)
    }

    fn supports_set_partial(&self) -> bool {
        self.inner.supports_set_partial()
    }
}

/// Flushes every file system holding `path` to disk (`syncfs`).
///
/// # Errors
/// When `path` cannot be opened, or the system refuses to sync.
pub fn sync_file_system(path: &Path) -> Result<(), StoreError> {
    use std::os::fd::AsRawFd;
    let dir = std::fs::File::open(path).map_err(|source| StoreError::OpenToSync {
        path: path.to_path_buf(),
        source,
    })?;
    // SAFETY: `dir` is an open file descriptor for the duration of the call.
    if unsafe { libc::syncfs(dir.as_raw_fd()) } != 0 {
        return Err(StoreError::Sync {
            path: path.to_path_buf(),
            source: io::Error::last_os_error(),
        });
    }
    Ok(())
}

/// [`BLOSC_CLEVEL`] as zarrs' level.
fn blosc_level() -> Result<BloscCompressionLevel, StoreError> {
    BloscCompressionLevel::try_from(BLOSC_CLEVEL)
        .map_err(|rejected| StoreError::BloscLevel { rejected })
}

/// The Blosc codec every array uses: LZ4 with byte shuffle, level [`BLOSC_CLEVEL`], automatic
/// block size.
fn blosc(format: SampleType) -> Result<BloscCodec, StoreError> {
    BloscCodec::new(
        BloscCompressor::LZ4,
        blosc_level()?,
        None,
        BloscShuffleMode::Shuffle,
        Some(format.bytes()),
    )
    .map_err(StoreError::BloscCodec)
}

/// A Zarr v3 group document. zarrs' `GroupMetadataV3` leaves out empty attributes; the stores
/// we have always written keep `"attributes": {}`, and must stay byte-identical.
#[derive(Serialize)]
struct GroupDocumentV3<'a> {
    zarr_format: u8,
    node_type: &'static str,
    attributes: &'a serde_json::Map<String, Value>,
}

/// The Zarr v2 `compressor` of an array: numcodecs' Blosc with the same settings as [`blosc`].
#[derive(Serialize)]
struct NumcodecsBlosc {
    id: &'static str,
    #[serde(flatten)]
    configuration: BloscCodecConfigurationNumcodecs,
}

/// Builds the Zarr metadata of an array, through zarrs' typed builders: v3 with the `bytes`
/// and `blosc` codecs (inside `sharding_indexed`, with a little-endian, CRC32C-checked index at
/// the end, when sharded), or v2 with the Blosc compressor.
///
/// # Errors
/// When sharding is asked of Zarr v2, a chunk edge is 0, or zarrs refuses the layout.
pub fn array_metadata(
    version: OmeZarrVersion,
    layout: &ArrayLayout,
) -> Result<ArrayMetadata, StoreError> {
    let nonzero = |v: &[u64]| -> Result<Vec<std::num::NonZeroU64>, StoreError> {
        v.iter()
            .map(|&e| std::num::NonZeroU64::new(e).ok_or(StoreError::ZeroChunkEdge))
            .collect()
    };
    Ok(match version {
        OmeZarrVersion::V04 => {
            if layout.inner_chunk.is_some() {
                return Err(StoreError::ShardingNeedsV3);
            }
            let compressor: MetadataV2 =
                serde_json::from_value(serde_json::to_value(NumcodecsBlosc {
                    id: "blosc",
                    configuration: BloscCodecConfigurationNumcodecs {
                        cname: BloscCompressor::LZ4,
                        clevel: blosc_level()?,
                        shuffle: BloscShuffleModeNumcodecs::Shuffle,
                        blocksize: 0,
                    },
                })?)?;
            ArrayMetadata::V2(
                ArrayMetadataV2::new(
                    layout.shape.clone(),
                    nonzero(&layout.chunk)?,
                    layout.format.zarr_v2_dtype().into(),
                    FillValueMetadataV3::from(0),
                    Some(compressor),
                    None,
                )
                .with_dimension_separator(ChunkKeySeparator::Slash),
            )
        }
        OmeZarrVersion::V05 => {
            let data_type = zarrs::array::DataType::from_metadata(
                &zarrs::metadata::v3::MetadataV3::new(layout.format.zarr_name()),
            )
            .map_err(StoreError::DataType)?;
            let mut builder = ArrayBuilder::new(
                layout.shape.clone(),
                layout.chunk.as_slice(),
                data_type.clone(),
                FillValueMetadataV3::from(0),
            );
            builder.chunk_key_encoding_default_separator(ChunkKeySeparator::Slash);
            match &layout.inner_chunk {
                None => {
                    builder
                        .array_to_bytes_codec(Arc::new(BytesCodec::little()))
                        .bytes_to_bytes_codecs(vec![Arc::new(blosc(layout.format)?)]);
                }
                Some(inner) => {
                    let mut sharding = ShardingCodecBuilder::new(nonzero(inner)?, &data_type);
                    sharding
                        .array_to_bytes_codec(Arc::new(BytesCodec::little()))
                        .bytes_to_bytes_codecs(vec![Arc::new(blosc(layout.format)?)])
                        .index_array_to_bytes_codec(Arc::new(BytesCodec::little()))
                        .index_bytes_to_bytes_codecs(vec![Arc::new(Crc32cCodec::new())]);
                    builder.array_to_bytes_codec(sharding.build_arc());
                }
            }
            builder.dimension_names(layout.dimension_names.clone());
            let mut metadata = builder
                .build_metadata()
                .map_err(|e| StoreError::ArrayMetadata(Box::new(e)))?;
            // zarrs writes a float fill value as `0.0`; our stores have always said `0` (the
            // same number to every reader), and must stay byte-identical.
            metadata.fill_value = FillValueMetadataV3::from(0);
            ArrayMetadata::V3(metadata)
        }
    })
}

/// A store being written under a temporary name next to its final path.
pub struct StoreWriter {
    /// Final path of the store.
    pub output: PathBuf,
    /// Temporary path being written.
    pub partial: PathBuf,
    /// The zarrs store over `partial`.
    pub store: Arc<Store>,
    /// OME-Zarr version being written.
    pub version: OmeZarrVersion,
}

/// The temporary path used while writing `output`.
pub fn partial_path(output: &Path) -> PathBuf {
    let name = output
        .file_name()
        .map_or_else(|| "output".into(), |n| n.to_string_lossy().into_owned());
    output.with_file_name(format!(".{name}.partial"))
}

/// Refuses an existing `output` unless `overwrite`.
fn refuse_existing(output: &Path, overwrite: bool) -> Result<(), StoreError> {
    if output.exists() && !overwrite {
        return Err(StoreError::OutputExists {
            path: output.to_path_buf(),
        });
    }
    Ok(())
}

impl StoreWriter {
    /// Starts writing `output`: refuses an existing output without `overwrite`, and clears
    /// what an interrupted earlier run left behind.
    ///
    /// # Errors
    /// When `output` exists and `overwrite` is false, or the temporary folder cannot be
    /// cleared, created or opened as a store.
    pub fn create(
        output: &Path,
        version: OmeZarrVersion,
        overwrite: bool,
    ) -> Result<Self, StoreError> {
        refuse_existing(output, overwrite)?;
        let partial = partial_path(output);
        if partial.exists() {
            std::fs::remove_dir_all(&partial).map_err(|source| StoreError::RemoveLeftovers {
                path: partial.clone(),
                source,
            })?;
        }
        Self::open_partial(output, version)
    }

    /// Opens the temporary folder of `output` that the partitions of one conversion write into
    /// together, and `ingest finalize` finishes and moves into place: created when missing,
    /// and never cleared (the other partitions' bricks are there). Refuses an existing output
    /// without `overwrite`.
    ///
    /// # Errors
    /// When `output` exists and `overwrite` is false, or the folder cannot be created or
    /// opened as a store.
    pub fn shared(
        output: &Path,
        version: OmeZarrVersion,
        overwrite: bool,
    ) -> Result<Self, StoreError> {
        refuse_existing(output, overwrite)?;
        Self::open_partial(output, version)
    }

    /// The temporary folder of `output`, created when missing.
    fn open_partial(output: &Path, version: OmeZarrVersion) -> Result<Self, StoreError> {
        let partial = partial_path(output);
        std::fs::create_dir_all(&partial).map_err(|source| StoreError::CreateOutput {
            path: output.to_path_buf(),
            partial: partial.clone(),
            source,
        })?;
        let store = Arc::new(StagingStore::new(&partial)?);
        Ok(Self {
            output: output.to_path_buf(),
            partial,
            store,
            version,
        })
    }

    /// Writes into an existing store in place (used by `ingest index`, which only adds new
    /// arrays and then replaces the root attributes atomically); never committed.
    ///
    /// # Errors
    /// When zarrs cannot open `path` as a store.
    pub fn in_place(path: &Path, version: OmeZarrVersion) -> Result<Self, StoreError> {
        let store = Arc::new(StagingStore::new(path)?);
        Ok(Self {
            output: path.to_path_buf(),
            partial: path.to_path_buf(),
            store,
            version,
        })
    }

    /// Sets one key of the root group's attributes, keeping everything else, by writing a
    /// temporary file and renaming it over the original.
    ///
    /// # Errors
    /// When the attributes document cannot be read, parsed, written or replaced.
    pub fn set_root_attribute(&self, key: &str, value: Value) -> Result<(), StoreError> {
        let (file, in_attributes) = match self.version {
            OmeZarrVersion::V05 => (self.partial.join("zarr.json"), true),
            OmeZarrVersion::V04 => (self.partial.join(".zattrs"), false),
        };
        let bytes = std::fs::read(&file).map_err(|source| StoreError::Read {
            path: file.clone(),
            source,
        })?;
        let mut doc: Value =
            serde_json::from_slice(&bytes).map_err(|source| StoreError::NotJson {
                path: file.clone(),
                source,
            })?;
        let attrs = if in_attributes {
            &mut doc["attributes"]
        } else {
            &mut doc
        };
        attrs[key] = value;
        let tmp = file.with_extension("json.partial");
        std::fs::write(&tmp, serde_json::to_vec_pretty(&doc)?).map_err(|source| {
            StoreError::Write {
                path: tmp.clone(),
                source,
            }
        })?;
        std::fs::rename(&tmp, &file).map_err(|source| StoreError::Replace { path: file, source })
    }

    /// Creates an array at `path` (e.g. `/0`) and writes its metadata.
    ///
    /// # Errors
    /// When zarrs refuses the layout (see [`array_metadata`]) or the metadata cannot be
    /// written.
    pub fn create_array(
        &self,
        path: &str,
        layout: &ArrayLayout,
    ) -> Result<Array<Store>, StoreError> {
        let meta = array_metadata(self.version, layout)?;
        // Inner chunks go into a shard in C order, so a store is byte-identical from run to
        // run whatever the thread count (zarrs' default writes them as they finish encoding).
        let array = Array::new_with_metadata(self.store.clone(), path, meta)
            .map_err(|source| StoreError::CreateArray {
                path: self.output.clone(),
                array: path.to_string(),
                source: Box::new(source),
            })?
            .with_codec_specific_options(&CodecSpecificOptions::default().with_option(
                ShardingCodecOptions::default().with_subchunk_write_order(SubchunkWriteOrder::C),
            ));
        array
            .store_metadata()
            .map_err(|source| StoreError::WriteArrayMetadata {
                path: self.output.clone(),
                array: path.to_string(),
                source,
            })?;
        Ok(array)
    }

    /// Writes the metadata of a group at `path` (relative, `""` for the root) whose
    /// attributes are `attributes`: zarrs' typed group metadata, pretty-printed.
    fn write_group_metadata(
        &self,
        path: &str,
        attributes: serde_json::Map<String, Value>,
    ) -> Result<(), StoreError> {
        let dir = self.partial.join(path);
        std::fs::create_dir_all(&dir).map_err(|source| StoreError::CreateFolder {
            path: dir.clone(),
            source,
        })?;
        let write = |name: &str, bytes: Vec<u8>| -> Result<(), StoreError> {
            let file = dir.join(name);
            std::fs::write(&file, bytes).map_err(|source| StoreError::Write { path: file, source })
        };
        match self.version {
            OmeZarrVersion::V04 => {
                write(".zattrs", serde_json::to_vec_pretty(&attributes)?)?;
                write(
                    ".zgroup",
                    serde_json::to_vec_pretty(&GroupMetadataV2::new())?,
                )
            }
            OmeZarrVersion::V05 => write(
                "zarr.json",
                serde_json::to_vec_pretty(&GroupDocumentV3 {
                    zarr_format: 3,
                    node_type: "group",
                    attributes: &attributes,
                })?,
            ),
        }
    }

    /// Writes a group without attributes at `path` (relative to the store).
    ///
    /// # Errors
    /// When its folder or metadata document cannot be written.
    pub fn write_group(&self, path: &str) -> Result<(), StoreError> {
        self.write_group_metadata(path, serde_json::Map::new())
    }

    /// Writes the root image group with its attributes. It is the last write of a store: what
    /// makes the store a store.
    ///
    /// # Errors
    /// When the attributes cannot be serialised or the metadata document cannot be written.
    pub fn write_image_group(&self, attributes: &ImageAttributes) -> Result<(), StoreError> {
        let Value::Object(map) = serde_json::to_value(attributes)? else {
            return Err(StoreError::AttributesNotObject);
        };
        self.write_group_metadata("", map)
    }

    /// Moves the finished store to its final path, replacing any previous output.
    ///
    /// # Errors
    /// When the store cannot be synced to disk, or the previous output cannot be moved aside
    /// and removed, or the new store cannot be renamed into place.
    pub fn commit(self) -> Result<PathBuf, StoreError> {
        sync_file_system(&self.partial)?;
        if self.output.exists() {
            let old = self.output.with_file_name(format!(
                ".{}.old",
                self.output
                    .file_name()
                    .unwrap_or_default()
                    .to_string_lossy()
            ));
            if old.exists() {
                std::fs::remove_dir_all(&old).map_err(StoreError::Io)?;
            }
            std::fs::rename(&self.output, &old).map_err(|source| StoreError::MoveAside {
                path: self.output.clone(),
                source,
            })?;
            std::fs::rename(&self.partial, &self.output).map_err(|source| {
                StoreError::MoveIntoPlace {
                    path: self.output.clone(),
                    source,
                }
            })?;
            std::fs::remove_dir_all(&old)
                .map_err(|source| StoreError::RemovePrevious { path: old, source })?;
        } else {
            std::fs::rename(&self.partial, &self.output).map_err(|source| {
                StoreError::MoveIntoPlace {
                    path: self.output.clone(),
                    source,
                }
            })?;
        }
        Ok(self.output)
    }
}

/// Total size in bytes of the files under `dir`.
pub fn directory_bytes(dir: &Path) -> u64 {
    fn walk(dir: &Path) -> u64 {
        std::fs::read_dir(dir).map_or(0, |entries| {
            entries
                .filter_map(Result::ok)
                .map(|e| match e.file_type() {
                    Ok(t) if t.is_dir() => walk(&e.path()),
                    Ok(_) => e.metadata().map_or(0, |m| m.len()),
                    Err(_) => 0,
                })
                .sum()
        })
    }
    walk(dir)
}
