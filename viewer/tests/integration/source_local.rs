//! `LocalSource` on stores written by the real `ingest` library: metadata, min/max grids and
//! bricks equal to the source voxels, for every layout, with and without region metadata.

use crate::source_common::{
    BRICK, Layout, SHAPE, ball, make_store, ramp, strip_region_metadata, voxels,
};
use residency_viewer::source::{
    BrickKey, BrickSource, BrickVoxels, LevelInfo, LocalSource, SampleType,
};

/// A log sink for `tracing_subscriber`.
#[derive(Clone, Default)]
struct Log(std::sync::Arc<std::sync::Mutex<Vec<u8>>>);

impl std::io::Write for Log {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl<'a> tracing_subscriber::fmt::MakeWriter<'a> for Log {
    type Writer = Log;

    fn make_writer(&'a self) -> Log {
        self.clone()
    }
}

/// The expected level-0 brick of a channel: the voxels, fill value 0 past the edge, or
/// `Empty` when all zero.
fn expected_brick(data: &[u16], brick: [u64; 3]) -> BrickVoxels {
    let [nz, ny, nx] = SHAPE;
    let mut v = Vec::new();
    for z in 0..BRICK {
        for y in 0..BRICK {
            for x in 0..BRICK {
                let g = [
                    brick[0] * BRICK + z,
                    brick[1] * BRICK + y,
                    brick[2] * BRICK + x,
                ];
                v.push(if g[0] < nz && g[1] < ny && g[2] < nx {
                    data[((g[0] * ny + g[1]) * nx + g[2]) as usize]
                } else {
                    0
                });
            }
        }
    }
    if v.iter().all(|&x| x == 0) {
        BrickVoxels::Empty
    } else {
        BrickVoxels::U16(v)
    }
}

fn level0_keys(channel: u32) -> Vec<BrickKey> {
    let g = SHAPE.map(|s| s.div_ceil(BRICK));
    let mut keys = Vec::new();
    for z in 0..g[0] {
        for y in 0..g[1] {
            for x in 0..g[2] {
                keys.push(BrickKey {
                    level: 0,
                    channel,
                    brick: [z, y, x],
                });
            }
        }
    }
    keys
}

#[test]
fn v3_store_reads_metadata_minmax_and_bricks_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let store = make_store(dir.path(), "vol", Layout::V3);
    let src = LocalSource::open(&store).unwrap();
    let info = src.info();
    assert_eq!(info.name, "vol");
    assert_eq!(info.sample_type, SampleType::U16);
    assert_eq!(info.channels, ["ball", "ramp"]);
    assert_eq!(info.voxel_size, [2.0, 0.5, 0.5]);
    assert_eq!(info.brick_shape, [8, 8, 8]);
    // Anisotropy-aware pyramid: z (4× coarser) is halved only once y and x caught up.
    assert_eq!(
        info.levels[..3],
        [
            LevelInfo {
                shape: [20, 24, 28],
                factor: [1, 1, 1]
            },
            LevelInfo {
                shape: [20, 12, 14],
                factor: [1, 2, 2]
            },
            LevelInfo {
                shape: [20, 6, 7],
                factor: [1, 4, 4]
            },
        ]
    );
    let last = info.levels.last().unwrap();
    assert!(last.shape.iter().all(|&s| s <= BRICK), "{last:?}");
    // Display hints: the omero window and the region-metadata range.
    let ball_max = *voxels(ball).iter().max().unwrap() as f64;
    assert_eq!(info.display[0].range, Some([0.0, ball_max]));
    assert!(info.display[0].window.is_some());
    // Most of the ball channel is background.
    assert_eq!(info.display[0].median, Some(0.0));

