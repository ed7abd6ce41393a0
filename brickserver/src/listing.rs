//! The dataset listing (`GET /datasets`, and `GET /`): JSON for programs, an HTML page for a
//! browser, each dataset with its store URL and the links that open it in the Residency web
//! viewer, neuroglancer and vizarr.
//!
//! Links are absolute, built from the server's public base URL: `--public-url` when given
//! (path prefix included), else the request's `X-Forwarded-Proto` and `X-Forwarded-Host`
//! (the first value of each, as a reverse proxy sets them), else `http://` and its `Host`.

use std::fmt::Write as _;
use std::str::FromStr;
use std::sync::Arc;

use axum::http::{HeaderMap, header};
use residency_schemas::SampleType;
use residency_schemas::ome::{ImageAttributes, OmeError, PyramidLayout, ZarrFormat};
use residency_schemas::server::{DatasetEntry, DatasetList};
use residency_schemas::zarr::{ArrayDescription, ArrayMetadataError};

use crate::dataset_store::DatasetStore;
use crate::datasets::Dataset;
use crate::neuroglancer;
use crate::store_keys::KeyError;

/// The URL the server is reached at from outside (`--public-url`): `http://` or `https://`,
/// a host, and an optional path prefix; no query or fragment. Kept without a trailing `/`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PublicUrl(String);

/// Why a `--public-url` is refused.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("public URL '{url}': {reason}")]
pub struct PublicUrlError {
    /// The URL as given.
    pub url: String,
    /// What is wrong with it.
    pub reason: &'static str,
}

impl FromStr for PublicUrl {
    type Err = PublicUrlError;

    fn from_str(url: &str) -> Result<Self, Self::Err> {
        let refuse = |reason| PublicUrlError {
            url: url.to_string(),
            reason,
        };
        let rest = url
            .strip_prefix("https://")
            .or_else(|| url.strip_prefix("http://"))
            .ok_or_else(|| refuse("expected http:// or https://"))?;
        let host = rest.split('/').next().unwrap_or_default();
        if !is_host(host) {
            return Err(refuse("expected a host (and port) after the scheme"));
        }
        if url.contains(['?', '#']) || url.chars().any(|c| c.is_whitespace() || c == '"') {
            return Err(refuse("expected no query, fragment, space or quote"));
        }
        Ok(Self(url.trim_end_matches('/').to_string()))
    }
}

impl PublicUrl {
    /// The URL, without a trailing `/`.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

/// Whether `host` is a plausible `host[:port]` (a name, an IPv4 or a bracketed IPv6 address),
/// safe to put into a link as is.
fn is_host(host: &str) -> bool {
    !host.is_empty()
        && host.bytes().all(|b| {
            b.is_ascii_alphanumeric() || matches!(b, b'.' | b'-' | b'_' | b':' | b'[' | b']')
        })
}

/// The first value of header `name`, trimmed (a proxy chain appends its values after it).
fn first_value<'a>(headers: &'a HeaderMap, name: &str) -> Option<&'a str> {
    let value = headers.get(name)?.to_str().ok()?;
    Some(value.split(',').next()?.trim()).filter(|v| !v.is_empty())
}

/// The base URL links are built on, without a trailing `/`: `public` when given, else
/// `X-Forwarded-Proto` (`http` or `https`; `http` otherwise) with `X-Forwarded-Host`, else
/// `Host` (`localhost` when neither is a plausible host).
pub(crate) fn base_url(headers: &HeaderMap, public: Option<&PublicUrl>) -> String {
    if let Some(p) = public {
        return p.as_str().to_string();
    }
    let scheme = first_value(headers, "x-forwarded-proto")
        .map(str::to_ascii_lowercase)
        .filter(|s| s == "http" || s == "https")
        .unwrap_or_else(|| "http".to_string());
    let host = first_value(headers, "x-forwarded-host")
        .filter(|h| is_host(h))
        .or_else(|| first_value(headers, header::HOST.as_str()).filter(|h| is_host(h)))
        .unwrap_or("localhost");
    format!("{scheme}://{host}")
}

