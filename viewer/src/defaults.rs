//! The default view of a volume, for every driver (the `viewer` commands, the window and the
//! web page): the orbit camera, channel colours and transfer-function ramps from the store's
//! `omero` windows and channel statistics, and reading scene files.

use std::path::PathBuf;
use std::str::FromStr;

use crate::gpu::renderer::MAX_CHANNELS;
use crate::scene::{Camera, ChannelStyle, OpacityPoint, Scene, SceneDocumentError, box_diagonal};
use crate::source::{SampleType, VolumeInfo};

/// Default vertical field of view, degrees: a scene file's.
pub use crate::scene::DEFAULT_FOV_DEGREES;
/// Default opacity (at the reference step) at the top of a default transfer-function ramp.
pub const DEFAULT_OPACITY: f64 = 0.05;
/// Default camera: azimuth 30°, elevation 20°, 1.5 volume diagonals from the centre.
pub const DEFAULT_ORBIT: CameraSpec = CameraSpec::Orbit {
    azimuth: 30.0,
    elevation: 20.0,
    distance: 1.5,
};
/// Colours cycled for channels whose store gives none (linear RGB).
pub const DEFAULT_COLOURS: [[f64; 3]; 6] = [
    [0.0, 1.0, 1.0],
    [1.0, 0.0, 1.0],
    [1.0, 1.0, 0.0],
    [0.0, 1.0, 0.0],
    [1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0],
];

/// Why a scene cannot be had: a scene file that cannot be read or is not a scene, or one
/// that draws a channel the volume does not have. Messages name the file or flag at fault.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// A scene file that cannot be read.
    #[error("{}: cannot read", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A document that is not a scene that can be drawn.
    #[error(transparent)]
    Document(#[from] SceneDocumentError),
    /// A channel the volume does not have.
    #[error("{what}: channel {channel} does not exist ({volume} has {channels} channels)")]
    NoChannel {
        /// Where it was asked for (`scene file`, `--tf`, ...).
        what: String,
        /// The channel.
        channel: usize,
        /// The volume.
        volume: String,
        /// Its channels.
        channels: usize,
    },
}

/// A list of numbers ([`numbers`]) that is not `N` finite numbers.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum NumbersError {
    /// Another count, or something that is not a number.
    #[error("{what} '{text}': expected {count} comma-separated numbers")]
    Count {
        /// The value's name, e.g. `camera eye`.
        what: String,
        /// The text given.
        text: String,
        /// Numbers expected.
        count: usize,
    },
    /// A number that is not finite.
    #[error("{what} '{text}': numbers must be finite")]
    NotFinite {
        /// The value's name.
        what: String,
        /// The text given.
        text: String,
    },
}

/// A `--camera` (or bench camera) that is not a [`CameraSpec`].
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum CameraSpecError {
    /// Its numbers are not three (or two triples) of finite numbers.
    #[error(transparent)]
    Numbers(#[from] NumbersError),
    /// An orbit distance of zero or less.
    #[error("camera '{text}': distance must be positive")]
    Distance {
        /// The text given.
        text: String,
    },
}

/// A camera as scene files, the command line (`--camera`) and the bench give it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CameraSpec {
    /// `AZIMUTH,ELEVATION,DISTANCE`: orbit around the volume centre, in the microscope's
    /// frame. Azimuth 0 and elevation 0 put the eye on the `−z` side looking toward `+z`
    /// (slice 0 nearest) with `−y` up, so `x` runs right and `y` down, as a slice viewer
    /// shows the stack; azimuth turns the eye toward `+x` about the `y` axis, elevation
    /// toward `−y` (up). Angles in degrees, distance in volume diagonals from the centre.
    Orbit {
        /// Degrees.
        azimuth: f64,
        /// Degrees.
        elevation: f64,
        /// Volume diagonals.
        distance: f64,
    },
    /// `EX,EY,EZ:TX,TY,TZ`: eye and target in world units (`x, y, z`), `−y` up.
    LookAt {
        /// Eye position.
        eye: [f64; 3],
        /// Point looked at.
        target: [f64; 3],
    },
}

