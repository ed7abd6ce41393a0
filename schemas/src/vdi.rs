//! Volumetric depth images (VDIs): the file format, and the in-memory image that the GPU
//! generator fills and the VDI renderer reads.
//!
//! A VDI keeps, for every pixel of a *camera of generation*, a list of up to N_S
//! *supersegments*, front to back along the pixel's ray: each the premultiplied colour and
//! opacity that compositing its stretch of the ray gives, with the front and back distance of
//! that stretch. Fully transparent stretches are left out. Compositing a pixel's supersegments
//! in order over the background gives the direct volume rendering (DVR) of that pixel
//! ([`VolumetricDepthImage::composite`]); a renderer can also march other rays through the
//! lists (Gupta et al., *Efficient Raycasting of Volumetric Depth Images for Remote Data
//! Visualization*, sections 2.3 to 4).
//!
//! # File layout
//!
//! This is the one place the layout is written down. Integers and samples are little-endian.
//!
//! | Bytes | Content |
//! |---|---|
//! | 8 | the magic [`VDI_MAGIC`] |
//! | 4 | `u32` length `H` of the header, at most [`MAX_HEADER_BYTES`] |
//! | `H` | the header, a [`VdiHeader`] as UTF-8 JSON (`schemas/json/vdi-header.schema.json`) |
//! | 8 + `L₁` | the counts plane |
//! | 8 + `L₂` | the colour plane |
//! | 8 + `L₃` | the depth plane |
//!
//! Nothing follows the depth plane. Each plane is stored as a `u64` length `L` followed by `L`
//! bytes: with compression `none` the raw plane itself; with `lz4` the raw plane as one LZ4
//! block behind a `u32` holding the raw plane's length (lz4_flex's `compress_prepend_size`);
//! with `shuffled_lz4` the same of the raw plane's bytes regrouped by their place in a value
//! (all first bytes of the plane's values, then all second bytes, ...; a value is one `f16`,
//! `u16` or `f32`, and a count is one byte), as blosc's byte shuffle does; with
//! `shuffled_zstd` the same regrouped bytes as one standard zstd frame (RFC 8878, its magic
//! first) whose header announces the raw plane's length.
//! The raw planes, lists in row-major order from the top-left pixel (`x` right, `y` down):
//!
//! - **counts**: one `u8` per list, its number of supersegments, at most N_S
//!   (`width·height` bytes);
//! - **colour**: for each list its used slots only, front to back (`Σ counts` slots in all),
//!   each premultiplied `[r, g, b, a]` (colour at least 0, and above 1 where channels mix
//!   additively; opacity in `[0, 1]`) as four IEEE half floats (format `f16`, 8
//!   bytes) or four `f32` (format `f32`, 16 bytes). The in-memory image holds half floats, as
//!   the GPU generates and draws them: format `f32` writes them widened, and reading it
//!   rounds each value to the nearest half float;
//! - **depth**: the same slots, each `[front, back]`, distances from the eye along the list's
//!   ray in world units with `0 ≤ front ≤ back`, each slot's front at or past the back of the
//!   slot before it in its list, as two `f32` (format `f32`, 8 bytes) or two
//!   `u16` (format `u16`, 4 bytes) quantised linearly between the header's `near` and `far`:
//!   `q = round((d − near)/(far − near)·65535)`, clamped to `0..=65535`, read back as
//!   `near + q/65535·(far − near)`.
//!
//! # What [`VolumetricDepthImage::decode`] checks
//!
//! The magic; a header of at most [`MAX_HEADER_BYTES`] that is valid JSON without unknown
//! fields; version [`VDI_VERSION`]; `width·height` in `1..=`[`MAX_VDI_PIXELS`], N_S in
//! `1..=`[`MAX_SUPERSEGMENTS`] and `width·height·N_S` at most [`MAX_VDI_SLOTS`] (which bounds
//! the memory a file can ask for); a scene hash of 16 lowercase hex digits; finite header
//! numbers, a field of view in `(0, 180)` degrees, `volume_min ≤ volume_max`, and with `u16`
//! depth `0 ≤ near < far` and a step `(far − near)/65535` wider than the f32 spacing (ulp) at
//! `far` (so that every level reads back as an f32 that quantises to it again); every plane's
//! stored length within the rest of the input, and its raw length (for LZ4 and zstd the
//! announced one, checked before decompressing; a zstd plane exactly one frame) exactly what
//! the header and counts imply; counts at most N_S; no trailing bytes; and in every used slot
//! finite values, a colour of at least 0, an opacity in `[0, 1]`, `0 ≤ front ≤ back`, and a
//! front at or past the back of the slot before it in its list (renderers find where a ray
//! is by that order). The colour checks apply to the colour as the image holds it, in half
//! floats: from an `f32` colour plane, a value of 65520 or more is infinite there and
//! refused, an opacity up to 2⁻¹¹ above 1 rounds to 1 and a value down to −2⁻²⁵ rounds to
//! −0, both accepted, and errors show the rounded values.
//! [`VolumetricDepthImage::encode`] checks the same, so that what it writes always reads back.

