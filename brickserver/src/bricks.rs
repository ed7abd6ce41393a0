//! The batched brick endpoint: many bricks, each given as (level, channel, brick
//! coordinates), in one framed response (`residency_schemas::wire::BrickBatchHeader`).
//!
//! `GET /NAME/bricks?b=L,C,z,y,x;L,C,z,y,x;...[&encoding=stored|raw]`. `stored` (the
//! default) carries each brick's encoded bytes exactly as stored: the chunk file, or the inner
//! chunk inside a shard. `raw` carries the decoded samples of the whole brick shape. A brick
//! that is not stored (or, raw, equals the fill value everywhere) is `empty`; one that cannot
//! be read or decoded is `error`, with a message naming it, and the rest of the batch is still
//! answered. A batch is capped in brick count and in decoded size.

use std::path::Path;
use std::sync::Arc;

use anyhow::{Context, Result, bail};
use axum::body::Bytes;
use rayon::prelude::*;
use residency_schemas::wire::{
    BrickBatchHeader, BrickEncoding, BrickEntry, BrickStatus, sample_bytes,
};
use zarrs::array::{
    Array, ArrayBytes, ArrayShardedExt, ArrayShardedReadableExt, ArrayShardedReadableExtCache,
    CodecOptions,
};
use zarrs::filesystem::FilesystemStore;

use crate::datasets::read_attributes;
use crate::regions::data_type_name;

/// Caps on one batch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BatchLimits {
    /// Most bricks in one request.
    pub max_bricks: usize,
    /// Most decoded bytes (bricks × brick voxels × sample size) in one request.
    pub max_bytes: u64,
}

impl Default for BatchLimits {
    fn default() -> Self {
        Self {
            max_bricks: 256,
            max_bytes: 64 << 20,
        }
    }
}

/// One requested brick.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct BrickAt {
    /// Pyramid level.
    pub level: u32,
    /// Channel.
    pub channel: u32,
    /// Brick coordinates `z, y, x`.
    pub brick: [u64; 3],
}

/// Why a batch request was refused.
#[derive(Debug, PartialEq, Eq)]
pub enum BatchError {
    /// Malformed (400).
    Bad(String),
    /// Over a cap (413).
    TooLarge(String),
}

/// Parses `b=L,C,z,y,x;...` and `encoding=...` from a query string, checking the count cap.
pub fn parse_batch(
    query: &str,
    limits: &BatchLimits,
) -> Result<(Vec<BrickAt>, BrickEncoding), BatchError> {
    let mut bricks = Vec::new();
    let mut encoding = BrickEncoding::Stored;
    for pair in query.split('&').filter(|p| !p.is_empty()) {
        let (name, value) = pair.split_once('=').unwrap_or((pair, ""));
        let value = percent_encoding::percent_decode_str(value)
            .decode_utf8()
            .map_err(|_| BatchError::Bad(format!("parameter '{name}' is not UTF-8")))?;
        match name {
            "b" => {
                for item in value.split(';').filter(|s| !s.is_empty()) {
                    if bricks.len() == limits.max_bricks {
                        return Err(BatchError::TooLarge(format!(
                            "more than {} bricks in one batch",
                            limits.max_bricks
                        )));
                    }
                    let n: Vec<u64> = item
                        .split(',')
                        .map(|v| v.trim().parse::<u64>())
                        .collect::<Result<_, _>>()
                        .map_err(|_| {
                            BatchError::Bad(format!(
                                "brick '{item}' is not five integers L,C,z,y,x"
                            ))
                        })?;
                    let [l, c, z, y, x] = n[..] else {
                        return Err(BatchError::Bad(format!(
                            "brick '{item}' is not five integers L,C,z,y,x"
                        )));
                    };
                    let narrow = |v: u64| {
                        u32::try_from(v)
                            .map_err(|_| BatchError::Bad(format!("brick '{item}': {v} too large")))
                    };
                    bricks.push(BrickAt {
                        level: narrow(l)?,
                        channel: narrow(c)?,
                        brick: [z, y, x],
                    });
                }
            }
            "encoding" => {
                encoding = match &*value {
                    "stored" => BrickEncoding::Stored,
                    "raw" => BrickEncoding::Raw,
                    other => {
                        return Err(BatchError::Bad(format!(
                            "encoding '{other}' is not 'stored' or 'raw'"
                        )));
                    }
                }
            }
            other => return Err(BatchError::Bad(format!("unknown parameter '{other}'"))),
        }
    }
    if bricks.is_empty() {
        return Err(BatchError::Bad(
            "no brick requested: give b=L,C,z,y,x[;L,C,z,y,x...]".into(),
        ));
    }
    Ok((bricks, encoding))
}