/// Parses `N` comma-separated finite numbers; `what` names the value in the error.
///
/// # Errors
///
/// [`NumbersError::Count`] for another count or a non-number, [`NumbersError::NotFinite`]
/// for a non-finite number.
pub fn numbers<const N: usize>(s: &str, what: &str) -> Result<[f64; N], NumbersError> {
    let count = || NumbersError::Count {
        what: what.to_string(),
        text: s.to_string(),
        count: N,
    };
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| count())?;
    let arr: [f64; N] = v.try_into().map_err(|_| count())?;
    if arr.iter().any(|x| !x.is_finite()) {
        return Err(NumbersError::NotFinite {
            what: what.to_string(),
            text: s.to_string(),
        });
    }
    Ok(arr)
}

impl FromStr for CameraSpec {
    type Err = CameraSpecError;

    fn from_str(s: &str) -> Result<Self, CameraSpecError> {
        if let Some((eye, target)) = s.split_once(':') {
            Ok(Self::LookAt {
                eye: numbers(eye, "camera eye")?,
                target: numbers(target, "camera target")?,
            })
        } else {
            let [azimuth, elevation, distance] = numbers(s, "camera")?;
            if distance <= 0.0 {
                return Err(CameraSpecError::Distance {
                    text: s.to_string(),
                });
            }
            Ok(Self::Orbit {
                azimuth,
                elevation,
                distance,
            })
        }
    }
}

/// Centre of the volume's box in world space (`x, y, z`; see the [`crate::scene`] module doc).
pub fn volume_centre(info: &VolumeInfo) -> [f64; 3] {
    let e = volume_extent(info);
    [e[0] / 2.0, e[1] / 2.0, e[2] / 2.0]
}

/// Extent of the volume's box in world space (`x, y, z`).
pub fn volume_extent(info: &VolumeInfo) -> [f64; 3] {
    let s = info.levels[0].shape;
    let v = info.voxel_size;
    [s[2] as f64 * v[2], s[1] as f64 * v[1], s[0] as f64 * v[0]]
}

impl CameraSpec {
    /// The camera for `info`'s volume.
    pub fn camera(&self, info: &VolumeInfo, fov_y_degrees: f64) -> Camera {
        self.camera_in_box(volume_extent(info), fov_y_degrees)
    }

    /// The camera for a volume whose box is `[0, extent]` (world units, `x, y, z`).
    pub fn camera_in_box(&self, extent: [f64; 3], fov_y_degrees: f64) -> Camera {
        let c = extent.map(|e| e / 2.0);
        match *self {
            Self::Orbit {
                azimuth,
                elevation,
                distance,
            } => {
                let e = extent;
                let diagonal = box_diagonal(e);
                let (a, el) = (azimuth.to_radians(), elevation.to_radians());
                let dir = [el.cos() * a.sin(), -el.sin(), -el.cos() * a.cos()];
                // The derivative of the eye position with respect to the elevation: always
                // orthogonal to the view direction, never zero, even looking straight down.
                let up = [-el.sin() * a.sin(), -el.cos(), el.sin() * a.cos()];
                let d = distance * diagonal;
                Camera {
                    eye: [c[0] + d * dir[0], c[1] + d * dir[1], c[2] + d * dir[2]],
                    target: c,
                    up,
                    fov_y_degrees,
                }
            }
            Self::LookAt { eye, target } => {
                let d = [target[0] - eye[0], target[1] - eye[1], target[2] - eye[2]];
                let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                // −y up (the scene default), unless the view is (nearly) along y.
                let up = if len > 0.0 && (d[1] / len).abs() > 0.999 {
                    [0.0, 0.0, 1.0]
                } else {
                    [0.0, -1.0, 0.0]
                };
                Camera {
                    eye,
                    target,
                    up,
                    fov_y_degrees,
                }
            }
        }
    }
}