    // Min/max grids: one hierarchy per channel and level, down to a single cell, and the
    // finest level-0 grid holds each 8³ cell's range over its voxels plus a 1-voxel halo.
    let minmax = info.minmax.as_ref().expect("region metadata");
    assert_eq!(minmax.len(), 2);
    for (c, f) in [ball as fn(u64, u64, u64) -> u16, ramp]
        .into_iter()
        .enumerate()
    {
        assert_eq!(minmax[c].len(), info.levels.len());
        for grids in &minmax[c] {
            assert_eq!(grids.last().unwrap().grid_shape, [1, 1, 1]);
        }
        let g = &minmax[c][0][0];
        assert_eq!(g.cell_shape, [8, 8, 8]);
        assert_eq!(g.grid_shape, [3, 3, 4]);
        let data = voxels(f);
        let [nz, ny, nx] = SHAPE;
        for cz in 0..3u64 {
            for cy in 0..3u64 {
                for cx in 0..4u64 {
                    let r = |c: u64, n: u64| (c * 8).saturating_sub(1)..(c * 8 + 9).min(n);
                    let (mut lo, mut hi) = (u16::MAX, 0);
                    for z in r(cz, nz) {
                        for y in r(cy, ny) {
                            for x in r(cx, nx) {
                                let v = data[((z * ny + y) * nx + x) as usize];
                                lo = lo.min(v);
                                hi = hi.max(v);
                            }
                        }
                    }
                    let i = ((cz * 3 + cy) * 4 + cx) as usize;
                    assert_eq!(
                        (g.min[i], g.max[i]),
                        (lo as f64, hi as f64),
                        "cell {cz},{cy},{cx}"
                    );
                }
            }
        }
        // Every level-0 brick equals the source voxels; all-zero bricks are Empty.
        let keys = level0_keys(c as u32);
        let got = src.fetch(&keys);
        let mut empty = 0;
        for (k, b) in keys.iter().zip(got) {
            let b = b.unwrap();
            assert_eq!(b, expected_brick(&data, k.brick), "{k:?}");
            empty += (b == BrickVoxels::Empty) as usize;
        }
        assert!(
            empty > 0 && empty < keys.len(),
            "channel {c}: {empty} empty"
        );
    }
}

#[test]
fn sharded_and_v2_stores_read_the_same_as_v3() {
    let dir = tempfile::tempdir().unwrap();
    let v3 = LocalSource::open(make_store(dir.path(), "a", Layout::V3)).unwrap();
    for (name, layout) in [("b", Layout::V3Sharded), ("c", Layout::V2)] {
        let other = LocalSource::open(make_store(dir.path(), name, layout)).unwrap();
        let mut info = other.info().clone();
        info.name = "a".into();
        assert_eq!(&info, v3.info(), "{layout:?}");
        let mut keys = Vec::new();
        for (l, level) in v3.info().levels.iter().enumerate() {
            let g = level.shape.map(|s| s.div_ceil(BRICK));
            for c in 0..2 {
                for z in 0..g[0] {
                    for y in 0..g[1] {
                        for x in 0..g[2] {
                            keys.push(BrickKey {
                                level: l as u32,
                                channel: c,
                                brick: [z, y, x],
                            });
                        }
                    }
                }
            }
        }
        let a: Vec<_> = v3.fetch(&keys).into_iter().map(Result::unwrap).collect();
        let b: Vec<_> = other.fetch(&keys).into_iter().map(Result::unwrap).collect();
        assert_eq!(a, b, "{layout:?}");
    }
}

/// Opens `store`, returning the source and what it logged.
fn open_logged(store: &std::path::Path) -> (LocalSource, String) {
    let log = Log::default();
    let subscriber = tracing_subscriber::fmt()
        .with_writer(log.clone())
        .with_ansi(false)
        .finish();
    let src = tracing::subscriber::with_default(subscriber, || LocalSource::open(store)).unwrap();
    let text = String::from_utf8(log.0.lock().unwrap().clone()).unwrap();
    (src, text)
}

#[test]
fn a_store_without_region_metadata_has_no_minmax() {
    let dir = tempfile::tempdir().unwrap();
    let store = make_store(dir.path(), "bare", Layout::V3);
    strip_region_metadata(&store);
    // Opening says that culling falls back to the bricks.
    let (src, text) = open_logged(&store);
    assert!(
        text.contains(&format!(
            "WARN residency_viewer::source::regions: {}: no region metadata; culling falls back to \
             computing min/max from bricks",
            store.display()
        )),
        "{text}"
    );
    assert_eq!(src.info().minmax, None);
    // The omero window still gives display hints, and bricks still read.
    assert!(src.info().display[0].window.is_some());
    let k = level0_keys(1)[1];
    assert_eq!(
        src.fetch(&[k]).pop().unwrap().unwrap(),
        expected_brick(&voxels(ramp), k.brick)
    );
}

