//! Where a store lives: a local folder (a plain path or a `file://` URL) or an S3-compatible
//! object store (`s3://bucket/prefix/name.ome.zarr`), opened as one zarrs storage either way.
//!
//! Object stores are reached through `object_store` (via `zarrs_object_store`). Credentials
//! and region come from the standard AWS variables (`AWS_ACCESS_KEY_ID`,
//! `AWS_SECRET_ACCESS_KEY`, `AWS_SESSION_TOKEN`, `AWS_REGION`/`AWS_DEFAULT_REGION`); a
//! non-AWS server is named by `AWS_ENDPOINT_URL` (plain `http://` needs `AWS_ALLOW_HTTP=true`),
//! or by [`ObjectStoreOptions::endpoint`]. Requests are path-style (`endpoint/bucket/key`).

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::{Arc, OnceLock};

use zarrs::filesystem::FilesystemStore;
use zarrs::storage::storage_adapter::async_to_sync::{
    AsyncToSyncBlockOn, AsyncToSyncStorageAdapter,
};
use zarrs::storage::{ReadableListableStorageTraits, ReadableWritableListableStorageTraits};
use zarrs_object_store::AsyncObjectStore;
use zarrs_object_store::object_store::aws::{AmazonS3, AmazonS3Builder};
use zarrs_object_store::object_store::prefix::PrefixStore;

/// A store's location, parsed from a command-line argument.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum StoreLocation {
    /// A local folder.
    Folder(PathBuf),
    /// A prefix in a bucket of an S3-compatible object store.
    S3 {
        /// The bucket.
        bucket: String,
        /// The key prefix of the store's root (no leading or trailing `/`).
        prefix: String,
    },
}

/// A location that cannot be parsed or opened. Messages name the location.
#[derive(Debug, thiserror::Error)]
pub enum LocationError {
    /// An `s3://` URL without a bucket or without a key prefix.
    #[error("{url}: an S3 location is s3://BUCKET/PREFIX (the store's root), with both parts")]
    S3Url {
        /// The URL as given.
        url: String,
    },
    /// A URL scheme other than `s3://` and `file://`.
    #[error("{url}: unknown scheme (stores are local paths, file:// or s3:// URLs)")]
    Scheme {
        /// The URL as given.
        url: String,
    },
    /// A local folder zarrs cannot open.
    #[error("{}: cannot open the store: {reason}", path.display())]
    Folder {
        /// The folder.
        path: PathBuf,
        /// What zarrs said.
        reason: String,
    },
    /// The object store client cannot be configured (credentials, region, endpoint).
    #[error("{location}: cannot reach the object store: {source}")]
    ObjectStore {
        /// The location.
        location: String,
        /// What `object_store` said.
        #[source]
        source: zarrs_object_store::object_store::Error,
    },
}

impl FromStr for StoreLocation {
    type Err = LocationError;

    /// `s3://bucket/prefix`, `file:///path`, or a plain path.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if let Some(rest) = s.strip_prefix("s3://") {
            let (bucket, prefix) = rest.split_once('/').unwrap_or((rest, ""));
            let prefix = prefix.trim_matches('/');
            if bucket.is_empty() || prefix.is_empty() {
                return Err(LocationError::S3Url { url: s.to_string() });
            }
            return Ok(Self::S3 {
                bucket: bucket.to_string(),
                prefix: prefix.to_string(),
            });
        }
        if let Some(path) = s.strip_prefix("file://") {
            return Ok(Self::Folder(PathBuf::from(path)));
        }
        if s.contains("://") {
            return Err(LocationError::Scheme { url: s.to_string() });
        }
        Ok(Self::Folder(PathBuf::from(s)))
    }
}

impl fmt::Display for StoreLocation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Folder(path) => write!(f, "{}", path.display()),
            Self::S3 { bucket, prefix } => write!(f, "s3://{bucket}/{prefix}"),
        }
    }
}

/// How to reach an object store beyond the AWS variables.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ObjectStoreOptions {
    /// Endpoint URL of a non-AWS server (overrides `AWS_ENDPOINT_URL`); an `http://`
    /// endpoint is allowed without `AWS_ALLOW_HTTP`.
    pub endpoint: Option<String>,
}

/// The tokio runtime that runs object-store requests for the synchronous zarrs API.
fn runtime() -> &'static tokio::runtime::Runtime {
    static RUNTIME: OnceLock<tokio::runtime::Runtime> = OnceLock::new();
    RUNTIME.get_or_init(|| {
        tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("object-store")
            .enable_all()
            .build()
            .expect("a tokio runtime for object-store requests")
    })
}

