//! Run time against error, per results file with a sweep: the table of every configuration,
//! its Pareto front, the trade-off plot and the verdicts on the defaults.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::format::{dataset_line, device_line, mb, psnr, slug, time_of, time_unit};
use crate::bench::experiment::Experiment;
use crate::bench::pareto;
use crate::bench::plots::{self, PlotError, TradeoffPoint};
use crate::bench::records::{BenchResults, RunRecord, SweptParameter};
use crate::gpu::renderer::Method;

/// The plot label's prefix for a method other than ours.
fn method_prefix(method: Method) -> &'static str {
    match method {
        Method::Residency => "",
        Method::PageTable => "PT ",
        Method::Octree => "OC ",
        Method::SparseLeap => "SL ",
        Method::Rasterize => "RA ",
    }
}

/// The label of a sweep run in the plot: `s0.5`, `b-1`, …, prefixed for other methods.
fn short_label(r: &RunRecord) -> String {
    let own = match &r.sweep {
        Some(p) => match p.name {
            SweptParameter::Default => "default".into(),
            SweptParameter::Step => format!("s{}", p.value),
            SweptParameter::LodBias => format!("b{}", p.value),
            SweptParameter::CacheFraction => format!("c{}", p.value),
            SweptParameter::LeafVoxels => format!("l{}", p.value),
        },
        None => r.label.clone(),
    };
    format!("{}{own}", method_prefix(r.method))
}

