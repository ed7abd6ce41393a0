//! What to draw: the camera, each channel's transfer function and visibility, and the
//! compositing rule that the GPU renderer and the f64 reference ray caster both follow.
//!
//! **World space** is physical space (for example µm), axes `x, y, z`. Level 0 of a volume of
//! `nx × ny × nz` voxels with spacing `(sx, sy, sz)` fills the box `[0, nx·sx] × [0, ny·sy] ×
//! [0, nz·sz]`; voxel `(i, j, k)` of level `l` (downsampling factor `f`) has its centre at
//! `((i + ½)·f_x·sx, (j + ½)·f_y·sy, (k + ½)·f_z·sz)`. Sampling is trilinear between voxel
//! centres, clamped to the edge voxels.
//!
//! **Compositing** (front to back, emission–absorption). At a sample, each visible channel
//! `c` with value `v` contributes opacity `α_c = 1 − (1 − a_c(v))^(Δ/Δ₀)`, where `a_c` is the
//! channel's opacity transfer function (defined for the reference step `Δ₀`, one level-0
//! voxel of the finest spacing) and `Δ` the step actually taken. Channels mix additively
//! before blending: the sample's colour is `Σ α_c·colour_c` and its opacity
//! `α = min(1, Σ α_c)`. The ray accumulates `C += T·colour`, `T *= 1 − α`, starting from
//! `T = 1`, and the final pixel is `C + T·background`.
//!
//! **Maximum intensity projection** (`mode: mip`). Each visible channel `c` keeps the
//! largest value `m_c` of its samples along the ray (NaN samples are ignored; `m_c = −∞` when
//! the ray meets none). Its opacity transfer function, scaled so that its highest control
//! point is 1, maps that value to an intensity `w_c = a_c(m_c) / max a_c` (a ramp is a
//! contrast window: 0 below its low end, 1 above its high end); a channel whose control points
//! are all 0 shows nothing. Channels add, as in napari: the pixel is `Σ w_c·colour_c +
//! (1 − a)·background` with `a = min(1, Σ w_c)`. The step does not enter: no opacity
//! correction, no early termination, except that a ray stops once every channel's maximum has
//! reached the value above which its intensity stays 1. Skipping is exact: a region whose
//! largest value in a channel is at most the ray's maximum so far cannot change it, and one
//! where the channel's transfer function is 0 for every value up to the region's largest
//! (not merely inside its range) cannot change the pixel ([`ChannelStyle::hides`]).
//!
//! **Iso-surfaces** (`mode: iso`). Each visible channel's surface is where its value equals
//! its iso value ([`ChannelStyle::iso_value`]: where its transfer function first reaches half
//! its highest opacity, the middle of a ramp). A ray meets a channel's surface between two
//! consecutive samples on either side of the iso value, at the point linear interpolation
//! between them puts it; a ray whose first sample of a channel is at or above the iso value
//! meets it there (so a clipped object shows its cut). The nearest surface of any channel is
//! drawn, opaque, in its channel's colour times `0.25 + 0.75·|n·l|`: `n` the gradient of the
//! channel's filtered field by central differences half a level-0 voxel either side along each
//! axis, `l` the ray's direction (a headlight; both sides lit). A ray that meets no surface
//! shows the background. Skipping is exact: a region whose range excludes every channel's iso
//! value is skipped only where each channel lies on the side of its iso value the ray already
//! knows it on (or, before the ray's first sample, below it).
//!
//! **Projection** (pinhole, [`Camera::ray_direction`]): `forward = normalize(target − eye)`,
//! `right = normalize(forward × up)`, `up' = right × forward`. Pixel `(px, py)` of a `W × H`
//! image (row 0 at the top) looks along `normalize(forward + nx·tan(fov/2)·(W/H)·right +
//! ny·tan(fov/2)·up')` with `nx = 2(px + ½)/W − 1` and `ny = 1 − 2(py + ½)/H`.
//!
//! **Scene files** are these types as JSON (`schemas/json/scene.schema.json`); `up` defaults
//! to `−y` (so that, looking toward `+z`, `x` runs right and `y` down as in a slice viewer),
//! `fov_y_degrees` to 30, `visible` to true, `background` to black, `filter` to trilinear and
//! `mode` to `dvr`.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::names::{Named, UnknownName};

