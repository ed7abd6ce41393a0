//! Where a store lives: a local folder (a plain path or a `file://` URL) or an S3-compatible
//! object store (`s3://bucket/prefix/name.ome.zarr`), opened as one zarrs storage either way.
//!
//! Object stores are reached through `object_store` (via `zarrs_object_store`). Credentials
//! and region come from the standard AWS variables (`AWS_ACCESS_KEY_ID`,
//! `AWS_SECRET_ACCESS_KEY`, `AWS_SESSION_TOKEN`, `AWS_REGION`/`AWS_DEFAULT_REGION`), and what
//! they leave unset from the AWS profile ([`crate::aws_profile`]); a non-AWS server is named by
//! `AWS_ENDPOINT_URL` (plain `http://` needs `AWS_ALLOW_HTTP=true`), a profile's
//! `endpoint_url`, or [`ObjectStoreOptions::endpoint`]. Requests are path-style
//! (`endpoint/bucket/key`). A failed request is tried again ([`S3_MAX_RETRIES`] times, with
//! backoff, within [`S3_RETRY_TIMEOUT`]), and one try is given up on after
//! [`S3_REQUEST_TIMEOUT`].
//!
//! Asynchronous programs (brickserver) make one client per store with
//! [`StoreLocation::object_store`], ask it with [`StoreLocation::exists_in`], and read the
//! pyramid through the same client with [`object_storage`], synchronously (its requests run on
//! their runtime, [`BlockOn`]) and by futures. The synchronous functions ([`StoreLocation::exists`],
//! [`StoreLocation::open_readable`], publishing and downloading) run theirs on the runtime the
//! caller gives in [`ObjectStoreOptions::runtime`] (synchronous programs start one with
//! [`ObjectStoreOptions::for_location`]); this crate keeps no runtime of its own. A synchronous
//! reader of many bricks (the viewer) opens the store with
//! [`StoreLocation::open_readable_and_async`] and reads bricks many at once by futures on that
//! runtime ([`BlockOn::run_all`]).

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::Arc;

use futures::{StreamExt, TryStreamExt};

use crate::aws_profile::{Profile, ProfileError};
use crate::ranged::RangedObjectStore;
use zarrs::filesystem::{FilesystemStore, FilesystemStoreCreateError};
use zarrs::storage::storage_adapter::async_to_sync::{
    AsyncToSyncBlockOn, AsyncToSyncStorageAdapter,
};
use zarrs::storage::{AsyncReadableStorageTraits, ReadableListableStorageTraits};
use zarrs_object_store::object_store::ClientConfigKey;
use zarrs_object_store::object_store::aws::{AmazonS3, AmazonS3Builder, AmazonS3ConfigKey};
use zarrs_object_store::object_store::path::Path as ObjectPath;
use zarrs_object_store::object_store::prefix::PrefixStore;
use zarrs_object_store::object_store::{ObjectStore, ObjectStoreExt, PutPayload};

/// The `object_store` crate this module reaches object stores with, for callers that make
/// their own requests (see [`StoreLocation::object_store`]).
pub use zarrs_object_store::object_store;

/// An object store and the key prefix of a store's root in it.
pub type ObjectStoreAt = (Arc<dyn ObjectStore>, ObjectPath);

/// The documents at a store's root that say what it is (Zarr v3, then v2): written last when a
/// store is published, and deleted first when one is replaced.
pub const ROOT_METADATA: [&str; 3] = ["zarr.json", ".zgroup", ".zattrs"];

/// Objects uploaded at once when a store is published.
const UPLOADS_IN_FLIGHT: usize = 16;

/// Times a failed object-store request is tried again: a 5xx or 429 answer, a connection that
/// failed, was reset or timed out, and a response body cut short (read again from where it
/// broke, if the object's `ETag` is unchanged). With one request in five failing, all eleven
/// tries of one request fail about once in 50 million requests.
pub const S3_MAX_RETRIES: usize = 10;

