//! Mapping a request path to a file inside a dataset, refusing anything that could reach
//! outside it: `..` in any spelling, backslashes, absolute paths, NUL bytes, and symlinks
//! that lead out of the dataset.

use std::fs::{File, Metadata};
use std::io;
use std::os::fd::{AsRawFd, FromRawFd};
use std::path::{Path, PathBuf};

use percent_encoding::percent_decode_str;

/// Why a key was refused or not found.
#[derive(Debug, thiserror::Error)]
pub enum KeyError {
    /// The key is malformed or tries to leave the dataset (answered 400).
    #[error("refused: {0}")]
    Refused(&'static str),
    /// No such key in the dataset (answered 404).
    #[error("no such key")]
    NotFound,
    /// The key exists but cannot be read (a symlink loop, no permission, an I/O error):
    /// answered 500, naming the key.
    #[error(transparent)]
    Unreadable(Box<dyn std::error::Error + Send + Sync>),
}

pub use residency_store::failure::StoreFailure;

/// Decodes a raw (still percent-encoded) key and refuses any spelling that could leave the
/// dataset: `..` and `.` segments, empty segments, backslashes, absolute paths, NUL bytes.
///
/// # Errors
/// [`KeyError::Refused`] naming the refused spelling, [`KeyError::NotFound`] for no key.
pub(crate) fn checked_key(raw_key: &str) -> Result<String, KeyError> {
    if raw_key.is_empty() {
        return Err(KeyError::NotFound);
    }
    let key = percent_decode_str(raw_key)
        .decode_utf8()
        .map_err(|_| KeyError::Refused("key is not UTF-8"))?;
    if key.contains('\0') {
        return Err(KeyError::Refused("NUL byte in key"));
    }
    if key.contains('\\') {
        return Err(KeyError::Refused("backslash in key"));
    }
    if key.starts_with('/') {
        return Err(KeyError::Refused("absolute key"));
    }
    for part in key.split('/') {
        match part {
            "" => return Err(KeyError::Refused("empty path segment")),
            "." | ".." => return Err(KeyError::Refused("relative path segment")),
            _ => {}
        }
    }
    Ok(key.into_owned())
}

/// Resolves the raw (still percent-encoded) key part of a request path against `root`
/// (canonical), returning the canonical path of an existing regular file inside `root`.
///
/// # Errors
/// [`KeyError`] when the key is malformed, leaves the root, or names no readable file.
pub fn resolve(root: &Path, raw_key: &str) -> Result<PathBuf, KeyError> {
    let key = checked_key(raw_key)?;
    let joined = root.join(&key);
    let real = joined.canonicalize().map_err(|e| match e.kind() {
        // A name too long for the file system names no file either (found by fuzzing).
        io::ErrorKind::NotFound | io::ErrorKind::NotADirectory | io::ErrorKind::InvalidFilename => {
            KeyError::NotFound
        }
        _ => KeyError::Unreadable(e.into()),
    })?;
    if !real.starts_with(root) {
        return Err(KeyError::Refused("key leads outside the dataset"));
    }
    if !real.is_file() {
        return Err(KeyError::NotFound);
    }
    Ok(real)
}

/// A dataset's root folder, held open so that keys are opened beneath it in one system call.
#[derive(Debug)]
pub struct RootDir {
    path: PathBuf,
    dir: File,
    /// The folder held open: its device and inode numbers.
    identity: (u64, u64),
}

impl RootDir {
    /// Opens the (canonical) root folder `path`.
    ///
    /// # Errors
    /// When the folder cannot be opened.
    pub fn open(path: &Path) -> io::Result<Self> {
        use std::os::unix::fs::MetadataExt;
        let dir = File::open(path)?;
        let meta = dir.metadata()?;
        Ok(Self {
            path: path.to_path_buf(),
            dir,
            identity: (meta.dev(), meta.ino()),
        })
    }

    /// The folder held open: its device and inode numbers.
    pub fn identity(&self) -> (u64, u64) {
        self.identity
    }

    /// Whether another folder now has the root folder's path (a store replaced whole, renamed
    /// over the one held open). A path that names nothing, for now, is not a replacement: a
    /// swap of folders may be half done.
    pub fn replaced(&self) -> bool {
        use std::os::unix::fs::MetadataExt;
        std::fs::metadata(&self.path).is_ok_and(|meta| (meta.dev(), meta.ino()) != self.identity)
    }

    /// The root folder.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Opens the regular file at `raw_key` (still percent-encoded) beneath the root. The
    /// kernel refuses any resolution that leaves the root, through `..` or a symlink
    /// (`openat2` with `RESOLVE_BENEATH`); where `openat2` is unavailable the key is
    /// canonicalised and checked instead.
    ///
    /// # Errors
    /// [`KeyError`] when the key is malformed, leaves the root, or names no readable file.
    pub fn open_key(&self, raw_key: &str) -> Result<(File, Metadata), KeyError> {
        let key = checked_key(raw_key)?;
        let unreadable = |e: io::Error| KeyError::Unreadable(e.into());
        let file = match self.openat2(&key) {
            Ok(f) => f,
            Err(e) => match e.raw_os_error() {
                // A name too long for the file system names no file either (found by fuzzing).
                Some(libc::ENOENT | libc::ENOTDIR | libc::ENAMETOOLONG) => {
                    return Err(KeyError::NotFound);
                }
                Some(libc::EXDEV) => {
                    return Err(KeyError::Refused("key leads outside the dataset"));
                }
                Some(libc::ENOSYS | libc::EPERM) => {
                    File::open(resolve(&self.path, raw_key)?).map_err(unreadable)?
                }
                _ => return Err(unreadable(e)),
            },
        };
        let meta = file.metadata().map_err(unreadable)?;
        if !meta.is_file() {
            return Err(KeyError::NotFound);
        }
        Ok((file, meta))
    }

