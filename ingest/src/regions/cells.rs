//! Conservative min/max cells: for every cell of a level and every channel, the *haloed*
//! range (culling) and the *exact* range (region queries), gathered slab by slab, window by
//! window; and how many rows of cells are written at once ([`CHUNK_ROWS`]).

use crate::sample_format::{Sample, max_of, min_of};
use crate::source::PlaneRegion;

/// Edge of a min/max cell in voxels of its level.
pub const CELL: u64 = 8;
/// Halo, in voxels, added around every cell.
pub const HALO: u64 = 1;

/// The cells (along one axis of extent `cells`) whose haloed ranges contain any of `voxels`.
pub fn cells_reached(voxels: std::ops::Range<u64>, cells: u64) -> std::ops::Range<u64> {
    *cells_of(voxels.start, cells).start()..*cells_of(voxels.end - 1, cells).end() + 1
}

/// The cells (along one axis of extent `cells`) whose haloed range contains voxel `v`.
#[inline]
fn cells_of(v: u64, cells: u64) -> std::ops::RangeInclusive<u64> {
    let lo = (v + 1).saturating_sub(CELL + HALO).div_ceil(CELL);
    let hi = ((v + HALO) / CELL).min(cells - 1);
    lo..=hi
}

/// Per-cell minima and maxima of every channel, `[c][gz][gy][gx]`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub struct Ranges<T: Sample> {
    /// Minimum per cell (`T::HIGHEST` where nothing was seen).
    pub min: Vec<T>,
    /// Maximum per cell (`T::LOWEST` where nothing was seen).
    pub max: Vec<T>,
}

/// Folds a row of values into per-column minima and maxima.
#[multiversion::multiversion(targets("x86_64+avx2"))]
fn fold_row<T: Sample>(min: &mut [T], max: &mut [T], values: &[T]) {
    for ((mn, mx), &v) in min.iter_mut().zip(max).zip(values) {
        (*mn, *mx) = (min_of(*mn, v), max_of(*mx, v));
    }
}

/// The smallest of `min` and the largest of `max` (the identities when empty).
#[multiversion::multiversion(targets("x86_64+avx2"))]
fn range_of<T: Sample>(min: &[T], max: &[T]) -> (T, T) {
    let mn = min.iter().fold(T::HIGHEST, |a, &v| min_of(a, v));
    let mx = max.iter().fold(T::LOWEST, |a, &v| max_of(a, v));
    (mn, mx)
}

impl<T: Sample> Ranges<T> {
    fn new(n: usize) -> Self {
        Self {
            min: vec![T::HIGHEST; n],
            max: vec![T::LOWEST; n],
        }
    }

    #[inline]
    fn fold(&mut self, i: usize, mn: T, mx: T) {
        if mn < self.min[i] {
            self.min[i] = mn;
        }
        if mx > self.max[i] {
            self.max[i] = mx;
        }
    }

    /// Folds a row of values into this row of ranges, element by element.
    #[inline]
    fn fold_row(&mut self, values: &[T]) {
        fold_row(&mut self.min, &mut self.max, values);
    }

    /// The range of ranges `i` (the identity when empty).
    #[inline]
    fn range_of(&self, i: std::ops::Range<usize>) -> (T, T) {
        range_of(&self.min[i.clone()], &self.max[i])
    }

    /// Sets range `i`.
    #[inline]
    fn set(&mut self, i: usize, (mn, mx): (T, T)) {
        (self.min[i], self.max[i]) = (mn, mx);
    }

    /// Folds cells `from` of another grid's ranges onto this grid's cells from `offset`.
    fn merge_at(&mut self, other: &Self, from: std::ops::Range<usize>, offset: usize) {
        for (i, (&mn, &mx)) in other.min[from.clone()]
            .iter()
            .zip(&other.max[from])
            .enumerate()
        {
            self.fold(offset + i, mn, mx);
        }
    }
}

