//! `viewer bench`: the renderer benchmark suite ([`residency_viewer::bench`]). `viewer bench run`
//! measures one dataset (Table-1 methods, time–error sweep, skipped work, scaling point) into a
//! JSON results file (`schemas/json/render-bench.schema.json`); `viewer bench report` turns
//! results files into markdown tables and PNG plots.

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{Context, Result, ensure};

use super::renderer_args::RendererArgs;
use super::scene_args::{SceneArgs, SourceArgs};
use residency_viewer::bench::{
    self, Bench, Experiment, MethodConfig, Plan, SweepGroup, SweepValues,
};
use residency_viewer::gpu::renderer::Method;
use residency_viewer::source::BrickSource;

/// Arguments of `viewer bench`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The `viewer bench` subcommands.
#[derive(clap::Subcommand, Debug)]
#[allow(clippy::large_enum_variant)] // parsed once
pub enum Command {
    /// Measure one dataset and write a results file.
    Run(Box<RunArgs>),
    /// Write markdown tables and PNG plots from results files.
    Report(ReportArgs),
    /// Volumetric depth images against direct volume rendering: quality and frame time at
    /// deviations from the camera of generation, sizes and generation time.
    Vdi(Box<VdiArgs>),
}

/// Arguments of `viewer bench vdi`.
#[derive(clap::Args, Debug)]
pub struct VdiArgs {
    /// Where the volume comes from.
    #[command(flatten)]
    pub source: SourceArgs,
    /// What to draw; its camera generates the VDIs.
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Renderer settings of the DVR frames and of the VDI pass.
    #[command(flatten)]
    pub renderer: RendererArgs,
    /// Image width in pixels (lists per row of the VDIs).
    #[arg(long, default_value_t = 128)]
    pub width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 128)]
    pub height: u32,
    /// Supersegment counts, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "15,20,30")]
    pub supersegments: Vec<u32>,
    /// Deviations from the camera of generation, degrees, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "0,5,10,20,30,40")]
    pub deviations: Vec<f64>,
    /// Frames timed per measurement (the median is kept).
    #[arg(long, default_value_t = 3)]
    pub timed_frames: usize,
    /// Most frames to converge one view.
    #[arg(long, default_value_t = 64)]
    pub max_frames: u32,
    /// The sampling along the ray `D_R` measured beside the full walk (the paper's Sec. 4.4:
    /// the share of the lists a ray crosses that it reads), in (0, 1].
    #[arg(long, default_value_t = bench::vdi::RAY_SAMPLING, value_parser = super::ray_sampling)]
    pub ray_sampling: f64,
    /// Dataset label in the tables [default: the dataset name].
    #[arg(long)]
    pub label: Option<String>,
    /// Results file (JSON, `schemas/json/vdi-bench.schema.json`).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Also write the tables as markdown here.
    #[arg(long, value_name = "FILE")]
    pub markdown: Option<PathBuf>,
    /// Also plot SSIM and frame time against deviation here (PNG).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
}

