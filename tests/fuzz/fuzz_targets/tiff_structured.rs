//! The TIFF reader on structured input: a well-formed TIFF (classic or BigTIFF, either byte
//! order, up to 6 pages, striped or tiled, uncompressed or LZW / Deflate / PackBits encoded
//! for real, or JPEG / any other code over garbage) whose tags may lie, with an ImageJ or
//! OME-XML `ImageDescription` built from fuzzed values. Reaches the claims checks, the
//! metadata parsers and the plane reads far more often than raw bytes do.
#![no_main]

use std::io::Write;

use arbitrary::Arbitrary;
use libfuzzer_sys::fuzz_target;
use residency_fuzz::tiffgen::{Entry, Tiff, tag};
use residency_fuzz::{known, planes, scratch};
use residency_ingest::source::TiffSource;

#[derive(Arbitrary, Debug)]
enum Num {
    Small(u8),
    Any(u64),
    Text(String),
}

impl Num {
    fn text(&self) -> String {
        match self {
            Num::Small(v) => v.to_string(),
            Num::Any(v) => v.to_string(),
            Num::Text(t) => t.clone(),
        }
    }
}

#[derive(Arbitrary, Debug)]
struct ImageJ {
    images: Option<Num>,
    channels: Option<Num>,
    slices: Option<Num>,
    frames: Option<Num>,
    spacing: Option<String>,
    unit: Option<String>,
    extra: Vec<(String, String)>,
}

#[derive(Arbitrary, Debug)]
enum Order {
    Xyzct,
    Xyzct2,
    Xyczt,
    Xyctz,
    Xytzc,
    Xytcz,
    Other(String),
}

#[derive(Arbitrary, Debug)]
struct OmeChannel {
    name: Option<String>,
    samples_per_pixel: Option<Num>,
}

#[derive(Arbitrary, Debug)]
struct Ome {
    size_z: Option<Num>,
    size_c: Option<Num>,
    size_t: Option<Num>,
    order: Option<Order>,
    channels: Vec<OmeChannel>,
    physical: [Option<String>; 3],
    unit: Option<String>,
    namespaced: bool,
    escape: bool,
}

#[derive(Arbitrary, Debug)]
enum Description {
    None,
    Text(String),
    ImageJ(ImageJ),
    Ome(Ome),
}

fn xml_attr(out: &mut String, name: &str, value: &str, escape: bool) {
    let v = if escape {
        value
            .replace('&', "&amp;")
            .replace('<', "&lt;")
            .replace('"', "&quot;")
    } else {
        value.to_string()
    };
    out.push_str(&format!(" {name}=\"{v}\""));
}

impl Description {
    fn text(&self) -> Option<String> {
        match self {
            Description::None => None,
            Description::Text(t) => Some(t.clone()),
            Description::ImageJ(ij) => {
                let mut s = String::from("ImageJ=1.54f\n");
                let mut line = |k: &str, v: Option<String>| {
                    if let Some(v) = v {
                        s.push_str(&format!("{k}={v}\n"));
                    }
                };
                line("images", ij.images.as_ref().map(Num::text));
                line("channels", ij.channels.as_ref().map(Num::text));
                line("slices", ij.slices.as_ref().map(Num::text));
                line("frames", ij.frames.as_ref().map(Num::text));
                line("spacing", ij.spacing.clone());
                line("unit", ij.unit.clone());
                for (k, v) in &ij.extra {
                    s.push_str(&format!("{k}={v}\n"));
                }
                Some(s)
            }
            Description::Ome(o) => {
                let mut s = String::from("<?xml version=\"1.0\"?><OME");
                if o.namespaced {
                    s.push_str(" xmlns=\"http://www.openmicroscopy.org/Schemas/OME/2016-06\"");
                }
                s.push_str("><Image ID=\"Image:0\"><Pixels");
                let e = o.escape;
                if let Some(order) = &o.order {
                    let v = match order {
                        Order::Xyzct => "XYZCT".to_string(),
                        Order::Xyzct2 => "XYZTC".to_string(),
                        Order::Xyczt => "XYCZT".to_string(),
                        Order::Xyctz => "XYCTZ".to_string(),
                        Order::Xytzc => "XYTZC".to_string(),
                        Order::Xytcz => "XYTCZ".to_string(),
                        Order::Other(t) => t.clone(),
                    };
                    xml_attr(&mut s, "DimensionOrder", &v, e);
                }
                for (name, v) in [
                    ("SizeZ", &o.size_z),
                    ("SizeC", &o.size_c),
                    ("SizeT", &o.size_t),
                ] {
                    if let Some(v) = v {
                        xml_attr(&mut s, name, &v.text(), e);
                    }
                }
                for (axis, v) in ["Z", "Y", "X"].iter().zip(&o.physical) {
                    if let Some(v) = v {
                        xml_attr(&mut s, &format!("PhysicalSize{axis}"), v, e);
                    }
                }
                if let Some(u) = &o.unit {
                    xml_attr(&mut s, "PhysicalSizeXUnit", u, e);
                }
                s.push('>');
                for (i, ch) in o.channels.iter().take(8).enumerate() {
                    s.push_str(&format!("<Channel ID=\"Channel:0:{i}\""));
                    if let Some(n) = &ch.name {
                        xml_attr(&mut s, "Name", n, e);
                    }
                    if let Some(n) = &ch.samples_per_pixel {
                        xml_attr(&mut s, "SamplesPerPixel", &n.text(), e);
                    }
                    s.push_str("/>");
                }
                s.push_str("</Pixels></Image></OME>");
                Some(s)
            }
        }
    }
}

