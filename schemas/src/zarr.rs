//! What Residency needs from a pyramid level's Zarr array metadata (`zarr.json` of Zarr v3 or
//! `.zarray` of Zarr v2), read through zarrs' typed metadata: shape, sample type, brick shape
//! (the inner chunk when sharded) and fill value.

use std::num::NonZeroU64;

use serde::Deserialize;
use zarrs_metadata::ConfigurationError;
use zarrs_metadata::v2::ArrayMetadataV2;
use zarrs_metadata::v3::{ArrayMetadataV3, FillValueMetadataV3};
use zarrs_metadata_ext::chunk_grid::regular::RegularChunkGridConfiguration;
use zarrs_metadata_ext::codec::sharding::ShardingCodecConfiguration;

use crate::SampleType;
use crate::ome::ZarrFormat;

/// Name of the Zarr v3 sharding codec.
pub const SHARDING_CODEC: &str = "sharding_indexed";

/// A problem with an array's metadata. Every message starts with the document it is about.
#[derive(Debug, thiserror::Error)]
pub enum ArrayMetadataError {
    /// Not JSON, or not of the Zarr specification's shape.
    #[error("{source_name}: not valid Zarr array metadata: {source}")]
    Malformed {
        /// The document.
        source_name: String,
        /// What the parser said.
        #[source]
        source: serde_json::Error,
    },
    /// A chunk grid's or the sharding codec's configuration that zarrs does not read.
    #[error("{source_name}: not valid Zarr array metadata: {source}")]
    BadConfiguration {
        /// The document.
        source_name: String,
        /// What zarrs said of the configuration (boxed: it holds the configuration).
        #[source]
        source: Box<ConfigurationError>,
    },
    /// A sharding codec configuration of a version zarrs does not know.
    #[error("{source_name}: not valid Zarr array metadata: unknown sharding configuration")]
    UnknownSharding {
        /// The document.
        source_name: String,
    },
    /// A Zarr v3 document that is not an array.
    #[error("{source_name}: not a Zarr array (node_type {node_type})")]
    NotAnArray {
        /// The document.
        source_name: String,
        /// What `node_type` says, as JSON.
        node_type: String,
    },
    /// A data type Residency does not store.
    #[error("{source_name}: unsupported data type '{data_type}'")]
    UnsupportedDataType {
        /// The document.
        source_name: String,
        /// The data type as written.
        data_type: String,
    },
    /// A chunk grid other than `regular`.
    #[error("{source_name}: unsupported chunk grid '{grid}' (only 'regular' is read)")]
    UnsupportedChunkGrid {
        /// The document.
        source_name: String,
        /// The grid's name.
        grid: String,
    },
    /// The chunk shape's dimensionality differs from the array's, or is below 3.
    #[error("{source_name}: chunk shape {chunk:?} does not match array shape {shape:?}")]
    ChunkMismatch {
        /// The document.
        source_name: String,
        /// The chunk (or inner chunk) shape.
        chunk: Vec<u64>,
        /// The array shape.
        shape: Vec<u64>,
    },
    /// A fill value that is not a number of the data type.
    #[error("{source_name}: unsupported fill value {fill_value}")]
    UnsupportedFillValue {
        /// The document.
        source_name: String,
        /// The fill value, as JSON.
        fill_value: String,
    },
}

/// What a renderer or server needs from one level's array metadata.
#[derive(Clone, Debug, PartialEq)]
pub struct ArrayDescription {
    /// Full array shape, in axis order.
    pub shape: Vec<u64>,
    /// Sample type.
    pub sample_type: SampleType,
    /// Brick shape on every axis: the inner chunk when sharded, the chunk otherwise.
    pub chunk: Vec<u64>,
    /// Whether the array is sharded (Zarr v3 `sharding_indexed`).
    pub sharded: bool,
    /// Fill value (0 when the metadata gives `null`).
    pub fill_value: f64,
}

/// The header of a Zarr v3 node document.
#[derive(Deserialize)]
struct NodeType {
    #[serde(default)]
    node_type: Option<serde_json::Value>,
}

