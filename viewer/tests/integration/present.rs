//! Frames to the screen on the GPU (`gpu::present`, `shaders/present.wgsl`), checked on
//! lavapipe against the CPU path byte for byte: the present pass drawn into offscreen
//! textures (an sRGB one, where the hardware encodes, and a unorm one, where the pass does)
//! and read back equals the CPU blit and panel of `interactive::overlay`. Also: a frame
//! rendered without its pixels reads no image back and leaves the same image on the GPU
//! that `render` reads back, and the view session's GPU mode shows the image of its CPU mode.

use std::sync::Arc;
use std::time::Duration;

use crate::render_common::{gpu, new_gpu};
use residency_viewer::gpu::device::Gpu;
use residency_viewer::gpu::present::{PresentError, Presenter, srgb_table, surface_format};
use residency_viewer::gpu::renderer::{RenderOptions, Renderer};
use residency_viewer::gpu::synthetic::SyntheticSource;
use residency_viewer::interactive::overlay::{
    Canvas, ORIENTATION_HEIGHT, SrgbTable, orientation_rgba, panel_rgba, panel_size,
};
use residency_viewer::interactive::session::{Session, Step};
use residency_viewer::scene::orientation::Orientation;
use residency_viewer::scene::{Camera, ChannelStyle, Filter, OpacityPoint, Scene};
use residency_viewer::source::{BrickSource, SampleType};

/// A storage buffer holding `pixels` (as the renderer's image buffer).
fn image_buffer(gpu: &Gpu, pixels: &[[f32; 4]]) -> wgpu::Buffer {
    let buffer = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("test image"),
        size: (pixels.len() * 16) as u64,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    gpu.queue
        .write_buffer(&buffer, 0, bytemuck::cast_slice(pixels));
    buffer
}

/// Maps `buffer` (MAP_READ) and returns its bytes.
fn read(gpu: &Gpu, buffer: &wgpu::Buffer) -> Vec<u8> {
    buffer.map_async(wgpu::MapMode::Read, .., |r| r.unwrap());
    gpu.device
        .poll(wgpu::PollType::wait_indefinitely())
        .unwrap();
    let bytes = buffer.get_mapped_range(..).unwrap().to_vec();
    buffer.unmap();
    bytes
}

/// The bytes of a storage buffer of the GPU (copied out).
fn buffer_bytes(gpu: &Gpu, source: &wgpu::Buffer, bytes: u64) -> Vec<u8> {
    let staging = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("test readback"),
        size: bytes,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
    encoder.copy_buffer_to_buffer(source, 0, &staging, 0, bytes);
    gpu.queue.submit([encoder.finish()]);
    read(gpu, &staging)
}

/// The present pass of `pixels` (`iw × ih`) onto a `tw × th` texture of `format`, read back
/// as `0x00RRGGBB` per pixel.
fn present(
    gpu: &Gpu,
    presenter: &Presenter,
    pixels: &[[f32; 4]],
    (iw, ih): (u32, u32),
    (tw, th): (u32, u32),
) -> Vec<u32> {
    let format = presenter.format();
    let texture = gpu.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("test target"),
        size: wgpu::Extent3d {
            width: tw,
            height: th,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    });
    let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
    let image = image_buffer(gpu, pixels);
    let row = (tw * 4).div_ceil(256) * 256;
    let staging = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("test target readback"),
        size: u64::from(row * th),
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
    presenter
        .encode(gpu, &mut encoder, &image, (iw, ih), &view, (tw, th))
        .unwrap();
    encoder.copy_texture_to_buffer(
        texture.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &staging,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row),
                rows_per_image: Some(th),
            },
        },
        texture.size(),
    );
    gpu.queue.submit([encoder.finish()]);
    let bytes = read(gpu, &staging);
    let bgra = matches!(
        format,
        wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb
    );
    (0..th as usize)
        .flat_map(|y| {
            let bytes = &bytes;
            (0..tw as usize).map(move |x| {
                let p = &bytes[y * row as usize + 4 * x..][..4];
                assert_eq!(p[3], 255, "opaque at ({x}, {y})");
                let (r, b) = if bgra { (p[2], p[0]) } else { (p[0], p[2]) };
                (u32::from(r) << 16) | (u32::from(p[1]) << 8) | u32::from(b)
            })
        })
        .collect()
}

