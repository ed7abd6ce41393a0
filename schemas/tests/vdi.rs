//! The VDI file format (`residency_schemas::vdi`): round trips in every format, the layout
//! byte for byte, compositing, and every refusal of `decode` and `encode` with its message.

use half::f16;
use residency_schemas::scene::Camera;
use residency_schemas::vdi::{
    ColourFormat, Compression, DepthFormat, MAX_VDI_SLOTS, RayBasis, VDI_MAGIC, VdiError,
    VdiHeader, VolumetricDepthImage,
};

const FILE: &str = "a.vdi";

/// `[r, g, b, a]` as the image holds it: each value rounded to the nearest half float.
fn half4(colour: [f32; 4]) -> [f16; 4] {
    colour.map(f16::from_f32)
}

fn header(colour: ColourFormat, depth: DepthFormat, compression: Compression) -> VdiHeader {
    VdiHeader {
        version: 1,
        width: 3,
        height: 2,
        supersegments: 4,
        camera: Camera {
            eye: [0.5, -2.0, 10.0],
            target: [0.5, 0.5, 0.5],
            up: [0.0, -1.0, 0.0],
            fov_y_degrees: 30.0,
        },
        rays: RayBasis {
            forward: [0.0, 0.0, -1.0],
            right: [0.4, 0.0, 0.0],
            up: [0.0, 0.27, 0.0],
        },
        view: std::array::from_fn(|i| if i % 5 == 0 { 1.0 } else { 0.0 }),
        projection: std::array::from_fn(|i| i as f32 * 0.125),
        near: 1.0,
        far: 9.0,
        volume_min: [0.0, 0.0, 0.0],
        volume_max: [1.0, 2.0, 3.0],
        background: [0.25, 0.5, 1.0],
        channels: 2,
        colour,
        depth,
        compression,
        scene_hash: "0123456789abcdef".into(),
        dataset: Some("kingsnake".into()),
    }
}

/// Lists of 2, 0, 4 / 1, 3, 1 supersegments with colours rounded to half floats from values
/// that f16 cannot hold exactly, and depths between `near` and `far`.
fn sample(
    colour: ColourFormat,
    depth: DepthFormat,
    compression: Compression,
) -> VolumetricDepthImage {
    let mut image = VolumetricDepthImage::new(header(colour, depth, compression));
    image.counts = vec![2, 0, 4, 1, 3, 1];
    for (i, &count) in image.counts.clone().iter().enumerate() {
        for s in 0..usize::from(count) {
            let a = 0.1 + 0.2 * s as f32 + 0.01 * i as f32;
            let tint = [0.3 + 0.1 * i as f32, 0.77, 0.123];
            image
                .colour
                .push(half4([a * tint[0], a * tint[1], a * tint[2], a]));
            let front = 1.0 + 0.37 * (i + 1) as f32 + 0.9 * s as f32;
            image.depth.push([front, front + 0.41]);
        }
    }
    image
}

/// Every colour format, depth format and compression, each with each.
fn every_format() -> impl Iterator<Item = (ColourFormat, DepthFormat, Compression)> {
    [ColourFormat::F16, ColourFormat::F32]
        .into_iter()
        .flat_map(|colour| {
            [DepthFormat::F32, DepthFormat::U16]
                .into_iter()
                .flat_map(move |depth| {
                    [
                        Compression::Lz4,
                        Compression::None,
                        Compression::ShuffledLz4,
                        Compression::ShuffledZstd,
                    ]
                    .map(|compression| (colour, depth, compression))
                })
        })
}

/// Where the planes start: after the magic, the header length and the header.
fn planes_start(bytes: &[u8]) -> usize {
    12 + u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize
}

/// `bytes` with its header JSON text replaced by `edit` of it (the planes kept).
fn with_header(bytes: &[u8], edit: impl FnOnce(&str) -> String) -> Vec<u8> {
    let start = planes_start(bytes);
    let json = edit(std::str::from_utf8(&bytes[12..start]).unwrap());
    let mut out = VDI_MAGIC.to_vec();
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(json.as_bytes());
    out.extend_from_slice(&bytes[start..]);
    out
}

fn refusal(bytes: &[u8]) -> String {
    VolumetricDepthImage::decode(bytes, FILE)
        .unwrap_err()
        .to_string()
}

fn plain() -> Vec<u8> {
    sample(ColourFormat::F32, DepthFormat::F32, Compression::None)
        .encode()
        .unwrap()
}