use half::f16;
#[cfg(not(target_arch = "wasm32"))]
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::scene::Camera;

mod decode;
mod encode;
mod error;

pub use error::VdiError;

/// Version of the VDI format described in the module documentation.
pub const VDI_VERSION: u32 = 1;

/// The first 8 bytes of a VDI file.
pub const VDI_MAGIC: [u8; 8] = *b"RESVDI\0\x01";

/// The most supersegments a list may hold (the largest N_S).
pub const MAX_SUPERSEGMENTS: u32 = 64;

/// The most pixels (supersegment lists) a VDI may have.
pub const MAX_VDI_PIXELS: u64 = 8192 * 8192;

/// The most slots (`width·height·N_S`) a VDI may have: the in-memory image holds every slot,
/// 16 bytes each, so this bounds what a file can make [`VolumetricDepthImage::decode`]
/// allocate (512 MiB of colour and 512 MiB of depth; 1920×1080 lists of 32 supersegments fit).
pub const MAX_VDI_SLOTS: u64 = 1 << 26;

/// The longest header, in bytes.
pub const MAX_HEADER_BYTES: u32 = 1 << 20;

/// What errors name as the file when [`VolumetricDepthImage::encode`] refuses an image.
const ENCODING: &str = "VDI to encode";

/// The header of a VDI file: the camera of generation, the image's sizes and the formats of
/// its planes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(
    title = "Volumetric depth image header",
    description = "JSON header of a volumetric depth image (VDI) file: 8 bytes 'RESVDI\\0\\x01', \
        a little-endian u32 header length H (at most 1 MiB), H bytes of this header, then three \
        planes, each a little-endian u64 stored length and its bytes (with compression `lz4` one \
        LZ4 block behind a u32 raw length): the u8 supersegment count of every list, row-major \
        from the top-left pixel; the colour and opacity of the used slots, list by list, front \
        to back; and their front and back depths. The module documentation of \
        `residency_schemas::vdi` describes the layout in full."
)]
pub struct VdiHeader {
    /// Format version, [`VDI_VERSION`].
    #[schemars(range(min = VDI_VERSION, max = VDI_VERSION))]
    pub version: u32,
    /// Width of the image in pixels (supersegment lists).
    #[schemars(range(min = 1))]
    pub width: u32,
    /// Height of the image in pixels (supersegment lists).
    #[schemars(range(min = 1))]
    pub height: u32,
    /// N_S: the most supersegments a list holds, and the slots per list in memory.
    #[schemars(range(min = 1, max = MAX_SUPERSEGMENTS))]
    pub supersegments: u32,
    /// The camera of generation, as the scene file writes it.
    pub camera: Camera,
    /// How the generator cast the rays of the lists.
    pub rays: RayBasis,
    /// World-to-view matrix of the camera of generation, column-major, right-handed.
    pub view: [f32; 16],
    /// View-to-clip matrix of the camera of generation, column-major, mapping depths `near`
    /// to `far` to clip depth 0 to 1 (as wgpu and WebGPU do).
    pub projection: [f32; 16],
    /// Near end of the depth range the projection maps (the generator sets `near` and `far`
    /// to the volume's span along the view); the low end of quantised `u16` depth.
    pub near: f32,
    /// Far end of the depth range the projection maps; the high end of quantised `u16` depth.
    pub far: f32,
    /// Lowest corner of the volume's box, world units.
    pub volume_min: [f64; 3],
    /// Highest corner of the volume's box, world units.
    pub volume_max: [f64; 3],
    /// The linear RGB colour the DVR image composites over.
    pub background: [f32; 3],
    /// Number of channels mixed into the VDI.
    pub channels: u32,
    /// Format of the colour plane.
    pub colour: ColourFormat,
    /// Format of the depth plane.
    pub depth: DepthFormat,
    /// Compression of the three planes.
    pub compression: Compression,
    /// Hash of the scene the VDI was generated from: 16 lowercase hex digits.
    #[schemars(pattern(r"^[0-9a-f]{16}$"))]
    pub scene_hash: String,
    /// Name of the dataset rendered, when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dataset: Option<String>,
}

