//! The `viewer` command line.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod cli;

#[derive(Parser)]
#[command(
    name = "viewer",
    version,
    about = "Residency-octree volume rendering of OME-Zarr volumes on wgpu"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
#[allow(clippy::large_enum_variant)] // parsed once; boxing buys nothing
enum Command {
    /// Render a scene on the GPU, progressively, until converged or out of budget.
    Render(cli::render::Args),
    /// Generate a volumetric depth image of a scene on the GPU, once the view has converged.
    Vdi(cli::vdi::Args),
    /// Serve volumetric depth images of a dataset's views over HTTP, for a page far away (the
    /// remote mode).
    Serve(Box<cli::serve::Args>),
    /// Render the same scene's ground truth on the CPU in f64 (full resolution, fine step).
    Reference(Box<cli::reference::Args>),
    /// Compare two images: PSNR, SSIM, max abs error, and an EXR error map.
    Compare(cli::compare::Args),
    /// Open an interactive window: orbit, pan, zoom, channel controls, statistics.
    View(Box<cli::view::Args>),
    /// Benchmark the renderer: methods side by side, time against error, skipped work, scaling.
    Bench(cli::bench::Args),
}

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    let result = match Cli::parse().command {
        Command::Render(args) => cli::render::run(args),
        Command::Vdi(args) => cli::vdi::run(args),
        Command::Serve(args) => cli::serve::run(*args),
        Command::Reference(args) => cli::reference::run(*args),
        Command::Compare(args) => cli::compare::run(args),
        Command::View(args) => cli::view::run(*args),
        Command::Bench(args) => cli::bench::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!(
                "error: {}",
                residency_schemas::error_chain::join_chain(e.chain())
            );
            ExitCode::FAILURE
        }
    }
}
