//! Command-line flags shared by the rendering subcommands: where the volume comes from
//! ([`SourceArgs`]) and what to draw ([`SceneArgs`]: a JSON scene file, flags, or both, the
//! flags overriding the file).

use std::path::PathBuf;
use std::str::FromStr;

use anyhow::{Context, Result, bail, ensure};

use crate::scene::{Camera, ChannelStyle, OpacityPoint, Scene};
use crate::source::{BrickSource, HttpSource, LocalSource, SampleType, VolumeInfo};

/// Where the volume comes from: a brick server and dataset name, or a local store.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct SourceArgs {
    /// Brick server URL, e.g. `http://127.0.0.1:8000` (with `--dataset`).
    #[arg(long, value_name = "URL", conflicts_with = "store", requires = "dataset")]
    pub server: Option<String>,
    /// Dataset name on the brick server.
    #[arg(long, value_name = "NAME", requires = "server")]
    pub dataset: Option<String>,
    /// Local OME-Zarr store, instead of a server.
    #[arg(long, value_name = "PATH")]
    pub store: Option<PathBuf>,
}

impl SourceArgs {
    /// Opens the source the flags name.
    pub fn open(&self) -> Result<Box<dyn BrickSource>> {
        match (&self.server, &self.dataset, &self.store) {
            (Some(url), Some(name), None) => Ok(Box::new(HttpSource::open(url, name)?)),
            (None, None, Some(path)) => Ok(Box::new(LocalSource::open(path)?)),
            _ => bail!("give either --server URL --dataset NAME, or --store PATH"),
        }
    }
}

/// Default vertical field of view, degrees.
pub const DEFAULT_FOV_DEGREES: f64 = 30.0;
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

/// A camera given on the command line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CameraSpec {
    /// `AZIMUTH,ELEVATION,DISTANCE`: orbit around the volume centre. Azimuth 0 and elevation 0
    /// put the eye on the `+z` side looking down `-z`, with `+y` up; azimuth turns toward `+x`
    /// about the `y` axis, elevation toward `+y`. Angles in degrees, distance in volume
    /// diagonals from the centre.
    Orbit {
        /// Degrees.
        azimuth: f64,
        /// Degrees.
        elevation: f64,
        /// Volume diagonals.
        distance: f64,
    },
    /// `EX,EY,EZ:TX,TY,TZ`: eye and target in world units (`x, y, z`).
    LookAt {
        /// Eye position.
        eye: [f64; 3],
        /// Point looked at.
        target: [f64; 3],
    },
}

fn numbers<const N: usize>(s: &str, what: &str) -> Result<[f64; N], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("{what} '{s}': expected {N} comma-separated numbers"))?;
    let arr: [f64; N] = v
        .try_into()
        .map_err(|_| format!("{what} '{s}': expected {N} comma-separated numbers"))?;
    if arr.iter().any(|x| !x.is_finite()) {
        return Err(format!("{what} '{s}': numbers must be finite"));
    }
    Ok(arr)
}