/// How the generator cast rays: pixel `(x, y)` (`x` right, `y` down, from the top-left) has
/// the world direction `normalize(forward + ndc_x·right + ndc_y·up)` with `ndc_x = (x +
/// 0.5)/width·2 − 1` and `ndc_y = 1 − (y + 0.5)/height·2`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RayBasis {
    /// Unit view direction.
    pub forward: [f32; 3],
    /// Right vector, already scaled by `tan(fov_y/2)·width/height`.
    pub right: [f32; 3],
    /// Up vector, already scaled by `tan(fov_y/2)`.
    pub up: [f32; 3],
}

/// How the colour plane stores a slot's `[r, g, b, a]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ColourFormat {
    /// Four IEEE 754 half floats (8 bytes a slot).
    F16,
    /// Four `f32` (16 bytes a slot): the image's half floats widened; reading rounds each to
    /// the nearest half float.
    F32,
}

/// How the depth plane stores a slot's `[front, back]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum DepthFormat {
    /// Two `f32` distances from the eye along the pixel's ray, world units (8 bytes a slot).
    F32,
    /// The same distances as two `u16` quantised linearly between `near` and `far`: `q =
    /// round((d − near)/(far − near)·65535)`, clamped (4 bytes a slot).
    U16,
}

/// How the planes are compressed.
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
    strum::EnumString,
    strum::IntoStaticStr,
    strum::VariantNames,
)]
#[serde(rename_all = "snake_case")]
#[strum(serialize_all = "snake_case")]
pub enum Compression {
    /// Each plane is one LZ4 block behind its raw length as a `u32` (lz4_flex's block
    /// format, size prepended).
    Lz4,
    /// The raw planes.
    None,
    /// As [`Compression::Lz4`], of each plane's bytes regrouped by their place in a value
    /// first (all first bytes, then all second bytes, ...; values of 2 bytes for `f16` and
    /// `u16`, 4 for `f32`, 1 for the counts), as blosc's shuffle does: the high bytes of
    /// neighbouring floats repeat, so LZ4 finds them (a third smaller than `lz4` on rendered
    /// VDIs). The default: what the generator writes and `viewer serve` answers unless asked
    /// otherwise.
    #[default]
    ShuffledLz4,
    /// The same shuffled bytes as one standard zstd frame that announces its decompressed
    /// size (written at level [`ZSTD_LEVEL`]): 1.4 to 1.7 times smaller than `shuffled_lz4` on
    /// rendered VDIs, and slower to write and read, so for links slower than the time it
    /// costs.
    ShuffledZstd,
}

/// The zstd level [`Compression::ShuffledZstd`] writes at.
pub const ZSTD_LEVEL: i32 = 3;

