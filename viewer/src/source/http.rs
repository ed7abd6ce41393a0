//! [`HttpSource`]: a `brickserver` over HTTP, with a blocking client.
//!
//! It reads `{url}/{name}/zarr.json` (or `.zattrs` for Zarr v2) and each level's array
//! metadata for the multiscales and region metadata, `{url}/{name}/minmax?channel=C` for each
//! channel's whole min/max hierarchy (an `RSMINMAX` document), and
//! `{url}/{name}/bricks?encoding=raw&b=L,C,z,y,x;...` for batches of decoded bricks (an
//! `RSBRICKS` document), at most [`MAX_BATCH`] bricks and [`MAX_BATCH_BYTES`] decoded bytes
//! per request (the server's caps), batches in parallel.

use std::time::Duration;

use anyhow::{Context, Result, anyhow, bail, ensure};
use rayon::prelude::*;
use residency_schemas::server::ApiError;
use residency_schemas::wire::{
    BRICKS_MAGIC, BrickBatchHeader, BrickEncoding, BrickStatus, MINMAX_MAGIC,
    MinMaxHierarchyHeader, decode_framed,
};

use super::ome;
use super::{BrickKey, BrickSource, BrickVoxels, MinMaxGrid, SampleType, VolumeInfo};
use residency_schemas::ome::{ImageAttributes, PyramidLayout, ZarrFormat};
use residency_schemas::zarr::ArrayDescription;

/// Most bricks asked for in one `/bricks` request; larger fetches are split.
pub const MAX_BATCH: usize = 256;

/// Most decoded bytes (bricks × brick voxels × sample size) asked for in one `/bricks`
/// request; larger fetches are split.
pub const MAX_BATCH_BYTES: u64 = 64 << 20;

/// Time allowed for one whole request, connection to last byte.
pub const REQUEST_TIMEOUT: Duration = Duration::from_mins(2);

/// A dataset on a `brickserver`.
pub struct HttpSource {
    base: String,
    agent: ureq::Agent,
    token: Option<String>,
    info: VolumeInfo,
}

impl std::fmt::Debug for HttpSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HttpSource")
            .field("base", &self.base)
            .field("info", &self.info)
            .finish_non_exhaustive()
    }
}

/// The outcome of a GET: the body of a 200, or the status of anything else.
enum Got {
    Ok(Vec<u8>),
    Status(u16, String),
}

impl HttpSource {
    /// Opens dataset `dataset` on the server at `server_url` (e.g. `http://127.0.0.1:8000`):
    /// loads its metadata and, when the server has region metadata, every channel's min/max
    /// hierarchy. Without region metadata, `minmax` is `None` and a warning says so.
    pub fn open(server_url: &str, dataset: &str) -> Result<Self> {
        Self::open_with_token(server_url, dataset, None)
    }

    /// [`HttpSource::open`] for a server started with `--token-file`: every request carries
    /// `Authorization: Bearer TOKEN`.
    pub fn open_with_token(server_url: &str, dataset: &str, token: Option<&str>) -> Result<Self> {
        let agent: ureq::Agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_global(Some(REQUEST_TIMEOUT))
            .build()
            .into();
        let base = format!("{}/{dataset}", server_url.trim_end_matches('/'));
        let mut source = Self {
            base,
            agent,
            token: token.map(str::to_string),
            info: VolumeInfo {
                name: dataset.to_string(),
                sample_type: SampleType::U8,
                channels: Vec::new(),
                display: Vec::new(),
                voxel_size: [1.0; 3],
                brick_shape: [1; 3],
                levels: Vec::new(),
                minmax: None,
            },
        };
        let (format, group_url, group_doc) = {
            let v3 = source.url("zarr.json");
            match source.get(&v3)? {
                Got::Ok(body) => (ZarrFormat::V3, v3, body),
                Got::Status(404, _) => {
                    let v2 = source.url(".zattrs");
                    match source.get(&v2)? {
                        Got::Ok(body) => (ZarrFormat::V2, v2, body),
                        Got::Status(404, _) => bail!(
                            "{}: no such dataset on the server (neither zarr.json nor .zattrs \
                             found)",
                            source.base
                        ),
                        Got::Status(s, msg) => bail!("{v2}: HTTP {s}: {msg}"),
                    }
                }
                Got::Status(s, msg) => bail!("{v3}: HTTP {s}: {msg}"),
            }
        };
        let group = ImageAttributes::parse(format, &group_doc, &group_url)?;
        let layout = PyramidLayout::of(group.image(), &group_url)?;
        let arrays = layout
            .level_paths
            .iter()
            .map(|p| {
                let url = source.url(&format!("{p}/{}", format.array_key()));
                let body = source.get_ok(&url)?;
                Ok(ArrayDescription::parse(format, &body, &url)?)
            })
            .collect::<Result<Vec<_>>>()?;
        let info = ome::volume_info(dataset, &group, &layout, &arrays, &source.base)?;
        source.info = info;
        source.info.minmax = if ome::usable_region_metadata(group.regions.as_ref(), &source.base) {
            source.load_minmax()?
        } else {
            None
        };
        Ok(source)
    }

