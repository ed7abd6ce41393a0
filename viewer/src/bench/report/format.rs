//! The cells and lines of the report: megabytes, optional numbers, PSNR, the time unit of a
//! set of runs, ratios, the device and dataset lines, and file-name slugs.

use crate::bench::records::{BenchResults, RunRecord};

/// Megabytes of `bytes`, two decimals.
pub(super) fn mb(bytes: f64) -> String {
    format!("{:.2}", bytes / 1e6)
}

/// `v` with `digits` decimals, `–` for none.
pub(super) fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "–".into(), |v| format!("{v:.digits$}"))
}

/// A PSNR in dB, one decimal, `∞` for none (identical images).
pub(super) fn psnr(v: Option<f64>) -> String {
    v.map_or_else(|| "∞".into(), |v| format!("{v:.1}"))
}

/// Whether a set of runs is timed in GPU ms (every run has it) or else in wall ms, and the
/// unit's name.
pub(super) fn time_unit<'a>(mut runs: impl Iterator<Item = &'a RunRecord>) -> (bool, &'static str) {
    if runs.all(|x| x.gpu_ms.is_some()) {
        (true, "GPU ms")
    } else {
        (false, "wall ms")
    }
}

/// The time of a run: GPU ms when every run of the set has it, else wall ms.
pub(super) fn time_of(r: &RunRecord, gpu: bool) -> f64 {
    if gpu {
        r.gpu_ms.unwrap_or(f64::NAN)
    } else {
        r.wall_ms
    }
}

/// `a / b` as `1.23×`, `–` when either is missing or `b` is not positive.
pub(super) fn ratio(a: Option<f64>, b: Option<f64>) -> String {
    match (a, b) {
        (Some(a), Some(b)) if b > 0.0 => format!("{:.2}×", a / b),
        _ => "–".into(),
    }
}

/// Device line of a results file.
pub(super) fn device_line(r: &BenchResults) -> String {
    format!(
        "{} ({}, {}), CPU {} × {} cores",
        r.device.adapter, r.device.backend, r.device.driver, r.device.cpu, r.device.cores
    )
}

/// Dataset line of a results file: label, kind, sample type, shape, bricks, levels, channels.
pub(super) fn dataset_line(r: &BenchResults) -> String {
    let d = &r.dataset;
    format!(
        "{} ({} {}, {}×{}×{} voxels z,y,x, bricks {}×{}×{}, {} levels, {} of {} channels rendered)",
        d.label,
        d.kind,
        d.sample_type.zarr_name(),
        d.shape[0],
        d.shape[1],
        d.shape[2],
        d.brick_shape[0],
        d.brick_shape[1],
        d.brick_shape[2],
        d.levels,
        d.visible_channels,
        d.channels
    )
}

/// `s` as a file-name part: lowercase ASCII words joined by `-`.
pub(super) fn slug(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '-'
            }
        })
        .collect::<String>()
        .split('-')
        .filter(|p| !p.is_empty())
        .collect::<Vec<_>>()
        .join("-")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slugs_are_lowercase_ascii_words() {
        assert_eq!(slug("sparse 128³ (4 ch)"), "sparse-128-4-ch");
    }
}