/// A 7 × 5 image over the whole range: exact table entries, values between them, out of
/// range, NaN.
fn known_image() -> Vec<[f32; 4]> {
    let specials = [0.0, 1.0, 2.0, -1.0, f32::NAN, 0.5, 0.0031308, 0.04, 1e-6];
    (0..35)
        .map(|i| {
            let v = |k: usize| {
                let j = (i * 3 + k) % 47;
                if j < specials.len() {
                    specials[j]
                } else {
                    // Table entries and points between them.
                    (j * 89 % 4096) as f32 / 4095.0 + (k as f32) * 1.7e-5
                }
            };
            [v(0), v(1), v(2), 0.5]
        })
        .collect()
}

/// The CPU path: blit and panel, as the window's softbuffer shows them.
fn cpu(
    pixels: &[[f32; 4]],
    (iw, ih): (usize, usize),
    (tw, th): (usize, usize),
    panel: Option<&[(String, u32)]>,
    orientation: Option<&Orientation>,
) -> Vec<u32> {
    let mut out = vec![0u32; tw * th];
    let mut canvas = Canvas {
        pixels: &mut out,
        width: tw,
        height: th,
    };
    canvas.blit(pixels, iw, ih, &SrgbTable::default());
    if let Some(lines) = panel {
        canvas.panel(lines, 1);
    }
    if let Some(o) = orientation {
        canvas.orientation(o, 1);
    }
    out
}

/// Asserts `got` equals `want`, naming the first pixels that differ (`0x00RRGGBB`).
fn assert_same(got: &[u32], want: &[u32], width: usize, label: &str) {
    assert_eq!(got.len(), want.len(), "{label}");
    let differ: Vec<String> = got
        .iter()
        .zip(want)
        .enumerate()
        .filter(|(_, (g, w))| g != w)
        .map(|(i, (g, w))| format!("({}, {}): {g:06x} not {w:06x}", i % width, i / width))
        .collect();
    assert!(
        differ.is_empty(),
        "{label}: {} pixels differ from the CPU path, first {:?}",
        differ.len(),
        &differ[..differ.len().min(4)]
    );
}

#[test]
fn the_present_pass_shows_the_bytes_of_the_cpu_path() {
    let gpu = gpu();
    let image = known_image();
    let lines = vec![
        ("frame 7".to_string(), 0x00ff_ffff),
        ("Ab".to_string(), 0x0012_3456),
    ];
    let (pw, ph) = panel_size(&lines, 1);
    assert_eq!((pw, ph), (64, 26));
    // The table is the CPU's: 0.5 is 188, as `SrgbTable` says.
    assert_eq!(srgb_table()[2048], 188);
    for format in [
        wgpu::TextureFormat::Rgba8UnormSrgb,
        wgpu::TextureFormat::Rgba8Unorm,
        wgpu::TextureFormat::Bgra8UnormSrgb,
        wgpu::TextureFormat::Bgra8Unorm,
    ] {
        let mut presenter = Presenter::new(gpu, format).unwrap();
        // Scaled up, unevenly, and 1:1.
        for (tw, th) in [(75u32, 31u32), (7, 5)] {
            let want = cpu(&image, (7, 5), (tw as usize, th as usize), None, None);
            let got = present(gpu, &presenter, &image, (7, 5), (tw, th));
            assert_same(&got, &want, tw as usize, &format!("{format:?} {tw}x{th}"));
        }
        // With the panel: text in its colour, the rest darkened to a quarter.
        let (w, h, rgba) = panel_rgba(&lines, 1);
        presenter.set_panel(gpu, w, h, &rgba).unwrap();
        let want = cpu(&image, (7, 5), (75, 31), Some(&lines), None);
        let got = present(gpu, &presenter, &image, (7, 5), (75, 31));
        assert_same(&got, &want, 75, &format!("{format:?} with the panel"));
        assert!(got.contains(&0x0012_3456) && got.contains(&0x00ff_ffff));
        // With the orientation strip too: the scale bar and axes along the bottom edge, the
        // image showing through around them; set twice at one size (the texture rewritten).
        let camera = Camera {
            eye: [3.0, -4.0, -20.0],
            target: [0.0; 3],
            up: [0.0, -1.0, 0.0],
            fov_y_degrees: 30.0,
        };
        let (tw, th) = (160usize, 120usize);
        for eye_x in [9.0, 3.0] {
            let camera = Camera {
                eye: [eye_x, -4.0, -20.0],
                ..camera.clone()
            };
            let o = Orientation::of(&camera, th as f64, Some("micrometer")).unwrap();
            let (w, h, rgba) = orientation_rgba(&o, tw, 1);
            assert_eq!((w, h), (tw as u32, ORIENTATION_HEIGHT as u32));
            presenter.set_footer(gpu, w, h, &rgba).unwrap();
            let want = cpu(&image, (7, 5), (tw, th), Some(&lines), Some(&o));
            let got = present(gpu, &presenter, &image, (7, 5), (tw as u32, th as u32));
            assert_same(&got, &want, tw, &format!("{format:?} with the orientation"));
            // The axes' colours and the white scale bar are there, under the panel's rows.
            let strip = &got[(th - ORIENTATION_HEIGHT) * tw..];
            for colour in [0x00ff_5555, 0x0055_ff55, 0x0055_99ff, 0x00ff_ffff, 0] {
                assert!(strip.contains(&colour), "{colour:06x} not drawn");
            }
        }
        presenter.clear_footer(gpu);
        presenter.clear_panel(gpu);
        let want = cpu(&image, (7, 5), (75, 31), None, None);
        let got = present(gpu, &presenter, &image, (7, 5), (75, 31));
        assert_same(&got, &want, 75, &format!("{format:?} without the overlays"));
    }
}

