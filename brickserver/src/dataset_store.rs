//! Where a served dataset's keys are read from: a local folder held open, or a key prefix in an
//! S3-compatible object store. Both give the same answers: the stored bytes, ranges of them,
//! and an `ETag` (the file's length and modification time, or the object store's own tag, so
//! that replicas reading one bucket answer alike).

use std::ops::Range;
use std::sync::Arc;

use axum::body::Bytes;
use residency_store::location::object_store::path::Path as ObjectPath;
use residency_store::location::object_store::{
    self, GetOptions, GetRange, ObjectStore, ObjectStoreExt,
};
use residency_store::location::{
    AsyncReadable, BlockOn, LocationError, ObjectStoreAt, ObjectStoreOptions, StoreLocation,
    object_storage,
};
use zarrs::storage::{ReadableListableStorageTraits, StoreKey};

use crate::store_keys::{KeyError, RootDir, StoreFailure, checked_key, resolve};

/// Why a dataset's store cannot be opened.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// A dataset folder cannot be opened.
    #[error("{location}: cannot open dataset folder: {source}")]
    Folder {
        /// The dataset's root folder.
        location: String,
        /// Why it cannot be opened.
        #[source]
        source: std::io::Error,
    },
    /// The folder cannot be opened as zarrs storage.
    #[error(transparent)]
    Storage(#[from] LocationError),
    /// An object-store dataset opened outside a tokio runtime, which its reads need.
    #[error("{location}: an object-store dataset is opened on the server's tokio runtime")]
    NoRuntime {
        /// The dataset's location.
        location: String,
    },
    /// An object-store dataset opened without its client.
    #[error("{location}: an object-store dataset is opened with its client")]
    NoClient {
        /// The dataset's location.
        location: String,
    },
}

/// A dataset's keys in an object store: its client and the key prefix of the store's root.
pub(crate) struct ObjectKeys {
    store: Arc<dyn ObjectStore>,
    prefix: ObjectPath,
    /// The same keys read by futures, for batched bricks, and the runtime they run on (the one
    /// [`DatasetStore::open`] ran on: in the binary, the multi-threaded runtime that makes the
    /// object-store requests).
    reads: AsyncReadable,
}

/// Where a dataset's keys are read from.
pub(crate) enum Keys {
    /// A local folder, opened once; keys are opened beneath it.
    Folder(RootDir),
    /// A prefix in an object store.
    Object(ObjectKeys),
}

/// A served dataset's store: its keys for verbatim answers, and the same store as zarrs storage
/// for the region index, batched bricks and the listing. An object store is reached through one
/// client, which all use: batched bricks are read by futures on the runtime the store was
/// opened on; what a dataset's loads read (the pyramid's metadata, the region
/// index's arrays: on first use, and again after a failed load) and the small documents, by
/// zarrs' synchronous API from blocking tasks, their requests run on that runtime.
pub struct DatasetStore {
    /// The keys.
    pub(crate) keys: Keys,
    zarr: Arc<dyn ReadableListableStorageTraits>,
    shown: String,
}

/// Part of an object, read with its `ETag`.
#[derive(Clone, Debug)]
pub(crate) struct ObjectPart {
    /// The bytes read.
    pub bytes: Bytes,
    /// Where they lie in the object.
    pub range: Range<u64>,
    /// The object's length.
    pub size: u64,
    /// The object's entity tag, quoted as HTTP writes it.
    pub etag: String,
}

impl DatasetStore {
    /// Opens the store at `location`: a folder's canonical path, or an `s3://` location read
    /// through `object_store`, its client (from [`StoreLocation::object_store`], the one client
    /// the dataset has). An object store is opened on a tokio runtime (the server's), which
    /// runs its requests.
    ///
    /// # Errors
    /// [`OpenError`] when the folder cannot be opened, or an object store is opened without
    /// its client or outside a runtime.
    pub fn open(
        location: &StoreLocation,
        object_store: Option<&ObjectStoreAt>,
    ) -> Result<Self, OpenError> {
        let shown = location.to_string();
        let (keys, zarr) = if let Some(path) = location.folder() {
            let root = RootDir::open(path).map_err(|source| OpenError::Folder {
                location: shown.clone(),
                source,
            })?;
            let zarr = location.open_readable(&ObjectStoreOptions::default())?;
            (Keys::Folder(root), zarr)
        } else {
            let (store, prefix) = object_store.cloned().ok_or_else(|| OpenError::NoClient {
                location: shown.clone(),
            })?;
            let runtime =
                tokio::runtime::Handle::try_current().map_err(|_| OpenError::NoRuntime {
                    location: shown.clone(),
                })?;
            let (zarr, reads) = object_storage(store.clone(), &prefix, BlockOn::new(runtime));
            let keys = Keys::Object(ObjectKeys {
                store,
                prefix,
                reads,
            });
            (keys, zarr)
        };
        Ok(Self { keys, zarr, shown })
    }

