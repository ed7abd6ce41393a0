//! What part of the volume a scene draws: a box, planes and a distance from the eye
//! ([`Clip`]), and the f64 rule that cuts a ray's span by them, which the GPU's `volume_span`
//! (`shaders/view.wgsl`) follows.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::Camera;

/// The most clipping planes a scene has (besides `near`).
pub const MAX_CLIP_PLANES: usize = 6;

/// An axis-aligned box in world space: the points `p` with `min ≤ p ≤ max` on every axis.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ClipBox {
    /// Low corner, world `x, y, z`.
    pub min: [f64; 3],
    /// High corner, world `x, y, z`.
    pub max: [f64; 3],
}

/// A plane in world space keeping the half-space its normal points into: the points `p` with
/// `(p − point) · normal ≥ 0`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ClipPlane {
    /// A point on the plane, world `x, y, z`.
    pub point: [f64; 3],
    /// Its normal (any length but 0), pointing into what is kept.
    pub normal: [f64; 3],
}

impl ClipPlane {
    /// Where the ray `eye + t·dir` is on the kept side, as a bound on `t`: `(lo, hi)` with
    /// `lo = −∞` or `hi = +∞` where the plane does not bound that end; `None` for a ray
    /// parallel to the plane on the cut side.
    fn bound(&self, eye: [f64; 3], dir: [f64; 3]) -> Option<(f64, f64)> {
        let s0: f64 = (0..3)
            .map(|k| (eye[k] - self.point[k]) * self.normal[k])
            .sum();
        let dn: f64 = (0..3).map(|k| dir[k] * self.normal[k]).sum();
        if dn == 0.0 {
            return (s0 >= 0.0).then_some((f64::NEG_INFINITY, f64::INFINITY));
        }
        let t = -s0 / dn;
        Some(if dn > 0.0 {
            (t, f64::INFINITY)
        } else {
            (f64::NEG_INFINITY, t)
        })
    }
}

/// What part of the volume is drawn: the points inside the box, on the kept side of every
/// plane, and at least `near` from the eye along the view direction (a plane that follows the
/// camera). Clipping cuts each ray's span through the volume, so what lies outside is neither
/// sampled nor fetched, in every mode and method.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Clip {
    /// The box kept (world space).
    #[serde(default, rename = "box", skip_serializing_if = "Option::is_none")]
    pub region: Option<ClipBox>,
    /// Planes, each keeping the side its normal points into; at most [`MAX_CLIP_PLANES`].
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    #[schemars(length(max = 6))]
    pub planes: Vec<ClipPlane>,
    /// Distance from the eye along the view direction before which nothing is drawn (world
    /// units).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(range(min = 0))]
    pub near: Option<f64>,
}

/// Why a scene's clipping cannot be drawn.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ClipError {
    /// A box whose corners are not finite, or whose low corner is above its high one.
    #[error("clip box: min {min:?} must be finite and at most max {max:?} on every axis")]
    Box {
        /// The low corner given.
        min: [f64; 3],
        /// The high corner given.
        max: [f64; 3],
    },
    /// A plane whose point or normal is not finite, or whose normal is 0.
    #[error(
        "clip plane {index}: point {point:?} and normal {normal:?} must be finite, the normal not 0"
    )]
    Plane {
        /// Its position in the list.
        index: usize,
        /// Its point.
        point: [f64; 3],
        /// Its normal.
        normal: [f64; 3],
    },
    /// More planes than [`MAX_CLIP_PLANES`].
    #[error("clip: {planes} planes, at most {MAX_CLIP_PLANES}")]
    TooManyPlanes {
        /// How many were given.
        planes: usize,
    },
    /// A near distance that is negative or not finite.
    #[error("clip near {near}: must be finite and at least 0")]
    Near {
        /// The distance given.
        near: f64,
    },
}

impl Clip {
    /// Whether nothing is clipped.
    pub fn is_empty(&self) -> bool {
        self.region.is_none() && self.planes.is_empty() && self.near.is_none()
    }

    /// Checks that the clipping can be drawn.
    ///
    /// # Errors
    /// The first [`ClipError`]: the box, the planes' count, each plane, then `near`.
    pub fn check(&self) -> Result<(), ClipError> {
        if let Some(b) = self.region {
            let ok = (0..3)
                .all(|k| b.min[k].is_finite() && b.max[k].is_finite() && b.min[k] <= b.max[k]);
            if !ok {
                return Err(ClipError::Box {
                    min: b.min,
                    max: b.max,
                });
            }
        }
        if self.planes.len() > MAX_CLIP_PLANES {
            return Err(ClipError::TooManyPlanes {
                planes: self.planes.len(),
            });
        }
        for (index, p) in self.planes.iter().enumerate() {
            let finite = p.point.iter().chain(&p.normal).all(|v| v.is_finite());
            if !finite || p.normal == [0.0; 3] {
                return Err(ClipError::Plane {
                    index,
                    point: p.point,
                    normal: p.normal,
                });
            }
        }
        if let Some(near) = self.near
            && !(near.is_finite() && near >= 0.0)
        {
            return Err(ClipError::Near { near });
        }
        Ok(())
    }

    /// Every plane that bounds what is kept, for `camera`: the planes, then `near`'s (its
    /// normal the view direction).
    pub fn planes_for(&self, camera: &Camera) -> Vec<ClipPlane> {
        let mut planes = self.planes.clone();
        if let Some(near) = self.near {
            let (forward, _, _) = camera.basis();
            planes.push(ClipPlane {
                point: std::array::from_fn(|k| camera.eye[k] + near * forward[k]),
                normal: forward,
            });
        }
        planes
    }

