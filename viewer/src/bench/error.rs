//! Why a benchmark stopped ([`BenchError`]).

use super::experiment::Experiment;
use crate::gpu::GpuError;
use crate::metrics::MetricsError;
use crate::reference::ReferenceError;

/// Why a benchmark stopped: a plan that measures nothing, no device, or a view whose
/// reference, frame or comparison failed. Messages name the dataset, view and configuration
/// at fault; the renderer's, the reference's and the metrics' errors are theirs, unchanged.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// `--views 0`.
    #[error("--views must be at least 1")]
    NoViews,
    /// `--timed-frames 0`.
    #[error("--timed-frames must be at least 1")]
    NoTimedFrames,
    /// The device, a renderer, a frame or the limit probe failed.
    #[error(transparent)]
    Gpu(Box<GpuError>),
    /// Two images could not be compared.
    #[error(transparent)]
    Metrics(#[from] MetricsError),
    /// The reference image of a view could not be rendered.
    #[error("{dataset}: reference of view {view}")]
    Reference {
        /// The dataset.
        dataset: String,
        /// The view, from 1.
        view: usize,
        /// Why.
        #[source]
        source: Box<ReferenceError>,
    },
    /// The limit probe marches emission–absorption only: it has no ceiling for another mode.
    #[error("the limit probe marches emission–absorption only (the scene's mode is {mode})")]
    ProbeMode {
        /// The scene's mode.
        mode: &'static str,
    },
    /// No frame was timed (a bug: the plan asks for at least one).
    #[error("no frame timed")]
    NoFrameTimed,
    /// A converged frame could not be compared with its reference.
    #[error("{dataset}: view {view} against its reference")]
    Compare {
        /// The dataset.
        dataset: String,
        /// The view, from 0.
        view: usize,
        /// Why.
        #[source]
        source: MetricsError,
    },
    /// A configuration's renderer could not be set up.
    #[error("{dataset}: {label}")]
    Renderer {
        /// The dataset.
        dataset: String,
        /// The configuration.
        label: String,
        /// Why.
        #[source]
        source: Box<GpuError>,
    },
    /// A view of a configuration failed.
    #[error("{dataset}: {experiment} {label}")]
    Run {
        /// The dataset.
        dataset: String,
        /// The experiment.
        experiment: Experiment,
        /// The configuration.
        label: String,
        /// Why.
        #[source]
        source: Box<BenchError>,
    },
    /// A limit-probe frame could not be compared with its reference.
    #[error("{dataset}: probe of view {view}")]
    Probe {
        /// The dataset.
        dataset: String,
        /// The view, from 0.
        view: usize,
        /// Why.
        #[source]
        source: MetricsError,
    },
}

impl From<GpuError> for BenchError {
    fn from(e: GpuError) -> Self {
        Self::Gpu(Box::new(e))
    }
}