struct Level {
    path: String,
    array: Array<FilesystemStore>,
    shards: ArrayShardedReadableExtCache,
    /// Bricks `z, y, x`.
    grid: [u64; 3],
}

/// The image arrays of one dataset, opened once, for reading bricks.
pub struct ImageArrays {
    levels: Vec<Level>,
    /// Zarr data type name of the samples.
    pub data_type: String,
    /// Brick shape `z, y, x`.
    pub brick_shape: [u64; 3],
    /// Channels.
    pub channels: u64,
    /// Leading (`t`) dimensions before `c`, read at index 0.
    leading: usize,
    has_channel_axis: bool,
}

/// The level array paths of an OME-Zarr image's first multiscale, finest first.
fn level_paths(root: &Path) -> Result<Vec<String>> {
    let (_, ome, file) = read_attributes(root)?;
    let datasets = ome["multiscales"][0]["datasets"]
        .as_array()
        .with_context(|| format!("{}: no OME-Zarr multiscales", file.display()))?;
    datasets
        .iter()
        .map(|d| {
            d["path"]
                .as_str()
                .map(str::to_string)
                .with_context(|| format!("{}: a multiscales dataset has no path", file.display()))
        })
        .collect()
}

impl ImageArrays {
    /// Opens the pyramid levels of the store at `root`.
    pub fn open(root: &Path) -> Result<Self> {
        let store = Arc::new(
            FilesystemStore::new(root)
                .with_context(|| format!("{}: cannot open the store", root.display()))?,
        );
        let mut levels = Vec::new();
        let mut first: Option<(String, [u64; 3], u64, usize, bool)> = None;
        for path in level_paths(root)? {
            let array = Array::open(store.clone(), &format!("/{path}"))
                .with_context(|| format!("cannot open image array '{path}'"))?;
            let dims = array.dimensionality();
            if !(3..=5).contains(&dims) {
                bail!("image array '{path}' has {dims} dimensions; bricks need (t,)(c,)z,y,x");
            }
            let brick_full = array
                .effective_subchunk_shape()
                .map(|s| s.iter().map(|v| v.get()).collect::<Vec<u64>>())
                .or_else(|| {
                    array
                        .chunk_shape(&vec![0; dims])
                        .ok()
                        .map(|s| s.iter().map(|v| v.get()).collect())
                })
                .with_context(|| format!("image array '{path}' has no regular chunk grid"))?;
            let has_c = dims >= 4;
            if has_c && brick_full[dims - 4] != 1 {
                bail!("image array '{path}' chunks several channels together; bricks need one");
            }
            let brick = [
                brick_full[dims - 3],
                brick_full[dims - 2],
                brick_full[dims - 1],
            ];
            let shape = array.shape().to_vec();
            let channels = if has_c { shape[dims - 4] } else { 1 };
            let grid = std::array::from_fn(|a| shape[dims - 3 + a].div_ceil(brick[a]));
            match &first {
                None => {
                    first = Some((data_type_name(&array), brick, channels, dims, has_c));
                }
                Some((_, b, _, _, _)) if *b != brick => {
                    bail!("image array '{path}' has bricks {brick:?}, unlike level 0's {b:?}")
                }
                Some(_) => {}
            }
            let shards = ArrayShardedReadableExtCache::new(&array);
            levels.push(Level {
                path,
                array,
                shards,
                grid,
            });
        }
        let (data_type, brick_shape, channels, dims, has_channel_axis) =
            first.context("the store lists no pyramid level")?;
        if sample_bytes(&data_type).is_none() {
            bail!("data type '{data_type}' cannot be served as bricks");
        }
        Ok(Self {
            levels,
            data_type,
            brick_shape,
            channels,
            leading: dims - 3 - has_channel_axis as usize,
            has_channel_axis,
        })
    }

    /// Decoded bytes of one full brick.
    pub fn brick_bytes(&self) -> u64 {
        self.brick_shape.iter().product::<u64>()
            * sample_bytes(&self.data_type).expect("checked at open") as u64
    }

    /// Checks a request against the dataset's levels, channels and brick grids.
    pub fn check(&self, at: &BrickAt) -> Result<(), String> {
        let level = self.levels.get(at.level as usize).ok_or_else(|| {
            format!(
                "level {} does not exist (the dataset has {})",
                at.level,
                self.levels.len()
            )
        })?;
        if at.channel as u64 >= self.channels {
            return Err(format!(
                "channel {} does not exist (the dataset has {})",
                at.channel, self.channels
            ));
        }
        if (0..3).any(|a| at.brick[a] >= level.grid[a]) {
            return Err(format!(
                "brick {:?} lies outside level {} ({:?} bricks, z, y, x)",
                at.brick, at.level, level.grid
            ));
        }
        Ok(())
    }