    fn url(&self, rest: &str) -> String {
        format!("{}/{rest}", self.base)
    }

    fn get(&self, url: &str) -> Result<Got> {
        let mut request = self.agent.get(url);
        if let Some(token) = &self.token {
            request = request.header("Authorization", &format!("Bearer {token}"));
        }
        let mut response = request
            .call()
            .map_err(|e| anyhow!("{url}: cannot reach the brick server: {e}"))?;
        let status = response.status().as_u16();
        let body = response
            .body_mut()
            .with_config()
            .limit(u64::MAX)
            .read_to_vec()
            .map_err(|e| anyhow!("{url}: cannot read the response: {e}"))?;
        Ok(if status == 200 {
            Got::Ok(body)
        } else if status == 401 {
            Got::Status(
                401,
                if self.token.is_some() {
                    "the server refused the token".into()
                } else {
                    "the server needs a token (--token-file)".into()
                },
            )
        } else {
            // The API answers errors as `{"error": "..."}`; anything else is shown as text.
            let text = serde_json::from_slice::<ApiError>(&body).map_or_else(
                |_| String::from_utf8_lossy(&body).trim().to_string(),
                |e| e.error,
            );
            Got::Status(status, text.chars().take(300).collect())
        })
    }

    fn get_ok(&self, url: &str) -> Result<Vec<u8>> {
        match self.get(url)? {
            Got::Ok(body) => Ok(body),
            Got::Status(s, msg) => bail!("{url}: HTTP {s}: {msg}"),
        }
    }

    /// Every channel's min/max hierarchy, or `None` (with a warning) when the server has none.
    fn load_minmax(&self) -> Result<Option<Vec<Vec<Vec<MinMaxGrid>>>>> {
        let mut all = Vec::new();
        for c in 0..self.info.channels.len() {
            let url = self.url(&format!("minmax?channel={c}"));
            match self.get(&url)? {
                Got::Ok(body) => all.push(self.parse_minmax(c, &body, &url)?),
                Got::Status(404, _) => {
                    ome::warn_no_region_metadata(&self.base);
                    return Ok(None);
                }
                Got::Status(s, msg) => bail!("{url}: HTTP {s}: {msg}"),
            }
        }
        Ok(Some(all))
    }

    fn parse_minmax(&self, channel: usize, body: &[u8], url: &str) -> Result<Vec<Vec<MinMaxGrid>>> {
        let (header, payload) = decode_framed::<MinMaxHierarchyHeader>(MINMAX_MAGIC, body)
            .with_context(|| format!("{url}: corrupt min/max document"))?;
        let info = &self.info;
        ensure!(
            header.channel == channel,
            "{url}: min/max document is for channel {}",
            header.channel
        );
        ensure!(
            header.data_type == info.sample_type,
            "{url}: min/max values are {} but the image is {}",
            header.data_type,
            info.sample_type.zarr_name()
        );
        ensure!(
            header.levels.len() == info.levels.len(),
            "{url}: min/max document has {} levels, the image {}",
            header.levels.len(),
            info.levels.len()
        );
        header
            .levels
            .iter()
            .zip(&info.levels)
            .enumerate()
            .map(|(i, (block, level))| {
                ensure!(
                    block.level == i && block.shape == level.shape,
                    "{url}: min/max level {} {:?} does not match image level {i} {:?}",
                    block.level,
                    block.shape,
                    level.shape
                );
                block
                    .grids
                    .iter()
                    .map(|g| {
                        let bytes = usize::try_from(g.offset)
                            .ok()
                            .zip(usize::try_from(g.length).ok())
                            .and_then(|(o, l)| payload.get(o..o.checked_add(l)?))
                            .with_context(|| {
                                format!(
                                    "{url}: min/max grid of level {i} at bytes {}+{} runs past \
                                     the {}-byte payload",
                                    g.offset,
                                    g.length,
                                    payload.len()
                                )
                            })?;
                        let values = header
                            .data_type
                            .decode_le_to_f64(bytes)
                            .with_context(|| format!("{url}: corrupt min/max grid"))?;
                        ome::minmax_grid(g.cell_shape, g.grid_shape, &values, url)
                    })
                    .collect()
            })
            .collect()
    }