    /// The part `[t0, t1]` of the span `span` of the ray `eye + t·dir` that is kept (`None`
    /// when nothing is), `planes` being [`Clip::planes_for`] the camera at `eye` (worked out
    /// once per view): the f64 rule the GPU follows in `volume_span`.
    pub fn clip_span(
        &self,
        planes: &[ClipPlane],
        eye: [f64; 3],
        dir: [f64; 3],
        span: (f64, f64),
    ) -> Option<(f64, f64)> {
        let (mut t0, mut t1) = span;
        if let Some(b) = self.region {
            for k in 0..3 {
                if dir[k] == 0.0 {
                    if eye[k] < b.min[k] || eye[k] > b.max[k] {
                        return None;
                    }
                    continue;
                }
                let (ta, tb) = ((b.min[k] - eye[k]) / dir[k], (b.max[k] - eye[k]) / dir[k]);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
        }
        for plane in planes {
            let (lo, hi) = plane.bound(eye, dir)?;
            t0 = t0.max(lo);
            t1 = t1.min(hi);
        }
        (t1 > t0).then_some((t0, t1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    #[test]
    fn clipping_cuts_the_span_by_the_box_the_planes_and_near() {
        let camera = Camera {
            eye: [-10.0, 5.0, 5.0],
            target: [5.0, 5.0, 5.0],
            up: [0.0, 1.0, 0.0],
            fov_y_degrees: 30.0,
        };
        let dir = [1.0, 0.0, 0.0];
        let span = (10.0, 20.0); // the volume [0, 10) along x
        let mut clip = Clip::default();
        assert!(clip.is_empty());
        assert_eq!(
            clip.clip_span(&clip.planes_for(&camera), camera.eye, dir, span),
            Some(span)
        );
        clip.region = Some(ClipBox {
            min: [2.0, 0.0, 0.0],
            max: [6.0, 10.0, 10.0],
        });
        assert_eq!(
            clip.clip_span(&clip.planes_for(&camera), camera.eye, dir, span),
            Some((12.0, 16.0))
        );
        // A plane keeping x ≥ 3 (normal +x), then one keeping x ≤ 5.
        clip.planes.push(ClipPlane {
            point: [3.0, 0.0, 0.0],
            normal: [2.0, 0.0, 0.0],
        });
        clip.planes.push(ClipPlane {
            point: [5.0, 0.0, 0.0],
            normal: [-1.0, 0.0, 0.0],
        });
        assert_eq!(
            clip.clip_span(&clip.planes_for(&camera), camera.eye, dir, span),
            Some((13.0, 15.0))
        );
        // Near: nothing closer than 14 to the eye along the view direction.
        clip.near = Some(14.0);
        assert_eq!(
            clip.clip_span(&clip.planes_for(&camera), camera.eye, dir, span),
            Some((14.0, 15.0))
        );
        assert_eq!(clip.planes_for(&camera).len(), 3);
        clip.near = Some(16.0);
        assert_eq!(
            clip.clip_span(&clip.planes_for(&camera), camera.eye, dir, span),
            None
        );
        // A ray parallel to a plane: kept on its side, cut on the other.
        let side = ClipPlane {
            point: [0.0, 6.0, 0.0],
            normal: [0.0, 1.0, 0.0],
        };
        let parallel = Clip {
            planes: vec![side],
            ..Clip::default()
        };
        assert_eq!(
            parallel.clip_span(&parallel.planes, camera.eye, dir, span),
            None
        );
        let other = Clip {
            planes: vec![ClipPlane {
                normal: [0.0, -1.0, 0.0],
                ..side
            }],
            ..Clip::default()
        };
        assert_eq!(
            other.clip_span(&other.planes, camera.eye, dir, span),
            Some(span)
        );
    }

    #[test]
    fn clipping_that_cannot_be_drawn_is_named() {
        let plane = ClipPlane {
            point: [0.0; 3],
            normal: [0.0, 0.0, 1.0],
        };
        let cases = [
            (
                Clip {
                    region: Some(ClipBox {
                        min: [0.0, 5.0, 0.0],
                        max: [1.0, 4.0, 1.0],
                    }),
                    ..Clip::default()
                },
                "clip box: min [0.0, 5.0, 0.0] must be finite and at most max [1.0, 4.0, 1.0] \
                 on every axis",
            ),
            (
                Clip {
                    planes: vec![plane; 7],
                    ..Clip::default()
                },
                "clip: 7 planes, at most 6",
            ),
            (
                Clip {
                    planes: vec![
                        plane,
                        ClipPlane {
                            normal: [0.0; 3],
                            ..plane
                        },
                    ],
                    ..Clip::default()
                },
                "clip plane 1: point [0.0, 0.0, 0.0] and normal [0.0, 0.0, 0.0] must be \
                 finite, the normal not 0",
            ),
            (
                Clip {
                    near: Some(-1.0),
                    ..Clip::default()
                },
                "clip near -1: must be finite and at least 0",
            ),
        ];
        for (clip, message) in cases {
            assert_eq!(clip.check().unwrap_err().to_string(), message);
        }
        let json = r#"{"camera": {"eye": [0,0,5], "target": [0,0,0]}, "channels": [],
            "clip": {"box": {"min": [0,0,0], "max": [1,1,1]}, "near": 2}}"#;
        let s: Scene = serde_json::from_str(json).unwrap();
        assert_eq!(s.clip.near, Some(2.0));
        assert!(s.clip.check().is_ok());
        // An unclipped scene is written without the field.
        let plain = Scene {
            clip: Clip::default(),
            ..s
        };
        assert!(serde_json::to_value(&plain).unwrap().get("clip").is_none());
    }
}
