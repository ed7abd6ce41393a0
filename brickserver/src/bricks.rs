//! The batched brick endpoint: many bricks, each given as (level, channel, brick
//! coordinates), in one framed response (`residency_schemas::wire::BrickBatchHeader`).
//!
//! `GET /NAME/bricks?b=L,C,z,y,x;L,C,z,y,x;...[&encoding=stored|raw]`. `stored` (the
//! default) carries each brick's encoded bytes exactly as stored: the chunk file, or the inner
//! chunk inside a shard. `raw` carries the decoded samples of the whole brick shape. A brick
//! that is not stored (or, raw, equals the fill value everywhere) is `empty`; one that cannot
//! be read or decoded is `error`, with a message naming it, and the rest of the batch is still
//! answered. A batch is capped in brick count and in decoded size.

use std::sync::Arc;

use axum::body::Bytes;
use futures::StreamExt;
use rayon::prelude::*;
use residency_schemas::SampleType;
use residency_schemas::wire::{BrickBatchHeader, BrickEncoding, BrickEntry, BrickStatus};
use residency_store::pyramid::{AsyncBricks, Pyramid, PyramidError, REMOTE_READS};
use zarrs::storage::ReadableListableStorageTraits;

use crate::dataset_store::DatasetStore;

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

impl BatchLimits {
    /// Checks the decoded size of `bricks` bricks of `brick_bytes` bytes each.
    ///
    /// # Errors
    /// [`BatchError::TooManyBytes`] when they exceed [`BatchLimits::max_bytes`].
    pub(crate) fn check_bytes(&self, bricks: usize, brick_bytes: u64) -> Result<(), BatchError> {
        let decoded = (bricks as u64).saturating_mul(brick_bytes);
        if decoded > self.max_bytes {
            return Err(BatchError::TooManyBytes {
                bricks,
                brick_bytes,
                max_bytes: self.max_bytes,
            });
        }
        Ok(())
    }
}

/// One requested brick: level, channel and brick coordinates `z, y, x`.
pub use residency_store::pyramid::BrickIndex as BrickAt;

/// Why a batch request was refused: malformed (400) or over a cap (413, see
/// [`BatchError::is_over_limit`]).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum BatchError {
    /// A parameter's value is not UTF-8 once percent-decoded.
    #[error("parameter '{name}' is not UTF-8")]
    NotUtf8 {
        /// The parameter's name.
        name: String,
    },
    /// A brick is not `L,C,z,y,x`.
    #[error("brick '{brick}' is not five integers L,C,z,y,x")]
    NotFiveIntegers {
        /// The brick as given.
        brick: String,
    },
    /// A brick's level or channel does not fit in 32 bits.
    #[error("brick '{brick}': {value} too large")]
    IndexTooLarge {
        /// The brick as given.
        brick: String,
        /// The level or channel.
        value: u64,
    },
    /// An `encoding` other than `stored` or `raw`.
    #[error("encoding '{encoding}' is not 'stored' or 'raw'")]
    UnknownEncoding {
        /// The encoding as given.
        encoding: String,
    },
    /// A parameter other than `b` and `encoding`.
    #[error("unknown parameter '{name}'")]
    UnknownParameter {
        /// The parameter's name.
        name: String,
    },
    /// No `b` parameter, or an empty one.
    #[error("no brick requested: give b=L,C,z,y,x[;L,C,z,y,x...]")]
    NoBrick,
    /// More bricks than [`BatchLimits::max_bricks`].
    #[error("more than {max_bricks} bricks in one batch")]
    TooManyBricks {
        /// The cap.
        max_bricks: usize,
    },
    /// More decoded bytes than [`BatchLimits::max_bytes`].
    #[error("{bricks} bricks of {brick_bytes} bytes exceed the batch limit of {max_bytes} bytes")]
    TooManyBytes {
        /// Bricks asked for.
        bricks: usize,
        /// Decoded bytes of one brick.
        brick_bytes: u64,
        /// The cap.
        max_bytes: u64,
    },
}