/// The first four bytes of a standard zstd frame (RFC 8878), as a `shuffled_zstd` plane
/// begins.
const ZSTD_MAGIC: [u8; 4] = [0x28, 0xb5, 0x2f, 0xfd];

impl Compression {
    /// Whether each plane's bytes are regrouped by their place in a value before compressing.
    fn shuffles(self) -> bool {
        match self {
            Self::ShuffledLz4 | Self::ShuffledZstd => true,
            Self::Lz4 | Self::None => false,
        }
    }
}

impl ColourFormat {
    /// Bytes of one value (a channel of a slot).
    fn value_bytes(self) -> usize {
        self.slot_bytes() / 4
    }

    fn slot_bytes(self) -> usize {
        match self {
            Self::F16 => 8,
            Self::F32 => 16,
        }
    }
}

impl DepthFormat {
    /// Bytes of one value (a depth of a slot).
    fn value_bytes(self) -> usize {
        self.slot_bytes() / 2
    }

    fn slot_bytes(self) -> usize {
        match self {
            Self::F32 => 8,
            Self::U16 => 4,
        }
    }
}

/// A volumetric depth image: per pixel (a supersegment list) up to N_S supersegments, front to
/// back.
#[derive(Clone, Debug, PartialEq)]
pub struct VolumetricDepthImage {
    /// The camera of generation, sizes and formats.
    pub header: VdiHeader,
    /// Supersegments per list, row-major from the top (width·height entries, each ≤ N_S).
    pub counts: Vec<u8>,
    /// The supersegments of every list, lists in row-major order from the top, each list's
    /// front to back (`Σ counts` entries, as the file stores them; [`Self::starts`] gives
    /// where each list begins): premultiplied colour and opacity `[r, g, b, a]` (what
    /// front-to-back compositing of its samples gives: composite a list's supersegments in
    /// order over the background and you get the DVR pixel), as half floats: the precision
    /// the GPU generates and draws them in, whatever the file's colour format.
    pub colour: Vec<[f16; 4]>,
    /// The same supersegments' `[front, back]`: distances from the eye along the list's ray,
    /// world units, front ≤ back, each front at or past the back before it in its list.
    pub depth: Vec<[f32; 2]>,
}

/// The sizes a valid header implies.
struct Shape {
    /// `width·height`.
    lists: usize,
}

fn finite<T: Copy + Into<f64>>(values: &[T]) -> bool {
    values.iter().all(|&v| v.into().is_finite())
}

/// The supersegments `counts` hold in all, each count checked to be at most the header's N_S.
fn used_slots(counts: &[u8], header: &VdiHeader, file: &str) -> Result<usize, VdiError> {
    let width = header.width as usize;
    let mut used = 0usize;
    for (index, &count) in counts.iter().enumerate() {
        if u32::from(count) > header.supersegments {
            return Err(VdiError::Count {
                file: file.to_owned(),
                x: (index % width) as u32,
                y: (index / width) as u32,
                count,
                supersegments: header.supersegments,
            });
        }
        used += usize::from(count);
    }
    Ok(used)
}