#[derive(Arbitrary, Debug, Clone, Copy)]
enum Bits {
    U8,
    U16,
    I16,
    U32,
    I32,
    F32,
    Other { bits: u16, format: u16 },
}

impl Bits {
    /// Bits per sample and SampleFormat.
    fn tags(self) -> (u16, u16) {
        match self {
            Bits::U8 => (8, 1),
            Bits::U16 => (16, 1),
            Bits::I16 => (16, 2),
            Bits::U32 => (32, 1),
            Bits::I32 => (32, 2),
            Bits::F32 => (32, 3),
            Bits::Other { bits, format } => (bits, format),
        }
    }
}

#[derive(Arbitrary, Debug, Clone, Copy, PartialEq)]
enum Codec {
    None,
    Lzw,
    Deflate,
    PackBits,
    Jpeg,
    Other(u16),
}

impl Codec {
    fn code(self) -> u16 {
        match self {
            Codec::None => 1,
            Codec::Lzw => 5,
            Codec::Deflate => 8,
            Codec::PackBits => 32773,
            Codec::Jpeg => 7,
            Codec::Other(c) => c,
        }
    }

    /// Encodes a strip or tile, or passes garbage through for codecs without an encoder here.
    fn encode(self, raw: &[u8]) -> Vec<u8> {
        match self {
            Codec::Lzw => weezl::encode::Encoder::with_tiff_size_switch(weezl::BitOrder::Msb, 8)
                .encode(raw)
                .unwrap_or_default(),
            Codec::Deflate => {
                let mut e =
                    flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
                e.write_all(raw).unwrap();
                e.finish().unwrap()
            }
            Codec::PackBits => {
                let mut out = Vec::new();
                for chunk in raw.chunks(128) {
                    out.push((chunk.len() - 1) as u8);
                    out.extend_from_slice(chunk);
                }
                out
            }
            Codec::None | Codec::Jpeg | Codec::Other(_) => raw.to_vec(),
        }
    }
}

#[derive(Arbitrary, Debug)]
struct Page {
    /// Width and height (1 + this % 64; `huge` replaces them in the tags, to test the
    /// claims checks).
    width: u8,
    height: u8,
    huge: Option<(u32, u32)>,
    bits: Bits,
    /// Samples per pixel (1 + this % 8).
    samples: u8,
    planar: Option<u16>,
    photometric: Option<u16>,
    codec: Codec,
    /// Encode the data with the codec (LZW, Deflate, PackBits), or store it as is.
    encode: bool,
    predictor: Option<u16>,
    /// Rows per strip (1 + this), or tiles of `16·(1 + a%4)` × `16·(1 + b%4)`.
    rows_per_strip: u8,
    tiles: Option<(u8, u8)>,
    data: Vec<u8>,
    /// Strip/tile (offset, count) pairs replacing the true ones.
    chunks: Option<Vec<(u32, u32)>>,
    resolution: Option<((u32, u32), (u32, u32))>,
    /// Any other entry: tag, type, count, value bytes.
    extra: Vec<(u16, u16, u32, Vec<u8>)>,
    /// Whether the page carries the description (the first page always may).
    describe: bool,
}

#[derive(Arbitrary, Debug)]
struct Input {
    big_endian: bool,
    bigtiff: bool,
    description: Description,
    pages: Vec<Page>,
}

