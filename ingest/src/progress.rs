//! The progress bar of long byte-counting work (a conversion, an upload): throughput and ETA
//! on stderr, or nothing when hidden.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A bar over `total` bytes, labelled `label` (`""` for none), drawn on stderr when `visible`.
pub fn bytes_bar(total: u64, label: &str, visible: bool) -> ProgressBar {
    let bar = if visible {
        ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr())
    } else {
        ProgressBar::hidden()
    };
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
