//! The `brickserver` command line.

use std::io::Write;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use residency_brickserver::bricks::BatchLimits;
use residency_brickserver::{
    App, AppState, ConnectionLimits, Datasets, OPEN_FILES, PublicUrl, ServerOptions,
    serve_on_threads, shared_port_listeners,
};
use residency_store::location::{ObjectStoreOptions, StoreLocation};

#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// mimalloc gives freed memory back and commits arenas page by page, so that the server's RSS
/// is what it holds (see `residency_store::allocator`); set before `main`.
#[used]
#[cfg_attr(target_os = "linux", unsafe(link_section = ".init_array"))]
static RETURN_FREED_MEMORY: extern "C" fn() =
    residency_store::allocator::return_freed_memory_for_serving;

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
        /// OME-Zarr stores: folders (paths or file:// URLs) or s3://BUCKET/PREFIX locations.
        datasets: Vec<StoreLocation>,
        /// Address to listen on (loopback unless told otherwise; port 0 picks a free port).
        #[arg(long, default_value = "127.0.0.1:8000")]
        bind: SocketAddr,
        /// Serve LOCATION under /NAME/ (repeatable).
        #[arg(long = "name", value_name = "NAME=LOCATION")]
        named: Vec<String>,
        /// Endpoint URL of an S3-compatible server that is not AWS, for s3:// datasets
        /// (default: AWS_ENDPOINT_URL, else AWS).
        #[arg(long, value_name = "URL")]
        s3_endpoint: Option<String>,
        /// Require `Authorization: Bearer <token>` on every request but /healthz; the token
        /// is the file's content without surrounding whitespace.
        #[arg(long)]
        token_file: Option<PathBuf>,
        /// The web viewer's built files (scripts/build-web.sh) [default: the folder `web`
        /// beside this binary, else `../share/residency/web` from it, as the wheel installs].
        #[arg(long, value_name = "DIR")]
        viewer_dir: Option<PathBuf>,
        /// The URL clients reach the server at (a reverse proxy's, path prefix included);
        /// every link in the listing is built on it. Otherwise links follow the request's
        /// X-Forwarded-Proto and X-Forwarded-Host, else its Host.
        #[arg(long, value_name = "URL")]
        public_url: Option<PublicUrl>,
        /// Memory cache budget in bytes, for chunks and decoded bricks (0: no cache).
        #[arg(long, default_value_t = 256 << 20)]
        cache_bytes: u64,
        /// Most connections open at once; more get a 503 and are closed.
        #[arg(long, default_value_t = 4096)]
        max_connections: usize,
        /// Seconds a client may take to send a request's headers, and the longest a
        /// kept-alive connection may stay idle; the connection is closed after that.
        #[arg(long, default_value_t = 30.0)]
        request_timeout: f64,
        /// Most bricks in one batched request.
        #[arg(long, default_value_t = 256)]
        max_batch_bricks: usize,
        /// Most decoded bytes in one batched request.
        #[arg(long, default_value_t = 64 << 20)]
        max_batch_bytes: u64,
        /// Seconds a dataset part (image arrays, region metadata) that could not be loaded
        /// is answered from the failure before a request tries again.
        #[arg(long, default_value_t = 5.0)]
        load_retry: f64,
        /// Most chunk files of folder stores held open between requests, as nginx's
        /// open_file_cache (0: each request opens its file); at most a quarter of the
        /// open-file limit.
        #[arg(long, value_name = "N", default_value_t = OPEN_FILES)]
        open_files: usize,
        /// Threads that serve connections, each with a listener of its own on the port and a
        /// single-threaded runtime (a connection stays on the thread that accepted it)
        /// [default: one per core].
        #[arg(long, value_name = "N")]
        threads: Option<usize>,
    },
}

