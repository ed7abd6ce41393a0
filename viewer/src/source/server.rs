//! The `brickserver` protocol as the viewer speaks it, with no I/O of its own: which URLs to
//! ask for, and how to read the answers into a [`VolumeInfo`] and bricks. The transport is a
//! [`Get`]: blocking `ureq` on worker threads natively ([`super::http`]), the browser's
//! `fetch` in the web viewer.
//!
//! It reads `{url}/{name}/zarr.json` (or `.zattrs` for Zarr v2) and each level's array
//! metadata for the multiscales and region metadata, `{url}/{name}/minmax?channel=C` for each
//! channel's whole min/max hierarchy (an `RSMINMAX` document), and
//! `{url}/{name}/bricks?encoding=raw&b=L,C,z,y,x;...` for batches of decoded bricks (an
//! `RSBRICKS` document), at most [`MAX_BATCH`] bricks and [`MAX_BATCH_BYTES`] decoded bytes
//! per request (the server's caps).

use std::sync::Arc;

use residency_schemas::ome::{ImageAttributes, PyramidLayout, ZarrFormat};
use residency_schemas::server::ApiError;
use residency_schemas::wire::{
    BRICKS_MAGIC, BrickBatchHeader, BrickEncoding, BrickStatus, MINMAX_MAGIC,
    MinMaxHierarchyHeader, decode_framed,
};
use residency_schemas::zarr::ArrayDescription;

use super::regions;
use super::{BrickKey, BrickVoxels, MinMaxGrid, SourceError, VolumeInfo};

/// Most bricks asked for in one `/bricks` request; larger fetches are split.
pub const MAX_BATCH: usize = 256;

/// Most decoded bytes (bricks × brick voxels × sample size) asked for in one `/bricks`
/// request; larger fetches are split.
pub const MAX_BATCH_BYTES: u64 = 64 << 20;

/// The outcome of a GET: the body of a 200, or the status of anything else with the
/// server's message.
#[derive(Debug)]
pub enum Reply {
    /// HTTP 200 and its body.
    Ok(Vec<u8>),
    /// Any other status, and a message for people (the API's `{"error": ...}` text, or
    /// what `401` means).
    Status(u16, String),
}

impl Reply {
    /// The reply to a request answered with `status` and `body`; `token_sent` says whether
    /// the request carried a bearer token (what a `401` means depends on it).
    pub fn new(status: u16, body: Vec<u8>, token_sent: bool) -> Self {
        match status {
            200 => Self::Ok(body),
            401 if token_sent => Self::Status(401, "the server refused the token".into()),
            401 => Self::Status(401, "the server needs a token (--token-file)".into()),
            _ => {
                // The API answers errors as `{"error": "..."}`; anything else is shown as text.
                let text = serde_json::from_slice::<ApiError>(&body).map_or_else(
                    |_| String::from_utf8_lossy(&body).trim().to_string(),
                    |e| e.error,
                );
                Self::Status(status, text.chars().take(300).collect())
            }
        }
    }

    /// The body of a 200; any other status is an error naming `url`.
    ///
    /// # Errors
    /// [`SourceError::Http`] with the status and the server's message.
    pub fn ok(self, url: &str) -> Result<Vec<u8>, SourceError> {
        match self {
            Self::Ok(body) => Ok(body),
            Self::Status(status, message) => Err(SourceError::Http {
                url: url.to_string(),
                status,
                message,
            }),
        }
    }

    /// The body of a 200, `None` for a 404; any other status is an error naming `url`.
    ///
    /// # Errors
    /// [`SourceError::Http`] with the status and the server's message.
    pub fn found(self, url: &str) -> Result<Option<Vec<u8>>, SourceError> {
        match self {
            Self::Status(404, _) => Ok(None),
            other => other.ok(url).map(Some),
        }
    }
}

