//! The reference ray caster: the scene's ground truth, on the CPU in `f64`, at level 0, with
//! the scene's filter (trilinear or tricubic) and a fine fixed step, following the conventions
//! of [`crate::scene`] exactly (world space, projection, opacity correction and compositing, or
//! maximum intensity projection).
//!
//! Each ray is clipped to the volume box `[0, extent)` and cut into segments of the step `Δ`
//! from the entry point, the last one shorter; each segment is sampled at its midpoint and
//! composited with its own length. Level-0 bricks are read through any [`BrickSource`] on
//! first use and kept, decoded, for the whole render. Pixels are rendered in parallel.

use std::collections::HashMap;
use std::sync::{Arc, RwLock};

use rayon::prelude::*;

use crate::image::RgbImage;
use crate::scene::{
    ChannelStyle, ClipPlane, Filter, RenderMode, Scene, bspline_weights, corrected_opacity,
};
use crate::source::{BrickKey, BrickSource, BrickVoxels, SourceError, VolumeInfo};

/// Why the reference cannot render a scene: options, a camera or a volume that define no
/// image, a ray too long to march, or a brick that cannot be read (the source's error,
/// unchanged). Messages name the option, channel or volume at fault.
#[derive(Debug, thiserror::Error)]
pub enum ReferenceError {
    /// An image without pixels.
    #[error("image size {width}×{height} is empty")]
    EmptyImage {
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
    },
    /// A step fraction that is zero, negative or not finite.
    #[error("step fraction {step_fraction} must be positive")]
    BadStep {
        /// The step fraction.
        step_fraction: f64,
    },
    /// A scene drawing a channel the volume does not have.
    #[error("scene draws channel {channel} but {volume} has {channels} channels")]
    NoChannel {
        /// The channel drawn.
        channel: usize,
        /// The volume.
        volume: String,
        /// Its channels.
        channels: usize,
    },
    /// A volume whose extent or step is not finite and positive.
    #[error(
        "{volume}: volume extent {extent:?} (x, y, z) and step {step} must be finite and positive"
    )]
    BadExtent {
        /// The volume.
        volume: String,
        /// Its extent, world `x, y, z`.
        extent: [f64; 3],
        /// The step, world units.
        step: f64,
    },
    /// A camera that defines no view.
    #[error(
        "camera eye {eye:?}, target {target:?}, up {up:?} and field of view {fov_y_degrees}° do \
         not define a view: they must be finite, eye and target distinct, up not along the \
         view, the field of view between 0 and 180°"
    )]
    BadCamera {
        /// Eye.
        eye: [f64; 3],
        /// Target.
        target: [f64; 3],
        /// Up.
        up: [f64; 3],
        /// Vertical field of view, degrees.
        fov_y_degrees: f64,
    },
    /// A ray needing more steps than [`MAX_STEPS_PER_RAY`].
    #[error(
        "a ray crossing {length:e} of the volume needs {segments} steps of {step:e}, more than \
         the {} allowed: use a larger --step",
        MAX_STEPS_PER_RAY
    )]
    RayTooLong {
        /// Length of the ray inside the volume, world units.
        length: f64,
        /// Steps it needs.
        segments: u64,
        /// The step, world units.
        step: f64,
    },
    /// A source that answered no result for a brick.
    #[error("the source answered no brick")]
    NoAnswer,
    /// A brick that cannot be read.
    #[error(transparent)]
    Source(Box<SourceError>),
}

impl From<SourceError> for ReferenceError {
    fn from(e: SourceError) -> Self {
        Self::Source(Box::new(e))
    }
}

/// Default step, as a fraction of the finest level-0 voxel spacing.
pub const DEFAULT_STEP_FRACTION: f64 = 0.25;

/// The most steps one ray may take: past it the render stops with an error rather than running
/// for hours (a volume whose voxels are 10⁶ times longer in z than in x, stepped at a fraction
/// of the x spacing). Without early termination a ray that would need more is refused before
/// its first step.
pub const MAX_STEPS_PER_RAY: u64 = 1 << 24;

