//! The voxel sample types Residency stores, serves and renders, with their Zarr names, sizes
//! and conversions: the one definition every crate uses.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// A voxel sample type. Stores keep the source's type; nothing is squeezed to 8 bits.
///
/// Serialized as its Zarr v3 data type name (`"uint16"`, `"float32"`, ...), as in `zarr.json`
/// and in the server's wire headers.
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    Hash,
    PartialOrd,
    Ord,
    Serialize,
    Deserialize,
    schemars::JsonSchema,
)]
pub enum SampleType {
    /// Unsigned 8-bit integer.
    #[serde(rename = "uint8")]
    U8,
    /// Unsigned 16-bit integer.
    #[serde(rename = "uint16")]
    U16,
    /// Signed 16-bit integer.
    #[serde(rename = "int16")]
    I16,
    /// Unsigned 32-bit integer.
    #[serde(rename = "uint32")]
    U32,
    /// Signed 32-bit integer.
    #[serde(rename = "int32")]
    I32,
    /// IEEE 754 32-bit float.
    #[serde(rename = "float32")]
    F32,
}

/// A data type name that is not one of the [`SampleType`]s.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "unsupported data type '{name}': expected one of uint8, uint16, int16, uint32, int32, float32"
)]
pub struct UnsupportedDataType {
    /// The name as given.
    pub name: String,
}

/// Little-endian sample bytes that do not decode as the type they claim.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{length} bytes is not a whole number of {sample_type} samples")]
pub struct PartialSample {
    /// The sample type.
    pub sample_type: SampleType,
    /// Bytes given.
    pub length: usize,
}

impl SampleType {
    /// Every sample type, narrowest first.
    pub const ALL: [Self; 6] = [
        Self::U8,
        Self::U16,
        Self::I16,
        Self::U32,
        Self::I32,
        Self::F32,
    ];

    /// Decoded bytes of a block (a brick) of `shape` samples.
    #[must_use]
    pub fn block_bytes(self, shape: [u64; 3]) -> u64 {
        shape.iter().product::<u64>() * self.bytes() as u64
    }

    /// Bytes per sample.
    #[must_use]
    pub fn bytes(self) -> usize {
        match self {
            Self::U8 => 1,
            Self::U16 | Self::I16 => 2,
            Self::U32 | Self::I32 | Self::F32 => 4,
        }
    }

    /// The Zarr v3 (and NumPy) data type name: `uint8`, `uint16`, `int16`, `uint32`, `int32`,
    /// `float32`.
    #[must_use]
    pub fn zarr_name(self) -> &'static str {
        match self {
            Self::U8 => "uint8",
            Self::U16 => "uint16",
            Self::I16 => "int16",
            Self::U32 => "uint32",
            Self::I32 => "int32",
            Self::F32 => "float32",
        }
    }

    /// The type of a Zarr v3 data type name, or `None` for a type Residency does not store.
    #[must_use]
    pub fn from_zarr_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|t| t.zarr_name() == name)
    }

    /// The Zarr v2 `dtype` written for this type (little-endian NumPy type string).
    #[must_use]
    pub fn zarr_v2_dtype(self) -> &'static str {
        match self {
            Self::U8 => "|u1",
            Self::U16 => "<u2",
            Self::I16 => "<i2",
            Self::U32 => "<u4",
            Self::I32 => "<i4",
            Self::F32 => "<f4",
        }
    }

    /// The type of a Zarr v2 `dtype` of either byte order (`<u2`, `>u2`, `|u1`, `=f4`), or
    /// `None` for a type Residency does not store. Byte order is the codec's business.
    #[must_use]
    pub fn from_zarr_v2_dtype(dtype: &str) -> Option<Self> {
        let bare = dtype.trim_start_matches(['<', '>', '|', '=']);
        Self::ALL
            .into_iter()
            .find(|t| &t.zarr_v2_dtype()[1..] == bare)
    }

    /// Whether this is a floating-point type.
    #[must_use]
    pub fn is_float(self) -> bool {
        self == Self::F32
    }

    /// The narrowest type that holds every value of both types exactly, if any
    /// (`u8 + u16 → u16`, `u16 + i16 → i32`, `u16 + f32 → f32`; `u32 + f32` has none).
    #[must_use]
    pub fn promote(a: Self, b: Self) -> Option<Self> {
        use SampleType::{F32, I16, I32, U8, U16, U32};
        if a == b {
            return Some(a);
        }
        let (lo, hi) = if a < b { (a, b) } else { (b, a) };
        Some(match (lo, hi) {
            (U8, x) => x,
            (U16, U32) => U32,
            (U16 | I16, I32) | (U16, I16) => I32,
            (U16 | I16, F32) => F32,
            _ => return None,
        })
    }

    /// Little-endian samples of this type as `f64` (exact for every type).
    ///
    /// # Errors
    /// [`PartialSample`] when `bytes` is not a whole number of samples.
    pub fn decode_le_to_f64(self, bytes: &[u8]) -> Result<Vec<f64>, PartialSample> {
        if !bytes.len().is_multiple_of(self.bytes()) {
            return Err(PartialSample {
                sample_type: self,
                length: bytes.len(),
            });
        }
        let c = bytes.chunks_exact(self.bytes());
        Ok(match self {
            Self::U8 => bytes.iter().map(|&v| f64::from(v)).collect(),
            Self::U16 => c
                .map(|b| f64::from(u16::from_le_bytes([b[0], b[1]])))
                .collect(),
            Self::I16 => c
                .map(|b| f64::from(i16::from_le_bytes([b[0], b[1]])))
                .collect(),
            Self::U32 => c
                .map(|b| f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])))
                .collect(),
            Self::I32 => c
                .map(|b| f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])))
                .collect(),
            Self::F32 => c
                .map(|b| f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])))
                .collect(),
        })
    }
}