    /// Bricks per request: within both of the server's caps, at least one.
    pub fn batch_size(&self) -> usize {
        let brick =
            self.info.brick_shape.iter().product::<u64>() * self.info.sample_type.bytes() as u64;
        ((MAX_BATCH_BYTES / brick.max(1)) as usize).clamp(1, MAX_BATCH)
    }

    /// Fetches one batch of at most [`HttpSource::batch_size`] valid keys.
    fn fetch_batch(&self, keys: &[BrickKey]) -> Vec<Result<BrickVoxels>> {
        let list: Vec<String> = keys
            .iter()
            .map(|k| {
                let [z, y, x] = k.brick;
                format!("{},{},{z},{y},{x}", k.level, k.channel)
            })
            .collect();
        let url = self.url(&format!("bricks?encoding=raw&b={}", list.join(";")));
        match self
            .get_ok(&url)
            .and_then(|body| self.parse_batch(keys, &body, &url))
        {
            Ok(results) => results,
            Err(e) => {
                let msg = format!("{e:#}");
                keys.iter()
                    .map(|k| Err(anyhow!("brick {k:?}: {msg}")))
                    .collect()
            }
        }
    }

    fn parse_batch(
        &self,
        keys: &[BrickKey],
        body: &[u8],
        url: &str,
    ) -> Result<Vec<Result<BrickVoxels>>> {
        // Name the document without its long brick list.
        let shown = url.split_once('&').map_or(url, |(a, _)| a);
        let (header, payload) = decode_framed::<BrickBatchHeader>(BRICKS_MAGIC, body)
            .with_context(|| format!("{shown}: corrupt brick batch"))?;
        let info = &self.info;
        ensure!(
            header.encoding == BrickEncoding::Raw,
            "{shown}: asked for raw bricks, got {:?}",
            header.encoding
        );
        ensure!(
            header.data_type == info.sample_type,
            "{shown}: bricks are {} but the image is {}",
            header.data_type,
            info.sample_type.zarr_name()
        );
        ensure!(
            header.brick_shape == info.brick_shape,
            "{shown}: bricks of {:?}, expected {:?}",
            header.brick_shape,
            info.brick_shape
        );
        ensure!(
            header.bricks.len() == keys.len(),
            "{shown}: {} bricks answered for {} asked",
            header.bricks.len(),
            keys.len()
        );
        let expected = info.brick_shape.iter().product::<u64>() as usize * info.sample_type.bytes();
        Ok(header
            .bricks
            .iter()
            .zip(keys)
            .map(|(entry, key)| {
                ensure!(
                    entry.level == key.level
                        && entry.channel == key.channel
                        && entry.brick == key.brick,
                    "{shown}: answered brick {},{},{:?} where {key:?} was asked",
                    entry.level,
                    entry.channel,
                    entry.brick
                );
                match entry.status {
                    BrickStatus::Empty => Ok(BrickVoxels::Empty),
                    BrickStatus::Error => bail!(
                        "{shown}: brick {key:?}: the server could not read it: {}",
                        entry.error.as_deref().unwrap_or("no reason given")
                    ),
                    BrickStatus::Ok => {
                        let bytes = usize::try_from(entry.offset)
                            .ok()
                            .filter(|_| entry.length as usize == expected)
                            .and_then(|o| payload.get(o..o.checked_add(expected)?))
                            .with_context(|| {
                                format!(
                                    "{shown}: brick {key:?} at bytes {}+{} is not {expected} \
                                     bytes inside the {}-byte payload",
                                    entry.offset,
                                    entry.length,
                                    payload.len()
                                )
                            })?;
                        Ok(decode_le(info.sample_type, bytes))
                    }
                }
            })
            .collect())
    }
}

/// Little-endian samples as typed voxels.
fn decode_le(t: SampleType, bytes: &[u8]) -> BrickVoxels {
    fn le<const N: usize, T>(bytes: &[u8], f: fn([u8; N]) -> T) -> Vec<T> {
        bytes
            .chunks_exact(N)
            .map(|b| f(b.try_into().expect("N bytes")))
            .collect()
    }
    match t {
        SampleType::U8 => BrickVoxels::U8(bytes.to_vec()),
        SampleType::U16 => BrickVoxels::U16(le(bytes, u16::from_le_bytes)),
        SampleType::I16 => BrickVoxels::I16(le(bytes, i16::from_le_bytes)),
        SampleType::U32 => BrickVoxels::U32(le(bytes, u32::from_le_bytes)),
        SampleType::I32 => BrickVoxels::I32(le(bytes, i32::from_le_bytes)),
        SampleType::F32 => BrickVoxels::F32(le(bytes, f32::from_le_bytes)),
    }
}

impl BrickSource for HttpSource {
    fn info(&self) -> &VolumeInfo {
        &self.info
    }

