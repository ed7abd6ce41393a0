//! The pyramid reader: an OME-Zarr image's levels opened once from any zarrs store (Zarr v2 or
//! v3, sharded or not), and its bricks read by (level, channel, brick) whatever the axis layout.
//! `brickserver`'s batch endpoint, the viewer's local source and `ingest index` all read
//! through it.

use std::sync::Arc;

use zarrs::array::{
    AdditionalFieldUnsupportedError, Array, ArrayBytes, ArrayCreateError, ArrayShardedReadableExt,
    ArrayShardedReadableExtCache, AsyncArrayShardedReadableExt, AsyncArrayShardedReadableExtCache,
    CodecOptions, ElementOwned,
};
use zarrs::metadata::ArrayMetadata;
use zarrs::metadata::v3::ArrayMetadataV3;
use zarrs::storage::byte_range::ByteRange;
use zarrs::storage::{AsyncReadableStorageTraits, ReadableStorageTraits, StoreKey};

use crate::at_once;
use residency_schemas::SampleType;
use residency_schemas::ome::{ImageAttributes, OmeError, PyramidLayout, ZarrFormat};
use residency_schemas::zarr::{ArrayDescription, ArrayMetadataError};

/// A level's array: for Zarr v3 made from its `zarr.json`, which the caller has read already
/// (over an object store, one request less per level), with the check `Array::open` makes (no
/// additional field that must be understood); for v2 opened by zarrs, which reads the array's
/// `.zarray` and `.zattrs`.
fn level_array<S: ReadableStorageTraits + ?Sized + 'static>(
    store: Arc<S>,
    format: ZarrFormat,
    path: &str,
    document: &[u8],
) -> Result<Array<S>, Box<dyn std::error::Error + Send + Sync>> {
    let node = format!("/{path}");
    let array = match format {
        ZarrFormat::V3 => {
            let metadata: ArrayMetadataV3 = serde_json::from_slice(document)?;
            let unsupported = metadata
                .additional_fields
                .iter()
                .find(|(_, field)| field.must_understand());
            if let Some((name, field)) = unsupported {
                let e =
                    AdditionalFieldUnsupportedError::new(name.clone(), field.as_value().clone());
                return Err(
                    CannotOpenArray(ArrayCreateError::AdditionalFieldUnsupportedError(e)).into(),
                );
            }
            Array::new_with_metadata(store, &node, ArrayMetadata::V3(metadata))
        }
        ZarrFormat::V2 => Array::open(store, &node),
    };
    array.map_err(|e| CannotOpenArray(e).into())
}

