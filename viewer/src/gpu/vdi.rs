//! Volumetric depth images from the renderer (the VDI paper, Sec. 3): the buffer the VDI pass
//! of `shaders/raycast/vdi.wgsl` writes, what it holds per pixel, and the
//! [`VolumetricDepthImage`] read back from it with the header of its view.
//!
//! The pass marches the same rays over the same data as an image frame, so a VDI is generated
//! from a converged view; [`super::renderer::Renderer::generate_vdi`] runs it.

use residency_schemas::vdi::{
    ColourFormat, Compression, DepthFormat, RayBasis, VDI_VERSION, VdiCamera, VdiHeader,
    VolumetricDepthImage,
};

use super::buffers::{check_binding, readback_buffer, storage_buffer};
use super::contract::VDI_STATE_SLOTS;
use super::device::Gpu;
use super::error::GpuError;
use crate::scene::{Camera, Scene};

/// Bytes of one slot of the VDI target (a `vec4<f32>`).
const SLOT_BYTES: u64 = 16;

/// The buffer the VDI pass writes (bound as the image) and its readback, for one image size
/// and supersegment count.
pub(crate) struct VdiTarget {
    /// Most supersegments per pixel.
    pub supersegments: u32,
    /// Pixels.
    pub pixels: u64,
    /// Per pixel `supersegments + VDI_STATE_SLOTS` slots.
    pub buffer: wgpu::Buffer,
    /// Its readback.
    pub readback: wgpu::Buffer,
}

impl VdiTarget {
    /// The target of `pixels` pixels of at most `supersegments` supersegments.
    ///
    /// # Errors
    /// A [`GpuError`] naming the target when it is over the device's storage-buffer limit.
    pub fn new(gpu: &Gpu, pixels: u64, supersegments: u32) -> Result<Self, GpuError> {
        let bytes = pixels * u64::from(supersegments + VDI_STATE_SLOTS) * SLOT_BYTES;
        check_binding(
            gpu,
            "the volumetric depth image",
            bytes,
            "generate a smaller image or with fewer supersegments",
        )?;
        Ok(Self {
            supersegments,
            pixels,
            buffer: storage_buffer(gpu, "vdi target", bytes, wgpu::BufferUsages::COPY_SRC),
            readback: readback_buffer(gpu, "vdi readback", bytes),
        })
    }

    /// Its size in bytes.
    pub fn bytes(&self) -> u64 {
        self.buffer.size()
    }
}

/// What the VDI pass found for one image, beside the VDI itself.
#[derive(Clone, Debug, PartialEq)]
pub struct VdiGeneration {
    /// The volumetric depth image.
    pub image: VolumetricDepthImage,
    /// The DVR image the same rays composited (linear RGBA, row-major from the top): what
    /// the VDI gives back from its own viewpoint, up to the supersegments' half-float colour.
    pub dvr: Vec<[f32; 4]>,
    /// Per pixel, the `γ` its supersegments were cut with.
    pub gamma: Vec<f32>,
    /// Marches the rays took in all (one per ray when every ray fits at the first `γ`).
    pub marches: u64,
}

/// Reads the VDI target's slots (`slots`, as the pass left them) into the image of `header`.
pub(crate) fn read_target(header: VdiHeader, slots: &[[f32; 4]]) -> VdiGeneration {
    let n = header.supersegments as usize;
    let stride = n + VDI_STATE_SLOTS as usize;
    let mut image = VolumetricDepthImage::new(header);
    let pixels = image.counts.len();
    let mut dvr = Vec::with_capacity(pixels);
    let mut gamma = Vec::with_capacity(pixels);
    let mut marches = 0u64;
    for p in 0..pixels {
        let at = &slots[p * stride..(p + 1) * stride];
        let (segments, state) = at.split_at(n);
        dvr.push(state[0]);
        let count = state[1][0].to_bits().min(n as u32) as usize;
        gamma.push(state[1][1]);
        marches += u64::from(state[1][2].to_bits());
        image.counts[p] = count as u8;
        for (s, slot) in segments[..count].iter().enumerate() {
            let [r, g] = unpack_half2(slot[0]);
            let [b, a] = unpack_half2(slot[1]);
            image.colour[p * n + s] = [r, g, b, a];
            image.depth[p * n + s] = [slot[2], slot[3]];
        }
    }
    VdiGeneration {
        image,
        dvr,
        gamma,
        marches,
    }
}

