//! Writing Zarr stores: array and group metadata for Zarr v2 (OME-Zarr 0.4) and v3
//! (OME-Zarr 0.5), the blosc-lz4 codec, optional sharding, and the atomic
//! write-to-temporary-then-rename that keeps a half-written store from looking complete.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context, Result, bail};
use serde_json::{Value, json};
use zarrs::array::{Array, ArrayMetadata};
use zarrs::filesystem::FilesystemStore;
use zarrs::storage::byte_range::ByteRangeIterator;
use zarrs::storage::{
    Bytes, MaybeBytesIterator, OffsetBytesIterator, ReadableStorageTraits, StorageError, StoreKey,
    StorePrefix, WritableStorageTraits,
};

use crate::sample_format::SampleFormat;

/// OME-Zarr version to write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OmeZarrVersion {
    /// OME-Zarr 0.4 on Zarr v2.
    V04,
    /// OME-Zarr 0.5 on Zarr v3.
    V05,
}

impl OmeZarrVersion {
    /// The version string (`"0.4"` or `"0.5"`).
    pub fn as_str(self) -> &'static str {
        match self {
            Self::V04 => "0.4",
            Self::V05 => "0.5",
        }
    }
}

/// Blosc compression level used for every array.
pub const BLOSC_CLEVEL: u32 = 5;

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
    pub format: SampleFormat,
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
    pub fn new(root: &Path) -> Result<Self> {
        Ok(Self {
            root: root.to_path_buf(),
            inner: FilesystemStore::new(root)
                .with_context(|| format!("{}: cannot open as a Zarr store", root.display()))?,
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
        let io = |e: std::io::Error| StorageError::from(Arc::new(e));
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
pub fn sync_file_system(path: &Path) -> Result<()> {
    use std::os::fd::AsRawFd;
    let dir = std::fs::File::open(path)
        .with_context(|| format!("{}: cannot open to sync", path.display()))?;
    // SAFETY: `dir` is an open file descriptor for the duration of the call.
    if unsafe { libc::syncfs(dir.as_raw_fd()) } != 0 {
        return Err(std::io::Error::last_os_error())
            .with_context(|| format!("{}: cannot sync to disk", path.display()));
    }
    Ok(())
}

/// Builds the Zarr metadata document for an array.
pub fn array_metadata(version: OmeZarrVersion, layout: &ArrayLayout) -> Result<Value> {
    let typesize = layout.format.bytes();
    Ok(match version {
        OmeZarrVersion::V04 => {
            if layout.inner_chunk.is_some() {
                bail!("sharding needs Zarr v3: use --ome-zarr-version 0.5");
            }
            json!({
                "zarr_format": 2,
                "shape": layout.shape,
                "chunks": layout.chunk,
                "dtype": layout.format.zarr_v2_dtype(),
                "compressor": {"id": "blosc", "cname": "lz4", "clevel": BLOSC_CLEVEL, "shuffle": 1, "blocksize": 0},
                "fill_value": 0,
                "order": "C",
                "filters": null,
                "dimension_separator": "/",
            })
        }
        OmeZarrVersion::V05 => {
            let inner_codecs = json!([
                {"name": "bytes", "configuration": {"endian": "little"}},
                {"name": "blosc", "configuration": {"cname": "lz4", "clevel": BLOSC_CLEVEL, "shuffle": "shuffle", "typesize": typesize, "blocksize": 0}},
            ]);
            let codecs = match &layout.inner_chunk {
                None => inner_codecs,
                Some(inner) => json!([{
                    "name": "sharding_indexed",
                    "configuration": {
                        "chunk_shape": inner,
                        "codecs": inner_codecs,
                        "index_codecs": [
                            {"name": "bytes", "configuration": {"endian": "little"}},
                            {"name": "crc32c"},
                        ],
                        "index_location": "end",
                    }
                }]),
            };
            let mut m = json!({
                "zarr_format": 3,
                "node_type": "array",
                "shape": layout.shape,
                "data_type": layout.format.name(),
                "chunk_grid": {"name": "regular", "configuration": {"chunk_shape": layout.chunk}},
                "chunk_key_encoding": {"name": "default", "configuration": {"separator": "/"}},
                "fill_value": 0,
                "codecs": codecs,
                "attributes": {},
            });
            if let Some(names) = &layout.dimension_names {
                m["dimension_names"] = json!(names);
            }
            m
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
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    output.with_file_name(format!(".{name}.partial"))
}

impl StoreWriter {
    /// Starts writing `output`: refuses an existing output without `overwrite`, and clears
    /// what an interrupted earlier run left behind.
    pub fn create(output: &Path, version: OmeZarrVersion, overwrite: bool) -> Result<Self> {
        let shown = output.display();
        if output.exists() && !overwrite {
            bail!("{shown}: output already exists (pass --overwrite to replace it)");
        }
        let partial = partial_path(output);
        if partial.exists() {
            std::fs::remove_dir_all(&partial).with_context(|| {
                format!(
                    "{}: cannot remove the leftovers of an interrupted run",
                    partial.display()
                )
            })?;
        }
        std::fs::create_dir_all(&partial).with_context(|| {
            format!(
                "{shown}: cannot create output: cannot create {}",
                partial.display()
            )
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
    pub fn in_place(path: &Path, version: OmeZarrVersion) -> Result<Self> {
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
    pub fn set_root_attribute(&self, key: &str, value: Value) -> Result<()> {
        let (file, in_attributes) = match self.version {
            OmeZarrVersion::V05 => (self.partial.join("zarr.json"), true),
            OmeZarrVersion::V04 => (self.partial.join(".zattrs"), false),
        };
        let shown = file.display();
        let mut doc: Value = serde_json::from_slice(
            &std::fs::read(&file).with_context(|| format!("{shown}: cannot read"))?,
        )
        .with_context(|| format!("{shown}: not valid JSON"))?;
        let attrs = if in_attributes {
            &mut doc["attributes"]
        } else {
            &mut doc
        };
        attrs[key] = value;
        let tmp = file.with_extension("json.partial");
        std::fs::write(&tmp, serde_json::to_vec_pretty(&doc)?)
            .with_context(|| format!("{}: cannot write", tmp.display()))?;
        std::fs::rename(&tmp, &file).with_context(|| format!("{shown}: cannot replace"))
    }

    /// Creates an array at `path` (e.g. `/0`) and writes its metadata.
    pub fn create_array(&self, path: &str, layout: &ArrayLayout) -> Result<Array<Store>> {
        let meta: ArrayMetadata = serde_json::from_value(array_metadata(self.version, layout)?)
            .context("array metadata")?;
        let array = Array::new_with_metadata(self.store.clone(), path, meta)
            .with_context(|| format!("{}: cannot create array {path}", self.output.display()))?;
        array.store_metadata().with_context(|| {
            format!("{}: cannot write metadata of {path}", self.output.display())
        })?;
        Ok(array)
    }

    /// Writes group metadata with `attributes` at `path` (relative, `""` for the root).
    /// The root group's metadata is the last write: it is what makes the store a store.
    pub fn write_group(&self, path: &str, attributes: Value) -> Result<()> {
        let dir = self.partial.join(path);
        std::fs::create_dir_all(&dir)?;
        let write = |name: &str, v: &Value| -> Result<()> {
            let file = dir.join(name);
            std::fs::write(&file, serde_json::to_vec_pretty(v)?)
                .with_context(|| format!("{}: cannot write", file.display()))
        };
        match self.version {
            OmeZarrVersion::V04 => {
                write(".zattrs", &attributes)?;
                write(".zgroup", &json!({"zarr_format": 2}))
            }
            OmeZarrVersion::V05 => write(
                "zarr.json",
                &json!({"zarr_format": 3, "node_type": "group", "attributes": attributes}),
            ),
        }
    }

    /// Moves the finished store to its final path, replacing any previous output.
    pub fn commit(self) -> Result<PathBuf> {
        let shown = self.output.display();
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
                std::fs::remove_dir_all(&old)?;
            }
            std::fs::rename(&self.output, &old)
                .with_context(|| format!("{shown}: cannot move the previous output aside"))?;
            std::fs::rename(&self.partial, &self.output)
                .with_context(|| format!("{shown}: cannot move the new store into place"))?;
            std::fs::remove_dir_all(&old)
                .with_context(|| format!("{}: cannot remove the previous output", old.display()))?;
        } else {
            std::fs::rename(&self.partial, &self.output)
                .with_context(|| format!("{shown}: cannot move the new store into place"))?;
        }
        Ok(self.output)
    }
}

/// Total size in bytes of the files under `dir`.
pub fn directory_bytes(dir: &Path) -> u64 {
    fn walk(dir: &Path) -> u64 {
        std::fs::read_dir(dir)
            .map(|entries| {
                entries
                    .filter_map(Result::ok)
                    .map(|e| match e.file_type() {
                        Ok(t) if t.is_dir() => walk(&e.path()),
                        Ok(_) => e.metadata().map(|m| m.len()).unwrap_or(0),
                        Err(_) => 0,
                    })
                    .sum()
            })
            .unwrap_or(0)
    }
    walk(dir)
}
