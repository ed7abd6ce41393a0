//! The methods side by side: Table 1 (ours against the paper's baselines, beside the paper's
//! ratios), the other papers' renderers against the octree baseline and ours, and ours against
//! the limit probe.

use std::fmt::Write as _;

use super::format::{mb, opt, psnr, ratio, time_of, time_unit};
use crate::bench::experiment::Experiment;
use crate::bench::paper::{RASTERIZE_PAPER, paper_row, sparseleap_row};
use crate::bench::records::{BenchResults, ProbeRecord, RunRecord};
use crate::gpu::probe::ProbeFilter;

/// The Table-1 runs of one results file: page table, octree, ours, ours without skipping.
pub(super) struct Table1Row<'a> {
    results: &'a BenchResults,
    by: [Option<&'a RunRecord>; 4],
}

/// The Table-1 rows of `all`, one per results file with Table-1 runs.
pub(super) fn table1_rows(all: &[BenchResults]) -> Vec<Table1Row<'_>> {
    all.iter()
        .filter(|r| r.runs.iter().any(|x| x.experiment == Experiment::Table1))
        .map(|r| {
            let find = |label: &str| {
                r.runs
                    .iter()
                    .find(|x| x.experiment == Experiment::Table1 && x.label == label)
            };
            Table1Row {
                results: r,
                by: [
                    find("page-table"),
                    find("octree"),
                    find("residency"),
                    find("residency (no skipping)"),
                ],
            }
        })
        .collect()
}

/// Our samples per second against the limit probe's (`gpu::probe`), per dataset with both:
/// the renderer's share of what sampling alone costs on the device.
pub(super) fn probe_table(out: &mut String, all: &[BenchResults]) {
    let rows: Vec<(&BenchResults, &RunRecord)> = all
        .iter()
        .filter(|r| !r.probe.is_empty() || r.probe_error.is_some())
        .filter_map(|r| {
            r.runs
                .iter()
                .find(|x| x.experiment == Experiment::Table1 && x.label == "residency")
                .map(|x| (r, x))
        })
        .collect();
    if rows.is_empty() {
        return;
    }
    let _ = writeln!(
        out,
        "| Dataset | ch | Ours M samples/s | Probe manual M samples/s | Ours / manual | Probe hardware M samples/s | Ours / hardware | Probe PSNR dB |\n|---|---|---|---|---|---|---|---|"
    );
    for (r, ours) in rows {
        let ours_rate = ours.gpu_ms.map_or(ours.wall_ms, |g| g).recip() * ours.samples * 1e3;
        let by = |filter: ProbeFilter| r.probe.iter().find(|p| p.filter == filter);
        let rate = |p: Option<&ProbeRecord>| {
            p.map_or_else(|| "–".into(), |p| format!("{:.2}", p.samples_per_s / 1e6))
        };
        let share = |p: Option<&ProbeRecord>| {
            p.map_or_else(
                || "–".into(),
                |p| format!("{:.0}%", 100.0 * ours_rate / p.samples_per_s),
            )
        };
        let note = r
            .probe_error
            .as_ref()
            .map_or_else(String::new, |e| format!(" (no probe: {e})"));
        let _ = writeln!(
            out,
            "| {}{note} | {} | {:.2} | {} | {} | {} | {} | {} |",
            r.dataset.label,
            r.dataset.visible_channels,
            ours_rate / 1e6,
            rate(by(ProbeFilter::Manual)),
            share(by(ProbeFilter::Manual)),
            rate(by(ProbeFilter::Hardware)),
            share(by(ProbeFilter::Hardware)),
            by(ProbeFilter::Manual).map_or_else(|| "–".into(), |p| psnr(p.psnr_db)),
        );
    }
}

