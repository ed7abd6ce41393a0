//! The datasets a server exposes, each under `/NAME/`.

use std::path::Path;

use residency_schemas::dataset::dataset_name;
use residency_store::location::{LocationError, ObjectStoreAt, ObjectStoreOptions, StoreLocation};

/// One served store.
#[derive(Clone, Debug)]
pub struct Dataset {
    /// URL name: the store is served under `/NAME/`.
    pub name: String,
    /// Where the store is: a canonical (symlink-free, absolute) root folder, or an object-store
    /// prefix.
    pub location: StoreLocation,
    /// The client of an object-store location, made once when the store was checked for and
    /// then used for every read (`None` for a folder).
    pub object_store: Option<ObjectStoreAt>,
}

/// All served datasets, in the order given.
#[derive(Clone, Debug, Default)]
pub struct Datasets(pub Vec<Dataset>);

fn valid_name(name: &str) -> bool {
    !name.is_empty()
        && !matches!(
            name,
            "datasets" | "healthz" | "metrics" | "openapi.json" | "viewer"
        )
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
        && !name.starts_with('.')
}

/// Why the datasets given on the command line cannot be served.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// A name that cannot be used in a URL.
    #[error(
        "{path}: dataset name '{name}' is not usable in a URL (letters, digits, '-', '_', '.'; not a reserved path)"
    )]
    BadName {
        /// The store.
        path: String,
        /// The name.
        name: String,
    },
    /// The store's folder cannot be opened.
    #[error("{path}: cannot open dataset: {source}")]
    CannotOpen {
        /// The store.
        path: String,
        /// What the file system said.
        source: std::io::Error,
    },
    /// The store is a file, not a folder.
    #[error("{path}: a dataset must be a folder (an OME-Zarr store)")]
    NotAFolder {
        /// The store.
        path: String,
    },
    /// Two datasets with one name.
    #[error("{path}: dataset name '{name}' is used twice (use --name NAME=LOCATION)")]
    Duplicate {
        /// The second store of that name.
        path: String,
        /// The name.
        name: String,
    },
    /// A `--name` argument without `=`.
    #[error("--name {pair}: expected NAME=LOCATION")]
    BadPair {
        /// The argument.
        pair: String,
    },
    /// Nothing to serve.
    #[error("no dataset given")]
    NoDataset,
    /// An object-store location with no store there (no root metadata).
    #[error("{location}: no store there (none of zarr.json, .zgroup, .zattrs at its root)")]
    NoStore {
        /// The location.
        location: String,
    },
    /// A location that cannot be parsed, or an object store that cannot be asked.
    #[error(transparent)]
    Location(#[from] LocationError),
}

impl Datasets {
    /// Builds the set from positional locations (named by [`dataset_name`] of their last
    /// component) and `NAME=LOCATION` pairs, checking that every folder is a folder, that a
    /// store is at every object-store location (asked on the caller's runtime), and that every
    /// name is unique and URL-safe.
    ///
    /// # Errors
    /// [`DatasetError`] naming the first location or argument at fault.
    pub async fn from_args(
        locations: &[StoreLocation],
        named: &[String],
        options: &ObjectStoreOptions,
    ) -> Result<Self, DatasetError> {
        let mut out: Vec<Dataset> = Vec::new();
        // Positional locations, then `NAME=LOCATION` pairs, each checked in turn (a pair is
        // parsed when its turn comes, so the first argument at fault is the one named).
        let positional = locations
            .iter()
            .map(|l| Ok((dataset_name(Path::new(&l.file_name())), l.clone())));
        let pairs = named.iter().map(|pair| -> Result<_, DatasetError> {
            let (name, location) = pair
                .split_once('=')
                .ok_or_else(|| DatasetError::BadPair { pair: pair.clone() })?;
            Ok((name.to_string(), location.parse::<StoreLocation>()?))
        });
        for entry in positional.chain(pairs) {
            let (name, location) = entry?;
            let shown = location.to_string();
            if !valid_name(&name) {
                return Err(DatasetError::BadName { path: shown, name });
            }
            let (location, object_store) = if let Some(path) = location.folder() {
                let root = path
                    .canonicalize()
                    .map_err(|source| DatasetError::CannotOpen {
                        path: shown.clone(),
                        source,
                    })?;
                if !root.is_dir() {
                    return Err(DatasetError::NotAFolder { path: shown });
                }
                (StoreLocation::Folder(root), None)
            } else {
                let at = location
                    .object_store(options)?
                    .expect("a location is a folder or an object store");
                if !location.exists_in(&at).await? {
                    return Err(DatasetError::NoStore { location: shown });
                }
                (location, Some(at))
            };
            if out.iter().any(|d| d.name == name) {
                return Err(DatasetError::Duplicate { path: shown, name });
            }
            out.push(Dataset {
                name,
                location,
                object_store,
            });
        }
        if out.is_empty() {
            return Err(DatasetError::NoDataset);
        }
        Ok(Self(out))
    }

    /// The dataset called `name`.
    pub fn get(&self, name: &str) -> Option<&Dataset> {
        self.0.iter().find(|d| d.name == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_url_safe_and_not_reserved() {
        assert!(!valid_name("datasets"));
        assert!(!valid_name("viewer"));
        assert!(!valid_name("a/b"));
        assert!(!valid_name(".."));
        assert!(valid_name("brain-01_v2"));
    }
}
