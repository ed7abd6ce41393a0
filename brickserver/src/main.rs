//! The `brickserver` command line.

use std::io::Write;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use residency_brickserver::{Datasets, ServerOptions, router};

#[derive(Parser)]
#[command(
    name = "brickserver",
    version,
    about = "Serve OME-Zarr stores and their region metadata over HTTP"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Serve datasets, each under /NAME/ (NAME: the folder name without .ome.zarr).
    Serve {
        /// OME-Zarr store folders.
        datasets: Vec<PathBuf>,
        /// Address to listen on (loopback unless told otherwise; port 0 picks a free port).
        #[arg(long, default_value = "127.0.0.1:8000")]
        bind: SocketAddr,
        /// Serve PATH under /NAME/ (repeatable).
        #[arg(long = "name", value_name = "NAME=PATH")]
        named: Vec<String>,
        /// Require `Authorization: Bearer <token>` on every request but /healthz; the token
        /// is the file's content without surrounding whitespace.
        #[arg(long)]
        token_file: Option<PathBuf>,
    },
}

/// Resolves on the first SIGINT or SIGTERM. The handlers are installed when this is
/// called, before the server announces itself, so no early signal is missed.
fn shutdown_signal() -> Result<impl std::future::Future<Output = ()>> {
    use tokio::signal::unix::{SignalKind, signal};
    let mut term = signal(SignalKind::terminate()).context("cannot handle SIGTERM")?;
    let mut int = signal(SignalKind::interrupt()).context("cannot handle SIGINT")?;
    Ok(async move {
        tokio::select! {
            _ = term.recv() => {},
            _ = int.recv() => {},
        }
        tracing::info!("shutting down");
    })
}

fn read_token(path: &std::path::Path) -> Result<String> {
    let token = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read token file", path.display()))?
        .trim()
        .to_string();
    if token.is_empty() {
        anyhow::bail!("{}: token file is empty", path.display());
    }
    Ok(token)
}

async fn serve(datasets: Datasets, bind: SocketAddr, options: ServerOptions) -> Result<()> {
    let listener = tokio::net::TcpListener::bind(bind)
        .await
        .with_context(|| format!("cannot listen on {bind}"))?;
    let addr = listener.local_addr()?;
    let shutdown = shutdown_signal()?;
    for d in &datasets.0 {
        println!("serving {} at http://{addr}/{}/", d.root.display(), d.name);
    }
    println!("listening on http://{addr}");
    std::io::stdout().flush()?;
    axum::serve(listener, router(datasets, options))
        .with_graceful_shutdown(shutdown)
        .await
        .context("server error")
}

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    let result = match Cli::parse().command {
        Command::Serve {
            datasets,
            bind,
            named,
            token_file,
        } => (|| {
            let datasets = Datasets::from_args(&datasets, &named)?;
            let options = ServerOptions {
                token: token_file.as_deref().map(read_token).transpose()?,
            };
            tokio::runtime::Runtime::new()
                .context("cannot start the runtime")?
                .block_on(serve(datasets, bind, options))
        })(),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