/// The min/max grids of all channels of one level: haloed (for culling) and exact (for
/// region queries), over the same cells.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub struct CellGrid<T: Sample> {
    /// Number of cells held `z, y, x`: every cell of the level, the rows a partition reaches,
    /// or the block of cells one column reaches.
    pub grid: [u64; 3],
    /// The level's cell row held first (0 for a whole level).
    pub z0: u64,
    /// The level's cell held first along `y` (0 but in a column's block).
    pub y0: u64,
    /// The level's cell held first along `x` (0 but in a column's block).
    pub x0: u64,
    /// Cell rows of the whole level.
    pub depth: u64,
    /// Channels.
    pub channels: usize,
    /// Ranges over each cell plus its halo.
    pub haloed: Ranges<T>,
    /// Ranges over each cell's own voxels.
    pub exact: Ranges<T>,
}

impl<T: Sample> CellGrid<T> {
    /// Folds in the ranges another grid of the same level found over the cells both hold
    /// (another pass's rows, or a column's block), so these cells are what one pass over both
    /// grids' voxels would have found.
    ///
    /// # Panics
    /// When the grids are of different levels or channels.
    pub fn merge(&mut self, other: &Self) {
        assert!(other.channels == self.channels && other.depth == self.depth);
        let overlap = |a0: u64, an: u64, b0: u64, bn: u64| a0.max(b0)..(a0 + an).min(b0 + bn);
        let zs = overlap(self.z0, self.grid[0], other.z0, other.grid[0]);
        let ys = overlap(self.y0, self.grid[1], other.y0, other.grid[1]);
        let xs = overlap(self.x0, self.grid[2], other.x0, other.grid[2]);
        if zs.is_empty() || ys.is_empty() || xs.is_empty() {
            return;
        }
        let n = (xs.end - xs.start) as usize;
        for c in 0..self.channels {
            for z in zs.clone() {
                for y in ys.clone() {
                    let theirs = other.index(c, z - other.z0, y - other.y0, xs.start - other.x0);
                    let at = self.index(c, z - self.z0, y - self.y0, xs.start - self.x0);
                    self.haloed.merge_at(&other.haloed, theirs..theirs + n, at);
                    self.exact.merge_at(&other.exact, theirs..theirs + n, at);
                }
            }
        }
    }

    /// The cell rows held: `z0..z0 + grid[0]`.
    pub fn rows(&self) -> std::ops::Range<u64> {
        self.z0..self.z0 + self.grid[0]
    }

    /// An empty block of cells `rows × ys × xs` of a level of `depth` rows (a column's).
    pub fn block(
        channels: usize,
        rows: std::ops::Range<u64>,
        ys: std::ops::Range<u64>,
        xs: std::ops::Range<u64>,
        depth: u64,
    ) -> Self {
        let mut grid = Self::new(
            channels,
            [rows.end - rows.start, ys.end - ys.start, xs.end - xs.start],
        );
        (grid.z0, grid.y0, grid.x0, grid.depth) = (rows.start, ys.start, xs.start, depth);
        grid
    }

    /// Its rows `rows` (as a block of the same cells in `y` and `x`).
    pub fn rows_of(&self, rows: std::ops::Range<u64>) -> Self {
        let mut out = Self::block(
            self.channels,
            rows,
            self.y0..self.y0 + self.grid[1],
            self.x0..self.x0 + self.grid[2],
            self.depth,
        );
        out.merge(self);
        out
    }

    /// An empty window of rows `rows` of a level of `depth` rows of `gy × gx` cells.
    pub fn window(
        channels: usize,
        [gy, gx]: [u64; 2],
        rows: std::ops::Range<u64>,
        depth: u64,
    ) -> Self {
        let mut grid = Self::new(channels, [rows.end - rows.start, gy, gx]);
        grid.z0 = rows.start;
        grid.depth = depth;
        grid
    }

    /// Holds rows up to `end` (capped at the level's rows) as well, empty.
    pub fn extend_to(&mut self, end: u64) {
        let end = end.min(self.depth);
        if end <= self.z0 + self.grid[0] {
            return;
        }
        *self = self.rows_of(self.z0..end);
    }

    /// Takes the rows before `end` out of the window (they are final), which then starts at
    /// `end` (or holds nothing past its last row).
    pub fn split_before(&mut self, end: u64) -> Self {
        let held = self.rows();
        let end = end.clamp(held.start, held.end);
        let front = self.rows_of(held.start..end);
        *self = self.rows_of(end..held.end);
        front
    }

