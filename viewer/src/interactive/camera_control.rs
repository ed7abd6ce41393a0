//! Mouse interaction with the [`Camera`]: orbit, pan and zoom, as pure functions of the
//! camera and the pointer motion in pixels (screen `y` runs down), so they can be tested
//! exactly.
//!
//! - **Orbit** turns the whole camera frame rigidly about the target: a horizontal drag of
//!   `dx` pixels rotates by `−dx·k` about the camera's up vector, a vertical drag of `dy`
//!   pixels by `−dy·k` about its right vector (`k` radians per pixel), so the volume turns
//!   with the pointer. The distance to the target and the frame's orthonormality are kept;
//!   the camera's `up` becomes the rotated (orthogonal) up vector.
//! - **Pan** translates eye and target together in the image plane so that a point at the
//!   target's depth follows the pointer: one pixel is `2·d·tan(fov/2)/H` world units, with `d`
//!   the eye–target distance and `H` the viewport height in pixels.
//! - **Zoom** scales the eye–target distance by `2^(−steps/4)`: four wheel steps toward the
//!   screen halve it, four away double it.

use glam::{DQuat, DVec3};

use crate::scene::Camera;

/// Wheel steps that halve the eye–target distance.
pub const STEPS_PER_HALVING: f64 = 4.0;

fn frame(cam: &Camera) -> (DVec3, DVec3, DVec3) {
    let (f, r, u) = cam.basis();
    (DVec3::from(f), DVec3::from(r), DVec3::from(u))
}

/// Orbits the camera about its target by a pointer motion of `(dx, dy)` pixels, at
/// `radians_per_pixel`.
pub fn orbit(cam: &Camera, dx: f64, dy: f64, radians_per_pixel: f64) -> Camera {
    let (_, right, up) = frame(cam);
    let yaw = DQuat::from_axis_angle(up, -dx * radians_per_pixel);
    let pitch = DQuat::from_axis_angle(right, -dy * radians_per_pixel);
    // Pitch about the current right vector, then yaw about the current up vector: both
    // axes belong to the frame before the motion, so the result does not depend on which
    // of the two a tiny motion applies first beyond second order.
    let q = yaw * pitch;
    let target = DVec3::from(cam.target);
    let eye = target + q * (DVec3::from(cam.eye) - target);
    Camera {
        eye: eye.into(),
        target: cam.target,
        up: (q * up).into(),
        fov_y_degrees: cam.fov_y_degrees,
    }
}

/// World units one pixel spans at the target's depth, in a viewport `viewport_height`
/// pixels high.
pub fn world_per_pixel(cam: &Camera, viewport_height: f64) -> f64 {
    let d = (DVec3::from(cam.eye) - DVec3::from(cam.target)).length();
    2.0 * d * (cam.fov_y_degrees.to_radians() / 2.0).tan() / viewport_height
}

/// Pans the camera so that the scene follows a pointer motion of `(dx, dy)` pixels in a
/// viewport `viewport_height` pixels high.
pub fn pan(cam: &Camera, dx: f64, dy: f64, viewport_height: f64) -> Camera {
    let (_, right, up) = frame(cam);
    let s = world_per_pixel(cam, viewport_height);
    let delta = -dx * s * right + dy * s * up;
    Camera {
        eye: (DVec3::from(cam.eye) + delta).into(),
        target: (DVec3::from(cam.target) + delta).into(),
        up: cam.up,
        fov_y_degrees: cam.fov_y_degrees,
    }
}

