//! The benchmark report: markdown tables (Table 1 with the paper's ratios beside ours, the
//! time–error sweep with its Pareto front and a verdict on each default, skipped work against
//! the naive loader, scaling) and the PNG plots, from one or more results files.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::plots::{self, PlotError, ScalingSeries, TradeoffPoint};
use super::{BenchResults, Experiment, FORMAT, ProbeRecord, RunRecord, SweptParameter, pareto};
use crate::gpu::probe::ProbeFilter;
use crate::gpu::renderer::Method;

/// Why a report could not be written: a results file that cannot be read or is not one, or a
/// report file or plot that cannot be written. Messages name the file.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// No results file given.
    #[error("no results files given")]
    NoInputs,
    /// A results file that cannot be read.
    #[error("{}: cannot read", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A file that is not a results file.
    #[error("{}: not a render-bench results file", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: serde_json::Error,
    },
    /// A results file of another format version.
    #[error("{}: format {format:?}, expected {:?}", path.display(), FORMAT)]
    Format {
        /// The file.
        path: PathBuf,
        /// Its format tag.
        format: String,
    },
    /// The output folder cannot be created.
    #[error("{}: cannot create", path.display())]
    CreateDir {
        /// The folder.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A report file cannot be written.
    #[error("{}: cannot write", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A plot cannot be drawn or written.
    #[error(transparent)]
    Plot(#[from] PlotError),
}

/// Table 1 of the residency-octree paper: ms per frame and GPU memory (GB) per method.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PaperRow {
    /// Data set.
    pub dataset: &'static str,
    /// Channels rendered.
    pub channels: usize,
    /// MRMCPT, Octree, Ours: ms per frame.
    pub ms: [f64; 3],
    /// MRMCPT, Octree, Ours: GB per frame.
    pub gb: [f64; 3],
}

impl PaperRow {
    /// A row: data set, channels, then ms and GB per frame of MRMCPT, Octree and Ours.
    const fn new(dataset: &'static str, channels: usize, ms: [f64; 3], gb: [f64; 3]) -> Self {
        Self {
            dataset,
            channels,
            ms,
            gb,
        }
    }
}

/// The rows of the paper's Table 1 that our synthetic kinds stand in for.
pub const PAPER: [PaperRow; 5] = [
    PaperRow::new("Kingsnake", 1, [15.0, 11.6, 5.1], [0.66, 0.23, 0.13]),
    PaperRow::new("Kingsnake", 4, [42.5, 60.7, 19.8], [1.88, 0.89, 0.48]),
    PaperRow::new("Rayleigh–Taylor", 1, [11.2, 13.8, 6.4], [0.13, 0.06, 0.04]),
    PaperRow::new("Rayleigh–Taylor", 4, [24.3, 54.9, 20.0], [0.31, 0.19, 0.14]),
    PaperRow::new("CyCIF Small", 16, [34.0, 122.8, 25.7], [0.95, 0.46, 0.29]),
];

/// The paper row our dataset `kind` with `channels` visible channels stands in for: sparse →
/// Kingsnake, mixing (and dense, its worst case with no constant region) → Rayleigh–Taylor (1
/// or 4 channels), cycif → CyCIF Small (16).
pub fn paper_row(kind: &str, channels: usize) -> Option<&'static PaperRow> {
    let (name, ch) = match kind {
        "sparse" => ("Kingsnake", if channels > 1 { 4 } else { 1 }),
        "dense" | "mixing" => ("Rayleigh–Taylor", if channels > 1 { 4 } else { 1 }),
        "cycif" => ("CyCIF Small", 16),
        _ => return None,
    };
    PAPER.iter().find(|r| r.dataset == name && r.channels == ch)
}

