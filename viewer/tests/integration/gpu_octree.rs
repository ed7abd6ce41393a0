//! The residency octree: masks under random inserts/evicts equal a from-scratch
//! recomputation; exact leaf sets of a brick; value ranges seeded from the min/max grids.

use residency_viewer::gpu::synthetic::SyntheticSource;
use residency_viewer::octree::{ResidencyOctree, node_index};
use residency_viewer::source::{BrickKey, BrickSource, SampleType};

/// Deterministic xorshift generator (no extra dependency).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

fn volume() -> SyntheticSource {
    // Odd, anisotropic shape (z, y, x) with bricks not dividing it, 2 channels.
    SyntheticSource::new(
        SampleType::U16,
        [13, 37, 50],
        [2.0, 1.0, 1.0],
        [8, 8, 8],
        4,
        2,
        |c, [x, y, z]| ((x * 7 + y * 3 + z * 11 + c as u64 * 5) % 97) as f64,
    )
}

#[test]
fn random_inserts_and_evicts_match_recomputation() {
    let source = volume();
    let info = source.info();
    for depth in [2, 3, 4] {
        let mut tree = ResidencyOctree::new(info, &[1, 0], depth).unwrap();
        let mut all = Vec::new();
        for (l, _) in info.levels.iter().enumerate() {
            let g = info.brick_grid(l);
            for c in 0..2 {
                for z in 0..g[0] {
                    for y in 0..g[1] {
                        for x in 0..g[2] {
                            all.push(BrickKey {
                                level: l as u32,
                                channel: c,
                                brick: [z, y, x],
                            });
                        }
                    }
                }
            }
        }
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15 ^ depth as u64);
        let mut resident = std::collections::HashSet::new();
        for step in 0..1500 {
            let key = all[rng.below(all.len() as u64) as usize];
            if rng.below(3) < 2 {
                assert_eq!(tree.insert(key).unwrap(), resident.insert(key));
            } else {
                assert_eq!(tree.evict(key).unwrap(), resident.remove(&key));
            }
            if step % 25 == 0 {
                assert_eq!(
                    tree.masks(),
                    &tree.masks_from_scratch()[..],
                    "depth {depth} step {step}"
                );
            }
        }
        assert_eq!(tree.masks(), &tree.masks_from_scratch()[..]);
        assert_eq!(tree.resident_count(), resident.len());
        // Evicting everything clears every mask.
        for key in resident.drain() {
            tree.evict(key).unwrap();
        }
        assert!(tree.masks().iter().all(|&m| m == 0));
    }
}

#[test]
fn a_brick_marks_exactly_its_widened_extent() {
    let source = volume();
    // depth 3: root 64 × 64 × 16 voxels (x, y, z), leaves 8 × 8 × 2.
    let mut tree = ResidencyOctree::new(source.info(), &[0], 3).unwrap();
    let key = BrickKey {
        level: 0,
        channel: 0,
        brick: [0, 1, 2],
    }; // x 16..24, y 8..16, z 0..8
    tree.insert(key).unwrap();
    // Widened by one voxel: x 15..25 → leaves 1..=3; y 7..17 → leaves 0..=2; z 0..9 → 0..=4.
    for z in 0..8u64 {
        for y in 0..8u64 {
            for x in 0..8u64 {
                let expect = (1..=3).contains(&x) && y <= 2 && z <= 4;
                assert_eq!(
                    tree.mask(node_index(3, [x, y, z]), 0),
                    expect as u16,
                    "{x} {y} {z}"
                );
            }
        }
    }
    assert_eq!(tree.mask(0, 0), 1);
    // A level-1 brick sets bit 1 and leaves bit 0 alone.
    tree.insert(BrickKey {
        level: 1,
        channel: 0,
        brick: [0, 0, 0],
    })
    .unwrap();
    assert_eq!(tree.mask(0, 0), 0b11);
    assert_eq!(tree.mask(node_index(3, [2, 1, 1]), 0), 0b11);
    tree.evict(key).unwrap();
    assert_eq!(tree.mask(0, 0), 0b10);
    assert!(
        tree.insert(BrickKey {
            level: 0,
            channel: 5,
            brick: [0, 0, 0]
        })
        .is_err()
    );
}

