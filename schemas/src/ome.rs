//! OME-Zarr image metadata as Rust types: `multiscales` (axes, datasets, coordinate
//! transformations), `omero` (channel labels, colours, display windows) and our region
//! metadata, for OME-Zarr 0.5 (Zarr v3, under `attributes.ome`) and 0.4 (Zarr v2, at the top of
//! `.zattrs`).
//!
//! `ingest` writes these types, and `ingest index`, `brickserver` and `viewer` read them, also
//! from stores other tools wrote. Reading is as lenient as the specification allows: axes
//! given as bare names (OME-NGFF 0.3), transformations we do not use, and a malformed `omero`
//! block (display hints only) are accepted; what the pyramid needs is checked, and a problem is
//! reported with the document it came from.
//!
//! The zarrs organisation's `ome_zarr_metadata` crate models the same specification; we keep
//! our own types because its `omero` channels require `color` and `window` (many stores lack
//! them), it writes fields in another order than the stores we have always written (which must
//! stay byte-identical), and it does not carry our region metadata.

use serde::de::{DeserializeOwned, Deserializer};
use serde::{Deserialize, Serialize};

use crate::{REGIONS_KEY, RegionMetadata};

/// The OME-Zarr version of an image, which fixes its Zarr version.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum OmeZarrVersion {
    /// OME-Zarr 0.4 (and the older 0.1–0.3) on Zarr v2: `.zgroup`, `.zattrs`, `.zarray`.
    #[serde(rename = "0.4")]
    V04,
    /// OME-Zarr 0.5 on Zarr v3: `zarr.json`, with the OME block under `attributes.ome`.
    #[serde(rename = "0.5")]
    V05,
}

impl OmeZarrVersion {
    /// The version string (`"0.4"` or `"0.5"`).
    #[must_use]
    pub fn as_str(self) -> &'static str {
        match self {
            Self::V04 => "0.4",
            Self::V05 => "0.5",
        }
    }

    /// The Zarr format this OME-Zarr version lives on.
    #[must_use]
    pub fn zarr_format(self) -> ZarrFormat {
        match self {
            Self::V04 => ZarrFormat::V2,
            Self::V05 => ZarrFormat::V3,
        }
    }
}

/// The Zarr format of a store.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ZarrFormat {
    /// Zarr v2: `.zgroup` + `.zattrs` for groups, `.zarray` for arrays.
    V2,
    /// Zarr v3: `zarr.json` for groups and arrays.
    V3,
}

impl ZarrFormat {
    /// Key of a group's attributes document, relative to the group.
    #[must_use]
    pub fn group_key(self) -> &'static str {
        match self {
            Self::V2 => ".zattrs",
            Self::V3 => "zarr.json",
        }
    }

    /// Key of an array's metadata document, relative to the array.
    #[must_use]
    pub fn array_key(self) -> &'static str {
        match self {
            Self::V2 => ".zarray",
            Self::V3 => "zarr.json",
        }
    }
}

/// A problem with a store's OME-Zarr metadata. Every message starts with the document it is
/// about.
#[derive(Debug, thiserror::Error)]
pub enum OmeError {
    /// The document is not JSON of the expected shape.
    #[error("{source_name}: not valid JSON")]
    NotJson {
        /// The document.
        source_name: String,
        /// What the parser said.
        #[source]
        source: serde_json::Error,
    },
    /// A Zarr v3 document that is not a group.
    #[error("{source_name}: not a Zarr group (node_type {node_type})")]
    NotAGroup {
        /// The document.
        source_name: String,
        /// What `node_type` says, as JSON.
        node_type: String,
    },
    /// No (or an empty) `multiscales` list.
    #[error("{source_name}: no OME-Zarr multiscales metadata")]
    NoMultiscales {
        /// The document.
        source_name: String,
    },
    /// `multiscales` is there but not of the specification's shape.
    #[error("{source_name}: malformed multiscales metadata: {source}")]
    BadMultiscales {
        /// The document.
        source_name: String,
        /// What the parser said.
        #[source]
        source: serde_json::Error,
    },
    /// The axes do not end in `z, y, x`.
    #[error("{source_name}: axes {names:?} do not end in z, y, x")]
    AxesNotZyx {
        /// The document.
        source_name: String,
        /// The axis names, in array order.
        names: Vec<String>,
    },
    /// A multiscale without datasets.
    #[error("{source_name}: multiscales has no datasets")]
    NoDatasets {
        /// The document.
        source_name: String,
    },
    /// A dataset without a `scale` transformation.
    #[error("{source_name}: dataset '{path}' has no scale transformation")]
    NoScale {
        /// The document.
        source_name: String,
        /// The dataset's path.
        path: String,
    },
    /// A `scale` whose length differs from the number of axes.
    #[error("{source_name}: dataset '{path}' has a scale of {entries} entries for {axes} axes")]
    ScaleLength {
        /// The document.
        source_name: String,
        /// The dataset's path.
        path: String,
        /// Entries in its scale.
        entries: usize,
        /// Axes of the multiscale.
        axes: usize,
    },
    /// A `scale` that is zero, negative or not finite along `z, y, x`.
    #[error("{source_name}: dataset '{path}' has a non-positive scale {scale:?}")]
    BadScale {
        /// The document.
        source_name: String,
        /// The dataset's path.
        path: String,
        /// Its `z, y, x` scale.
        scale: [f64; 3],
    },
    /// The region metadata is there but malformed.
    #[error("{source_name}: malformed '{REGIONS_KEY}' region metadata: {source}")]
    BadRegions {
        /// The document.
        source_name: String,
        /// What the parser said.
        #[source]
        source: serde_json::Error,
    },
}