/// A row of SparseLeap's Table 1 (Hadwiger et al., TVCG 2018): frames per second of octree
/// empty space skipping and of SparseLeap with rasterisation (no early ray termination,
/// 1200² pixels, GeForce Titan X), for one occupancy setting of one data set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LeapRow {
    /// Data set and occupancy of the enabled segments.
    pub dataset: &'static str,
    /// Octree frames per second.
    pub octree_fps: f64,
    /// SparseLeap (with rasterisation) frames per second.
    pub sparseleap_fps: f64,
}

impl LeapRow {
    /// SparseLeap's speed-up over the octree: octree time over SparseLeap time.
    pub fn speedup(&self) -> f64 {
        self.sparseleap_fps / self.octree_fps
    }
}

/// The SparseLeap rows our kinds stand in for: sparse → King Snake with 0.92% of its voxels
/// enabled, dense and mixing → King Snake at 59.57%, cycif → KESM Mouse Brain (59,162 small
/// segmented objects, microscopy) at 23.4%. Over all 16 rows of that table the speed-up runs
/// from 0.77× (Dreh Sensor, dense) to 2.43× (SEM Mouse Cortex, dense).
pub const SPARSELEAP_PAPER: [(&[&str], LeapRow); 3] = [
    (
        &["sparse"],
        LeapRow {
            dataset: "King Snake 0.92%",
            octree_fps: 8.5,
            sparseleap_fps: 15.0,
        },
    ),
    (
        &["dense", "mixing"],
        LeapRow {
            dataset: "King Snake 59.57%",
            octree_fps: 3.0,
            sparseleap_fps: 5.5,
        },
    ),
    (
        &["cycif"],
        LeapRow {
            dataset: "KESM Mouse Brain 23.4%",
            octree_fps: 18.0,
            sparseleap_fps: 24.0,
        },
    ),
];

/// Speed-ups of octree rasterisation over per-ray octree traversal in its paper's Table 1
/// (Wang et al.: nine CT data sets, 512² pixels, tricubic filtering): smallest, median,
/// largest. None of them is microscopy, so every kind is shown beside the whole range.
pub const RASTERIZE_PAPER: [f64; 3] = [2.18, 2.63, 4.23];

/// The SparseLeap row our dataset `kind` stands in for.
pub fn sparseleap_row(kind: &str) -> Option<&'static LeapRow> {
    SPARSELEAP_PAPER
        .iter()
        .find(|(kinds, _)| kinds.contains(&kind))
        .map(|(_, r)| r)
}

/// Reads and checks a results file.
///
/// # Errors
/// [`ReportError::Read`], [`ReportError::Parse`] or [`ReportError::Format`], naming the file.
pub fn read(path: &Path) -> Result<BenchResults, ReportError> {
    let bytes = std::fs::read(path).map_err(|source| ReportError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let r: BenchResults = serde_json::from_slice(&bytes).map_err(|source| ReportError::Parse {
        path: path.to_path_buf(),
        source,
    })?;
    if r.format != FORMAT {
        return Err(ReportError::Format {
            path: path.to_path_buf(),
            format: r.format,
        });
    }
    Ok(r)
}

fn mb(bytes: f64) -> String {
    format!("{:.2}", bytes / 1e6)
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "–".into(), |v| format!("{v:.digits$}"))
}

fn psnr(v: Option<f64>) -> String {
    v.map_or_else(|| "∞".into(), |v| format!("{v:.1}"))
}

/// Whether a set of runs is timed in GPU ms (every run has it) or else in wall ms, and the
/// unit's name.
fn time_unit<'a>(mut runs: impl Iterator<Item = &'a RunRecord>) -> (bool, &'static str) {
    if runs.all(|x| x.gpu_ms.is_some()) {
        (true, "GPU ms")
    } else {
        (false, "wall ms")
    }
}

/// The time of a run: GPU ms when every run of the set has it, else wall ms.
fn time_of(r: &RunRecord, gpu: bool) -> f64 {
    if gpu {
        r.gpu_ms.unwrap_or(f64::NAN)
    } else {
        r.wall_ms
    }
}

