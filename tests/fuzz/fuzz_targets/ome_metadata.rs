//! OME-Zarr metadata of a foreign store, read the way the viewer opens any store (local or
//! over HTTP): the image group's attributes (`ImageAttributes::parse`), its pyramid
//! (`PyramidLayout::of`) and each level's array metadata (`ArrayDescription::parse`), all in
//! `residency-schemas` (`schemas/src/ome.rs`, `schemas/src/zarr.rs`; they were
//! `viewer/src/source/ome.rs` `parse_group` / `parse_array` before the move), then
//! `VolumeInfo::from_ome` (`schemas/src/volume/from_ome.rs`) that checks them against each
//! other and the region metadata, and `MinMaxGrid::from_values` on each region grid the
//! metadata describes.
//!
//! Input: one byte choosing Zarr v2 (even) or v3 (odd), then the group document and the array
//! documents separated by NUL bytes; level `i` reads array document `i` (the last one repeats).
#![no_main]

use libfuzzer_sys::fuzz_target;
use residency_schemas::ome::{ImageAttributes, PyramidLayout, ZarrFormat};
use residency_schemas::volume::{MinMaxGrid, VolumeInfo};
use residency_schemas::zarr::ArrayDescription;

fuzz_target!(|data: &[u8]| {
    let Some((&first, rest)) = data.split_first() else {
        return;
    };
    let format = if first % 2 == 0 {
        ZarrFormat::V2
    } else {
        ZarrFormat::V3
    };
    let mut docs = rest.split(|&b| b == 0);
    let group_doc = docs.next().unwrap_or_default();
    let array_docs: Vec<&[u8]> = docs.collect();
    let Ok(group) = ImageAttributes::parse(format, group_doc, "g") else {
        return;
    };
    let Ok(layout) = PyramidLayout::of(group.image(), "g") else {
        return;
    };
    if array_docs.is_empty() {
        return;
    }
    let mut arrays = Vec::new();
    for i in 0..layout.level_paths.len() {
        let doc = array_docs[i.min(array_docs.len() - 1)];
        match ArrayDescription::parse(format, doc, "a") {
            Ok(a) => arrays.push(a),
            Err(_) => return,
        }
    }
    if let Ok(info) = VolumeInfo::from_ome("v", &group, &layout, &arrays, "s") {
        assert_eq!(info.levels.len(), layout.level_paths.len());
        assert_eq!(info.channels.len(), info.display.len());
    }
    // The region grids, with as many values as they claim when that is small, or none.
    for level in group.regions.iter().flat_map(|r| &r.levels) {
        for grid in level.minmax.iter().chain(&level.range) {
            let cells = grid
                .grid_shape
                .iter()
                .try_fold(1u64, |a, &g| a.checked_mul(g));
            let values = match cells {
                Some(c) if c <= 1 << 12 => vec![0.5; 2 * c as usize],
                _ => Vec::new(),
            };
            let _ = MinMaxGrid::from_values(grid.cell_shape, grid.grid_shape, &values, "m");
        }
    }
});