/// Checks everything the header alone decides, returning its sizes.
fn check_header(header: &VdiHeader, file: &str) -> Result<Shape, VdiError> {
    let field = |field, problem| VdiError::HeaderField {
        file: file.to_owned(),
        field,
        problem,
    };
    if header.version != VDI_VERSION {
        return Err(VdiError::Version {
            file: file.to_owned(),
            version: header.version,
        });
    }
    let lists = u64::from(header.width) * u64::from(header.height);
    if !(1..=MAX_VDI_PIXELS).contains(&lists) {
        return Err(VdiError::Pixels {
            file: file.to_owned(),
            width: header.width,
            height: header.height,
        });
    }
    if !(1..=MAX_SUPERSEGMENTS).contains(&header.supersegments) {
        return Err(VdiError::Supersegments {
            file: file.to_owned(),
            supersegments: header.supersegments,
        });
    }
    let slots = lists * u64::from(header.supersegments);
    if slots > MAX_VDI_SLOTS {
        return Err(VdiError::Slots {
            file: file.to_owned(),
            width: header.width,
            height: header.height,
            supersegments: header.supersegments,
            slots,
        });
    }
    let hash = &header.scene_hash;
    if hash.len() != 16 || !hash.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f')) {
        return Err(VdiError::SceneHash {
            file: file.to_owned(),
            hash: hash.clone(),
        });
    }
    let camera = &header.camera;
    if ![camera.eye, camera.target, camera.up]
        .iter()
        .all(|v| finite(v))
    {
        return Err(field("camera", "holds a non-finite number"));
    }
    if !(camera.fov_y_degrees > 0.0 && camera.fov_y_degrees < 180.0) {
        return Err(field("camera.fov_y_degrees", "is not in (0, 180)"));
    }
    let rays = &header.rays;
    if ![rays.forward, rays.right, rays.up]
        .iter()
        .all(|v| finite(v))
    {
        return Err(field("rays", "holds a non-finite number"));
    }
    if !finite(&header.view) {
        return Err(field("view", "holds a non-finite number"));
    }
    if !finite(&header.projection) {
        return Err(field("projection", "holds a non-finite number"));
    }
    if !finite(&[header.near, header.far]) {
        return Err(field("near or far", "is not finite"));
    }
    if header.depth == DepthFormat::U16 && !u16_depth_range(header.near, header.far) {
        return Err(field(
            "near and far",
            "are not 0 ≤ near < far with (far − near)/65535 wider than the f32 spacing at far, \
             as u16 depth needs",
        ));
    }
    if !finite(&header.volume_min) || !finite(&header.volume_max) {
        return Err(field(
            "volume_min or volume_max",
            "holds a non-finite number",
        ));
    }
    if (0..3).any(|i| header.volume_min[i] > header.volume_max[i]) {
        return Err(field("volume_min", "is above volume_max"));
    }
    if !finite(&header.background) {
        return Err(field("background", "holds a non-finite number"));
    }
    Ok(Shape {
        lists: lists as usize,
    })
}

/// Checks one used slot: finite, colour at least 0, opacity in `[0, 1]`, `0 ≤ front ≤ back`,
/// and its front not before `previous_back`, the back of the slot before it in its list.
#[inline]
fn check_slot(
    file: &str,
    at: (u32, u32, u32),
    colour: [f16; 4],
    depth: [f32; 2],
    previous_back: Option<f32>,
) -> Result<(), VdiError> {
    // The same checks as `slot_error`'s, as one expression, for the common case; the half
    // floats compared as they are (no conversion: `half` compares sign and magnitude, ±0
    // equal, NaN unordered, as f32 does).
    let [front, back] = depth;
    let valid = colour.iter().all(|c| c.is_finite())
        && depth.iter().all(|v| v.is_finite())
        && colour[..3].iter().all(|&c| c >= f16::ZERO)
        && (f16::ZERO..=f16::ONE).contains(&colour[3])
        && 0.0 <= front
        && front <= back
        && previous_back.is_none_or(|p| front >= p);
    if valid {
        Ok(())
    } else {
        slot_error(file, at, colour, depth, previous_back)
    }
}