/// An HTTP GET: blocking natively, awaited in the browser. Errors are transport failures
/// (the server cannot be reached); statuses are [`Reply::Status`].
#[allow(async_fn_in_trait)] // implemented and awaited inside this crate only
pub trait Get {
    /// Gets `url`.
    ///
    /// # Errors
    /// A [`SourceError`] naming `url` when the server cannot be reached or its answer read.
    async fn get(&self, url: &str) -> Result<Reply, SourceError>;
}

/// The URL of dataset `dataset` on the server at `server_url` (e.g. `http://127.0.0.1:8000`).
pub fn dataset_url(server_url: &str, dataset: &str) -> String {
    format!("{}/{dataset}", server_url.trim_end_matches('/'))
}

/// Loads the description of the dataset at `base` ([`dataset_url`]) named `dataset`: its
/// multiscales and array metadata, then, when the store has usable region metadata, every
/// channel's min/max hierarchy (`minmax` stays `None`, with a warning, when it has none).
///
/// # Errors
///
/// A server that cannot be reached, a dataset that does not exist, and metadata that cannot be
/// read are errors naming the URL.
pub async fn open<G: Get>(http: &G, base: &str, dataset: &str) -> Result<VolumeInfo, SourceError> {
    let url = |rest: &str| format!("{base}/{rest}");
    let (format, group_url, group_doc) = {
        let v3 = url("zarr.json");
        let v2 = url(".zattrs");
        if let Some(body) = http.get(&v3).await?.found(&v3)? {
            (ZarrFormat::V3, v3, body)
        } else if let Some(body) = http.get(&v2).await?.found(&v2)? {
            (ZarrFormat::V2, v2, body)
        } else {
            return Err(SourceError::NoSuchDataset {
                base: base.to_string(),
            });
        }
    };
    let group = ImageAttributes::parse(format, &group_doc, &group_url)?;
    let layout = PyramidLayout::of(group.image(), &group_url)?;
    let mut arrays = Vec::with_capacity(layout.level_paths.len());
    for p in &layout.level_paths {
        let array_url = url(&format!("{p}/{}", format.array_key()));
        let body = http.get(&array_url).await?.ok(&array_url)?;
        arrays.push(ArrayDescription::parse(format, &body, &array_url)?);
    }
    let mut info = VolumeInfo::from_ome(dataset, &group, &layout, &arrays, base)?;
    if regions::usable_region_metadata(group.regions.as_ref(), base) {
        info.minmax = load_minmax(http, base, &info).await?;
    }
    Ok(info)
}

/// Every channel's min/max hierarchy, or `None` (with a warning) when the server has none.
async fn load_minmax<G: Get>(
    http: &G,
    base: &str,
    info: &VolumeInfo,
) -> Result<Option<Vec<Vec<Vec<MinMaxGrid>>>>, SourceError> {
    let mut all = Vec::new();
    for c in 0..info.channels.len() {
        let url = format!("{base}/minmax?channel={c}");
        let Some(body) = http.get(&url).await?.found(&url)? else {
            regions::warn_no_region_metadata(base);
            return Ok(None);
        };
        all.push(parse_minmax(info, c, &body, &url)?);
    }
    Ok(Some(all))
}

