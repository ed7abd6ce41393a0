//! How each frame of a volumetric depth image is drawn, in the window (`viewer view --vdi`)
//! and in the page's remote mode: the filter it reads the VDI with and the image-space
//! sampling `D_I`, from the user's [`VdiFilterChoice`], whether the camera moves, and what
//! frames cost on this device.
//!
//! At rest a frame is drawn at full resolution with the choice's filter at rest. While the
//! camera moves, a [`FrameRateController`] sets `D_I` to hold the frame-time target, except
//! under [`VdiFilterChoice::Auto`] on a device fast enough for the linear filter: there the
//! moving frames read the VDI with the linear filter at full resolution as long as the last
//! frame the linear filter drew at full resolution held the target. The linear filter is
//! closer to direct volume rendering away from the VDI's camera (16 channels at 10° on the VDI
//! bench: SSIM 0.988 against the nearest list's 0.970), so a device with time to spare spends
//! it on that. A linear frame over the target hands the rest of the motion to the nearest list
//! and the controller; the next linear frame at full resolution, at rest, measures the linear
//! filter again (where the last frame of a motion is a linear one, it is the rest frame: the
//! next motion then reads the nearest list, and the rest after it measures). "Held" allows
//! [`TARGET_SLACK`]. Until a linear
//! frame has been measured (a frame along the VDI's own rays is drawn by the nearest pipeline,
//! whatever the filter asked), moving frames read the nearest list: no device pays a slow
//! frame to find out.

use crate::frame_rate::FrameRateController;
use crate::gpu::vdi_filter::VdiFilter;
use crate::vdi_filter_choice::VdiFilterChoice;

/// The smallest `D_I` the controller may choose.
pub const MIN_SCALE: f64 = 0.25;

/// A linear frame this many times the target still holds it: a window's frames paced by the
/// display's refresh (a FIFO surface waits for it) take the target itself, give or take the
/// clock, whatever the ray caster costs below it.
pub const TARGET_SLACK: f64 = 1.1;

/// One frame to draw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VdiFramePlan {
    /// The filter the frame reads the VDI with.
    pub filter: VdiFilter,
    /// Its `D_I`: the fraction of the width and height rays are cast for.
    pub scale: f64,
    /// `scale` is the controller's (a moving frame the controller holds to the target).
    held: bool,
}

impl VdiFramePlan {
    /// Whether this is a preview: a frame drawn while the camera moves at the controller's
    /// `D_I`, which may also sample along its rays (`D_R`).
    pub fn preview(&self) -> bool {
        self.held
    }
}

/// Plans each VDI frame and learns from the time it took ([`VdiFramePlanner::record`]).
#[derive(Clone, Debug, PartialEq)]
pub struct VdiFramePlanner {
    choice: VdiFilterChoice,
    controller: FrameRateController,
    /// Time of the last frame the linear pipeline drew at full resolution, ms.
    linear_ms: Option<f64>,
}

impl VdiFramePlanner {
    /// A planner for the user's `choice`, holding `target_ms` per frame while the camera moves.
    ///
    /// # Panics
    /// When `target_ms` is not positive and finite.
    pub fn new(choice: VdiFilterChoice, target_ms: f64) -> Self {
        Self {
            choice,
            controller: FrameRateController::new(target_ms, MIN_SCALE),
            linear_ms: None,
        }
    }

    /// The user's choice of filter.
    pub fn choice(&self) -> VdiFilterChoice {
        self.choice
    }

    /// Takes another choice of filter from the user.
    pub fn set_choice(&mut self, choice: VdiFilterChoice) {
        self.choice = choice;
    }

    /// The frame time held while the camera moves, ms.
    pub fn target_ms(&self) -> f64 {
        self.controller.target_ms
    }

    /// Time of the last frame the linear pipeline drew at full resolution, ms, if any.
    pub fn linear_ms(&self) -> Option<f64> {
        self.linear_ms
    }

    /// The filter of a frame at rest (drawn at full resolution).
    pub fn filter_at_rest(&self) -> VdiFilter {
        self.choice.filter(false)
    }