/// [`check_slot`] of a slot that failed its quick check: the error of the first check it
/// fails.
#[cold]
#[inline(never)]
fn slot_error(
    file: &str,
    (x, y, slot): (u32, u32, u32),
    colour: [f16; 4],
    depth: [f32; 2],
    previous_back: Option<f32>,
) -> Result<(), VdiError> {
    let colour = colour.map(f16::to_f32);
    let non_finite = |what| VdiError::NonFinite {
        file: file.to_owned(),
        x,
        y,
        slot,
        what,
    };
    if !finite(&colour) {
        return Err(non_finite("colour"));
    }
    // Channels mix additively, so a premultiplied colour may pass 1; an opacity may not.
    if colour[..3].iter().any(|&c| c < 0.0) || !(0.0..=1.0).contains(&colour[3]) {
        return Err(VdiError::ColourRange {
            file: file.to_owned(),
            x,
            y,
            slot,
            colour,
        });
    }
    if !finite(&depth) {
        return Err(non_finite("depth"));
    }
    let [front, back] = depth;
    if !(0.0 <= front && front <= back) {
        return Err(VdiError::DepthOrder {
            file: file.to_owned(),
            x,
            y,
            slot,
            front,
            back,
        });
    }
    if let Some(previous_back) = previous_back
        && front < previous_back
    {
        return Err(VdiError::ListOrder {
            file: file.to_owned(),
            x,
            y,
            slot,
            front,
            previous_back,
        });
    }
    Ok(())
}

/// Rows of lists per band that are checked and converted at once, when encoding and decoding.
const BAND_ROWS: usize = 16;

/// A band of [`BAND_ROWS`] rows of lists (fewer at the bottom): where its lists and
/// supersegments begin, its counts and how many supersegments they hold.
struct Band<'c> {
    first_list: usize,
    first_slot: usize,
    counts: &'c [u8],
    slots: usize,
}

/// The image's lists of `counts` (`width` a row), top to bottom in bands.
fn bands(counts: &[u8], width: usize) -> impl Iterator<Item = Band<'_>> {
    let mut first_slot = 0;
    counts
        .chunks(BAND_ROWS * width)
        .enumerate()
        .map(move |(i, counts)| {
            let slots = counts.iter().map(|&c| usize::from(c)).sum();
            let band = Band {
                first_list: i * BAND_ROWS * width,
                first_slot,
                counts,
                slots,
            };
            first_slot += slots;
            band
        })
}

/// `a` and `b`, on two threads where the platform has them.
fn join<A: Send, B: Send>(a: impl FnOnce() -> A + Send, b: impl FnOnce() -> B + Send) -> (A, B) {
    #[cfg(not(target_arch = "wasm32"))]
    return rayon::join(a, b);
    #[cfg(target_arch = "wasm32")]
    return (a(), b());
}

/// `f` of each item, on several threads where the platform has them; the first error in the
/// items' order, if any.
fn try_in_order<T: Send>(
    items: Vec<T>,
    f: impl Fn(T) -> Result<(), VdiError> + Sync + Send,
) -> Result<(), VdiError> {
    #[cfg(not(target_arch = "wasm32"))]
    let results: Vec<_> = items.into_par_iter().map(f).collect();
    #[cfg(target_arch = "wasm32")]
    let results: Vec<_> = items.into_iter().map(f).collect();
    results
        .into_iter()
        .find_map(Result::err)
        .map_or(Ok(()), Err)
}

/// Whether `near` and `far` suit quantised `u16` depth: `0 ≤ near < far`, with a quantisation
/// step `(far − near)/65535` wider than the f32 spacing (ulp) at `far` (by a margin for the f64
/// arithmetic), so that every level reads back as an f32 within less than half a step of it,
/// which quantises to the same level: decoding then encoding changes nothing.
fn u16_depth_range(near: f32, far: f32) -> bool {
    if !(0.0 <= near && near < far) {
        return false;
    }
    // `far` is finite and positive here, so its bits plus one are the next f32 up.
    let ulp = f64::from(f32::from_bits(far.to_bits() + 1)) - f64::from(far);
    (f64::from(far) - f64::from(near)) / 65535.0 >= 1.0001 * ulp
}

/// The `u16` of distance `d` between `near` and `far`, rounded and clamped.
fn quantise(d: f32, near: f32, far: f32) -> u16 {
    let t = (f64::from(d) - f64::from(near)) / (f64::from(far) - f64::from(near));
    (t * 65535.0).round().clamp(0.0, 65535.0) as u16
}