    /// An empty grid of `grid` cells per channel.
    pub fn new(channels: usize, grid: [u64; 3]) -> Self {
        let n = channels * (grid[0] * grid[1] * grid[2]) as usize;
        Self {
            grid,
            z0: 0,
            y0: 0,
            x0: 0,
            depth: grid[0],
            channels,
            haloed: Ranges::new(n),
            exact: Ranges::new(n),
        }
    }

    /// The cell rows covering voxel planes `planes` of a level of `shape`, with the rows their
    /// halos reach (one up, one down): what a pass over those planes can touch (the tests'
    /// reference for what the windows a pass opens reach).
    #[cfg(test)]
    pub fn for_rows(channels: usize, shape: [u64; 3], planes: std::ops::Range<u64>) -> Self {
        let full = shape.map(|s| s.div_ceil(CELL));
        let z1 = (planes.end.div_ceil(CELL) + 1).min(full[0]);
        let z0 = (planes.start / CELL).saturating_sub(1).min(z1);
        let mut grid = Self::new(channels, [z1 - z0, full[1], full[2]]);
        grid.z0 = z0;
        grid.depth = full[0];
        grid
    }

    /// The grid of cells covering a level of `shape` (the tests' whole-level reference).
    #[cfg(test)]
    pub fn for_shape(channels: usize, shape: [u64; 3]) -> Self {
        Self::new(channels, shape.map(|s| s.div_ceil(CELL)))
    }

    fn index(&self, c: usize, z: u64, y: u64, x: u64) -> usize {
        let [_, gy, gx] = self.grid;
        ((c as u64 * self.grid[0] + z) * gy * gx + y * gx + x) as usize
    }

    /// Makes room for the rows that a slab of `nz` planes from depth `z0` over `window` of
    /// its planes reaches (halos included), and returns the level's cells per plane row and
    /// column, `gy, gx`, that [`slice_cells`] takes for the windows of that slab.
    pub fn start_slab(&mut self, z0: u64, nz: u64, window: PlaneRegion) -> [u64; 2] {
        // The level's cells per row (a block holds the cells its column reaches).
        let gy = (window.y0 + window.ny)
            .div_ceil(CELL)
            .max(self.y0 + self.grid[1]);
        let gx = (window.x0 + window.nx)
            .div_ceil(CELL)
            .max(self.x0 + self.grid[2]);
        // The rows these planes reach, halos included, may start past the window's end.
        if nz > 0 {
            self.extend_to(*cells_of(z0 + nz - 1, self.depth).end() + 1);
        }
        [gy, gx]
    }

    /// Folds into the cells what [`slice_cells`] found in a window of plane `z` of channel
    /// `c`, after [`start_slab`](Self::start_slab) for the slab of that plane.
    pub fn fold_slice(&mut self, c: usize, z: u64, cells: &SliceCells<T>) {
        let held = self.z0..self.z0 + self.grid[0];
        let (hy, hx) = (&cells.haloed_cells[0], &cells.haloed_cells[1]);
        let w = (hx.end - hx.start) as usize;
        for cz in cells_of(z, self.depth).filter(|cz| held.contains(cz)) {
            for (j, cy) in hy.clone().enumerate() {
                let base = self.index(c, cz - self.z0, cy - self.y0, hx.start - self.x0);
                for i in 0..w {
                    let k = j * w + i;
                    self.haloed
                        .fold(base + i, cells.haloed.min[k], cells.haloed.max[k]);
                }
            }
        }
        let (ey, ex) = (&cells.exact_cells[0], &cells.exact_cells[1]);
        let w = (ex.end - ex.start) as usize;
        for (j, cy) in ey.clone().enumerate() {
            let base = self.index(c, z / CELL - self.z0, cy - self.y0, ex.start - self.x0);
            for i in 0..w {
                let k = j * w + i;
                self.exact
                    .fold(base + i, cells.exact.min[k], cells.exact.max[k]);
            }
        }
    }