/// How the reference is rendered.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReferenceOptions {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Step as a fraction of the finest level-0 voxel spacing.
    pub step_fraction: f64,
    /// Stop a ray once its transmittance falls below this (0: never stop early).
    pub min_transmittance: f64,
}

impl ReferenceOptions {
    /// A `width × height` render with the default step and no early termination.
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            step_fraction: DEFAULT_STEP_FRACTION,
            min_transmittance: 0.0,
        }
    }
}

/// Level-0 voxels of one channel, read brick by brick through a source and cached.
struct Level0<'a> {
    source: &'a dyn BrickSource,
    channel: u32,
    shape: [u64; 3],
    brick: [u64; 3],
    cache: RwLock<HashMap<[u64; 3], Arc<BrickVoxels>>>,
}

impl Level0<'_> {
    fn brick(&self, b: [u64; 3]) -> Result<Arc<BrickVoxels>, ReferenceError> {
        if let Some(v) = self.cache.read().expect("cache lock").get(&b) {
            return Ok(v.clone());
        }
        let key = BrickKey {
            level: 0,
            channel: self.channel,
            brick: b,
        };
        let voxels = self
            .source
            .fetch(&[key])
            .pop()
            .ok_or(ReferenceError::NoAnswer)??;
        let voxels = Arc::new(voxels);
        self.cache
            .write()
            .expect("cache lock")
            .insert(b, voxels.clone());
        Ok(voxels)
    }

    /// Voxel `v` (`z, y, x`), which must lie inside the volume.
    fn voxel(
        &self,
        v: [u64; 3],
        last: &mut Option<([u64; 3], Arc<BrickVoxels>)>,
    ) -> Result<f64, ReferenceError> {
        let b: [u64; 3] = std::array::from_fn(|i| v[i] / self.brick[i]);
        let bricks = match last {
            Some((lb, data)) if *lb == b => data.clone(),
            _ => {
                let data = self.brick(b)?;
                *last = Some((b, data.clone()));
                data
            }
        };
        let l: [u64; 3] = std::array::from_fn(|i| v[i] % self.brick[i]);
        let index = (l[0] * self.brick[1] + l[1]) * self.brick[2] + l[2];
        Ok(bricks.value(index as usize))
    }

    /// Trilinear sample at continuous voxel coordinates `u` (`z, y, x`; voxel centres at
    /// integers), clamped to the edge voxels.
    fn sample(
        &self,
        u: [f64; 3],
        last: &mut Option<([u64; 3], Arc<BrickVoxels>)>,
    ) -> Result<f64, ReferenceError> {
        let mut i0 = [0u64; 3];
        let mut i1 = [0u64; 3];
        let mut f = [0.0; 3];
        for a in 0..3 {
            let max = (self.shape[a] - 1) as f64;
            let x = u[a].clamp(0.0, max);
            let lo = x.floor();
            i0[a] = lo as u64;
            i1[a] = (i0[a] + 1).min(self.shape[a] - 1);
            f[a] = x - lo;
        }
        let mut value = 0.0;
        for corner in 0..8 {
            let (z, y, x) = (corner & 4 != 0, corner & 2 != 0, corner & 1 != 0);
            let w = [(z, 0), (y, 1), (x, 2)]
                .iter()
                .map(|&(hi, a)| if hi { f[a] } else { 1.0 - f[a] })
                .product::<f64>();
            if w == 0.0 {
                continue;
            }
            let v = [
                if z { i1[0] } else { i0[0] },
                if y { i1[1] } else { i0[1] },
                if x { i1[2] } else { i0[2] },
            ];
            value += w * self.voxel(v, last)?;
        }
        Ok(value)
    }

    /// Tricubic B-spline sample at `u` (as [`Level0::sample`]): the 4³ voxels around it
    /// weighted by [`bspline_weights`] per axis, indices clamped to the edge voxels.
    fn sample_tricubic(
        &self,
        u: [f64; 3],
        last: &mut Option<([u64; 3], Arc<BrickVoxels>)>,
    ) -> Result<f64, ReferenceError> {
        let mut index = [[0u64; 4]; 3];
        let mut weight = [[0.0; 4]; 3];
        for a in 0..3 {
            let lo = u[a].floor();
            weight[a] = bspline_weights(u[a] - lo);
            let max = (self.shape[a] - 1) as f64;
            for (k, i) in index[a].iter_mut().enumerate() {
                *i = (lo + k as f64 - 1.0).clamp(0.0, max) as u64;
            }
        }
        let mut value = 0.0;
        for (z, wz) in index[0].iter().zip(weight[0]) {
            for (y, wy) in index[1].iter().zip(weight[1]) {
                for (x, wx) in index[2].iter().zip(weight[2]) {
                    let w = wz * wy * wx;
                    if w != 0.0 {
                        value += w * self.voxel([*z, *y, *x], last)?;
                    }
                }
            }
        }
        Ok(value)
    }

    /// The sample of `filter` at `u`.
    fn filtered(
        &self,
        filter: Filter,
        u: [f64; 3],
        last: &mut Option<([u64; 3], Arc<BrickVoxels>)>,
    ) -> Result<f64, ReferenceError> {
        match filter {
            Filter::Trilinear => self.sample(u, last),
            Filter::Tricubic => self.sample_tricubic(u, last),
        }
    }
}