    /// An object store's keys read by futures; `None` for a folder.
    pub(crate) fn async_store(&self) -> Option<&AsyncReadable> {
        match &self.keys {
            Keys::Object(keys) => Some(&keys.reads),
            Keys::Folder(_) => None,
        }
    }

    /// The store as zarrs storage (synchronous: call it from blocking code).
    pub fn zarr(&self) -> Arc<dyn ReadableListableStorageTraits> {
        self.zarr.clone()
    }

    /// The store's location, as messages name it.
    pub fn shown(&self) -> &str {
        &self.shown
    }

    /// Reads a small document whose key comes from the store's own metadata (synchronous:
    /// call it from blocking code); `None` when there is no such key.
    ///
    /// # Errors
    /// [`KeyError`] when the key is malformed, leaves the store, or cannot be read.
    pub(crate) fn read_document(&self, key: &str) -> Result<Option<Vec<u8>>, KeyError> {
        // Keys from metadata are literal: encode `%` so they are not decoded again.
        const LITERAL: &percent_encoding::AsciiSet = &percent_encoding::CONTROLS.add(b'%');
        let raw = percent_encoding::utf8_percent_encode(key, LITERAL).to_string();
        match &self.keys {
            Keys::Folder(root) => match resolve(root.path(), &raw) {
                Ok(path) => std::fs::read(path)
                    .map(Some)
                    .map_err(|e| KeyError::Unreadable(e.into())),
                Err(KeyError::NotFound) => Ok(None),
                Err(e) => Err(e),
            },
            Keys::Object(_) => {
                let key = checked_key(&raw)?;
                let key = StoreKey::new(key).map_err(|_| KeyError::Refused("not a store key"))?;
                // zarrs' error holds the object store's failure among its causes (`StoreFailure::in_chain`).
                self.zarr
                    .get(&key)
                    .map(|found| found.map(|bytes| bytes.to_vec()))
                    .map_err(|e| KeyError::Unreadable(Box::new(e)))
            }
        }
    }
}

/// An object store's `ETag` as an HTTP entity tag: quoted (S3 quotes its tags; some servers
/// do not), or made of the length and modification time where the store gives none.
fn entity_tag(meta: &object_store::ObjectMeta) -> String {
    match meta.e_tag.as_deref() {
        Some(tag) if tag.starts_with('"') || tag.starts_with("W/\"") => tag.to_string(),
        Some(tag) => format!("\"{tag}\""),
        None => format!(
            "\"{:x}-{:x}\"",
            meta.size,
            meta.last_modified.timestamp_nanos_opt().unwrap_or(0)
        ),
    }
}

impl ObjectKeys {
    fn path(&self, key: &str) -> Result<ObjectPath, KeyError> {
        let key = ObjectPath::parse(key).map_err(|_| KeyError::Refused("not an object key"))?;
        Ok(self.prefix.parts().chain(key.parts()).collect())
    }

    /// Reads `range` of the object at `key` (decoded, checked), or all of it.
    ///
    /// # Errors
    /// [`KeyError::NotFound`] when there is no such object, [`KeyError::Unreadable`] holding a
    /// [`StoreFailure`] when the request fails after the client's retries (an unsatisfiable
    /// range among others: see [`ObjectKeys::head`]).
    pub async fn get(&self, key: &str, range: Option<GetRange>) -> Result<ObjectPart, KeyError> {
        let path = self.path(key)?;
        let options = GetOptions {
            range,
            ..GetOptions::default()
        };
        let got = self.store.get_opts(&path, options).await.map_err(failed)?;
        let (range, meta) = (got.range.clone(), got.meta.clone());
        let bytes = got.bytes().await.map_err(failed)?;
        Ok(ObjectPart {
            bytes,
            range,
            size: meta.size,
            etag: entity_tag(&meta),
        })
    }

    /// The length and `ETag` of the object at `key` (decoded, checked).
    ///
    /// # Errors
    /// As [`ObjectKeys::get`].
    pub async fn head(&self, key: &str) -> Result<(u64, String), KeyError> {
        let meta = self.store.head(&self.path(key)?).await.map_err(failed)?;
        Ok((meta.size, entity_tag(&meta)))
    }
}

