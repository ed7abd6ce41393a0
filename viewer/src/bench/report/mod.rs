//! The benchmark report: markdown tables (Table 1 with the paper's ratios beside ours, the
//! time–error sweep with its Pareto front and a verdict on each default, skipped work against
//! the naive loader, scaling) and the PNG plots, from one or more results files.

mod format;
mod methods;
mod scaling;
mod skipped;
mod sweep;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use self::format::{dataset_line, device_line};
use self::methods::{probe_table, readback_table, seed_table, table1, table1_rows};
use self::scaling::scaling;
use self::skipped::{SkippedTotals, skipped};
use self::sweep::{sweep, write_verdicts};
use crate::bench::experiment::Experiment;
use crate::bench::plots::PlotError;
use crate::bench::records::{BenchResults, FORMAT};

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

/// Reads and checks a results file.
///
/// # Errors
/// [`ReportError::Read`], [`ReportError::Parse`] or [`ReportError::Format`], naming the file.
pub(crate) fn read(path: &Path) -> Result<BenchResults, ReportError> {
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
        let mut readback = String::new();
        readback_table(&mut readback, &all);
        if !readback.is_empty() {
            let _ = writeln!(
                out,
                "\n### The image readback\n\nOurs (the residency run of Table 1), each converged frame timed in wall ms twice on the same view: rendered and its image read back to the CPU (16 bytes a pixel, as `viewer render` and the CPU blit need), and rendered with the image left on the GPU (as `viewer view` renders for presenting on the GPU). The difference is the readback's cost (copy, map, transfer), which GPU timestamps do not show.\n\n{readback}"
            );
        }
    }
    let sweeps: Vec<&BenchResults> = all
        .iter()
        .filter(|r| r.runs.iter().any(|x| x.experiment == Experiment::Sweep))
        .collect();
    if !sweeps.is_empty() {
        let _ = writeln!(out, "\n## Run time against error\n");
        for (i, r) in sweeps.iter().enumerate() {
            sweep(
                &mut out,
                r,
                dir,
                i,
                &mut written.plots,
                &mut written.verdicts,
            )?;
        }
    }
    skipped(&mut out, &all);
    scaling(&mut out, &all, dir, &mut written.plots)?;
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
