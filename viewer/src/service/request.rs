//! The checks a request of `viewer serve` ([`VdiRequest`], `crate::vdi_service`) passes
//! before it reaches the GPU ([`check`]).

use crate::defaults::{SceneError, check_channel};
use crate::scene::{Camera, RenderMode, Scene};
use crate::source::VolumeInfo;
pub use crate::vdi_service::{DEFAULT_SUPERSEGMENTS, Limits, ServiceInfo, VdiRequest};
use residency_schemas::vdi::Compression;

/// A request that passed [`check`]: the scene to draw and the size of the image.
#[derive(Clone, Debug, PartialEq)]
pub struct CheckedRequest {
    /// The scene, the default one with the request's camera when it gave no scene.
    pub scene: Scene,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Most supersegments per pixel (N_S).
    pub supersegments: u32,
    /// How the answer's planes are compressed.
    pub compression: Compression,
}

/// A request the service refuses before it reaches the GPU: answered 400, or 413 when over a
/// limit ([`RequestError::over_limit`]).
#[derive(Debug, thiserror::Error)]
pub enum RequestError {
    /// The body is not a [`VdiRequest`].
    #[error("request body is not a VDI request")]
    Body(#[source] serde_json::Error),
    /// Both a scene and a camera.
    #[error("give a scene or a camera, not both")]
    SceneAndCamera,
    /// A zero width or height.
    #[error("width and height must be positive (got {width} × {height})")]
    EmptyImage {
        /// The width asked for.
        width: u32,
        /// The height asked for.
        height: u32,
    },
    /// More pixels than `--max-pixels`.
    #[error(
        "{width} × {height} = {pixels} pixels is over the limit of {limit} pixels (--max-pixels)"
    )]
    TooManyPixels {
        /// The width asked for.
        width: u32,
        /// The height asked for.
        height: u32,
        /// Their product.
        pixels: u64,
        /// The service's limit.
        limit: u64,
    },
    /// No supersegment per pixel.
    #[error("supersegments must be at least 1")]
    NoSupersegments,
    /// More supersegments per pixel than `--max-supersegments`.
    #[error(
        "{supersegments} supersegments per pixel is over the limit of {limit} \
         (--max-supersegments)"
    )]
    TooManySupersegments {
        /// The N_S asked for.
        supersegments: u32,
        /// The service's limit.
        limit: u32,
    },
    /// A camera coordinate that is not finite.
    #[error("camera: eye, target, up and fov_y_degrees must be finite")]
    CameraNotFinite,
    /// The eye on the target: no view direction.
    #[error("camera: eye and target must differ")]
    EyeOnTarget,
    /// Up along the view direction: no image plane orientation.
    #[error("camera: up must not be parallel to the view direction")]
    UpAlongView,
    /// A field of view outside `(0, 180)` degrees.
    #[error("camera: fov_y_degrees {fov} must lie between 0 and 180 degrees")]
    FieldOfView {
        /// The field of view given.
        fov: f64,
    },
    /// A scene styling a channel the dataset does not have.
    #[error(transparent)]
    Channel(#[from] SceneError),
    /// A scene that shows nothing.
    #[error("scene: no channel is visible")]
    NothingVisible,
    /// A scene in a mode a VDI cannot hold.
    #[error("scene: mode {mode}: a VDI holds composited colour and opacity (mode dvr only)")]
    Mode {
        /// The scene's mode.
        mode: &'static str,
    },
}

impl RequestError {
    /// Whether the request is well formed but over one of the service's [`Limits`] (413).
    pub fn over_limit(&self) -> bool {
        matches!(
            self,
            Self::TooManyPixels { .. } | Self::TooManySupersegments { .. }
        )
    }
}