/// Resolves on the first SIGINT or SIGTERM. The handlers are installed when this is
/// called, before the server announces itself, so no early signal is missed.
fn shutdown_signal() -> Result<impl Future<Output = ()>> {
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

/// Raises the open-file limit to its hard maximum, as servers do: each connection, and each
/// chunk file held open, is a file.
fn raise_file_limit() {
    // SAFETY: getrlimit/setrlimit only read and write the struct passed.
    unsafe {
        let mut lim = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        if libc::getrlimit(libc::RLIMIT_NOFILE, &raw mut lim) == 0 && lim.rlim_cur < lim.rlim_max {
            lim.rlim_cur = lim.rlim_max;
            libc::setrlimit(libc::RLIMIT_NOFILE, &raw const lim);
        }
    }
}

/// The web viewer's default folder: `web` beside the running executable (where
/// `scripts/build-web.sh` writes, e.g. `target/release/web`), else `share/residency/web` under
/// the executable's prefix (where the Python wheel installs it: `ENV/bin/brickserver`,
/// `ENV/share/residency/web`), else the first (the page then says it was not built).
fn default_viewer_dir() -> Option<PathBuf> {
    let exe = std::env::current_exe().ok()?;
    let bin = exe.parent()?;
    let beside = bin.join("web");
    let shared = bin
        .parent()
        .map(|prefix| prefix.join("share/residency/web"));
    let built = |dir: &PathBuf| dir.join("index.html").is_file();
    Some(match shared {
        Some(shared) if !built(&beside) && built(&shared) => shared,
        _ => beside,
    })
}

async fn run(
    datasets: Datasets,
    bind: SocketAddr,
    options: ServerOptions,
    limits: ConnectionLimits,
    threads: usize,
) -> Result<()> {
    let listeners =
        shared_port_listeners(bind, threads).with_context(|| format!("cannot listen on {bind}"))?;
    let addr = listeners[0].local_addr()?;
    let shutdown = shutdown_signal()?;
    // Where it serves, for whoever reads stdout; a reader that has gone (a closed pipe) does
    // not stop the server.
    let mut stdout = std::io::stdout().lock();
    let said = datasets
        .0
        .iter()
        .try_for_each(|d| {
            writeln!(
                stdout,
                "serving {} at http://{addr}/{}/",
                d.location, d.name
            )
        })
        .and_then(|()| writeln!(stdout, "listening on http://{addr}"))
        .and_then(|()| stdout.flush());
    if let Err(e) = said
        && e.kind() != std::io::ErrorKind::BrokenPipe
    {
        return Err(e.into());
    }
    drop(stdout);
    let state = Arc::new(AppState::new(datasets, &options)?);
    let viewer = state.viewer();
    match (viewer.built(), viewer.looked_at()) {
        (Some(dir), _) => tracing::info!("web viewer from {}", dir.display()),
        (None, Some(dir)) => tracing::warn!(
            "no web viewer in {} (run scripts/build-web.sh, or pass --viewer-dir): \
             /NAME/view answers 503",
            dir.display()
        ),
        (None, None) => tracing::warn!("no web viewer folder: /NAME/view answers 503"),
    }
    let metrics = state.metrics.clone();
    let app = App::new(state, &options).await;
    // BLOCKING_THREADS shared out among the serving threads' runtimes.
    let blocking = BLOCKING_THREADS.div_ceil(threads);
    serve_on_threads(listeners, app, limits, metrics, blocking, shutdown)
        .await
        .context("cannot start the serving threads")
}

/// Most blocking threads of the starting runtime, and of the serving threads' runtimes together.
const BLOCKING_THREADS: usize = 64;

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
            s3_endpoint,
            token_file,
            viewer_dir,
            public_url,
            cache_bytes,
            max_connections,
            request_timeout,
            max_batch_bricks,
            max_batch_bytes,
            load_retry,
            open_files,
            threads,
        } => (|| {
            // Each object-store dataset's client is made here, once, and its requests run on
            // the server's runtime (see `DatasetStore`), so the options carry no runtime.
            let object_store = ObjectStoreOptions {
                endpoint: s3_endpoint,
                runtime: None,
            };
            // The runtime that starts the server (opening the datasets on its blocking threads)
            // and runs object-store requests (batched bricks read from an object store are
            // its tasks, decoded on its workers); connections are served on threads of their own
            // (`serve_on_threads`), whose runtimes' blocking threads read files the page cache
            // does not hold and run zarrs' reads. Both pools are capped at BLOCKING_THREADS:
            // disk- and network-bound work, so a few dozen keep a disk or a store busy, where
            // tokio's default of 512 would each hold a stack and an allocator heap.
            let runtime = tokio::runtime::Builder::new_multi_thread()
                .enable_all()
                .max_blocking_threads(BLOCKING_THREADS)
                .build()
                .context("cannot start the runtime")?;
            let datasets =
                runtime.block_on(Datasets::from_args(&datasets, &named, &object_store))?;
            if !(request_timeout > 0.0 && request_timeout.is_finite()) {
                anyhow::bail!("--request-timeout must be a positive number of seconds");
            }
            if max_connections == 0 || max_batch_bricks == 0 || threads == Some(0) {
                anyhow::bail!(
                    "--max-connections, --max-batch-bricks and --threads must be at least 1"
                );
            }
            let threads = threads.unwrap_or_else(|| {
                std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
            });
            let timeout = Duration::from_secs_f64(request_timeout);
            let options = ServerOptions {
                token: token_file.as_deref().map(read_token).transpose()?,
                cache_bytes,
                batch: BatchLimits {
                    max_bricks: max_batch_bricks,
                    max_bytes: max_batch_bytes,
                },
                viewer_dir: viewer_dir.or_else(default_viewer_dir),
                public_url,
                load_retry: Duration::try_from_secs_f64(load_retry)
                    .context("--load-retry must be a number of seconds, 0 or more")?,
                open_files,
            };
            let limits = ConnectionLimits {
                max_connections,
                header_timeout: timeout,
            };
            raise_file_limit();
            runtime.block_on(run(datasets, bind, options, limits, threads))
        })(),
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
