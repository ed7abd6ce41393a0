//! The Residency web viewer: its page on a dataset (`GET /NAME/view`) and its files
//! (`GET /viewer/...`).

use std::sync::Arc;

use aide::openapi::Response as Documented;
use aide::transform::TransformOperation;
use axum::body::Body;
use axum::extract::{Path, Request, State};
use axum::http::{Response, StatusCode};
use axum::response::Redirect;

use super::params::{DatasetPath, ViewerFilePath};
use super::state::AppState;
use crate::openapi::{answer, binary, page, responses, string, text, with_content};

/// The answer when the viewer is not built.
fn not_built() -> Documented {
    text(
        "The web viewer is not built: the message names the folder looked at and says how to \
         build it (scripts/build-web.sh, or --viewer-dir)",
    )
}

/// The documentation of `GET /NAME/view`.
pub(super) fn view_docs(op: TransformOperation<'_>) -> TransformOperation<'_> {
    let op = op
        .summary("The Residency web viewer (WebAssembly + WebGPU) on dataset NAME")
        .description(
            "The viewer's index.html, its %VIEWER_BASE% placeholders replaced with ../viewer/ \
             (relative, so it works behind a path prefix). Wins over the Zarr key route: a \
             store's root key 'view' is not served.",
        );
    responses(
        op,
        [
            (200, page("The viewer page")),
            (404, page("No such dataset: the same page, which says so")),
            (503, not_built()),
        ],
    )
}

/// The documentation of `GET /viewer`.
pub(super) fn redirect_docs(op: TransformOperation<'_>) -> TransformOperation<'_> {
    let op = op.summary("Redirects to viewer/ (relative, so a path prefix survives)");
    responses(op, [(308, answer("Location: viewer/"))])
}

/// The documentation of `GET /viewer/`.
pub(super) fn page_docs(op: TransformOperation<'_>) -> TransformOperation<'_> {
    let op = op.summary(
        "The Residency web viewer page, its %VIEWER_BASE% placeholders replaced with ./ (the \
         page takes ?server=URL&dataset=NAME)",
    );
    responses(op, [(200, page("The viewer page")), (503, not_built())])
}

/// The documentation of `GET /viewer/FILE`.
pub(super) fn file_docs(op: TransformOperation<'_>) -> TransformOperation<'_> {
    let op = op
        .summary(
            "A file of the web viewer: .wasm as application/wasm, .js as text/javascript, \
             .html, .css; Last-Modified with If-Modified-Since, Range",
        )
        .input::<Path<ViewerFilePath>>();
    let wasm = binary("application/wasm");
    let mut file = with_content(answer("The file"), "application/wasm", wasm);
    for media in ["text/javascript", "text/html", "text/css"] {
        file = with_content(file, media, string());
    }
    responses(
        op,
        [
            (200, file),
            (206, answer("A byte range of the file")),
            (304, answer("Not modified (If-Modified-Since)")),
            (
                404,
                text("No such file (hidden files and paths leaving the folder included)"),
            ),
            (503, not_built()),
        ],
    )
}

/// `GET /viewer`: to `viewer/`.
pub(super) async fn redirect() -> Redirect {
    Redirect::permanent("viewer/")
}

/// `GET /viewer/...`: the web viewer's files.
pub(super) async fn viewer_file(
    State(state): State<Arc<AppState>>,
    request: Request,
) -> Response<Body> {
    state.viewer.file(request).await
}

/// `GET /NAME/view`: the web viewer's page, 404 (with the page, which says so) for an unknown
/// dataset.
pub(super) async fn view(
    State(state): State<Arc<AppState>>,
    Path(DatasetPath { name }): Path<DatasetPath>,
) -> Response<Body> {
    let status = if state.index_of(&name).is_some() {
        StatusCode::OK
    } else {
        StatusCode::NOT_FOUND
    };
    state.viewer.page("../viewer/", status).await
}
