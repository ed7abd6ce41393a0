//! The binary documents `brickserver` serves and `viewer` reads, shared so both sides agree.
//!
//! Each is *framed*: an 8-byte magic, a little-endian `u32` header length `H`, `H` bytes of
//! JSON header (described by a JSON Schema in `schemas/json/`), then the payload. Offsets in a
//! header count from the first payload byte. Sample values in payloads are little-endian.
//!
//! - [`MINMAX_MAGIC`] / [`MinMaxHierarchyHeader`]: the whole conservative min/max hierarchy of
//!   one channel, every level and every grid, for a renderer to load once;
//! - [`BRICKS_MAGIC`] / [`BrickBatchHeader`]: many bricks in one response.

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

/// Magic of a min/max hierarchy document.
pub const MINMAX_MAGIC: &[u8; 8] = b"RSMINMAX";
/// Magic of a brick batch document.
pub const BRICKS_MAGIC: &[u8; 8] = b"RSBRICKS";
/// Media type of a min/max hierarchy document.
pub const MINMAX_MEDIA_TYPE: &str = "application/x-residency-minmax";
/// Media type of a brick batch document.
pub const BRICKS_MEDIA_TYPE: &str = "application/x-residency-bricks";

/// Header of a min/max hierarchy document (`GET /NAME/minmax?channel=C`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MinMaxHierarchyHeader {
    /// Channel index.
    pub channel: usize,
    /// Zarr data type name of the values (`uint8`, `uint16`, `int16`, `uint32`, `int32`,
    /// `float32`).
    pub data_type: String,
    /// Voxels added around each cell when its range was taken (see the region metadata).
    pub halo: u64,
    /// Levels, finest first.
    pub levels: Vec<MinMaxLevelBlock>,
}

/// The grids of one level in a min/max hierarchy document.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MinMaxLevelBlock {
    /// Level index.
    pub level: usize,
    /// Level shape `z, y, x`.
    pub shape: [u64; 3],
    /// Grids, finest first; the last has a single cell.
    pub grids: Vec<MinMaxGridBlock>,
}

/// Where one grid's values lie in the payload: `gz·gy·gx` minima, then as many maxima, each a
/// sample of the header's data type, `z`-major. NaN marks a cell without a non-NaN voxel.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MinMaxGridBlock {
    /// Cell edge in voxels of the level, `z, y, x`.
    pub cell_shape: [u64; 3],
    /// Cells `z, y, x`.
    pub grid_shape: [u64; 3],
    /// Payload offset of the first minimum.
    pub offset: u64,
    /// Bytes of minima and maxima together.
    pub length: u64,
}

/// How a batch carries brick bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BrickEncoding {
    /// The brick's encoded bytes exactly as stored: the chunk file, or the inner chunk's bytes
    /// inside a shard. Decode them with the array's codecs (`zarr.json` / `.zarray`).
    Stored,
    /// The decoded samples of the whole brick shape, little-endian, `z`-major, voxels past
    /// the volume's edge holding the fill value.
    Raw,
}

/// What a batch holds for one requested brick.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BrickStatus {
    /// Bytes follow at `offset`.
    Ok,
    /// The brick is not stored, or (raw) equals the fill value everywhere: no bytes.
    Empty,
    /// The brick could not be read; `error` says why. No bytes.
    Error,
}

/// Header of a brick batch document (`GET /NAME/bricks?b=...`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BrickBatchHeader {
    /// How bytes are carried.
    pub encoding: BrickEncoding,
    /// Zarr data type name of the samples.
    pub data_type: String,
    /// Brick shape `z, y, x`.
    pub brick_shape: [u64; 3],
    /// One entry per requested brick, in request order.
    pub bricks: Vec<BrickEntry>,
}

/// One brick of a batch.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BrickEntry {
    /// Pyramid level.
    pub level: u32,
    /// Channel.
    pub channel: u32,
    /// Brick coordinates `z, y, x`.
    pub brick: [u64; 3],
    /// What follows.
    pub status: BrickStatus,
    /// Payload offset (0 unless `ok`).
    pub offset: u64,
    /// Payload bytes (0 unless `ok`).
    pub length: u64,
    /// Why the brick could not be read (only with `error`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// A malformed framed document.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct WireError(pub String);

impl std::fmt::Display for WireError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for WireError {}