    fn fetch(&self, keys: &[BrickKey]) -> Vec<Result<BrickVoxels>> {
        // Invalid keys are answered here; the rest go to the server in batches.
        let mut results: Vec<Option<Result<BrickVoxels>>> = keys
            .iter()
            .map(|k| self.info.check_key(k).err().map(Err))
            .collect();
        let valid: Vec<(usize, BrickKey)> = keys
            .iter()
            .enumerate()
            .filter(|(i, _)| results[*i].is_none())
            .map(|(i, k)| (i, *k))
            .collect();
        let answered: Vec<Vec<Result<BrickVoxels>>> = valid
            .par_chunks(self.batch_size())
            .map(|batch| {
                let keys: Vec<BrickKey> = batch.iter().map(|(_, k)| *k).collect();
                self.fetch_batch(&keys)
            })
            .collect();
        for ((i, _), r) in valid.iter().zip(answered.into_iter().flatten()) {
            results[*i] = Some(r);
        }
        results
            .into_iter()
            .map(|r| r.expect("every key answered"))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use residency_schemas::wire::{BrickEntry, MinMaxGridBlock, MinMaxLevelBlock, encode_framed};

    use super::*;
    use crate::source::LevelInfo;

    /// A source for `http://h/v` without a server, for the document parsers.
    fn source() -> HttpSource {
        HttpSource {
            base: "http://h/v".into(),
            agent: ureq::Agent::new_with_defaults(),
            token: None,
            info: VolumeInfo {
                name: "v".into(),
                sample_type: SampleType::I16,
                channels: vec!["a".into(), "b".into()],
                display: vec![crate::source::ChannelDisplay::default(); 2],
                voxel_size: [1.0; 3],
                brick_shape: [1, 1, 2],
                levels: vec![LevelInfo {
                    shape: [1, 1, 4],
                    factor: [1; 3],
                }],
                minmax: None,
            },
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
        let src = source();
        let payload: Vec<u8> = [-3i16, 7].iter().flat_map(|v| v.to_le_bytes()).collect();
        let doc = batch(
            vec![
                entry(0, BrickStatus::Empty, 0, 0),
                entry(1, BrickStatus::Ok, 0, 4),
            ],
            &payload,
        );
        let got = src.parse_batch(&[key(0), key(1)], &doc, "u").unwrap();
        let got: Vec<BrickVoxels> = got.into_iter().map(Result::unwrap).collect();
        assert_eq!(got, [BrickVoxels::Empty, BrickVoxels::I16(vec![-3, 7])]);

        let doc = batch(vec![entry(1, BrickStatus::Error, 0, 0)], &[]);
        let e = src.parse_batch(
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
        let src = source();
        let e = src.parse_batch(&[key(0)], b"garbage", "u").unwrap_err();
        assert_eq!(
            format!("{e:#}"),
            "u: corrupt brick batch: not a RSBRICKS document (bad magic)"
        );
        // A brick running past the payload.
        let doc = batch(vec![entry(0, BrickStatus::Ok, 2, 4)], &[0; 4]);
        let e = src.parse_batch(&[key(0)], &doc, "u").unwrap();
        assert_eq!(
            e.into_iter().next().unwrap().unwrap_err().to_string(),
            format!(
                "u: brick {:?} at bytes 2+4 is not 4 bytes inside the 4-byte payload",
                key(0)
            )
        );
        // Answers out of order, or too few.
        let doc = batch(vec![entry(1, BrickStatus::Empty, 0, 0)], &[]);
        let e = src.parse_batch(&[key(0)], &doc, "u").unwrap();
        assert_eq!(
            e.into_iter().next().unwrap().unwrap_err().to_string(),
            format!(
                "u: answered brick 0,1,[0, 0, 1] where {:?} was asked",
                key(0)
            )
        );
        let e = src.parse_batch(&[key(0), key(1)], &doc, "u").unwrap_err();
        assert_eq!(e.to_string(), "u: 1 bricks answered for 2 asked");
    }

    #[test]
    fn minmax_documents_decode_and_are_checked() {
        let src = source();
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
        let grids = src.parse_minmax(1, &doc, "m").unwrap();
        assert_eq!(
            (grids[0][0].min.clone(), grids[0][0].max.clone()),
            (vec![-5.0], vec![9.0])
        );
        let e = src.parse_minmax(0, &doc, "m").unwrap_err();
        assert_eq!(e.to_string(), "m: min/max document is for channel 1");
        let doc = encode_framed(MINMAX_MAGIC, &header(1, 8), &payload);
        let e = src.parse_minmax(1, &doc, "m").unwrap_err();
        assert_eq!(
            e.to_string(),
            "m: min/max grid of level 0 at bytes 0+8 runs past the 4-byte payload"
        );
    }
}