/// Where a ray meets the box `[0, extent)`: `(t_enter, t_exit)` with `t_enter ≥ 0`, or `None`.
///
/// The box is half-open like the cells the renderer indexes (`floor` of a coordinate: voxels,
/// bricks, octree leaves): a ray parallel to an axis that lies exactly in the plane of a lower
/// face (`0`) meets the volume, one in the plane of an upper face (`extent`) does not.
pub fn clip_to_box(eye: [f64; 3], dir: [f64; 3], extent: [f64; 3]) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
    for a in 0..3 {
        if dir[a] == 0.0 {
            if eye[a] < 0.0 || eye[a] >= extent[a] {
                return None;
            }
            continue;
        }
        let ta = (0.0 - eye[a]) / dir[a];
        let tb = (extent[a] - eye[a]) / dir[a];
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
    }
    (t1 > t0).then_some((t0, t1))
}

/// Renders `scene` from `source` at level 0.
///
/// # Errors
/// A [`ReferenceError`] naming the option, channel or volume that defines no image, a ray
/// that needs too many steps, or the source's error for a brick that cannot be read.
pub fn render(
    source: &dyn BrickSource,
    scene: &Scene,
    options: &ReferenceOptions,
) -> Result<RgbImage, ReferenceError> {
    let info = source.info();
    if options.width == 0 || options.height == 0 {
        return Err(ReferenceError::EmptyImage {
            width: options.width,
            height: options.height,
        });
    }
    if !(options.step_fraction > 0.0 && options.step_fraction.is_finite()) {
        return Err(ReferenceError::BadStep {
            step_fraction: options.step_fraction,
        });
    }
    let visible: Vec<&ChannelStyle> = scene.channels.iter().filter(|c| c.visible).collect();
    for c in &visible {
        if c.channel >= info.channels.len() {
            return Err(ReferenceError::NoChannel {
                channel: c.channel,
                volume: info.name.clone(),
                channels: info.channels.len(),
            });
        }
    }
    let volumes: Vec<Level0> = visible
        .iter()
        .map(|c| Level0 {
            source,
            channel: c.channel as u32,
            shape: info.levels[0].shape,
            brick: info.brick_shape,
            cache: RwLock::new(HashMap::new()),
        })
        .collect();
    let spacing_xyz = info.spacing_xyz();
    let reference_step = spacing_xyz.iter().copied().fold(f64::INFINITY, f64::min);
    let step = options.step_fraction * reference_step;
    let extent = extent_xyz(info);
    if !(extent.iter().all(|e| e.is_finite() && *e > 0.0) && step > 0.0 && step.is_finite()) {
        return Err(ReferenceError::BadExtent {
            volume: info.name.clone(),
            extent,
            step,
        });
    }
    let cam = &scene.camera;
    let (f, r, u) = cam.basis();
    if !(cam.eye.iter().chain(&cam.target).all(|v| v.is_finite())
        && [f, r, u].iter().flatten().all(|v| v.is_finite())
        && cam.fov_y_degrees > 0.0
        && cam.fov_y_degrees < 180.0)
    {
        return Err(ReferenceError::BadCamera {
            eye: cam.eye,
            target: cam.target,
            up: cam.up,
            fov_y_degrees: cam.fov_y_degrees,
        });
    }
    let rule = RayRule {
        scene,
        styles: &visible,
        start: Accumulated::new(scene.mode, &visible),
        planes: scene.clip.planes_for(&scene.camera),
    };
    let pixels = (0..options.width * options.height)
        .into_par_iter()
        .map(|p| {
            let (px, py) = (p % options.width, p / options.width);
            let dir = scene
                .camera
                .ray_direction(px, py, options.width, options.height);
            let mut lasts: Vec<Option<([u64; 3], Arc<BrickVoxels>)>> = vec![None; volumes.len()];
            let pixel = march(
                dir,
                extent,
                (step, reference_step),
                options.min_transmittance,
                &rule,
                &volumes,
                spacing_xyz,
                &mut lasts,
            )?;
            Ok(pixel.map(|c| c as f32))
        })
        .collect::<Result<Vec<[f32; 3]>, ReferenceError>>()?;
    Ok(RgbImage {
        width: options.width,
        height: options.height,
        pixels,
    })
}