impl BatchError {
    /// Whether the batch is well formed but over a cap (413 rather than 400).
    pub fn is_over_limit(&self) -> bool {
        matches!(self, Self::TooManyBricks { .. } | Self::TooManyBytes { .. })
    }
}

/// Parses `b=L,C,z,y,x;...` and `encoding=...` from a query string, checking the count cap.
///
/// # Errors
/// [`BatchError`] for a malformed query, or more bricks than [`BatchLimits::max_bricks`].
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
            .map_err(|_| BatchError::NotUtf8 {
                name: name.to_string(),
            })?;
        match name {
            "b" => {
                for item in value.split(';').filter(|s| !s.is_empty()) {
                    if bricks.len() == limits.max_bricks {
                        return Err(BatchError::TooManyBricks {
                            max_bricks: limits.max_bricks,
                        });
                    }
                    let not_five = || BatchError::NotFiveIntegers {
                        brick: item.to_string(),
                    };
                    let n: Vec<u64> = item
                        .split(',')
                        .map(|v| v.trim().parse::<u64>())
                        .collect::<Result<_, _>>()
                        .map_err(|_| not_five())?;
                    let [l, c, z, y, x] = n[..] else {
                        return Err(not_five());
                    };
                    let narrow = |value: u64| {
                        u32::try_from(value).map_err(|_| BatchError::IndexTooLarge {
                            brick: item.to_string(),
                            value,
                        })
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
                        return Err(BatchError::UnknownEncoding {
                            encoding: other.to_string(),
                        });
                    }
                }
            }
            other => {
                return Err(BatchError::UnknownParameter {
                    name: other.to_string(),
                });
            }
        }
    }
    if bricks.is_empty() {
        return Err(BatchError::NoBrick);
    }
    Ok((bricks, encoding))
}

pub(crate) use residency_store::pyramid::NoSuchBrick;

/// A dataset's image, opened once through the pyramid reader: its attributes (the region
/// metadata among them) and its level arrays.
pub(crate) type ImagePyramid = Pyramid<dyn ReadableListableStorageTraits>;

/// The image arrays of one dataset, for reading bricks.
pub(crate) struct ImageArrays {
    pyramid: Arc<ImagePyramid>,
    /// Sample type of the bricks.
    pub data_type: SampleType,
    /// Brick shape `z, y, x`.
    pub brick_shape: [u64; 3],
    /// An object store's level arrays read by futures, and the runtime they run on.
    remote: Option<(Arc<AsyncBricks>, tokio::runtime::Handle)>,
}

impl ImageArrays {
    /// The image arrays of a dataset's store, from its opened `pyramid`.
    pub fn new(dataset: &DatasetStore, pyramid: Arc<ImagePyramid>) -> Self {
        let remote = dataset.async_store().map(|store| {
            let bricks = pyramid.async_bricks(store.storage.clone());
            (Arc::new(bricks), store.runtime.handle().clone())
        });
        Self {
            data_type: pyramid.sample_type,
            brick_shape: pyramid.brick_shape,
            pyramid,
            remote,
        }
    }

    /// Decoded bytes of one full brick.
    #[must_use]
    pub fn brick_bytes(&self) -> u64 {
        self.pyramid.brick_bytes()
    }

    /// Checks a request against the dataset's levels, channels and brick grids.
    ///
    /// # Errors
    /// [`NoSuchBrick`] for a level, channel or brick the dataset does not have.
    pub fn check(&self, at: &BrickAt) -> Result<(), NoSuchBrick> {
        self.pyramid.check(at)
    }

    /// Reads one brick from a folder: `None` when empty, else its stored or decoded bytes.
    ///
    /// # Errors
    /// [`PyramidError`] naming the brick and its key when it cannot be read or decoded.
    fn read(&self, at: &BrickAt, encoding: BrickEncoding) -> Result<Option<Vec<u8>>, PyramidError> {
        match encoding {
            BrickEncoding::Stored => self.pyramid.read_brick_encoded(at),
            BrickEncoding::Raw => Ok(not_fill(self.pyramid.read_brick_bytes(at)?)),
        }
    }