fn ratio(a: Option<f64>, b: Option<f64>) -> String {
    match (a, b) {
        (Some(a), Some(b)) if b > 0.0 => format!("{:.2}×", a / b),
        _ => "–".into(),
    }
}

/// Device line of a results file.
pub fn device_line(r: &BenchResults) -> String {
    format!(
        "{} ({}, {}), CPU {} × {} cores",
        r.device.adapter, r.device.backend, r.device.driver, r.device.cpu, r.device.cores
    )
}

fn dataset_line(r: &BenchResults) -> String {
    let d = &r.dataset;
    format!(
        "{} ({} {}, {}×{}×{} voxels z,y,x, bricks {}×{}×{}, {} levels, {} of {} channels rendered)",
        d.label,
        d.kind,
        d.sample_type.zarr_name(),
        d.shape[0],
        d.shape[1],
        d.shape[2],
        d.brick_shape[0],
        d.brick_shape[1],
        d.brick_shape[2],
        d.levels,
        d.visible_channels,
        d.channels
    )
}

/// What `viewer bench report` wrote.
#[derive(Clone, Debug, Default)]
pub struct Written {
    /// The full markdown report.
    pub report: PathBuf,
    /// The README summary table.
    pub summary: PathBuf,
    /// PNG plots.
    pub plots: Vec<PathBuf>,
    /// Per sweep dataset: the defaults' verdicts, one line each.
    pub verdicts: Vec<String>,
}

struct Table1Row<'a> {
    results: &'a BenchResults,
    by: [Option<&'a RunRecord>; 4],
}

fn table1_rows(all: &[BenchResults]) -> Vec<Table1Row<'_>> {
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
fn probe_table(out: &mut String, all: &[BenchResults]) {
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

fn table1(out: &mut String, all: &[BenchResults], summary: bool) {
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
        let paper = paper_row(&r.dataset.kind, r.dataset.visible_channels);
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

/// The other papers' renderers beside ours and the octree baseline: each one's time, its
/// speed-up over the per-ray octree (the comparison its paper makes) beside the paper's, and
/// ours against it.
fn seed_table(out: &mut String, all: &[BenchResults], summary: bool) {
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
        let leap = sparseleap_row(&r.dataset.kind).map_or_else(
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

/// The sweep of one results file: its table, plot and verdicts on the defaults.
fn sweep(
    out: &mut String,
    r: &BenchResults,
    dir: &Path,
    index: usize,
    written: &mut Written,
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
    written.plots.push(path);
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
        written.verdicts.extend(lines);
    }
    Ok(())
}

/// Writes verdict lines as a markdown list: a dataset's line as an item, its per-parameter
/// lines (already `  - …`) nested under it.
fn write_verdicts(out: &mut String, lines: &[String]) {
    for l in lines {
        if l.starts_with("  -") {
            let _ = writeln!(out, "{l}");
        } else {
            let _ = writeln!(out, "- {l}");
        }
    }
}

fn slug(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '-'
            }
        })
        .collect::<String>()
        .split('-')
        .filter(|p| !p.is_empty())
        .collect::<Vec<_>>()
        .join("-")
}

fn skipped(out: &mut String, all: &[BenchResults]) {
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
pub struct SkippedTotals {
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
    pub fn of(r: &BenchResults) -> Self {
        Self {
            naive: r.skipped.iter().map(|s| s.naive_bytes).sum(),
            fetched: r.skipped.iter().map(|s| s.ours_bytes_fetched).sum(),
            bricks_read: r.skipped.iter().map(|s| s.ours_bricks_read).sum(),
            brick_bytes: r.dataset.sample_type.block_bytes(r.dataset.brick_shape),
        }
    }

    /// Naive over ours fetched (`None` if ours fetched nothing).
    pub fn ratio(&self) -> Option<f64> {
        (self.fetched > 0).then(|| self.naive as f64 / self.fetched as f64)
    }

    /// The ceiling of [`SkippedTotals::ratio`]: naive over the bricks our converged frames
    /// read (`None` if they read nothing).
    pub fn ceiling(&self) -> Option<f64> {
        let read = self.bricks_read * self.brick_bytes;
        (read > 0).then(|| self.naive as f64 / read as f64)
    }
}

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

fn scaling(
    out: &mut String,
    all: &[BenchResults],
    dir: &Path,
    written: &mut Written,
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
        written.plots.push(p);
    }
    Ok(())
}