impl FromStr for CameraSpec {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s.split_once(':') {
            Some((eye, target)) => Ok(Self::LookAt {
                eye: numbers(eye, "camera eye")?,
                target: numbers(target, "camera target")?,
            }),
            None => {
                let [azimuth, elevation, distance] = numbers(s, "camera")?;
                if distance <= 0.0 {
                    return Err(format!("camera '{s}': distance must be positive"));
                }
                Ok(Self::Orbit {
                    azimuth,
                    elevation,
                    distance,
                })
            }
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
    [
        s[2] as f64 * v[2],
        s[1] as f64 * v[1],
        s[0] as f64 * v[0],
    ]
}

impl CameraSpec {
    /// The camera for `info`'s volume.
    pub fn camera(&self, info: &VolumeInfo, fov_y_degrees: f64) -> Camera {
        let c = volume_centre(info);
        match *self {
            Self::Orbit {
                azimuth,
                elevation,
                distance,
            } => {
                let e = volume_extent(info);
                let diagonal = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt();
                let (a, el) = (azimuth.to_radians(), elevation.to_radians());
                let dir = [el.cos() * a.sin(), el.sin(), el.cos() * a.cos()];
                // The derivative of the eye position with respect to the elevation: always
                // orthogonal to the view direction, never zero, even looking straight down.
                let up = [-el.sin() * a.sin(), el.cos(), -el.sin() * a.cos()];
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
                // +y up, unless the view is (nearly) along y.
                let up = if len > 0.0 && (d[1] / len).abs() > 0.999 {
                    [0.0, 0.0, 1.0]
                } else {
                    [0.0, 1.0, 0.0]
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

/// A transfer function given on the command line for one channel.
#[derive(Clone, Debug, PartialEq)]
pub struct TfSpec {
    /// Channel index.
    pub channel: usize,
    /// Opacity control points, ascending in value.
    pub points: Vec<OpacityPoint>,
}

impl FromStr for TfSpec {
    type Err = String;

    /// `C:LO:HI:OPACITY` (a ramp from 0 at `LO` to `OPACITY` at `HI`, holding above), or
    /// `C:V=A,V=A,...` (explicit control points).
    fn from_str(s: &str) -> Result<Self, String> {
        let bad = |why: &str| format!("transfer function '{s}': {why}");
        let parts: Vec<&str> = s.split(':').collect();
        let channel = parts[0]
            .trim()
            .parse::<usize>()
            .map_err(|_| bad("expected a channel index before the first ':'"))?;
        let num = |p: &str| {
            p.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| bad(&format!("'{p}' is not a finite number")))
        };
        let points = match parts.len() {
            4 => {
                let (lo, hi, a) = (num(parts[1])?, num(parts[2])?, num(parts[3])?);
                if lo >= hi {
                    return Err(bad("LO must be below HI"));
                }
                vec![
                    OpacityPoint {
                        value: lo,
                        opacity: 0.0,
                    },
                    OpacityPoint {
                        value: hi,
                        opacity: a,
                    },
                ]
            }
            2 => parts[1]
                .split(',')
                .map(|p| {
                    let (v, a) = p
                        .split_once('=')
                        .ok_or_else(|| bad("expected VALUE=OPACITY pairs"))?;
                    Ok(OpacityPoint {
                        value: num(v)?,
                        opacity: num(a)?,
                    })
                })
                .collect::<Result<Vec<_>, String>>()?,
            _ => return Err(bad("expected C:LO:HI:OPACITY or C:V=A,V=A,...")),
        };
        if points.iter().any(|p| !(0.0..=1.0).contains(&p.opacity)) {
            return Err(bad("opacities must lie in [0, 1]"));
        }
        if points.windows(2).any(|w| w[0].value > w[1].value) {
            return Err(bad("values must ascend"));
        }
        Ok(Self { channel, points })
    }
}

/// A channel colour given on the command line: `C:R,G,B`, linear RGB in `[0, 1]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ColorSpec {
    /// Channel index.
    pub channel: usize,
    /// Linear RGB.
    pub color: [f64; 3],
}

impl FromStr for ColorSpec {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let (c, rgb) = s
            .split_once(':')
            .ok_or_else(|| format!("colour '{s}': expected C:R,G,B"))?;
        let channel = c
            .trim()
            .parse()
            .map_err(|_| format!("colour '{s}': '{c}' is not a channel index"))?;
        let color = numbers::<3>(rgb, "colour")?;
        if color.iter().any(|v| !(0.0..=1.0).contains(v)) {
            return Err(format!("colour '{s}': components must lie in [0, 1]"));
        }
        Ok(Self { channel, color })
    }
}

/// Background colour: `R,G,B`, linear RGB.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rgb(pub [f64; 3]);

impl FromStr for Rgb {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        numbers::<3>(s, "background").map(Rgb)
    }
}

/// What to draw: a JSON scene file (`schemas/json/scene.schema.json`) and/or flags. Flags
/// override the file; without either, the camera orbits the volume and every channel gets
/// its store colour and a ramp over its display window.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct SceneArgs {
    /// JSON scene file (camera, channel styles, background).
    #[arg(long, value_name = "FILE")]
    pub scene: Option<PathBuf>,
    /// Camera: `AZIMUTH,ELEVATION,DISTANCE` (degrees, degrees, volume diagonals) orbiting the
    /// volume centre, or `EX,EY,EZ:TX,TY,TZ` (eye and target, world units `x, y, z`).
    #[arg(long, value_name = "SPEC", allow_hyphen_values = true)]
    pub camera: Option<CameraSpec>,
    /// Vertical field of view in degrees [default: 30, or the scene file's].
    #[arg(long, value_name = "DEGREES")]
    pub fov: Option<f64>,
    /// Transfer function of a channel (repeatable): `C:LO:HI:OPACITY` ramps the opacity from 0
    /// at LO to OPACITY at HI; `C:V=A,V=A,...` gives control points.
    #[arg(long = "tf", value_name = "SPEC", allow_hyphen_values = true)]
    pub tf: Vec<TfSpec>,
    /// Visible channels, e.g. `0,2` [default: all].
    #[arg(long, value_name = "LIST", value_delimiter = ',')]
    pub channels: Option<Vec<usize>>,
    /// Colour of a channel (repeatable): `C:R,G,B`, linear RGB in [0, 1].
    #[arg(long = "color", value_name = "SPEC")]
    pub color: Vec<ColorSpec>,
    /// Background: `R,G,B`, linear RGB [default: black].
    #[arg(long, value_name = "RGB")]
    pub background: Option<Rgb>,
}

/// The default transfer-function ramp of a channel: from 0 at the display window's start to
/// [`DEFAULT_OPACITY`] at its end; without a window, over the channel's value range, else over
/// the sample type's range (`[0, 1]` for float).
pub fn default_opacity(info: &VolumeInfo, channel: usize) -> Vec<OpacityPoint> {
    let d = info.display.get(channel).cloned().unwrap_or_default();
    let [lo, hi] = d
        .window
        .filter(|[a, b]| a < b)
        .or(d.range.filter(|[a, b]| a < b))
        .unwrap_or(match info.sample_type {
            SampleType::U8 => [0.0, u8::MAX as f64],
            SampleType::U16 => [0.0, u16::MAX as f64],
            SampleType::I16 => [0.0, i16::MAX as f64],
            SampleType::U32 => [0.0, u32::MAX as f64],
            SampleType::I32 => [0.0, i32::MAX as f64],
            SampleType::F32 => [0.0, 1.0],
        });
    vec![
        OpacityPoint {
            value: lo,
            opacity: 0.0,
        },
        OpacityPoint {
            value: hi,
            opacity: DEFAULT_OPACITY,
        },
    ]
}

/// The default style of every channel of `info`.
pub fn default_channels(info: &VolumeInfo) -> Vec<ChannelStyle> {
    (0..info.channels.len())
        .map(|c| ChannelStyle {
            channel: c,
            visible: true,
            color: info
                .display
                .get(c)
                .and_then(|d| d.color)
                .unwrap_or(DEFAULT_COLOURS[c % DEFAULT_COLOURS.len()]),
            opacity: default_opacity(info, c),
        })
        .collect()
}

/// Reads a JSON scene file.
pub fn read_scene(path: &std::path::Path) -> Result<Scene> {
    let shown = path.display();
    let bytes = std::fs::read(path).with_context(|| format!("{shown}: cannot read"))?;
    serde_json::from_slice(&bytes).with_context(|| format!("{shown}: not a valid scene file"))
}

impl SceneArgs {
    /// The scene for `info`'s volume: the scene file (or the defaults), then the flags.
    pub fn scene(&self, info: &VolumeInfo) -> Result<Scene> {
        let n = info.channels.len();
        let mut scene = match &self.scene {
            Some(path) => read_scene(path)?,
            None => Scene {
                camera: DEFAULT_ORBIT.camera(info, DEFAULT_FOV_DEGREES),
                channels: default_channels(info),
                background: [0.0; 3],
            },
        };
        let check = |c: usize, what: &str| {
            ensure!(
                c < n,
                "{what}: channel {c} does not exist ({} has {n} channels)",
                info.name
            );
            Ok(())
        };
        for s in &scene.channels {
            check(s.channel, "scene file")?;
        }
        if let Some(fov) = self.fov {
            ensure!(
                fov > 0.0 && fov < 180.0,
                "--fov {fov}: must lie between 0 and 180 degrees"
            );
            scene.camera.fov_y_degrees = fov;
        }
        if let Some(spec) = &self.camera {
            scene.camera = spec.camera(info, scene.camera.fov_y_degrees);
        }
        // A channel named by a flag but absent from the scene file gets its default style.
        let style = |scene: &mut Scene, c: usize| -> usize {
            match scene.channels.iter().position(|s| s.channel == c) {
                Some(i) => i,
                None => {
                    scene.channels.push(default_channels(info).swap_remove(c));
                    scene.channels.len() - 1
                }
            }
        };
        for tf in &self.tf {
            check(tf.channel, "--tf")?;
            let i = style(&mut scene, tf.channel);
            scene.channels[i].opacity = tf.points.clone();
        }
        for col in &self.color {
            check(col.channel, "--color")?;
            let i = style(&mut scene, col.channel);
            scene.channels[i].color = col.color;
        }
        if let Some(visible) = &self.channels {
            for &c in visible {
                check(c, "--channels")?;
                style(&mut scene, c);
            }
            for s in &mut scene.channels {
                s.visible = visible.contains(&s.channel);
            }
        }
        if let Some(Rgb(bg)) = self.background {
            scene.background = bg;
        }
        scene.channels.sort_by_key(|s| s.channel);
        Ok(scene)
    }
}