#[test]
fn every_format_round_trips_within_its_precision() {
    for (colour, depth, compression) in every_format() {
        let image = sample(colour, depth, compression);
        let bytes = image.encode().unwrap();
        let back = VolumetricDepthImage::decode(&bytes, FILE).unwrap();
        let case = format!("{colour:?} {depth:?} {compression:?}");
        assert_eq!(back.header, image.header, "{case}");
        assert_eq!(back.counts, image.counts, "{case}");
        assert_eq!((back.colour.len(), back.depth.len()), (11, 11), "{case}");
        assert_eq!(back.starts(), [0, 2, 2, 6, 7, 10, 11], "{case}");
        // The image holds half floats, which both colour formats store exactly.
        for (i, (b, a)) in back.colour.iter().zip(&image.colour).enumerate() {
            assert_eq!(b.map(f16::to_bits), a.map(f16::to_bits), "{case} slot {i}");
        }
        let step = (9.0 - 1.0) / 65535.0;
        for (b, a) in back.depth.iter().zip(&image.depth) {
            for (&b, &a) in b.iter().zip(a) {
                match depth {
                    DepthFormat::F32 => assert_eq!(b.to_bits(), a.to_bits(), "{case}"),
                    DepthFormat::U16 => assert!(
                        f64::from((b - a).abs()) <= step / 2.0 + f64::from(a) * 1e-7,
                        "{case} {a} {b}"
                    ),
                }
            }
        }
        // A second trip changes nothing.
        let again = VolumetricDepthImage::decode(&back.encode().unwrap(), FILE).unwrap();
        assert_eq!(again, back, "{case}");
    }
}

/// LZ4 pays off on sparse lists: 30,000 counts, nearly all zero, take a few dozen bytes,
/// behind the announced raw length.
#[test]
fn lz4_planes_are_smaller_and_size_prepended() {
    let mut image = sample(ColourFormat::F32, DepthFormat::F32, Compression::Lz4);
    image.header.width = 300;
    image.header.height = 100;
    let mut big = VolumetricDepthImage::new(image.header.clone());
    big.counts[..6].copy_from_slice(&image.counts);
    big.colour.clone_from(&image.colour);
    big.depth.clone_from(&image.depth);
    let lz4 = big.encode().unwrap();
    big.header.compression = Compression::None;
    let raw = big.encode().unwrap();
    let start = planes_start(&lz4);
    let counts_stored = u64::from_le_bytes(lz4[start..start + 8].try_into().unwrap());
    assert!(counts_stored < 200, "{counts_stored}");
    let announced = u32::from_le_bytes(lz4[start + 8..start + 12].try_into().unwrap());
    assert_eq!(announced, 30000);
    let start = planes_start(&raw);
    let raw_counts = u64::from_le_bytes(raw[start..start + 8].try_into().unwrap());
    assert_eq!(raw_counts, 30000);
    assert!(lz4.len() < raw.len(), "{} {}", lz4.len(), raw.len());
}

/// The layout of the module documentation, byte for byte, on a one-pixel image.
#[test]
fn the_layout_is_as_documented() {
    let mut h = header(ColourFormat::F32, DepthFormat::F32, Compression::None);
    h.width = 1;
    h.height = 1;
    h.supersegments = 2;
    h.dataset = None;
    let mut image = VolumetricDepthImage::new(h.clone());
    image.counts[0] = 1;
    image.colour.push(half4([0.25, 0.5, 0.125, 0.75]));
    image.depth.push([2.0, 3.5]);
    let json = serde_json::to_vec(&h).unwrap();
    assert!(!String::from_utf8_lossy(&json).contains("dataset"));
    let mut expected = b"RESVDI\0\x01".to_vec();
    expected.extend_from_slice(&(json.len() as u32).to_le_bytes());
    expected.extend_from_slice(&json);
    expected.extend_from_slice(&1u64.to_le_bytes());
    expected.push(1);
    expected.extend_from_slice(&16u64.to_le_bytes());
    for v in [0.25f32, 0.5, 0.125, 0.75] {
        expected.extend_from_slice(&v.to_le_bytes());
    }
    expected.extend_from_slice(&8u64.to_le_bytes());
    for v in [2.0f32, 3.5] {
        expected.extend_from_slice(&v.to_le_bytes());
    }
    assert_eq!(image.encode().unwrap(), expected);

    // The same in f16 and u16: 8 and 4 bytes a slot.
    image.header.colour = ColourFormat::F16;
    image.header.depth = DepthFormat::U16;
    let bytes = image.encode().unwrap();
    let tail = &bytes[planes_start(&bytes)..];
    let mut planes = 1u64.to_le_bytes().to_vec();
    planes.push(1);
    planes.extend_from_slice(&8u64.to_le_bytes());
    for v in [0.25f32, 0.5, 0.125, 0.75] {
        planes.extend_from_slice(&f16::from_f32(v).to_le_bytes());
    }
    planes.extend_from_slice(&4u64.to_le_bytes());
    // (2 − 1)/8·65535 = 8191.875 and (3.5 − 1)/8·65535 = 20479.6875, rounded.
    planes.extend_from_slice(&8192u16.to_le_bytes());
    planes.extend_from_slice(&20480u16.to_le_bytes());
    assert_eq!(tail, planes);
    let back = VolumetricDepthImage::decode(&bytes, FILE).unwrap();
    let depth = |q: f64| (1.0 + q / 65535.0 * 8.0) as f32;
    assert_eq!(back.depth[0], [depth(8192.0), depth(20480.0)]);
}

