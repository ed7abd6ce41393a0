//! Command-line flags shared by the rendering subcommands: where the volume comes from
//! ([`SourceArgs`]) and what to draw ([`SceneArgs`]: a JSON scene file, flags, or both, the
//! flags overriding the file).

use std::path::PathBuf;
use std::str::FromStr;

use anyhow::{Context, Result, bail, ensure};
use residency_schemas::vdi::VolumetricDepthImage;

use residency_store::location::{ObjectStoreOptions, StoreLocation};
use residency_viewer::defaults::{
    CameraSpec, NumbersError, check_channel, default_channels, default_scene, numbers, read_scene,
    volume_extent,
};
use residency_viewer::scene::{ClipBox, ClipPlane, Filter, OpacityPoint, RenderMode, Scene};
use residency_viewer::source::{BrickSource, HttpSource, LocalSource, VolumeInfo, read_token_file};

/// Where the volume comes from: a brick server and dataset name, or a local store.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct SourceArgs {
    /// Brick server URL, e.g. `http://127.0.0.1:8000` (with `--dataset`).
    #[arg(
        long,
        value_name = "URL",
        conflicts_with = "store",
        requires = "dataset"
    )]
    pub server: Option<String>,
    /// Dataset name on the brick server.
    #[arg(long, value_name = "NAME", requires = "server")]
    pub dataset: Option<String>,
    /// File holding the bearer token of a server started with `--token-file`.
    #[arg(long, value_name = "FILE", requires = "server")]
    pub token_file: Option<PathBuf>,
    /// OME-Zarr store read directly, instead of a server: a folder, a file:// URL, or
    /// s3://BUCKET/PREFIX (credentials and region from the AWS variables).
    #[arg(long, value_name = "PATH")]
    pub store: Option<StoreLocation>,
    /// Endpoint URL of an S3-compatible server that is not AWS, for an s3:// `--store`
    /// (default: AWS_ENDPOINT_URL, else AWS).
    #[arg(long, value_name = "URL")]
    pub s3_endpoint: Option<String>,
}