/// Level-0 extent of the volume box, world `x, y, z`.
fn extent_xyz(info: &VolumeInfo) -> [f64; 3] {
    let s = info.levels[0].shape;
    let v = info.voxel_size;
    [s[2] as f64 * v[2], s[1] as f64 * v[1], s[0] as f64 * v[0]]
}

/// What a ray has made of its samples so far, by the scene's mode ([`crate::scene`]).
#[derive(Clone)]
enum Accumulated {
    /// Emission–absorption: the colour and the transmittance.
    Dvr([f64; 3], f64),
    /// Maximum intensity projection: each visible channel's largest value (`None`: no value
    /// yet), and the value from which its intensity no longer changes
    /// ([`ChannelStyle::saturation_value`]).
    Mip {
        /// Each channel's largest value.
        maxima: Vec<Option<f64>>,
        /// Each channel's saturation value.
        saturation: Vec<f64>,
    },
    /// Iso-surfaces: each visible channel's iso value ([`ChannelStyle::iso_value`]), where the
    /// last samples were taken and each channel's value there (`None`: no value yet), then
    /// the shaded colour of the surface met.
    Iso {
        /// Each channel's iso value.
        levels: Vec<Option<f64>>,
        /// Ray parameter of the last samples.
        at: f64,
        /// Each channel's last value.
        last: Vec<Option<f64>>,
        /// The colour of the surface met, which ends the ray.
        hit: Option<[f64; 3]>,
    },
}

impl Accumulated {
    /// Nothing yet, for the visible channels' `styles` in `mode` (once per render: each ray
    /// starts from a clone).
    fn new(mode: RenderMode, styles: &[&ChannelStyle]) -> Self {
        let channels = styles.len();
        match mode {
            RenderMode::Dvr => Self::Dvr([0.0; 3], 1.0),
            RenderMode::Mip => Self::Mip {
                maxima: vec![None; channels],
                saturation: styles.iter().map(|s| s.saturation_value()).collect(),
            },
            RenderMode::Iso => Self::Iso {
                levels: styles.iter().map(|s| s.iso_value()).collect(),
                at: 0.0,
                last: vec![None; channels],
                hit: None,
            },
        }
    }