/// The distance of quantised depth `q`.
fn dequantise(q: u16, near: f32, far: f32) -> f32 {
    let (near, far) = (f64::from(near), f64::from(far));
    (near + f64::from(q) / 65535.0 * (far - near)) as f32
}

impl VolumetricDepthImage {
    /// An image of `header`'s sizes with every list empty (all counts zero, no
    /// supersegments).
    pub fn new(header: VdiHeader) -> Self {
        let lists = header.width as usize * header.height as usize;
        Self {
            header,
            counts: vec![0; lists],
            colour: Vec::new(),
            depth: Vec::new(),
        }
    }

    /// Where each list's supersegments begin in `colour` and `depth`: `width·height + 1`
    /// prefix sums of the counts (the last is `Σ counts`).
    pub fn starts(&self) -> Vec<usize> {
        let mut starts = Vec::with_capacity(self.counts.len() + 1);
        let mut sum = 0usize;
        starts.push(0);
        for &count in &self.counts {
            sum += usize::from(count);
            starts.push(sum);
        }
        starts
    }

    /// The colour and depth of list `(x, y)`'s supersegments, front to back. It sums the
    /// counts before the list: for many lists, index with [`Self::starts`].
    ///
    /// # Panics
    /// When `(x, y)` is outside the image or the arrays are shorter than the counts say.
    pub fn list(&self, x: u32, y: u32) -> (&[[f16; 4]], &[[f32; 2]]) {
        assert!(
            x < self.header.width && y < self.header.height,
            "list ({x}, {y}) is outside a {}×{} VDI",
            self.header.width,
            self.header.height
        );
        let index = y as usize * self.header.width as usize + x as usize;
        let start: usize = self.counts[..index].iter().map(|&c| usize::from(c)).sum();
        let end = start + usize::from(self.counts[index]);
        (&self.colour[start..end], &self.depth[start..end])
    }

    /// The pixel `(x, y)` as the DVR image has it: the list's supersegments composited front
    /// to back over the header's background, `rgb = Σ T_j·c_j + T·background` and `a = 1 − T`,
    /// where `T_j` is the product of `(1 − a_k)` for `k < j` and `T` that of all. Returns
    /// linear RGB and alpha.
    ///
    /// # Panics
    /// As [`VolumetricDepthImage::list`].
    pub fn composite(&self, x: u32, y: u32) -> [f32; 4] {
        self.composite_list(self.list(x, y).0)
    }

    /// Every list's colour and depth, row-major from the top, in one pass.
    pub fn lists(&self) -> impl Iterator<Item = (&[[f16; 4]], &[[f32; 2]])> {
        let mut start = 0usize;
        self.counts.iter().map(move |&count| {
            let end = start + usize::from(count);
            let list = (&self.colour[start..end], &self.depth[start..end]);
            start = end;
            list
        })
    }

    /// The supersegments `colour` of one list composited as [`Self::composite`] does.
    pub fn composite_list(&self, colour: &[[f16; 4]]) -> [f32; 4] {
        let mut rgb = [0.0f64; 3];
        let mut transmittance = 1.0f64;
        for c in colour {
            for (sum, &channel) in rgb.iter_mut().zip(c) {
                *sum += transmittance * f64::from(channel);
            }
            transmittance *= 1.0 - f64::from(c[3]);
        }
        let [r, g, b] = std::array::from_fn(|i| {
            (rgb[i] + transmittance * f64::from(self.header.background[i])) as f32
        });
        [r, g, b, (1.0 - transmittance) as f32]
    }
}

#[cfg(test)]
mod tests {
    use super::decode::unshuffle;
    use super::encode::shuffle;
    use super::*;