/// One axis of a multiscale image.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Axis {
    /// Name: `c`, `z`, `y`, `x`, `t`, ...
    pub name: String,
    /// Kind: `space`, `channel`, `time`, or another the writer chose.
    #[serde(rename = "type", skip_serializing_if = "Option::is_none")]
    pub kind: Option<String>,
    /// Physical unit (UDUNITS-2 name, such as `micrometer`), for space and time axes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
}

impl<'de> Deserialize<'de> for Axis {
    /// An axis object, or (OME-NGFF 0.3) a bare axis name.
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        struct Named {
            name: String,
            #[serde(rename = "type")]
            kind: Option<String>,
            unit: Option<String>,
        }
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Either {
            Named(Named),
            Bare(String),
        }
        Ok(match Either::deserialize(d)? {
            Either::Named(a) => Self {
                name: a.name,
                kind: a.kind,
                unit: a.unit,
            },
            Either::Bare(name) => Self {
                name,
                kind: None,
                unit: None,
            },
        })
    }
}

/// A coordinate transformation of a dataset (or of a whole multiscale).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type")]
pub enum CoordinateTransformation {
    /// Physical size of a voxel along every axis.
    #[serde(rename = "scale")]
    Scale {
        /// One entry per axis.
        scale: Vec<f64>,
    },
    /// Physical position of the first voxel's centre along every axis.
    #[serde(rename = "translation")]
    Translation {
        /// One entry per axis.
        translation: Vec<f64>,
    },
    /// Any other transformation (`identity`, or values given by `path`): not used by us.
    #[serde(other)]
    Other,
}

/// One resolution level of a multiscale image.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Dataset {
    /// Path of the level's array, relative to the image group.
    pub path: String,
    /// Its transformations: a `scale`, then optionally a `translation`.
    #[serde(rename = "coordinateTransformations", default)]
    pub coordinate_transformations: Vec<CoordinateTransformation>,
}

impl Dataset {
    /// The `scale` transformation's values, if the dataset has one.
    #[must_use]
    pub fn scale(&self) -> Option<&[f64]> {
        self.coordinate_transformations
            .iter()
            .find_map(|t| match t {
                CoordinateTransformation::Scale { scale } => Some(scale.as_slice()),
                _ => None,
            })
    }
}

/// How the levels of a multiscale were made (the free-form `metadata` of a multiscale, with
/// the fields we write).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DownsamplingMethod {
    /// What a coarser voxel holds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// The program that made the levels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub method: Option<String>,
    /// Its version.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub version: Option<String>,
}

/// One multiscale image: axes and levels, finest first.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Multiscale {
    /// Image name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Axes, in array order.
    pub axes: Vec<Axis>,
    /// Levels, finest first.
    pub datasets: Vec<Dataset>,
    /// Downsampling kind (`mean`, `gaussian`, ...).
    #[serde(rename = "type", default, skip_serializing_if = "Option::is_none")]
    pub kind: Option<String>,
    /// How the levels were made.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "lenient"
    )]
    pub metadata: Option<DownsamplingMethod>,
    /// OME-Zarr version, written here by 0.4 (0.5 writes it in the `ome` block).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub version: Option<String>,
}