impl ArrayDescription {
    /// Parses one level's array metadata document. `source` names it in errors.
    ///
    /// # Errors
    /// [`ArrayMetadataError`] when the document is not Zarr array metadata of the given
    /// format, or uses a data type, chunk grid or fill value Residency does not read.
    pub fn parse(
        format: ZarrFormat,
        document: &[u8],
        source: &str,
    ) -> Result<Self, ArrayMetadataError> {
        let named = || source.to_string();
        let malformed = |source| ArrayMetadataError::Malformed {
            source_name: named(),
            source,
        };
        let description = match format {
            ZarrFormat::V3 => {
                let header: NodeType = serde_json::from_slice(document).map_err(malformed)?;
                let node_type = header.node_type.unwrap_or(serde_json::Value::Null);
                if node_type != "array" {
                    return Err(ArrayMetadataError::NotAnArray {
                        source_name: named(),
                        node_type: node_type.to_string(),
                    });
                }
                let meta: ArrayMetadataV3 = serde_json::from_slice(document).map_err(malformed)?;
                Self::of_v3(&meta, source)?
            }
            ZarrFormat::V2 => {
                let meta: ArrayMetadataV2 = serde_json::from_slice(document).map_err(malformed)?;
                Self::of_v2(&meta, source)?
            }
        };
        let n = description.shape.len();
        if n < 3 || description.chunk.len() != n {
            return Err(ArrayMetadataError::ChunkMismatch {
                source_name: named(),
                chunk: description.chunk,
                shape: description.shape,
            });
        }
        Ok(description)
    }

    fn of_v3(meta: &ArrayMetadataV3, source: &str) -> Result<Self, ArrayMetadataError> {
        let named = || source.to_string();
        let bad_configuration = |source| ArrayMetadataError::BadConfiguration {
            source_name: named(),
            source: Box::new(source),
        };
        let name = meta.data_type.name();
        let sample_type = SampleType::from_zarr_name(name).ok_or_else(|| {
            ArrayMetadataError::UnsupportedDataType {
                source_name: named(),
                data_type: name.to_string(),
            }
        })?;
        let sharding = meta.codecs.iter().find(|c| c.name() == SHARDING_CODEC);
        let (chunk, sharded): (Vec<NonZeroU64>, bool) = if let Some(s) = sharding {
            let ShardingCodecConfiguration::V1(c) = s
                .to_configuration::<ShardingCodecConfiguration>()
                .map_err(bad_configuration)?
            else {
                return Err(ArrayMetadataError::UnknownSharding {
                    source_name: named(),
                });
            };
            (c.chunk_shape, true)
        } else {
            if meta.chunk_grid.name() != "regular" {
                return Err(ArrayMetadataError::UnsupportedChunkGrid {
                    source_name: named(),
                    grid: meta.chunk_grid.name().to_string(),
                });
            }
            let c: RegularChunkGridConfiguration = meta
                .chunk_grid
                .to_configuration()
                .map_err(bad_configuration)?;
            (c.chunk_shape, false)
        };
        Ok(Self {
            shape: meta.shape.clone(),
            sample_type,
            chunk: chunk.iter().map(|c| c.get()).collect(),
            sharded,
            fill_value: fill_value(&meta.fill_value, source)?,
        })
    }

    fn of_v2(meta: &ArrayMetadataV2, source: &str) -> Result<Self, ArrayMetadataError> {
        let dtype = meta.dtype.to_string();
        let sample_type = SampleType::from_zarr_v2_dtype(&dtype).ok_or_else(|| {
            ArrayMetadataError::UnsupportedDataType {
                source_name: source.to_string(),
                data_type: dtype.clone(),
            }
        })?;
        Ok(Self {
            shape: meta.shape.clone(),
            sample_type,
            chunk: meta.chunks.iter().map(|c| c.get()).collect(),
            sharded: false,
            fill_value: fill_value(&meta.fill_value, source)?,
        })
    }

    /// Brick shape `z, y, x`.
    #[must_use]
    pub fn brick_shape(&self) -> [u64; 3] {
        let n = self.chunk.len();
        [self.chunk[n - 3], self.chunk[n - 2], self.chunk[n - 1]]
    }

    /// Level shape `z, y, x`.
    #[must_use]
    pub fn zyx_shape(&self) -> [u64; 3] {
        let n = self.shape.len();
        [self.shape[n - 3], self.shape[n - 2], self.shape[n - 1]]
    }

    /// Chunk (or inner chunk) extent along the leading axes, before `z, y, x`.
    #[must_use]
    pub fn leading_chunk(&self) -> &[u64] {
        &self.chunk[..self.chunk.len() - 3]
    }
}

