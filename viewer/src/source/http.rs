//! [`HttpSource`]: a `brickserver` over HTTP with a blocking client (`ureq`), speaking the
//! protocol of [`super::server`]; batches of one fetch go out in parallel.

use std::path::Path;
use std::time::Duration;

use rayon::prelude::*;

use super::server::{self, Get, Reply};
use super::{BrickKey, BrickSource, BrickVoxels, SourceError, VolumeInfo};

pub use super::server::{MAX_BATCH, MAX_BATCH_BYTES};

/// Time allowed for one whole request, connection to last byte.
pub const REQUEST_TIMEOUT: Duration = Duration::from_mins(2);

/// Blocking GETs with an optional bearer token.
struct Client {
    agent: ureq::Agent,
    token: Option<String>,
}

impl Get for Client {
    async fn get(&self, url: &str) -> Result<Reply, SourceError> {
        let mut request = self.agent.get(url);
        if let Some(token) = &self.token {
            request = request.header("Authorization", &format!("Bearer {token}"));
        }
        let mut response = request.call().map_err(|e| SourceError::Unreachable {
            url: url.to_string(),
            source: e.into(),
        })?;
        let status = response.status().as_u16();
        let body = response
            .body_mut()
            .with_config()
            .limit(u64::MAX)
            .read_to_vec()
            .map_err(|e| SourceError::ReadResponse {
                url: url.to_string(),
                source: Box::new(e),
            })?;
        Ok(Reply::new(status, body, self.token.is_some()))
    }
}

/// A dataset on a `brickserver`.
pub struct HttpSource {
    base: String,
    client: Client,
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

/// Reads a bearer-token file (as `brickserver serve --token-file` does): its text, trimmed.
///
/// # Errors
/// [`SourceError::TokenFile`], naming the file, when it cannot be read as text.
pub fn read_token_file(path: &Path) -> Result<String, SourceError> {
    let text = std::fs::read_to_string(path).map_err(|source| SourceError::TokenFile {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(text.trim().to_string())
}

impl HttpSource {
    /// Opens dataset `dataset` on the server at `server_url` (e.g. `http://127.0.0.1:8000`):
    /// loads its metadata and, when the server has region metadata, every channel's min/max
    /// hierarchy. Without region metadata, `minmax` is `None` and a warning says so.
    ///
    /// # Errors
    /// As [`server::open`]: a server that cannot be reached, a dataset it does not have, or
    /// metadata that cannot be read, each naming the URL.
    pub fn open(server_url: &str, dataset: &str) -> Result<Self, SourceError> {
        Self::open_with_token(server_url, dataset, None)
    }

    /// [`HttpSource::open`] for a server started with `--token-file`: every request carries
    /// `Authorization: Bearer TOKEN`.
    ///
    /// # Errors
    /// As [`HttpSource::open`]; a refused token is an HTTP 401 naming the URL.
    pub fn open_with_token(
        server_url: &str,
        dataset: &str,
        token: Option<&str>,
    ) -> Result<Self, SourceError> {
        let agent: ureq::Agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_global(Some(REQUEST_TIMEOUT))
            .build()
            .into();
        let client = Client {
            agent,
            token: token.map(str::to_string),
        };
        let base = server::dataset_url(server_url, dataset);
        // `Client::get` blocks and never yields, so this completes in one poll.
        let info = pollster::block_on(server::open(&client, &base, dataset))?;
        Ok(Self { base, client, info })
    }

    /// Bricks per request: within both of the server's caps, at least one.
    pub fn batch_size(&self) -> usize {
        server::batch_size(&self.info)
    }
}

impl BrickSource for HttpSource {
    fn info(&self) -> &VolumeInfo {
        &self.info
    }

    fn fetch(&self, keys: &[BrickKey]) -> Vec<Result<BrickVoxels, SourceError>> {
        // Invalid keys are answered here; the rest go to the server in batches.
        let mut results: Vec<Option<Result<BrickVoxels, SourceError>>> = keys
            .iter()
            .map(|k| self.info.check_key(k).err().map(|e| Err(e.into())))
            .collect();
        let valid: Vec<(usize, BrickKey)> = keys
            .iter()
            .enumerate()
            .filter(|(i, _)| results[*i].is_none())
            .map(|(i, k)| (i, *k))
            .collect();
        let answered: Vec<Vec<Result<BrickVoxels, SourceError>>> = valid
            .par_chunks(self.batch_size())
            .map(|batch| {
                let keys: Vec<BrickKey> = batch.iter().map(|(_, k)| *k).collect();
                pollster::block_on(server::fetch_batch(
                    &self.client,
                    &self.base,
                    &self.info,
                    &keys,
                ))
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