/// A problem opening a pyramid or reading one of its bricks. Every message names the store
/// (and the level or brick) it is about.
#[derive(Debug, thiserror::Error)]
pub enum PyramidError {
    /// Neither `zarr.json` nor `.zattrs` at the store's root.
    #[error("{store}: not an OME-Zarr image (no zarr.json or .zattrs)")]
    NotAnImage {
        /// The store.
        store: String,
    },
    /// The image group's OME metadata is unusable.
    #[error(transparent)]
    Ome(#[from] OmeError),
    /// A level's array metadata is unusable.
    #[error(transparent)]
    ArrayMetadata(#[from] ArrayMetadataError),
    /// A level's metadata document is missing.
    #[error("{document}: missing (the multiscales list a level that is not in the store)")]
    MissingLevel {
        /// The document looked for.
        document: String,
    },
    /// The levels disagree on sample type, brick shape or axes, or hold several channels in
    /// one brick.
    #[error("{store}: {problem}")]
    Inconsistent {
        /// The store.
        store: String,
        /// What disagrees.
        problem: String,
    },
    /// The storage could not be read, or zarrs could not open an array.
    #[error("{what}: {source}")]
    Storage {
        /// The key, array or brick being read.
        what: String,
        /// What the storage or zarrs said.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

/// zarrs cannot open a level's array (the cause of a [`PyramidError::Storage`]).
#[derive(Debug, thiserror::Error)]
#[error("cannot open the array: {0}")]
pub struct CannotOpenArray(#[source] pub ArrayCreateError);

/// A requested brick the pyramid does not have.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum NoSuchBrick {
    /// No such pyramid level.
    #[error("level {level} does not exist (the dataset has {levels})")]
    Level {
        /// The level asked for.
        level: u32,
        /// Levels of the dataset.
        levels: usize,
    },
    /// No such channel.
    #[error("channel {channel} does not exist (the dataset has {channels})")]
    Channel {
        /// The channel asked for.
        channel: u32,
        /// Channels of the dataset.
        channels: u64,
    },
    /// The brick lies outside the level's brick grid.
    #[error("brick {brick:?} lies outside level {level} ({grid:?} bricks, z, y, x)")]
    Brick {
        /// The brick asked for, `z, y, x`.
        brick: [u64; 3],
        /// The level.
        level: u32,
        /// The level's brick grid, `z, y, x`.
        grid: [u64; 3],
    },
}

/// One brick of one channel at one level.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct BrickIndex {
    /// Pyramid level, 0 the finest.
    pub level: u32,
    /// Channel.
    pub channel: u32,
    /// Brick coordinates `z, y, x`, in bricks.
    pub brick: [u64; 3],
}

/// One opened level.
pub struct PyramidLevel<S: ?Sized> {
    /// Path of the level's array (`multiscales[0].datasets[].path`).
    pub path: String,
    /// The array, opened by zarrs.
    pub array: Array<S>,
    /// What its metadata says.
    pub description: ArrayDescription,
    /// Bricks along `z, y, x`.
    pub grid: [u64; 3],
    /// zarrs' cache of shard indices for inner-chunk reads.
    shards: ArrayShardedReadableExtCache,
}

/// A pyramid's level arrays over async storage (an object store read by futures), for
/// [`Pyramid::read_brick_bytes_async`] and [`Pyramid::read_brick_encoded_async`]: the same
/// bricks as the synchronous reads, with no thread held while a request is on the network.
/// Made by [`Pyramid::async_bricks`].
pub struct AsyncBricks {
    /// Levels, finest first.
    levels: Vec<AsyncLevel>,
}

/// One level of [`AsyncBricks`]: the array over the async storage, and zarrs' cache of its
/// shard indices.
struct AsyncLevel {
    array: Array<dyn AsyncReadableStorageTraits>,
    shards: AsyncArrayShardedReadableExtCache,
}

/// Whether the byte range zarrs gives for an inner chunk is the sharding codec's mark of one
/// that is not stored (offset and length both `u64::MAX`). zarrs 0.23's
/// `retrieve_encoded_subchunk` does not check for the mark: it asks the store for the bytes
/// from offset `u64::MAX` (a capacity-overflow panic from a folder, a refused range from an
/// object store). The range it reports for the mark starts at `u64::MAX` (its end wraps; a
/// build with overflow checks panics inside zarrs instead).
fn not_stored(range: Option<&ByteRange>) -> bool {
    matches!(range, None | Some(ByteRange::FromStart(u64::MAX, _)))
}

/// Shard indices a level's cache holds before it is emptied (a shard index of a 64³-brick
/// shard of 8³ bricks is 8 KiB).
const SHARD_INDICES_KEPT: usize = 4096;

/// Bricks of one batch read at once from an object store (brickserver's batches, the viewer's
/// fetches): such reads wait on the network, not the CPU, so they are futures, this many in
/// flight, rather than one per core.
pub const REMOTE_READS: usize = 32;

/// An OME-Zarr image's pyramid, opened for brick reads.
pub struct Pyramid<S: ?Sized> {
    /// The store, for reading other arrays of the image (such as the region metadata's).
    pub store: Arc<S>,
    /// The store's name in messages (a path or URL).
    pub name: String,
    /// Zarr format of the store.
    pub format: ZarrFormat,
    /// The image group's attributes.
    pub attributes: ImageAttributes,
    /// Axes and levels of the first multiscale.
    pub layout: PyramidLayout,
    /// Levels, finest first.
    pub levels: Vec<PyramidLevel<S>>,
    /// Sample type shared by every level.
    pub sample_type: SampleType,
    /// Brick shape `z, y, x` shared by every level.
    pub brick_shape: [u64; 3],
    /// Channels (1 without a `c` axis).
    pub channels: u64,
}

impl<S: ?Sized> std::fmt::Debug for Pyramid<S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Pyramid")
            .field("name", &self.name)
            .field("format", &self.format)
            .field("sample_type", &self.sample_type)
            .field("brick_shape", &self.brick_shape)
            .field("channels", &self.channels)
            .finish_non_exhaustive()
    }
}

/// Reads the document at `key`, or `None` when the store has no such key.
///
/// # Errors
/// [`PyramidError::Storage`] when the storage fails.
pub fn read_key<S: ReadableStorageTraits + ?Sized>(
    store: &S,
    key: &str,
    shown: &str,
) -> Result<Option<Vec<u8>>, PyramidError> {
    let storage = |source: Box<dyn std::error::Error + Send + Sync>| PyramidError::Storage {
        what: shown.to_string(),
        source,
    };
    let key = StoreKey::new(key).map_err(|e| storage(e.into()))?;
    store
        .get(&key)
        .map(|b| b.map(|b| b.to_vec()))
        .map_err(|e| storage(e.into()))
}

impl<S: ?Sized> Pyramid<S> {
    /// The array chunk (or inner chunk) indices of a brick.
    fn indices(&self, at: &BrickIndex) -> Vec<u64> {
        self.layout.chunk_indices(u64::from(at.channel), at.brick)
    }

