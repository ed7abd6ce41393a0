//! The renderer benchmark suite (`viewer bench`): the records it writes
//! (`schemas/json/render-bench.schema.json`), the experiment driver and the report.
//!
//! Every measurement renders the same scene from the same camera path, an orbit of `K` views
//! about the vertical (`y`) axis, in one process on one device. For each view a method first
//! converges (fetches until a frame requests nothing: a warm cache), then `R` further frames
//! are timed: the median GPU time (timestamp queries) and median wall time per converged
//! frame, the bricks the frame read (`bricks_used`, times the slot size: the bytes the cache
//! needs resident), the samples taken, and the error of the converged image against the f64
//! reference of the same view ([`crate::reference`]: PSNR, SSIM, max abs).
//!
//! Modules, each below the ones that use it:
//! - `experiment`: the [`Experiment`]s and their names;
//! - `records`: the results file, [`BenchResults`] and its records;
//! - `plan`: what to measure ([`Plan`]); `error`: [`BenchError`];
//! - `naive`: the naive frustum loader of the skipped-work comparison;
//! - `driver`: the [`Bench`] driver, one configuration over the orbit; `experiments`: the
//!   experiments on it and [`Bench::run_all`];
//! - `channels`: simulated channels ([`vary_transfer_functions`]);
//! - `paper`: the papers' published numbers; `pareto`: the Pareto front of time against
//!   error; `plots`: PNG plots (plotters); [`report`]: markdown tables and plots from results
//!   files;
//! - [`vdi`]: `viewer bench vdi`, volumetric depth images against direct volume rendering.

mod channels;
mod driver;
mod error;
mod experiment;
mod experiments;
mod naive;
mod paper;
mod pareto;
mod plan;
mod plots;
mod records;
pub mod report;
pub mod vdi;

pub use channels::vary_transfer_functions;
pub use driver::Bench;
pub use error::BenchError;
pub use experiment::{Experiment, UnknownExperiment};
pub use plan::{MethodConfig, Plan, SweepGroup, SweepValues};
pub use plots::{Line, PlotError, panels};
pub use records::{
    BenchResults, DatasetInfo, DeviceInfo, FORMAT, OptionsRecord, ProbeRecord, RunRecord, Settings,
    SkippedRecord, SweepParam, SweptParameter, ViewRecord,
};