mod clip;
pub mod orientation;

pub use clip::{Clip, ClipBox, ClipError, ClipPlane, MAX_CLIP_PLANES};

/// A pinhole camera in world space.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    /// Eye position.
    pub eye: [f64; 3],
    /// Point looked at.
    pub target: [f64; 3],
    /// Up direction (need not be orthogonal to the view direction).
    #[serde(default = "default_up")]
    pub up: [f64; 3],
    /// Vertical field of view, degrees.
    #[serde(default = "default_fov")]
    #[schemars(extend("exclusiveMinimum" = 0, "exclusiveMaximum" = 180))]
    pub fov_y_degrees: f64,
}

fn default_up() -> [f64; 3] {
    [0.0, -1.0, 0.0]
}

/// The vertical field of view of a scene that names none, degrees.
pub const DEFAULT_FOV_DEGREES: f64 = 30.0;

fn default_fov() -> f64 {
    DEFAULT_FOV_DEGREES
}

fn default_true() -> bool {
    true
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn normalize(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if !(1e-150..=1e150).contains(&n) {
        // The squares overflow or lose precision (a camera 1e300 units away): scale first.
        let m = v[0].abs().max(v[1].abs()).max(v[2].abs());
        if m > 0.0 && m.is_finite() {
            let w = v.map(|x| x / m);
            let n = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
            return w.map(|x| x / n);
        }
    }
    v.map(|x| x / n)
}

impl Camera {
    /// The orthonormal camera frame `(forward, right, up')` of the projection in the module
    /// doc.
    pub fn basis(&self) -> ([f64; 3], [f64; 3], [f64; 3]) {
        let forward = normalize(sub(self.target, self.eye));
        let right = normalize(cross(forward, self.up));
        let up = cross(right, forward);
        (forward, right, up)
    }

    /// The unit direction of the ray through the centre of pixel `(px, py)` of a
    /// `width × height` image (the projection in the module doc).
    pub fn ray_direction(&self, px: usize, py: usize, width: usize, height: usize) -> [f64; 3] {
        let (f, r, u) = self.basis();
        let tan_half = (self.fov_y_degrees.to_radians() / 2.0).tan();
        let aspect = width as f64 / height as f64;
        let nx = (2.0 * (px as f64 + 0.5) / width as f64 - 1.0) * tan_half * aspect;
        let ny = (1.0 - 2.0 * (py as f64 + 0.5) / height as f64) * tan_half;
        normalize(std::array::from_fn(|i| f[i] + nx * r[i] + ny * u[i]))
    }
}

/// One control point of a piecewise-linear opacity transfer function.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct OpacityPoint {
    /// Data value (in the channel's own units, as stored).
    pub value: f64,
    /// Opacity at the reference step, in `[0, 1]`.
    #[schemars(range(min = 0, max = 1))]
    pub opacity: f64,
}

impl OpacityPoint {
    /// The highest opacity of `points` (0 when every point is 0, or there are none).
    pub fn top(points: &[Self]) -> f64 {
        points.iter().map(|p| p.opacity).fold(0.0, f64::max)
    }

    /// A two-point ramp: opacity 0 at `lo` rising to `opacity` at `hi`.
    pub fn ramp(lo: f64, hi: f64, opacity: f64) -> Vec<Self> {
        vec![
            Self {
                value: lo,
                opacity: 0.0,
            },
            Self { value: hi, opacity },
        ]
    }
}

/// How one channel is drawn.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ChannelStyle {
    /// Channel index in the volume.
    pub channel: usize,
    /// Whether the channel is drawn at all (an invisible channel is never fetched).
    #[serde(default = "default_true")]
    pub visible: bool,
    /// Linear RGB emission colour, each in `[0, 1]`.
    #[schemars(inner(range(min = 0, max = 1)))]
    pub color: [f64; 3],
    /// Opacity control points, ascending in value. Below the first point and above the last,
    /// the end opacities hold.
    pub opacity: Vec<OpacityPoint>,
}