    /// Whether nothing further along the ray can change the pixel: the transmittance is at
    /// most `min_transmittance` (or 0), or every channel's maximum has reached its
    /// [`ChannelStyle::saturation_value`].
    fn done(&self, min_transmittance: f64) -> bool {
        match self {
            Self::Dvr(_, t) => *t <= min_transmittance || *t == 0.0,
            Self::Mip { maxima, saturation } => saturation
                .iter()
                .zip(maxima)
                .all(|(&s, m)| m.unwrap_or(f64::NEG_INFINITY) >= s),
            Self::Iso { hit, .. } => hit.is_some(),
        }
    }

    /// Takes one segment of length `length` whose samples, at ray parameter `at`, are `values`
    /// (one per visible channel, NaN for none). For iso-surfaces, returns the surface crossed
    /// first since the last samples: its channel's index among `styles` and the ray parameter
    /// of the crossing.
    fn take(
        &mut self,
        styles: &[&ChannelStyle],
        values: &[f64],
        (at, length): (f64, f64),
        reference: f64,
    ) -> Option<(usize, f64)> {
        match self {
            Self::Dvr(colour, t) => {
                let mut sample_colour = [0.0; 3];
                let mut alpha_sum = 0.0;
                for (style, &v) in styles.iter().zip(values) {
                    let alpha = corrected_opacity(style.opacity_at(v), length, reference);
                    alpha_sum += alpha;
                    for (s, c) in sample_colour.iter_mut().zip(style.color) {
                        *s += alpha * c;
                    }
                }
                let alpha = alpha_sum.min(1.0);
                for (c, s) in colour.iter_mut().zip(sample_colour) {
                    *c += *t * s;
                }
                *t *= 1.0 - alpha;
            }
            Self::Mip { maxima, .. } => {
                for (m, &v) in maxima.iter_mut().zip(values) {
                    if !v.is_nan() {
                        *m = Some(m.map_or(v, |m| m.max(v)));
                    }
                }
            }
            Self::Iso {
                levels,
                at: before,
                last,
                ..
            } => {
                let mut first: Option<(usize, f64)> = None;
                for (k, (&level, &v)) in levels.iter().zip(values).enumerate() {
                    let Some(iso) = level else {
                        continue;
                    };
                    if v.is_nan() {
                        continue;
                    }
                    let crossed = match last[k] {
                        None => (v >= iso).then_some(at),
                        Some(u) if (u >= iso) != (v >= iso) => {
                            Some(*before + (iso - u) / (v - u) * (at - *before))
                        }
                        Some(_) => None,
                    };
                    if let Some(t) = crossed
                        && first.is_none_or(|(_, f)| t < f)
                    {
                        first = Some((k, t));
                    }
                    last[k] = Some(v);
                }
                *before = at;
                return first;
            }
        }
        None
    }

    /// Ends the ray on a surface of colour `colour` (iso-surfaces).
    fn hit(&mut self, colour: [f64; 3]) {
        if let Self::Iso { hit, .. } = self {
            *hit = Some(colour);
        }
    }

    /// The pixel over `background`.
    fn pixel(&self, styles: &[&ChannelStyle], background: [f64; 3]) -> [f64; 3] {
        match self {
            Self::Dvr(colour, t) => std::array::from_fn(|i| colour[i] + t * background[i]),
            Self::Iso { hit, .. } => hit.unwrap_or(background),
            Self::Mip { maxima, .. } => {
                let mut colour = [0.0; 3];
                let mut sum = 0.0;
                for (style, m) in styles.iter().zip(maxima) {
                    let top = style.opacity_top();
                    let w = match m {
                        Some(m) if top > 0.0 => style.opacity_at(*m) / top,
                        _ => 0.0,
                    };
                    sum += w;
                    for (o, c) in colour.iter_mut().zip(style.color) {
                        *o += w * c;
                    }
                }
                let a = sum.min(1.0);
                std::array::from_fn(|i| colour[i] + (1.0 - a) * background[i])
            }
        }
    }
}

/// What every ray of one render shares: the scene, its visible channels' styles, a ray's state
/// before its first sample, and the clip planes for the scene's camera.
struct RayRule<'a> {
    scene: &'a Scene,
    styles: &'a [&'a ChannelStyle],
    start: Accumulated,
    planes: Vec<ClipPlane>,
}

