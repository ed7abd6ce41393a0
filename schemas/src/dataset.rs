//! The dataset-name rule: how a store's folder becomes the name it is served and shown under.

use std::path::Path;

/// Folder suffixes dropped from a store's name, longest first.
pub const STORE_SUFFIXES: [&str; 2] = [".ome.zarr", ".zarr"];

/// The dataset name of a store at `path`: its folder name without `.ome.zarr` (or `.zarr`),
/// so `/data/brain.ome.zarr` is `brain`. A path without a final component (such as `/`) is
/// named by the whole path.
#[must_use]
pub fn dataset_name(path: &Path) -> String {
    let name = path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    STORE_SUFFIXES
        .iter()
        .find_map(|s| name.strip_suffix(s))
        .unwrap_or(&name)
        .to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_drop_one_store_suffix() {
        assert_eq!(dataset_name(Path::new("/data/brain.ome.zarr")), "brain");
        assert_eq!(dataset_name(Path::new("scan.zarr")), "scan");
        assert_eq!(dataset_name(Path::new("raw/volume")), "volume");
        assert_eq!(dataset_name(Path::new("a.zarr.zarr")), "a.zarr");
        assert_eq!(dataset_name(Path::new("sample.ome.zarr/")), "sample");
        assert_eq!(dataset_name(Path::new("/")), "/");
    }
}