impl fmt::Display for SampleType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.zarr_name())
    }
}

/// Parses a data type name as users write it on the command line and in raw file names:
/// the Zarr names and their short and C forms (`uint8`, `u8`, `ubyte`, `uint16`, `u16`,
/// `ushort`, `int16`, `i16`, `short`, `uint32`, `u32`, `uint`, `int32`, `i32`, `int`,
/// `float32`, `f32`, `float`), in any case.
impl FromStr for SampleType {
    type Err = UnsupportedDataType;

    fn from_str(name: &str) -> Result<Self, Self::Err> {
        Ok(match name.to_ascii_lowercase().as_str() {
            "uint8" | "u8" | "ubyte" => Self::U8,
            "uint16" | "u16" | "ushort" => Self::U16,
            "int16" | "i16" | "short" => Self::I16,
            "uint32" | "u32" | "uint" => Self::U32,
            "int32" | "i32" | "int" => Self::I32,
            "float32" | "f32" | "float" => Self::F32,
            other => {
                return Err(UnsupportedDataType {
                    name: other.to_string(),
                });
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_in_both_zarr_versions_and_serde() {
        for t in SampleType::ALL {
            assert_eq!(SampleType::from_zarr_name(t.zarr_name()), Some(t));
            assert_eq!(SampleType::from_zarr_v2_dtype(t.zarr_v2_dtype()), Some(t));
            assert_eq!(t.zarr_name().parse::<SampleType>(), Ok(t));
            let json = serde_json::to_string(&t).unwrap();
            assert_eq!(json, format!("\"{}\"", t.zarr_name()));
            assert_eq!(serde_json::from_str::<SampleType>(&json).unwrap(), t);
        }
        assert_eq!(SampleType::from_zarr_v2_dtype(">u2"), Some(SampleType::U16));
        assert_eq!(SampleType::from_zarr_v2_dtype("<f8"), None);
        assert_eq!(SampleType::from_zarr_name("float64"), None);
        assert_eq!("FLOAT".parse::<SampleType>(), Ok(SampleType::F32));
        assert_eq!(
            "f64".parse::<SampleType>().unwrap_err().to_string(),
            "unsupported data type 'f64': expected one of uint8, uint16, int16, uint32, int32, float32"
        );
    }

    #[test]
    fn promotion_holds_both_exactly() {
        use SampleType::{F32, I16, I32, U8, U16, U32};
        assert_eq!(SampleType::promote(U8, U16), Some(U16));
        assert_eq!(SampleType::promote(U16, I16), Some(I32));
        assert_eq!(SampleType::promote(I16, U16), Some(I32));
        assert_eq!(SampleType::promote(U16, U32), Some(U32));
        assert_eq!(SampleType::promote(I16, U32), None);
        assert_eq!(SampleType::promote(U16, F32), Some(F32));
        assert_eq!(SampleType::promote(U32, F32), None);
        assert_eq!(SampleType::promote(I32, F32), None);
    }

    #[test]
    fn samples_decode_exactly() {
        assert_eq!(
            SampleType::I16.decode_le_to_f64(&(-3i16).to_le_bytes()),
            Ok(vec![-3.0])
        );
        assert_eq!(
            SampleType::F32.decode_le_to_f64(&f32::MAX.to_le_bytes()),
            Ok(vec![f64::from(f32::MAX)])
        );
        assert_eq!(
            SampleType::U16
                .decode_le_to_f64(&[1, 2, 3])
                .unwrap_err()
                .to_string(),
            "3 bytes is not a whole number of uint16 samples"
        );
    }
}