/// The default transfer-function ramp of a channel, from opacity 0 at `lo` to
/// [`DEFAULT_OPACITY`] at `hi`, so that the background is transparent and the brightest
/// structures the most opaque:
/// - `lo` is the display window's start, raised to the median when that is higher (the
///   background of sparse fluorescence), else the range minimum, else 0;
/// - `hi` is halfway between the window's end and the range maximum (a window that ends at
///   the 99.9th percentile of a very sparse channel would otherwise make nearly all its signal
///   opaque), else whichever of the two is known;
/// - with neither above `lo`, the sample type's range (`[0, 1]` for float).
pub fn default_opacity(info: &VolumeInfo, channel: usize) -> Vec<OpacityPoint> {
    let d = info.display.get(channel).cloned().unwrap_or_default();
    // Only finite hints count: a float channel holding ±Inf has an infinite range (and maybe
    // median), and a ramp ending at infinity would give NaN opacities.
    let finite = |v: &f64| v.is_finite();
    let end = |pair: Option<[f64; 2]>, i: usize| pair.map(|p| p[i]).filter(finite);
    let lo = end(d.window, 0)
        .or(end(d.range, 0))
        .unwrap_or(0.0)
        .max(d.median.filter(finite).unwrap_or(f64::NEG_INFINITY));
    let hi = match (end(d.window, 1), end(d.range, 1)) {
        (Some(end), Some(max)) if max > end => 0.5 * (end + max),
        (Some(end), _) => end,
        (None, Some(max)) => max,
        (None, None) => f64::NEG_INFINITY,
    };
    let [lo, hi] = if hi > lo {
        [lo, hi]
    } else {
        match info.sample_type {
            SampleType::U8 => [0.0, u8::MAX as f64],
            SampleType::U16 => [0.0, u16::MAX as f64],
            SampleType::I16 => [0.0, i16::MAX as f64],
            SampleType::U32 => [0.0, u32::MAX as f64],
            SampleType::I32 => [0.0, i32::MAX as f64],
            SampleType::F32 => [0.0, 1.0],
        }
    };
    OpacityPoint::ramp(lo, hi, DEFAULT_OPACITY)
}

/// The default style of every channel of `info`: the first [`MAX_CHANNELS`] visible (as many
/// as render at once), the rest listed but hidden.
pub fn default_channels(info: &VolumeInfo) -> Vec<ChannelStyle> {
    (0..info.channels.len())
        .map(|c| ChannelStyle {
            channel: c,
            visible: c < MAX_CHANNELS,
            color: info
                .display
                .get(c)
                .and_then(|d| d.color)
                .unwrap_or(DEFAULT_COLOURS[c % DEFAULT_COLOURS.len()]),
            opacity: default_opacity(info, c),
        })
        .collect()
}

/// The default scene of `info`'s volume: [`DEFAULT_ORBIT`], every channel visible in its
/// store colour with its default ramp ([`default_channels`]), black background.
pub fn default_scene(info: &VolumeInfo) -> Scene {
    Scene {
        camera: DEFAULT_ORBIT.camera(info, DEFAULT_FOV_DEGREES),
        channels: default_channels(info),
        background: [0.0; 3],
        filter: crate::scene::Filter::Trilinear,
        mode: crate::scene::RenderMode::Dvr,
        clip: crate::scene::Clip::default(),
    }
}

/// Errors unless `info`'s volume has channel `channel`; `what` names where it was asked for
/// (`scene file`, `--tf`, ...).
///
/// # Errors
/// [`SceneError::NoChannel`], naming `what`, the channel and the volume.
pub fn check_channel(info: &VolumeInfo, channel: usize, what: &str) -> Result<(), SceneError> {
    let n = info.channels.len();
    if channel < n {
        Ok(())
    } else {
        Err(SceneError::NoChannel {
            what: what.to_string(),
            channel,
            volume: info.name.clone(),
            channels: n,
        })
    }
}

/// Reads a JSON scene file.
///
/// # Errors
/// [`SceneError::Read`] or [`SceneError::Document`], naming the file.
pub fn read_scene(path: &std::path::Path) -> Result<Scene, SceneError> {
    let bytes = std::fs::read(path).map_err(|source| SceneError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(Scene::from_json(&bytes, &path.display().to_string())?)
}
