//! GPU residency pieces on their own: LRU slot allocation driven by usage feedback, brick
//! upload validation, page-table ids, and the transfer-function prefix tables.

use crate::render_common::new_gpu as gpu;
use residency_viewer::gpu::brick_cache::{AtlasKind, BrickCache};
use residency_viewer::gpu::page_table::PageTables;
use residency_viewer::gpu::residency::{RangeClass, range_class};
use residency_viewer::gpu::synthetic::SyntheticSource;
use residency_viewer::octree::OctreeGeometry;
use residency_viewer::scene::{ChannelStyle, OpacityPoint, RenderMode};
use residency_viewer::source::{BrickKey, BrickSource, BrickVoxels, SampleType};

#[test]
fn lru_follows_usage_feedback_and_protects_the_current_frame() {
    let gpu = gpu();
    let mut cache = BrickCache::new(
        &gpu.device,
        &gpu.limits,
        SampleType::U16,
        [8, 8, 8],
        // Three slots of 9³ u16: an 8³ brick and its one-voxel apron.
        3 * 2 * 9 * 9 * 9,
    )
    .unwrap();
    assert_eq!(cache.capacity(), 3);
    assert_eq!(cache.slot_bytes(), 2 * 9 * 9 * 9);
    assert_eq!(cache.kind(), AtlasKind::Uint);
    // Fill at frame 1 (ids 10, 11, 12).
    for id in 10..13 {
        let (slot, evicted) = cache.allocate(1).unwrap();
        assert_eq!(evicted, None);
        cache.assign(slot, id);
        let v = BrickVoxels::U16(vec![id as u16; 512]);
        cache.upload(&gpu.queue, slot, cache.brick_bytes(&v).unwrap());
    }
    // The shader reports slot 1 used last in frame 2, slot 0 in frame 6, slot 2 in frame 7.
    cache.note_usage(&[6, 2, 7]);
    assert_eq!(cache.available(7), 2);
    // Rendering frame 8 next: the least recently used slot goes first.
    assert_eq!(cache.allocate(7), Some((1, Some(11))));
    cache.assign(1, 20);
    assert_eq!(cache.allocate(7), Some((0, Some(10))));
    cache.assign(0, 21);
    // Slot 2 was used in frame 7 and the others were just filled: nothing left to evict.
    assert_eq!(cache.allocate(7), None);
    // Wrong type or size is refused.
    let refused = |v: &BrickVoxels| cache.brick_bytes(v).unwrap_err().to_string();
    assert_eq!(
        refused(&BrickVoxels::U8(vec![0; 512])),
        "brick has 512 samples of the wrong type or count (expected 512 of U16)"
    );
    assert_eq!(
        refused(&BrickVoxels::U16(vec![0; 100])),
        "brick has 100 samples of the wrong type or count (expected 512 of U16)"
    );
    assert_eq!(
        refused(&BrickVoxels::Empty),
        "an empty brick takes no cache slot"
    );
}

#[test]
fn page_table_ids_round_trip() {
    let gpu = gpu();
    let src = SyntheticSource::new(
        SampleType::U8,
        [13, 37, 50],
        [1.0; 3],
        [8; 3],
        4,
        3,
        |_, _| 1.0,
    );
    let info = src.info();
    let geometry = OctreeGeometry::new(info, 3).unwrap();
    let pages = PageTables::new(&gpu.device, &geometry, &[2, 0]).unwrap();
    let mut next = 0;
    for slot_channel in [2u32, 0] {
        for l in 0..info.levels.len() {
            let g = info.brick_grid(l);
            assert_eq!(
                pages.offsets()[usize::from(slot_channel != 2) * info.levels.len() + l],
                next
            );
            for z in 0..g[0] {
                for y in 0..g[1] {
                    for x in 0..g[2] {
                        let key = BrickKey {
                            level: l as u32,
                            channel: slot_channel,
                            brick: [z, y, x],
                        };
                        let id = pages.id(&key).unwrap();
                        assert_eq!(id, next);
                        assert_eq!(pages.key(id), Some(key));
                        next += 1;
                    }
                }
            }
        }
    }
    // Channel 1 is not rendered; bricks outside the grid have no id.
    assert_eq!(
        pages.id(&BrickKey {
            level: 0,
            channel: 1,
            brick: [0, 0, 0]
        }),
        None
    );
    assert_eq!(
        pages.id(&BrickKey {
            level: 0,
            channel: 0,
            brick: [9, 0, 0]
        }),
        None
    );
    assert_eq!(pages.key(next), None);
}