/// Decodes channel `channel`'s `RSMINMAX` document (from `url`) and checks it against `info`.
///
/// # Errors
/// A [`SourceError`] naming `url`: a document that cannot be decoded, or that is for another
/// channel, sample type or set of levels than `info`'s.
pub fn parse_minmax(
    info: &VolumeInfo,
    channel: usize,
    body: &[u8],
    url: &str,
) -> Result<Vec<Vec<MinMaxGrid>>, SourceError> {
    let (header, payload) =
        decode_framed::<MinMaxHierarchyHeader>(MINMAX_MAGIC, body).map_err(|source| {
            SourceError::CorruptMinMax {
                url: url.to_string(),
                source,
            }
        })?;
    if header.channel != channel {
        return Err(SourceError::MinMaxChannel {
            url: url.to_string(),
            channel: header.channel,
        });
    }
    if header.data_type != info.sample_type {
        return Err(SourceError::MinMaxType {
            url: url.to_string(),
            found: header.data_type,
            image: info.sample_type,
        });
    }
    if header.levels.len() != info.levels.len() {
        return Err(SourceError::MinMaxLevelCount {
            url: url.to_string(),
            levels: header.levels.len(),
            image_levels: info.levels.len(),
        });
    }
    header
        .levels
        .iter()
        .zip(&info.levels)
        .enumerate()
        .map(|(i, (block, level))| {
            if block.level != i || block.shape != level.shape {
                return Err(SourceError::MinMaxLevel {
                    url: url.to_string(),
                    level: block.level,
                    shape: block.shape,
                    index: i,
                    image_shape: level.shape,
                });
            }
            block
                .grids
                .iter()
                .map(|g| {
                    let bytes = usize::try_from(g.offset)
                        .ok()
                        .zip(usize::try_from(g.length).ok())
                        .and_then(|(o, l)| payload.get(o..o.checked_add(l)?))
                        .ok_or_else(|| SourceError::MinMaxGridRange {
                            url: url.to_string(),
                            level: i,
                            offset: g.offset,
                            length: g.length,
                            payload: payload.len(),
                        })?;
                    let values = header.data_type.decode_le_to_f64(bytes).map_err(|source| {
                        SourceError::CorruptMinMaxGrid {
                            url: url.to_string(),
                            source,
                        }
                    })?;
                    Ok(MinMaxGrid::from_values(
                        g.cell_shape,
                        g.grid_shape,
                        &values,
                        url,
                    )?)
                })
                .collect()
        })
        .collect()
}

/// Bricks per request: within both of the server's caps, at least one.
pub fn batch_size(info: &VolumeInfo) -> usize {
    ((MAX_BATCH_BYTES / info.brick_bytes().max(1)) as usize).clamp(1, MAX_BATCH)
}

/// The `/bricks` URL asking dataset `base` for `keys`, decoded (`encoding=raw`).
pub fn batch_url(base: &str, keys: &[BrickKey]) -> String {
    let list: Vec<String> = keys
        .iter()
        .map(|k| {
            let [z, y, x] = k.brick;
            format!("{},{},{z},{y},{x}", k.level, k.channel)
        })
        .collect();
    format!("{base}/bricks?encoding=raw&b={}", list.join(";"))
}

/// Fetches one batch of at most [`batch_size`] valid keys of dataset `base`: one result per
/// key; a failed request fails every key of the batch with its message
/// ([`SourceError::Batch`]).
pub async fn fetch_batch<G: Get>(
    http: &G,
    base: &str,
    info: &VolumeInfo,
    keys: &[BrickKey],
) -> Vec<Result<BrickVoxels, SourceError>> {
    let url = batch_url(base, keys);
    let answer = http.get(&url).await.and_then(|reply| reply.ok(&url));
    match answer.and_then(|body| parse_batch(info, keys, &body, &url)) {
        Ok(results) => results,
        Err(e) => {
            let batch = Arc::new(e);
            keys.iter()
                .map(|&key| {
                    Err(SourceError::Batch {
                        key,
                        batch: Arc::clone(&batch),
                    })
                })
                .collect()
        }
    }
}

