//! Writing a store under a temporary name next to its final path ([`StoreWriter`]), and the
//! atomic rename that keeps a half-written store from looking complete.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use residency_schemas::ome::{ImageAttributes, OmeZarrVersion};
use serde_json::Value;
use zarrs::array::codec::array_to_bytes::sharding::{ShardingCodecOptions, SubchunkWriteOrder};
use zarrs::array::{Array, CodecSpecificOptions};
use zarrs::metadata::v2::GroupMetadataV2;

use super::error::StoreError;
use super::metadata::{ArrayLayout, GroupDocumentV3, array_metadata};
use super::staging::{StagingStore, Store, sync_file_system};

/// A store being written under a temporary name next to its final path.
pub(crate) struct StoreWriter {
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
