//! `GET /` and `GET /datasets`: the served datasets, with links that open each in the
//! Residency web viewer, neuroglancer and vizarr.

use std::sync::Arc;

use aide::transform::TransformOperation;
use axum::body::Body;
use axum::extract::State;
use axum::http::{HeaderMap, Response, header};
use axum::response::{IntoResponse, Json};
use residency_schemas::server::DatasetList;

use super::state::{AppState, blocking};
use crate::listing::{self, Listed, StoreSummary};
use crate::openapi::{json, responses, string, with_content};

/// The documentation of `GET /`.
pub(super) fn home_docs(op: TransformOperation<'_>) -> TransformOperation<'_> {
    let op = op.summary(
        "The datasets: for a browser (an Accept that prefers text/html) an HTML page with each \
         dataset's size, levels, channels and links (the Residency viewer's relative, \
         NAME/view); otherwise the JSON of /datasets",
    );
    let answer = json::<DatasetList>("The datasets (the answer varies with Accept)");
    responses(op, [(200, with_content(answer, "text/html", string()))])
}

/// The documentation of `GET /datasets`.
pub(super) fn list_docs(op: TransformOperation<'_>) -> TransformOperation<'_> {
    let op = op
        .summary(
            "List the served datasets, with links that open each in the Residency web viewer, \
             neuroglancer and vizarr",
        )
        .description(
            "Links are built on --public-url when given, else on the request's \
             X-Forwarded-Proto and X-Forwarded-Host (first values), else http:// and its Host. \
             The neuroglancer link names the store's Zarr version (zarr:// for v2, zarr3:// for \
             v3) and carries each channel's omero window and colour.",
        );
    responses(op, [(200, json::<DatasetList>("The datasets"))])
}

/// The datasets with their links. Each store's summary is read once, on the blocking pool, at
/// the first listing (a store that cannot be summarized is said so once, in the log).
async fn listed(state: &Arc<AppState>, headers: &HeaderMap) -> Vec<Listed> {
    let base = listing::base_url(headers, state.public_url.as_ref());
    let st = state.clone();
    blocking(move || {
        let summaries: Vec<_> = st
            .datasets
            .0
            .iter()
            .enumerate()
            .map(|(i, d)| {
                let served = st.served(i);
                served
                    .loaded
                    .summary
                    .get_or_init(|| match StoreSummary::read(&served.store) {
                        Ok(s) => {
                            if let Err(e) = &s.level0 {
                                tracing::warn!(
                                    "{}: listed without size, channels or sample type: {e}",
                                    d.name
                                );
                            }
                            Some(Arc::new(s))
                        }
                        Err(e) => {
                            tracing::warn!("{}: not summarized in the listing: {e}", d.name);
                            None
                        }
                    })
                    .clone()
            })
            .collect();
        listing::list(&st.datasets.0, &summaries, &base)
    })
    .await
}

/// `GET /`: the dataset list as an HTML page for a browser (an `Accept` that prefers
/// `text/html`), else as JSON like `/datasets`.
pub(super) async fn home(State(state): State<Arc<AppState>>, headers: HeaderMap) -> Response<Body> {
    let html = listing::prefers_html(headers.get(header::ACCEPT).and_then(|h| h.to_str().ok()));
    let datasets = listed(&state, &headers).await;
    let vary = [(header::VARY, "Accept")];
    if html {
        let content_type = (header::CONTENT_TYPE, "text/html; charset=utf-8");
        (vary, [content_type], listing::html(&datasets)).into_response()
    } else {
        (vary, Json(listing::json(datasets))).into_response()
    }
}

/// `GET /datasets`: the dataset list as JSON.
pub(super) async fn list(
    State(state): State<Arc<AppState>>,
    headers: HeaderMap,
) -> Json<DatasetList> {
    Json(listing::json(listed(&state, &headers).await))
}