    fn openat2(&self, key: &str) -> io::Result<File> {
        let path = std::ffi::CString::new(key).map_err(|_| io::ErrorKind::InvalidInput)?;
        // SAFETY: open_how is plain data; zero is a valid value for every field.
        let mut how: libc::open_how = unsafe { std::mem::zeroed() };
        how.flags = (libc::O_RDONLY | libc::O_CLOEXEC) as u64;
        how.resolve = libc::RESOLVE_BENEATH | libc::RESOLVE_NO_MAGICLINKS;
        // SAFETY: valid directory descriptor, NUL-terminated path and a correctly sized struct.
        let fd = unsafe {
            libc::syscall(
                libc::SYS_openat2,
                self.dir.as_raw_fd(),
                path.as_ptr(),
                &raw const how,
                size_of::<libc::open_how>(),
            )
        };
        if fd < 0 {
            return Err(io::Error::last_os_error());
        }
        // SAFETY: the kernel just returned this descriptor, owned by nobody else.
        Ok(unsafe { File::from_raw_fd(fd as i32) })
    }
}

/// Reads as much of `file` as the page cache holds, without waiting for the disk
/// (`preadv2` with `RWF_NOWAIT`). Returns the bytes and whether they are the whole file.
pub(crate) fn read_cached(file: &File, len: usize) -> (Vec<u8>, bool) {
    let mut buf: Vec<u8> = Vec::with_capacity(len);
    while buf.len() < len {
        let want = len - buf.len();
        let rest = &mut buf.spare_capacity_mut()[..want];
        let iov = libc::iovec {
            iov_base: rest.as_mut_ptr().cast(),
            iov_len: rest.len(),
        };
        // SAFETY: the iovec points into the vector's spare capacity, which the kernel fills.
        let n = unsafe {
            libc::preadv2(
                file.as_raw_fd(),
                &raw const iov,
                1,
                buf.len() as libc::off_t,
                libc::RWF_NOWAIT,
            )
        };
        if n <= 0 {
            break;
        }
        // SAFETY: the kernel initialised `n` more bytes.
        unsafe { buf.set_len(buf.len() + n as usize) };
    }
    let whole = buf.len() == len;
    (buf, whole)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn traversal_in_any_spelling_is_refused() {
        let dir = std::env::temp_dir().canonicalize().unwrap();
        for key in [
            "..",
            "../etc/passwd",
            "%2e%2e/x",
            "%2E%2E%2Fx",
            "a/../../x",
            "a\\..\\x",
            "a%5c..%5cx",
            "/etc/passwd",
            "%2fetc%2fpasswd",
            "a%00b",
            "a//b",
            "./a",
        ] {
            assert!(
                matches!(resolve(&dir, key), Err(KeyError::Refused(_))),
                "{key}"
            );
        }
        assert!(matches!(
            resolve(&dir, "no-such-key-here"),
            Err(KeyError::NotFound)
        ));
        // Fuzz target region_query: a segment longer than the file system's NAME_MAX was a
        // 500 ("File name too long"); it names no key, so it is a 404.
        let long = format!("m{}", "+D".repeat(200));
        assert!(matches!(resolve(&dir, &long), Err(KeyError::NotFound)));
        let root = RootDir::open(&dir).unwrap();
        assert!(matches!(root.open_key(&long), Err(KeyError::NotFound)));
    }

    #[test]
    fn keys_open_beneath_the_root_only() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().canonicalize().unwrap();
        std::fs::create_dir(root.join("a")).unwrap();
        std::fs::write(root.join("a/chunk"), b"12345").unwrap();
        std::os::unix::fs::symlink("/etc/passwd", root.join("escape")).unwrap();
        std::os::unix::fs::symlink("a/chunk", root.join("inside")).unwrap();
        let r = RootDir::open(&root).unwrap();
        let (f, meta) = r.open_key("a/chunk").unwrap();
        assert_eq!(meta.len(), 5);
        assert_eq!(read_cached(&f, 5), (b"12345".to_vec(), true));
        assert!(r.open_key("inside").is_ok());
        assert!(matches!(
            r.open_key("escape"),
            Err(KeyError::Refused("key leads outside the dataset"))
        ));
        assert!(matches!(r.open_key("a"), Err(KeyError::NotFound)));
        assert!(matches!(r.open_key("a/none"), Err(KeyError::NotFound)));
        assert!(matches!(r.open_key("a/chunk/x"), Err(KeyError::NotFound)));
        assert!(matches!(r.open_key("%2e%2e/x"), Err(KeyError::Refused(_))));
    }

    #[test]
    fn a_symlink_loop_is_unreadable_not_missing() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().canonicalize().unwrap();
        std::os::unix::fs::symlink("loop", root.join("loop")).unwrap();
        assert!(matches!(
            resolve(&root, "loop"),
            Err(KeyError::Unreadable(e)) if e.to_string().contains("symbolic links")
        ));
    }
}