/// The sweep of one results file: its table, plot (added to `plots_written`) and verdicts on
/// the defaults (added to `verdicts`).
pub(super) fn sweep(
    out: &mut String,
    r: &BenchResults,
    dir: &Path,
    index: usize,
    plots_written: &mut Vec<PathBuf>,
    verdicts: &mut Vec<String>,
) -> Result<(), PlotError> {
    let runs: Vec<&RunRecord> = r
        .runs
        .iter()
        .filter(|x| x.experiment == Experiment::Sweep)
        .collect();
    if runs.is_empty() {
        return Ok(());
    }
    let (gpu, unit) = time_unit(runs.iter().copied());
    let points: Vec<(f64, f64)> = runs
        .iter()
        .map(|x| (time_of(x, gpu), x.psnr_db.unwrap_or(f64::INFINITY)))
        .collect();
    let front = pareto::front(&points);
    let _ = writeln!(out, "\n### Time against error: {}\n", dataset_line(r));
    let _ = writeln!(
        out,
        "Device: {}. {}×{} pixels, {} views, median of {} converged frames per view. Each parameter is swept alone from the defaults, for ours and (step and LOD bias) for every other method; the cache budget is a fraction of the defaults' working set (the most bricks one view read). Time is {unit} per converged frame, error is against the f64 reference of the same view (mean over views; max abs is the largest).\n",
        device_line(r),
        r.settings.width,
        r.settings.height,
        r.settings.views,
        r.settings.timed_frames
    );
    let _ = writeln!(
        out,
        "| Configuration | {unit} | wall ms | resident MB | samples/frame | PSNR dB | SSIM | max abs | converged views | Pareto |\n|---|---|---|---|---|---|---|---|---|---|"
    );
    for (i, x) in runs.iter().enumerate() {
        let _ = writeln!(
            out,
            "| {}{} | {:.1} | {:.1} | {} | {:.0} | {} | {:.4} | {:.4} | {}/{} | {} |",
            x.label,
            if x.is_default { " **(defaults)**" } else { "" },
            time_of(x, gpu),
            x.wall_ms,
            mb(x.resident_bytes),
            x.samples,
            psnr(x.psnr_db),
            x.ssim,
            x.max_abs_error,
            x.converged_views,
            x.views.len(),
            if front.contains(&i) { "on front" } else { "" }
        );
    }
    let name = format!("sweep-{index}-{}.png", slug(&r.dataset.label));
    let path = dir.join(&name);
    let tp: Vec<TradeoffPoint> = runs
        .iter()
        .enumerate()
        .map(|(i, x)| TradeoffPoint {
            label: short_label(x),
            ms: points[i].0,
            psnr: x.psnr_db.unwrap_or(
                points
                    .iter()
                    .map(|p| p.1)
                    .filter(|v| v.is_finite())
                    .fold(0.0, f64::max)
                    + 1.0,
            ),
            front: front.contains(&i),
            default: x.is_default,
            group: x.method.name().to_string(),
        })
        .collect();
    plots::tradeoff(
        &path,
        &format!("{}: {unit} vs PSNR ({})", r.dataset.label, r.device.adapter),
        &format!("{unit} per converged frame"),
        &tp,
    )?;
    plots_written.push(path);
    let _ = writeln!(
        out,
        "\n![time against error, {}]({name})\n\nLabels: `s` step, `b` LOD bias, `c` cache fraction, `l` leaf voxels, prefixed `PT` (page table), `OC` (octree), `SL` (SparseLeap) or `RA` (rasterize) for the other methods' runs, one colour per method; the black ring is ours at its defaults; red rings and the line are the Pareto front over every method.\n",
        r.dataset.label
    );
    // Verdicts: the defaults against the whole front, and against each parameter's own sweep.
    if let Some(d) = runs.iter().position(|x| x.is_default) {
        let on = front.contains(&d);
        let dp = points[d];
        let mut lines = vec![format!(
            "{}: defaults (step {}, LOD bias {}, leaf {} voxels, full cache) at {:.1} {unit}, {} dB: {} the Pareto front of all {} points",
            r.dataset.label,
            runs[d].options.step,
            runs[d].options.lod_bias,
            runs[d].options.leaf_voxels,
            dp.0,
            psnr(runs[d].psnr_db),
            if on { "on" } else { "OFF" },
            runs.len()
        )];
        for param in SweptParameter::SWEPT {
            let idx: Vec<usize> = (0..runs.len())
                .filter(|&i| {
                    i == d
                        || (runs[i].method == Method::Residency
                            && runs[i].sweep.as_ref().is_some_and(|p| p.name == param))
                })
                .collect();
            if idx.len() < 2 {
                continue;
            }
            let sub: Vec<(f64, f64)> = idx.iter().map(|&i| points[i]).collect();
            let f = pareto::front(&sub);
            let pos = idx.iter().position(|&i| i == d).unwrap_or(0);
            let dominators: Vec<String> = idx
                .iter()
                .filter(|&&i| {
                    i != d
                        && points[i].0 <= dp.0
                        && points[i].1 >= dp.1
                        && (points[i].0 < dp.0 || points[i].1 > dp.1)
                })
                .map(|&i| {
                    format!(
                        "{} ({:.1} {unit}, {} dB)",
                        runs[i].label,
                        points[i].0,
                        psnr(runs[i].psnr_db)
                    )
                })
                .collect();
            lines.push(if f.contains(&pos) {
                format!("  - {param}: the default is on the front of its sweep")
            } else {
                format!(
                    "  - {param}: the default is OFF the front of its sweep, dominated by {}",
                    dominators.join(", ")
                )
            });
        }
        // The other methods: where their defaults and their points stand on the same front.
        for method in Method::ALL.into_iter().filter(|&m| m != Method::Residency) {
            let own: Vec<usize> = (0..runs.len())
                .filter(|&i| runs[i].method == method)
                .collect();
            let Some(&def) = own.iter().find(|&&i| {
                runs[i]
                    .sweep
                    .as_ref()
                    .is_some_and(|p| p.name == SweptParameter::Default)
            }) else {
                continue;
            };
            let on_front = own.iter().filter(|i| front.contains(i)).count();
            lines.push(format!(
                "  - {}: defaults at {:.1} {unit}, {} dB, {} the front; {on_front} of its {} points on it",
                method.name(),
                points[def].0,
                psnr(runs[def].psnr_db),
                if front.contains(&def) { "on" } else { "off" },
                own.len()
            ));
        }
        write_verdicts(out, &lines);
        verdicts.extend(lines);
    }
    Ok(())
}

/// Writes verdict lines as a markdown list: a dataset's line as an item, its per-parameter
/// lines (already `  - …`) nested under it.
pub(super) fn write_verdicts(out: &mut String, lines: &[String]) {
    for l in lines {
        if l.starts_with("  -") {
            let _ = writeln!(out, "{l}");
        } else {
            let _ = writeln!(out, "- {l}");
        }
    }
}