/// Why a store's summary could not be read (the listing then says less about it).
#[derive(Debug, thiserror::Error)]
pub enum SummaryError {
    /// Neither `zarr.json` nor `.zattrs` at the store's root, or one that cannot be read.
    #[error("{store}: no readable zarr.json or .zattrs")]
    NoGroup {
        /// The store's root.
        store: String,
    },
    /// The OME metadata is unusable.
    #[error(transparent)]
    Ome(#[from] OmeError),
}

/// Why level 0's array metadata could not be read (the listing then gives no size, channels or
/// sample type for the store).
#[derive(Debug, thiserror::Error)]
pub enum Level0Error {
    /// No such key in the store.
    #[error("{key}: missing")]
    Missing {
        /// The array metadata's key, under the store's root.
        key: String,
    },
    /// The key, from the store's own metadata, tries to leave the store.
    #[error("{key}: refused: {why}")]
    Refused {
        /// The array metadata's key, under the store's root.
        key: String,
        /// Why the key was refused.
        why: &'static str,
    },
    /// The key exists but cannot be read.
    #[error("{key}: {source}")]
    Unreadable {
        /// The array metadata's key, under the store's root.
        key: String,
        /// The I/O error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The array metadata is unusable.
    #[error(transparent)]
    Metadata(#[from] ArrayMetadataError),
}

/// What the listing says about a store, from its image group's metadata and level 0's array
/// metadata (two small documents).
#[derive(Debug)]
pub struct StoreSummary {
    /// Zarr format.
    pub format: ZarrFormat,
    /// The image group's attributes.
    pub attributes: ImageAttributes,
    /// Its levels and axes.
    pub layout: PyramidLayout,
    /// Level 0's array metadata, or why it is unreadable.
    pub level0: Result<ArrayDescription, Level0Error>,
}

impl StoreSummary {
    /// Reads the summary of a dataset's store (synchronous: call it from blocking code).
    ///
    /// # Errors
    /// [`SummaryError`] when the image group's metadata is missing or unusable.
    pub fn read(store: &DatasetStore) -> Result<Self, SummaryError> {
        let shown = store.shown().to_string();
        let read_key = |key: &str| store.read_document(key);
        let no_group = || SummaryError::NoGroup {
            store: shown.clone(),
        };
        let (format, group) = match read_key("zarr.json").map_err(|_| no_group())? {
            Some(doc) => (ZarrFormat::V3, doc),
            None => match read_key(".zattrs").map_err(|_| no_group())? {
                Some(doc) => (ZarrFormat::V2, doc),
                None => return Err(no_group()),
            },
        };
        let source = format!("{shown}/{}", format.group_key());
        let attributes = ImageAttributes::parse(format, &group, &source)?;
        let layout = PyramidLayout::of(attributes.image(), &source)?;
        let key = format!("{}/{}", layout.level_paths[0], format.array_key());
        let shown_key = format!("{shown}/{key}");
        let level0 = match read_key(&key) {
            Ok(Some(doc)) => ArrayDescription::parse(format, &doc, &shown_key).map_err(Into::into),
            Ok(None) | Err(KeyError::NotFound) => Err(Level0Error::Missing { key: shown_key }),
            Err(KeyError::Refused(why)) => Err(Level0Error::Refused {
                key: shown_key,
                why,
            }),
            Err(KeyError::Unreadable(source)) => Err(Level0Error::Unreadable {
                key: shown_key,
                source,
            }),
        };
        Ok(Self {
            format,
            attributes,
            layout,
            level0,
        })
    }

    /// Channels: the length of the `c` axis (1 without one); `None` when level 0 is unreadable.
    pub fn channels(&self) -> Option<u64> {
        let level0 = self.level0.as_ref().ok()?;
        Some(self.layout.channel_axis.map_or(1, |c| level0.shape[c]))
    }

    /// Level 0's size `x, y, z` in voxels, when readable.
    pub(crate) fn size_xyz(&self) -> Option<[u64; 3]> {
        let [z, y, x] = self.level0.as_ref().ok()?.zyx_shape();
        Some([x, y, z])
    }

    /// The sample type, when level 0 is readable.
    pub(crate) fn sample_type(&self) -> Option<SampleType> {
        Some(self.level0.as_ref().ok()?.sample_type)
    }
}

/// One dataset as listed: its entry and what is known of its store.
#[derive(Debug)]
pub(crate) struct Listed {
    /// The JSON entry.
    pub entry: DatasetEntry,
    /// The store's summary, when its metadata could be read.
    pub summary: Option<Arc<StoreSummary>>,
}

/// Lists `datasets`, with their `summaries` (one per dataset, read once by the caller:
/// [`StoreSummary::read`]), with links built on `base` (see [`base_url`]).
pub(crate) fn list(
    datasets: &[Dataset],
    summaries: &[Option<Arc<StoreSummary>>],
    base: &str,
) -> Vec<Listed> {
    datasets
        .iter()
        .zip(summaries)
        .map(|(d, summary)| {
            let url = format!("{base}/{}/", d.name);
            let state = match summary {
                Some(s) => neuroglancer::state(
                    &d.name,
                    &url,
                    s.format,
                    &s.attributes,
                    &s.layout,
                    s.channels().unwrap_or(1),
                ),
                None => neuroglancer::fallback_state(&d.name, &url),
            };
            let entry = DatasetEntry {
                name: d.name.clone(),
                view: format!("{base}/{}/view", d.name),
                neuroglancer: neuroglancer::link(&state),
                vizarr: format!("https://hms-dbmi.github.io/vizarr/?source={url}"),
                url,
            };
            Listed {
                entry,
                summary: summary.clone(),
            }
        })
        .collect()
}

/// The JSON listing.
pub(crate) fn json(listed: Vec<Listed>) -> DatasetList {
    DatasetList {
        datasets: listed.into_iter().map(|l| l.entry).collect(),
    }
}

/// Whether a request's `Accept` header prefers HTML (`text/html` or `application/xhtml+xml`)
/// to JSON, by quality; a tie (`*/*`, or no header) is JSON.
pub(crate) fn prefers_html(accept: Option<&str>) -> bool {
    let Some(accept) = accept else {
        return false;
    };
    // The quality each media range gives; the most specific range naming a type decides.
    let mut ranges: Vec<(String, f32)> = Vec::new();
    for item in accept.split(',') {
        let mut parts = item.split(';');
        let media = parts.next().unwrap_or_default().trim().to_ascii_lowercase();
        if media.is_empty() {
            continue;
        }
        let q = parts
            .filter_map(|p| p.trim().strip_prefix("q="))
            .find_map(|q| q.trim().parse::<f32>().ok())
            .unwrap_or(1.0);
        ranges.push((media, q.clamp(0.0, 1.0)));
    }
    let quality = |media: &str| -> f32 {
        let (kind, _) = media.split_once('/').unwrap_or((media, ""));
        let wildcard = format!("{kind}/*");
        [media, wildcard.as_str(), "*/*"]
            .iter()
            .find_map(|m| ranges.iter().find(|(r, _)| r == m).map(|(_, q)| *q))
            .unwrap_or(0.0)
    };
    let html = quality("text/html").max(quality("application/xhtml+xml"));
    html > 0.0 && html > quality("application/json")
}

/// Escapes text for HTML (element content and quoted attribute values).
pub(crate) fn escape_html(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// The listing as an HTML page: a table of the datasets, each with its size, levels, channels
/// and sample type when known, and its links (the Residency viewer's relative, `NAME/view`).
pub(crate) fn html(listed: &[Listed]) -> String {
    let mut page = String::from(
        "<!doctype html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>Residency datasets</title>\n\
         <link rel=\"icon\" href=\"data:,\">\n<style>\n\
         body { font-family: system-ui, sans-serif; margin: 2em; }\n\
         table { border-collapse: collapse; }\n\
         th, td { text-align: left; padding: 0.3em 0.8em; border-bottom: 1px solid #ccc; }\n\
         td.links a { margin-right: 0.8em; }\n\
         </style>\n</head>\n<body>\n<h1>Residency datasets</h1>\n",
    );
    if listed.is_empty() {
        page.push_str("<p>No dataset is served.</p>\n");
    }
    page.push_str(
        "<table>\n<thead><tr><th>Dataset</th><th>Size (x × y × z)</th><th>Levels</th>\
         <th>Channels</th><th>Type</th><th>Open</th></tr></thead>\n<tbody>\n",
    );
    for l in listed {
        let e = &l.entry;
        let name = escape_html(&e.name);
        let path =
            percent_encoding::utf8_percent_encode(&e.name, percent_encoding::NON_ALPHANUMERIC);
        let s = l.summary.as_deref();
        let unknown = || "?".to_string();
        let size = s
            .and_then(StoreSummary::size_xyz)
            .map_or_else(unknown, |[x, y, z]| format!("{x} × {y} × {z}"));
        let levels = s.map_or_else(unknown, |s| s.layout.level_paths.len().to_string());
        let channels = s
            .and_then(StoreSummary::channels)
            .map_or_else(unknown, |c| c.to_string());
        let kind = s
            .and_then(StoreSummary::sample_type)
            .map_or_else(unknown, |t| t.to_string());
        let _ = writeln!(
            page,
            "<tr><td>{name}</td><td>{size}</td><td>{levels}</td><td>{channels}</td>\
             <td>{kind}</td><td class=\"links\">\
             <a href=\"{path}/view\">open in the Residency viewer</a>\
             <a href=\"{}\">neuroglancer</a>\
             <a href=\"{}\">vizarr</a>\
             <a href=\"{}\">store: {}</a></td></tr>",
            escape_html(&e.neuroglancer),
            escape_html(&e.vizarr),
            escape_html(&e.url),
            escape_html(&e.url),
        );
    }
    page.push_str(
        "</tbody>\n</table>\n<p>As JSON: <a href=\"datasets\">datasets</a>. \
         The API: <a href=\"openapi.json\">openapi.json</a>.</p>\n</body>\n</html>\n",
    );
    page
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accept_prefers_html_only_when_it_ranks_higher() {
        let browser = "text/html,application/xhtml+xml,application/xml;q=0.9,*/*;q=0.8";
        assert!(prefers_html(Some(browser)));
        assert!(prefers_html(Some("text/html")));
        assert!(prefers_html(Some("text/*")));
        assert!(prefers_html(Some("application/json;q=0.5, text/html")));
        assert!(!prefers_html(None));
        assert!(!prefers_html(Some("*/*")));
        assert!(!prefers_html(Some("application/json")));
        assert!(!prefers_html(Some("application/json, text/html")));
        assert!(!prefers_html(Some("text/html;q=0")));
        assert!(!prefers_html(Some("text/html;q=0.5, application/*")));
    }

    #[test]
    fn public_urls_are_checked() {
        let ok: PublicUrl = "https://example.org/residency/".parse().unwrap();
        assert_eq!(ok.as_str(), "https://example.org/residency");
        assert_eq!(
            "http://[::1]:8000".parse::<PublicUrl>().unwrap().as_str(),
            "http://[::1]:8000"
        );
        for bad in [
            "example.org",
            "ftp://x",
            "https://",
            "https://a b",
            "https://x/?q",
            "https://x/#f",
        ] {
            assert!(bad.parse::<PublicUrl>().is_err(), "{bad}");
        }
    }

    #[test]
    fn html_is_escaped() {
        assert_eq!(
            escape_html("<a href=\"x\">&'"),
            "&lt;a href=&quot;x&quot;&gt;&amp;&#39;"
        );
    }
}
