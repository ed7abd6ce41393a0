//! Accepting connections: each served by the crate's `http1` module (HTTP/1.1 with a
//! header-read timeout, so a slow or idle client cannot hold a connection forever), a
//! connection limit (connections past it get a `503` and are closed), and graceful shutdown
//! (in-flight requests finish); on the caller's runtime, or on one single-threaded runtime per
//! core, each with a listener of its own on the shared port.

use std::future::Future;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use socket2::{Domain, Protocol, Socket, Type};
use tokio::io::AsyncWriteExt;
use tokio::net::TcpListener;
use tokio::sync::{Semaphore, oneshot, watch};

use crate::http1::{App, connection};
use crate::metrics::Metrics;

/// Connection-level limits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConnectionLimits {
    /// Most connections open at once.
    pub max_connections: usize,
    /// Longest wait for a request's headers, on a new or an idle kept-alive connection.
    pub header_timeout: Duration,
}

impl Default for ConnectionLimits {
    fn default() -> Self {
        Self {
            max_connections: 4096,
            header_timeout: Duration::from_secs(30),
        }
    }
}

const TOO_MANY: &[u8] = b"HTTP/1.1 503 Service Unavailable\r\nRetry-After: 1\r\nContent-Type: text/plain\r\nContent-Length: 29\r\nConnection: close\r\n\r\ntoo many connections, retry\r\n";

/// Serves `app` on `listener` until `shutdown` resolves, then lets open requests finish
/// (for at most 10 s). Failures of single connections (an `accept` that fails, a client that
/// breaks off) are logged, and serving goes on. Everything runs on the caller's runtime; see
/// [`serve_on_threads`] for one single-threaded runtime per core.
pub async fn serve(
    listener: TcpListener,
    app: App,
    limits: ConnectionLimits,
    metrics: Arc<Metrics>,
    shutdown: impl Future<Output = ()>,
) {
    let permits = Arc::new(Semaphore::new(limits.max_connections));
    let (stopping, stop) = watch::channel(false);
    tokio::join!(
        serve_listener(listener, app, limits, metrics, permits, stop),
        async {
            shutdown.await;
            let _ = stopping.send(true);
        },
    );
}

/// Serves `app` on every listener of `listeners` (sockets bound to one address, such as
/// [`shared_port_listeners`] makes), each on a thread of its own that runs a single-threaded
/// runtime with `blocking_threads` threads for blocking reads, until `shutdown` resolves; then
/// lets open requests finish (for at most 10 s) and returns once every thread has ended. A
/// connection is served from start to end on the thread that accepted it, as in nginx's worker
/// processes: no task moves between cores, and no wake-up crosses threads. The connection limit
/// is one for all threads.
///
/// # Errors
/// A thread, its runtime or its listener's registration with the runtime that cannot be made
/// (at start).
pub async fn serve_on_threads(
    listeners: Vec<std::net::TcpListener>,
    app: App,
    limits: ConnectionLimits,
    metrics: Arc<Metrics>,
    blocking_threads: usize,
    shutdown: impl Future<Output = ()>,
) -> std::io::Result<()> {
    let permits = Arc::new(Semaphore::new(limits.max_connections));
    let (stopping, stop) = watch::channel(false);
    let mut ended = Vec::with_capacity(listeners.len());
    for (i, listener) in listeners.into_iter().enumerate() {
        listener.set_nonblocking(true)?;
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .max_blocking_threads(blocking_threads.max(1))
            .build()?;
        // Registered with the thread's runtime here, so that a failure is this call's error.
        let listener = {
            let _entered = runtime.enter();
            TcpListener::from_std(listener)?
        };
        let serving = serve_listener(
            listener,
            app.clone(),
            limits,
            metrics.clone(),
            permits.clone(),
            stop.clone(),
        );
        let (end, ended_rx) = oneshot::channel::<()>();
        std::thread::Builder::new()
            .name(format!("brickserver-{i}"))
            .spawn(move || {
                runtime.block_on(serving);
                let _ = end.send(());
            })?;
        ended.push(ended_rx);
    }
    shutdown.await;
    let _ = stopping.send(true);
    for end in ended {
        let _ = end.await;
    }
    Ok(())
}