/// Decodes an `RSBRICKS` answer (from `url`) to the batch `keys`: one result per key, in order.
///
/// # Errors
///
/// A document that cannot be decoded, or does not answer `keys` with `info`'s bricks, is an
/// error as a whole; a brick the server could not read is an error for that brick only.
pub fn parse_batch(
    info: &VolumeInfo,
    keys: &[BrickKey],
    body: &[u8],
    url: &str,
) -> Result<Vec<Result<BrickVoxels, SourceError>>, SourceError> {
    // Name the document without its long brick list.
    let shown = url.split_once('&').map_or(url, |(a, _)| a);
    let (header, payload) =
        decode_framed::<BrickBatchHeader>(BRICKS_MAGIC, body).map_err(|source| {
            SourceError::CorruptBatch {
                url: shown.to_string(),
                source,
            }
        })?;
    if header.encoding != BrickEncoding::Raw {
        return Err(SourceError::BatchEncoding {
            url: shown.to_string(),
            encoding: header.encoding,
        });
    }
    if header.data_type != info.sample_type {
        return Err(SourceError::BatchType {
            url: shown.to_string(),
            found: header.data_type,
            image: info.sample_type,
        });
    }
    if header.brick_shape != info.brick_shape {
        return Err(SourceError::BatchBrickShape {
            url: shown.to_string(),
            found: header.brick_shape,
            expected: info.brick_shape,
        });
    }
    if header.bricks.len() != keys.len() {
        return Err(SourceError::BatchCount {
            url: shown.to_string(),
            answered: header.bricks.len(),
            asked: keys.len(),
        });
    }
    let expected = info.brick_bytes() as usize;
    Ok(header
        .bricks
        .iter()
        .zip(keys)
        .map(|(entry, key)| {
            if entry.level != key.level || entry.channel != key.channel || entry.brick != key.brick
            {
                return Err(SourceError::BatchOrder {
                    url: shown.to_string(),
                    level: entry.level,
                    channel: entry.channel,
                    brick: entry.brick,
                    key: *key,
                });
            }
            match entry.status {
                BrickStatus::Empty => Ok(BrickVoxels::Empty),
                BrickStatus::Error => Err(SourceError::ServerBrick {
                    url: shown.to_string(),
                    key: *key,
                    reason: entry
                        .error
                        .clone()
                        .unwrap_or_else(|| "no reason given".to_string()),
                }),
                BrickStatus::Ok => {
                    let bytes = usize::try_from(entry.offset)
                        .ok()
                        .filter(|_| entry.length as usize == expected)
                        .and_then(|o| payload.get(o..o.checked_add(expected)?))
                        .ok_or_else(|| SourceError::BatchRange {
                            url: shown.to_string(),
                            key: *key,
                            offset: entry.offset,
                            length: entry.length,
                            expected,
                            payload: payload.len(),
                        })?;
                    Ok(BrickVoxels::from_le_bytes(info.sample_type, bytes))
                }
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use residency_schemas::wire::{BrickEntry, MinMaxGridBlock, MinMaxLevelBlock, encode_framed};

    use super::*;
    use crate::source::{LevelInfo, SampleType};

    /// The volume of `http://h/v`, for the document parsers.
    fn info() -> VolumeInfo {
        VolumeInfo {
            name: "v".into(),
            sample_type: SampleType::I16,
            channels: vec!["a".into(), "b".into()],
            display: vec![crate::source::ChannelDisplay::default(); 2],
            voxel_size: [1.0; 3],
            unit: None,
            brick_shape: [1, 1, 2],
            levels: vec![LevelInfo {
                shape: [1, 1, 4],
                factor: [1; 3],
            }],
            minmax: None,
        }
    }

    fn key(x: u64) -> BrickKey {
        BrickKey {
            level: 0,
            channel: 1,
            brick: [0, 0, x],
        }
    }

    fn entry(x: u64, status: BrickStatus, offset: u64, length: u64) -> BrickEntry {
        BrickEntry {
            level: 0,
            channel: 1,
            brick: [0, 0, x],
            status,
            offset,
            length,
            error: (status == BrickStatus::Error).then(|| "bad chunk".into()),
        }
    }

    fn batch(bricks: Vec<BrickEntry>, payload: &[u8]) -> Vec<u8> {
        let header = BrickBatchHeader {
            encoding: BrickEncoding::Raw,
            data_type: SampleType::I16,
            brick_shape: [1, 1, 2],
            bricks,
        };
        encode_framed(BRICKS_MAGIC, &header, payload)
    }

    #[test]
    fn brick_batches_decode_per_brick() {
        let info = info();
        let payload: Vec<u8> = [-3i16, 7].iter().flat_map(|v| v.to_le_bytes()).collect();
        let doc = batch(
            vec![
                entry(0, BrickStatus::Empty, 0, 0),
                entry(1, BrickStatus::Ok, 0, 4),
            ],
            &payload,
        );
        let got = parse_batch(&info, &[key(0), key(1)], &doc, "u").unwrap();
        let got: Vec<BrickVoxels> = got.into_iter().map(Result::unwrap).collect();
        assert_eq!(got, [BrickVoxels::Empty, BrickVoxels::I16(vec![-3, 7])]);

        let doc = batch(vec![entry(1, BrickStatus::Error, 0, 0)], &[]);
        let e = parse_batch(
            &info,
            &[key(1)],
            &doc,
            "http://h/v/bricks?encoding=raw&b=0,1,0,0,1",
        );
        let e = e.unwrap().pop().unwrap().unwrap_err();
        assert_eq!(
            e.to_string(),
            format!(
                "http://h/v/bricks?encoding=raw: brick {:?}: the server could not read it: bad chunk",
                key(1)
            )
        );
    }

    #[test]
    fn corrupt_batches_are_errors_not_panics() {
        let info = info();
        let e = parse_batch(&info, &[key(0)], b"garbage", "u").unwrap_err();
        assert_eq!(
            crate::error_chain(&e),
            "u: corrupt brick batch: not a RSBRICKS document (bad magic)"
        );
        // A brick running past the payload.
        let doc = batch(vec![entry(0, BrickStatus::Ok, 2, 4)], &[0; 4]);
        let e = parse_batch(&info, &[key(0)], &doc, "u").unwrap();
        assert_eq!(
            e.into_iter().next().unwrap().unwrap_err().to_string(),
            format!(
                "u: brick {:?} at bytes 2+4 is not 4 bytes inside the 4-byte payload",
                key(0)
            )
        );
        // Answers out of order, or too few.
        let doc = batch(vec![entry(1, BrickStatus::Empty, 0, 0)], &[]);
        let e = parse_batch(&info, &[key(0)], &doc, "u").unwrap();
        assert_eq!(
            e.into_iter().next().unwrap().unwrap_err().to_string(),
            format!(
                "u: answered brick 0,1,[0, 0, 1] where {:?} was asked",
                key(0)
            )
        );
        let e = parse_batch(&info, &[key(0), key(1)], &doc, "u").unwrap_err();
        assert_eq!(e.to_string(), "u: 1 bricks answered for 2 asked");
    }

    #[test]
    fn minmax_documents_decode_and_are_checked() {
        let info = info();
        let header = |channel: usize, length: u64| MinMaxHierarchyHeader {
            channel,
            data_type: SampleType::I16,
            halo: 1,
            levels: vec![MinMaxLevelBlock {
                level: 0,
                shape: [1, 1, 4],
                grids: vec![MinMaxGridBlock {
                    cell_shape: [8, 8, 8],
                    grid_shape: [1, 1, 1],
                    offset: 0,
                    length,
                }],
            }],
        };
        let payload: Vec<u8> = [-5i16, 9].iter().flat_map(|v| v.to_le_bytes()).collect();
        let doc = encode_framed(MINMAX_MAGIC, &header(1, 4), &payload);
        let grids = parse_minmax(&info, 1, &doc, "m").unwrap();
        assert_eq!(
            (grids[0][0].min.clone(), grids[0][0].max.clone()),
            (vec![-5.0], vec![9.0])
        );
        let e = parse_minmax(&info, 0, &doc, "m").unwrap_err();
        assert_eq!(e.to_string(), "m: min/max document is for channel 1");
        let doc = encode_framed(MINMAX_MAGIC, &header(1, 8), &payload);
        let e = parse_minmax(&info, 1, &doc, "m").unwrap_err();
        assert_eq!(
            e.to_string(),
            "m: min/max grid of level 0 at bytes 0+8 runs past the 4-byte payload"
        );
    }
}
