//! The binary documents `brickserver` serves and `viewer` reads, shared so both sides agree.
//!
//! Each is *framed*: an 8-byte magic, a little-endian `u32` header length `H`, `H` bytes of
//! JSON header (described by a JSON Schema in `schemas/json/`), then the payload. Offsets in a
//! header count from the first payload byte. Sample values in payloads are little-endian.
//!
//! - [`MINMAX_MAGIC`] / [`MinMaxHierarchyHeader`]: the whole conservative min/max hierarchy of
//!   one channel, every level and every grid, for a renderer to load once;
//! - [`BRICKS_MAGIC`] / [`BrickBatchHeader`]: many bricks in one response.

use schemars::JsonSchema;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::SampleType;

/// Magic of a min/max hierarchy document.
pub const MINMAX_MAGIC: &[u8; 8] = b"RSMINMAX";
/// Magic of a brick batch document.
pub const BRICKS_MAGIC: &[u8; 8] = b"RSBRICKS";
/// Media type of a min/max hierarchy document.
pub const MINMAX_MEDIA_TYPE: &str = "application/x-residency-minmax";
/// Media type of a brick batch document.
pub const BRICKS_MEDIA_TYPE: &str = "application/x-residency-bricks";

/// Header of a min/max hierarchy document (`GET /NAME/minmax?channel=C`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(
    title = "Min/max hierarchy header",
    description = "JSON header of the framed binary document of `GET /NAME/minmax?channel=C` \
        (media type application/x-residency-minmax): 8 bytes 'RSMINMAX', a little-endian u32 \
        header length H, H bytes of this header, then the payload. Each grid's block at `offset` \
        (from the first payload byte) holds gz*gy*gx minima then as many maxima, little-endian \
        samples of `data_type`, z-major; NaN marks a cell with no non-NaN voxel. These are the \
        haloed (conservative for trilinear sampling) cells of the region metadata."
)]
#[schemars(deny_unknown_fields)]
pub struct MinMaxHierarchyHeader {
    /// Channel index.
    pub channel: usize,
    /// Sample type of the values, by its Zarr name (`uint8`, `uint16`, `int16`, `uint32`,
    /// `int32`, `float32`).
    pub data_type: SampleType,
    /// Voxels added around each cell when its range was taken (see the region metadata).
    pub halo: u64,
    /// Levels, finest first.
    pub levels: Vec<MinMaxLevelBlock>,
}

/// The grids of one level in a min/max hierarchy document.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct MinMaxLevelBlock {
    /// Level index.
    pub level: usize,
    /// Level shape `z, y, x`.
    pub shape: [u64; 3],
    /// Grids, finest first; the last has a single cell.
    #[schemars(length(min = 1))]
    pub grids: Vec<MinMaxGridBlock>,
}

/// Where one grid's values lie in the payload: `gz·gy·gx` minima, then as many maxima, each a
/// sample of the header's data type, `z`-major. NaN marks a cell without a non-NaN voxel.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
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
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
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
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
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
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(
    title = "Brick batch header",
    description = "JSON header of the framed binary document of `GET \
        /NAME/bricks?b=L,C,z,y,x;...` (media type application/x-residency-bricks): 8 bytes \
        'RSBRICKS', a little-endian u32 header length H, H bytes of this header, then the \
        payload. An `ok` brick's bytes lie at `offset` (from the first payload byte) for \
        `length` bytes: with encoding `stored` the brick's encoded bytes exactly as stored \
        (chunk file, or the inner chunk inside a shard); with `raw` the decoded little-endian \
        samples of the whole brick shape, z-major."
)]
#[schemars(deny_unknown_fields)]
pub struct BrickBatchHeader {
    /// How bytes are carried.
    pub encoding: BrickEncoding,
    /// Sample type, by its Zarr name.
    pub data_type: SampleType,
    /// Brick shape `z, y, x`.
    #[schemars(inner(range(min = 1)))]
    pub brick_shape: [u64; 3],
    /// One entry per requested brick, in request order.
    pub bricks: Vec<BrickEntry>,
}