/// The first wait before a retry; each next wait is drawn at random up to twice the last one
/// (decorrelated jitter), at most [`S3_MAX_BACKOFF`].
pub const S3_FIRST_BACKOFF: std::time::Duration = std::time::Duration::from_millis(100);

/// The longest wait between two tries of one request.
pub const S3_MAX_BACKOFF: std::time::Duration = std::time::Duration::from_secs(2);

/// No retry starts once this long has passed since a request's first try.
pub const S3_RETRY_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(30);

/// How long one try may take in all, from connecting to the last byte of the answer (a
/// stalled server is given up on after this and tried again); `AWS_TIMEOUT` overrides it.
pub const S3_REQUEST_TIMEOUT: &str = "30s";

/// How long connecting may take; `AWS_CONNECT_TIMEOUT` overrides it.
pub const S3_CONNECT_TIMEOUT: &str = "5s";

/// The retry settings of every object-store client this module makes.
fn s3_retry() -> object_store::RetryConfig {
    object_store::RetryConfig {
        backoff: object_store::BackoffConfig {
            init_backoff: S3_FIRST_BACKOFF,
            max_backoff: S3_MAX_BACKOFF,
            base: 2.0,
        },
        max_retries: S3_MAX_RETRIES,
        retry_timeout: S3_RETRY_TIMEOUT,
    }
}

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
    #[error("{}: cannot open the store: {source}", path.display())]
    Folder {
        /// The folder.
        path: PathBuf,
        /// What zarrs said.
        #[source]
        source: FilesystemStoreCreateError,
    },
    /// The object store client cannot be configured (credentials, region, endpoint), or a
    /// request failed.
    #[error("{location}: {source}")]
    ObjectStore {
        /// The location (and key) of the request.
        location: String,
        /// What `object_store` said.
        #[source]
        source: object_store::Error,
    },
    /// The AWS profile cannot be read.
    #[error(transparent)]
    Profile(#[from] ProfileError),
    /// A synchronous function was called for an object-store location without a runtime in
    /// [`ObjectStoreOptions::runtime`] to run its requests.
    #[error("{location}: object-store requests need a tokio runtime (ObjectStoreOptions::runtime)")]
    NoRuntime {
        /// The location.
        location: String,
    },
    /// The runtime for an object-store location's requests cannot be started.
    #[error("{location}: cannot start a runtime for object-store requests")]
    Runtime {
        /// The location.
        location: String,
        /// What tokio said.
        #[source]
        source: std::io::Error,
    },
    /// A store is already there, and replacing it was not asked for.
    #[error("{location}: output already exists (pass --overwrite to replace it)")]
    Exists {
        /// The location.
        location: String,
    },
    /// A downloaded file cannot be written.
    #[error("{}: cannot write", path.display())]
    WriteFile {
        /// The file.
        path: PathBuf,
        /// What the file system said.
        #[source]
        source: std::io::Error,
    },
    /// A file of the store to publish cannot be read.
    #[error("{}: cannot read", path.display())]
    ReadFile {
        /// The file.
        path: PathBuf,
        /// What the file system said.
        #[source]
        source: std::io::Error,
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

/// How to reach an object store beyond the AWS variables, and the caller's runtime that runs
/// the requests of this module's synchronous functions.
#[derive(Clone, Debug, Default)]
pub struct ObjectStoreOptions {
    /// Endpoint URL of a non-AWS server (overrides `AWS_ENDPOINT_URL`); an `http://`
    /// endpoint is allowed without `AWS_ALLOW_HTTP`.
    pub endpoint: Option<String>,
    /// Runs object-store requests for the synchronous functions ([`StoreLocation::exists`],
    /// [`StoreLocation::upload_folder`], [`StoreLocation::download_prefix`],
    /// [`StoreLocation::open_readable`], [`StoreLocation::open_readable_and_async`], whose async
    /// storage's reads run on it by [`BlockOn::run_all`]); without one they refuse object-store locations
    /// ([`LocationError::NoRuntime`]). Folders need none, and asynchronous callers use
    /// [`StoreLocation::exists_in`] and [`object_storage`] on their own runtime instead.
    pub runtime: Option<BlockOn>,
}

/// Worker threads of the runtime [`ObjectStoreOptions::for_location`] starts: one per core, at
/// least two. Requests wait on the network, so a few workers keep many in flight; readers that
/// decode what they read on these workers ([`BlockOn::run_all`]) decode on every core.
fn request_threads() -> usize {
    std::thread::available_parallelism().map_or(2, |n| n.get().max(2))
}

impl ObjectStoreOptions {
    /// Options for a synchronous program that reaches `location`: `endpoint`, and for an
    /// object-store location a runtime started for its requests, which lives as long as these
    /// options and the storage opened with them. A folder gets no runtime.
    ///
    /// # Errors
    /// [`LocationError::Runtime`] when the runtime cannot be started.
    pub fn for_location(
        location: &StoreLocation,
        endpoint: Option<String>,
    ) -> Result<Self, LocationError> {
        let runtime = match location {
            StoreLocation::Folder(_) => None,
            StoreLocation::S3 { .. } => {
                Some(BlockOn::start(request_threads()).map_err(|source| {
                    LocationError::Runtime {
                        location: location.to_string(),
                        source,
                    }
                })?)
            }
        };
        Ok(Self { endpoint, runtime })
    }

    /// The runtime for `location`'s requests.
    fn runtime_for(&self, location: &StoreLocation) -> Result<&BlockOn, LocationError> {
        self.runtime
            .as_ref()
            .ok_or_else(|| LocationError::NoRuntime {
                location: location.to_string(),
            })
    }
}

/// Runs object-store futures for zarrs' synchronous API on a multi-threaded tokio runtime the
/// caller chose, from synchronous code: a thread outside the runtime, or a blocking task of it
/// (`spawn_blocking`), never an async task.
#[derive(Clone, Debug)]
pub struct BlockOn {
    handle: tokio::runtime::Handle,
    /// The runtime, when this started it: kept alive until the last clone is dropped.
    _started: Option<Arc<tokio::runtime::Runtime>>,
}

impl BlockOn {
    /// Runs futures on the runtime of `handle`, which the caller keeps running for as long as
    /// this is used.
    pub fn new(handle: tokio::runtime::Handle) -> Self {
        Self {
            handle,
            _started: None,
        }
    }

    /// Starts a multi-threaded runtime of `threads` workers for this alone, stopped when the
    /// last clone is dropped (from synchronous code, not from inside another runtime).
    ///
    /// # Errors
    /// The I/O error of a runtime that cannot be started.
    pub fn start(threads: usize) -> std::io::Result<Self> {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(threads)
            .thread_name("object-store")
            .enable_all()
            .build()?;
        Ok(Self {
            handle: runtime.handle().clone(),
            _started: Some(Arc::new(runtime)),
        })
    }

    /// The runtime's handle, for async callers that spawn on it.
    pub fn handle(&self) -> &tokio::runtime::Handle {
        &self.handle
    }

    /// Runs `tasks` on the runtime, one runtime task each and at most `in_flight` at once, from
    /// synchronous code (as [`BlockOn`]), and gives their outputs in the order of `tasks`. The
    /// runtime's workers run them side by side: what a task does after its request (decoding)
    /// does not wait for the others.
    ///
    /// # Panics
    /// With a task's own panic, when one panics.
    pub fn run_all<F>(&self, tasks: impl IntoIterator<Item = F>, in_flight: usize) -> Vec<F::Output>
    where
        F: Future + Send + 'static,
        F::Output: Send + 'static,
    {
        // Lazily spawned: no more than `in_flight` tasks exist at once.
        let spawned = futures::stream::iter(tasks).map(|task| self.handle.spawn(task));
        self.handle.block_on(
            spawned
                .buffered(in_flight.max(1))
                .map(|done| match done {
                    Ok(output) => output,
                    Err(e) if e.is_panic() => std::panic::resume_unwind(e.into_panic()),
                    Err(e) => panic!("an object-store task was cancelled: {e}"),
                })
                .collect(),
        )
    }
}

impl AsyncToSyncBlockOn for BlockOn {
    fn block_on<F: Future>(&self, future: F) -> F::Output {
        self.handle.block_on(future)
    }
}

/// An object store's keys as zarrs' async storage, and the runtime its requests run on (see
/// [`StoreLocation::open_readable_and_async`]).
#[derive(Clone)]
pub struct AsyncReadable {
    /// The keys, one ranged `GET` per read ([`RangedObjectStore`]).
    pub storage: Arc<dyn AsyncReadableStorageTraits>,
    /// The runtime that runs the requests (from [`ObjectStoreOptions::runtime`]).
    pub runtime: BlockOn,
}

/// The keys under `prefix` in `store`, read through that one client two ways: by zarrs'
/// synchronous API, its requests run by `runtime` (a reader's one-time loads: metadata, region
/// arrays), and by futures (bricks, many at once); one ranged `GET` per read either way
/// ([`RangedObjectStore`]). For callers that also make their own requests to `store` (see
/// [`StoreLocation::object_store`]), and for [`StoreLocation::open_readable_and_async`].
pub fn object_storage(
    store: Arc<dyn ObjectStore>,
    prefix: &ObjectPath,
    runtime: BlockOn,
) -> (Arc<dyn ReadableListableStorageTraits>, AsyncReadable) {
    let storage = Arc::new(RangedObjectStore::new(Arc::new(PrefixStore::new(
        store,
        prefix.clone(),
    ))));
    let sync = Arc::new(AsyncToSyncStorageAdapter::new(
        storage.clone(),
        runtime.clone(),
    ));
    (sync, AsyncReadable { storage, runtime })
}

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

    /// The S3 client of an `s3://` location, and its key prefix.
    fn s3_client(&self, options: &ObjectStoreOptions) -> Result<(AmazonS3, String), LocationError> {
        let Self::S3 { bucket, prefix } = self else {
            unreachable!("called for S3 locations only");
        };
        let mut builder = AmazonS3Builder::from_env().with_bucket_name(bucket);
        // What the environment leaves unset comes from the AWS profile, if there is one.
        let unset = |name: &str| std::env::var_os(name).is_none_or(|v| v.is_empty());
        if let Some(profile) = Profile::from_env()? {
            if unset("AWS_ACCESS_KEY_ID") {
                if let Some(key) = profile.access_key_id {
                    builder = builder.with_access_key_id(key);
                }
                if let Some(secret) = profile.secret_access_key {
                    builder = builder.with_secret_access_key(secret);
                }
                if let Some(token) = profile.session_token {
                    builder = builder.with_token(token);
                }
            }
            if let Some(region) = profile.region
                && unset("AWS_REGION")
                && unset("AWS_DEFAULT_REGION")
            {
                builder = builder.with_region(region);
            }
            if let Some(endpoint) = profile.endpoint_url
                && unset("AWS_ENDPOINT_URL")
                && options.endpoint.is_none()
            {
                builder = builder
                    .with_allow_http(endpoint.starts_with("http://"))
                    .with_endpoint(endpoint);
            }
        }
        if let Some(endpoint) = &options.endpoint {
            builder = builder
                .with_endpoint(endpoint)
                .with_allow_http(endpoint.starts_with("http://"));
        }
        // Bounded tries and timeouts, so that a failing or stalled server is an error in
        // bounded time, never a hang; the environment's timeouts win.
        for (variable, key, value) in [
            ("AWS_TIMEOUT", ClientConfigKey::Timeout, S3_REQUEST_TIMEOUT),
            (
                "AWS_CONNECT_TIMEOUT",
                ClientConfigKey::ConnectTimeout,
                S3_CONNECT_TIMEOUT,
            ),
        ] {
            if unset(variable) {
                builder = builder.with_config(AmazonS3ConfigKey::Client(key), value);
            }
        }
        let s3 = builder.with_retry(s3_retry()).build().map_err(|source| {
            LocationError::ObjectStore {
                location: self.to_string(),
                source,
            }
        })?;
        Ok((s3, prefix.clone()))
    }

    /// The object store and the key prefix of an `s3://` location (`None` for a folder), for
    /// readers that make their own requests: ranged reads with the store's `ETag`s.
    ///
    /// # Errors
    /// [`LocationError::ObjectStore`] when the object-store client cannot be configured.
    pub fn object_store(
        &self,
        options: &ObjectStoreOptions,
    ) -> Result<Option<ObjectStoreAt>, LocationError> {
        if self.folder().is_some() {
            return Ok(None);
        }
        let (s3, prefix) = self.s3_client(options)?;
        Ok(Some((Arc::new(s3), ObjectPath::from(prefix))))
    }

    /// Whether a store is at this location: its root metadata exists (a folder: the folder
    /// exists).
    ///
    /// # Errors
    /// [`LocationError::ObjectStore`] when the object store cannot be asked.
    pub fn exists(&self, options: &ObjectStoreOptions) -> Result<bool, LocationError> {
        let Self::S3 { .. } = self else {
            return Ok(self.folder().is_some_and(Path::exists));
        };
        let runtime = options.runtime_for(self)?;
        let (s3, prefix) = self.s3_client(options)?;
        let at: ObjectStoreAt = (Arc::new(s3), ObjectPath::from(prefix));
        runtime.block_on(self.exists_in(&at))
    }

    /// Whether a store is at `prefix` in `store` (this location's object store and key
    /// prefix, from [`StoreLocation::object_store`]): its root metadata exists. Errors name
    /// this location.
    ///
    /// # Errors
    /// [`LocationError::ObjectStore`] when the object store cannot be asked.
    pub async fn exists_in(&self, (store, prefix): &ObjectStoreAt) -> Result<bool, LocationError> {
        for name in ROOT_METADATA {
            let key = ObjectPath::from(format!("{prefix}/{name}"));
            match store.head(&key).await {
                Ok(_) => return Ok(true),
                Err(object_store::Error::NotFound { .. }) => {}
                Err(source) => {
                    return Err(LocationError::ObjectStore {
                        location: format!("{self}/{name}"),
                        source,
                    });
                }
            }
        }
        Ok(false)
    }

    /// Refuses a location where a store already is, unless `overwrite`.
    ///
    /// # Errors
    /// [`LocationError::Exists`], or [`LocationError::ObjectStore`] when the object store
    /// cannot be asked.
    pub fn check_absent(
        &self,
        options: &ObjectStoreOptions,
        overwrite: bool,
    ) -> Result<(), LocationError> {
        if !overwrite && self.exists(options)? {
            return Err(LocationError::Exists {
                location: self.to_string(),
            });
        }
        Ok(())
    }

    /// Uploads every file of `folder` under this object-store location so that a reader never
    /// takes a partial store for a complete one: the root metadata ([`ROOT_METADATA`]) last,
    /// one document at a time, and those it put where there was none deleted again if one of
    /// them fails (a failed upload leaves no root metadata that was not there before, unless
    /// deleting failed too).
    /// The other keys there are kept unless `clear` (replacing a store: then the old root
    /// metadata is deleted first, then every key under the prefix). Keys under `scratch` (a
    /// sub-prefix such as `.partitions`) are deleted just before the root metadata goes up.
    /// `uploaded` is called with each file's bytes. Returns the bytes uploaded.
    ///
    /// # Errors
    /// [`LocationError::ReadFile`] for a file that cannot be read, and
    /// [`LocationError::ObjectStore`] (naming the key) for a request that failed.
    pub fn upload_folder(
        &self,
        folder: &Path,
        options: &ObjectStoreOptions,
        clear: bool,
        scratch: Option<&str>,
        uploaded: &(dyn Fn(u64) + Sync),
    ) -> Result<u64, LocationError> {
        let runtime = options.runtime_for(self)?;
        let (s3, prefix) = self.s3_client(options)?;
        let mut files = Vec::new();
        list_files(folder, folder, &mut files)?;
        let (root, rest): (Vec<String>, Vec<String>) = files
            .into_iter()
            .partition(|rel| ROOT_METADATA.contains(&rel.as_str()));
        let failed = |key: &str, source| LocationError::ObjectStore {
            location: format!("{self}/{key}"),
            source,
        };
        runtime.block_on(async {
            if clear {
                for name in ROOT_METADATA {
                    let key = ObjectPath::from(format!("{prefix}/{name}"));
                    match s3.delete(&key).await {
                        Ok(()) | Err(object_store::Error::NotFound { .. }) => {}
                        Err(source) => return Err(failed(name, source)),
                    }
                }
                // Then every other key, in bulk requests.
                delete_under(&s3, &prefix)
                    .await
                    .map_err(|source| failed("", source))?;
            }
            let upload = |batch: Vec<String>| {
                let (s3, prefix, failed) = (&s3, &prefix, &failed);
                futures::stream::iter(batch)
                    .map(move |rel| async move {
                        let key = ObjectPath::from(format!("{prefix}/{rel}"));
                        put_file(s3, &key, &folder.join(&rel), &|source| failed(&rel, source))
                            .await
                            .inspect(|&n| uploaded(n))
                    })
                    .buffer_unordered(UPLOADS_IN_FLIGHT)
                    .try_fold(0, |total, n| async move { Ok(total + n) })
            };
            let mut total = upload(rest).await?;
            if let Some(sub) = scratch {
                delete_under(&s3, &format!("{prefix}/{sub}"))
                    .await
                    .map_err(|source| failed(sub, source))?;
            }
            // The root documents one by one: if one fails, those it put where there was none
            // are taken down, so that a failed upload never leaves a store that looks whole
            // (a document that was there, as for `ingest index`, stays: old or new, it is
            // whole).
            let mut fresh = Vec::new();
            for rel in &root {
                let key = ObjectPath::from(format!("{prefix}/{rel}"));
                let existed = match s3.head(&key).await {
                    Ok(_) => true,
                    Err(object_store::Error::NotFound { .. }) => false,
                    Err(source) => return Err(failed(rel, source)),
                };
                match put_file(&s3, &key, &folder.join(rel), &|source| failed(rel, source)).await {
                    Ok(n) => {
                        uploaded(n);
                        total += n;
                        if !existed {
                            fresh.push(key);
                        }
                    }
                    Err(e) => {
                        for key in &fresh {
                            let _ = s3.delete(key).await;
                        }
                        return Err(e);
                    }
                }
            }
            Ok(total)
        })
    }

    /// Downloads every object under the sub-prefix `sub` of this object-store location into
    /// `folder` (created), each as the file at its key below the location. Returns how many.
    ///
    /// # Errors
    /// [`LocationError::ObjectStore`] (naming the key) for a request that failed, and
    /// [`LocationError::WriteFile`] when a file cannot be written.
    pub fn download_prefix(
        &self,
        sub: &str,
        folder: &Path,
        options: &ObjectStoreOptions,
    ) -> Result<usize, LocationError> {
        let runtime = options.runtime_for(self)?;
        let (s3, prefix) = self.s3_client(options)?;
        let failed = |key: &str, source| LocationError::ObjectStore {
            location: format!("{self}/{key}"),
            source,
        };
        runtime.block_on(async {
            let listed: Vec<_> = s3
                .list(Some(&ObjectPath::from(format!("{prefix}/{sub}"))))
                .try_collect()
                .await
                .map_err(|source| failed(sub, source))?;
            for meta in &listed {
                let key = meta.location.as_ref();
                let rel = key.strip_prefix(&format!("{prefix}/")).unwrap_or(key);
                let got = s3
                    .get(&meta.location)
                    .await
                    .map_err(|source| failed(rel, source))?;
                let bytes = got.bytes().await.map_err(|source| failed(rel, source))?;
                let path = folder.join(rel);
                let write = |source| LocationError::WriteFile {
                    path: path.clone(),
                    source,
                };
                if let Some(parent) = path.parent() {
                    tokio::fs::create_dir_all(parent).await.map_err(write)?;
                }
                tokio::fs::write(&path, bytes).await.map_err(write)?;
            }
            Ok(listed.len())
        })
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
        Ok(self.open_readable_and_async(options)?.0)
    }

    /// [`StoreLocation::open_readable`], and for an object store the same keys through the same
    /// client as async storage, with the runtime that runs its requests: for a synchronous
    /// reader that reads its metadata through the first and many bricks at once by futures
    /// through the second ([`BlockOn::run_all`]). A folder has no async storage (`None`).
    ///
    /// # Errors
    /// As [`StoreLocation::open_readable`].
    pub fn open_readable_and_async(
        &self,
        options: &ObjectStoreOptions,
    ) -> Result<
        (
            Arc<dyn ReadableListableStorageTraits>,
            Option<AsyncReadable>,
        ),
        LocationError,
    > {
        Ok(match self {
            Self::Folder(path) => (Arc::new(folder_store(path)?), None),
            Self::S3 { .. } => {
                let runtime = options.runtime_for(self)?.clone();
                let (s3, prefix) = self.s3_client(options)?;
                let (sync, reads) =
                    object_storage(Arc::new(s3), &ObjectPath::from(prefix), runtime);
                (sync, Some(reads))
            }
        })
    }
}

/// Deletes every key under `prefix`, in bulk requests.
async fn delete_under(s3: &AmazonS3, prefix: &str) -> Result<(), object_store::Error> {
    let listed = s3
        .list(Some(&ObjectPath::from(prefix)))
        .map_ok(|meta| meta.location)
        .boxed();
    s3.delete_stream(listed).try_collect::<Vec<_>>().await?;
    Ok(())
}

/// Files larger than this go up in parts (S3 takes at most 5 GB in one request; the AWS CLI
/// switches to parts at the same size).
pub const MULTIPART_THRESHOLD: u64 = 8 << 20;

/// The size of each part of a multipart upload (grown for files of more than 10,000 parts,
/// S3's limit).
const PART_BYTES: u64 = 8 << 20;

/// Parts of one file uploaded at once.
const PARTS_IN_FLIGHT: usize = 4;

/// Uploads the file at `path` to `key`: in one request up to [`MULTIPART_THRESHOLD`], else as
/// a multipart upload read from the file part by part (aborted if a part fails). Returns its
/// bytes.
async fn put_file(
    s3: &AmazonS3,
    key: &ObjectPath,
    path: &Path,
    failed: &(dyn Fn(object_store::Error) -> LocationError + Sync),
) -> Result<u64, LocationError> {
    use tokio::io::AsyncReadExt;
    let read = |source| LocationError::ReadFile {
        path: path.to_path_buf(),
        source,
    };
    let len = tokio::fs::metadata(path).await.map_err(read)?.len();
    if len <= MULTIPART_THRESHOLD {
        let bytes = tokio::fs::read(path).await.map_err(read)?;
        s3.put(key, PutPayload::from(bytes)).await.map_err(failed)?;
        return Ok(len);
    }
    let part = PART_BYTES.max(len.div_ceil(10_000)) as usize;
    let upload = s3.put_multipart(key).await.map_err(failed)?;
    let mut writer = object_store::WriteMultipart::new_with_chunk_size(upload, part);
    let mut file = tokio::fs::File::open(path).await.map_err(read)?;
    let mut buffer = Vec::with_capacity(part);
    let sent = async {
        loop {
            writer
                .wait_for_capacity(PARTS_IN_FLIGHT)
                .await
                .map_err(failed)?;
            buffer.clear();
            (&mut file)
                .take(part as u64)
                .read_to_end(&mut buffer)
                .await
                .map_err(read)?;
            if buffer.is_empty() {
                return Ok(());
            }
            writer.write(&buffer);
        }
    }
    .await;
    match sent {
        Ok(()) => {
            writer.finish().await.map_err(failed)?;
            Ok(len)
        }
        Err(e) => {
            let _ = writer.abort().await;
            Err(e)
        }
    }
}

/// Every file under `dir`, as `/`-separated paths relative to `root`, sorted.
fn list_files(root: &Path, dir: &Path, out: &mut Vec<String>) -> Result<(), LocationError> {
    let read = |path: &Path, source| LocationError::ReadFile {
        path: path.to_path_buf(),
        source,
    };
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .map_err(|e| read(dir, e))?
        .collect::<Result<_, _>>()
        .map_err(|e| read(dir, e))?;
    entries.sort_by_key(std::fs::DirEntry::path);
    for entry in entries {
        let path = entry.path();
        if entry.file_type().map_err(|e| read(&path, e))?.is_dir() {
            list_files(root, &path, out)?;
        } else {
            let rel = path.strip_prefix(root).unwrap_or(&path);
            let parts: Vec<_> = rel.iter().map(|p| p.to_string_lossy()).collect();
            out.push(parts.join("/"));
        }
    }
    Ok(())
}

fn folder_store(path: &Path) -> Result<FilesystemStore, LocationError> {
    FilesystemStore::new(path).map_err(|source| LocationError::Folder {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_all_keeps_the_order_and_at_most_in_flight_tasks_at_once() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let runtime = BlockOn::start(2).unwrap();
        let (now, most) = (Arc::new(AtomicUsize::new(0)), Arc::new(AtomicUsize::new(0)));
        let tasks = (0..20u64).map(|i| {
            let (now, most) = (now.clone(), most.clone());
            async move {
                most.fetch_max(now.fetch_add(1, Ordering::SeqCst) + 1, Ordering::SeqCst);
                // Later tasks finish first: the order of the outputs is the order of the tasks.
                tokio::time::sleep(std::time::Duration::from_millis(40 - 2 * i)).await;
                now.fetch_sub(1, Ordering::SeqCst);
                i * 10
            }
        });
        let out = runtime.run_all(tasks, 5);
        assert_eq!(out, (0..20).map(|i| i * 10).collect::<Vec<_>>());
        assert_eq!(most.load(Ordering::SeqCst), 5);
        let panicked = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            runtime.run_all([async { panic!("brick 7 is cursed") }], 1)
        }));
        let message = panicked.unwrap_err();
        assert_eq!(message.downcast_ref::<&str>(), Some(&"brick 7 is cursed"));
    }

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

    #[test]
    fn object_store_requests_run_on_the_callers_runtime_only() {
        let s3: StoreLocation = "s3://bucket/name.ome.zarr".parse().unwrap();
        let without = ObjectStoreOptions::default();
        // Refused before any request is made: there is no runtime of this crate's to fall
        // back on.
        assert_eq!(
            s3.exists(&without).unwrap_err().to_string(),
            "s3://bucket/name.ome.zarr: object-store requests need a tokio runtime \
             (ObjectStoreOptions::runtime)"
        );
        assert!(matches!(
            s3.open_readable(&without),
            Err(LocationError::NoRuntime { .. })
        ));
        let folder = StoreLocation::Folder(std::env::temp_dir());
        assert!(
            ObjectStoreOptions::for_location(&folder, None)
                .unwrap()
                .runtime
                .is_none()
        );
        assert!(folder.exists(&without).unwrap());
        let with =
            ObjectStoreOptions::for_location(&s3, Some("http://127.0.0.1:9".into())).unwrap();
        let runtime = with
            .runtime
            .clone()
            .expect("a runtime for an s3:// location");
        // The runtime is the caller's: it runs futures for as long as a clone of it is held.
        assert_eq!(runtime.block_on(async { 7 }), 7);
        assert!(s3.open_readable(&with).is_ok());
    }
}