    /// Reads one brick: `None` when empty, else its stored or decoded bytes.
    pub fn read(&self, at: &BrickAt, encoding: BrickEncoding) -> Result<Option<Vec<u8>>, String> {
        let level = &self.levels[at.level as usize];
        let mut indices = vec![0u64; self.leading];
        if self.has_channel_axis {
            indices.push(at.channel as u64);
        }
        indices.extend(at.brick);
        let named = |e: &dyn std::fmt::Display| {
            let key = if level.shards.array_is_sharded() {
                format!("an inner chunk of array '{}'", level.path)
            } else {
                format!("key '{}'", level.array.chunk_key(&indices))
            };
            format!(
                "level {} channel {} brick {:?} ({key}): {e}",
                at.level, at.channel, at.brick
            )
        };
        if level.shards.len() > 4096 {
            level.shards.clear();
        }
        match encoding {
            BrickEncoding::Stored if level.shards.array_is_sharded() => level
                .array
                .retrieve_encoded_subchunk(&level.shards, &indices)
                .map_err(|e| named(&e)),
            BrickEncoding::Stored => level
                .array
                .retrieve_encoded_chunk(&indices)
                .map_err(|e| named(&e)),
            BrickEncoding::Raw => {
                let bytes: ArrayBytes<'static> = level
                    .array
                    .retrieve_subchunk_opt(&level.shards, &indices, &CodecOptions::default())
                    .map_err(|e| named(&e))?;
                let raw = bytes.into_fixed().map_err(|e| named(&e))?.into_owned();
                Ok((!raw.iter().all(|&b| b == 0)).then_some(raw))
            }
        }
    }
}

/// Reads a whole batch (in parallel) into its header and payload, given a brick reader
/// (which may consult a cache).
pub fn read_batch(
    arrays: &ImageArrays,
    bricks: &[BrickAt],
    encoding: BrickEncoding,
    read: impl Fn(&BrickAt) -> Result<Option<Bytes>, String> + Sync,
) -> (BrickBatchHeader, Vec<u8>) {
    let results: Vec<Result<Option<Bytes>, String>> = bricks
        .par_iter()
        .map(|at| arrays.check(at).and_then(|()| read(at)))
        .collect();
    let mut payload = Vec::new();
    let entries = bricks
        .iter()
        .zip(results)
        .map(|(at, result)| {
            let (status, offset, length, error) = match result {
                Ok(Some(bytes)) => {
                    let offset = payload.len() as u64;
                    payload.extend_from_slice(&bytes);
                    (BrickStatus::Ok, offset, bytes.len() as u64, None)
                }
                Ok(None) => (BrickStatus::Empty, 0, 0, None),
                Err(e) => (BrickStatus::Error, 0, 0, Some(e)),
            };
            BrickEntry {
                level: at.level,
                channel: at.channel,
                brick: at.brick,
                status,
                offset,
                length,
                error,
            }
        })
        .collect();
    let header = BrickBatchHeader {
        encoding,
        data_type: arrays.data_type.clone(),
        brick_shape: arrays.brick_shape,
        bricks: entries,
    };
    (header, payload)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn batch_requests_parse_and_are_capped() {
        let limits = BatchLimits {
            max_bricks: 2,
            max_bytes: 1 << 20,
        };
        let (bricks, enc) = parse_batch("b=0,1,2,3,4%3B1,0,0,0,0&encoding=raw", &limits).unwrap();
        assert_eq!(enc, BrickEncoding::Raw);
        assert_eq!(
            bricks,
            vec![
                BrickAt {
                    level: 0,
                    channel: 1,
                    brick: [2, 3, 4]
                },
                BrickAt {
                    level: 1,
                    channel: 0,
                    brick: [0, 0, 0]
                }
            ]
        );
        assert_eq!(
            parse_batch("b=0,0,0,0,0;0,0,0,0,1;0,0,0,0,2", &limits),
            Err(BatchError::TooLarge(
                "more than 2 bricks in one batch".into()
            ))
        );
        assert_eq!(
            parse_batch("b=0,0,0,0", &limits),
            Err(BatchError::Bad(
                "brick '0,0,0,0' is not five integers L,C,z,y,x".into()
            ))
        );
        assert!(matches!(parse_batch("", &limits), Err(BatchError::Bad(_))));
        assert!(matches!(
            parse_batch("b=0,0,0,0,0&encoding=zip", &limits),
            Err(BatchError::Bad(_))
        ));
    }
}