/// Checks `request` against the dataset `info`, the service's `limits`, and builds its scene
/// (from `default_scene` when it gives none).
///
/// # Errors
/// The first [`RequestError`] found: image size, N_S, camera, channels, then mode.
pub fn check(
    request: VdiRequest,
    info: &VolumeInfo,
    default_scene: &Scene,
    limits: &Limits,
) -> Result<CheckedRequest, RequestError> {
    let VdiRequest {
        scene,
        camera,
        width,
        height,
        supersegments,
        request: _,
        compression,
    } = request;
    if width == 0 || height == 0 {
        return Err(RequestError::EmptyImage { width, height });
    }
    let pixels = u64::from(width) * u64::from(height);
    if pixels > limits.max_pixels {
        return Err(RequestError::TooManyPixels {
            width,
            height,
            pixels,
            limit: limits.max_pixels,
        });
    }
    let supersegments = supersegments.unwrap_or(DEFAULT_SUPERSEGMENTS);
    if supersegments == 0 {
        return Err(RequestError::NoSupersegments);
    }
    if supersegments > limits.max_supersegments {
        return Err(RequestError::TooManySupersegments {
            supersegments,
            limit: limits.max_supersegments,
        });
    }
    let scene = match (scene, camera) {
        (Some(_), Some(_)) => return Err(RequestError::SceneAndCamera),
        (Some(scene), None) => scene,
        (None, camera) => Scene {
            camera: camera.unwrap_or_else(|| default_scene.camera.clone()),
            ..default_scene.clone()
        },
    };
    check_camera(&scene.camera)?;
    for style in &scene.channels {
        check_channel(info, style.channel, "scene")?;
    }
    if !scene.channels.iter().any(|s| s.visible) {
        return Err(RequestError::NothingVisible);
    }
    if scene.mode != RenderMode::Dvr {
        return Err(RequestError::Mode {
            mode: scene.mode.name(),
        });
    }
    Ok(CheckedRequest {
        scene,
        width,
        height,
        supersegments,
        compression: compression.unwrap_or_default(),
    })
}

