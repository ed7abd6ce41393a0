//! What a finished conversion reports ([`ConvertSummary`]).

use std::fmt::Write;
use std::path::PathBuf;

use crate::columns::ColumnPlan;
use crate::sample_format::SampleType;

/// What one level of a finished conversion holds.
#[derive(Clone, Debug, PartialEq)]
pub struct LevelSummary {
    /// Shape `c, z, y, x`.
    pub shape: [u64; 4],
    /// Bricks written (all channels).
    pub bricks_written: u64,
    /// Bricks equal to the fill value everywhere, not written.
    pub bricks_empty: u64,
}

/// The end-of-run report of a conversion.
#[derive(Clone, Debug, PartialEq)]
pub struct ConvertSummary {
    /// Path of the finished store.
    pub output: PathBuf,
    /// Sample format of the store.
    pub format: SampleType,
    /// Per-level results, finest first.
    pub levels: Vec<LevelSummary>,
    /// Bytes of level-0 voxels (uncompressed).
    pub input_bytes: u64,
    /// Bytes of the whole store on disk.
    pub stored_bytes: u64,
    /// Bytes of the level-0 image array on disk.
    pub level0_stored_bytes: u64,
    /// Bytes of the region metadata (arrays and attributes) on disk.
    pub metadata_bytes: u64,
    /// Wall time in seconds.
    pub seconds: f64,
    /// The columns the planes were cut into, when they were (see [`crate::columns`]).
    pub columns: Option<ColumnPlan>,
    /// Level-0 planes (of all channels) read in place from the input files, not copied (see
    /// [`ConvertOptions::map_inputs`](super::ConvertOptions::map_inputs)).
    pub planes_in_place: u64,
}

/// The report line of the planes read in place out of `planes`, or nothing when none was.
pub(crate) fn in_place_report(in_place: u64, planes: u64) -> String {
    if in_place == 0 {
        return String::new();
    }
    format!("  {in_place} of {planes} planes read in place from the input files (memory-mapped)\n")
}

/// The report line of a pass made in columns, or nothing for whole planes.
pub(crate) fn columns_report(columns: Option<&ColumnPlan>, plane: [u64; 2]) -> String {
    columns.map_or_else(String::new, |c| {
        format!(
            "  in {} columns of {}×{} voxels (levels 0 to {} column by column) to stay within the memory limit (estimated peak {:.1} MiB)\n",
            c.columns(plane).len(),
            c.edge[0].min(plane[0]),
            c.edge[1].min(plane[1]),
            c.local_levels - 1,
            c.estimate as f64 / f64::from(1 << 20)
        )
    })
}

impl ConvertSummary {
    /// Human-readable report printed by the command line.
    pub fn report(&self) -> String {
        let mut s = format!("wrote {} ({})\n", self.output.display(), self.format);
        for (i, l) in self.levels.iter().enumerate() {
            let _ = writeln!(
                s,
                "  level {i}: shape c,z,y,x = {:?}, bricks written {}, empty (not written) {}",
                l.shape, l.bricks_written, l.bricks_empty
            );
        }
        let mb = self.input_bytes as f64 / 1e6;
        let _ = writeln!(
            s,
            "  input {:.1} MB, stored {:.1} MB, level-0 compression ratio {:.2}, region metadata {:.3} MB ({:.2}% of the store)",
            mb,
            self.stored_bytes as f64 / 1e6,
            self.input_bytes as f64 / self.level0_stored_bytes.max(1) as f64,
            self.metadata_bytes as f64 / 1e6,
            100.0 * self.metadata_bytes as f64 / self.stored_bytes.max(1) as f64
        );
        let _ = writeln!(
            s,
            "  {:.2} s, {:.1} MB/s",
            self.seconds,
            mb / self.seconds.max(1e-9)
        );
        let plane = [self.levels[0].shape[2], self.levels[0].shape[3]];
        let [c, z, ..] = self.levels[0].shape;
        s + &in_place_report(self.planes_in_place, c * z)
            + &columns_report(self.columns.as_ref(), plane)
    }
}