#[test]
fn composite_blends_front_to_back_over_the_background() {
    let mut image = VolumetricDepthImage::new(header(
        ColourFormat::F32,
        DepthFormat::F32,
        Compression::None,
    ));
    image.counts[4] = 2;
    image.colour = vec![
        half4([0.25, 0.5, 0.125, 0.5]),
        half4([0.5, 0.25, 0.75, 0.75]),
    ];
    image.depth = vec![[1.0, 2.0], [2.5, 4.0]];
    // rgb = c0 + 0.5·c1 + 0.5·0.25·background, a = 1 − 0.5·0.25.
    assert_eq!(image.composite(1, 1), [0.53125, 0.6875, 0.625, 0.875]);
    assert_eq!(image.composite(0, 0), [0.25, 0.5, 1.0, 0.0]);
    let (colour, depth) = image.list(1, 1);
    assert_eq!(
        colour,
        [
            half4([0.25, 0.5, 0.125, 0.5]),
            half4([0.5, 0.25, 0.75, 0.75])
        ]
    );
    assert_eq!(depth, [[1.0, 2.0], [2.5, 4.0]]);
    assert_eq!(image.list(2, 1), (&[][..], &[][..]));
    // In one pass, the same lists and composites.
    let lists: Vec<_> = image.lists().collect();
    assert_eq!(lists.len(), 6);
    for (i, list) in lists.iter().enumerate() {
        let (x, y) = (i as u32 % 3, i as u32 / 3);
        assert_eq!(*list, image.list(x, y), "list {i}");
        assert_eq!(
            image.composite_list(list.0),
            image.composite(x, y),
            "list {i}"
        );
    }
    assert_eq!(image.starts(), [0, 0, 0, 0, 0, 2, 2]);
}

#[test]
fn bad_magic_is_refused() {
    let mut bytes = plain();
    bytes[7] = 2;
    assert_eq!(refusal(&bytes), "a.vdi: not a VDI (bad magic)");
    assert_eq!(refusal(b"RESV"), "a.vdi: not a VDI (bad magic)");
    assert_eq!(refusal(b""), "a.vdi: not a VDI (bad magic)");
}

#[test]
fn other_versions_are_refused() {
    let bytes = with_header(&plain(), |j| j.replace("\"version\":1", "\"version\":7"));
    assert_eq!(
        refusal(&bytes),
        "a.vdi: VDI version 7 is not supported (this build reads 1)"
    );
}

#[test]
fn every_truncation_is_refused() {
    for bytes in [
        plain(),
        sample(ColourFormat::F16, DepthFormat::U16, Compression::Lz4)
            .encode()
            .unwrap(),
        sample(
            ColourFormat::F16,
            DepthFormat::F32,
            Compression::ShuffledZstd,
        )
        .encode()
        .unwrap(),
    ] {
        for end in 0..bytes.len() {
            assert!(VolumetricDepthImage::decode(&bytes[..end], FILE).is_err());
        }
    }
    let bytes = plain();
    // 11 used slots of 8 bytes of f32 depth.
    assert_eq!(
        refusal(&bytes[..bytes.len() - 1]),
        "a.vdi: truncated: the depth plane needs 88 bytes, only 87 remain"
    );
    assert_eq!(
        refusal(&bytes[..10]),
        "a.vdi: truncated: the header length needs 4 bytes, only 2 remain"
    );
    let start = planes_start(&bytes);
    assert_eq!(
        refusal(&bytes[..start - 1]),
        format!(
            "a.vdi: truncated: the header needs {} bytes, only {} remain",
            start - 12,
            start - 13
        )
    );
    assert_eq!(
        refusal(&bytes[..start + 3]),
        "a.vdi: truncated: the length of the counts plane needs 8 bytes, only 3 remain"
    );
}

#[test]
fn an_lz4_size_other_than_implied_is_refused_before_decompressing() {
    let bytes = sample(ColourFormat::F32, DepthFormat::F32, Compression::Lz4)
        .encode()
        .unwrap();
    let prefix = planes_start(&bytes) + 8;
    for (announced, text) in [(7u32, "7"), (u32::MAX, "4294967295")] {
        let mut bad = bytes.clone();
        bad[prefix..prefix + 4].copy_from_slice(&announced.to_le_bytes());
        assert_eq!(
            refusal(&bad),
            format!(
                "a.vdi: the counts plane announces {text} bytes decompressed, the header and \
                 counts imply 6"
            )
        );
    }
    // A block that does not decompress keeps the decoder's error as its source.
    let mut bad = bytes.clone();
    let counts_stored = u64::from_le_bytes(bytes[prefix - 8..prefix].try_into().unwrap());
    for b in &mut bad[prefix + 4..prefix + counts_stored as usize] {
        *b = 0xff;
    }
    let error = VolumetricDepthImage::decode(&bad, FILE).unwrap_err();
    assert!(
        matches!(
            error,
            VdiError::Lz4 {
                plane: "counts",
                ..
            }
        ),
        "{error:?}"
    );
    assert_eq!(
        error.to_string(),
        "a.vdi: the counts plane does not decompress"
    );
    assert!(std::error::Error::source(&error).is_some());
}

