//! The browser's `fetch` as the [`Get`] of the brick-server protocol.

use wasm_bindgen::JsCast;
use wasm_bindgen_futures::JsFuture;

use crate::source::SourceError;
use crate::source::server::{Get, Reply};

/// GETs through `window.fetch` (CORS applies: brickserver allows any origin).
#[derive(Clone, Copy, Debug, Default)]
pub struct BrowserFetch;

/// A JavaScript error value as text.
pub fn js_text(value: &wasm_bindgen::JsValue) -> String {
    value
        .dyn_ref::<js_sys::Error>()
        .map(|e| String::from(e.message()))
        .or_else(|| value.as_string())
        .unwrap_or_else(|| format!("{value:?}"))
}

impl Get for BrowserFetch {
    async fn get(&self, url: &str) -> Result<Reply, SourceError> {
        let unreachable = |e: &wasm_bindgen::JsValue| SourceError::Unreachable {
            url: url.to_string(),
            source: js_text(e).into(),
        };
        let window = web_sys::window().ok_or_else(|| SourceError::NoWindow {
            url: url.to_string(),
        })?;
        let response = JsFuture::from(window.fetch_with_str(url))
            .await
            .map_err(|e| unreachable(&e))?;
        let response: web_sys::Response =
            response.dyn_into().map_err(|_| SourceError::NotAResponse {
                url: url.to_string(),
            })?;
        let status = response.status();
        let buffer = JsFuture::from(response.array_buffer().map_err(|e| unreachable(&e))?)
            .await
            .map_err(|e| unreachable(&e))?;
        let body = js_sys::Uint8Array::new(&buffer).to_vec();
        Ok(Reply::new(status, body, false))
    }
}