impl SourceArgs {
    /// Opens the source the flags name.
    pub fn open(&self) -> Result<Box<dyn BrickSource>> {
        match (&self.server, &self.dataset, &self.store) {
            (Some(url), Some(name), None) => {
                let token = self
                    .token_file
                    .as_deref()
                    .map(read_token_file)
                    .transpose()?;
                Ok(Box::new(HttpSource::open_with_token(
                    url,
                    name,
                    token.as_deref(),
                )?))
            }
            (None, None, Some(location)) => {
                let options = ObjectStoreOptions::for_location(location, self.s3_endpoint.clone())?;
                Ok(Box::new(LocalSource::open_location(location, &options)?))
            }
            _ => bail!("give either --server URL --dataset NAME, or --store PATH"),
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

/// A `--tf` that is not a transfer function: the flag's text and what is wrong with it.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("transfer function '{spec}': {why}")]
pub struct TfSpecError {
    /// The text given.
    pub spec: String,
    /// What is wrong.
    pub why: String,
}

impl FromStr for TfSpec {
    type Err = TfSpecError;

    /// `C:LO:HI:OPACITY` (a ramp from 0 at `LO` to `OPACITY` at `HI`, holding above), or
    /// `C:V=A,V=A,...` (explicit control points).
    fn from_str(s: &str) -> Result<Self, TfSpecError> {
        let bad = |why: &str| TfSpecError {
            spec: s.to_string(),
            why: why.to_string(),
        };
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
                OpacityPoint::ramp(lo, hi, a)
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
                .collect::<Result<Vec<_>, TfSpecError>>()?,
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

/// A `--color` that is not `C:R,G,B` with components in `[0, 1]`.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ColorSpecError {
    /// No `:` between channel and colour.
    #[error("colour '{spec}': expected C:R,G,B")]
    Syntax {
        /// The text given.
        spec: String,
    },
    /// A channel that is not an index.
    #[error("colour '{spec}': '{channel}' is not a channel index")]
    Channel {
        /// The text given.
        spec: String,
        /// The channel part.
        channel: String,
    },
    /// Not three finite numbers.
    #[error(transparent)]
    Numbers(#[from] NumbersError),
    /// A component outside `[0, 1]`.
    #[error("colour '{spec}': components must lie in [0, 1]")]
    Range {
        /// The text given.
        spec: String,
    },
}

impl FromStr for ColorSpec {
    type Err = ColorSpecError;

    fn from_str(s: &str) -> Result<Self, ColorSpecError> {
        let (c, rgb) = s.split_once(':').ok_or_else(|| ColorSpecError::Syntax {
            spec: s.to_string(),
        })?;
        let channel = c.trim().parse().map_err(|_| ColorSpecError::Channel {
            spec: s.to_string(),
            channel: c.to_string(),
        })?;
        let color = numbers::<3>(rgb, "colour")?;
        if color.iter().any(|v| !(0.0..=1.0).contains(v)) {
            return Err(ColorSpecError::Range {
                spec: s.to_string(),
            });
        }
        Ok(Self { channel, color })
    }
}

/// Background colour: `R,G,B`, linear RGB.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rgb(pub [f64; 3]);

impl FromStr for Rgb {
    type Err = NumbersError;

    fn from_str(s: &str) -> Result<Self, NumbersError> {
        numbers::<3>(s, "background").map(Rgb)
    }
}

/// `--clip-box`: the box kept, `X0,Y0,Z0,X1,Y1,Z1` in world units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoxSpec(pub ClipBox);

impl FromStr for BoxSpec {
    type Err = NumbersError;

    fn from_str(s: &str) -> Result<Self, NumbersError> {
        let v = numbers::<6>(s, "clip box")?;
        Ok(Self(ClipBox {
            min: [v[0], v[1], v[2]],
            max: [v[3], v[4], v[5]],
        }))
    }
}

/// `--clip-plane`: a plane through a point keeping the side its normal points into,
/// `PX,PY,PZ,NX,NY,NZ` in world units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneSpec(pub ClipPlane);

impl FromStr for PlaneSpec {
    type Err = NumbersError;

    fn from_str(s: &str) -> Result<Self, NumbersError> {
        let v = numbers::<6>(s, "clip plane")?;
        Ok(Self(ClipPlane {
            point: [v[0], v[1], v[2]],
            normal: [v[3], v[4], v[5]],
        }))
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
    /// Reconstruction filter of every sample: `trilinear`, or `tricubic` (the cubic B-spline
    /// over 4³ voxels; 8 trilinear fetches per sample) [default: the scene file's, else
    /// trilinear].
    #[arg(long, value_name = "FILTER", value_parser = super::names_parser::<Filter>())]
    pub filter: Option<Filter>,
    /// What each ray makes of its samples: `dvr` (emission–absorption, the default), `mip`
    /// (maximum intensity projection: per channel the largest value along the ray, through
    /// its transfer function scaled to 1, channels added) or `iso` (per channel the surface
    /// where its value crosses the middle of its ramp, the nearest drawn shaded; methods
    /// residency, page-table and octree) [default: the scene file's, else dvr].
    #[arg(long, value_name = "MODE", value_parser = super::names_parser::<RenderMode>())]
    pub mode: Option<RenderMode>,
    /// Draw only what lies inside this box: `X0,Y0,Z0,X1,Y1,Z1`, world units (replaces the
    /// scene file's box).
    #[arg(long, value_name = "BOX", allow_hyphen_values = true)]
    pub clip_box: Option<BoxSpec>,
    /// Draw only what lies on the side of a plane its normal points into:
    /// `PX,PY,PZ,NX,NY,NZ`, a point and the normal, world units (repeatable, at most 6; added
    /// to the scene file's planes).
    #[arg(long, value_name = "PLANE", allow_hyphen_values = true)]
    pub clip_plane: Vec<PlaneSpec>,
    /// Draw nothing nearer the eye than this distance along the view direction (world units):
    /// a clip plane that follows the camera.
    #[arg(long, value_name = "DISTANCE")]
    pub clip_near: Option<f64>,
}

impl SceneArgs {
    /// Reads the volumetric depth image at `path` (`viewer render --vdi`, `viewer view --vdi`)
    /// and the camera to ray cast it from ([`SceneArgs::camera_for_vdi`]). The flags that
    /// would change what the VDI baked in are refused first, before the file is read.
    pub fn open_vdi(
        &self,
        path: &std::path::Path,
    ) -> Result<(VolumetricDepthImage, residency_viewer::scene::Camera)> {
        self.refuse_for_vdi()?;
        let bytes =
            std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
        let vdi = VolumetricDepthImage::decode(&bytes, &path.display().to_string())?;
        let h = &vdi.header;
        if h.volume_min != [0.0; 3] {
            bail!(
                "{}: a VDI's volume box starts at the origin",
                path.display()
            );
        }
        let extent = std::array::from_fn(|a| h.volume_max[a] - h.volume_min[a]);
        let camera = self.camera_for_vdi(h.camera.clone(), extent)?;
        Ok((vdi, camera))
    }

    /// The camera to render a volumetric depth image with: the scene file's (else `generated`,
    /// the VDI's own camera), then `--fov` and `--camera` (an orbit about the VDI's volume box
    /// `[0, extent]`).
    fn camera_for_vdi(
        &self,
        generated: residency_viewer::scene::Camera,
        extent: [f64; 3],
    ) -> Result<residency_viewer::scene::Camera> {
        let camera = match &self.scene {
            Some(path) => read_scene(path)?.camera,
            None => generated,
        };
        self.camera_flags(camera, extent)
    }

    /// `camera` with `--fov`, then `--camera` (about a volume box `[0, extent]`), applied.
    fn camera_flags(
        &self,
        mut camera: residency_viewer::scene::Camera,
        extent: [f64; 3],
    ) -> Result<residency_viewer::scene::Camera> {
        if let Some(fov) = self.fov {
            ensure!(
                fov > 0.0 && fov < 180.0,
                "--fov {fov}: must lie between 0 and 180 degrees"
            );
            camera.fov_y_degrees = fov;
        }
        if let Some(spec) = &self.camera {
            camera = spec.camera_in_box(extent, camera.fov_y_degrees);
        }
        Ok(camera)
    }

    /// Refuses the flags that would change what a VDI baked in (colours, transfer functions,
    /// background, filter, mode, clipping).
    fn refuse_for_vdi(&self) -> Result<()> {
        let baked = [
            (!self.tf.is_empty(), "--tf"),
            (!self.color.is_empty(), "--color"),
            (self.channels.is_some(), "--channels"),
            (self.background.is_some(), "--background"),
            (self.filter.is_some(), "--filter"),
            (self.mode.is_some(), "--mode"),
            (self.clip_box.is_some(), "--clip-box"),
            (!self.clip_plane.is_empty(), "--clip-plane"),
            (self.clip_near.is_some(), "--clip-near"),
        ];
        if let Some((_, flag)) = baked.iter().find(|(given, _)| *given) {
            bail!(
                "{flag} does not apply to a VDI: its colours, transfer functions, background, \
                 filter, mode and clipping were fixed when it was generated (`viewer vdi`)"
            );
        }
        Ok(())
    }

    /// The scene for `info`'s volume: the scene file (or the defaults), then the flags.
    pub fn scene(&self, info: &VolumeInfo) -> Result<Scene> {
        let mut scene = match &self.scene {
            Some(path) => read_scene(path)?,
            None => default_scene(info),
        };
        let check = |c: usize, what: &str| check_channel(info, c, what);
        for s in &scene.channels {
            check(s.channel, "scene file")?;
        }
        scene.camera = self.camera_flags(scene.camera, volume_extent(info))?;
        // A channel named by a flag but absent from the scene file gets its default style.
        let style = |scene: &mut Scene, c: usize| -> usize {
            if let Some(i) = scene.channels.iter().position(|s| s.channel == c) {
                i
            } else {
                let mut style = default_channels(info).swap_remove(c);
                style.visible = true;
                scene.channels.push(style);
                scene.channels.len() - 1
            }
        };
        for tf in &self.tf {
            check(tf.channel, "--tf")?;
            let i = style(&mut scene, tf.channel);
            scene.channels[i].opacity.clone_from(&tf.points);
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
        if let Some(filter) = self.filter {
            scene.filter = filter;
        }
        if let Some(mode) = self.mode {
            scene.mode = mode;
        }
        if let Some(BoxSpec(b)) = self.clip_box {
            scene.clip.region = Some(b);
        }
        scene
            .clip
            .planes
            .extend(self.clip_plane.iter().map(|p| p.0));
        if let Some(near) = self.clip_near {
            scene.clip.near = Some(near);
        }
        scene.clip.check()?;
        scene.channels.sort_by_key(|s| s.channel);
        Ok(scene)
    }
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use residency_viewer::defaults::{
        DEFAULT_COLOURS, DEFAULT_FOV_DEGREES, DEFAULT_OPACITY, DEFAULT_ORBIT, default_opacity,
        volume_centre, volume_extent,
    };
    use residency_viewer::scene::{ChannelStyle, box_diagonal};
    use residency_viewer::source::{ChannelDisplay, LevelInfo, SampleType};

    use super::*;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        source: SourceArgs,
        #[command(flatten)]
        scene: SceneArgs,
    }

    fn info() -> VolumeInfo {
        VolumeInfo {
            name: "vol".into(),
            sample_type: SampleType::U16,
            channels: vec!["a".into(), "b".into(), "c".into()],
            display: vec![
                ChannelDisplay {
                    color: Some([1.0, 0.0, 0.0]),
                    window: Some([100.0, 900.0]),
                    range: Some([0.0, 1000.0]),
                    median: Some(150.0),
                },
                ChannelDisplay {
                    color: None,
                    window: None,
                    range: Some([5.0, 50.0]),
                    median: None,
                },
                ChannelDisplay::default(),
            ],
            // z, y, x: a box of x 40, y 20, z 30 world units.
            voxel_size: [3.0, 1.0, 0.5],
            unit: None,
            brick_shape: [8, 8, 8],
            levels: vec![LevelInfo {
                shape: [10, 20, 80],
                factor: [1, 1, 1],
            }],
            minmax: None,
        }
    }

    fn parse(args: &[&str]) -> Cli {
        Cli::try_parse_from(std::iter::once("viewer").chain(args.iter().copied())).unwrap()
    }

    #[test]
    fn defaults_come_from_the_store() {
        let info = info();
        let scene = parse(&["--store", "x"]).scene.scene(&info).unwrap();
        assert_eq!(volume_centre(&info), [20.0, 10.0, 15.0]);
        let ramp = |lo, hi| OpacityPoint::ramp(lo, hi, DEFAULT_OPACITY);
        let c = &scene.channels;
        assert_eq!(c.len(), 3);
        assert!(c.iter().all(|s| s.visible));
        assert_eq!(
            (c[0].color, &c[0].opacity),
            ([1.0, 0.0, 0.0], &ramp(150.0, 950.0))
        );
        assert_eq!(
            (c[1].color, &c[1].opacity),
            (DEFAULT_COLOURS[1], &ramp(5.0, 50.0))
        );
        assert_eq!(c[2].opacity, ramp(0.0, 65535.0));
        assert_eq!(scene.background, [0.0; 3]);
        assert_eq!(scene.camera.target, [20.0, 10.0, 15.0]);
        assert_eq!(scene.camera.fov_y_degrees, DEFAULT_FOV_DEGREES);
        let d: Vec<f64> = (0..3)
            .map(|i| scene.camera.eye[i] - scene.camera.target[i])
            .collect();
        let diagonal = (40.0f64 * 40.0 + 20.0 * 20.0 + 30.0 * 30.0).sqrt();
        let len = d.iter().map(|x| x * x).sum::<f64>().sqrt();
        assert!((len - 1.5 * diagonal).abs() < 1e-9);
    }

    #[test]
    fn infinite_hints_give_a_finite_ramp() {
        // A float channel holding -Inf and +Inf: its range (and median) may be infinite.
        let mut info = info();
        info.sample_type = SampleType::F32;
        info.display[0] = ChannelDisplay {
            color: None,
            window: Some([-2.0, 3.0]),
            range: Some([f64::NEG_INFINITY, f64::INFINITY]),
            median: Some(0.5),
        };
        info.display[1] = ChannelDisplay {
            color: None,
            window: Some([f64::NEG_INFINITY, 4.0]),
            range: Some([1.0, f64::INFINITY]),
            median: Some(f64::INFINITY),
        };
        let tf = |c| {
            default_opacity(&info, c)
                .iter()
                .map(|p| p.value)
                .collect::<Vec<_>>()
        };
        assert_eq!(tf(0), [0.5, 3.0]);
        assert_eq!(tf(1), [1.0, 4.0]);
        for c in 0..2 {
            let style = ChannelStyle {
                channel: c,
                visible: true,
                color: [1.0; 3],
                opacity: default_opacity(&info, c),
            };
            for v in [f64::NEG_INFINITY, -1e38, 0.0, 3e38, f64::INFINITY] {
                assert!(style.opacity_at(v).is_finite(), "{c} {v}");
            }
        }
    }

    #[test]
    fn orbits_of_huge_and_tiny_volumes_stay_finite() {
        for v in [1e300, 1e-300] {
            let mut info = info();
            info.voxel_size = [v; 3];
            let cam = DEFAULT_ORBIT.camera(&info, 30.0);
            let (f, r, u) = cam.basis();
            assert!(
                cam.eye
                    .iter()
                    .chain(&f)
                    .chain(&r)
                    .chain(&u)
                    .all(|x| x.is_finite()),
                "{v}: {cam:?}"
            );
            let d = box_diagonal(volume_extent(&info));
            assert!((d / v / 6900f64.sqrt() - 1.0).abs() < 1e-12, "{d}");
        }
    }

    #[test]
    fn orbit_zero_views_the_stack_like_a_slice_viewer() {
        let info = info();
        let cam = "0,0,1".parse::<CameraSpec>().unwrap().camera(&info, 30.0);
        let diagonal = (40.0f64 * 40.0 + 20.0 * 20.0 + 30.0 * 30.0).sqrt();
        assert_eq!(cam.eye, [20.0, 10.0, 15.0 - diagonal]);
        let (forward, right, up) = cam.basis();
        assert_eq!(
            (forward, right, up),
            ([0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0])
        );
        // Straight down from above (elevation 90°): the frame stays well defined.
        let cam = "0,90,1".parse::<CameraSpec>().unwrap().camera(&info, 30.0);
        let (forward, right, _) = cam.basis();
        assert!((forward[1] - 1.0).abs() < 1e-12 && (right[0] - 1.0).abs() < 1e-12);
    }

    #[test]
    fn flags_set_camera_tf_colour_visibility_and_background() {
        let info = info();
        let cli = parse(&[
            "--server",
            "http://h:1",
            "--dataset",
            "d",
            "--camera",
            "90,0,2",
            "--fov",
            "45",
            "--tf",
            "2:-10:10:0.5",
            "--tf",
            "1:0=0.1,20=0.2",
            "--color",
            "2:0.5,0.25,1",
            "--channels",
            "0,2",
            "--background",
            "1,1,1",
            "--filter",
            "tricubic",
        ]);
        assert_eq!(cli.source.server.as_deref(), Some("http://h:1"));
        let scene = cli.scene.scene(&info).unwrap();
        let diagonal = (40.0f64 * 40.0 + 20.0 * 20.0 + 30.0 * 30.0).sqrt();
        // Azimuth 90°: the eye on the +x side, level, looking down -x, -y up.
        let eye = scene.camera.eye;
        assert!((eye[0] - (20.0 + 2.0 * diagonal)).abs() < 1e-9);
        assert!(
            (eye[1] - 10.0).abs() < 1e-12 && (eye[2] - 15.0).abs() < 1e-9,
            "{eye:?}"
        );
        assert!((scene.camera.up[1] + 1.0).abs() < 1e-15);
        assert_eq!(scene.camera.fov_y_degrees, 45.0);
        let c = &scene.channels;
        assert_eq!(
            c.iter().map(|s| s.visible).collect::<Vec<_>>(),
            [true, false, true]
        );
        assert_eq!(c[2].opacity_at(0.0), 0.25);
        assert_eq!(c[2].color, [0.5, 0.25, 1.0]);
        assert_eq!(c[1].opacity_at(10.0), 0.15000000000000002);
        assert_eq!(scene.background, [1.0; 3]);
        assert_eq!(scene.filter, Filter::Tricubic);
    }

    #[test]
    fn look_at_camera_and_scene_file_with_overrides() {
        let info = info();
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("scene.json");
        std::fs::write(
            &file,
            r#"{"camera": {"eye": [0, 0, 100], "target": [1, 2, 3]},
                "channels": [{"channel": 1, "color": [0, 1, 0], "opacity": [{"value": 0, "opacity": 0.3}]}]}"#,
        )
        .unwrap();
        let path = file.to_str().unwrap();
        let scene = parse(&["--store", "s", "--scene", path])
            .scene
            .scene(&info)
            .unwrap();
        assert_eq!(scene.channels.len(), 1);
        assert_eq!(scene.camera.target, [1.0, 2.0, 3.0]);
        let scene = parse(&[
            "--store",
            "s",
            "--scene",
            path,
            "--camera",
            "1,2,3:4,5,6",
            "--channels",
            "0",
        ])
        .scene
        .scene(&info)
        .unwrap();
        assert_eq!(
            (scene.camera.eye, scene.camera.target),
            ([1.0, 2.0, 3.0], [4.0, 5.0, 6.0])
        );
        // Channel 0 joins with its default style; channel 1 stays, hidden.
        assert_eq!(scene.channels.len(), 2);
        assert_eq!(
            (scene.channels[0].channel, scene.channels[0].visible),
            (0, true)
        );
        assert_eq!(
            (scene.channels[1].channel, scene.channels[1].visible),
            (1, false)
        );
        // Looking straight down y, up switches to +z.
        let cam = "0,10,0:0,0,0"
            .parse::<CameraSpec>()
            .unwrap()
            .camera(&info, 30.0);
        assert_eq!(cam.up, [0.0, 0.0, 1.0]);
    }

    #[test]
    fn bad_flags_give_clear_errors() {
        let info = info();
        let e = parse(&["--store", "s", "--tf", "3:0:1:1"])
            .scene
            .scene(&info)
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "--tf: channel 3 does not exist (vol has 3 channels)"
        );
        let bad = |args: &[&str]| {
            Cli::try_parse_from(std::iter::once("viewer").chain(args.iter().copied()))
                .err()
                .unwrap()
                .to_string()
        };
        assert!(
            bad(&["--tf", "0:5:1:0.5"])
                .contains("transfer function '0:5:1:0.5': LO must be below HI")
        );
        assert!(bad(&["--tf", "0:1:5:1.5"]).contains("opacities must lie in [0, 1]"));
        assert!(
            bad(&["--camera", "1,2"]).contains("camera '1,2': expected 3 comma-separated numbers")
        );
        assert!(bad(&["--camera", "1,2,0"]).contains("distance must be positive"));
        assert!(bad(&["--color", "0:2,0,0"]).contains("components must lie in [0, 1]"));
        assert!(
            bad(&["--server", "u", "--store", "s", "--dataset", "d"])
                .contains("cannot be used with")
        );
        let e = SourceArgs::default().open().err().unwrap();
        assert_eq!(
            e.to_string(),
            "give either --server URL --dataset NAME, or --store PATH"
        );
        let missing = tempfile::tempdir().unwrap().path().join("gone.json");
        let e = parse(&["--scene", missing.to_str().unwrap()])
            .scene
            .scene(&info)
            .unwrap_err();
        assert_eq!(e.to_string(), format!("{}: cannot read", missing.display()));
    }
}