/// `bytes` with plane `index` (0 counts, 1 colour, 2 depth; its length and stored bytes)
/// replaced by `stored`.
fn with_plane(bytes: &[u8], index: usize, stored: &[u8]) -> Vec<u8> {
    let length = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap()) as usize;
    let mut start = planes_start(bytes);
    for _ in 0..index {
        start += 8 + length(start);
    }
    let old = length(start);
    let mut out = bytes[..start].to_vec();
    out.extend_from_slice(&(stored.len() as u64).to_le_bytes());
    out.extend_from_slice(stored);
    out.extend_from_slice(&bytes[start + 8 + old..]);
    out
}

/// A `shuffled_zstd` plane is one zstd frame of level 3 whose header announces the raw length:
/// checked before decompressing, as is that nothing follows the frame.
#[test]
fn a_zstd_plane_is_one_frame_that_announces_the_implied_size() {
    let image = sample(
        ColourFormat::F16,
        DepthFormat::F32,
        Compression::ShuffledZstd,
    );
    let bytes = image.encode().unwrap();
    let start = planes_start(&bytes);
    let stored = u64::from_le_bytes(bytes[start..start + 8].try_into().unwrap()) as usize;
    let frame = &bytes[start + 8..start + 8 + stored];
    // The six counts of the sample, each one byte (so the shuffle keeps them as they are).
    assert_eq!(frame, zstd::bulk::compress(&image.counts, 3).unwrap());
    assert_eq!(frame[..4], [0x28, 0xb5, 0x2f, 0xfd]);
    assert_eq!(
        zstd::zstd_safe::get_frame_content_size(frame).ok(),
        Some(Some(6))
    );
    assert_eq!(VolumetricDepthImage::decode(&bytes, FILE).unwrap(), image);

    let seven = zstd::bulk::compress(&[0; 7], 3).unwrap();
    assert_eq!(
        refusal(&with_plane(&bytes, 0, &seven)),
        "a.vdi: the counts plane announces 7 bytes decompressed, the header and counts imply 6"
    );
    let sizeless = zstd::stream::encode_all(&image.counts[..], 3).unwrap();
    assert_eq!(
        zstd::bulk::decompress(&sizeless, 6).unwrap(),
        image.counts,
        "a valid frame but for its size"
    );
    assert_eq!(
        refusal(&with_plane(&bytes, 0, &sizeless)),
        "a.vdi: the counts plane is not a zstd frame of known size: its frame header does not \
         announce its size"
    );
    assert_eq!(
        refusal(&with_plane(
            &bytes,
            0,
            &lz4_flex::block::compress_prepend_size(&image.counts)
        )),
        "a.vdi: the counts plane is not a zstd frame of known size: it does not begin with \
         zstd's magic number"
    );
    // A skippable frame (magic 0x184D2A50, 4 bytes of length, then that many bytes) reads as
    // content size 0 in zstd: refused by its magic even where the plane is empty.
    let mut empty = VolumetricDepthImage::new(image.header.clone());
    empty.header.width = 1;
    empty.header.height = 1;
    empty.counts = vec![0];
    let empty_bytes = empty.encode().unwrap();
    let skippable = [0x50, 0x2a, 0x4d, 0x18, 3, 0, 0, 0, 1, 2, 3];
    assert_eq!(
        zstd::zstd_safe::get_frame_content_size(&skippable).ok(),
        Some(Some(0))
    );
    assert_eq!(
        refusal(&with_plane(&empty_bytes, 1, &skippable)),
        "a.vdi: the colour plane is not a zstd frame of known size: it does not begin with \
         zstd's magic number"
    );
    // A standard frame whose header is cut short.
    assert_eq!(
        refusal(&with_plane(&bytes, 0, &frame[..5])),
        "a.vdi: the counts plane is not a zstd frame of known size: its frame header is not a \
         zstd frame header"
    );
    let mut two = frame.to_vec();
    two.extend_from_slice(&zstd::bulk::compress(&[], 3).unwrap());
    assert_eq!(
        refusal(&with_plane(&bytes, 0, &two)),
        "a.vdi: the counts plane is not a zstd frame of known size: it is not exactly one whole \
         zstd frame"
    );
    // The frame's header (magic, a descriptor of a single segment, one byte of size: 6), then
    // one last raw block of 5 bytes: a whole frame, whose content falls short of its header.
    // The decoder's error is kept as the source.
    assert_eq!(frame[4..6], [0x20, 6]);
    let mut bad = frame[..6].to_vec();
    bad.extend_from_slice(&[1 | 5 << 3, 0, 0, 1, 2, 3, 4, 5]);
    assert_eq!(
        zstd::zstd_safe::find_frame_compressed_size(&bad).ok(),
        Some(bad.len())
    );
    let error = VolumetricDepthImage::decode(&with_plane(&bytes, 0, &bad), FILE).unwrap_err();
    assert!(
        matches!(
            error,
            VdiError::Zstd {
                plane: "counts",
                ..
            }
        ),
        "{error:?}"
    );
    assert_eq!(
        error.to_string(),
        "a.vdi: the counts plane does not decompress"
    );
    assert!(std::error::Error::source(&error).is_some());
}