/// An `omero` channel's display window.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct OmeroWindow {
    /// Smallest value of the channel.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    /// Largest value of the channel.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max: Option<f64>,
    /// Value shown black.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start: Option<f64>,
    /// Value shown at full colour.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub end: Option<f64>,
}

/// One channel of the `omero` block.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct OmeroChannel {
    /// Channel label.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub label: Option<String>,
    /// Colour as `RRGGBB` hex (sRGB).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub color: Option<String>,
    /// Display window.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub window: Option<OmeroWindow>,
    /// Whether the channel is shown.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub active: Option<bool>,
    /// Display coefficient.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coefficient: Option<f64>,
    /// Display mapping family (`linear`, ...).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub family: Option<String>,
    /// Whether the colour map is inverted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inverted: Option<bool>,
}

/// Default rendering settings of the `omero` block.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct OmeroRenderingDefaults {
    /// Colour model (`color` or `greyscale`).
    pub model: String,
    /// Plane shown first.
    #[serde(rename = "defaultZ")]
    pub default_z: u64,
    /// Time point shown first.
    #[serde(rename = "defaultT")]
    pub default_t: u64,
}

/// The `omero` block: display hints per channel.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Omero {
    /// One entry per channel (possibly fewer than the image has).
    #[serde(default)]
    pub channels: Vec<OmeroChannel>,
    /// Default rendering settings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rdefs: Option<OmeroRenderingDefaults>,
}

/// The attributes of an OME-Zarr image group, whatever the version: OME metadata and, when the
/// store has it, our region metadata.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageAttributes {
    /// OME-Zarr version the attributes follow.
    pub version: OmeZarrVersion,
    /// The multiscale images (at least one).
    pub multiscales: Vec<Multiscale>,
    /// Display hints; `None` when absent or malformed (they are hints only).
    pub omero: Option<Omero>,
    /// Region metadata, under [`REGIONS_KEY`].
    pub regions: Option<RegionMetadata>,
}

/// The `ome` block of OME-Zarr 0.5 attributes, as written.
#[derive(Serialize)]
struct OmeBlockOut<'a> {
    version: &'static str,
    multiscales: &'a [Multiscale],
    #[serde(skip_serializing_if = "Option::is_none")]
    omero: Option<&'a Omero>,
}

/// OME-Zarr 0.5 attributes, as written.
#[derive(Serialize)]
struct AttributesV05Out<'a> {
    ome: OmeBlockOut<'a>,
    #[serde(rename = "residency", skip_serializing_if = "Option::is_none")]
    regions: Option<&'a RegionMetadata>,
}

/// OME-Zarr 0.4 attributes, as written.
#[derive(Serialize)]
struct AttributesV04Out<'a> {
    multiscales: &'a [Multiscale],
    #[serde(skip_serializing_if = "Option::is_none")]
    omero: Option<&'a Omero>,
    #[serde(rename = "residency", skip_serializing_if = "Option::is_none")]
    regions: Option<&'a RegionMetadata>,
}

impl Serialize for ImageAttributes {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self.version {
            OmeZarrVersion::V05 => AttributesV05Out {
                ome: OmeBlockOut {
                    version: "0.5",
                    multiscales: &self.multiscales,
                    omero: self.omero.as_ref(),
                },
                regions: self.regions.as_ref(),
            }
            .serialize(s),
            OmeZarrVersion::V04 => AttributesV04Out {
                multiscales: &self.multiscales,
                omero: self.omero.as_ref(),
                regions: self.regions.as_ref(),
            }
            .serialize(s),
        }
    }
}

/// Deserializes `T`, or gives `None` when the value is not a valid `T`: for display hints and
/// free-form fields that must not make a store unreadable.
fn lenient<'de, D: Deserializer<'de>, T: DeserializeOwned>(d: D) -> Result<Option<T>, D::Error> {
    let value = serde_json::Value::deserialize(d)?;
    Ok(serde_json::from_value(value).ok())
}

/// A group's attributes as read: our keys typed, the OME block kept whole until its version is
/// known.
#[derive(Deserialize)]
struct AttributesIn {
    #[serde(default)]
    ome: Option<serde_json::Map<String, serde_json::Value>>,
    #[serde(default)]
    multiscales: Option<serde_json::Value>,
    #[serde(default)]
    omero: Option<serde_json::Value>,
    #[serde(rename = "residency", default)]
    regions: Option<serde_json::Value>,
}