/// Runs object-store futures on [`runtime`] from synchronous code (not from inside an async
/// task: callers in async code use `spawn_blocking`).
struct BlockOnRuntime;

impl AsyncToSyncBlockOn for BlockOnRuntime {
    fn block_on<F: Future>(&self, future: F) -> F::Output {
        runtime().block_on(future)
    }
}

type ObjectStorage =
    AsyncToSyncStorageAdapter<AsyncObjectStore<PrefixStore<AmazonS3>>, BlockOnRuntime>;

impl StoreLocation {
    /// The folder, for a local store.
    pub fn folder(&self) -> Option<&Path> {
        match self {
            Self::Folder(path) => Some(path),
            Self::S3 { .. } => None,
        }
    }

    /// The store's name: its last path component (`name.ome.zarr`).
    pub fn file_name(&self) -> String {
        match self {
            Self::Folder(path) => path.file_name().map_or_else(
                || path.display().to_string(),
                |n| n.to_string_lossy().into(),
            ),
            Self::S3 { prefix, .. } => prefix.rsplit('/').next().unwrap_or(prefix).to_string(),
        }
    }

    fn object_storage(&self, options: &ObjectStoreOptions) -> Result<ObjectStorage, LocationError> {
        let Self::S3 { bucket, prefix } = self else {
            unreachable!("called for S3 locations only");
        };
        let mut builder = AmazonS3Builder::from_env().with_bucket_name(bucket);
        if let Some(endpoint) = &options.endpoint {
            builder = builder
                .with_endpoint(endpoint)
                .with_allow_http(endpoint.starts_with("http://"));
        }
        let s3 = builder
            .build()
            .map_err(|source| LocationError::ObjectStore {
                location: self.to_string(),
                source,
            })?;
        let store = AsyncObjectStore::new(PrefixStore::new(s3, prefix.as_str()));
        Ok(AsyncToSyncStorageAdapter::new(
            Arc::new(store),
            BlockOnRuntime,
        ))
    }

    /// Opens the store for reading.
    ///
    /// # Errors
    /// [`LocationError::Folder`] when zarrs cannot open the folder, or
    /// [`LocationError::ObjectStore`] when the object-store client cannot be configured.
    /// Whether the store exists is found out by the first read.
    pub fn open_readable(
        &self,
        options: &ObjectStoreOptions,
    ) -> Result<Arc<dyn ReadableListableStorageTraits>, LocationError> {
        Ok(match self {
            Self::Folder(path) => Arc::new(folder_store(path)?),
            Self::S3 { .. } => Arc::new(self.object_storage(options)?),
        })
    }

    /// Opens the store for reading and writing.
    ///
    /// # Errors
    /// As [`StoreLocation::open_readable`].
    pub fn open_writable(
        &self,
        options: &ObjectStoreOptions,
    ) -> Result<Arc<dyn ReadableWritableListableStorageTraits>, LocationError> {
        Ok(match self {
            Self::Folder(path) => Arc::new(folder_store(path)?),
            Self::S3 { .. } => Arc::new(self.object_storage(options)?),
        })
    }
}

fn folder_store(path: &Path) -> Result<FilesystemStore, LocationError> {
    FilesystemStore::new(path).map_err(|e| LocationError::Folder {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locations_parse_and_print() {
        let s3: StoreLocation = "s3://bucket/a/b/name.ome.zarr/".parse().unwrap();
        assert_eq!(
            s3,
            StoreLocation::S3 {
                bucket: "bucket".into(),
                prefix: "a/b/name.ome.zarr".into()
            }
        );
        assert_eq!(s3.to_string(), "s3://bucket/a/b/name.ome.zarr");
        assert_eq!(s3.file_name(), "name.ome.zarr");
        let file: StoreLocation = "file:///data/x.ome.zarr".parse().unwrap();
        assert_eq!(file.folder(), Some(Path::new("/data/x.ome.zarr")));
        let plain: StoreLocation = "rel/x.ome.zarr".parse().unwrap();
        assert_eq!(plain.file_name(), "x.ome.zarr");
        let err = |s: &str| s.parse::<StoreLocation>().unwrap_err().to_string();
        assert_eq!(
            err("s3://bucket"),
            "s3://bucket: an S3 location is s3://BUCKET/PREFIX (the store's root), with both parts"
        );
        assert_eq!(
            err("gs://b/p"),
            "gs://b/p: unknown scheme (stores are local paths, file:// or s3:// URLs)"
        );
    }
}
