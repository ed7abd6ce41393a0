//! The store a conversion writes into while it runs ([`StagingStore`]): plain writes, one
//! file-system sync at the end.

use std::io;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use zarrs::filesystem::FilesystemStore;
use zarrs::storage::byte_range::ByteRangeIterator;
use zarrs::storage::{
    Bytes, MaybeBytesIterator, OffsetBytesIterator, ReadableStorageTraits, StorageError, StoreKey,
    StorePrefix, WritableStorageTraits,
};

use super::error::StoreError;

/// The zarrs store type used throughout.
pub(crate) type Store = StagingStore;

/// A filesystem store for a store under construction. Whole values are written with a plain
/// write, without the per-file `fsync` of zarrs' [`FilesystemStore`]: the store is private
/// until [`StoreWriter::commit`](super::writer::StoreWriter::commit) syncs the file system
/// once and renames it into place. Everything else is delegated to [`FilesystemStore`].
#[derive(Debug)]
pub(crate) struct StagingStore {
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
        let mut file = std::fs::File::create(&path).map_err(io)?;
        io::Write::write_all(&mut file, &value).map_err(io)?;
        start_writeback(&file);
        Ok(())
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

/// Starts writing `file`'s pages to the disk without waiting (Linux `sync_file_range`), so
/// the one sync at the end ([`sync_file_system`]) waits for little: the disk works while the
/// conversion does. Only a hint; failures are left for that sync to report.
fn start_writeback(file: &std::fs::File) {
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        // SAFETY: `file` is an open file descriptor for the duration of the call, which only
        // starts writeback of its dirty pages.
        unsafe { libc::sync_file_range(file.as_raw_fd(), 0, 0, libc::SYNC_FILE_RANGE_WRITE) };
    }
    #[cfg(not(target_os = "linux"))]
    let _ = file;
}

/// Flushes every file system holding `path` to disk (`syncfs`).
///
/// # Errors
/// When `path` cannot be opened, or the system refuses to sync.
pub(crate) fn sync_file_system(path: &Path) -> Result<(), StoreError> {
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