/// A Zarr v3 group document's header.
#[derive(Deserialize)]
struct GroupDocumentIn {
    #[serde(default)]
    node_type: Option<serde_json::Value>,
    #[serde(default)]
    attributes: Option<serde_json::Value>,
}

impl ImageAttributes {
    /// Parses the image group's attributes from its metadata document: `zarr.json` (Zarr v3,
    /// attributes under `attributes`, the OME block under `ome`) or `.zattrs` (Zarr v2, the
    /// attributes themselves). A Zarr v3 group whose attributes keep `multiscales` at the top
    /// (written before OME-Zarr 0.5) is read too. `source` names the document in errors.
    ///
    /// # Errors
    /// [`OmeError`] when the document is not JSON, not a group, has no usable multiscale, or
    /// has malformed region metadata.
    pub fn parse(format: ZarrFormat, document: &[u8], source: &str) -> Result<Self, OmeError> {
        let named = |s: &str| s.to_string();
        let not_json = |e| OmeError::NotJson {
            source_name: named(source),
            source: e,
        };
        let attributes = match format {
            ZarrFormat::V3 => {
                let doc: GroupDocumentIn = serde_json::from_slice(document).map_err(not_json)?;
                let node_type = doc.node_type.unwrap_or(serde_json::Value::Null);
                if node_type != "group" {
                    return Err(OmeError::NotAGroup {
                        source_name: named(source),
                        node_type: node_type.to_string(),
                    });
                }
                doc.attributes
                    .unwrap_or(serde_json::Value::Object(serde_json::Map::new()))
            }
            ZarrFormat::V2 => serde_json::from_slice(document).map_err(not_json)?,
        };
        let attrs: AttributesIn = serde_json::from_value(attributes).map_err(not_json)?;
        // The OME keys: under `ome` (0.5), else at the top (0.4 and older).
        let (ome_version, multiscales, omero) = match attrs.ome {
            Some(mut ome) => (
                ome.remove("version"),
                ome.remove("multiscales"),
                ome.remove("omero"),
            ),
            None => (None, attrs.multiscales, attrs.omero),
        };
        let no_multiscales = || OmeError::NoMultiscales {
            source_name: named(source),
        };
        let multiscales: Vec<Multiscale> = match multiscales {
            None | Some(serde_json::Value::Null) => return Err(no_multiscales()),
            Some(m) => serde_json::from_value(m).map_err(|e| OmeError::BadMultiscales {
                source_name: named(source),
                source: e,
            })?,
        };
        if multiscales.is_empty() {
            return Err(no_multiscales());
        }
        let version = match (ome_version.as_ref().and_then(|v| v.as_str()), format) {
            (Some("0.5"), _) | (None, ZarrFormat::V3) => OmeZarrVersion::V05,
            _ => OmeZarrVersion::V04,
        };
        let omero = omero.and_then(|o| serde_json::from_value(o).ok());
        let regions = match attrs.regions {
            None | Some(serde_json::Value::Null) => None,
            Some(r) => Some(serde_json::from_value(r).map_err(|e| OmeError::BadRegions {
                source_name: named(source),
                source: e,
            })?),
        };
        Ok(Self {
            version,
            multiscales,
            omero,
            regions,
        })
    }

    /// The first multiscale image, the one Residency reads.
    #[must_use]
    pub fn image(&self) -> &Multiscale {
        &self.multiscales[0]
    }
}

/// The pyramid a multiscale describes, checked: which axis is which, and each level's path and
/// `z, y, x` scale.
#[derive(Clone, Debug, PartialEq)]
pub struct PyramidLayout {
    /// Axis names, in array order; the last three are `z, y, x`.
    pub axis_names: Vec<String>,
    /// Index of the `c` axis among the leading ones, if any.
    pub channel_axis: Option<usize>,
    /// Level paths, finest first.
    pub level_paths: Vec<String>,
    /// Voxel size of each level, `z, y, x`, in the axes' units.
    pub level_scales: Vec<[f64; 3]>,
    /// The `x` axis's unit (`micrometer`, ...), when the metadata names one: the unit of
    /// every scale, since writers give the spatial axes one unit.
    pub unit: Option<String>,
}