#[test]
fn ranges_come_from_the_minmax_grids() {
    // x < 16 holds 0, the rest 100 + x: one channel, u8, 32³, bricks 16³, cells 4³.
    let source = SyntheticSource::new(
        SampleType::U8,
        [32, 32, 32],
        [1.0; 3],
        [16; 3],
        4,
        1,
        |_, [x, _, _]| {
            if x < 16 { 0.0 } else { 100.0 + x as f64 }
        },
    );
    let tree = ResidencyOctree::new(source.info(), &[0], 3).unwrap(); // leaves 4³ voxels
    // Two levels (32³, 16³). Leaf x 0..4: level-0 cell 0 reads voxels 0..5, level-1 cell 0
    // (8 level-0 voxels) reads level-1 voxels 0..5 = level-0 x < 10: all zero, homogeneous.
    assert_eq!(source.info().levels.len(), 2);
    assert_eq!(tree.range(node_index(3, [0, 0, 0]), 0), (0.0, 0.0));
    // Leaf x 12..16 touches the level-0 cell whose halo reaches voxel 16 (value 116).
    let (lo, hi) = tree.range(node_index(3, [3, 0, 0]), 0);
    assert_eq!(lo, 0.0);
    assert!(hi >= 116.0, "{hi}");
    // A leaf far inside x >= 16: x 24..28, min over all levels is positive.
    let (lo, hi) = tree.range(node_index(3, [6, 3, 3]), 0);
    assert!(lo >= 100.0 && hi <= 131.0, "{lo} {hi}");
    // The root's range is the union.
    assert_eq!(tree.range(0, 0), (0.0, 131.0));
    // Flat GPU layout: [mask, min bits, max bits] per node and channel.
    let words = tree.gpu_words(0..1);
    assert_eq!(words, vec![0, 0f32.to_bits(), 131f32.to_bits()]);
    // Without region metadata, every in-volume node has the unknown range.
    let tree = ResidencyOctree::new(source.without_minmax().info(), &[0], 2).unwrap();
    assert!(tree.unknown_ranges());
    assert_eq!(tree.range(0, 0), (f64::NEG_INFINITY, f64::INFINITY));
}

#[test]
fn without_minmax_ranges_come_from_level0_bricks() {
    // 16³ u8, bricks 8³, value = x; leaves of 2³ voxels (depth 3).
    let src = SyntheticSource::new(
        SampleType::U8,
        [16, 16, 16],
        [1.0; 3],
        [8; 3],
        4,
        1,
        |_, [x, _, _]| x as f64,
    )
    .without_minmax();
    let mut tree = ResidencyOctree::new(src.info(), &[0], 3).unwrap();
    let key = BrickKey {
        level: 0,
        channel: 0,
        brick: [0, 0, 0],
    };
    let voxels = src.fetch(&[key]).pop().unwrap().unwrap();
    tree.take_dirty();
    // Leaves 0..4 per axis overlap the brick; a leaf's footprint is its 2 voxels plus one on
    // each side, so leaves 0, 1, 2 fit in voxels 0..8 but leaf 3 (voxels 5..=8) does not.
    assert_eq!(tree.refine_ranges(&key, &voxels), 27);
    assert_eq!(tree.range(node_index(3, [0, 0, 0]), 0), (0.0, 2.0));
    assert_eq!(tree.range(node_index(3, [2, 1, 0]), 0), (3.0, 6.0));
    assert_eq!(
        tree.range(node_index(3, [3, 0, 0]), 0),
        (f64::NEG_INFINITY, f64::INFINITY)
    );
    // The depth-2 parent of leaves 0..2 is known once all 8 children are: not yet (leaf 3
    // of the next parent is unknown, but parent [0,0,0] covers leaves 0..1 only).
    assert_eq!(tree.range(node_index(2, [0, 0, 0]), 0), (0.0, 4.0));
    assert_eq!(tree.range(0, 0), (f64::NEG_INFINITY, f64::INFINITY));
    assert!(tree.take_dirty().is_some());
    // A level-1 brick changes nothing.
    let k1 = BrickKey {
        level: 1,
        channel: 0,
        brick: [0, 0, 0],
    };
    let v1 = src.fetch(&[k1]).pop().unwrap().unwrap();
    assert_eq!(tree.refine_ranges(&k1, &v1), 0);
}