#[test]
fn a_raw_plane_of_another_size_is_refused() {
    let mut bytes = plain();
    let start = planes_start(&bytes);
    bytes[start..start + 8].copy_from_slice(&5u64.to_le_bytes());
    assert_eq!(
        refusal(&bytes),
        "a.vdi: the counts plane holds 5 bytes, the header and counts imply 6"
    );
}

#[test]
fn a_count_above_n_s_is_refused() {
    let mut bytes = plain();
    let start = planes_start(&bytes);
    bytes[start + 8 + 4] = 25;
    assert_eq!(
        refusal(&bytes),
        "a.vdi: list (1, 1) has 25 supersegments, more than the header's 4"
    );
}

#[test]
fn front_beyond_back_is_refused() {
    let mut bytes = plain();
    let end = bytes.len();
    // The last used slot is list (2, 1)'s first: front 1 + 0.37·6, back 0.41 further.
    bytes[end - 8..end - 4].copy_from_slice(&4.0f32.to_le_bytes());
    bytes[end - 4..].copy_from_slice(&3.5f32.to_le_bytes());
    assert_eq!(
        refusal(&bytes),
        "a.vdi: list (2, 1) supersegment 0 has front 4 and back 3.5, not 0 ≤ front ≤ back"
    );
    bytes[end - 8..end - 4].copy_from_slice(&(-1.0f32).to_le_bytes());
    assert_eq!(
        refusal(&bytes),
        "a.vdi: list (2, 1) supersegment 0 has front -1 and back 3.5, not 0 ≤ front ≤ back"
    );
}

#[test]
fn a_supersegment_before_the_end_of_the_one_before_it_is_refused() {
    let mut bytes = plain();
    let end = bytes.len();
    // List (1, 1) holds slots 7, 8 and 9 of 11 (8 bytes each, the depth plane last): its
    // second supersegment made to begin before its first ends.
    let slot = |k: usize| end - (11 - k) * 8;
    let back0 = f32::from_le_bytes(bytes[slot(7) + 4..slot(7) + 8].try_into().unwrap());
    let front = back0 - 0.25;
    bytes[slot(8)..slot(8) + 4].copy_from_slice(&front.to_le_bytes());
    let error = VolumetricDepthImage::decode(&bytes, FILE).unwrap_err();
    assert!(
        matches!(error, VdiError::ListOrder { slot: 1, .. }),
        "{error:?}"
    );
    assert_eq!(
        error.to_string(),
        format!(
            "a.vdi: list (1, 1) supersegment 1 begins at {front}, before supersegment 0 ends at \
             {back0}: a list's supersegments must follow each other front to back"
        )
    );
    // Touching is following: a supersegment may begin where the one before it ends.
    bytes[slot(8)..slot(8) + 4].copy_from_slice(&back0.to_le_bytes());
    let image = VolumetricDepthImage::decode(&bytes, FILE).unwrap();
    assert_eq!(image.depth[8][0], back0);
    // Encoding refuses it too.
    let mut image = sample(ColourFormat::F32, DepthFormat::F32, Compression::None);
    image.depth[9][0] = image.depth[8][1] - 0.5;
    assert_eq!(
        image.encode().unwrap_err().to_string(),
        format!(
            "VDI to encode: list (1, 1) supersegment 2 begins at {}, before supersegment 1 ends \
             at {}: a list's supersegments must follow each other front to back",
            image.depth[9][0], image.depth[8][1]
        )
    );
}

#[test]
fn trailing_bytes_are_refused() {
    let mut bytes = plain();
    bytes.extend_from_slice(&[0, 0, 0]);
    assert_eq!(refusal(&bytes), "a.vdi: 3 bytes follow the depth plane");
}