impl PyramidLayout {
    /// Checks a multiscale: its axes end in `z, y, x` (at most one `c` axis before them), it
    /// has datasets, and each dataset has a positive finite `scale` of one entry per axis.
    /// `source` names the document in errors.
    ///
    /// # Errors
    /// [`OmeError`] naming the first problem.
    pub fn of(multiscale: &Multiscale, source: &str) -> Result<Self, OmeError> {
        let named = |s: &str| s.to_string();
        let names: Vec<String> = multiscale.axes.iter().map(|a| a.name.clone()).collect();
        let n = names.len();
        if n < 3 || names[n - 3..] != ["z", "y", "x"] {
            return Err(OmeError::AxesNotZyx {
                source_name: named(source),
                names,
            });
        }
        let channel_axis = names[..n - 3].iter().position(|a| a == "c");
        if multiscale.datasets.is_empty() {
            return Err(OmeError::NoDatasets {
                source_name: named(source),
            });
        }
        let mut level_paths = Vec::new();
        let mut level_scales = Vec::new();
        for ds in &multiscale.datasets {
            let scale = ds.scale().ok_or_else(|| OmeError::NoScale {
                source_name: named(source),
                path: ds.path.clone(),
            })?;
            if scale.len() != n {
                return Err(OmeError::ScaleLength {
                    source_name: named(source),
                    path: ds.path.clone(),
                    entries: scale.len(),
                    axes: n,
                });
            }
            let zyx = [scale[n - 3], scale[n - 2], scale[n - 1]];
            if !zyx.iter().all(|s| s.is_finite() && *s > 0.0) {
                return Err(OmeError::BadScale {
                    source_name: named(source),
                    path: ds.path.clone(),
                    scale: zyx,
                });
            }
            level_paths.push(ds.path.clone());
            level_scales.push(zyx);
        }
        Ok(Self {
            axis_names: names,
            channel_axis,
            level_paths,
            level_scales,
            unit: multiscale.axes[n - 1].unit.clone(),
        })
    }

    /// The chunk (or inner chunk) indices of brick `brick` (`z, y, x`) of channel `channel`:
    /// the channel on the `c` axis, 0 on any other leading axis.
    #[must_use]
    pub fn chunk_indices(&self, channel: u64, brick: [u64; 3]) -> Vec<u64> {
        let n = self.axis_names.len();
        let mut idx = vec![0; n];
        if let Some(c) = self.channel_axis {
            idx[c] = channel;
        }
        idx[n - 3..].copy_from_slice(&brick);
        idx
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A two-level OME-Zarr 0.4 image group of two channels (one named in `omero`), also the
    /// fixture of `volume::from_ome`'s tests.
    pub(crate) const GROUP_V2: &str = r#"{
        "multiscales": [{"version": "0.4", "axes": [
            {"name": "c", "type": "channel"}, {"name": "z", "type": "space"},
            {"name": "y", "type": "space"}, {"name": "x", "type": "space", "unit": "micrometer"}],
          "datasets": [
            {"path": "0", "coordinateTransformations": [{"type": "scale", "scale": [1, 2.0, 0.5, 0.5]}]},
            {"path": "1", "coordinateTransformations": [{"type": "scale", "scale": [1, 2.0, 1.0, 1.0]},
                                                        {"type": "translation", "translation": [0, 0, 0.25, 0.25]}]}]}],
        "omero": {"channels": [{"label": "dapi", "color": "FF8000",
                                "window": {"min": 0, "max": 100, "start": 5, "end": 90}}]}
    }"#;

    #[test]
    fn v2_attributes_give_the_pyramid() {
        let a = ImageAttributes::parse(ZarrFormat::V2, GROUP_V2.as_bytes(), "s/.zattrs").unwrap();
        assert_eq!(a.version, OmeZarrVersion::V04);
        assert_eq!(a.regions, None);
        let p = PyramidLayout::of(a.image(), "s/.zattrs").unwrap();
        assert_eq!(p.channel_axis, Some(0));
        assert_eq!(p.level_paths, ["0", "1"]);
        assert_eq!(p.level_scales, [[2.0, 0.5, 0.5], [2.0, 1.0, 1.0]]);
        assert_eq!(p.unit.as_deref(), Some("micrometer"));
        assert_eq!(p.chunk_indices(1, [2, 3, 4]), [1, 2, 3, 4]);
        let omero = a.omero.unwrap();
        assert_eq!(omero.channels[0].label.as_deref(), Some("dapi"));
        assert_eq!(
            omero.channels[0].window,
            Some(OmeroWindow {
                min: Some(0.0),
                max: Some(100.0),
                start: Some(5.0),
                end: Some(90.0)
            })
        );
    }