/// Table 1 of `all` (the datasets with Table-1 runs), in full or as the README's `summary`.
pub(super) fn table1(out: &mut String, all: &[BenchResults], summary: bool) {
    let rows = table1_rows(all);
    if rows.is_empty() {
        return;
    }
    let (gpu, unit) = time_unit(rows.iter().flat_map(|r| r.by.iter().flatten().copied()));
    let t = |x: Option<&RunRecord>| x.map(|x| time_of(x, gpu));
    let m = |x: Option<&RunRecord>| x.map(|x| x.resident_bytes);
    if summary {
        let _ = writeln!(
            out,
            "| Dataset | ch | MRMCPT {unit} | Octree {unit} | Ours {unit} | no-skip {unit} | MRMCPT/Ours (paper) | Octree/Ours (paper) | resident MB MRMCPT / Octree / Ours | memory ratios (paper) |\n|---|---|---|---|---|---|---|---|---|---|"
        );
    } else {
        let _ = writeln!(
            out,
            "| Dataset | ch | MRMCPT {unit} | Octree {unit} | Ours {unit} | no-skip {unit} | MRMCPT/Ours | paper | Octree/Ours | paper | wall ms MRMCPT / Octree / Ours | resident MB MRMCPT / Octree / Ours | MRMCPT/Ours mem | paper | Octree/Ours mem | paper | PSNR dB MRMCPT / Octree / Ours / no-skip |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
        );
    }
    for row in &rows {
        let r = row.results;
        let [pt, oc, ours, ns] = row.by;
        let paper = r
            .dataset
            .sample_kind()
            .and_then(|k| paper_row(k, r.dataset.visible_channels));
        let pr = |i: usize| {
            paper.map_or_else(
                || "–".into(),
                |p| format!("{:.2}× ({} {}ch)", p.ms[i] / p.ms[2], p.dataset, p.channels),
            )
        };
        let prm =
            |i: usize| paper.map_or_else(|| "–".into(), |p| format!("{:.2}×", p.gb[i] / p.gb[2]));
        let ms = |x: Option<&RunRecord>| opt(t(x), 1);
        let mbs = |x: Option<&RunRecord>| x.map_or_else(|| "–".into(), |x| mb(x.resident_bytes));
        // The columns both tables start with; then the ratios, baselines over ours, of time and
        // of memory, and the resident MB of the three methods.
        let _ = write!(
            out,
            "| {} | {} | {} | {} | {} | {} |",
            r.dataset.label,
            r.dataset.visible_channels,
            ms(pt),
            ms(oc),
            ms(ours),
            ms(ns),
        );
        let time_ratio = [ratio(t(pt), t(ours)), ratio(t(oc), t(ours))];
        let mem_ratio = [ratio(m(pt), m(ours)), ratio(m(oc), m(ours))];
        let resident = format!("{} / {} / {}", mbs(pt), mbs(oc), mbs(ours));
        if summary {
            let _ = writeln!(
                out,
                " {} ({}) | {} ({}) | {resident} | {} ({}), {} ({}) |",
                time_ratio[0],
                pr(0).split(' ').next().unwrap_or("–"),
                time_ratio[1],
                pr(1).split(' ').next().unwrap_or("–"),
                mem_ratio[0],
                prm(0),
                mem_ratio[1],
                prm(1),
            );
        } else {
            let wall = |x: Option<&RunRecord>| {
                x.map_or_else(|| "–".into(), |x| format!("{:.1}", x.wall_ms))
            };
            let ps = |x: Option<&RunRecord>| x.map_or_else(|| "–".into(), |x| psnr(x.psnr_db));
            let _ = writeln!(
                out,
                " {} | {} | {} | {} | {} / {} / {} | {resident} | {} | {} | {} | {} | {} / {} / {} / {} |",
                time_ratio[0],
                pr(0),
                time_ratio[1],
                pr(1),
                wall(pt),
                wall(oc),
                wall(ours),
                mem_ratio[0],
                prm(0),
                mem_ratio[1],
                prm(1),
                ps(pt),
                ps(oc),
                ps(ours),
                ps(ns),
            );
        }
    }
}