/// Refuses a camera that defines no view: a coordinate that is not finite, the eye on the
/// target, up along the view, or a field of view outside `(0, 180)` degrees.
///
/// # Errors
/// [`RequestError::CameraNotFinite`], [`RequestError::EyeOnTarget`],
/// [`RequestError::UpAlongView`] or [`RequestError::FieldOfView`].
pub fn check_camera(camera: &Camera) -> Result<(), RequestError> {
    let finite = camera
        .eye
        .iter()
        .chain(&camera.target)
        .chain(&camera.up)
        .chain(std::iter::once(&camera.fov_y_degrees))
        .all(|v| v.is_finite());
    if !finite {
        return Err(RequestError::CameraNotFinite);
    }
    let view: [f64; 3] = std::array::from_fn(|a| camera.target[a] - camera.eye[a]);
    if view.iter().all(|&v| v == 0.0) {
        return Err(RequestError::EyeOnTarget);
    }
    let up = camera.up;
    let cross = [
        view[1] * up[2] - view[2] * up[1],
        view[2] * up[0] - view[0] * up[2],
        view[0] * up[1] - view[1] * up[0],
    ];
    if cross.iter().all(|&v| v == 0.0) {
        return Err(RequestError::UpAlongView);
    }
    let fov = camera.fov_y_degrees;
    if !(fov > 0.0 && fov < 180.0) {
        return Err(RequestError::FieldOfView { fov });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::defaults::default_scene;
    use crate::source::{ChannelDisplay, LevelInfo, SampleType};

    fn info() -> VolumeInfo {
        VolumeInfo {
            name: "vol".into(),
            sample_type: SampleType::U16,
            channels: vec!["a".into(), "b".into()],
            display: vec![ChannelDisplay::default(); 2],
            voxel_size: [1.0; 3],
            unit: None,
            brick_shape: [8, 8, 8],
            levels: vec![LevelInfo {
                shape: [16, 16, 16],
                factor: [1, 1, 1],
            }],
            minmax: None,
        }
    }

    const LIMITS: Limits = Limits {
        max_pixels: 100,
        max_supersegments: 30,
        max_requests_per_second: 20.0,
    };

    fn checked(json: &str) -> Result<CheckedRequest, String> {
        let info = info();
        let request: VdiRequest = serde_json::from_str(json).map_err(|e| e.to_string())?;
        check(request, &info, &default_scene(&info), &LIMITS).map_err(|e| e.to_string())
    }

    #[test]
    fn a_camera_alone_views_the_default_scene() {
        let c = checked(r#"{"camera": {"eye": [1, 2, 3], "target": [4, 5, 6]}, "width": 10, "height": 10, "supersegments": 30}"#).unwrap();
        assert_eq!(
            (c.scene.camera.eye, c.scene.camera.target),
            ([1.0, 2.0, 3.0], [4.0, 5.0, 6.0])
        );
        assert_eq!(c.scene.channels, default_scene(&info()).channels);
        assert_eq!((c.width, c.height, c.supersegments), (10, 10, 30));
        let c = checked(r#"{"width": 2, "height": 3}"#).unwrap();
        assert_eq!(c.scene, default_scene(&info()));
        assert_eq!(c.supersegments, DEFAULT_SUPERSEGMENTS);
    }

    #[test]
    fn bad_requests_are_named() {
        let cam = |c: &str| format!(r#"{{"camera": {c}, "width": 4, "height": 4}}"#);
        let cases = [
            (
                r#"{"width": 0, "height": 4}"#.to_string(),
                "width and height must be positive (got 0 × 4)",
            ),
            (
                r#"{"width": 11, "height": 10}"#.to_string(),
                "11 × 10 = 110 pixels is over the limit of 100 pixels (--max-pixels)",
            ),
            (
                r#"{"width": 1, "height": 1, "supersegments": 0}"#.to_string(),
                "supersegments must be at least 1",
            ),
            (
                r#"{"width": 1, "height": 1, "supersegments": 31}"#.to_string(),
                "31 supersegments per pixel is over the limit of 30 (--max-supersegments)",
            ),
            (
                cam(r#"{"eye": [1, 1, 1], "target": [1, 1, 1]}"#),
                "camera: eye and target must differ",
            ),
            (
                cam(r#"{"eye": [0, 0, 0], "target": [0, 2, 0]}"#),
                "camera: up must not be parallel to the view direction",
            ),
            (
                cam(r#"{"eye": [0, 0, 0], "target": [1, 0, 0], "fov_y_degrees": 180}"#),
                "camera: fov_y_degrees 180 must lie between 0 and 180 degrees",
            ),
        ];
        for (json, message) in cases {
            assert_eq!(checked(&json).unwrap_err(), message, "{json}");
        }
        let mut scene = default_scene(&info());
        scene.channels[1].channel = 5;
        let json = format!(
            r#"{{"scene": {}, "width": 4, "height": 4}}"#,
            serde_json::to_string(&scene).unwrap()
        );
        assert_eq!(
            checked(&json).unwrap_err(),
            "scene: channel 5 does not exist (vol has 2 channels)"
        );
        for style in &mut scene.channels {
            style.channel = 0;
            style.visible = false;
        }
        let json = format!(
            r#"{{"scene": {}, "width": 4, "height": 4}}"#,
            serde_json::to_string(&scene).unwrap()
        );
        assert_eq!(checked(&json).unwrap_err(), "scene: no channel is visible");
        let mut scene = default_scene(&info());
        scene.mode = RenderMode::Mip;
        let json = format!(
            r#"{{"scene": {}, "width": 4, "height": 4}}"#,
            serde_json::to_string(&scene).unwrap()
        );
        assert_eq!(
            checked(&json).unwrap_err(),
            "scene: mode mip: a VDI holds composited colour and opacity (mode dvr only)"
        );
        let mut camera = default_scene(&info()).camera;
        camera.eye[0] = f64::NAN;
        assert_eq!(
            check_camera(&camera).unwrap_err().to_string(),
            "camera: eye, target, up and fov_y_degrees must be finite"
        );
        assert!(checked(r#"{"width": 1, "height": 1, "colour": 1}"#).is_err());
        let over = RequestError::TooManySupersegments {
            supersegments: 1,
            limit: 0,
        };
        assert!(over.over_limit() && !RequestError::NoSupersegments.over_limit());
    }
}