impl ChannelStyle {
    /// Opacity at the reference step for value `v` (NaN is transparent).
    pub fn opacity_at(&self, v: f64) -> f64 {
        let pts = &self.opacity;
        if v.is_nan() || pts.is_empty() {
            return 0.0;
        }
        if v <= pts[0].value {
            return pts[0].opacity;
        }
        for w in pts.windows(2) {
            let (a, b) = (w[0], w[1]);
            if v <= b.value {
                if b.value == a.value {
                    return b.opacity;
                }
                let t = (v - a.value) / (b.value - a.value);
                return a.opacity + t * (b.opacity - a.opacity);
            }
        }
        pts[pts.len() - 1].opacity
    }

    /// The highest opacity of the control points: what maximum intensity projection scales
    /// the transfer function by (0 when every point is 0, or there are none).
    pub fn opacity_top(&self) -> f64 {
        OpacityPoint::top(&self.opacity)
    }

    /// The value from which maximum intensity projection's intensity no longer changes as the
    /// ray's maximum grows: the first control point of the run of points at the top opacity
    /// that ends the list (the intensity stays 1 from there); `−∞` when every point is 0 (the
    /// intensity is always 0); `+∞` when the transfer function ends below its top. A ray whose
    /// maximum has reached it in every channel cannot change any more.
    pub fn saturation_value(&self) -> f64 {
        let top = self.opacity_top();
        if top <= 0.0 {
            return f64::NEG_INFINITY;
        }
        let run = self
            .opacity
            .iter()
            .rev()
            .take_while(|p| p.opacity == top)
            .count();
        match run {
            0 => f64::INFINITY,
            n => self.opacity[self.opacity.len() - n].value,
        }
    }

    /// The value of this channel's iso-surface: where its transfer function first reaches
    /// half its highest opacity, interpolated between control points (`None` when every point
    /// is 0).
    pub fn iso_value(&self) -> Option<f64> {
        let half = self.opacity_top() / 2.0;
        if half <= 0.0 {
            return None;
        }
        let first = self.opacity.first()?;
        if first.opacity >= half {
            return Some(first.value);
        }
        self.opacity.windows(2).find_map(|w| {
            let (a, b) = (w[0], w[1]);
            (a.opacity < half && b.opacity >= half).then(|| {
                a.value + (half - a.opacity) / (b.opacity - a.opacity) * (b.value - a.value)
            })
        })
    }

    /// Whether a region of values in `[lo, hi]` of this channel shows nothing under `mode`,
    /// so that it is neither sampled nor fetched: in [`RenderMode::Dvr`], the transfer function
    /// is transparent over `[lo, hi]` ([`ChannelStyle::transparent_over`]); in
    /// [`RenderMode::Mip`], over every value up to `hi`, since a value in the region may become
    /// the ray's maximum and the intensity is that of the maximum; in [`RenderMode::Iso`], the
    /// range excludes the iso value (no surface inside; which side it lies on decides whether
    /// a ray may skip it). An invisible channel, and a region of NaN only, show nothing in any.
    pub fn hides(&self, mode: RenderMode, lo: f64, hi: f64) -> bool {
        match mode {
            RenderMode::Dvr => self.transparent_over(lo, hi),
            RenderMode::Mip => {
                lo.is_nan() || hi.is_nan() || self.transparent_over(f64::NEG_INFINITY, hi)
            }
            RenderMode::Iso => {
                !self.visible
                    || lo.is_nan()
                    || hi.is_nan()
                    || self.iso_value().is_none_or(|iso| iso < lo || iso > hi)
            }
        }
    }

    /// Whether the transfer function is fully transparent for every value in `[lo, hi]`.
    pub fn transparent_over(&self, lo: f64, hi: f64) -> bool {
        // An invisible channel, or a region of NaN only, shows nothing.
        if !self.visible || lo.is_nan() || hi.is_nan() {
            return true;
        }
        if self.opacity_at(lo) > 0.0 || self.opacity_at(hi) > 0.0 {
            return false;
        }
        self.opacity
            .iter()
            .all(|p| p.value <= lo || p.value >= hi || p.opacity == 0.0)
    }
}

