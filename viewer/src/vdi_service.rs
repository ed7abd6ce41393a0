//! The documents of the VDI render service (`viewer serve`), as the service and its clients
//! (the page's remote mode, `crate::web`) both read and write them: the request for a VDI of a
//! view ([`VdiRequest`], `schemas/json/vdi-request.schema.json`), the description of the
//! dataset served ([`ServiceInfo`]) and the bounds of a request ([`Limits`]).

use residency_schemas::vdi::MAX_SUPERSEGMENTS;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::scene::{Camera, Scene};

/// Supersegments per pixel (N_S) when a request names none.
pub const DEFAULT_SUPERSEGMENTS: u32 = 20;

/// The body of `POST /vdi`: the view to generate a volumetric depth image of.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(
    title = "VDI request",
    description = "Body of `viewer serve`'s POST /vdi: the view whose volumetric depth image \
        is wanted."
)]
pub struct VdiRequest {
    /// The whole scene (camera, channel styles, background, filter). Absent, the service's
    /// default scene is drawn, from `camera` when that is given.
    #[serde(default)]
    pub scene: Option<Scene>,
    /// The camera of the service's default scene; only when `scene` is absent.
    #[serde(default)]
    pub camera: Option<Camera>,
    /// Width in pixels (supersegment lists per row).
    #[schemars(range(min = 1))]
    pub width: u32,
    /// Height in pixels.
    #[schemars(range(min = 1))]
    pub height: u32,
    /// Most supersegments per pixel (N_S) [default: 20].
    #[serde(default)]
    #[schemars(range(min = 1, max = MAX_SUPERSEGMENTS))]
    pub supersegments: Option<u32>,
    /// A sequence number of the client's, echoed in the `x-residency-request` header.
    #[serde(default)]
    pub request: Option<u64>,
}

/// The answer of `GET /info`: what a page needs to build cameras and scenes of the dataset.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ServiceInfo {
    /// The dataset's name.
    pub dataset: String,
    /// The volume's box `[0, extent]` in world units, `x, y, z`.
    pub extent: [f64; 3],
    /// Channel names, in index order.
    pub channels: Vec<String>,
    /// Number of resolution levels.
    pub levels: usize,
    /// The scene drawn when a request gives none (its camera orbits the volume).
    pub scene: Scene,
    /// The bounds every request is held to.
    pub limits: Limits,
}

/// The bounds every request is held to.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    /// Most pixels (width × height) of one VDI.
    pub max_pixels: u64,
    /// Most supersegments per pixel (N_S) of one VDI.
    pub max_supersegments: u32,
    /// Most `POST /vdi` requests per second, all clients together (a burst of as many is
    /// allowed).
    pub max_requests_per_second: f64,
}