/// The other papers' renderers beside ours and the octree baseline: each one's time, its
/// speed-up over the per-ray octree (the comparison its paper makes) beside the paper's, and
/// ours against it.
pub(super) fn seed_table(out: &mut String, all: &[BenchResults], summary: bool) {
    let rows: Vec<(&BenchResults, [Option<&RunRecord>; 4])> = all
        .iter()
        .filter_map(|r| {
            let find = |label: &str| {
                r.runs
                    .iter()
                    .find(|x| x.experiment == Experiment::Table1 && x.label == label)
            };
            let by = [
                find("octree"),
                find("sparseleap"),
                find("rasterize"),
                find("residency"),
            ];
            (by[1].is_some() || by[2].is_some()).then_some((r, by))
        })
        .collect();
    if rows.is_empty() {
        return;
    }
    let (gpu, unit) = time_unit(rows.iter().flat_map(|(_, by)| by.iter().flatten().copied()));
    let t = |x: Option<&RunRecord>| x.map(|x| time_of(x, gpu));
    let ms = |x: Option<&RunRecord>| opt(t(x), 1);
    let [lo, median, hi] = RASTERIZE_PAPER;
    let raster_paper = format!("{median:.2}× ({lo:.2}–{hi:.2}×)");
    if summary {
        let _ = writeln!(
            out,
            "| Dataset | ch | Octree {unit} | SparseLeap {unit} | Rasterize {unit} | Ours {unit} | Octree/SparseLeap (paper) | Octree/Rasterize (paper) | SparseLeap/Ours | Rasterize/Ours |\n|---|---|---|---|---|---|---|---|---|---|"
        );
    } else {
        let _ = writeln!(
            out,
            "| Dataset | ch | Octree {unit} | SparseLeap {unit} | Rasterize {unit} | Ours {unit} | Octree/SparseLeap | SparseLeap paper | Octree/Rasterize | Rasterize paper | SparseLeap/Ours | Rasterize/Ours | resident MB SparseLeap / Rasterize / Ours | samples/frame SparseLeap / Rasterize / Ours | boxes rasterised SparseLeap / Rasterize | PSNR dB SparseLeap / Rasterize / Ours |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
        );
    }
    for (r, [oc, sl, ra, ours]) in &rows {
        let leap = r
            .dataset
            .sample_kind()
            .and_then(sparseleap_row)
            .map_or_else(
                || "–".into(),
                |p| format!("{:.2}× ({})", p.speedup(), p.dataset),
            );
        let _ = write!(
            out,
            "| {} | {} | {} | {} | {} | {} |",
            r.dataset.label,
            r.dataset.visible_channels,
            ms(*oc),
            ms(*sl),
            ms(*ra),
            ms(*ours),
        );
        let (oc_sl, oc_ra) = (ratio(t(*oc), t(*sl)), ratio(t(*oc), t(*ra)));
        let (sl_ours, ra_ours) = (ratio(t(*sl), t(*ours)), ratio(t(*ra), t(*ours)));
        if summary {
            let _ = writeln!(
                out,
                " {oc_sl} ({}) | {oc_ra} ({median:.2}×) | {sl_ours} | {ra_ours} |",
                leap.split(' ').next().unwrap_or("–"),
            );
        } else {
            let three = |f: &dyn Fn(&RunRecord) -> String| {
                [*sl, *ra, *ours]
                    .map(|x| x.map_or_else(|| "–".into(), f))
                    .join(" / ")
            };
            let boxes = [*sl, *ra]
                .map(|x| {
                    x.map_or_else(
                        || "–".into(),
                        |x| {
                            format!(
                                "{:.0}",
                                x.views.iter().map(|v| v.segment_boxes as f64).sum::<f64>()
                                    / x.views.len().max(1) as f64
                            )
                        },
                    )
                })
                .join(" / ");
            let _ = writeln!(
                out,
                " {oc_sl} | {leap} | {oc_ra} | {raster_paper} | {sl_ours} | {ra_ours} | {} | {} | {boxes} | {} |",
                three(&|x| mb(x.resident_bytes)),
                three(&|x| format!("{:.0}", x.samples)),
                three(&|x| psnr(x.psnr_db)),
            );
        }
    }
}

/// Our converged frame's wall time with the image read back (as `viewer render` and the CPU
/// blit need it) and without (as `viewer view` presents on the GPU), per dataset with both:
/// what the readback costs. Nothing when no results file has the second.
pub(super) fn readback_table(out: &mut String, all: &[BenchResults]) {
    let rows: Vec<(&BenchResults, &RunRecord, f64)> = all
        .iter()
        .filter_map(|r| {
            let x = r
                .runs
                .iter()
                .find(|x| x.experiment == Experiment::Table1 && x.label == "residency")?;
            Some((r, x, x.wall_ms_without_readback?))
        })
        .collect();
    if rows.is_empty() {
        return;
    }
    let _ = writeln!(
        out,
        "| Dataset | pixels | wall ms with readback | wall ms without | readback share |\n|---|---|---|---|---|"
    );
    for (r, x, without) in rows {
        let share = if x.wall_ms > 0.0 {
            format!("{:.0} %", 100.0 * (x.wall_ms - without) / x.wall_ms)
        } else {
            "–".into()
        };
        let _ = writeln!(
            out,
            "| {} | {}×{} | {:.2} | {:.2} | {share} |",
            r.dataset.label, r.settings.width, r.settings.height, x.wall_ms, without
        );
    }
}
