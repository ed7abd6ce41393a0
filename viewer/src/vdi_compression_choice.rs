//! Which compression the page asks the render service to send its volumetric depth images in
//! (`?vdi_compression=`, the request's `compression`): one for every request, or
//! [`VdiCompressionChoice::Auto`], which weighs the link. `shuffled_zstd` makes a VDI 1.4 to
//! 1.7 times smaller than `shuffled_lz4`, and costs the service more time to write it and the
//! page more time to read it: worth it where the bytes it saves take longer to cross the link
//! than that. [`LinkRate`] is how fast the last answer crossed it, as the browser's network
//! stack timed its body (Resource Timing: from its first byte to its last, whatever the page's
//! main thread was doing meanwhile).

use residency_schemas::vdi::Compression;
use serde::{Deserialize, Serialize};

use residency_schemas::names::{Named, UnknownName};

/// Below this link rate (Mbit/s) [`VdiCompressionChoice::Auto`] asks for `shuffled_zstd`.
///
/// Below the rate where the time zstd saves on the link equals the time it costs, with a
/// margin. Measured on the 2-core development machine (2026-12-07) on VDIs of 640×360: zstd
/// makes them 29 % (CyCIF) to 43 % (sparse) smaller, and costs about 4 ns more a byte of
/// `shuffled_lz4` to write (the service, natively) and 2 to 2.5 ns more to read (the page,
/// WebAssembly in Chromium). A link of R Mbit/s carries a byte in 8000/R ns, so the saving
/// pays for itself below 8000 · 0.29 / 6.5 ≈ 360 Mbit/s for CyCIF, about 500 for the others.
pub const ZSTD_BELOW_MBIT_PER_S: f64 = 300.0;

/// Answers smaller than this (bytes) say too little of the link to weigh it: they may arrive
/// in one burst. Below it the last measurement stands; for an answer that small either
/// compression crosses a 100 Mbit/s link within 6 ms.
pub const MIN_MEASURED_BYTES: u64 = 64 * 1024;

/// The finest time a page is given (ms): Chromium rounds Resource Timing to 0.1 ms. A body
/// timed at less took at most this.
pub const TIMER_RESOLUTION_MS: f64 = 0.1;

/// The compression the user picked for the VDIs the page asks for.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    Serialize,
    Deserialize,
    strum::EnumCount,
    strum::EnumString,
    strum::IntoStaticStr,
    strum::VariantArray,
    strum::VariantNames,
)]
#[serde(rename_all = "snake_case")]
#[strum(
    serialize_all = "snake_case",
    parse_err_ty = UnknownName<VdiCompressionChoice>,
    parse_err_fn = UnknownName::new
)]
pub enum VdiCompressionChoice {
    /// `shuffled_zstd` while the last answer large enough to weigh the link
    /// ([`MIN_MEASURED_BYTES`]) crossed it slower than [`ZSTD_BELOW_MBIT_PER_S`], else
    /// `shuffled_lz4` (also before any such answer). Every answer of that size measures again,
    /// zstd's too, so a link that speeds up brings LZ4 back. There is no hysteresis: near the
    /// threshold both cost about the same.
    #[default]
    Auto,
    /// [`Compression::ShuffledLz4`] for every request.
    ShuffledLz4,
    /// [`Compression::ShuffledZstd`] for every request.
    ShuffledZstd,
}

residency_schemas::strum_names!(VdiCompressionChoice, all);

impl Named for VdiCompressionChoice {
    const NOUN: &'static str = "VDI compression";
}

/// How fast an answer crossed the link: its body's bytes over the time from its first byte to
/// its last (serialized as its Mbit/s alone).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(transparent)]
pub struct LinkRate {
    /// Megabits a second.
    pub mbit_per_s: f64,
}