/// WGSL's `unpack2x16float` of the bits of `word`.
fn unpack_half2(word: f32) -> [f32; 2] {
    let bits = word.to_bits();
    [
        half::f16::from_bits(bits as u16).to_f32(),
        half::f16::from_bits((bits >> 16) as u16).to_f32(),
    ]
}

/// The header of a VDI of `scene` at `width × height` with at most `supersegments` per list,
/// over a volume whose world box is `[0, extent]`, mixing `channels` channels.
pub(crate) fn header(
    scene: &Scene,
    width: u32,
    height: u32,
    supersegments: u32,
    extent: [f64; 3],
    channels: u32,
) -> VdiHeader {
    let cam = &scene.camera;
    let (forward, right, up) = cam.basis();
    let tan_half = (cam.fov_y_degrees.to_radians() / 2.0).tan();
    let aspect = f64::from(width) / f64::from(height);
    let f3 = |v: [f64; 3]| v.map(|x| x as f32);
    // The depth range: the volume's corners along the view, in front of the eye.
    let depths = (0..8).map(|corner: usize| {
        (0..3)
            .map(|a| {
                let x = if corner >> a & 1 == 1 { extent[a] } else { 0.0 };
                (x - cam.eye[a]) * forward[a]
            })
            .sum::<f64>()
    });
    let (lo, hi) = depths.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), d| {
        (lo.min(d), hi.max(d))
    });
    let far = hi.max(1e-6);
    let near = lo.clamp(far * 1e-6, far * (1.0 - 1e-6));
    let eye = glam::DVec3::from(cam.eye);
    let view = glam::DMat4::look_to_rh(eye, glam::DVec3::from(forward), glam::DVec3::from(up));
    let projection = glam::DMat4::perspective_rh(cam.fov_y_degrees.to_radians(), aspect, near, far);
    VdiHeader {
        version: VDI_VERSION,
        width,
        height,
        supersegments,
        camera: cam.into(),
        rays: RayBasis {
            forward: f3(forward),
            right: f3(right.map(|x| x * tan_half * aspect)),
            up: f3(up.map(|x| x * tan_half)),
        },
        view: view.as_mat4().to_cols_array(),
        projection: projection.as_mat4().to_cols_array(),
        near: near as f32,
        far: far as f32,
        volume_min: [0.0; 3],
        volume_max: extent,
        background: f3(scene.background),
        channels,
        colour: ColourFormat::F16,
        depth: DepthFormat::F32,
        compression: Compression::ShuffledLz4,
        scene_hash: scene_hash(scene),
        dataset: None,
    }
}

impl From<&Camera> for VdiCamera {
    fn from(c: &Camera) -> Self {
        Self {
            eye: c.eye,
            target: c.target,
            up: c.up,
            fov_y_degrees: c.fov_y_degrees,
        }
    }
}

impl From<&VdiCamera> for Camera {
    fn from(c: &VdiCamera) -> Self {
        Self {
            eye: c.eye,
            target: c.target,
            up: c.up,
            fov_y_degrees: c.fov_y_degrees,
        }
    }
}

/// 16 hex digits naming `scene`: FNV-1a (64 bits) of its JSON.
pub fn scene_hash(scene: &Scene) -> String {
    let json = serde_json::to_vec(scene).expect("a scene always serializes");
    let hash = json.iter().fold(0xcbf2_9ce4_8422_2325_u64, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    });
    format!("{hash:016x}")
}
