//! The progress bar of long byte-counting work (a conversion, an upload): throughput and ETA
//! on stderr, or nothing when hidden.

use std::sync::Arc;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Told, as long work goes on, the bytes done so far and the total: a caller's own display of
/// progress (a Python callback, say), beside or instead of the bar.
#[derive(Clone)]
pub struct ProgressCallback(pub Arc<dyn Fn(u64, u64) + Send + Sync>);

impl std::fmt::Debug for ProgressCallback {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ProgressCallback")
    }
}

/// A [`bytes_bar`] whose steps are also told to a callback.
pub struct Progress {
    bar: ProgressBar,
    callback: Option<ProgressCallback>,
}

impl Progress {
    /// A bar over `total` bytes (as [`bytes_bar`]) that tells `callback` each step.
    pub fn new(total: u64, label: &str, visible: bool, callback: Option<ProgressCallback>) -> Self {
        Self {
            bar: bytes_bar(total, label, visible),
            callback,
        }
    }

    /// Counts `bytes` more done.
    pub fn inc(&self, bytes: u64) {
        self.bar.inc(bytes);
        if let Some(c) = &self.callback {
            (c.0)(self.bar.position(), self.bar.length().unwrap_or(0));
        }
    }

    /// Ends the bar and clears it from the terminal.
    pub fn finish_and_clear(&self) {
        self.bar.finish_and_clear();
    }
}

/// A bar over `total` bytes, labelled `label` (`""` for none), drawn on stderr when `visible`.
pub fn bytes_bar(total: u64, label: &str, visible: bool) -> ProgressBar {
    // A hidden bar still counts, over its length (what `Progress` tells its callback).
    let target = if visible {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    };
    let bar = ProgressBar::with_draw_target(Some(total), target);
    bar.set_style(
        ProgressStyle::with_template(
            "{prefix}{spinner} [{elapsed_precise}] [{wide_bar}] {bytes}/{total_bytes} {binary_bytes_per_sec} ETA {eta}",
        )
        .expect("template"),
    );
    if !label.is_empty() {
        bar.set_prefix(format!("{label} "));
    }
    bar
}