/// Min/max cells without a halo do not bound the trilinear samples inside them (a sample
/// near a cell's face reads the next cell's voxels), so the renderer's culling would hide
/// visible matter: such metadata is ignored, with a warning naming the store.
#[test]
fn region_metadata_without_a_halo_is_not_used_for_culling() {
    let dir = tempfile::tempdir().unwrap();
    let store = make_store(dir.path(), "nohalo", Layout::V3);
    let file = store.join("zarr.json");
    let mut doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&file).unwrap()).unwrap();
    assert_eq!(doc["attributes"]["residency"]["halo"], 1);
    doc["attributes"]["residency"]["halo"] = 0.into();
    std::fs::write(&file, serde_json::to_vec(&doc).unwrap()).unwrap();
    let (src, text) = open_logged(&store);
    assert!(
        text.contains(&format!(
            "WARN residency_viewer::source::regions: {}: the region metadata's min/max cells have \
             no halo, so they do not bound trilinear samples; culling falls back to computing \
             min/max from bricks",
            store.display()
        )),
        "{text}"
    );
    assert_eq!(src.info().minmax, None);
}

#[test]
fn bad_stores_and_bricks_give_errors_naming_them() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nothing.ome.zarr");
    let e = LocalSource::open(&missing).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!("{}: no such store", missing.display())
    );
    let e = LocalSource::open(dir.path()).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "{}: not an OME-Zarr image (no zarr.json or .zattrs)",
            dir.path().display()
        )
    );

    let store = make_store(dir.path(), "vol", Layout::V3);
    // A corrupt chunk: its brick fails with an error naming it; the others still read.
    std::fs::write(store.join("0/c/1/0/1/1"), b"not blosc").unwrap();
    let src = LocalSource::open(&store).unwrap();
    let bad = BrickKey {
        level: 0,
        channel: 1,
        brick: [0, 1, 1],
    };
    let outside = BrickKey {
        level: 0,
        channel: 0,
        brick: [3, 0, 0],
    };
    let good = BrickKey {
        level: 0,
        channel: 1,
        brick: [0, 0, 1],
    };
    let mut got = src.fetch(&[bad, outside, good]).into_iter();
    let e = got.next().unwrap().unwrap_err();
    let chain = residency_viewer::error_chain(&e);
    assert!(
        chain.starts_with(&format!(
            "{}: cannot read brick [0, 1, 1] of channel 1 at level 0: ",
            store.display()
        )),
        "{chain}"
    );
    let e = got.next().unwrap().unwrap_err();
    assert_eq!(
        e.to_string(),
        "vol: brick BrickKey { level: 0, channel: 0, brick: [3, 0, 0] }: outside the level's \
         brick grid [3, 3, 4]"
    );
    assert_eq!(
        got.next().unwrap().unwrap(),
        expected_brick(&voxels(ramp), good.brick)
    );

    // A level whose zarr.json holds a field a reader must understand is refused, as zarrs'
    // Array::open refuses it; one marked `"must_understand": false` is not.
    let extra = make_store(dir.path(), "extra", Layout::V3);
    let level = extra.join("1/zarr.json");
    let plain: serde_json::Value = serde_json::from_slice(&std::fs::read(&level).unwrap()).unwrap();
    let with = |field: serde_json::Value| {
        let mut doc = plain.clone();
        doc["foo"] = field;
        std::fs::write(&level, serde_json::to_vec(&doc).unwrap()).unwrap();
        LocalSource::open(&extra).map(|_| ())
    };
    let e = with(serde_json::json!("bar")).unwrap_err();
    assert_eq!(
        residency_viewer::error_chain(&e),
        format!(
            "{}: cannot open the array: unsupported additional field foo with value \"bar\"",
            level.display()
        )
    );
    with(serde_json::json!({"must_understand": false, "x": 1})).unwrap();
}