    /// Folds one slab of voxels (`planes[c · nz + z]`, each `[y][x]` over `window` of its
    /// plane, starting at depth `z0` of the level) into the cells. Slabs and windows may arrive in any
    /// order: a cell at a window's edge takes its halo from the next window's voxels when
    /// they come. (Conversions fold each gather group's window as its chunks are gathered, see
    /// `SlabSink::process`; this is the same, a whole plane at a time.)
    #[cfg(test)]
    pub fn add_slab(&mut self, planes: &[&[T]], z0: u64, nz: u64, window: PlaneRegion) {
        use rayon::prelude::*;
        let grid = self.start_slab(z0, nz, window);
        let slices: Vec<(usize, u64, SliceCells<T>)> = (0..self.channels)
            .flat_map(|c| (0..nz).map(move |dz| (c, dz)))
            .collect::<Vec<_>>()
            .into_par_iter()
            .map(|(c, dz)| {
                let plane = planes[(c as u64 * nz + dz) as usize];
                let cells = slice_cells(plane, window.nx as usize, window, grid);
                (c, z0 + dz, cells)
            })
            .collect();
        for (c, z, cells) in slices {
            self.fold_slice(c, z, &cells);
        }
    }

    /// The next coarser grid: each cell is the min of mins and max of maxes of 2×2×2 cells.
    /// A window of rows starting on an even row gives the coarser rows it covers.
    pub fn coarsen(&self) -> Self {
        debug_assert!(self.z0.is_multiple_of(2) && self.y0 == 0 && self.x0 == 0);
        let g = self.grid.map(|s| s.div_ceil(2));
        let mut out = Self::window(
            self.channels,
            [g[1], g[2]],
            self.z0 / 2..self.z0 / 2 + g[0],
            self.depth.div_ceil(2),
        );
        for c in 0..self.channels {
            for z in 0..self.grid[0] {
                for y in 0..self.grid[1] {
                    for x in 0..self.grid[2] {
                        let i = self.index(c, z, y, x);
                        let o = out.index(c, z / 2, y / 2, x / 2);
                        out.haloed.fold(o, self.haloed.min[i], self.haloed.max[i]);
                        out.exact.fold(o, self.exact.min[i], self.exact.max[i]);
                    }
                }
            }
        }
        out
    }

    /// The haloed (`exact == false`) or exact ranges as `[c][2][gz][gy][gx]`, with cells that
    /// saw no value (all NaN) as NaN.
    pub fn to_min_max_array(&self, exact: bool) -> Vec<T> {
        let ranges = if exact { &self.exact } else { &self.haloed };
        let n = (self.grid[0] * self.grid[1] * self.grid[2]) as usize;
        let nan = T::from_f64(f64::NAN);
        let mut out = Vec::with_capacity(2 * ranges.min.len());
        for c in 0..self.channels {
            let (mn, mx) = (
                &ranges.min[c * n..(c + 1) * n],
                &ranges.max[c * n..(c + 1) * n],
            );
            let empty = |i: usize| mn[i] > mx[i];
            out.extend((0..n).map(|i| if empty(i) { nan } else { unsigned_zero(mn[i]) }));
            out.extend((0..n).map(|i| if empty(i) { nan } else { unsigned_zero(mx[i]) }));
        }
        out
    }
}

/// `v`, with −0.0 written as 0.0. Of two equal values a range keeps the one it saw first,
/// and the order in which a cell's voxels are seen depends on how the workers share the
/// slab, so a cell holding both zeros would otherwise get either sign.
fn unsigned_zero<T: Sample>(v: T) -> T {
    if v == T::default() { T::default() } else { v }
}

/// The cells one window of a slice reaches: haloed ranges (x and y halo; z is the caller's)
/// over the cells `haloed_cells` (rows, columns), and exact ranges over `exact_cells`.
pub struct SliceCells<T: Sample> {
    haloed_cells: [std::ops::Range<u64>; 2],
    haloed: Ranges<T>,
    exact_cells: [std::ops::Range<u64>; 2],
    exact: Ranges<T>,
}