    /// The key or inner chunk a brick lives in, for messages.
    fn located(&self, at: &BrickIndex) -> String {
        let level = &self.levels[at.level as usize];
        let key = if level.shards.array_is_sharded() {
            format!("an inner chunk of array '{}'", level.path)
        } else {
            format!("key '{}'", level.array.chunk_key(&self.indices(at)))
        };
        format!(
            "level {} channel {} brick {:?} ({key})",
            at.level, at.channel, at.brick
        )
    }

    fn brick_error(
        &self,
        at: &BrickIndex,
        e: impl std::error::Error + Send + Sync + 'static,
    ) -> PyramidError {
        PyramidError::Storage {
            what: self.located(at),
            source: e.into(),
        }
    }

    /// The level arrays over `store`, the same keys as this pyramid's store read through
    /// async storage (for an object store: futures on the caller's runtime).
    pub fn async_bricks(&self, store: Arc<dyn AsyncReadableStorageTraits>) -> AsyncBricks {
        AsyncBricks {
            levels: self
                .levels
                .iter()
                .map(|level| {
                    let array = level.array.with_storage(store.clone());
                    let shards = AsyncArrayShardedReadableExtCache::new(&array);
                    AsyncLevel { array, shards }
                })
                .collect(),
        }
    }

    /// Level `at.level` of `bricks`, its shard-index cache kept bounded.
    async fn async_level<'a>(bricks: &'a AsyncBricks, at: &BrickIndex) -> &'a AsyncLevel {
        let level = &bricks.levels[at.level as usize];
        if level.shards.len().await > SHARD_INDICES_KEPT {
            level.shards.clear().await;
        }
        level
    }

    /// A decoded brick's samples as little-endian bytes.
    fn fixed_bytes(
        &self,
        at: &BrickIndex,
        bytes: ArrayBytes<'static>,
    ) -> Result<Vec<u8>, PyramidError> {
        Ok(bytes
            .into_fixed()
            .map_err(|e| self.brick_error(at, e))?
            .into_owned())
    }

    /// [`Pyramid::read_brick`] through `bricks` (made by [`Pyramid::async_bricks`]).
    ///
    /// # Errors
    /// [`PyramidError::Storage`] naming the brick when it cannot be read or decoded as `T`.
    pub async fn read_brick_async<T: ElementOwned + Send + Sync>(
        &self,
        bricks: &AsyncBricks,
        at: &BrickIndex,
    ) -> Result<Vec<T>, PyramidError> {
        let AsyncLevel { array, shards } = Self::async_level(bricks, at).await;
        array
            .async_retrieve_subchunk_opt(shards, &self.indices(at), &CodecOptions::default())
            .await
            .map_err(|e| self.brick_error(at, e))
    }

    /// [`Pyramid::read_brick_bytes`] through `bricks` (made by [`Pyramid::async_bricks`]).
    ///
    /// # Errors
    /// [`PyramidError::Storage`] naming the brick when it cannot be read or decoded.
    pub async fn read_brick_bytes_async(
        &self,
        bricks: &AsyncBricks,
        at: &BrickIndex,
    ) -> Result<Vec<u8>, PyramidError> {
        let AsyncLevel { array, shards } = Self::async_level(bricks, at).await;
        let bytes = array
            .async_retrieve_subchunk_opt(shards, &self.indices(at), &CodecOptions::default())
            .await
            .map_err(|e| self.brick_error(at, e))?;
        self.fixed_bytes(at, bytes)
    }

    /// [`Pyramid::read_brick_encoded`] through `bricks` (made by [`Pyramid::async_bricks`]).
    ///
    /// # Errors
    /// [`PyramidError::Storage`] naming the brick when the store cannot be read.
    pub async fn read_brick_encoded_async(
        &self,
        bricks: &AsyncBricks,
        at: &BrickIndex,
    ) -> Result<Option<Vec<u8>>, PyramidError> {
        let AsyncLevel { array, shards } = Self::async_level(bricks, at).await;
        let indices = self.indices(at);
        if shards.array_is_sharded() {
            let range = array
                .async_subchunk_byte_range(shards, &indices)
                .await
                .map_err(|e| self.brick_error(at, e))?;
            if not_stored(range.as_ref()) {
                return Ok(None);
            }
            array
                .async_retrieve_encoded_subchunk(shards, &indices)
                .await
                .map_err(|e| self.brick_error(at, e))
        } else {
            array
                .async_retrieve_encoded_chunk(&indices)
                .await
                .map(|bytes| bytes.map(|b| b.to_vec()))
                .map_err(|e| self.brick_error(at, e))
        }
    }
}