impl LinkRate {
    /// The rate of an answer of `bytes` whose body took `transfer_ms` to arrive (at least
    /// [`TIMER_RESOLUTION_MS`]), or `None` where it says too little: under
    /// [`MIN_MEASURED_BYTES`], or a time that is negative or not finite (the browser kept no
    /// timing).
    pub fn measured(bytes: u64, transfer_ms: f64) -> Option<Self> {
        if bytes < MIN_MEASURED_BYTES || !(transfer_ms.is_finite() && transfer_ms >= 0.0) {
            return None;
        }
        Some(Self {
            mbit_per_s: bytes as f64 * 8.0 / (transfer_ms.max(TIMER_RESOLUTION_MS) * 1e3),
        })
    }
}

impl VdiCompressionChoice {
    /// The compression to ask for, given the link's last measured rate (`None`: not measured).
    pub fn compression(self, link: Option<LinkRate>) -> Compression {
        match self {
            Self::ShuffledLz4 => Compression::ShuffledLz4,
            Self::ShuffledZstd => Compression::ShuffledZstd,
            Self::Auto => match link {
                Some(rate) if rate.mbit_per_s < ZSTD_BELOW_MBIT_PER_S => Compression::ShuffledZstd,
                _ => Compression::ShuffledLz4,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_names_are_the_compressions_and_auto() {
        let names = VdiCompressionChoice::ALL.map(VdiCompressionChoice::name);
        assert_eq!(names, ["auto", "shuffled_lz4", "shuffled_zstd"]);
        for choice in VdiCompressionChoice::ALL {
            assert_eq!(choice.name().parse::<VdiCompressionChoice>(), Ok(choice));
        }
        assert_eq!(
            "zstd"
                .parse::<VdiCompressionChoice>()
                .unwrap_err()
                .to_string(),
            "unknown VDI compression 'zstd' (auto, shuffled_lz4 or shuffled_zstd)"
        );
    }

    #[test]
    fn auto_asks_for_zstd_below_the_threshold_once_the_link_is_measured() {
        use Compression::{ShuffledLz4, ShuffledZstd};
        // 1 MiB in 100 ms: 83.9 Mbit/s.
        let slow = LinkRate::measured(1 << 20, 100.0);
        assert_eq!(slow.map(|r| (r.mbit_per_s * 10.0).round()), Some(839.0));
        // 1 MiB in 20 ms: 419.4 Mbit/s.
        let fast = LinkRate::measured(1 << 20, 20.0);
        let at = |mbit: f64| Some(LinkRate { mbit_per_s: mbit });
        let cases = [
            (None, ShuffledLz4),
            (slow, ShuffledZstd),
            (fast, ShuffledLz4),
            // The README, the request's doc and docs/*.md say 300 Mbit/s.
            (at(300.0), ShuffledLz4),
            (at(299.999), ShuffledZstd),
        ];
        for (link, compression) in cases {
            assert_eq!(
                VdiCompressionChoice::Auto.compression(link),
                compression,
                "{link:?}"
            );
            assert_eq!(
                VdiCompressionChoice::ShuffledLz4.compression(link),
                ShuffledLz4
            );
            assert_eq!(
                VdiCompressionChoice::ShuffledZstd.compression(link),
                ShuffledZstd
            );
        }
    }

    #[test]
    fn small_answers_and_missing_times_do_not_measure_the_link() {
        assert_eq!(LinkRate::measured(MIN_MEASURED_BYTES - 1, 100.0), None);
        assert!(LinkRate::measured(MIN_MEASURED_BYTES, 100.0).is_some());
        for ms in [-0.5, f64::NAN, f64::INFINITY] {
            assert_eq!(LinkRate::measured(1 << 20, ms), None, "{ms}");
        }
        // A body timed within the timer's resolution arrived at least that fast: 1 MiB in
        // 0.1 ms is 83,886 Mbit/s, LZ4's side.
        for ms in [0.0, 0.05, 0.1] {
            let rate = LinkRate::measured(1 << 20, ms).unwrap();
            assert_eq!(rate.mbit_per_s.round(), 83886.0, "{ms}");
            assert_eq!(
                VdiCompressionChoice::Auto.compression(Some(rate)),
                Compression::ShuffledLz4
            );
        }
    }
}