/// Moves the eye toward the target (positive `steps`, the wheel turned away from the user)
/// or away from it, scaling the distance by `2^(−steps/4)`; the distance never falls below
/// `min_distance`.
pub fn zoom(cam: &Camera, steps: f64, min_distance: f64) -> Camera {
    let target = DVec3::from(cam.target);
    let offset = DVec3::from(cam.eye) - target;
    let d = offset.length();
    let scaled = (d * (-steps / STEPS_PER_HALVING).exp2()).max(min_distance.min(d));
    Camera {
        eye: (target + offset * (scaled / d)).into(),
        target: cam.target,
        up: cam.up,
        fov_y_degrees: cam.fov_y_degrees,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(eye: [f64; 3], fov: f64) -> Camera {
        Camera {
            eye,
            target: [0.0; 3],
            up: [0.0, 1.0, 0.0],
            fov_y_degrees: fov,
        }
    }

    fn close(a: [f64; 3], b: [f64; 3]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12)
    }

    /// Pixel coordinates (x right, y down) of world point `p` in a `w × h` image.
    fn project(cam: &Camera, p: [f64; 3], w: f64, h: f64) -> (f64, f64) {
        let (f, r, u) = frame(cam);
        let v = DVec3::from(p) - DVec3::from(cam.eye);
        let t = (cam.fov_y_degrees.to_radians() / 2.0).tan();
        let (x, y, z) = (v.dot(r), v.dot(u), v.dot(f));
        let nx = x / z / (t * w / h);
        let ny = y / z / t;
        ((nx + 1.0) * w / 2.0, (1.0 - ny) * h / 2.0)
    }

    #[test]
    fn horizontal_drag_turns_the_eye_against_the_pointer_about_up() {
        let c = orbit(&cam([0.0, 0.0, 10.0], 30.0), 90.0, 0.0, 1f64.to_radians());
        // Dragging right moves the eye to the left (−x), a quarter turn.
        assert!(close(c.eye, [-10.0, 0.0, 0.0]), "{:?}", c.eye);
        assert!(close(c.up, [0.0, 1.0, 0.0]), "{:?}", c.up);
        assert_eq!(c.target, [0.0; 3]);
        let (f, r, _) = c.basis();
        assert!(
            close(f, [1.0, 0.0, 0.0]) && close(r, [0.0, 0.0, 1.0]),
            "{f:?} {r:?}"
        );
        // Half a turn the other way: the eye behind the target.
        let c = orbit(&cam([0.0, 0.0, 10.0], 30.0), -90.0, 0.0, 2f64.to_radians());
        assert!(close(c.eye, [0.0, 0.0, -10.0]), "{:?}", c.eye);
    }

    #[test]
    fn vertical_drag_tilts_the_eye_about_right_and_up_follows() {
        let c = orbit(&cam([0.0, 0.0, 10.0], 30.0), 0.0, 90.0, 1f64.to_radians());
        // Dragging down lifts the eye over the top: it looks straight down −y.
        assert!(close(c.eye, [0.0, 10.0, 0.0]), "{:?}", c.eye);
        assert!(close(c.up, [0.0, 0.0, -1.0]), "{:?}", c.up);
        let (f, r, u) = c.basis();
        assert!(close(f, [0.0, -1.0, 0.0]), "{f:?}");
        assert!(close(r, [1.0, 0.0, 0.0]), "right is the axis: {r:?}");
        assert!(close(u, [0.0, 0.0, -1.0]), "{u:?}");
        // 30° up.
        let c = orbit(&cam([0.0, 0.0, 10.0], 30.0), 0.0, 30.0, 1f64.to_radians());
        assert!(
            close(c.eye, [0.0, 5.0, 10.0 * 0.75f64.sqrt()]),
            "{:?}",
            c.eye
        );
    }

    #[test]
    fn orbit_is_rigid_about_the_target() {
        let mut c = Camera {
            eye: [3.0, -4.0, 12.0],
            target: [1.0, 2.0, 3.0],
            up: [0.2, -1.0, 0.1],
            fov_y_degrees: 40.0,
        };
        let d0 = (DVec3::from(c.eye) - DVec3::from(c.target)).length();
        for (dx, dy) in [(13.0, -7.0), (-40.0, 22.0), (5.0, 300.0)] {
            c = orbit(&c, dx, dy, 0.01);
            let d = (DVec3::from(c.eye) - DVec3::from(c.target)).length();
            assert!((d - d0).abs() < 1e-12, "{d} {d0}");
            assert_eq!(c.target, [1.0, 2.0, 3.0]);
            let (f, _, _) = frame(&c);
            assert!(
                DVec3::from(c.up).dot(f).abs() < 1e-12,
                "up stays orthogonal"
            );
            assert!((DVec3::from(c.up).length() - 1.0).abs() < 1e-12);
        }
        // No motion, no change (beyond the up vector becoming orthonormal).
        let still = orbit(&c, 0.0, 0.0, 0.01);
        assert!(close(still.eye, c.eye) && close(still.up, c.up));
    }

    #[test]
    fn pan_moves_eye_and_target_so_the_scene_follows_the_pointer() {
        // fov 90°, distance 10, 100 px high: one pixel is 0.2 world units.
        let c0 = cam([0.0, 0.0, 10.0], 90.0);
        assert!((world_per_pixel(&c0, 100.0) - 0.2).abs() < 1e-15);
        let c = pan(&c0, 10.0, 0.0, 100.0);
        assert!(close(c.eye, [-2.0, 0.0, 10.0]), "{:?}", c.eye);
        assert!(close(c.target, [-2.0, 0.0, 0.0]), "{:?}", c.target);
        assert_eq!(c.up, c0.up);
        let c = pan(&c0, 0.0, 5.0, 100.0);
        assert!(close(c.eye, [0.0, 1.0, 10.0]) && close(c.target, [0.0, 1.0, 0.0]));
        // A point at the target's depth moves by exactly the pointer's motion on screen.
        let c0 = Camera {
            eye: [3.0, -4.0, 12.0],
            target: [1.0, 2.0, 3.0],
            up: [0.0, -1.0, 0.0],
            fov_y_degrees: 30.0,
        };
        let (w, h) = (160.0, 120.0);
        let (x0, y0) = project(&c0, c0.target, w, h);
        assert!((x0 - 80.0).abs() < 1e-9 && (y0 - 60.0).abs() < 1e-9);
        let c = pan(&c0, 17.0, -9.0, h);
        let (x, y) = project(&c, c0.target, w, h);
        assert!(
            (x - 97.0).abs() < 1e-9 && (y - 51.0).abs() < 1e-9,
            "{x} {y}"
        );
    }

    #[test]
    fn zoom_scales_the_distance_by_powers_of_two() {
        let c0 = cam([0.0, 0.0, 16.0], 30.0);
        assert_eq!(zoom(&c0, 4.0, 0.0).eye, [0.0, 0.0, 8.0]);
        assert_eq!(zoom(&c0, -8.0, 0.0).eye, [0.0, 0.0, 64.0]);
        assert!(close(
            zoom(&c0, 2.0, 0.0).eye,
            [0.0, 0.0, 8.0 * 2f64.sqrt()]
        ));
        assert_eq!(zoom(&c0, 0.0, 0.0), c0);
        // Never closer than the minimum distance.
        assert_eq!(zoom(&c0, 100.0, 1.0).eye, [0.0, 0.0, 1.0]);
        // Off-axis: the direction is kept.
        let c = Camera {
            eye: [4.0, 6.0, 15.0],
            target: [1.0, 2.0, 3.0],
            ..c0
        };
        let z = zoom(&c, 4.0, 0.0);
        assert!(close(z.eye, [2.5, 4.0, 9.0]), "{:?}", z.eye);
        assert_eq!(z.target, c.target);
    }
}