impl<S: ReadableStorageTraits + ?Sized + 'static> Pyramid<S> {
    /// Opens the image at the root of `store`, named `name` in messages: its attributes, the
    /// first multiscale's levels and each level's array. Checks that every level has the same
    /// sample type, brick shape and dimensionality, and one channel per brick.
    ///
    /// # Errors
    /// [`PyramidError`] naming the store and the document or level at fault.
    pub fn open(store: Arc<S>, name: &str) -> Result<Self, PyramidError> {
        let shown = |key: &str| format!("{name}/{key}");
        let (format, group_document) =
            if let Some(doc) = read_key(&*store, "zarr.json", &shown("zarr.json"))? {
                (ZarrFormat::V3, doc)
            } else if let Some(doc) = read_key(&*store, ".zattrs", &shown(".zattrs"))? {
                (ZarrFormat::V2, doc)
            } else {
                return Err(PyramidError::NotAnImage {
                    store: name.to_string(),
                });
            };
        let group_source = shown(format.group_key());
        let attributes = ImageAttributes::parse(format, &group_document, &group_source)?;
        let layout = PyramidLayout::of(attributes.image(), &group_source)?;
        let inconsistent = |problem: String| PyramidError::Inconsistent {
            store: name.to_string(),
            problem,
        };
        let n = layout.axis_names.len();
        let mut levels: Vec<PyramidLevel<S>> = Vec::new();
        let level_key = |path: &str| format!("{path}/{}", format.array_key());
        // The levels' documents side by side (over an object store each waits on the network),
        // checked in order (up to the first that could not be read).
        let documents = at_once::try_read_all(&layout.level_paths, |path| {
            let key = level_key(path);
            read_key(&*store, &key, &shown(&key))
        });
        for (path, document) in layout.level_paths.iter().zip(documents) {
            let key = level_key(path);
            let document = document?.ok_or_else(|| PyramidError::MissingLevel {
                document: shown(&key),
            })?;
            let description = ArrayDescription::parse(format, &document, &shown(&key))?;
            if description.shape.len() != n {
                return Err(inconsistent(format!(
                    "level '{path}' has {} dimensions for {n} axes",
                    description.shape.len()
                )));
            }
            if let Some(first) = levels.first() {
                if description.sample_type != first.description.sample_type {
                    return Err(inconsistent(format!(
                        "level '{path}' is {} but level '{}' is {}",
                        description.sample_type, first.path, first.description.sample_type
                    )));
                }
                if description.brick_shape() != first.description.brick_shape() {
                    return Err(inconsistent(format!(
                        "level '{path}' has bricks {:?} but level '{}' has {:?}",
                        description.brick_shape(),
                        first.path,
                        first.description.brick_shape()
                    )));
                }
            }
            if let Some(c) = layout.channel_axis
                && description.chunk[c] != 1
            {
                return Err(inconsistent(format!(
                    "level '{path}' has chunks of {} along axis 'c'; one brick must hold one \
                     channel",
                    description.chunk[c]
                )));
            }
            let array = level_array(store.clone(), format, path, &document).map_err(|e| {
                PyramidError::Storage {
                    what: shown(&key),
                    source: e,
                }
            })?;
            let brick = description.brick_shape();
            let zyx = description.zyx_shape();
            levels.push(PyramidLevel {
                path: path.clone(),
                shards: ArrayShardedReadableExtCache::new(&array),
                array,
                grid: std::array::from_fn(|a| zyx[a].div_ceil(brick[a])),
                description,
            });
        }
        let first = &levels[0].description;
        let channels = layout.channel_axis.map_or(1, |c| first.shape[c]);
        Ok(Self {
            store,
            name: name.to_string(),
            format,
            sample_type: first.sample_type,
            brick_shape: first.brick_shape(),
            channels,
            attributes,
            layout,
            levels,
        })
    }

    /// Checks that `at` names a brick of the pyramid.
    ///
    /// # Errors
    /// [`NoSuchBrick`] saying which of level, channel or brick is outside.
    pub fn check(&self, at: &BrickIndex) -> Result<(), NoSuchBrick> {
        let level = self
            .levels
            .get(at.level as usize)
            .ok_or(NoSuchBrick::Level {
                level: at.level,
                levels: self.levels.len(),
            })?;
        if u64::from(at.channel) >= self.channels {
            return Err(NoSuchBrick::Channel {
                channel: at.channel,
                channels: self.channels,
            });
        }
        if (0..3).any(|a| at.brick[a] >= level.grid[a]) {
            return Err(NoSuchBrick::Brick {
                brick: at.brick,
                level: at.level,
                grid: level.grid,
            });
        }
        Ok(())
    }

    /// Decoded bytes of one full brick.
    #[must_use]
    pub fn brick_bytes(&self) -> u64 {
        self.sample_type.block_bytes(self.brick_shape)
    }

    /// Keeps zarrs' shard-index cache of a level bounded.
    fn trim_shard_cache(level: &PyramidLevel<S>) {
        if level.shards.len() > SHARD_INDICES_KEPT {
            level.shards.clear();
        }
    }

    /// The decoded samples of a whole brick (its full shape, `z`-major; voxels past the
    /// volume's edge hold the fill value). The brick must pass [`Pyramid::check`].
    ///
    /// # Errors
    /// [`PyramidError::Storage`] naming the brick when it cannot be read or decoded as `T`.
    pub fn read_brick<T: ElementOwned>(&self, at: &BrickIndex) -> Result<Vec<T>, PyramidError> {
        let level = &self.levels[at.level as usize];
        Self::trim_shard_cache(level);
        level
            .array
            .retrieve_subchunk_opt(&level.shards, &self.indices(at), &CodecOptions::default())
            .map_err(|e| self.brick_error(at, e))
    }

    /// The decoded samples of a whole brick as little-endian bytes.
    ///
    /// # Errors
    /// [`PyramidError::Storage`] naming the brick when it cannot be read or decoded.
    pub fn read_brick_bytes(&self, at: &BrickIndex) -> Result<Vec<u8>, PyramidError> {
        let level = &self.levels[at.level as usize];
        Self::trim_shard_cache(level);
        let bytes = level
            .array
            .retrieve_subchunk_opt(&level.shards, &self.indices(at), &CodecOptions::default())
            .map_err(|e| self.brick_error(at, e))?;
        self.fixed_bytes(at, bytes)
    }

    /// A brick's bytes exactly as stored (the chunk file, or the inner chunk's bytes inside its
    /// shard), or `None` when the brick is not stored.
    ///
    /// # Errors
    /// [`PyramidError::Storage`] naming the brick when the store cannot be read.
    pub fn read_brick_encoded(&self, at: &BrickIndex) -> Result<Option<Vec<u8>>, PyramidError> {
        let level = &self.levels[at.level as usize];
        Self::trim_shard_cache(level);
        let indices = self.indices(at);
        if level.shards.array_is_sharded() {
            let range = level
                .array
                .subchunk_byte_range(&level.shards, &indices)
                .map_err(|e| self.brick_error(at, e))?;
            if not_stored(range.as_ref()) {
                return Ok(None);
            }
            level
                .array
                .retrieve_encoded_subchunk(&level.shards, &indices)
                .map_err(|e| self.brick_error(at, e))
        } else {
            level
                .array
                .retrieve_encoded_chunk(&indices)
                .map_err(|e| self.brick_error(at, e))
        }
    }
}
