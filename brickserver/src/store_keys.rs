//! Mapping a request path to a file inside a dataset, refusing anything that could reach
//! outside it: `..` in any spelling, backslashes, absolute paths, NUL bytes, and symlinks
//! that lead out of the dataset.

use std::path::{Path, PathBuf};

use percent_encoding::percent_decode_str;

/// Why a key was refused or not found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum KeyError {
    /// The key is malformed or tries to leave the dataset (answered 400).
    Refused(&'static str),
    /// No such key in the dataset (answered 404).
    NotFound,
    /// The key exists but cannot be read (a symlink loop, no permission, an I/O error):
    /// answered 500, naming the key.
    Unreadable(String),
}

/// Resolves the raw (still percent-encoded) key part of a request path against `root`
/// (canonical), returning the canonical path of an existing regular file inside `root`.
pub fn resolve(root: &Path, raw_key: &str) -> Result<PathBuf, KeyError> {
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
    let joined = root.join(&*key);
    let real = joined.canonicalize().map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound | std::io::ErrorKind::NotADirectory => KeyError::NotFound,
        _ => KeyError::Unreadable(e.to_string()),
    })?;
    if !real.starts_with(root) {
        return Err(KeyError::Refused("key leads outside the dataset"));
    }
    if !real.is_file() {
        return Err(KeyError::NotFound);
    }
    Ok(real)
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
        assert_eq!(resolve(&dir, "no-such-key-here"), Err(KeyError::NotFound));
    }

    #[test]
    fn a_symlink_loop_is_unreadable_not_missing() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().canonicalize().unwrap();
        std::os::unix::fs::symlink("loop", root.join("loop")).unwrap();
        assert!(matches!(
            resolve(&root, "loop"),
            Err(KeyError::Unreadable(e)) if e.contains("symbolic links")
        ));
    }
}