/// Writes `render-bench.md`, `summary.md` and the plots into `dir` from `inputs`.
///
/// # Errors
/// [`ReportError::NoInputs`], the first results file that cannot be read, or a report file
/// or plot that cannot be written, each naming the file.
pub fn write(inputs: &[PathBuf], dir: &Path, command: &str) -> Result<Written, ReportError> {
    if inputs.is_empty() {
        return Err(ReportError::NoInputs);
    }
    let all = inputs
        .iter()
        .map(|p| read(p))
        .collect::<Result<Vec<_>, _>>()?;
    std::fs::create_dir_all(dir).map_err(|source| ReportError::CreateDir {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut written = Written::default();
    let devices: Vec<String> = {
        let mut d: Vec<String> = all.iter().map(device_line).collect();
        d.sort();
        d.dedup();
        d
    };
    let mut out = String::new();
    let _ = writeln!(out, "# Renderer benchmark\n");
    let _ = writeln!(
        out,
        "Measured on {} by `{command}` ({} results files). Numbers are from this machine; the paper's are from an RTX-class GPU, so compare ratios, not milliseconds.\n",
        devices.join("; "),
        all.len()
    );
    let _ = writeln!(out, "## Datasets\n");
    for r in &all {
        let _ = writeln!(
            out,
            "- {}: experiments {}; {}×{} pixels, {} views (azimuth from {}° in equal steps, elevation {}°, {} diagonals), {} timed frames per view, reference {:.1} s",
            dataset_line(r),
            r.experiments
                .iter()
                .map(|e| e.name())
                .collect::<Vec<_>>()
                .join(", "),
            r.settings.width,
            r.settings.height,
            r.settings.views,
            r.settings.first_azimuth,
            r.settings.elevation,
            r.settings.distance,
            r.settings.timed_frames,
            r.settings.reference_s
        );
    }
    if !table1_rows(&all).is_empty() {
        let _ = writeln!(out, "\n## Table 1: methods side by side\n");
        let _ = writeln!(
            out,
            "Per dataset, each method over the same orbit in one process: for each view it converges first (warm cache), then the converged frames are timed. ms is the mean over views of the median per view; resident MB is the bricks a converged frame read × the brick size (what the method needs resident); ratios are baseline / ours, beside the paper's ratios for the data set our kind stands in for (Kingsnake for sparse, Rayleigh–Taylor for mixing and for dense, its worst case with no region empty or constant, CyCIF Small at 16 channels for cycif). Multi-channel sparse and dense datasets duplicate one channel with shifted transfer functions, as the paper does.\n"
        );
        table1(&mut out, &all, false);
        let _ = writeln!(
            out,
            "\n### The other papers' renderers\n\nSparseLeap (`--method sparseleap`: occupancy geometry rasterised into per-pixel ray segment lists) and octree rasterisation (`--method rasterize`: a cut of bricks by projected bounding sphere rasterised into ray segment lists, macrocell skipping inside bricks), in the same runs as Table 1, on the same data path, cache and compositing. Each paper compares itself with per-ray octree traversal, so their speed-ups over our octree baseline stand beside the papers' (SparseLeap: its Table 1 row for the data set our kind stands in for; octree rasterisation: the median and range of its Table 1, CT data only). Boxes rasterised is the mean per converged frame.\n"
        );
        seed_table(&mut out, &all, false);
        let _ = writeln!(
            out,
            "\n### Ours against the limit probe\n\nThe limit probe (`viewer/src/gpu/probe.rs`, `shaders/probe.wgsl`) casts the same rays with the same transfer functions, compositing and step (at level 0) through one resident texture of level 0, with no traversal, page tables or residency: the samples per second sampling alone reaches on this device, by hand (8 texel loads, as the renderer) and with the texture unit's filtering where `R32Float` is filterable. Ours is the residency run of Table 1: samples per converged frame over its GPU ms. A sample is one step of all drawn channels.\n"
        );
        probe_table(&mut out, &all);
    }
    let sweeps: Vec<&BenchResults> = all
        .iter()
        .filter(|r| r.runs.iter().any(|x| x.experiment == Experiment::Sweep))
        .collect();
    if !sweeps.is_empty() {
        let _ = writeln!(out, "\n## Run time against error\n");
        for (i, r) in sweeps.iter().enumerate() {
            sweep(&mut out, r, dir, i, &mut written)?;
        }
    }
    skipped(&mut out, &all);
    scaling(&mut out, &all, dir, &mut written)?;
    let report = dir.join("render-bench.md");
    std::fs::write(&report, &out).map_err(|source| ReportError::Write {
        path: report.clone(),
        source,
    })?;

    let mut s = String::new();
    let _ = writeln!(
        s,
        "Measured on {} by `{command}`; full tables and plots in [docs/benchmarks/render-bench.md](docs/benchmarks/render-bench.md). Ratios are baseline / ours, the paper's Table 1 ratios in parentheses.\n",
        devices.join("; ")
    );
    table1(&mut s, &all, true);
    let _ = writeln!(s);
    let mut seeds = String::new();
    seed_table(&mut seeds, &all, true);
    if !seeds.is_empty() {
        let _ = writeln!(
            s,
            "The other papers' renderers, same runs (speed-ups over per-ray octree traversal, the papers' in parentheses; then each against ours):\n\n{seeds}"
        );
    }
    probe_table(&mut s, &all);
    let skip: Vec<String> = all
        .iter()
        .filter_map(|r| {
            let t = SkippedTotals::of(r);
            let ceiling = t
                .ceiling()
                .map_or(String::new(), |c| format!(" (ceiling {c:.2}×)"));
            t.ratio()
                .map(|x| format!("{} {:.2}×{ceiling}", r.dataset.label, x))
        })
        .collect();
    if !skip.is_empty() {
        let _ = writeln!(
            s,
            "\nBytes fetched, naive frustum loader / ours (cold cache, same views; the ceiling is naive / the bricks the converged image reads, what any loader must deliver): {}.",
            skip.join(", ")
        );
    }
    if !written.verdicts.is_empty() {
        let _ = writeln!(s, "\nDefaults against the time–error Pareto front:\n");
        write_verdicts(&mut s, &written.verdicts);
    }
    let summary = dir.join("summary.md");
    std::fs::write(&summary, &s).map_err(|source| ReportError::Write {
        path: summary.clone(),
        source,
    })?;
    written.report = report;
    written.summary = summary;
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_map_to_the_papers_rows() {
        assert_eq!(paper_row("sparse", 1).unwrap().ms, [15.0, 11.6, 5.1]);
        assert_eq!(paper_row("sparse", 4).unwrap().gb, [1.88, 0.89, 0.48]);
        assert_eq!(paper_row("dense", 4).unwrap().ms[2], 20.0);
        assert_eq!(paper_row("mixing", 1).unwrap().ms, [11.2, 13.8, 6.4]);
        assert_eq!(paper_row("cycif", 8).unwrap().channels, 16);
        assert!(paper_row("fluorescence", 3).is_none());
        assert_eq!(slug("sparse 128³ (4 ch)"), "sparse-128-4-ch");
    }
}