#[test]
fn the_present_pass_refuses_what_it_cannot_draw() {
    let gpu = gpu();
    let err = Presenter::new(gpu, wgpu::TextureFormat::Rgba16Float).unwrap_err();
    assert_eq!(
        err.to_string(),
        "cannot present to a Rgba16Float target (8-bit RGBA or BGRA, sRGB or not, only)"
    );
    assert_eq!(
        surface_format(&[
            wgpu::TextureFormat::Rgba16Float,
            wgpu::TextureFormat::Bgra8Unorm,
            wgpu::TextureFormat::Rgba8UnormSrgb,
        ]),
        Some(wgpu::TextureFormat::Rgba8UnormSrgb)
    );
    assert_eq!(surface_format(&[wgpu::TextureFormat::Rgb10a2Unorm]), None);
    let mut presenter = Presenter::new(gpu, wgpu::TextureFormat::Rgba8Unorm).unwrap();
    assert_eq!(
        presenter.set_panel(gpu, 2, 2, &[0; 15]).unwrap_err(),
        PresentError::Overlay {
            what: "panel",
            bytes: 15,
            width: 2,
            height: 2
        }
    );
    let texture = gpu.device.create_texture(&wgpu::TextureDescriptor {
        label: None,
        size: wgpu::Extent3d {
            width: 4,
            height: 4,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba8Unorm,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
        view_formats: &[],
    });
    let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
    let image = image_buffer(gpu, &[[0.0; 4]; 6]);
    let mut encoder = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
    let err = presenter
        .encode(gpu, &mut encoder, &image, (3, 3), &view, (4, 4))
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        "the image buffer holds 96 bytes, under the 144 of a 3×3 image"
    );
    let err = presenter
        .encode(gpu, &mut encoder, &image, (3, 2), &view, (0, 4))
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        "cannot present a 3×2 image to a 0×4 target: one is empty"
    );
}

fn source() -> Arc<SyntheticSource> {
    Arc::new(SyntheticSource::new(
        SampleType::U8,
        [32, 32, 32],
        [1.0; 3],
        [8; 3],
        4,
        1,
        |_, [x, y, z]| {
            let d = [x as f64 - 14.0, y as f64 - 17.0, z as f64 - 16.0];
            220.0 * (-(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) / 50.0).exp()
        },
    ))
}

fn scene() -> Scene {
    Scene {
        camera: Camera {
            eye: [16.0, 16.0, -50.0],
            target: [16.0, 16.0, 16.0],
            up: [0.0, -1.0, 0.0],
            fov_y_degrees: 40.0,
        },
        channels: vec![ChannelStyle {
            channel: 0,
            visible: true,
            color: [1.0, 0.6, 0.2],
            opacity: vec![
                OpacityPoint {
                    value: 20.0,
                    opacity: 0.0,
                },
                OpacityPoint {
                    value: 220.0,
                    opacity: 0.4,
                },
            ],
        }],
        background: [0.05, 0.0, 0.1],
        filter: Filter::Trilinear,
        mode: residency_viewer::scene::RenderMode::Dvr,
        clip: residency_viewer::scene::Clip::default(),
    }
}