/// Min/max cells of one window of a slice (`window.ny` rows of `window.nx` values, each row
/// `stride` values after the one before) of a level whose planes have `grid` = `gy, gx` cells
/// (see [`CellGrid::start_slab`]): haloed in x and y, and exact, over the cells the window's
/// voxels reach.
///
/// Each row of cells is folded column by column first (the rows of a cell, then its halo
/// rows: whole rows of values at once, which the compiler vectorizes), and each cell's
/// columns of the result are folded after.
pub fn slice_cells<T: Sample>(
    slice: &[T],
    stride: usize,
    window: PlaneRegion,
    [gy, gx]: [u64; 2],
) -> SliceCells<T> {
    let [y1, x1] = window.end();
    let haloed_cells = [
        cells_reached(window.y0..y1, gy),
        cells_reached(window.x0..x1, gx),
    ];
    let exact_cells = [
        window.y0 / CELL..(y1 - 1) / CELL + 1,
        window.x0 / CELL..(x1 - 1) / CELL + 1,
    ];
    let (hx0, ex0) = (haloed_cells[1].start, exact_cells[1].start);
    let hw = (haloed_cells[1].end - hx0) as usize;
    let ew = (exact_cells[1].end - ex0) as usize;
    let mut out = SliceCells {
        haloed: Ranges::new((haloed_cells[0].end - haloed_cells[0].start) as usize * hw),
        exact: Ranges::new((exact_cells[0].end - exact_cells[0].start) as usize * ew),
        haloed_cells,
        exact_cells,
    };
    let nx = window.nx as usize;
    let row = |y: u64| &slice[(y - window.y0) as usize * stride..][..nx];
    // The voxels of `first..end` (level coordinates along one axis) inside `window`'s
    // `start..stop`, relative to `start`.
    let inside = |first: u64, end: u64, start: u64, stop: u64| {
        let lo = first.clamp(start, stop) - start;
        lo as usize..(end.clamp(start, stop) - start).max(lo) as usize
    };
    let mut column = Ranges::<T>::new(nx);
    let mut haloed = Ranges::<T>::new(nx);
    for cy in out.haloed_cells[0].clone() {
        // The cell row's own rows, then its halo rows.
        column.min.fill(T::HIGHEST);
        column.max.fill(T::LOWEST);
        for y in inside(cy * CELL, (cy + 1) * CELL, window.y0, y1) {
            column.fold_row(row(window.y0 + y as u64));
        }
        if out.exact_cells[0].contains(&cy) {
            let base = (cy - out.exact_cells[0].start) as usize * ew;
            for (i, cx) in out.exact_cells[1].clone().enumerate() {
                let xs = inside(cx * CELL, (cx + 1) * CELL, window.x0, x1);
                out.exact.set(base + i, column.range_of(xs));
            }
        }
        haloed.min.copy_from_slice(&column.min);
        haloed.max.copy_from_slice(&column.max);
        for y in [(cy * CELL).wrapping_sub(HALO), (cy + 1) * CELL + HALO - 1] {
            if (window.y0..y1).contains(&y) {
                haloed.fold_row(row(y));
            }
        }
        let base = (cy - out.haloed_cells[0].start) as usize * hw;
        for (i, cx) in out.haloed_cells[1].clone().enumerate() {
            let xs = inside(
                (cx * CELL).saturating_sub(HALO),
                (cx + 1) * CELL + HALO,
                window.x0,
                x1,
            );
            out.haloed.set(base + i, haloed.range_of(xs));
        }
    }
    out
}