/// Marches one ray; returns its pixel.
#[allow(clippy::too_many_arguments)]
fn march(
    dir: [f64; 3],
    extent: [f64; 3],
    (step, reference_step): (f64, f64),
    min_transmittance: f64,
    rule: &RayRule<'_>,
    volumes: &[Level0],
    spacing_xyz: [f64; 3],
    lasts: &mut [Option<([u64; 3], Arc<BrickVoxels>)>],
) -> Result<[f64; 3], ReferenceError> {
    let RayRule {
        scene,
        styles,
        start,
        planes,
    } = rule;
    let eye = scene.camera.eye;
    let mut ray = start.clone();
    let Some((t0, t1)) =
        clip_to_box(eye, dir, extent).and_then(|span| scene.clip.clip_span(planes, eye, dir, span))
    else {
        return Ok(ray.pixel(styles, scene.background));
    };
    let segments = ((t1 - t0) / step).ceil() as u64;
    let too_long = || ReferenceError::RayTooLong {
        length: t1 - t0,
        segments,
        step,
    };
    if segments > MAX_STEPS_PER_RAY && min_transmittance <= 0.0 {
        return Err(too_long());
    }
    let mut values = Vec::with_capacity(styles.len());
    // Each segment's samples at its ray parameter `at`, and (iso-surfaces) the surface they
    // cross, shaded.
    let mut take = |ray: &mut Accumulated, at: f64, length: f64, values: &mut Vec<f64>| {
        let u = voxel_coordinates(std::array::from_fn(|k| eye[k] + at * dir[k]), spacing_xyz);
        values.clear();
        for (volume, last) in volumes.iter().zip(lasts.iter_mut()) {
            values.push(volume.filtered(scene.filter, u, last)?);
        }
        if let Some((k, t)) = ray.take(styles, values, (at, length), reference_step) {
            let p: [f64; 3] = std::array::from_fn(|a| eye[a] + t * dir[a]);
            let normal = gradient(&volumes[k], scene.filter, p, spacing_xyz, &mut lasts[k])?;
            let lit = normal.map_or(1.0, |n| {
                (n[0] * dir[0] + n[1] * dir[1] + n[2] * dir[2]).abs()
            });
            ray.hit(styles[k].color.map(|c| c * (0.25 + 0.75 * lit)));
        }
        Ok::<(), ReferenceError>(())
    };
    // Iso-surfaces: a ray starting at or above a channel's iso value (at a cut, or where an
    // object crosses the volume's face) meets its surface where it enters: a sample there.
    if matches!(ray, Accumulated::Iso { .. }) {
        take(&mut ray, t0, 0.0, &mut values)?;
    }
    for i in 0..segments {
        if i == MAX_STEPS_PER_RAY {
            return Err(too_long());
        }
        if ray.done(min_transmittance) {
            break;
        }
        let a = t0 + i as f64 * step;
        let b = (a + step).min(t1);
        if b <= a {
            break;
        }
        take(&mut ray, 0.5 * (a + b), b - a, &mut values)?;
    }
    Ok(ray.pixel(styles, scene.background))
}

/// Continuous level-0 voxel coordinates (`z, y, x`, voxel centres at integers) of the world
/// point `p` (`x, y, z`).
fn voxel_coordinates(p: [f64; 3], spacing_xyz: [f64; 3]) -> [f64; 3] {
    [
        p[2] / spacing_xyz[2] - 0.5,
        p[1] / spacing_xyz[1] - 0.5,
        p[0] / spacing_xyz[0] - 0.5,
    ]
}