fn options() -> RenderOptions {
    RenderOptions {
        width: 24,
        height: 20,
        level_bounds: vec![(0, 0)],
        ..Default::default()
    }
}

#[test]
fn a_frame_without_pixels_reads_no_image_back_and_leaves_the_same_image_on_the_gpu() {
    let gpu = gpu();
    let src = source();
    let info = src.info().clone();
    // Two renderers given the same bricks: one reads its frames back, one does not.
    let mut with = Renderer::new(gpu, &info, &scene(), options()).unwrap();
    let mut without = Renderer::new(gpu, &info, &scene(), options()).unwrap();
    for round in 0..6 {
        let a = with.render(gpu).unwrap();
        let b = without.render_without_pixels(gpu).unwrap();
        assert_eq!(with.image_readbacks(), round + 1, "one image copy a frame");
        assert_eq!(without.image_readbacks(), 0, "no image copy");
        assert_eq!(a.pixels.len(), 24 * 20);
        assert!(b.pixels.is_empty());
        // The same bricks asked for (in the order the shader's atomics gave).
        let keys = |o: &residency_viewer::gpu::renderer::FrameOutput| {
            let mut k: Vec<_> = o.requests.iter().map(|r| r.key).collect();
            k.sort();
            k
        };
        assert_eq!(keys(&a), keys(&b));
        assert_eq!(a.counts, b.counts);
        // The image left on the GPU is the one `render` read back, bit for bit.
        let on_gpu = buffer_bytes(gpu, without.image_buffer(), 24 * 20 * 16);
        assert_eq!(on_gpu, bytemuck::cast_slice::<[f32; 4], u8>(&a.pixels));
        if a.requests.is_empty() {
            assert!(round > 0, "the first frame has nothing resident");
            assert!(a.pixels.iter().any(|p| p[3] > 0.1), "something drawn");
            return;
        }
        let keys: Vec<_> = a.requests.iter().map(|r| r.key).collect();
        for (key, voxels) in keys.iter().zip(src.fetch(&keys)) {
            let voxels = voxels.unwrap();
            with.insert(gpu, *key, &voxels).unwrap();
            without.insert(gpu, *key, &voxels).unwrap();
        }
    }
    panic!("not converged in 6 frames");
}

/// Steps until idle.
fn settle(s: &mut Session) {
    for _ in 0..500 {
        if s.step(Duration::from_millis(20)).unwrap() == Step::Idle {
            return;
        }
    }
    panic!("no convergence after 500 steps: {}", s.status());
}

#[test]
fn the_session_on_the_gpu_shows_the_image_it_reads_back_on_the_cpu() {
    let mut cpu_mode = Session::new(new_gpu(), source(), scene(), options(), 2, 4);
    let mut gpu_mode = Session::new(new_gpu(), source(), scene(), options(), 2, 4);
    gpu_mode.set_read_pixels(false);
    assert!(gpu_mode.gpu_image().is_none(), "no frame yet");
    settle(&mut cpu_mode);
    settle(&mut gpu_mode);
    assert_eq!(gpu_mode.status(), "converged");
    let (w, h, pixels) = cpu_mode.image();
    assert_eq!((w, h), (24, 20));
    assert!(gpu_mode.image().2.is_empty(), "nothing read back");
    let (buffer, size) = gpu_mode.gpu_image().unwrap();
    assert_eq!(size, (24, 20));
    let on_gpu = buffer_bytes(gpu_mode.gpu(), buffer, 24 * 20 * 16);
    assert_eq!(on_gpu, bytemuck::cast_slice::<[f32; 4], u8>(pixels));
    // No channel visible: the background, on the GPU too.
    let mut hidden = scene();
    hidden.channels[0].visible = false;
    gpu_mode.set_scene(hidden);
    settle(&mut gpu_mode);
    let (buffer, size) = gpu_mode.gpu_image().unwrap();
    assert_eq!(size, (24, 20));
    let on_gpu = buffer_bytes(gpu_mode.gpu(), buffer, 24 * 20 * 16);
    let bg: Vec<[f32; 4]> = vec![[0.05, 0.0, 0.1, 0.0]; 24 * 20];
    assert_eq!(on_gpu, bytemuck::cast_slice::<[f32; 4], u8>(&bg));
}