/// Arguments of `viewer bench run`.
#[derive(clap::Args, Debug)]
pub struct RunArgs {
    /// Where the volume comes from.
    #[command(flatten)]
    pub source: SourceArgs,
    /// What to draw (the camera is replaced by the orbit).
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Base renderer settings (the defaults of every run; `--method` is ignored: every method
    /// of `--methods` runs).
    #[command(flatten)]
    pub renderer: RendererArgs,
    /// Experiments, comma-separated: table1, sweep, skipped, scaling.
    #[arg(
        long,
        value_parser = super::names_parser::<Experiment>(),
        value_delimiter = ',',
        default_value = "table1,skipped"
    )]
    pub experiment: Vec<Experiment>,
    /// Dataset label in reports [default: the dataset name].
    #[arg(long)]
    pub label: Option<String>,
    /// Kind of data (sparse, dense, cycif, fluorescence): picks the paper's row to compare with.
    #[arg(long, default_value = "fluorescence")]
    pub kind: String,
    /// Image width in pixels.
    #[arg(long, default_value_t = 128)]
    pub width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 128)]
    pub height: u32,
    /// Views of the orbit about the vertical axis.
    #[arg(long, default_value_t = 4)]
    pub views: usize,
    /// Frames timed per view after convergence (the median is kept).
    #[arg(long, default_value_t = 3)]
    pub timed_frames: usize,
    /// Most frames to converge one view.
    #[arg(long, default_value_t = 64)]
    pub max_frames: u32,
    /// Orbit elevation, degrees.
    #[arg(long, default_value_t = 20.0, allow_hyphen_values = true)]
    pub elevation: f64,
    /// Orbit distance in volume diagonals from the centre.
    #[arg(long, default_value_t = 1.5)]
    pub distance: f64,
    /// Azimuth of the first view, degrees.
    #[arg(long, default_value_t = 30.0, allow_hyphen_values = true)]
    pub first_azimuth: f64,
    /// Reference step as a fraction of the finest level-0 voxel.
    #[arg(long, default_value_t = residency_viewer::reference::DEFAULT_STEP_FRACTION)]
    pub reference_step: f64,
    /// Table-1 methods, comma-separated: residency, page-table, octree, sparseleap,
    /// rasterize, no-skipping.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "page-table,octree,residency,no-skipping,sparseleap,rasterize"
    )]
    pub methods: Vec<String>,
    /// Give each visible channel after the first a transfer function shifted up its range
    /// (simulated channels: one volume duplicated, as in the paper).
    #[arg(long)]
    pub vary_tf: bool,
    /// Sweep: which parameters to sweep, comma-separated: step, lod-bias, cache, leaf, and
    /// `methods` (every other `--methods` method over the same steps and LOD biases).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "step,lod-bias,cache,leaf,methods"
    )]
    pub sweep_params: Vec<String>,
    /// Sweep: step factors.
    #[arg(long, value_delimiter = ',', default_value = "0.25,0.5,1,2")]
    pub steps: Vec<f32>,
    /// Sweep: LOD biases.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "-2,-1,0,1",
        allow_hyphen_values = true
    )]
    pub lod_biases: Vec<f32>,
    /// Sweep: cache budgets as fractions of the defaults' working set.
    #[arg(long, value_delimiter = ',', default_value = "0.25,0.5,0.75")]
    pub cache_fractions: Vec<f64>,
    /// Sweep: octree leaf targets in level-0 voxels.
    #[arg(long, value_delimiter = ',', default_value = "4,8,16,32")]
    pub leaf_voxels: Vec<u64>,
    /// Results file (JSON).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Arguments of `viewer bench report`.
#[derive(clap::Args, Debug)]
pub struct ReportArgs {
    /// Results files of `viewer bench run`.
    #[arg(required = true)]
    pub results: Vec<PathBuf>,
    /// Folder for `render-bench.md`, `summary.md` and the plots.
    #[arg(long, value_name = "DIR")]
    pub out_dir: PathBuf,
    /// The command line named in the report as how the numbers were made.
    #[arg(long, default_value = "viewer bench")]
    pub command: String,
}

fn parse_method(s: &str) -> Result<MethodConfig> {
    let s = s.trim();
    s.parse().map_err(|_| {
        let names = MethodConfig::names().collect::<Vec<_>>().join(", ");
        anyhow::anyhow!("--methods: unknown method {s:?} ({names})")
    })
}

/// The values of a sweep parameter: all of `values` when it is swept (`on`), else none.
fn swept<T: Clone>(on: bool, values: &[T]) -> Vec<T> {
    if on { values.to_vec() } else { Vec::new() }
}