    #[test]
    fn the_shuffle_groups_bytes_by_their_place_and_is_undone() {
        let raw = [1, 2, 3, 4, 5, 6];
        assert_eq!(shuffle(&raw, 2), [1, 3, 5, 2, 4, 6]);
        assert_eq!(shuffle(&raw, 3), [1, 4, 2, 5, 3, 6]);
        assert_eq!(shuffle(&raw, 1), raw);
        assert_eq!(unshuffle(&shuffle(&raw, 2), 2), raw);
        assert_eq!(unshuffle(&shuffle(&raw, 3), 3), raw);
        let twelve: Vec<u8> = (1..=12).collect();
        assert_eq!(shuffle(&twelve, 4), [1, 5, 9, 2, 6, 10, 3, 7, 11, 4, 8, 12]);
        assert_eq!(shuffle(&twelve, 2), [1, 3, 5, 7, 9, 11, 2, 4, 6, 8, 10, 12]);
        // Bytes past the last whole value stay 0, as before the one-pass shuffles.
        assert_eq!(unshuffle(&[1, 2, 3, 4], 3), [1, 2, 3, 0]);
        for width in 1..=4 {
            let bytes: Vec<u8> = (0..4096u32 * 12).map(|i| (i * 7919 % 251) as u8).collect();
            assert_eq!(unshuffle(&shuffle(&bytes, width), width), bytes, "{width}");
            assert!(shuffle(&[], width).is_empty() && unshuffle(&[], width).is_empty());
        }
        // Neighbouring floats share their high bytes: grouped, LZ4 finds them.
        let ramp: Vec<u8> = (0..4096)
            .flat_map(|i| (1.0f32 + i as f32 * 1e-3).to_le_bytes())
            .collect();
        let plain = lz4_flex::block::compress_prepend_size(&ramp).len();
        let grouped = lz4_flex::block::compress_prepend_size(&shuffle(&ramp, 4)).len();
        assert!(grouped * 2 < plain, "{grouped} shuffled against {plain}");
    }

    #[test]
    fn every_u16_level_reads_back_to_itself_where_the_range_is_accepted() {
        // The last two are just wide enough: (1 − near)/65535 is 1.0002 and 1.00011 f32 steps
        // at 1.
        for (near, far) in [
            (0.0, 1.0),
            (1.0, 9.0),
            (100.0, 104.0),
            (1000.0, 1010.0),
            (0.0, 1e30),
            (1.0 - 65535.0 * f32::EPSILON * 1.0002, 1.0),
            (1.0 - 65535.0 * f32::EPSILON * 1.00011, 1.0),
        ] {
            assert!(u16_depth_range(near, far), "{near} {far}");
            for q in 0..=u16::MAX {
                assert_eq!(
                    quantise(dequantise(q, near, far), near, far),
                    q,
                    "{near} {far}"
                );
            }
        }
        // A little narrower than the narrowest of those at 1.0, an empty range, a negative
        // near, and ranges whose levels f32 cannot tell apart.
        for (near, far) in [
            (1.0 - 65535.0 * f32::EPSILON * 0.9999, 1.0),
            (1.0, 1.0),
            (-1.0, 1.0),
            (1000.0, 1000.5),
            (f32::MAX / 2.0, f32::MAX),
        ] {
            assert!(!u16_depth_range(near, far), "{near} {far}");
        }
    }

    #[test]
    fn quantisation_is_within_half_a_step_and_clamps() {
        let (near, far) = (2.0f32, 10.0f32);
        let step = f64::from(far - near) / 65535.0;
        assert_eq!(quantise(near, near, far), 0);
        assert_eq!(quantise(far, near, far), 65535);
        assert_eq!(quantise(0.5, near, far), 0);
        assert_eq!(quantise(1e30, near, far), 65535);
        assert_eq!(quantise(6.0, near, far), 32768);
        assert_eq!(dequantise(0, near, far), near);
        assert_eq!(dequantise(65535, near, far), far);
        for i in 0..=1000 {
            let d = near + (far - near) * i as f32 / 1000.0;
            let back = dequantise(quantise(d, near, far), near, far);
            assert!(
                (f64::from(back) - f64::from(d)).abs() <= step / 2.0 + f64::from(d) * 1e-7,
                "{d} -> {back}"
            );
        }
    }
}