/// How a sample is reconstructed from the voxels around it. Both filters clamp to the edge
/// voxels, and every method, the web viewer and the f64 reference follow the same one.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    Serialize,
    Deserialize,
    JsonSchema,
    strum::EnumCount,
    strum::EnumString,
    strum::IntoStaticStr,
    strum::VariantArray,
    strum::VariantNames,
)]
#[serde(rename_all = "kebab-case")]
#[strum(
    serialize_all = "kebab-case",
    parse_err_ty = UnknownFilter,
    parse_err_fn = UnknownFilter::new
)]
pub enum Filter {
    /// Trilinear interpolation between the 2³ voxel centres around the sample.
    #[default]
    Trilinear,
    /// The cubic B-spline over the 4³ voxel centres around the sample (weights
    /// `(1−a)³/6`, `(3a³−6a²+4)/6`, `(−3a³+3a²+3a+1)/6`, `a³/6` per axis): smooth,
    /// approximating rather than interpolating. The GPU evaluates it as 8 trilinear samples
    /// (Sigg and Hadwiger's fast form).
    Tricubic,
}

crate::strum_names!(Filter, all);

impl Filter {
    /// Voxels a sample reads beyond the trilinear footprint on each side: 0, or 1 for the
    /// tricubic filter (voxels `i − 1` to `i + 2` instead of `i` and `i + 1`). Region ranges
    /// are widened by this many voxels before they classify space, so that the one-voxel
    /// halo of the store's min/max cells still bounds every voxel a sample reads.
    pub fn reach(self) -> u64 {
        match self {
            Self::Trilinear => 0,
            Self::Tricubic => 1,
        }
    }
}

impl Named for Filter {
    const NOUN: &'static str = "filter";
}

/// What a ray makes of the samples it meets: the rule that every method, the web viewer
/// and the f64 reference follow (the module doc has both in full).
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    Hash,
    Serialize,
    Deserialize,
    JsonSchema,
    strum::EnumCount,
    strum::EnumString,
    strum::IntoStaticStr,
    strum::VariantArray,
    strum::VariantNames,
)]
#[serde(rename_all = "kebab-case")]
#[strum(
    serialize_all = "kebab-case",
    parse_err_ty = UnknownMode,
    parse_err_fn = UnknownMode::new
)]
pub enum RenderMode {
    /// Emission–absorption volume rendering: the channels' colours composited front to back
    /// with the opacity of their transfer functions.
    #[default]
    Dvr,
    /// Maximum intensity projection: per channel the largest value along the ray, shown
    /// through its transfer function scaled to 1, the channels added.
    Mip,
    /// Iso-surfaces: per channel the surface where its value crosses its iso value, the
    /// nearest drawn opaque and shaded by a headlight.
    Iso,
}

crate::strum_names!(RenderMode, all);

impl Named for RenderMode {
    const NOUN: &'static str = "mode";
}

/// A mode name that is not one of [`RenderMode::ALL`]'s.
pub type UnknownMode = UnknownName<RenderMode>;

/// A filter name that is not one of [`Filter::ALL`]'s.
pub type UnknownFilter = UnknownName<Filter>;

/// The cubic B-spline weights of the voxels `i − 1, i, i + 1, i + 2` for a sample at
/// `i + a` (`a` in `[0, 1)`, voxel centres at integers). They are non-negative and sum to 1.
pub fn bspline_weights(a: f64) -> [f64; 4] {
    let (a2, a3) = (a * a, a * a * a);
    [
        (1.0 - a).powi(3) / 6.0,
        (3.0 * a3 - 6.0 * a2 + 4.0) / 6.0,
        (-3.0 * a3 + 3.0 * a2 + 3.0 * a + 1.0) / 6.0,
        a3 / 6.0,
    ]
}

/// A whole scene: camera, channel styles and background.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(title = "Viewer scene", example = scene_example())]
pub struct Scene {
    /// The camera.
    pub camera: Camera,
    /// One style per drawn channel; channels not listed are not drawn.
    pub channels: Vec<ChannelStyle>,
    /// Linear RGB background.
    #[serde(default)]
    #[schemars(inner(range(min = 0, max = 1)))]
    pub background: [f64; 3],
    /// The reconstruction filter of every sample.
    #[serde(default)]
    pub filter: Filter,
    /// What each ray makes of its samples.
    #[serde(default)]
    pub mode: RenderMode,
    /// What part of the volume is drawn (all of it by default).
    #[serde(default, skip_serializing_if = "Clip::is_empty")]
    pub clip: Clip,
}