/// One brick of a batch.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
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
    // Left out, never `null`, when there is none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(with = "String")]
    pub error: Option<String>,
}

/// A malformed framed document.
#[derive(Debug, thiserror::Error)]
pub enum WireError {
    /// The document does not start with the expected magic.
    #[error("not a {} document (bad magic)", String::from_utf8_lossy(.expected))]
    BadMagic {
        /// The magic looked for.
        expected: [u8; 8],
    },
    /// The header length points past the end of the document.
    #[error("header of {length} bytes runs past the document")]
    HeaderPastEnd {
        /// Header length the document claims.
        length: usize,
    },
    /// The header is not the expected JSON.
    #[error("bad header: {source}")]
    BadHeader {
        /// What the JSON parser said.
        #[source]
        source: serde_json::Error,
    },
}

/// Frames `header` and `payload` behind `magic`.
///
/// # Panics
/// If the header's JSON is 4 GiB or longer.
pub fn encode_framed(magic: &[u8; 8], header: &impl Serialize, payload: &[u8]) -> Vec<u8> {
    let json = serde_json::to_vec(header).expect("headers always serialize");
    let length = u32::try_from(json.len()).expect("a header under 4 GiB");
    let mut out = Vec::with_capacity(12 + json.len() + payload.len());
    out.extend_from_slice(magic);
    out.extend_from_slice(&length.to_le_bytes());
    out.extend_from_slice(&json);
    out.extend_from_slice(payload);
    out
}

/// Splits a framed document into its header and payload, checking the magic.
///
/// # Errors
/// [`WireError`] when the magic differs, the header runs past the document, or the header is
/// not a valid `H`.
pub fn decode_framed<'a, H: DeserializeOwned>(
    magic: &[u8; 8],
    bytes: &'a [u8],
) -> Result<(H, &'a [u8]), WireError> {
    if bytes.len() < 12 || &bytes[..8] != magic {
        return Err(WireError::BadMagic { expected: *magic });
    }
    let length = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize;
    let end = 12usize
        .checked_add(length)
        .filter(|&e| e <= bytes.len())
        .ok_or(WireError::HeaderPastEnd { length })?;
    let header = serde_json::from_slice(&bytes[12..end])
        .map_err(|source| WireError::BadHeader { source })?;
    Ok((header, &bytes[end..]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn framing_round_trips_and_rejects_garbage() {
        let header = BrickBatchHeader {
            encoding: BrickEncoding::Raw,
            data_type: SampleType::U16,
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
        let e = decode_framed::<BrickBatchHeader>(MINMAX_MAGIC, &doc).unwrap_err();
        assert!(
            matches!(e, WireError::BadMagic { expected } if expected == *MINMAX_MAGIC),
            "{e:?}"
        );
        let mut cut = doc.clone();
        cut.truncate(20);
        assert_eq!(
            decode_framed::<BrickBatchHeader>(BRICKS_MAGIC, &cut)
                .unwrap_err()
                .to_string(),
            format!("header of {} bytes runs past the document", doc.len() - 15)
        );
        assert_eq!(
            decode_framed::<BrickBatchHeader>(MINMAX_MAGIC, b"RSBRICKS")
                .unwrap_err()
                .to_string(),
            "not a RSMINMAX document (bad magic)"
        );
        let e =
            decode_framed::<BrickBatchHeader>(BRICKS_MAGIC, &encode_framed(BRICKS_MAGIC, &1, &[]))
                .unwrap_err();
        assert!(e.to_string().starts_with("bad header: invalid type"), "{e}");
        let cause = std::error::Error::source(&e).expect("the parser's error is kept");
        assert_eq!(e.to_string(), format!("bad header: {cause}"));
    }
}