    /// The next frame, drawn while the camera moves (`moving`) or at rest.
    pub fn next(&self, moving: bool) -> VdiFramePlan {
        let at = |filter, scale, held| VdiFramePlan {
            filter,
            scale,
            held,
        };
        if !moving {
            return at(self.filter_at_rest(), 1.0, false);
        }
        let linear_fits = self
            .linear_ms
            .is_some_and(|ms| ms <= TARGET_SLACK * self.controller.target_ms);
        if self.choice == VdiFilterChoice::Auto && linear_fits {
            return at(VdiFilter::Linear, 1.0, false);
        }
        at(self.choice.filter(true), self.controller.scale(), true)
    }

    /// Takes the time of the frame drawn for `plan`, in `ms`, by the pipeline of `drawn` (the
    /// nearest one draws a frame along the VDI's own rays whatever the plan's filter:
    /// `VdiRenderer::drawn_with`).
    pub fn record(&mut self, plan: VdiFramePlan, drawn: VdiFilter, ms: f64) {
        if plan.held {
            self.controller.update(ms);
        }
        if drawn == VdiFilter::Linear && plan.scale >= 1.0 && ms > 0.0 && ms.is_finite() {
            self.linear_ms = Some(ms);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{VdiFilter, VdiFilterChoice, VdiFramePlanner};

    /// (filter, D_I) of the next frame.
    fn next(p: &VdiFramePlanner, moving: bool) -> (VdiFilter, f64) {
        let plan = p.next(moving);
        (plan.filter, plan.scale)
    }

    #[test]
    fn auto_moves_with_the_linear_filter_while_its_last_full_frame_held_the_target() {
        use VdiFilter::{Linear, Nearest};
        let mut p = VdiFramePlanner::new(VdiFilterChoice::Auto, 10.0);
        assert_eq!(
            (next(&p, true), next(&p, false)),
            ((Nearest, 1.0), (Linear, 1.0))
        );
        // Slow nearest frames while moving: the controller lowers D_I; nothing learnt of the
        // linear filter.
        p.record(p.next(true), Nearest, 40.0);
        let (filter, scale) = next(&p, true);
        assert!(filter == Nearest && scale < 1.0, "{filter:?} {scale}");
        assert_eq!(p.linear_ms(), None);
        // A frame at rest asked linear but drawn by the nearest pipeline (along the VDI's
        // rays) says nothing of the linear filter's cost.
        p.record(p.next(false), Nearest, 1.0);
        assert_eq!((p.linear_ms(), next(&p, true).0), (None, Nearest));
        // A linear frame at rest within the target: moving frames go linear, at full
        // resolution, and leave the controller alone.
        p.record(p.next(false), Linear, 8.0);
        assert_eq!((p.linear_ms(), next(&p, true)), (Some(8.0), (Linear, 1.0)));
        p.record(p.next(true), Linear, 11.0);
        assert_eq!(next(&p, true), (Linear, 1.0));
        // One over the target and its slack: the rest of the motion is the nearest list's, at
        // the D_I the controller had (its slow frames above), until a linear frame holds the
        // target again.
        p.record(p.next(true), Linear, 11.5);
        assert_eq!(next(&p, true), (Nearest, scale));
        p.record(p.next(false), Linear, 9.0);
        assert_eq!(next(&p, true), (Linear, 1.0));
    }

    #[test]
    fn a_chosen_filter_is_kept_moving_and_at_rest() {
        for (choice, filter) in [
            (VdiFilterChoice::Nearest, VdiFilter::Nearest),
            (VdiFilterChoice::Linear, VdiFilter::Linear),
        ] {
            let mut p = VdiFramePlanner::new(choice, 10.0);
            p.record(p.next(false), filter, 1.0);
            p.record(p.next(true), filter, 1000.0);
            let (moving, scale) = next(&p, true);
            assert!(
                moving == filter && scale < 1.0,
                "{choice:?}: {moving:?} {scale}"
            );
            assert_eq!(next(&p, false), (filter, 1.0));
        }
        let mut p = VdiFramePlanner::new(VdiFilterChoice::Nearest, 10.0);
        p.record(p.next(false), VdiFilter::Nearest, 1.0);
        p.set_choice(VdiFilterChoice::Auto);
        assert_eq!(p.choice(), VdiFilterChoice::Auto);
        assert_eq!(p.filter_at_rest(), VdiFilter::Linear);
        assert_eq!(p.target_ms(), 10.0);
    }
}