/// Runs `viewer bench run`.
pub fn run_bench(args: RunArgs) -> Result<()> {
    ensure!(
        args.width >= 11 && args.height >= 11,
        "--width and --height must be at least 11 (SSIM's window)"
    );
    let source: Arc<dyn BrickSource> = Arc::from(args.source.open()?);
    let info = source.info();
    let mut scene = args.scene.scene(info)?;
    if args.vary_tf {
        bench::vary_transfer_functions(&mut scene);
    }
    let options = args.renderer.options(
        args.width,
        args.height,
        info.levels.len(),
        scene.channels.len(),
    )?;
    let methods: Vec<MethodConfig> = args
        .methods
        .iter()
        .map(|m| parse_method(m))
        .collect::<Result<_>>()?;
    let plan = Plan {
        experiments: args.experiment.clone(),
        label: args.label.clone(),
        kind: args.kind.clone(),
        views: args.views,
        timed_frames: args.timed_frames,
        max_frames: args.max_frames,
        elevation: args.elevation,
        distance: args.distance,
        first_azimuth: args.first_azimuth,
        reference_step: args.reference_step,
        workers: args.renderer.workers,
        methods: methods.clone(),
        sweep: {
            let groups = args
                .sweep_params
                .iter()
                .map(|p| {
                    p.parse::<SweepGroup>().map_err(|_| {
                        let names = <SweepGroup as strum::VariantNames>::VARIANTS.join(", ");
                        anyhow::anyhow!("--sweep-params: unknown parameter {p:?} ({names})")
                    })
                })
                .collect::<Result<Vec<_>>>()?;
            let on = |g: SweepGroup| groups.contains(&g);
            SweepValues {
                steps: swept(on(SweepGroup::Step), &args.steps),
                lod_biases: swept(on(SweepGroup::LodBias), &args.lod_biases),
                cache_fractions: swept(on(SweepGroup::Cache), &args.cache_fractions),
                leaf_voxels: swept(on(SweepGroup::Leaf), &args.leaf_voxels),
                methods: if on(SweepGroup::Methods) {
                    methods
                        .iter()
                        .filter(|c| c.skipping && c.method != Method::Residency)
                        .map(|c| c.method)
                        .collect()
                } else {
                    Vec::new()
                },
            }
        },
        progress: !args.quiet,
    };
    let name = info.name.clone();
    let results = Bench::new(source, scene, options, plan)?
        .run_all()
        .with_context(|| format!("{name}: benchmark"))?;
    let json = serde_json::to_string_pretty(&results)?;
    std::fs::write(&args.out, json + "\n")
        .with_context(|| format!("{}: cannot write the results", args.out.display()))?;
    tracing::info!("{name}: wrote {}", args.out.display());
    Ok(())
}

/// Runs `viewer bench vdi`.
pub fn run_vdi(args: VdiArgs) -> Result<()> {
    ensure!(
        args.width >= 11 && args.height >= 11,
        "--width and --height must be at least 11 (SSIM's window)"
    );
    let source: Arc<dyn BrickSource> = Arc::from(args.source.open()?);
    let info = source.info();
    let scene = args.scene.scene(info)?;
    let options = args.renderer.options(
        args.width,
        args.height,
        info.levels.len(),
        scene.channels.len(),
    )?;
    let plan = bench::vdi::VdiPlan {
        supersegments: args.supersegments.clone(),
        deviations: args.deviations.clone(),
        timed_frames: args.timed_frames,
        max_frames: args.max_frames,
        workers: args.renderer.workers,
        ray_sampling: args.ray_sampling,
    };
    let label = args.label.clone().unwrap_or_else(|| info.name.clone());
    let gpu = residency_viewer::gpu::device::Gpu::new()?;
    let results = bench::vdi::run(&gpu, Arc::clone(&source), &scene, options, &plan, &label)
        .with_context(|| format!("{label}: VDI benchmark"))?;
    let json = serde_json::to_string_pretty(&results)?;
    std::fs::write(&args.out, json + "\n")
        .with_context(|| format!("{}: cannot write the results", args.out.display()))?;
    if let Some(path) = &args.markdown {
        std::fs::write(path, bench::vdi::markdown(&results))
            .with_context(|| format!("{}: cannot write the tables", path.display()))?;
    }
    if let Some(path) = &args.plot {
        bench::vdi::plot(&results, path)?;
    }
    tracing::info!("{label}: wrote {}", args.out.display());
    Ok(())
}

/// Runs `viewer bench`.
pub fn run(args: Args) -> Result<()> {
    match args.command {
        Command::Run(a) => run_bench(*a),
        Command::Vdi(a) => run_vdi(*a),
        Command::Report(a) => {
            let w = bench::report::write(&a.results, &a.out_dir, &a.command)?;
            super::report(format_args!(
                "{}\n{}\n",
                w.report.display(),
                w.summary.display()
            ))?;
            for p in &w.plots {
                super::report(format_args!("{}\n", p.display()))?;
            }
            Ok(())
        }
    }
}