    /// [`ImageArrays::read`] by futures from an object store, through `bricks` (the arrays'
    /// [`AsyncBricks`]).
    ///
    /// # Errors
    /// [`PyramidError`] naming the brick and its key when it cannot be read or decoded.
    async fn read_async(
        &self,
        bricks: &AsyncBricks,
        at: &BrickAt,
        encoding: BrickEncoding,
    ) -> Result<Option<Vec<u8>>, PyramidError> {
        match encoding {
            BrickEncoding::Stored => self.pyramid.read_brick_encoded_async(bricks, at).await,
            BrickEncoding::Raw => Ok(not_fill(
                self.pyramid.read_brick_bytes_async(bricks, at).await?,
            )),
        }
    }
}

/// Decoded bytes, or `None` when they are all the fill value (zero).
fn not_fill(raw: Vec<u8>) -> Option<Vec<u8>> {
    (!raw.iter().all(|&b| b == 0)).then_some(raw)
}

/// Where a batch's bricks are kept between requests (the server's memory cache).
/// A brick is kept as its bytes, an empty brick as no bytes.
pub(crate) trait BrickCache: Send + Sync + 'static {
    /// A kept brick, or `None` when it is not kept.
    fn get(&self, at: &BrickAt) -> Option<Bytes>;
    /// Keeps a brick just read.
    fn keep(&self, at: &BrickAt, bytes: Bytes);
}

/// A brick's bytes as a batch answers them: `None` for an empty brick.
fn present(bytes: Bytes) -> Option<Bytes> {
    (!bytes.is_empty()).then_some(bytes)
}

/// A brick's answer without reading the store: its error when the dataset has no such brick,
/// or the brick kept in `cache`; `None` when it must be read.
fn known(arrays: &ImageArrays, cache: &impl BrickCache, at: &BrickAt) -> Option<BrickRead> {
    if let Err(e) = arrays.check(at) {
        return Some(Err(e.into()));
    }
    cache.get(at).map(|kept| Ok(present(kept)))
}

/// Keeps a brick just read (`None`: empty) in `cache`, and gives it back as a batch answers it.
fn keep(cache: &impl BrickCache, at: &BrickAt, read: Option<Vec<u8>>) -> Option<Bytes> {
    let bytes = read.map(Bytes::from).unwrap_or_default();
    cache.keep(at, bytes.clone());
    present(bytes)
}

