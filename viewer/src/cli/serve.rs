//! `viewer serve`: the render service of the remote mode ([`residency_viewer::service`]): a
//! page far away asks for volumetric depth images of its views, generated here on the GPU next
//! to the data.

use std::net::SocketAddr;
use std::path::PathBuf;

use anyhow::{Result, ensure};

use super::renderer_args::{ConvergeArgs, RendererArgs, open_scene};
use super::scene_args::{SceneArgs, SourceArgs};
use residency_schemas::vdi::MAX_SUPERSEGMENTS;
use residency_viewer::gpu::device::Gpu;
use residency_viewer::service::{Limits, ServiceOptions, serve};
use residency_viewer::source::read_token_file;

/// Arguments of `viewer serve`.
#[derive(clap::Args, Debug)]
#[command(after_help = "\
POST /vdi takes a JSON VDI request (schemas/json/vdi-request.schema.json) and answers the \
encoded VDI (application/x-residency-vdi); GET /info describes the dataset \
(schemas/json/vdi-service-info.schema.json); GET /healthz answers ok. At most one generation \
runs at a time (the bound on concurrent generations): a request waiting for the GPU is \
answered 409 when a newer one arrives, as only the latest view matters. Errors are JSON \
{\"error\": \"...\"} answers. See docs/viewer.md, \"Remote \
rendering\".")]
pub struct Args {
    /// Where the volume comes from.
    #[command(flatten)]
    pub source: SourceArgs,
    /// The default scene: drawn when a request gives no scene (with the request's camera
    /// when it gives one).
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Address to listen on (port 0: one the system picks, logged at start).
    #[arg(long, value_name = "ADDR", default_value = "127.0.0.1:8090")]
    pub bind: SocketAddr,
    /// Require `Authorization: Bearer <token>` on every request but /healthz and CORS
    /// preflights; the token is the file's content without surrounding whitespace. (Not
    /// `--token-file`, which is the token this service sends to a `--server`.)
    #[arg(long, value_name = "FILE")]
    pub serve_token_file: Option<PathBuf>,
    /// Most pixels (width × height) of one requested VDI; larger requests are answered 413.
    #[arg(long, value_name = "N", default_value_t = 1920 * 1080)]
    pub max_pixels: u64,
    /// Most supersegments per pixel (N_S) of one requested VDI (at most 64); more are
    /// answered 413.
    #[arg(long, value_name = "N", default_value_t = 30)]
    pub max_supersegments: u32,
    /// Most VDI requests per second, all clients together (a burst of as many is allowed);
    /// more are answered 429 with a `Retry-After`.
    #[arg(long, value_name = "R", default_value_t = 20.0)]
    pub max_requests_per_second: f64,
    /// How long each requested view may take to converge.
    #[command(flatten)]
    pub converge: ConvergeArgs,
    /// Renderer settings.
    #[command(flatten)]
    pub renderer: RendererArgs,
}

/// Runs `viewer serve` until the process is stopped.
pub fn run(args: Args) -> Result<()> {
    ensure!(
        (1..=MAX_SUPERSEGMENTS).contains(&args.max_supersegments),
        "--max-supersegments {} must lie between 1 and {MAX_SUPERSEGMENTS}",
        args.max_supersegments
    );
    ensure!(args.max_pixels > 0, "--max-pixels must be positive");
    ensure!(
        args.max_requests_per_second > 0.0 && args.max_requests_per_second.is_finite(),
        "--max-requests-per-second {} must be positive",
        args.max_requests_per_second
    );
    let token = match &args.serve_token_file {
        Some(path) => {
            let token = read_token_file(path)?;
            ensure!(!token.is_empty(), "{}: token file is empty", path.display());
            Some(token)
        }
        None => None,
    };
    // The width and height of each request replace these.
    let (source, default_scene, render) =
        open_scene(&args.source, &args.scene, &args.renderer, 1, 1)?;
    let budget = args.converge.budget(args.renderer.workers)?;
    let gpu = Gpu::new()?;
    tracing::info!(
        "serving VDIs of {} on {} ({:?})",
        source.info().name,
        gpu.adapter_info.name,
        gpu.adapter_info.backend
    );
    let options = ServiceOptions {
        bind: args.bind,
        token,
        limits: Limits {
            max_pixels: args.max_pixels,
            max_supersegments: args.max_supersegments,
            max_requests_per_second: args.max_requests_per_second,
        },
        default_scene,
        render,
        budget,
    };
    serve(gpu, source, options)?;
    Ok(())
}