/// Cell rows per chunk of the min/max arrays: the rows written at once.
pub const CHUNK_ROWS: u64 = 8;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::convert::sink::planes_of;
    use crate::regions::histograms::LevelHistograms;

    /// A partition's rows of cells see what the whole grid sees there, and merge back into it.
    /// Columns of a plane, in any order and not on cell edges, fold into the cells what the
    /// whole plane does, halos across column edges included.
    #[test]
    fn columns_see_what_whole_planes_see() {
        let shape = [12, 30, 37];
        let values: Vec<u16> = (0..12 * 30 * 37)
            .map(|i| (i * 7919 % 1009) as u16)
            .collect();
        let plane = PlaneRegion::whole([30, 37]);
        let mut whole = CellGrid::<u16>::for_shape(1, shape);
        whole.add_slab(&planes_of(&values, 12, 30 * 37), 0, 12, plane);
        let mut cut = CellGrid::<u16>::for_shape(1, shape);
        for (y0, ny, x0, nx) in [
            (13, 17, 20, 17),
            (0, 13, 0, 20),
            (13, 17, 0, 20),
            (0, 13, 20, 17),
        ] {
            let region = PlaneRegion { y0, x0, ny, nx };
            let slab: Vec<u16> = (0..12)
                .flat_map(|z| {
                    let values = &values;
                    (y0..y0 + ny).flat_map(move |y| {
                        let row = ((z * 30 + y) * 37) as usize;
                        values[row + x0 as usize..row + (x0 + nx) as usize]
                            .iter()
                            .copied()
                    })
                })
                .collect();
            cut.add_slab(&planes_of(&slab, 12, region.area() as usize), 0, 12, region);
        }
        assert_eq!(cut.haloed, whole.haloed);
        assert_eq!(cut.exact, whole.exact);
    }

    /// A window that slides down the level (rows taken out as they become final) sees what
    /// the whole grid sees, and its histograms come out row by row.
    #[test]
    fn sliding_windows_give_the_whole_grid_row_by_row() {
        let shape = [40, 8, 8];
        let values: Vec<u16> = (0..40 * 64).map(|i| (i * 13 % 977) as u16).collect();
        let plane = PlaneRegion::whole([8, 8]);
        let mut whole = CellGrid::<u16>::for_shape(1, shape);
        whole.add_slab(&planes_of(&values, 40, 64), 0, 40, plane);
        let mut window = CellGrid::<u16>::window(1, [1, 1], 0..0, 5);
        let mut rows = CellGrid::<u16>::window(1, [1, 1], 0..0, 5);
        for z0 in (0..40).step_by(6) {
            let nz = 6.min(40 - z0);
            window.add_slab(
                &planes_of(
                    &values[(z0 * 64) as usize..((z0 + nz) * 64) as usize],
                    nz as usize,
                    64,
                ),
                z0,
                nz,
                plane,
            );
            // Rows whose halo ends before the next plane are final.
            let done = window.split_before((z0 + nz - HALO) / CELL);
            assert_eq!(done.z0, rows.rows().end);
            rows.extend_to(done.rows().end);
            rows.merge(&done);
            assert!(window.grid[0] <= 3, "{:?}", window.rows());
        }
        let last = window.split_before(u64::MAX);
        rows.extend_to(last.rows().end);
        rows.merge(&last);
        assert_eq!(rows.rows(), 0..5);
        assert_eq!(rows.haloed, whole.haloed);
        assert_eq!(rows.exact, whole.exact);

        let mut histograms = LevelHistograms::for_rows(2, [5, 1, 2], 0..0);
        histograms.extend_to(3, 5);
        for b in 0..3 {
            let i = histograms.index(1, [b, 0, 1]);
            histograms.fine.get_mut().unwrap()[i].first_key = b as u32 + 10;
        }
        let front = histograms.split_before(2);
        assert_eq!((front.origin, front.bricks), ([0, 0, 0], [2, 1, 2]));
        assert_eq!((histograms.z0, histograms.bricks), (2, [1, 1, 2]));
        assert_eq!(
            front.fine.iter().map(|h| h.first_key).collect::<Vec<_>>(),
            [0, 0, 0, 0, 0, 10, 0, 11]
        );
        let mut column = LevelHistograms::block(1, 4..6, 2..3, 1..3);
        let i = column.index(0, [5, 2, 2]);
        assert_eq!(i, 3);
        column.fine.get_mut().unwrap()[i].first_key = 7;
        let block = column.split_before(u64::MAX);
        assert_eq!((block.origin, block.bricks), ([4, 2, 1], [2, 1, 2]));
        assert_eq!(block.fine[3].first_key, 7);
        histograms.extend_to(9, 5);
        assert_eq!(histograms.bricks, [3, 1, 2]);
        let i = histograms.index(1, [2, 0, 1]);
        assert_eq!(histograms.fine.get_mut().unwrap()[i].first_key, 12);
    }

    #[test]
    fn row_windows_see_and_merge_what_the_whole_grid_sees() {
        let shape = [40, 8, 8];
        let values: Vec<u16> = (0..40 * 64).map(|i| (i * 7 % 1000) as u16).collect();
        let mut whole = CellGrid::<u16>::for_shape(1, shape);
        whole.add_slab(
            &planes_of(&values, 40, 64),
            0,
            40,
            PlaneRegion::whole([shape[1], shape[2]]),
        );
        let mut merged = CellGrid::<u16>::for_shape(1, shape);
        for planes in [0..16, 16..24, 24..40] {
            let mut part = CellGrid::<u16>::for_rows(1, shape, planes.clone());
            let slab = &values[(planes.start * 64) as usize..(planes.end * 64) as usize];
            part.add_slab(
                &planes_of(slab, (planes.end - planes.start) as usize, 64),
                planes.start,
                planes.end - planes.start,
                PlaneRegion::whole([shape[1], shape[2]]),
            );
            merged.merge(&part);
        }
        let rows = CellGrid::<u16>::for_rows(1, shape, 16..24);
        assert_eq!((rows.z0, rows.grid, rows.depth), (1, [3, 1, 1], 5));
        assert_eq!(merged.haloed, whole.haloed);
        assert_eq!(merged.exact, whole.exact);
        let histograms = LevelHistograms::for_rows(2, [5, 2, 2], 3..9);
        assert_eq!((histograms.z0, histograms.bricks), (3, [2, 2, 2]));
        assert_eq!(histograms.index(1, [4, 1, 0]), 14);
    }

    #[test]
    fn haloed_cells_include_neighbours() {
        assert_eq!(cells_of(0, 4), 0..=0);
        assert_eq!(cells_of(7, 4), 0..=1);
        assert_eq!(cells_of(8, 4), 0..=1);
        assert_eq!(cells_of(9, 4), 1..=1);
        assert_eq!(cells_of(31, 4), 3..=3);
    }

    #[test]
    fn a_cell_of_both_zeros_is_written_as_0_whichever_comes_first() {
        // 1 × 1 × 8 planes: one cell of zeros, -0.0 first or last.
        for first in [-0.0f32, 0.0] {
            let mut plane = [-first; 8];
            plane[0] = first;
            let mut g = CellGrid::<f32>::for_shape(1, [1, 1, 8]);
            g.add_slab(&planes_of(&plane, 1, 8), 0, 1, PlaneRegion::whole([1, 8]));
            for exact in [true, false] {
                let bits: Vec<u32> = g
                    .to_min_max_array(exact)
                    .iter()
                    .map(|v| v.to_bits())
                    .collect();
                assert_eq!(bits, [0, 0], "-0.0 first: {}", first.is_sign_negative());
            }
        }
        // Other values keep their sign.
        let mut g = CellGrid::<f32>::for_shape(1, [1, 1, 2]);
        g.add_slab(
            &planes_of(&[-1.5, 2.0], 1, 2),
            0,
            1,
            PlaneRegion::whole([1, 2]),
        );
        assert_eq!(g.to_min_max_array(true), [-1.5, 2.0]);
    }

    #[test]
    fn cell_ranges_cover_the_halo() {
        // 1 × 1 × 20 volume: value = x.
        let slab: Vec<u16> = (0..20).collect();
        let mut g = CellGrid::<u16>::for_shape(1, [1, 1, 20]);
        g.add_slab(&planes_of(&slab, 1, 20), 0, 1, PlaneRegion::whole([1, 20]));
        assert_eq!(g.grid, [1, 1, 3]);
        assert_eq!(g.haloed.min, [0, 7, 15]);
        assert_eq!(g.haloed.max, [8, 16, 19]);
        assert_eq!(g.exact.min, [0, 8, 16]);
        assert_eq!(g.exact.max, [7, 15, 19]);
        let c = g.coarsen();
        assert_eq!(
            (c.haloed.min.clone(), c.haloed.max.clone()),
            (vec![0, 15], vec![16, 19])
        );
        assert_eq!(
            (c.exact.min.clone(), c.exact.max.clone()),
            (vec![0, 16], vec![15, 19])
        );
    }
}
