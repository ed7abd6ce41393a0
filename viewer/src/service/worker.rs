//! The GPU worker of the service: one thread owning the device, a fetcher and a live renderer,
//! fed through a one-deep queue where only the latest request waits ([`Latest`]). It hands
//! each VDI it generates to rayon's threads to encode (and compress: zstd takes tens of ms at
//! 640×360) and goes on to the next request, so the GPU never waits for the CPU's encoding.

use std::any::Any;
use std::collections::BTreeSet;
use std::panic::AssertUnwindSafe;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use futures_channel::oneshot;
use residency_schemas::vdi::VolumetricDepthImage;

use super::ServiceError;
use super::request::CheckedRequest;
use crate::gpu::device::Gpu;
use crate::gpu::renderer::{RenderOptions, Renderer};
use crate::gpu::streaming::{Budget, Fetcher, converge};
use crate::scene::Scene;
use crate::source::BrickSource;

/// A VDI generated for a request.
#[derive(Debug)]
pub(crate) struct Generated {
    /// The encoded VDI.
    pub(crate) bytes: Vec<u8>,
    /// Time from the start of its generation (renderer set-up, convergence, VDI pass,
    /// encoding) to the bytes.
    pub(crate) elapsed: Duration,
}

/// One request waiting for the GPU, and where its answer goes.
pub(crate) struct Job {
    /// What to generate.
    pub(crate) request: CheckedRequest,
    /// The answer's way back to the HTTP handler.
    pub(crate) reply: oneshot::Sender<Result<Generated, ServiceError>>,
}

/// A one-deep queue: the latest item waiting, or none; a newer item takes an older one's place.
#[derive(Debug)]
pub(crate) struct Latest<T> {
    slot: Mutex<(Option<T>, bool)>,
    ready: Condvar,
}

impl<T> Latest<T> {
    /// An empty, open queue.
    pub(crate) fn new() -> Self {
        Self {
            slot: Mutex::new((None, false)),
            ready: Condvar::new(),
        }
    }

    /// Puts `item` in the queue; returns the item it superseded, if one was waiting.
    pub(crate) fn put(&self, item: T) -> Option<T> {
        let mut slot = self
            .slot
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let old = slot.0.replace(item);
        self.ready.notify_one();
        old
    }

    /// Waits for an item and takes it; `None` once the queue is closed.
    pub(crate) fn take(&self) -> Option<T> {
        let mut slot = self
            .slot
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        loop {
            if slot.1 {
                return None;
            }
            if let Some(item) = slot.0.take() {
                return Some(item);
            }
            slot = self
                .ready
                .wait(slot)
                .unwrap_or_else(std::sync::PoisonError::into_inner);
        }
    }

    /// Closes the queue: [`Latest::take`] answers `None` from now on; returns the item that was
    /// waiting.
    pub(crate) fn close(&self) -> Option<T> {
        let mut slot = self
            .slot
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        slot.1 = true;
        self.ready.notify_all();
        slot.0.take()
    }
}

/// A renderer and the fetcher feeding it, kept between requests.
struct Session {
    renderer: Renderer,
    fetcher: Fetcher,
}

/// What the worker thread owns.
pub(crate) struct Worker {
    gpu: Gpu,
    source: Arc<dyn BrickSource>,
    render: RenderOptions,
    budget: Budget,
    session: Option<Session>,
}

/// What a caught panic said (its `&str` or `String` payload).
fn panic_message(panic: &(dyn Any + Send)) -> String {
    panic
        .downcast_ref::<&str>()
        .map(|s| (*s).to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "no message".to_string())
}

/// The channels a scene draws.
fn drawn(scene: &Scene) -> BTreeSet<usize> {
    scene
        .channels
        .iter()
        .filter(|s| s.visible)
        .map(|s| s.channel)
        .collect()
}

impl Worker {
    /// The worker of `source` on `gpu`; `render` is completed per request.
    pub(crate) fn new(
        gpu: Gpu,
        source: Arc<dyn BrickSource>,
        render: RenderOptions,
        budget: Budget,
    ) -> Self {
        Self {
            gpu,
            source,
            render,
            budget,
            session: None,
        }
    }

