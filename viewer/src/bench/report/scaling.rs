//! Scaling: the residency octree's frame time and bytes against volume size and channel
//! count, as a table and two plots.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::format::{mb, psnr, time_of, time_unit};
use crate::bench::experiment::Experiment;
use crate::bench::plots::{self, PlotError, ScalingSeries};
use crate::bench::records::{BenchResults, RunRecord};

/// The scaling series of `runs`: one per distinct `key` with more than one distinct `x`, its
/// points `(x, value)` ascending in `x` (the first run of each `x` kept), labelled `label(key)`.
fn scaling_series<K: Ord>(
    runs: &[(&BenchResults, &RunRecord)],
    key: impl Fn(&BenchResults, &RunRecord) -> K,
    x: impl Fn(&BenchResults, &RunRecord) -> f64,
    label: impl Fn(&K) -> String,
    value: impl Fn(&RunRecord) -> [f64; 3],
) -> Vec<ScalingSeries> {
    let mut keys: Vec<K> = runs.iter().map(|&(r, run)| key(r, run)).collect();
    keys.sort();
    keys.dedup();
    keys.into_iter()
        .filter_map(|k| {
            let mut pts: Vec<(f64, [f64; 3])> = runs
                .iter()
                .filter(|&&(r, run)| key(r, run) == k)
                .map(|&(r, run)| (x(r, run), value(run)))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            pts.dedup_by(|a, b| a.0 == b.0);
            (pts.len() > 1).then(|| ScalingSeries {
                label: label(&k),
                points: pts,
            })
        })
        .collect()
}

/// The scaling table of `all`'s scaling runs and its plots in `dir` (added to `plots`).
pub(super) fn scaling(
    out: &mut String,
    all: &[BenchResults],
    dir: &Path,
    plots_written: &mut Vec<PathBuf>,
) -> Result<(), PlotError> {
    let runs: Vec<(&BenchResults, &RunRecord)> = all
        .iter()
        .flat_map(|r| {
            r.runs
                .iter()
                .filter(|x| x.experiment == Experiment::Scaling)
                .map(move |x| (r, x))
        })
        .collect();
    if runs.is_empty() {
        return Ok(());
    }
    let (gpu, unit) = time_unit(runs.iter().map(|&(_, x)| x));
    let _ = writeln!(out, "\n## Scaling\n");
    let _ = writeln!(
        out,
        "The residency octree with the defaults over the same orbit; frame time is {unit} per converged frame, resident bytes the bricks a converged frame read, fetched bytes the whole orbit from a cold cache.\n"
    );
    let _ = writeln!(
        out,
        "| Dataset | kind | voxels | channels | {unit} | wall ms | resident MB | fetched MB (orbit) | cold MB (first view) | PSNR dB |\n|---|---|---|---|---|---|---|---|---|---|"
    );
    for (r, x) in &runs {
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} | {:.1} | {:.1} | {} | {} | {} | {} |",
            r.dataset.label,
            r.dataset.kind,
            r.dataset.voxels,
            x.channels,
            time_of(x, gpu),
            x.wall_ms,
            mb(x.resident_bytes),
            mb(x.bytes_fetched as f64),
            mb(x.cold_bytes_fetched as f64),
            psnr(x.psnr_db)
        );
    }
    let value = |x: &RunRecord| {
        [
            time_of(x, gpu),
            x.resident_bytes / 1e6,
            x.bytes_fetched as f64 / 1e6,
        ]
    };
    // Size series: same kind and channel count, several sizes; channel series: same kind and
    // size, several channel counts.
    let size_series = scaling_series(
        &runs,
        |r, x| (r.dataset.kind.clone(), x.channels),
        |r, _| r.dataset.voxels as f64,
        |(kind, ch)| format!("{kind}, {ch} ch"),
        value,
    );
    let chan_series = scaling_series(
        &runs,
        |r, _| (r.dataset.kind.clone(), r.dataset.voxels),
        |_, x| x.channels as f64,
        |(kind, vox)| format!("{kind}, {vox} voxels"),
        value,
    );
    let adapter = &runs[0].0.device.adapter;
    let figures = [
        (
            size_series,
            "scaling-size.png",
            "volume size",
            "level-0 voxels per channel",
            true,
        ),
        (
            chan_series,
            "scaling-channels.png",
            "channel count",
            "visible channels",
            false,
        ),
    ];
    for (series, name, what, x_desc, log_x) in figures {
        if series.is_empty() {
            continue;
        }
        let p = dir.join(name);
        plots::scaling(
            &p,
            &format!("Scaling with {what} ({adapter})"),
            x_desc,
            log_x,
            &series,
        )?;
        let _ = writeln!(out, "\n![scaling with {what}]({name})\n");
        plots_written.push(p);
    }
    Ok(())
}