/// The object-store range for an HTTP `Range` header value, read by the same RFC 9110 parser
/// as [`crate::responses::parse_range`] but without the object's length: `bytes=a-b`,
/// `bytes=a-` and `bytes=-n`. `None` where a file would be answered whole (several ranges,
/// another unit, a malformed or reversed range). Whether the range lies in the object is the
/// store's to say.
pub(crate) fn requested_range(value: &str) -> Option<GetRange> {
    use http_range_header::SyntacticallyCorrectRange as R;
    let ranges = http_range_header::parse_range_header(value.trim()).ok()?;
    let [range] = ranges.into_ranges()[..] else {
        return None;
    };
    Some(match range {
        R::Indexed(start, last) => GetRange::Bounded(start..last.saturating_add(1)),
        R::FromStart(start) => GetRange::Offset(start),
        R::FromLast(n) => GetRange::Suffix(n),
    })
}

/// The key error of a failed object-store request: a missing object, or a [`StoreFailure`]
/// (the client has tried again already), unreachable when the connection failed, was reset
/// or timed out, and an error answer otherwise (a 5xx, a refusal, a malformed answer).
fn failed(e: object_store::Error) -> KeyError {
    if let object_store::Error::NotFound { .. } = e {
        return KeyError::NotFound;
    }
    KeyError::Unreadable(Box::new(StoreFailure::of_request(e)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_for_the_object_store() {
        assert_eq!(requested_range("bytes=0-9"), Some(GetRange::Bounded(0..10)));
        assert_eq!(requested_range("bytes=90-"), Some(GetRange::Offset(90)));
        assert_eq!(requested_range("bytes=-16"), Some(GetRange::Suffix(16)));
        assert_eq!(
            requested_range("bytes=0-18446744073709551615"),
            Some(GetRange::Bounded(0..u64::MAX))
        );
        assert_eq!(requested_range("bytes=0-1,5-6"), None);
        assert_eq!(requested_range("items=0-1"), None);
        assert_eq!(requested_range("bytes=9-3"), None);
    }

    #[test]
    fn object_tags_are_quoted_entity_tags() {
        let meta = |e_tag: Option<&str>| object_store::ObjectMeta {
            location: ObjectPath::from("a"),
            last_modified: chrono_epoch(),
            size: 255,
            e_tag: e_tag.map(str::to_string),
            version: None,
        };
        assert_eq!(entity_tag(&meta(Some("\"abc\""))), "\"abc\"");
        assert_eq!(entity_tag(&meta(Some("W/\"abc\""))), "W/\"abc\"");
        assert_eq!(entity_tag(&meta(Some("abc"))), "\"abc\"");
        assert_eq!(entity_tag(&meta(None)), "\"ff-0\"");
    }

    #[test]
    fn store_failures_are_unreachable_only_for_transport_errors() {
        use object_store::client::{HttpError, HttpErrorKind};
        let generic = |source: Box<dyn std::error::Error + Send + Sync>| {
            failed(object_store::Error::Generic {
                store: "S3",
                source,
            })
        };
        let transport = |kind| generic(Box::new(HttpError::new(kind, std::io::Error::other("x"))));
        let unreachable = |e: &KeyError| match e {
            KeyError::Unreadable(source) => {
                StoreFailure::in_chain(source.as_ref()).map(|f| f.unreachable)
            }
            _ => None,
        };
        for kind in [
            HttpErrorKind::Connect,
            HttpErrorKind::Request,
            HttpErrorKind::Timeout,
            HttpErrorKind::Interrupted,
        ] {
            assert_eq!(unreachable(&transport(kind)), Some(true), "{kind:?}");
        }
        assert_eq!(unreachable(&transport(HttpErrorKind::Decode)), Some(false));
        let answered = generic("503 Service Unavailable: SlowDown".into());
        assert_eq!(unreachable(&answered), Some(false));
        assert_eq!(
            answered.to_string(),
            "the object store answered an error (Generic S3 error: 503 Service Unavailable: \
             SlowDown)"
        );
        let missing = failed(object_store::Error::NotFound {
            path: "a".into(),
            source: "gone".into(),
        });
        assert!(matches!(missing, KeyError::NotFound));
        assert_eq!(unreachable(&missing), None);
    }

    fn chrono_epoch() -> chrono::DateTime<chrono::Utc> {
        chrono::DateTime::from_timestamp(0, 0).expect("the epoch")
    }
}