    /// Answers the jobs of `queue` one at a time until it closes, skipping those whose client
    /// has gone: generates each VDI here, then encodes it on rayon's threads while the next
    /// job is generated.
    pub(crate) fn run(mut self, queue: &Latest<Job>) {
        while let Some(job) = queue.take() {
            if job.reply.is_canceled() {
                // The client went away (a page aborts a request it no longer needs).
                continue;
            }
            let start = Instant::now();
            let generated =
                std::panic::catch_unwind(AssertUnwindSafe(|| self.generate(&job.request)))
                    .unwrap_or_else(|panic| {
                        // The renderer may be half-updated: the next request builds a new one.
                        self.session = None;
                        Err(ServiceError::Panicked(panic_message(panic.as_ref())))
                    });
            match generated {
                Ok(image) => rayon::spawn(move || {
                    let answer = match std::panic::catch_unwind(|| image.encode()) {
                        Ok(Ok(bytes)) => Ok(Generated {
                            bytes,
                            elapsed: start.elapsed(),
                        }),
                        Ok(Err(e)) => Err(ServiceError::Encode(e)),
                        Err(panic) => Err(ServiceError::Panicked(panic_message(panic.as_ref()))),
                    };
                    // The client may be gone: its answer is dropped.
                    let _ = job.reply.send(answer);
                }),
                Err(e) => {
                    let _ = job.reply.send(Err(e));
                }
            }
        }
    }

    /// The options of `request`'s renderer.
    fn options(&self, request: &CheckedRequest) -> RenderOptions {
        let levels = self.source.info().levels.len() as u32;
        let bounds = self
            .render
            .level_bounds
            .first()
            .copied()
            .unwrap_or((0, levels.saturating_sub(1)));
        RenderOptions {
            width: request.width,
            height: request.height,
            level_bounds: vec![bounds; request.scene.channels.len()],
            ..self.render.clone()
        }
    }

    /// Generates the VDI of `request`, its header naming the dataset and the compression to
    /// encode it with, on the live renderer when it draws the same channels with the same
    /// filter at the same size (restyled to the request's scene: its resident bricks carry
    /// over), else on a new one.
    fn generate(&mut self, request: &CheckedRequest) -> Result<VolumetricDepthImage, ServiceError> {
        let gpu = &self.gpu;
        let reusable = self.session.as_mut().is_some_and(|s| {
            let options = s.renderer.options();
            options.width == request.width
                && options.height == request.height
                && s.renderer.scene().filter == request.scene.filter
                && drawn(s.renderer.scene()) == drawn(&request.scene)
                && s.renderer.restyle(gpu, &request.scene)
        });
        if !reusable {
            // Dropped first, so that two renderers never hold the GPU's memory together.
            self.session = None;
            let options = self.options(request);
            let renderer = Renderer::new(gpu, self.source.info(), &request.scene, options)?;
            let fetcher = Fetcher::new(
                Arc::clone(&self.source),
                self.budget.workers,
                self.budget.batch,
            );
            self.session = Some(Session { renderer, fetcher });
        }
        let Some(session) = self.session.as_mut() else {
            unreachable!("a session was just made");
        };
        let generated = converge(gpu, &mut session.renderer, &session.fetcher, &self.budget)
            .and_then(|_| session.renderer.generate_vdi(gpu, request.supersegments));
        let mut generation = match generated {
            Ok((generation, _)) => generation,
            Err(e) => {
                // A failed device or pass leaves the renderer in doubt: start afresh.
                self.session = None;
                return Err(e.into());
            }
        };
        generation.image.header.dataset = Some(self.source.info().name.clone());
        generation.image.header.compression = request.compression;
        Ok(generation.image)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_latest_item_waits() {
        let queue = Latest::new();
        assert_eq!(queue.put(1), None);
        assert_eq!(queue.put(2), Some(1));
        assert_eq!(queue.take(), Some(2));
        assert_eq!(queue.put(3), None);
        assert_eq!(queue.close(), Some(3));
        assert_eq!(queue.take(), None);
    }

    #[test]
    fn take_waits_for_a_put() {
        let queue = Arc::new(Latest::new());
        let taker = {
            let queue = Arc::clone(&queue);
            std::thread::spawn(move || (queue.take(), queue.take()))
        };
        std::thread::sleep(Duration::from_millis(20));
        queue.put("a");
        // Wait until the taker has the first item, so the close cannot overtake it.
        while queue.slot.lock().unwrap().0.is_some() {
            std::thread::yield_now();
        }
        queue.close();
        assert_eq!(taker.join().unwrap(), (Some("a"), None));
    }
}