/// Every sample type `ingest` writes reads back exactly, typed, with its min/max grids.
#[test]
fn every_sample_type_reads_back_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let [nz, ny, nx] = [9u64, 10, 11];
    // A value per voxel, zero in the first brick column (x < 8) so some bricks are empty.
    let value = |z: u64, y: u64, x: u64| -> f64 {
        if x < 8 {
            0.0
        } else {
            (x as f64 - 7.0) * 3.0 - y as f64 + z as f64 * 0.5
        }
    };
    for (dtype, sample_type) in [
        ("uint8", SampleType::U8),
        ("int16", SampleType::I16),
        ("uint32", SampleType::U32),
        ("int32", SampleType::I32),
        ("float32", SampleType::F32),
    ] {
        // Integer types hold the value rounded down (and offset to stay non-negative when
        // unsigned); float32 holds it exactly.
        let stored = |z, y, x| -> f64 {
            let v = value(z, y, x);
            match sample_type {
                SampleType::F32 => v,
                SampleType::U8 | SampleType::U32 if v != 0.0 => (v + 20.0).floor(),
                _ => v.floor(),
            }
        };
        let mut bytes = Vec::new();
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    let v = stored(z, y, x);
                    match sample_type {
                        SampleType::U8 => bytes.push(v as u8),
                        SampleType::I16 => bytes.extend((v as i16).to_le_bytes()),
                        SampleType::U32 => bytes.extend((v as u32).to_le_bytes()),
                        SampleType::I32 => bytes.extend((v as i32).to_le_bytes()),
                        _ => bytes.extend((v as f32).to_le_bytes()),
                    }
                }
            }
        }
        let raw = dir.path().join(format!("v_{nx}x{ny}x{nz}_{dtype}.raw"));
        std::fs::write(&raw, bytes).unwrap();
        let out = dir.path().join(format!("{dtype}.ome.zarr"));
        let mut o =
            residency_ingest::ConvertOptions::new(vec![raw.to_str().unwrap().into()], out.clone());
        o.brick = [BRICK; 3];
        residency_ingest::convert(&o).unwrap();

        let src = LocalSource::open(&out).unwrap();
        assert_eq!(src.info().sample_type, sample_type, "{dtype}");
        let root = &src.info().minmax.as_ref().unwrap()[0][0];
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    lo = lo.min(stored(z, y, x));
                    hi = hi.max(stored(z, y, x));
                }
            }
        }
        let top = root.last().unwrap();
        assert_eq!((top.min[0], top.max[0]), (lo, hi), "{dtype}");
        let g = src.info().brick_grid(0);
        for bz in 0..g[0] {
            for by in 0..g[1] {
                for bx in 0..g[2] {
                    let key = BrickKey {
                        level: 0,
                        channel: 0,
                        brick: [bz, by, bx],
                    };
                    let b = src.fetch(&[key]).pop().unwrap().unwrap();
                    let kind = std::mem::discriminant(&b);
                    assert_eq!(bx == 0, b == BrickVoxels::Empty, "{dtype} {key:?}");
                    if bx == 0 {
                        continue;
                    }
                    let typed = match sample_type {
                        SampleType::U8 => BrickVoxels::U8(vec![]),
                        SampleType::I16 => BrickVoxels::I16(vec![]),
                        SampleType::U32 => BrickVoxels::U32(vec![]),
                        SampleType::I32 => BrickVoxels::I32(vec![]),
                        _ => BrickVoxels::F32(vec![]),
                    };
                    assert_eq!(kind, std::mem::discriminant(&typed), "{dtype}");
                    for i in 0..BRICK {
                        for j in 0..BRICK {
                            for k in 0..BRICK {
                                let (z, y, x) = (bz * BRICK + i, by * BRICK + j, bx * BRICK + k);
                                let want = if z < nz && y < ny && x < nx {
                                    stored(z, y, x)
                                } else {
                                    0.0
                                };
                                let idx = ((i * BRICK + j) * BRICK + k) as usize;
                                assert_eq!(b.value(idx), want, "{dtype} voxel {z},{y},{x}");
                            }
                        }
                    }
                }
            }
        }
    }
}