/// A document that is not a scene that can be drawn. Messages name the document.
#[derive(Debug, thiserror::Error)]
pub enum SceneDocumentError {
    /// A document that is not a valid scene.
    #[error("{document}: not a valid scene file")]
    Parse {
        /// The document (a file name, or what the page calls it).
        document: String,
        /// What serde said.
        #[source]
        source: serde_json::Error,
    },
    /// A scene whose clipping cannot be drawn.
    #[error("{document}: clipping that cannot be drawn")]
    Clip {
        /// The document.
        document: String,
        /// What is wrong with it.
        #[source]
        source: ClipError,
    },
}

impl Scene {
    /// Parses a scene file's JSON; `document` names it in the error.
    ///
    /// # Errors
    /// [`SceneDocumentError::Parse`], naming `document`, with serde's message;
    /// [`SceneDocumentError::Clip`] for clipping that cannot be drawn.
    pub fn from_json(json: &[u8], document: &str) -> Result<Scene, SceneDocumentError> {
        let scene: Scene =
            serde_json::from_slice(json).map_err(|source| SceneDocumentError::Parse {
                document: document.to_string(),
                source,
            })?;
        scene
            .clip
            .check()
            .map_err(|source| SceneDocumentError::Clip {
                document: document.to_string(),
                source,
            })?;
        Ok(scene)
    }

    /// Whether `other` draws alike but for the camera: the same channel styles, background,
    /// filter, mode and clipping.
    pub fn same_style(&self, other: &Scene) -> bool {
        self.channels == other.channels
            && self.background == other.background
            && self.filter == other.filter
            && self.mode == other.mode
            && self.clip == other.clip
    }
}

/// The example of the scene schema (read back by the tests and the fuzzing seeds).
fn scene_example() -> serde_json::Value {
    serde_json::json!({
        "camera": {
            "eye": [60.0, 40.0, 90.0],
            "target": [20.0, 24.0, 20.0],
            "up": [0.0, 1.0, 0.0],
            "fov_y_degrees": 30.0
        },
        "channels": [
            {
                "channel": 0,
                "visible": true,
                "color": [0.0, 1.0, 1.0],
                "opacity": [{"value": 200.0, "opacity": 0.0}, {"value": 1500.0, "opacity": 0.08}]
            },
            {
                "channel": 2,
                "color": [1.0, 1.0, 0.0],
                "opacity": [
                    {"value": 20.0, "opacity": 0.0},
                    {"value": 120.0, "opacity": 0.05},
                    {"value": 255.0, "opacity": 0.05}
                ]
            }
        ],
        "background": [0.0, 0.0, 0.0],
        "clip": {
            "box": {"min": [0.0, 0.0, 0.0], "max": [40.0, 48.0, 40.0]},
            "planes": [{"point": [20.0, 24.0, 20.0], "normal": [1.0, 0.0, 1.0]}]
        }
    })
}

/// Length of the diagonal of a box of `extent`, without overflow or underflow for extents
/// near the ends of the `f64` range (voxel sizes of `1e300` or `1e-300`).
pub fn box_diagonal(e: [f64; 3]) -> f64 {
    let d = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt();
    if d.is_finite() && d > 0.0 {
        return d;
    }
    let m = e[0].max(e[1]).max(e[2]);
    if !(m.is_finite() && m > 0.0) {
        return d;
    }
    let [a, b, c] = e.map(|v| v / m);
    m * (a * a + b * b + c * c).sqrt()
}