/// Frames `header` and `payload` behind `magic`.
pub fn encode_framed(magic: &[u8; 8], header: &impl Serialize, payload: &[u8]) -> Vec<u8> {
    let json = serde_json::to_vec(header).expect("headers always serialize");
    let mut out = Vec::with_capacity(12 + json.len() + payload.len());
    out.extend_from_slice(magic);
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(&json);
    out.extend_from_slice(payload);
    out
}

/// Splits a framed document into its header and payload, checking the magic.
pub fn decode_framed<'a, H: DeserializeOwned>(
    magic: &[u8; 8],
    bytes: &'a [u8],
) -> Result<(H, &'a [u8]), WireError> {
    if bytes.len() < 12 || &bytes[..8] != magic {
        return Err(WireError(format!(
            "not a {} document (bad magic)",
            String::from_utf8_lossy(magic)
        )));
    }
    let len = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes")) as usize;
    let end = 12usize
        .checked_add(len)
        .filter(|&e| e <= bytes.len())
        .ok_or_else(|| WireError(format!("header of {len} bytes runs past the document")))?;
    let header = serde_json::from_slice(&bytes[12..end])
        .map_err(|e| WireError(format!("bad header: {e}")))?;
    Ok((header, &bytes[end..]))
}

/// Bytes per sample of a Zarr data type name, or `None` for one not served.
pub fn sample_bytes(data_type: &str) -> Option<usize> {
    match data_type {
        "uint8" => Some(1),
        "uint16" | "int16" => Some(2),
        "uint32" | "int32" | "float32" => Some(4),
        _ => None,
    }
}

/// Little-endian samples of `data_type` as `f64` (exact for every type served).
pub fn samples_to_f64(data_type: &str, bytes: &[u8]) -> Result<Vec<f64>, WireError> {
    let size = sample_bytes(data_type)
        .ok_or_else(|| WireError(format!("unsupported data type '{data_type}'")))?;
    if !bytes.len().is_multiple_of(size) {
        return Err(WireError(format!(
            "{} bytes is not a whole number of {data_type} samples",
            bytes.len()
        )));
    }
    let c = bytes.chunks_exact(size);
    Ok(match data_type {
        "uint8" => bytes.iter().map(|&v| v as f64).collect(),
        "uint16" => c.map(|b| u16::from_le_bytes([b[0], b[1]]) as f64).collect(),
        "int16" => c.map(|b| i16::from_le_bytes([b[0], b[1]]) as f64).collect(),
        "uint32" => c
            .map(|b| u32::from_le_bytes(b.try_into().expect("4")) as f64)
            .collect(),
        "int32" => c
            .map(|b| i32::from_le_bytes(b.try_into().expect("4")) as f64)
            .collect(),
        _ => c
            .map(|b| f32::from_le_bytes(b.try_into().expect("4")) as f64)
            .collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn framing_round_trips_and_rejects_garbage() {
        let header = BrickBatchHeader {
            encoding: BrickEncoding::Raw,
            data_type: "uint16".into(),
            brick_shape: [2, 2, 2],
            bricks: vec![BrickEntry {
                level: 0,
                channel: 1,
                brick: [0, 0, 3],
                status: BrickStatus::Ok,
                offset: 0,
                length: 3,
                error: None,
            }],
        };
        let doc = encode_framed(BRICKS_MAGIC, &header, &[1, 2, 3]);
        let (back, payload) = decode_framed::<BrickBatchHeader>(BRICKS_MAGIC, &doc).unwrap();
        assert_eq!((back, payload), (header, &[1u8, 2, 3][..]));
        assert_eq!(
            decode_framed::<BrickBatchHeader>(MINMAX_MAGIC, &doc).unwrap_err(),
            WireError("not a RSMINMAX document (bad magic)".into())
        );
        let mut cut = doc.clone();
        cut.truncate(20);
        assert!(
            decode_framed::<BrickBatchHeader>(BRICKS_MAGIC, &cut)
                .unwrap_err()
                .0
                .contains("runs past the document")
        );
    }

    #[test]
    fn samples_decode_exactly() {
        assert_eq!(
            samples_to_f64("int16", &(-3i16).to_le_bytes()).unwrap(),
            [-3.0]
        );
        assert_eq!(
            samples_to_f64("float32", &f32::MAX.to_le_bytes()).unwrap(),
            [f32::MAX as f64]
        );
        assert!(samples_to_f64("uint16", &[1, 2, 3]).is_err());
        assert!(samples_to_f64("float64", &[0; 8]).is_err());
    }
}
