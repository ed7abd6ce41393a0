//! The Residency web viewer's files (built by `scripts/build-web.sh`: `index.html`, `main.js`,
//! `vdi_worker.js`, `style.css`, the wasm-bindgen glue and the `.wasm`), served at `GET
//! /NAME/view` (the page for dataset NAME) and `GET /viewer/FILE` (through tower-http's
//! `ServeDir`: content types by extension, `.wasm` as `application/wasm`, `Last-Modified` and
//! `If-Modified-Since`, ranges).
//!
//! The page refers to its files through the placeholder [`VIEWER_BASE`], which the server
//! replaces with the relative path from the page's URL to the files (`../viewer/` for
//! `/NAME/view`, `./` for `/viewer/`), so the links work behind a reverse proxy that adds a
//! path prefix.

use std::path::{Path, PathBuf};

use axum::body::Body;
use axum::extract::Request;
use axum::http::{HeaderValue, Response, StatusCode, Uri, header};
use tower_http::services::ServeDir;

/// The placeholder in `index.html` for the path to the viewer's files.
pub const VIEWER_BASE: &str = "%VIEWER_BASE%";

/// The path prefix of the viewer's files.
pub(crate) const FILES_PREFIX: &str = "/viewer";

/// Where the viewer's files are, if they were built.
#[derive(Clone, Debug, Default)]
pub struct ViewerFiles {
    dir: Option<PathBuf>,
}

/// A response with `status`, a `text/plain` body and no caching.
fn text(status: StatusCode, body: String) -> Response<Body> {
    Response::builder()
        .status(status)
        .header(header::CONTENT_TYPE, "text/plain; charset=utf-8")
        .header(header::CACHE_CONTROL, "no-cache")
        .body(Body::from(body))
        .expect("a valid response")
}

impl ViewerFiles {
    /// The files in `dir` (`None`: none).
    pub fn new(dir: Option<PathBuf>) -> Self {
        Self { dir }
    }

    /// The folder looked at.
    pub fn looked_at(&self) -> Option<&Path> {
        self.dir.as_deref()
    }

    /// The folder served: the one given, when it holds `index.html`.
    pub fn built(&self) -> Option<&Path> {
        self.dir
            .as_deref()
            .filter(|d| d.join("index.html").is_file())
    }

    /// The message of the 503 answer when the viewer is not built.
    pub(crate) fn not_built_message(&self) -> String {
        let looked = self.dir.as_deref().map_or_else(
            || "no folder: the running executable's folder is unknown".to_string(),
            |d| format!("looked for index.html in {}", d.display()),
        );
        format!(
            "the web viewer is not built: run scripts/build-web.sh, or pass --viewer-dir \
             ({looked})\n"
        )
    }

    /// The 503 answer when the viewer is not built.
    fn not_built(&self) -> Response<Body> {
        text(StatusCode::SERVICE_UNAVAILABLE, self.not_built_message())
    }

    /// The page, its file references relative to `base`, with `status` (200, or 404 for an
    /// unknown dataset: the page then says so itself); 503 when the viewer is not built.
    pub async fn page(&self, base: &str, status: StatusCode) -> Response<Body> {
        // A missing folder or index.html is a failed read: not built.
        let Some(dir) = self.dir.as_deref() else {
            return self.not_built();
        };
        match tokio::fs::read_to_string(dir.join("index.html")).await {
            Ok(html) => Response::builder()
                .status(status)
                .header(header::CONTENT_TYPE, "text/html; charset=utf-8")
                .header(header::CACHE_CONTROL, "no-cache")
                .body(Body::from(html.replace(VIEWER_BASE, base)))
                .expect("a valid response"),
            Err(_) => self.not_built(),
        }
    }

    /// `GET /viewer/FILE`: the page for `index.html` (relative to `./`), any other file of the
    /// folder as it is; 404 for a file not there (or a path leaving the folder), 503 when the
    /// viewer is not built.
    pub async fn file(&self, request: Request) -> Response<Body> {
        let Some(dir) = self.built() else {
            return self.not_built();
        };
        let path = request.uri().path();
        let rest = path.strip_prefix(FILES_PREFIX).unwrap_or(path).to_string();
        if rest == "/" || rest == "/index.html" {
            return self.page("./", StatusCode::OK).await;
        }
        // No hidden files (nor `..`, which ServeDir refuses too), in any spelling.
        let decoded = percent_encoding::percent_decode_str(&rest).decode_utf8_lossy();
        if decoded.split(['/', '\\']).any(|s| s.starts_with('.')) {
            return text(StatusCode::NOT_FOUND, format!("no viewer file '{rest}'\n"));
        }
        // ServeDir serves the request's path beneath `dir`: take the prefix off.
        let uri = match request.uri().query() {
            Some(q) => format!("{rest}?{q}"),
            None => rest.clone(),
        };
        let (mut parts, body) = request.into_parts();
        parts.uri = uri.parse::<Uri>().unwrap_or_else(|_| Uri::from_static("/"));
        let mut serve = ServeDir::new(dir).append_index_html_on_directories(false);
        match serve.try_call(Request::from_parts(parts, body)).await {
            Ok(response) => {
                let mut response = response.map(Body::new);
                if response.status() == StatusCode::NOT_FOUND {
                    return text(StatusCode::NOT_FOUND, format!("no viewer file '{rest}'\n"));
                }
                // Revalidated (Last-Modified), so a rebuilt viewer is picked up at once.
                response
                    .headers_mut()
                    .insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
                response
            }
            Err(e) => {
                let message = format!("cannot read viewer file '{rest}': {e}");
                tracing::error!("{message}");
                text(StatusCode::INTERNAL_SERVER_ERROR, format!("{message}\n"))
            }
        }
    }
}
