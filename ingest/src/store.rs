//! Writing Zarr stores: array and group metadata for Zarr v2 (OME-Zarr 0.4) and v3
//! (OME-Zarr 0.5), the blosc-lz4 codec, optional sharding, and the atomic
//! write-to-temporary-then-rename that keeps a half-written store from looking complete.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context, Result, bail};
use serde_json::{Value, json};
use zarrs::array::{Array, ArrayMetadata};
use zarrs::filesystem::FilesystemStore;

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
pub type Store = FilesystemStore;

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
        let store = Arc::new(FilesystemStore::new(&partial).with_context(|| {
            format!("{shown}: cannot open {} as a Zarr store", partial.display())
        })?);
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
        let store = Arc::new(
            FilesystemStore::new(path)
                .with_context(|| format!("{}: cannot open as a Zarr store", path.display()))?,
        );
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