#[test]
fn range_classes_follow_the_exact_transparency_rule() {
    let style = ChannelStyle {
        channel: 0,
        visible: true,
        color: [1.0; 3],
        opacity: vec![
            OpacityPoint {
                value: 0.0,
                opacity: 0.0,
            },
            OpacityPoint {
                value: 40.0,
                opacity: 0.0,
            },
            OpacityPoint {
                value: 60.0,
                opacity: 0.5,
            },
            OpacityPoint {
                value: 80.0,
                opacity: 0.0,
            },
            OpacityPoint {
                value: 100.0,
                opacity: 0.0,
            },
        ],
    };
    let s = Some(&style);
    let class = |empty, constant| RangeClass { empty, constant };
    let cases = [
        (
            (0.0, 40.0),
            class(true, false),
            "zero opacity up to the ramp's foot",
        ),
        ((39.0, 41.0), class(false, false), "reaches into the ramp"),
        (
            (79.0, 100.0),
            class(false, false),
            "still inside the ramp at 79",
        ),
        ((80.0, 1e9), class(true, false), "past the ramp"),
        ((50.0, 50.0), class(false, true), "one visible value"),
        ((90.0, 90.0), class(true, true), "one transparent value"),
        (
            (f32::INFINITY, f32::NEG_INFINITY),
            class(true, false),
            "no data",
        ),
        ((f32::NAN, f32::NAN), class(true, false), "NaN only"),
    ];
    for ((lo, hi), want, why) in cases {
        assert_eq!(range_class(s, RenderMode::Dvr, lo, hi), want, "{why}");
    }
    assert_eq!(
        range_class(None, RenderMode::Dvr, 50.0, 60.0),
        class(true, false),
        "a channel not drawn"
    );
    let hidden = ChannelStyle {
        visible: false,
        ..style.clone()
    };
    assert_eq!(
        range_class(Some(&hidden), RenderMode::Dvr, 50.0, 60.0),
        class(true, false),
        "a hidden channel"
    );
}

#[test]
fn renderer_rejects_bad_setups_with_errors() {
    use residency_viewer::gpu::renderer::{RenderOptions, Renderer};
    use residency_viewer::scene::{Camera, Scene};
    let gpu = gpu();
    let src = SyntheticSource::new(SampleType::U8, [8, 8, 8], [1.0; 3], [8; 3], 4, 1, |_, _| {
        1.0
    });
    let style = |channel| ChannelStyle {
        channel,
        visible: true,
        color: [1.0; 3],
        opacity: vec![OpacityPoint {
            value: 0.0,
            opacity: 0.1,
        }],
    };
    let scene = |channels| Scene {
        camera: Camera {
            eye: [-9.0, 4.0, 4.0],
            target: [4.0; 3],
            up: [0.0, 0.0, 1.0],
            fov_y_degrees: 30.0,
        },
        channels,
        background: [0.0; 3],
        filter: residency_viewer::scene::Filter::Trilinear,
        mode: RenderMode::Dvr,
        clip: residency_viewer::scene::Clip::default(),
    };
    let err = |s: &Scene, o: RenderOptions| {
        residency_viewer::error_chain(&Renderer::new(&gpu, src.info(), s, o).err().unwrap())
    };
    let ok = scene(vec![style(0)]);
    assert!(
        err(
            &ok,
            RenderOptions {
                width: 0,
                ..Default::default()
            }
        )
        .contains("is empty")
    );
    assert!(err(&scene(vec![style(3)]), RenderOptions::default()).contains("no channel 3"));
    assert!(
        err(
            &scene((0..17).map(|_| style(0)).collect()),
            RenderOptions::default()
        )
        .contains("at most 16")
    );
    assert!(
        err(
            &ok,
            RenderOptions {
                cache_bytes: 10,
                ..Default::default()
            }
        )
        .contains("holds no brick")
    );
    assert!(Renderer::new(&gpu, src.info(), &ok, RenderOptions::default()).is_ok());
}
