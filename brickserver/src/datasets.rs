//! The datasets a server exposes, each under `/NAME/`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

/// One served store.
#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    /// URL name: the store is served under `/NAME/`.
    pub name: String,
    /// Canonical (symlink-free, absolute) root folder of the store.
    pub root: PathBuf,
}

/// The group attributes of the store at `root` (from `zarr.json` in Zarr v3, `.zattrs` in v2),
/// the OME block within them (`ome` in OME-Zarr 0.5, the attributes themselves in 0.4), and
/// the file they came from, for messages.
pub fn read_attributes(root: &Path) -> Result<(serde_json::Value, serde_json::Value, PathBuf)> {
    let (file, v3) = if root.join("zarr.json").is_file() {
        (root.join("zarr.json"), true)
    } else {
        (root.join(".zattrs"), false)
    };
    let text = std::fs::read(&file).with_context(|| format!("cannot read {}", file.display()))?;
    let doc: serde_json::Value = serde_json::from_slice(&text)
        .with_context(|| format!("{} is not valid JSON", file.display()))?;
    let attrs = if v3 { doc["attributes"].clone() } else { doc };
    let ome = if v3 {
        attrs["ome"].clone()
    } else {
        attrs.clone()
    };
    Ok((attrs, ome, file))
}

/// All served datasets, in the order given.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Datasets(pub Vec<Dataset>);

/// The default name of a store folder: its file name without `.ome.zarr` / `.zarr`.
pub fn default_name(path: &Path) -> String {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    name.trim_end_matches(".ome.zarr")
        .trim_end_matches(".zarr")
        .to_string()
}

fn valid_name(name: &str) -> bool {
    !name.is_empty()
        && !matches!(name, "datasets" | "healthz" | "metrics" | "openapi.json")
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
        && !name.starts_with('.')
}

impl Datasets {
    /// Builds the set from positional paths and `NAME=PATH` pairs, checking that every path is
    /// a folder and every name is unique and URL-safe.
    pub fn from_args(paths: &[PathBuf], named: &[String]) -> Result<Self> {
        let mut out = Vec::new();
        let mut add = |name: String, path: &Path| -> Result<()> {
            if !valid_name(&name) {
                bail!(
                    "{}: dataset name '{name}' is not usable in a URL (letters, digits, '-', '_', '.'; not a reserved path)",
                    path.display()
                );
            }
            let root = path
                .canonicalize()
                .with_context(|| format!("{}: cannot open dataset", path.display()))?;
            if !root.is_dir() {
                bail!(
                    "{}: a dataset must be a folder (an OME-Zarr store)",
                    path.display()
                );
            }
            if out.iter().any(|d: &Dataset| d.name == name) {
                bail!(
                    "{}: dataset name '{name}' is used twice (use --name NAME=PATH)",
                    path.display()
                );
            }
            out.push(Dataset { name, root });
            Ok(())
        };
        for p in paths {
            add(default_name(p), p)?;
        }
        for pair in named {
            let (name, path) = pair
                .split_once('=')
                .with_context(|| format!("--name {pair}: expected NAME=PATH"))?;
            add(name.to_string(), Path::new(path))?;
        }
        if out.is_empty() {
            bail!("no dataset given");
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
    fn names_default_to_the_folder_without_suffix() {
        assert_eq!(default_name(Path::new("/data/brain.ome.zarr")), "brain");
        assert_eq!(default_name(Path::new("scan.zarr")), "scan");
        assert!(!valid_name("datasets"));
        assert!(!valid_name("a/b"));
        assert!(!valid_name(".."));
        assert!(valid_name("brain-01_v2"));
    }
}
