//! `residency.Server`: `brickserver serve` inside the Python process, on a runtime of its own
//! (threads of this process), until closed.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;

use residency_brickserver::{App, AppState, ConnectionLimits, Datasets, ServerOptions, serve};
use residency_store::location::{ObjectStoreOptions, StoreLocation};
use tokio::sync::oneshot;

/// Why a server cannot start: the messages `brickserver serve` prints.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// The runtime cannot start.
    #[error("cannot start the runtime: {0}")]
    Runtime(#[source] std::io::Error),
    /// A store is not a dataset the server can serve.
    #[error(transparent)]
    Dataset(#[from] residency_brickserver::datasets::DatasetError),
    /// The datasets cannot be opened.
    #[error(transparent)]
    Open(#[from] residency_brickserver::dataset_store::OpenError),
    /// The address cannot be listened on.
    #[error("cannot listen on {bind}: {source}")]
    Listen {
        /// The address.
        bind: SocketAddr,
        /// Why.
        #[source]
        source: std::io::Error,
    },
}

/// A running server: its address, and how to stop it.
pub struct Running {
    /// The address it listens on.
    pub address: SocketAddr,
    /// Resolves the server's shutdown when sent to (or dropped).
    stop: Option<oneshot::Sender<()>>,
    /// The thread running it, joined on [`Running::stop`].
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Running {
    /// Starts serving `stores` on `bind` (port 0: a free port), with the web viewer from
    /// `viewer_dir`, S3 stores through `s3_endpoint`. Returns once the server listens.
    ///
    /// # Errors
    /// A [`ServeError`]: a store is not servable, or the address cannot be listened on.
    pub fn start(
        stores: &[StoreLocation],
        bind: SocketAddr,
        viewer_dir: Option<PathBuf>,
        s3_endpoint: Option<String>,
    ) -> Result<Self, ServeError> {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .enable_all()
            .build()
            .map_err(ServeError::Runtime)?;
        let object_store = ObjectStoreOptions {
            endpoint: s3_endpoint,
            runtime: None,
        };
        let options = ServerOptions {
            viewer_dir,
            ..ServerOptions::default()
        };
        let (listener, app, metrics) = runtime.block_on(async {
            let datasets = Datasets::from_args(stores, &[], &object_store).await?;
            let listener = tokio::net::TcpListener::bind(bind)
                .await
                .map_err(|source| ServeError::Listen { bind, source })?;
            let state = Arc::new(AppState::new(datasets, &options)?);
            let metrics = state.metrics.clone();
            let app = App::new(state, &options).await;
            Ok::<_, ServeError>((listener, app, metrics))
        })?;
        let address = listener
            .local_addr()
            .map_err(|source| ServeError::Listen { bind, source })?;
        let (stop, stopped) = oneshot::channel::<()>();
        let thread = std::thread::spawn(move || {
            runtime.block_on(serve(
                listener,
                app,
                ConnectionLimits::default(),
                metrics,
                async {
                    let _ = stopped.await;
                },
            ));
        });
        Ok(Self {
            address,
            stop: Some(stop),
            thread: Some(thread),
        })
    }

    /// Stops the server: no new connection is accepted, open requests finish (for at most
    /// 10 s), and its threads end. Stopping twice does nothing.
    pub fn stop(&mut self) {
        drop(self.stop.take());
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        self.stop();
    }
}
