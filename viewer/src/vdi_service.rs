//! The documents of the VDI render service (`viewer serve`), as the service and its clients
//! (the page's remote mode, `crate::web`) both read and write them: the request for a VDI of a
//! view ([`VdiRequest`], `schemas/json/vdi-request.schema.json`), the description of the
//! dataset served ([`ServiceInfo`], `schemas/json/vdi-service-info.schema.json`), the GPU
//! adapter rendering it ([`Adapter`]) and the bounds of a request ([`Limits`]).

use residency_schemas::vdi::{Compression, MAX_SUPERSEGMENTS};
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
    /// How the answer's planes are compressed [default: `shuffled_lz4`]: `shuffled_zstd` is
    /// smaller and costs more time to write and read, worth it over slow links (the page's
    /// `auto` asks for it below 300 Mbit/s).
    #[serde(default)]
    pub compression: Option<Compression>,
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
    /// The GPU adapter the service renders on.
    pub adapter: Adapter,
}

/// The GPU adapter a service renders on, as wgpu reports it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Adapter {
    /// The adapter's name (`wgpu::AdapterInfo::name`), such as `llvmpipe (LLVM 19.1.7, 256
    /// bits)` for Mesa's lavapipe.
    pub name: String,
    /// The wgpu backend it is driven by (`wgpu::Backend::to_str`): `vulkan`, `metal`, `dx12`,
    /// `gl`, `webgpu` or `noop`.
    pub backend: String,
}

impl From<&wgpu::AdapterInfo> for Adapter {
    fn from(info: &wgpu::AdapterInfo) -> Self {
        Self {
            name: info.name.clone(),
            backend: info.backend.to_str().to_owned(),
        }
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::defaults::default_scene;
    use crate::source::{ChannelDisplay, LevelInfo, SampleType, VolumeInfo};

    #[test]
    fn the_info_names_the_adapter_and_round_trips() {
        let volume = VolumeInfo {
            name: "vol".into(),
            sample_type: SampleType::U8,
            channels: vec!["a".into()],
            display: vec![ChannelDisplay::default()],
            voxel_size: [1.0; 3],
            unit: None,
            brick_shape: [8, 8, 8],
            levels: vec![LevelInfo {
                shape: [16, 16, 16],
                factor: [1, 1, 1],
            }],
            minmax: None,
        };
        let adapter = Adapter::from(&wgpu::AdapterInfo {
            name: "llvmpipe (LLVM 19.1.7, 256 bits)".into(),
            driver: "llvmpipe".into(),
            ..wgpu::AdapterInfo::new(wgpu::DeviceType::Cpu, wgpu::Backend::Vulkan)
        });
        assert_eq!(
            adapter,
            Adapter {
                name: "llvmpipe (LLVM 19.1.7, 256 bits)".into(),
                backend: "vulkan".into(),
            }
        );
        let info = ServiceInfo {
            dataset: "vol".into(),
            extent: [16.0; 3],
            channels: vec!["a".into()],
            levels: 1,
            scene: default_scene(&volume),
            limits: Limits {
                max_pixels: 100,
                max_supersegments: 30,
                max_requests_per_second: 20.0,
            },
            adapter,
        };
        let json = serde_json::to_value(&info).unwrap();
        assert_eq!(
            json["adapter"],
            serde_json::json!({"name": "llvmpipe (LLVM 19.1.7, 256 bits)", "backend": "vulkan"})
        );
        let back: ServiceInfo = serde_json::from_value(json).unwrap();
        assert_eq!(back, info);
    }
}
