//! The path parameters of the routes, as extracted and as documented.

use schemars::JsonSchema;
use serde::Deserialize;

/// The path of a dataset's API routes (`/NAME/regions`, `/NAME/view`, ...).
#[derive(Deserialize, JsonSchema)]
pub(super) struct DatasetPath {
    /// Dataset name.
    pub(super) name: String,
}

/// The path of a Zarr key of a dataset, `/NAME/KEY` (the handler reads the key still
/// percent-encoded, from the request's URI).
#[derive(Deserialize, JsonSchema)]
pub(super) struct KeyPath {
    /// Dataset name.
    pub(super) name: String,
    /// The Zarr key, '/'-separated.
    #[expect(
        dead_code,
        reason = "documents the key; the handler reads it still percent-encoded, from the URI"
    )]
    pub(super) key: String,
}

/// The path of a file of the web viewer, `/viewer/FILE`, as documented (the viewer's file
/// service reads it from the request).
#[derive(JsonSchema)]
#[expect(dead_code, reason = "only its schema is used, to document the path")]
pub(super) struct ViewerFilePath {
    /// Path of the file in the viewer's folder ('/'-separated); index.html is the page as at /viewer/.
    pub(super) file: String,
}