fn build(input: &Input) -> Vec<u8> {
    let mut t = Tiff::new(input.big_endian, input.bigtiff);
    let description = input.description.text();
    for (i, p) in input.pages.iter().take(6).enumerate() {
        let (bits, format) = p.bits.tags();
        let spp = 1 + (p.samples % 8) as u32;
        let (w, h) = (1 + p.width as u32 % 64, 1 + p.height as u32 % 64);
        // Data sizes follow the tags, but stay small: at most 64-bit samples and 16 KiB of
        // samples per page, so the harness's own encoding never dominates the run time.
        let bytes_per_pixel = (spp as usize * bits.min(64) as usize).div_ceil(8).max(1);
        let h = h.min((16384 / (w as usize * bytes_per_pixel)).max(1) as u32);
        let fill = |n: usize| -> Vec<u8> {
            if p.data.is_empty() {
                vec![0; n]
            } else {
                p.data.iter().copied().cycle().take(n).collect()
            }
        };
        // (chunk rows, chunk columns, chunks) of true data.
        let mut chunk_bytes = Vec::new();
        let tiled = p
            .tiles
            .map(|(a, b)| (16 * (1 + a as u32 % 4), 16 * (1 + b as u32 % 4)));
        match tiled {
            Some((tw, th)) => {
                let n = w.div_ceil(tw) * h.div_ceil(th);
                let tile = (tw as usize * th as usize * bytes_per_pixel).min(16384);
                for _ in 0..n.min(16) {
                    chunk_bytes.push(fill(tile));
                }
            }
            None => {
                let rows = 1 + p.rows_per_strip as u32;
                let mut y = 0;
                while y < h {
                    let r = rows.min(h - y);
                    chunk_bytes.push(fill(r as usize * w as usize * bytes_per_pixel));
                    y += r;
                }
            }
        }
        let mut offsets = Vec::new();
        let mut counts = Vec::new();
        for raw in &chunk_bytes {
            let enc = if p.encode {
                p.codec.encode(raw)
            } else {
                raw.clone()
            };
            offsets.push(t.blob(&enc));
            counts.push(enc.len() as u64);
        }
        if let Some(over) = &p.chunks {
            offsets = over.iter().map(|c| c.0 as u64).collect();
            counts = over.iter().map(|c| c.1 as u64).collect();
        }
        let (w, h) = p.huge.unwrap_or((w, h));
        let mut e: Vec<Entry> = vec![
            t.longs(tag::IMAGE_WIDTH, &[w]),
            t.longs(tag::IMAGE_LENGTH, &[h]),
            t.shorts(tag::BITS_PER_SAMPLE, &vec![bits; spp as usize]),
            t.shorts(tag::COMPRESSION, &[p.codec.code()]),
            t.shorts(
                tag::PHOTOMETRIC,
                &[p.photometric.unwrap_or(if spp >= 3 { 2 } else { 1 })],
            ),
            t.shorts(tag::SAMPLES_PER_PIXEL, &[spp as u16]),
        ];
        if (i == 0 || p.describe)
            && let Some(d) = &description
        {
            e.push(t.ascii(tag::IMAGE_DESCRIPTION, d.as_bytes()));
        }
        match tiled {
            Some((tw, th)) => {
                e.push(t.longs(tag::TILE_WIDTH, &[tw]));
                e.push(t.longs(tag::TILE_LENGTH, &[th]));
                e.push(t.offsets(tag::TILE_OFFSETS, &offsets));
                e.push(t.offsets(tag::TILE_BYTE_COUNTS, &counts));
            }
            None => {
                e.push(t.offsets(tag::STRIP_OFFSETS, &offsets));
                e.push(t.longs(tag::ROWS_PER_STRIP, &[1 + p.rows_per_strip as u32]));
                e.push(t.offsets(tag::STRIP_BYTE_COUNTS, &counts));
            }
        }
        if let Some(((xn, xd), (yn, yd))) = p.resolution {
            e.push(t.rational(tag::X_RESOLUTION, xn, xd));
            e.push(t.rational(tag::Y_RESOLUTION, yn, yd));
        }
        if let Some(pc) = p.planar {
            e.push(t.shorts(tag::PLANAR_CONFIGURATION, &[pc]));
        }
        if let Some(pr) = p.predictor {
            e.push(t.shorts(tag::PREDICTOR, &[pr]));
        }
        e.push(t.shorts(tag::SAMPLE_FORMAT, &vec![format; spp as usize]));
        for (tg, ty, count, bytes) in p.extra.iter().take(4) {
            e.push(Entry {
                tag: *tg,
                ty: *ty,
                count: *count as u64,
                bytes: bytes.clone(),
            });
        }
        e.sort_by_key(|e| e.tag);
        t.ifd(e);
    }
    t.finish()
}

fuzz_target!(|input: Input| {
    if input.pages.is_empty() {
        return;
    }
    let bytes = build(&input);
    let path = scratch::file("structured.tif", &bytes);
    known::guarded(|| {
        if let Ok(mut source) = TiffSource::open(&path) {
            planes::read_all(&mut source);
        }
    });
});