/// `count` listening sockets on `addr`, all on the same port (`SO_REUSEPORT`: the kernel spreads
/// new connections over them), for [`serve_on_threads`]. Port 0 picks one free port for all.
///
/// # Errors
/// The address cannot be bound (in use, not this machine's, not permitted).
pub fn shared_port_listeners(
    addr: SocketAddr,
    count: usize,
) -> std::io::Result<Vec<std::net::TcpListener>> {
    let mut listeners: Vec<std::net::TcpListener> = Vec::with_capacity(count.max(1));
    for _ in 0..count.max(1) {
        // The first socket resolves port 0; the others join it on the port it got.
        let at = listeners
            .first()
            .map_or(Ok(addr), std::net::TcpListener::local_addr)?;
        let socket = Socket::new(Domain::for_address(at), Type::STREAM, Some(Protocol::TCP))?;
        socket.set_reuse_address(true)?;
        socket.set_reuse_port(true)?;
        socket.bind(&at.into())?;
        socket.listen(1024)?;
        listeners.push(socket.into());
    }
    Ok(listeners)
}

/// Serves the connections `listener` accepts until `stop` turns true (the connections close
/// once their request in progress is answered; idle ones at once), then waits until every
/// connection holding one of `permits` has closed, or 10 s.
///
/// The connections wait for the stop on a channel of this listener's own, passed on from
/// `stop`: on [`serve_on_threads`]' runtimes, each thread's connections then look at a channel
/// only their thread touches, and no lock is shared between threads at each request.
async fn serve_listener(
    listener: TcpListener,
    app: App,
    limits: ConnectionLimits,
    metrics: Arc<Metrics>,
    permits: Arc<Semaphore>,
    mut stop: watch::Receiver<bool>,
) {
    let (stopping, connections_stop) = watch::channel(false);
    tokio::select! {
        () = accept(listener, &app, limits, &metrics, &permits, &connections_stop) => {},
        _ = stop.wait_for(|stopped| *stopped) => {},
    }
    let _ = stopping.send(true);
    drain(&permits, limits).await;
}

/// Accepts connections on `listener` and serves each on a task of its own, until the runtime
/// stops polling it (never returns by itself).
async fn accept(
    listener: TcpListener,
    app: &App,
    limits: ConnectionLimits,
    metrics: &Arc<Metrics>,
    permits: &Arc<Semaphore>,
    stop: &watch::Receiver<bool>,
) {
    loop {
        let (mut stream, peer) = match listener.accept().await {
            Ok(conn) => conn,
            Err(e) => {
                // Out of file descriptors and the like: wait a little, keep serving.
                tracing::warn!("accept failed: {e}");
                tokio::time::sleep(Duration::from_millis(20)).await;
                continue;
            }
        };
        let Ok(permit) = permits.clone().try_acquire_owned() else {
            metrics.connections_refused.inc();
            tracing::warn!(%peer, "connection limit ({}) reached", limits.max_connections);
            tokio::spawn(async move {
                let _ = stream.write_all(TOO_MANY).await;
                let _ = stream.shutdown().await;
            });
            continue;
        };
        let _ = stream.set_nodelay(true);
        let open = metrics.connections.clone();
        open.inc();
        let (app, stop) = (app.clone(), stop.clone());
        tokio::spawn(async move {
            if let Err(e) = connection(stream, app, limits.header_timeout, stop).await {
                tracing::debug!(%peer, "connection ended: {e}");
            }
            open.dec();
            drop(permit);
        });
    }
}

/// Waits until every connection has closed (each holds a permit), or 10 s.
async fn drain(permits: &Semaphore, limits: ConnectionLimits) {
    let all = u32::try_from(limits.max_connections).unwrap_or(u32::MAX);
    tokio::select! {
        _ = permits.acquire_many(all) => {},
        () = tokio::time::sleep(Duration::from_secs(10)) => {
            tracing::warn!("connections still open after 10 s; closing them");
        }
    }
}
