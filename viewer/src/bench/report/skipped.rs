//! Skipped work against the naive frustum loader: per view and summed per results file.

use std::fmt::Write as _;

use super::format::{mb, opt, psnr};
use crate::bench::records::BenchResults;

/// The skipped-work table of every results file of `all` with skipped records.
pub(super) fn skipped(out: &mut String, all: &[BenchResults]) {
    let with: Vec<&BenchResults> = all.iter().filter(|r| !r.skipped.is_empty()).collect();
    if with.is_empty() {
        return;
    }
    let _ = writeln!(out, "\n## Skipped work against a naive loader\n");
    let _ = writeln!(
        out,
        "Naive: every brick of the level the LOD rule picks at the distance of the volume centre (the shader's `footprint_level` and `channel_level`) whose box meets the view frustum, for every visible channel; its bytes count the bricks that hold data (fill-value bricks are not stored), its image is a ray caster without skipping pinned to that level. Ours: the residency octree with the defaults from a cold cache until a frame requests nothing, converging to the naive loader's level (coarser levels stand in while bricks stream, and count in its bytes), so both have the same error. \"Ours read\" is the bricks holding data that our converged frame read: any loader has to deliver them to draw this image, so naive/read is the ceiling of the bytes ratio at this error, whatever a loader skips (occlusion included: a converged ray reads nothing behind the point where it became opaque). \"Empty\" bricks are transparent under the transfer function by their conservative (haloed) range, so the counts are lower bounds; ours never fetches such a brick, since every trilinear footprint that reaches it lies in that range and so has opacity exactly 0. Bytes are decoded bytes. Per view, then the sum.\n"
    );
    let _ = writeln!(
        out,
        "| Dataset | view ° | naive level | naive bricks (fill / empty under TF) | naive MB | ours bricks fetched | ours MB | naive/ours bytes | ours read (converged) | ceiling naive/read | ours requested (empty under TF) | samples naive / ours | PSNR dB naive / ours |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for r in with {
        for s in &r.skipped {
            let _ = writeln!(
                out,
                "| {} | {:.0} | {} | {} ({} / {}) | {} | {} | {} | {} | {} | {} | {} ({}) | {} / {} | {} / {} |",
                r.dataset.label,
                s.azimuth,
                s.naive_level,
                s.naive_bricks,
                s.naive_fill_bricks,
                s.naive_empty_bricks,
                mb(s.naive_bytes as f64),
                s.ours_bricks_fetched,
                mb(s.ours_bytes_fetched as f64),
                opt(s.bytes_ratio, 2),
                s.ours_bricks_read,
                opt(s.bytes_ceiling, 2),
                s.ours_bricks_requested,
                s.ours_requested_empty,
                s.naive_samples,
                s.ours_samples,
                psnr(s.naive_psnr_db),
                psnr(s.ours_psnr_db),
            );
        }
        let t = SkippedTotals::of(r);
        let _ = writeln!(
            out,
            "| **{} total** | | | | {} | | {} | {} | {} | {} | | | |",
            r.dataset.label,
            mb(t.naive as f64),
            mb(t.fetched as f64),
            opt(t.ratio(), 2),
            t.bricks_read,
            opt(t.ceiling(), 2),
        );
    }
}

/// Decoded bytes over every skipped record of one results file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct SkippedTotals {
    /// The naive loader's.
    pub naive: u64,
    /// Ours fetched.
    pub fetched: u64,
    /// Bricks our converged frames read.
    pub bricks_read: u64,
    /// Bytes of one brick.
    pub brick_bytes: u64,
}

impl SkippedTotals {
    /// The totals of `r`'s skipped records.
    pub(crate) fn of(r: &BenchResults) -> Self {
        Self {
            naive: r.skipped.iter().map(|s| s.naive_bytes).sum(),
            fetched: r.skipped.iter().map(|s| s.ours_bytes_fetched).sum(),
            bricks_read: r.skipped.iter().map(|s| s.ours_bricks_read).sum(),
            brick_bytes: r.dataset.sample_type.block_bytes(r.dataset.brick_shape),
        }
    }

    /// Naive over ours fetched (`None` if ours fetched nothing).
    pub(crate) fn ratio(&self) -> Option<f64> {
        (self.fetched > 0).then(|| self.naive as f64 / self.fetched as f64)
    }

    /// The ceiling of [`SkippedTotals::ratio`]: naive over the bricks our converged frames
    /// read (`None` if they read nothing).
    pub(crate) fn ceiling(&self) -> Option<f64> {
        let read = self.bricks_read * self.brick_bytes;
        (read > 0).then(|| self.naive as f64 / read as f64)
    }
}