#[test]
fn unknown_header_fields_are_refused() {
    let bytes = with_header(&plain(), |j| j.replacen('{', "{\"extra\":1,", 1));
    let error = VolumetricDepthImage::decode(&bytes, FILE).unwrap_err();
    assert_eq!(
        error.to_string(),
        "a.vdi: bad VDI header: unknown field `extra`, expected one of `version`, `width`, \
         `height`, `supersegments`, `camera`, `rays`, `view`, `projection`, `near`, `far`, \
         `volume_min`, `volume_max`, `background`, `channels`, `colour`, `depth`, \
         `compression`, `scene_hash`, `dataset` at line 1 column 8"
    );
    assert!(std::error::Error::source(&error).is_some());
}

#[test]
fn non_finite_and_out_of_range_values_are_refused() {
    let bytes = plain();
    // The colour plane starts after the counts plane (8 + 6 bytes) and its own length.
    let colour = planes_start(&bytes) + 14 + 8;
    let mut bad = bytes.clone();
    bad[colour..colour + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    assert_eq!(
        refusal(&bad),
        "a.vdi: list (0, 0) supersegment 0 has a non-finite colour"
    );
    // An f32 colour is held as the nearest half float and checked there: from 65520 on it is
    // infinite, and refused; below, it is rounded (65519 to f16's largest, 65504); an opacity
    // up to 2⁻¹¹ above 1 rounds to 1, and a colour down to −2⁻²⁵ to −0, both accepted.
    let at = |bytes: &[u8], offset: usize, value: f32| {
        let mut edited = bytes.to_vec();
        edited[colour + offset..colour + offset + 4].copy_from_slice(&value.to_le_bytes());
        edited
    };
    assert_eq!(
        refusal(&at(&bytes, 4, 65520.0)),
        "a.vdi: list (0, 0) supersegment 0 has a non-finite colour"
    );
    let image = VolumetricDepthImage::decode(&at(&bytes, 4, 65519.0), FILE).unwrap();
    assert_eq!(image.colour[0][1], f16::MAX);
    let image = VolumetricDepthImage::decode(&at(&bytes, 4, 1000.3), FILE).unwrap();
    assert_eq!(image.colour[0][1], f16::from_f32(1000.5));
    let edited = at(&at(&bytes, 12, 1.0 + 2f32.powi(-11)), 0, -(2f32.powi(-25)));
    let image = VolumetricDepthImage::decode(&edited, FILE).unwrap();
    assert_eq!(
        (image.colour[0][3], image.colour[0][0].to_bits()),
        (f16::ONE, 0x8000)
    );
    assert!(
        refusal(&at(&bytes, 12, 1.0 + 2f32.powi(-10)))
            .ends_with(", 1.0009766]: a colour below 0 or an opacity outside [0, 1]")
    );
    let mut bad = bytes.clone();
    bad[colour + 16 + 12..colour + 32].copy_from_slice(&1.5f32.to_le_bytes());
    let message = refusal(&bad);
    assert!(
        message.starts_with("a.vdi: list (0, 0) supersegment 1 has colour and opacity ["),
        "{message}"
    );
    assert!(
        message.ends_with(", 1.5]: a colour below 0 or an opacity outside [0, 1]"),
        "{message}"
    );
    let mut bad = bytes.clone();
    let end = bad.len();
    bad[end - 4..].copy_from_slice(&f32::INFINITY.to_le_bytes());
    assert_eq!(
        refusal(&bad),
        "a.vdi: list (2, 1) supersegment 0 has a non-finite depth"
    );
    // JSON has no infinities (an f32 field refuses 1e39), so encode refuses to write one.
    let bad = with_header(&bytes, |j| j.replace("\"far\":9.0", "\"far\":1e39"));
    assert_eq!(
        refusal(&bad),
        "a.vdi: bad VDI header: number out of range at line 1 column 418"
    );
    let mut image = sample(ColourFormat::F32, DepthFormat::F32, Compression::None);
    image.header.far = f32::INFINITY;
    assert_eq!(
        image.encode().unwrap_err().to_string(),
        "VDI to encode: header field near or far is not finite"
    );
}

#[test]
fn headers_out_of_range_are_refused() {
    let bytes = plain();
    let cases = [
        (
            "\"width\":3",
            "\"width\":0",
            "a.vdi: a VDI of 0×2 pixels: it must have 1 to 67108864 pixels",
        ),
        (
            "\"supersegments\":4",
            "\"supersegments\":65",
            "a.vdi: 65 supersegments per list: a VDI has 1 to 64",
        ),
        (
            "\"0123456789abcdef\"",
            "\"0123456789ABCDEF\"",
            "a.vdi: scene hash \"0123456789ABCDEF\" is not 16 lowercase hex digits",
        ),
        (
            "\"fov_y_degrees\":30.0",
            "\"fov_y_degrees\":180.0",
            "a.vdi: header field camera.fov_y_degrees is not in (0, 180)",
        ),
        (
            "\"volume_min\":[0.0,0.0,0.0]",
            "\"volume_min\":[0.0,2.5,0.0]",
            "a.vdi: header field volume_min is above volume_max",
        ),
    ];
    for (from, to, message) in cases {
        let bad = with_header(&bytes, |j| {
            assert!(j.contains(from), "{from}");
            j.replace(from, to)
        });
        assert_eq!(refusal(&bad), message);
    }
    let bad = with_header(&bytes, |j| {
        j.replace("\"width\":3", "\"width\":8192")
            .replace("\"height\":2", "\"height\":8192")
    });
    assert_eq!(
        refusal(&bad),
        format!(
            "a.vdi: 8192×8192 lists of 4 supersegments are 268435456 slots, more than the \
             {MAX_VDI_SLOTS} a VDI may hold"
        )
    );
    let mut bad = bytes.clone();
    bad[8..12].copy_from_slice(&(2u32 << 20).to_le_bytes());
    assert_eq!(
        refusal(&bad),
        "a.vdi: the header is 2097152 bytes long, more than the 1048576 allowed"
    );
    let mut h = header(ColourFormat::F16, DepthFormat::U16, Compression::Lz4);
    h.near = 9.0;
    let image = VolumetricDepthImage::new(h);
    assert_eq!(
        image.encode().unwrap_err().to_string(),
        "VDI to encode: header field near and far are not 0 ≤ near < far with (far − near)/65535 \
         wider than the f32 spacing at far, as u16 depth needs"
    );
}

#[test]
fn encode_refuses_what_decode_would() {
    let good = sample(ColourFormat::F16, DepthFormat::F32, Compression::Lz4);
    let mut image = good.clone();
    image.counts[2] = 5;
    assert_eq!(
        image.encode().unwrap_err().to_string(),
        "VDI to encode: list (2, 0) has 5 supersegments, more than the header's 4"
    );
    let mut image = good.clone();
    image.colour.pop();
    assert_eq!(
        image.encode().unwrap_err().to_string(),
        "VDI to encode: colour has 10 entries, the header and counts imply 11"
    );
    let mut image = good.clone();
    image.colour[3] = half4([0.5, 0.5, 0.5, 1.25]);
    assert_eq!(
        image.encode().unwrap_err().to_string(),
        "VDI to encode: list (2, 0) supersegment 1 has colour and opacity [0.5, 0.5, 0.5, 1.25]: \
         a colour below 0 or an opacity outside [0, 1]"
    );
    // Channels mix additively: a premultiplied colour past 1 is kept.
    let mut image = good.clone();
    image.colour[3] = half4([1.5, 0.5, 2.25, 1.0]);
    let back = VolumetricDepthImage::decode(&image.encode().unwrap(), "a.vdi").unwrap();
    assert_eq!(back.colour[3], half4([1.5, 0.5, 2.25, 1.0]));
    let mut image = good.clone();
    image.colour[3] = half4([-0.25, 0.5, 0.5, 1.0]);
    assert_eq!(
        image.encode().unwrap_err().to_string(),
        "VDI to encode: list (2, 0) supersegment 1 has colour and opacity [-0.25, 0.5, 0.5, 1.0]: \
         a colour below 0 or an opacity outside [0, 1]"
    );
    let mut image = good.clone();
    image.depth[6] = [f32::NAN, 1.0];
    assert_eq!(
        image.encode().unwrap_err().to_string(),
        "VDI to encode: list (0, 1) supersegment 0 has a non-finite depth"
    );
    // A count that the arrays do not hold is refused, not read past.
    let mut image = good.clone();
    image.counts[1] = 1;
    assert_eq!(
        image.encode().unwrap_err().to_string(),
        "VDI to encode: colour has 11 entries, the header and counts imply 12"
    );
}

/// The file as the module documentation lays it out, written one slot after the other: the
/// reference the parallel encoder must match byte for byte.
fn reference_encoding(image: &VolumetricDepthImage) -> Vec<u8> {
    let h = &image.header;
    let (mut colour, mut depth) = (Vec::new(), Vec::new());
    for (c, d) in image.colour.iter().zip(&image.depth) {
        for &v in c {
            match h.colour {
                ColourFormat::F16 => colour.extend_from_slice(&v.to_le_bytes()),
                ColourFormat::F32 => colour.extend_from_slice(&v.to_f32().to_le_bytes()),
            }
        }
        for &v in d {
            match h.depth {
                DepthFormat::F32 => depth.extend_from_slice(&v.to_le_bytes()),
                DepthFormat::U16 => {
                    let t =
                        (f64::from(v) - f64::from(h.near)) / (f64::from(h.far) - f64::from(h.near));
                    let q = (t * 65535.0).round().clamp(0.0, 65535.0) as u16;
                    depth.extend_from_slice(&q.to_le_bytes());
                }
            }
        }
    }
    let shuffled = |raw: &[u8], width: usize| {
        let n = raw.len() / width;
        let mut shuffled = vec![0; raw.len()];
        for (i, value) in raw.chunks_exact(width).enumerate() {
            for (b, &byte) in value.iter().enumerate() {
                shuffled[b * n + i] = byte;
            }
        }
        shuffled
    };
    let plane = |raw: &[u8], width: usize| match h.compression {
        Compression::None => raw.to_vec(),
        Compression::Lz4 => lz4_flex::block::compress_prepend_size(raw),
        Compression::ShuffledLz4 => lz4_flex::block::compress_prepend_size(&shuffled(raw, width)),
        Compression::ShuffledZstd => zstd::bulk::compress(&shuffled(raw, width), 3).unwrap(),
    };
    let json = serde_json::to_vec(h).unwrap();
    let mut out = VDI_MAGIC.to_vec();
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(&json);
    let colour_width = if h.colour == ColourFormat::F16 { 2 } else { 4 };
    let depth_width = if h.depth == DepthFormat::U16 { 2 } else { 4 };
    for p in [
        plane(&image.counts, 1),
        plane(&colour, colour_width),
        plane(&depth, depth_width),
    ] {
        out.extend_from_slice(&(p.len() as u64).to_le_bytes());
        out.extend_from_slice(&p);
    }
    out
}

/// `encode` and `decode` check and convert bands of 16 rows of lists in parallel, yet
/// `encode` writes the bytes a slot-by-slot encoder writes, in every format, `decode` reads
/// back every slot where the file put it, and both refuse with the first bad slot in the
/// file's order.
#[test]
fn bands_encode_and_decode_the_files_bytes_and_name_the_first_bad_slot() {
    let mut h = header(ColourFormat::F16, DepthFormat::F32, Compression::None);
    h.height = 40;
    let mut good = VolumetricDepthImage::new(h);
    // Every third list empty, so that a list often follows an empty one.
    good.counts = (0..120).map(|i| (i % 3) as u8).collect();
    for (i, &count) in good.counts.clone().iter().enumerate() {
        for s in 0..count {
            let a = 0.25 + 0.005 * i as f32 + 0.125 * f32::from(s);
            good.colour
                .push(half4([0.5 * a, 0.25 * a, 0.125 + 0.001 * i as f32, a]));
            let front = 1.0 + 0.05 * i as f32 + f32::from(s);
            good.depth.push([front, front + 0.5]);
        }
    }
    for (colour, depth, compression) in every_format() {
        let mut image = good.clone();
        (image.header.colour, image.header.depth) = (colour, depth);
        image.header.compression = compression;
        let bytes = image.encode().unwrap();
        assert_eq!(
            bytes,
            reference_encoding(&image),
            "{colour:?} {depth:?} {compression:?}"
        );
        let back = VolumetricDepthImage::decode(&bytes, FILE).unwrap();
        assert_eq!(back.counts, image.counts);
        // Every slot read back where the file put it: written again, the same bytes.
        assert_eq!(
            back.encode().unwrap(),
            bytes,
            "{colour:?} {depth:?} {compression:?}"
        );
        // Colour in either format reads back exactly (the image's half floats).
        assert_eq!(
            back.colour, image.colour,
            "{colour:?} {depth:?} {compression:?}"
        );
        if depth == DepthFormat::F32 {
            assert_eq!(back.depth, image.depth);
        }
    }
    // The last slot of band 0 (list (2, 15)) and a slot of band 2 (list (1, 35)).
    let slot_of = |x: usize, y: usize| good.starts()[y * 3 + x];
    let mut image = good.clone();
    image.colour[slot_of(1, 35)][3] = f16::from_f32(2.0);
    let message = image.encode().unwrap_err().to_string();
    assert!(
        message.starts_with("VDI to encode: list (1, 35) supersegment 0 has colour and opacity ["),
        "{message}"
    );
    // The decoder, of files with the same bad slots (written without checks), names the same.
    let mut file_of = image.clone();
    file_of.header.colour = ColourFormat::F32;
    let decoded = VolumetricDepthImage::decode(&reference_encoding(&file_of), FILE);
    let message = decoded.unwrap_err().to_string();
    assert!(
        message.starts_with(&format!(
            "{FILE}: list (1, 35) supersegment 0 has colour and opacity ["
        )),
        "{message}"
    );
    image.depth[slot_of(2, 15) + 1] = [f32::INFINITY, 1.0];
    assert_eq!(
        image.encode().unwrap_err().to_string(),
        "VDI to encode: list (2, 15) supersegment 1 has a non-finite depth"
    );
    for compression in [
        Compression::None,
        Compression::ShuffledLz4,
        Compression::ShuffledZstd,
    ] {
        let mut file_of = image.clone();
        file_of.header.compression = compression;
        let decoded = VolumetricDepthImage::decode(&reference_encoding(&file_of), FILE);
        assert_eq!(
            decoded.unwrap_err().to_string(),
            format!("{FILE}: list (2, 15) supersegment 1 has a non-finite depth")
        );
    }
}