/// A fill value as `f64`: `null` is 0, numbers are themselves, and `"NaN"`, `"Infinity"`,
/// `"-Infinity"` are the floats they name.
fn fill_value(v: &FillValueMetadataV3, source: &str) -> Result<f64, ArrayMetadataError> {
    let unsupported = || ArrayMetadataError::UnsupportedFillValue {
        source_name: source.to_string(),
        fill_value: v.to_string(),
    };
    match v {
        FillValueMetadataV3::Null => Ok(0.0),
        FillValueMetadataV3::Number(n) => n.as_f64().ok_or_else(unsupported),
        FillValueMetadataV3::String(s) => match s.as_str() {
            "NaN" => Ok(f64::NAN),
            "Infinity" => Ok(f64::INFINITY),
            "-Infinity" => Ok(f64::NEG_INFINITY),
            _ => Err(unsupported()),
        },
        _ => Err(unsupported()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn array_v2(shape: [u64; 4], dtype: &str) -> String {
        format!(
            r#"{{"zarr_format": 2, "shape": {shape:?}, "chunks": [1, 8, 8, 8], "dtype": "{dtype}",
                "fill_value": 0, "order": "C", "compressor": null, "filters": null}}"#
        )
    }

    #[test]
    fn v2_and_sharded_v3_arrays_are_described() {
        let a = ArrayDescription::parse(
            ZarrFormat::V2,
            array_v2([2, 10, 20, 20], "<u2").as_bytes(),
            "a0",
        )
        .unwrap();
        assert_eq!(a.sample_type, SampleType::U16);
        assert_eq!((a.brick_shape(), a.zyx_shape()), ([8, 8, 8], [10, 20, 20]));
        assert_eq!(
            (a.leading_chunk(), a.sharded, a.fill_value),
            (&[1][..], false, 0.0)
        );
        let v3 = r#"{"zarr_format": 3, "node_type": "array", "shape": [1, 64, 64, 64],
            "data_type": "float32", "fill_value": "NaN",
            "chunk_grid": {"name": "regular", "configuration": {"chunk_shape": [1, 32, 32, 32]}},
            "chunk_key_encoding": {"name": "default", "configuration": {"separator": "/"}},
            "codecs": [{"name": "sharding_indexed", "configuration": {"chunk_shape": [1, 8, 8, 8],
              "codecs": [{"name": "bytes", "configuration": {"endian": "little"}}],
              "index_codecs": [{"name": "bytes", "configuration": {"endian": "little"}}, {"name": "crc32c"}],
              "index_location": "end"}}]}"#;
        let b = ArrayDescription::parse(ZarrFormat::V3, v3.as_bytes(), "b").unwrap();
        assert_eq!(
            (b.sample_type, b.brick_shape(), b.sharded),
            (SampleType::F32, [8, 8, 8], true)
        );
        assert!(b.fill_value.is_nan());
    }

    #[test]
    fn unsupported_arrays_give_errors_naming_the_document() {
        let e = ArrayDescription::parse(
            ZarrFormat::V2,
            array_v2([1, 8, 8, 8], "<f8").as_bytes(),
            "a",
        )
        .unwrap_err();
        assert_eq!(e.to_string(), "a: unsupported data type '<f8'");
        let e =
            ArrayDescription::parse(ZarrFormat::V3, br#"{"node_type": "group"}"#, "g").unwrap_err();
        assert_eq!(e.to_string(), r#"g: not a Zarr array (node_type "group")"#);
        let e = ArrayDescription::parse(ZarrFormat::V2, b"[", "x").unwrap_err();
        assert!(
            e.to_string()
                .starts_with("x: not valid Zarr array metadata: "),
            "{e}"
        );
        let cause = std::error::Error::source(&e).expect("the parser's error is kept");
        assert_eq!(
            e.to_string(),
            format!("x: not valid Zarr array metadata: {cause}")
        );
        let flat = array_v2([1, 8, 8, 8], "|u1").replace("[1, 8, 8, 8]", "[8, 8]");
        let e = ArrayDescription::parse(ZarrFormat::V2, flat.as_bytes(), "f").unwrap_err();
        assert_eq!(
            e.to_string(),
            "f: chunk shape [8, 8] does not match array shape [8, 8]"
        );
        let odd =
            array_v2([1, 8, 8, 8], "|u1").replace(r#""fill_value": 0"#, r#""fill_value": "x""#);
        let e = ArrayDescription::parse(ZarrFormat::V2, odd.as_bytes(), "o").unwrap_err();
        assert_eq!(e.to_string(), r#"o: unsupported fill value "x""#);
    }
}
