//! Holding a target frame time by changing how much of the image is rendered: the
//! proportional–integral (PI) controller the VDI paper uses for preview rendering (Sec. 4.4),
//! which sets the image-space sampling `D_I` (the fraction of the display's width and height
//! that rays are cast for; the rest is upsampled) from the frame times measured.
//!
//! The controller works in the velocity form on the logarithm of `D_I`, with the error
//! `½·ln(target / measured)` (the change of `ln D_I` that a cost proportional to the pixels
//! would need): so one pair of gains suits a fast and a slow device alike, and `D_I` clamped to
//! its bounds leaves nothing wound up to unwind when the scene gets cheaper.

/// A PI controller of the image-space sampling `D_I` in `[min_scale, 1]`.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameRateController {
    /// The frame time to hold, in milliseconds.
    pub target_ms: f64,
    /// The smallest `D_I` it may choose.
    pub min_scale: f64,
    /// Proportional gain (on the change of the error).
    pub kp: f64,
    /// Integral gain (on the error).
    pub ki: f64,
    previous_error: f64,
    log_scale: f64,
}

/// The largest error taken from one frame (a frame 55 times off the target): a stall, a
/// window moved, does not throw `D_I` to a bound at once.
const MAX_ERROR: f64 = 2.0;

impl FrameRateController {
    /// A controller holding `target_ms` per frame, starting at full resolution, with gains
    /// that settle a cost proportional to the pixels within a few frames.
    ///
    /// # Panics
    /// When `target_ms` is not positive and finite, or `min_scale` is not in `(0, 1]`.
    pub fn new(target_ms: f64, min_scale: f64) -> Self {
        assert!(
            target_ms > 0.0 && target_ms.is_finite(),
            "target {target_ms} ms"
        );
        assert!(min_scale > 0.0 && min_scale <= 1.0, "min scale {min_scale}");
        Self {
            target_ms,
            min_scale,
            kp: 0.3,
            ki: 0.6,
            previous_error: 0.0,
            log_scale: 0.0,
        }
    }

    /// The `D_I` to render the next frame with.
    pub fn scale(&self) -> f64 {
        self.log_scale.exp()
    }

    /// Takes the time of the frame just rendered (at [`FrameRateController::scale`]) and
    /// returns the `D_I` of the next one. A non-finite or non-positive time is ignored.
    pub fn update(&mut self, frame_ms: f64) -> f64 {
        if !(frame_ms > 0.0 && frame_ms.is_finite()) {
            return self.scale();
        }
        let error = (0.5 * (self.target_ms / frame_ms).ln()).clamp(-MAX_ERROR, MAX_ERROR);
        let step = self.kp * (error - self.previous_error) + self.ki * error;
        self.previous_error = error;
        self.log_scale = (self.log_scale + step).clamp(self.min_scale.ln(), 0.0);
        self.scale()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Frame time of a renderer whose cost is `fixed` plus `per_scale²` (the pixels).
    fn cost(scale: f64, fixed: f64, per_scale2: f64) -> f64 {
        fixed + per_scale2 * scale * scale
    }

    #[test]
    fn it_settles_on_the_target_when_full_resolution_is_too_slow() {
        let mut c = FrameRateController::new(10.0, 0.1);
        let mut ms = cost(c.scale(), 1.0, 36.0);
        for _ in 0..40 {
            ms = cost(c.update(ms), 1.0, 36.0);
        }
        // 1 + 36·s² = 10 at s = 0.5.
        assert!((ms - 10.0).abs() < 1e-3, "{ms} ms at scale {}", c.scale());
        assert!((c.scale() - 0.5).abs() < 1e-4, "{}", c.scale());
        // A fixed cost the pixels cannot lower: 5 + 36·s² = 10 at s = √(5/36).
        let mut c = FrameRateController::new(10.0, 0.1);
        let mut ms = cost(c.scale(), 5.0, 36.0);
        for _ in 0..40 {
            ms = cost(c.update(ms), 5.0, 36.0);
        }
        assert!(
            (c.scale() - (5.0f64 / 36.0).sqrt()).abs() < 1e-3,
            "{}",
            c.scale()
        );
    }

    #[test]
    fn it_stays_at_full_resolution_when_frames_are_fast_and_recovers_at_once() {
        let mut c = FrameRateController::new(10.0, 0.1);
        for _ in 0..100 {
            assert_eq!(c.update(2.0), 1.0);
        }
        // No wind-up: a slow frame after many fast ones lowers the scale straight away.
        assert!(c.update(40.0) < 1.0);
    }

    #[test]
    fn it_never_goes_below_its_floor_and_ignores_bad_times() {
        let mut c = FrameRateController::new(1.0, 0.25);
        for _ in 0..50 {
            assert!(c.update(1000.0) >= 0.25);
        }
        assert_eq!(c.scale(), 0.25);
        let before = c.scale();
        assert_eq!(c.update(f64::NAN), before);
        assert_eq!(c.update(0.0), before);
        // Leaving the floor needs fast frames again, without a wound-up integral to unwind:
        // twice the target's speed doubles D_I within a few frames.
        let mut steps = 0;
        while c.update(0.5) < 1.0 {
            steps += 1;
            assert!(steps < 5, "still at {}", c.scale());
        }
    }
}