/// Opacity of a step of length `step`, given opacity `a` at the reference step `reference`.
pub fn corrected_opacity(a: f64, step: f64, reference: f64) -> f64 {
    if a >= 1.0 {
        return 1.0;
    }
    1.0 - (1.0 - a.max(0.0)).powf(step / reference)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::Value;

    const SCHEMA: &str = include_str!("../json/scene.schema.json");

    fn keys(v: &Value) -> Vec<String> {
        let mut k: Vec<String> = v.as_object().unwrap().keys().cloned().collect();
        k.sort();
        k
    }

    /// A document that is not a scene, or whose clipping cannot be drawn, is named with the
    /// cause after it; a drawable one parses.
    #[test]
    fn a_document_that_is_no_drawable_scene_is_named() {
        let e = Scene::from_json(b"{\"camera\": 1}", "a.json").unwrap_err();
        assert!(matches!(e, SceneDocumentError::Parse { .. }));
        assert_eq!(
            crate::error_chain(&e),
            "a.json: not a valid scene file: invalid type: integer `1`, expected struct Camera \
             at line 1 column 12"
        );
        let clipped = br#"{"camera": {"eye": [0, 0, 5], "target": [0, 0, 0]}, "channels": [],
            "clip": {"near": -1}}"#;
        let e = Scene::from_json(clipped, "page scene").unwrap_err();
        assert!(matches!(e, SceneDocumentError::Clip { .. }));
        assert_eq!(
            crate::error_chain(&e),
            "page scene: clipping that cannot be drawn: clip near -1: must be finite and at least 0"
        );
        let ok = br#"{"camera": {"eye": [0, 0, 5], "target": [0, 0, 0]}, "channels": []}"#;
        assert_eq!(
            Scene::from_json(ok, "b").unwrap().camera.fov_y_degrees,
            30.0
        );
    }

    /// The schema's example is a valid scene, and the schema and the serde types name the
    /// same fields, with the same required ones.
    #[test]
    fn schema_example_is_a_scene_and_schema_matches_the_types() {
        let schema: Value = serde_json::from_str(SCHEMA).unwrap();
        let example = &schema["examples"][0];
        let scene: Scene = serde_json::from_value(example.clone()).unwrap();
        assert_eq!(scene.camera.eye, [60.0, 40.0, 90.0]);
        assert_eq!(scene.channels.len(), 2);
        assert!(scene.channels[1].visible, "visible defaults to true");
        assert_eq!(scene.channels[1].opacity_at(70.0), 0.025);
        assert_eq!(scene.channels[1].opacity_at(1000.0), 0.05);

        let back = serde_json::to_value(&scene).unwrap();
        let props = |s: &Value| keys(&s["properties"]);
        assert_eq!(keys(&back), props(&schema));
        assert_eq!(
            keys(&back["camera"]),
            props(&schema["properties"]["camera"])
        );
        let ch = &schema["properties"]["channels"]["items"];
        assert_eq!(keys(&back["channels"][0]), props(ch));
        let pt = &ch["properties"]["opacity"]["items"];
        assert_eq!(keys(&back["channels"][0]["opacity"][0]), props(pt));
        // What the schema requires is exactly what serde cannot default.
        let minimal = serde_json::json!({
            "camera": {"eye": [0, 0, 5], "target": [0, 0, 0]},
            "channels": [{"channel": 0, "color": [1, 1, 1], "opacity": []}]
        });
        let s: Scene = serde_json::from_value(minimal).unwrap();
        assert_eq!(s.camera.up, [0.0, -1.0, 0.0]);
        assert_eq!(s.camera.fov_y_degrees, 30.0);
        assert_eq!(s.background, [0.0; 3]);
        assert_eq!(s.filter, Filter::Trilinear);
        assert_eq!(
            schema["required"],
            serde_json::json!(["camera", "channels"])
        );
        assert_eq!(
            schema["properties"]["camera"]["required"],
            serde_json::json!(["eye", "target"])
        );
        assert_eq!(
            ch["required"],
            serde_json::json!(["channel", "color", "opacity"])
        );
    }

    #[test]
    fn unknown_fields_are_refused() {
        let e = serde_json::from_str::<Scene>(
            r#"{"camera": {"eye": [0,0,5], "target": [0,0,0], "fov": 40}, "channels": []}"#,
        )
        .unwrap_err();
        assert!(e.to_string().starts_with("unknown field `fov`"), "{e}");
    }

    #[test]
    fn rays_follow_the_documented_projection() {
        let cam = Camera {
            eye: [0.0, 0.0, 10.0],
            target: [0.0, 0.0, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_y_degrees: 90.0,
        };
        let (f, r, u) = cam.basis();
        assert_eq!(
            (f, r, u),
            ([0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        );
        assert_eq!(cam.ray_direction(0, 0, 1, 1), [0.0, 0.0, -1.0]);
        // 2×2 pixels, tan(45°) = 1: the top-left pixel centre is at (-½, ½) on the image
        // plane at distance 1.
        let d = cam.ray_direction(0, 0, 2, 2);
        let n = 1.5f64.sqrt();
        let expect = [-0.5 / n, 0.5 / n, -1.0 / n];
        assert!(
            d.iter().zip(expect).all(|(a, b)| (a - b).abs() < 1e-15),
            "{d:?}"
        );
        // A wide image widens the horizontal extent by its aspect ratio.
        let d = cam.ray_direction(3, 0, 4, 1);
        assert!((d[0] / -d[2] - 0.75 * 4.0).abs() < 1e-12, "{d:?}");
        assert!(d[1].abs() < 1e-15);
    }

    #[test]
    fn bspline_weights_sum_to_one_and_meet_smoothly() {
        assert_eq!(bspline_weights(0.0), [1.0 / 6.0, 4.0 / 6.0, 1.0 / 6.0, 0.0]);
        assert_eq!(
            bspline_weights(0.5),
            [1.0 / 48.0, 23.0 / 48.0, 23.0 / 48.0, 1.0 / 48.0]
        );
        for i in 0..=16 {
            let w = bspline_weights(f64::from(i) / 16.0);
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-15, "{w:?}");
            assert!(w.iter().all(|&x| x >= 0.0));
        }
        // At a = 1 the weights are a = 0's, shifted by one voxel.
        let w = bspline_weights(1.0);
        assert_eq!(w, [0.0, 1.0 / 6.0, 4.0 / 6.0, 1.0 / 6.0]);
        assert_eq!("tricubic".parse::<Filter>(), Ok(Filter::Tricubic));
        assert_eq!(
            "cubic".parse::<Filter>().unwrap_err().to_string(),
            "unknown filter 'cubic' (trilinear or tricubic)"
        );
    }

    #[test]
    fn each_filter_has_one_name_for_strum_and_serde() {
        assert_eq!(Filter::ALL.map(Filter::name), ["trilinear", "tricubic"]);
        for f in Filter::ALL {
            assert_eq!(serde_json::to_value(f).unwrap(), f.name());
            assert_eq!(f.name().parse::<Filter>(), Ok(f));
        }
    }

    fn style(points: &[(f64, f64)]) -> ChannelStyle {
        ChannelStyle {
            channel: 0,
            visible: true,
            color: [1.0; 3],
            opacity: points
                .iter()
                .map(|&(value, opacity)| OpacityPoint { value, opacity })
                .collect(),
        }
    }

    #[test]
    fn each_mode_has_one_name_for_strum_and_serde() {
        assert_eq!(RenderMode::ALL.map(RenderMode::name), ["dvr", "mip", "iso"]);
        for m in RenderMode::ALL {
            assert_eq!(serde_json::to_value(m).unwrap(), m.name());
            assert_eq!(m.name().parse::<RenderMode>(), Ok(m));
        }
        assert_eq!(
            "isosurface".parse::<RenderMode>().unwrap_err().to_string(),
            "unknown mode 'isosurface' (dvr, mip or iso)"
        );
        let s: Scene = serde_json::from_str(
            r#"{"camera": {"eye": [0,0,5], "target": [0,0,0]}, "channels": [], "mode": "mip"}"#,
        )
        .unwrap();
        assert_eq!(s.mode, RenderMode::Mip);
    }

    #[test]
    fn mip_scales_the_transfer_function_and_saturates_at_its_last_top_run() {
        let ramp = style(&[(100.0, 0.0), (200.0, 0.08)]);
        assert_eq!(ramp.opacity_top(), 0.08);
        assert_eq!(ramp.saturation_value(), 200.0);
        // A peak that falls again never saturates; a plateau saturates where its top run
        // starts; a function of zeros is always 0, so it never holds a ray back.
        let peak = style(&[(0.0, 0.0), (50.0, 0.5), (90.0, 0.1)]);
        assert_eq!(
            (peak.opacity_top(), peak.saturation_value()),
            (0.5, f64::INFINITY)
        );
        let plateau = style(&[
            (0.0, 0.0),
            (10.0, 0.4),
            (20.0, 0.4),
            (30.0, 0.2),
            (40.0, 0.4),
        ]);
        assert_eq!(plateau.saturation_value(), 40.0);
        let run = style(&[(0.0, 0.0), (10.0, 0.4), (20.0, 0.4)]);
        assert_eq!(run.saturation_value(), 10.0);
        let zeros = style(&[(0.0, 0.0), (10.0, 0.0)]);
        assert_eq!(
            (zeros.opacity_top(), zeros.saturation_value()),
            (0.0, f64::NEG_INFINITY)
        );
        assert_eq!(style(&[]).saturation_value(), f64::NEG_INFINITY);
    }

    #[test]
    fn the_iso_value_is_where_the_function_reaches_half_its_top_and_hides_ranges_without_it() {
        let ramp = style(&[(100.0, 0.0), (200.0, 0.08)]);
        assert_eq!(ramp.iso_value(), Some(150.0));
        let steps = style(&[(0.0, 0.0), (10.0, 0.1), (20.0, 0.4), (30.0, 0.2)]);
        // Half the top (0.2) is reached between 10 (0.1) and 20 (0.4): a third of the way.
        assert!((steps.iso_value().unwrap() - 40.0 / 3.0).abs() < 1e-12);
        assert_eq!(style(&[(5.0, 0.3), (9.0, 0.6)]).iso_value(), Some(5.0));
        assert_eq!(style(&[(0.0, 0.0), (9.0, 0.0)]).iso_value(), None);
        for (lo, hi, hidden) in [
            (0.0, 149.0, true),
            (140.0, 160.0, false),
            (150.0, 150.0, false),
            (151.0, 900.0, true),
        ] {
            assert_eq!(ramp.hides(RenderMode::Iso, lo, hi), hidden, "{lo} {hi}");
        }
        assert!(style(&[(0.0, 0.0)]).hides(RenderMode::Iso, 0.0, 1.0));
    }

    #[test]
    fn mip_hides_a_region_only_below_where_the_function_first_rises() {
        let ramp = style(&[(100.0, 0.0), (200.0, 0.08)]);
        // DVR: transparent inside [lo, hi]. MIP: transparent for every value up to hi.
        for (lo, hi, dvr, mip) in [
            (0.0, 100.0, true, true),
            (0.0, 150.0, false, false),
            (150.0, 180.0, false, false),
            (f64::NAN, f64::NAN, true, true),
        ] {
            assert_eq!(ramp.hides(RenderMode::Dvr, lo, hi), dvr, "{lo} {hi}");
            assert_eq!(ramp.hides(RenderMode::Mip, lo, hi), mip, "{lo} {hi}");
        }
        // A band: [300, 400] is transparent, yet its values may become the ray's maximum, and
        // the maximum's intensity is 0 only up to 100.
        let band = style(&[(100.0, 0.0), (150.0, 0.5), (200.0, 0.0)]);
        assert!(band.hides(RenderMode::Dvr, 300.0, 400.0));
        assert!(!band.hides(RenderMode::Mip, 300.0, 400.0));
        assert!(band.hides(RenderMode::Mip, 20.0, 90.0));
        // Opaque from the start: nothing is hidden.
        let floor = style(&[(100.0, 0.2), (200.0, 0.5)]);
        assert!(!floor.hides(RenderMode::Mip, 0.0, 1.0));
        let hidden = ChannelStyle {
            visible: false,
            ..ramp
        };
        assert!(hidden.hides(RenderMode::Mip, 0.0, 1000.0));
    }

    #[test]
    fn opacity_correction_matches_the_compositing_rule() {
        assert_eq!(corrected_opacity(0.5, 1.0, 1.0), 0.5);
        assert_eq!(corrected_opacity(0.5, 2.0, 1.0), 0.75);
        assert!((corrected_opacity(0.75, 0.5, 1.0) - 0.5).abs() < 1e-15);
        assert_eq!(corrected_opacity(1.0, 0.1, 1.0), 1.0);
        assert_eq!(corrected_opacity(-0.2, 1.0, 1.0), 0.0);
    }
}