/// The unit gradient of `volume`'s filtered field at world point `p` (world `x, y, z`), by
/// central differences half a level-0 voxel either side along each axis (`None` where it is
/// 0).
fn gradient(
    volume: &Level0,
    filter: Filter,
    p: [f64; 3],
    spacing_xyz: [f64; 3],
    last: &mut Option<([u64; 3], Arc<BrickVoxels>)>,
) -> Result<Option<[f64; 3]>, ReferenceError> {
    let mut g = [0.0; 3];
    for (a, ga) in g.iter_mut().enumerate() {
        let mut at = |sign: f64| {
            let q: [f64; 3] = std::array::from_fn(|k| {
                if k == a {
                    p[k] + sign * 0.5 * spacing_xyz[k]
                } else {
                    p[k]
                }
            });
            volume.filtered(filter, voxel_coordinates(q, spacing_xyz), last)
        };
        *ga = (at(1.0)? - at(-1.0)?) / spacing_xyz[a];
    }
    let n = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
    Ok((n > 0.0 && n.is_finite()).then(|| g.map(|x| x / n)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Camera, OpacityPoint};
    use crate::source::{LevelInfo, SampleType};

    /// An in-memory volume: `value(z, y, x)` over `shape`, bricks of `brick`.
    struct Memory {
        info: VolumeInfo,
        value: fn(u64, u64, u64) -> f32,
    }

    impl Memory {
        fn new(shape: [u64; 3], brick: [u64; 3], value: fn(u64, u64, u64) -> f32) -> Self {
            Self {
                info: VolumeInfo {
                    name: "memory".into(),
                    sample_type: SampleType::F32,
                    channels: vec!["c0".into()],
                    display: vec![crate::source::ChannelDisplay::default()],
                    voxel_size: [1.0; 3],
                    unit: None,
                    brick_shape: brick,
                    levels: vec![LevelInfo {
                        shape,
                        factor: [1; 3],
                    }],
                    minmax: None,
                },
                value,
            }
        }
    }

    impl BrickSource for Memory {
        fn info(&self) -> &VolumeInfo {
            &self.info
        }

        fn fetch(&self, keys: &[BrickKey]) -> Vec<Result<BrickVoxels, SourceError>> {
            keys.iter()
                .map(|k| {
                    self.info.check_key(k)?;
                    let b = self.info.brick_shape;
                    let s = self.info.levels[0].shape;
                    let mut v = Vec::new();
                    for z in 0..b[0] {
                        for y in 0..b[1] {
                            for x in 0..b[2] {
                                let g = [
                                    k.brick[0] * b[0] + z,
                                    k.brick[1] * b[1] + y,
                                    k.brick[2] * b[2] + x,
                                ];
                                v.push(if g[0] < s[0] && g[1] < s[1] && g[2] < s[2] {
                                    (self.value)(g[0], g[1], g[2])
                                } else {
                                    0.0
                                });
                            }
                        }
                    }
                    Ok(BrickVoxels::F32(v))
                })
                .collect()
        }
    }

    fn scene(eye: [f64; 3], target: [f64; 3], opacity: f64) -> Scene {
        Scene {
            camera: Camera {
                eye,
                target,
                up: [0.0, 1.0, 0.0],
                fov_y_degrees: 1e-6,
            },
            channels: vec![ChannelStyle {
                channel: 0,
                visible: true,
                color: [1.0, 0.5, 0.25],
                opacity: vec![OpacityPoint {
                    value: 0.0,
                    opacity,
                }],
            }],
            background: [0.0, 0.0, 1.0],
            filter: Filter::Trilinear,
            mode: RenderMode::Dvr,
            clip: crate::scene::Clip::default(),
        }
    }

    #[test]
    fn constant_medium_gives_beer_lambert() {
        // A 6×5×7 volume of constant opacity 0.1 per voxel, seen along -z through 6 voxels:
        // the transmittance is 0.9^6 whatever the step, and the colour (1 − 0.9^6)·colour.
        let vol = Memory::new([6, 5, 7], [4, 4, 4], |_, _, _| 1.0);
        let s = scene([3.5, 2.5, 100.0], [3.5, 2.5, 0.0], 0.1);
        for fraction in [0.25, 0.3, 1.0] {
            let mut o = ReferenceOptions::new(1, 1);
            o.step_fraction = fraction;
            let img = render(&vol, &s, &o).unwrap();
            let t = 0.9f64.powi(6);
            let p = img.pixels[0];
            let expect = [(1.0 - t), 0.5 * (1.0 - t), 0.25 * (1.0 - t) + t];
            for i in 0..3 {
                assert!(
                    (p[i] as f64 - expect[i]).abs() < 1e-6,
                    "{p:?} vs {expect:?}"
                );
            }
        }
    }

    #[test]
    fn trilinear_sampling_follows_voxel_centres() {
        // value = x: a ray along -z at world x = 2.75 reads 2.25 everywhere (centres at +½).
        let vol = Memory::new([4, 4, 8], [4, 4, 4], |_, _, x| x as f32);
        let mut last = None;
        let l0 = Level0 {
            source: &vol,
            channel: 0,
            shape: [4, 4, 8],
            brick: [4, 4, 4],
            cache: RwLock::new(HashMap::new()),
        };
        assert_eq!(l0.sample([1.0, 1.0, 2.25], &mut last).unwrap(), 2.25);
        // Across a brick boundary (x = 3 | 4) and clamped at the edges.
        assert_eq!(l0.sample([1.0, 1.0, 3.5], &mut last).unwrap(), 3.5);
        assert_eq!(l0.sample([1.0, 1.0, -0.4], &mut last).unwrap(), 0.0);
        assert_eq!(l0.sample([1.0, 1.0, 9.0], &mut last).unwrap(), 7.0);
        // Opacity ramp 0 at x=0 to 1 at x=8 along that ray: a(2.25) = 0.28125 per voxel.
        let mut s = scene([2.75, 2.0, 50.0], [2.75, 2.0, 0.0], 0.0);
        s.channels[0].opacity = OpacityPoint::ramp(0.0, 8.0, 1.0);
        let img = render(&vol, &s, &ReferenceOptions::new(1, 1)).unwrap();
        let t = (1.0 - 0.28125f64).powi(4);
        assert!(
            (img.pixels[0][0] as f64 - (1.0 - t)).abs() < 1e-6,
            "{:?}",
            img.pixels[0]
        );
    }

    #[test]
    fn rays_that_miss_show_the_background_and_channels_add_up() {
        let vol = Memory::new([4, 4, 4], [4, 4, 4], |_, _, _| 1.0);
        let s = scene([10.0, 10.0, 10.0], [20.0, 20.0, 20.0], 0.5);
        let img = render(&vol, &s, &ReferenceOptions::new(2, 2)).unwrap();
        assert!(img.pixels.iter().all(|p| *p == [0.0, 0.0, 1.0]));
        assert_eq!(
            clip_to_box([2.0, 2.0, 10.0], [0.0, 0.0, -1.0], [4.0; 3]),
            Some((6.0, 10.0))
        );
        assert_eq!(
            clip_to_box([5.0, 2.0, 10.0], [0.0, 0.0, -1.0], [4.0; 3]),
            None
        );
        // In the plane of a face: the lower face is inside, the upper one outside.
        assert_eq!(
            clip_to_box([0.0, 2.0, 10.0], [0.0, 0.0, -1.0], [4.0; 3]),
            Some((6.0, 10.0))
        );
        assert_eq!(
            clip_to_box([4.0, 2.0, 10.0], [0.0, 0.0, -1.0], [4.0; 3]),
            None
        );
        // Inside the volume: the ray starts at the eye.
        assert_eq!(
            clip_to_box([2.0, 2.0, 1.0], [0.0, 0.0, -1.0], [4.0; 3]),
            Some((0.0, 1.0))
        );
    }

    #[test]
    fn a_missing_channel_is_an_error() {
        let vol = Memory::new([4, 4, 4], [4, 4, 4], |_, _, _| 1.0);
        let mut s = scene([2.0, 2.0, 10.0], [2.0, 2.0, 0.0], 0.5);
        s.channels[0].channel = 3;
        let e = render(&vol, &s, &ReferenceOptions::new(1, 1)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "scene draws channel 3 but memory has 1 channels"
        );
    }
}