/// Why one brick of a batch could not be read; its message goes into the brick's entry.
#[derive(Debug, thiserror::Error)]
pub(crate) enum BrickReadError {
    /// The dataset has no such level, channel or brick.
    #[error(transparent)]
    NoSuchBrick(#[from] NoSuchBrick),
    /// The store could not give the brick (names the brick and its key).
    #[error(transparent)]
    Store(#[from] PyramidError),
}

/// One brick of a batch: its bytes (`None`: empty), or why it could not be read.
pub(crate) type BrickRead = Result<Option<Bytes>, BrickReadError>;

/// Reads a batch's bricks, each from `cache` when kept there, else from the store and then
/// kept: from a folder in parallel on the blocking pool, one brick per core; from an object
/// store as one task per brick on the store's runtime (the one its client runs on),
/// [`REMOTE_READS`] in flight: no thread waits on the network, and the runtime's workers
/// decode side by side. A brick that cannot be read is its error; the rest are still read.
pub(crate) async fn read_bricks<C: BrickCache>(
    arrays: Arc<ImageArrays>,
    bricks: Arc<[BrickAt]>,
    encoding: BrickEncoding,
    cache: Arc<C>,
) -> Vec<BrickRead> {
    let Some((remote, runtime)) = arrays.remote.clone() else {
        let read_all = move || {
            bricks
                .par_iter()
                .map(|at| {
                    known(&arrays, &*cache, at)
                        .unwrap_or_else(|| Ok(keep(&*cache, at, arrays.read(at, encoding)?)))
                })
                .collect()
        };
        return tokio::task::spawn_blocking(read_all)
            .await
            .expect("reading a batch panicked");
    };
    // One task per brick, so that the runtime's workers decode bricks side by side (zarrs
    // decodes inside the future that reads).
    let tasks = bricks.iter().copied().map(|at| {
        let (arrays, remote, cache) = (arrays.clone(), remote.clone(), cache.clone());
        runtime.spawn(async move {
            if let Some(answer) = known(&arrays, &*cache, &at) {
                return answer;
            }
            let read = arrays.read_async(&remote, &at, encoding).await?;
            Ok(keep(&*cache, &at, read))
        })
    });
    futures::stream::iter(tasks)
        .buffered(REMOTE_READS)
        .map(|task| task.expect("reading a brick panicked"))
        .collect()
        .await
}

/// A batch's document: its header and payload, from the bricks read ([`read_bricks`], in the
/// batch's order).
pub(crate) fn batch_document(
    arrays: &ImageArrays,
    bricks: &[BrickAt],
    encoding: BrickEncoding,
    results: Vec<BrickRead>,
) -> (BrickBatchHeader, Vec<u8>) {
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
                Err(e) => (BrickStatus::Error, 0, 0, Some(e.to_string())),
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
        data_type: arrays.data_type,
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
        let refused = |query: &str| parse_batch(query, &limits).unwrap_err();
        let too_many = refused("b=0,0,0,0,0;0,0,0,0,1;0,0,0,0,2");
        assert_eq!(too_many, BatchError::TooManyBricks { max_bricks: 2 });
        assert!(too_many.is_over_limit());
        assert_eq!(too_many.to_string(), "more than 2 bricks in one batch");
        for (query, message) in [
            (
                "b=0,0,0,0",
                "brick '0,0,0,0' is not five integers L,C,z,y,x",
            ),
            ("b=0,0,x", "brick '0,0,x' is not five integers L,C,z,y,x"),
            (
                "b=4294967296,0,0,0,0",
                "brick '4294967296,0,0,0,0': 4294967296 too large",
            ),
            ("b=%FF", "parameter 'b' is not UTF-8"),
            (
                "b=0,0,0,0,0&encoding=zip",
                "encoding 'zip' is not 'stored' or 'raw'",
            ),
            ("b=0,0,0,0,0&x=1", "unknown parameter 'x'"),
            ("", "no brick requested: give b=L,C,z,y,x[;L,C,z,y,x...]"),
        ] {
            let e = refused(query);
            assert!(!e.is_over_limit(), "{query}");
            assert_eq!(e.to_string(), message, "{query}");
        }
        let bytes = limits.check_bytes(3, 1 << 19).unwrap_err();
        assert!(bytes.is_over_limit());
        assert_eq!(
            bytes.to_string(),
            "3 bricks of 524288 bytes exceed the batch limit of 1048576 bytes"
        );
        assert_eq!(limits.check_bytes(2, 1 << 19), Ok(()));
    }

    #[test]
    fn missing_bricks_are_named() {
        let cases = [
            (
                NoSuchBrick::Level {
                    level: 4,
                    levels: 2,
                },
                "level 4 does not exist (the dataset has 2)",
            ),
            (
                NoSuchBrick::Channel {
                    channel: 5,
                    channels: 2,
                },
                "channel 5 does not exist (the dataset has 2)",
            ),
            (
                NoSuchBrick::Brick {
                    brick: [99, 0, 0],
                    level: 0,
                    grid: [3, 5, 4],
                },
                "brick [99, 0, 0] lies outside level 0 ([3, 5, 4] bricks, z, y, x)",
            ),
        ];
        for (error, message) in cases {
            assert_eq!(error.to_string(), message);
        }
    }
}