    #[test]
    fn v3_groups_bare_axes_and_odd_omero_are_read() {
        let doc = r#"{"zarr_format": 3, "node_type": "group", "attributes": {"ome": {
            "version": "0.5", "multiscales": [{"axes": ["z", "y", "x"],
            "datasets": [{"path": "s0", "coordinateTransformations": [{"type": "identity"},
                {"type": "scale", "scale": [1, 1, 1]}]}]}],
            "omero": {"channels": [{"color": 7}]}}}}"#;
        let a = ImageAttributes::parse(ZarrFormat::V3, doc.as_bytes(), "g").unwrap();
        assert_eq!(a.version, OmeZarrVersion::V05);
        assert_eq!(a.omero, None);
        let p = PyramidLayout::of(a.image(), "g").unwrap();
        assert_eq!(
            (p.channel_axis, p.level_paths),
            (None, vec!["s0".to_string()])
        );
    }

    #[test]
    fn bad_metadata_gives_errors_naming_the_document() {
        let e = ImageAttributes::parse(ZarrFormat::V2, b"{}", "http://h/d/.zattrs").unwrap_err();
        assert_eq!(
            e.to_string(),
            "http://h/d/.zattrs: no OME-Zarr multiscales metadata"
        );
        let e = ImageAttributes::parse(ZarrFormat::V3, b"{", "d/zarr.json").unwrap_err();
        assert_eq!(e.to_string(), "d/zarr.json: not valid JSON");
        let e = ImageAttributes::parse(
            ZarrFormat::V3,
            br#"{"zarr_format": 3, "node_type": "array"}"#,
            "d/zarr.json",
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            r#"d/zarr.json: not a Zarr group (node_type "array")"#
        );
        let bad_axes = GROUP_V2.replace(r#""name": "x""#, r#""name": "w""#);
        let a = ImageAttributes::parse(ZarrFormat::V2, bad_axes.as_bytes(), "g").unwrap();
        assert_eq!(
            PyramidLayout::of(a.image(), "g").unwrap_err().to_string(),
            r#"g: axes ["c", "z", "y", "w"] do not end in z, y, x"#
        );
        let no_scale = GROUP_V2.replace(
            r#""type": "scale", "scale": [1, 2.0, 0.5, 0.5]"#,
            r#""type": "identity""#,
        );
        let a = ImageAttributes::parse(ZarrFormat::V2, no_scale.as_bytes(), "g").unwrap();
        assert_eq!(
            PyramidLayout::of(a.image(), "g").unwrap_err().to_string(),
            "g: dataset '0' has no scale transformation"
        );
        let zero = GROUP_V2.replace("[1, 2.0, 0.5, 0.5]", "[1, 0, 0.5, 0.5]");
        let a = ImageAttributes::parse(ZarrFormat::V2, zero.as_bytes(), "g").unwrap();
        assert_eq!(
            PyramidLayout::of(a.image(), "g").unwrap_err().to_string(),
            "g: dataset '0' has a non-positive scale [0.0, 0.5, 0.5]"
        );
        let bad_regions = GROUP_V2.replacen('{', r#"{"residency": {"version": 1},"#, 1);
        let e = ImageAttributes::parse(ZarrFormat::V2, bad_regions.as_bytes(), "g").unwrap_err();
        assert!(
            e.to_string()
                .starts_with("g: malformed 'residency' region metadata: invalid type"),
            "{e}"
        );
        let cause = std::error::Error::source(&e).expect("the parser's error is kept");
        assert_eq!(
            e.to_string(),
            format!("g: malformed 'residency' region metadata: {cause}")
        );
    }

    #[test]
    fn attributes_write_in_the_order_of_each_version() {
        let a = ImageAttributes::parse(ZarrFormat::V2, GROUP_V2.as_bytes(), "g").unwrap();
        let v4 = serde_json::to_string(&a).unwrap();
        assert!(
            v4.starts_with(r#"{"multiscales":[{"axes":[{"name":"c","type":"channel"}"#),
            "{v4}"
        );
        let v5 = serde_json::to_string(&ImageAttributes {
            version: OmeZarrVersion::V05,
            ..a
        })
        .unwrap();
        assert!(
            v5.starts_with(r#"{"ome":{"version":"0.5","multiscales":[{"#),
            "{v5}"
        );
        assert!(
            v5.ends_with(r#""window":{"min":0.0,"max":100.0,"start":5.0,"end":90.0}}]}}}"#),
            "{v5}"
        );
    }
}
