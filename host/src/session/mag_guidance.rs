//! Magnetometer guidance a person can act on: from the board's current attitude (the
//! accelerometer's up direction) and the current field direction, both in the board frame, how
//! to turn the board so the field lands in an empty coverage region ([`super::coverage`]).
//!
//! Geometry. The Earth's field `f` and the up direction `u` are fixed in the room; seen from the
//! board they turn together, so the angle `δ` between them (90° plus the dip) never changes. A
//! turn about the vertical (a heading change) keeps `u` and swings `f` on the cone of half-angle
//! `δ` around it: it moves only the field's horizontal part. A target direction `t` is reachable
//! by heading alone when `∠(u, t) = δ`. Otherwise the board has to be tilted first: the smallest
//! tilt brings the up direction to the nearest point of the cone `{u′ : ∠(u′, t) = δ}`,
//! `u′ = cos δ·t + sin δ·p` with `p` the unit part of `u` perpendicular to `t`, a tilt of
//! `|∠(u, t) − δ|`. Up moving towards the board direction `d` means the end of the board at `d`
//! rises. Names of ends and faces follow the positions' pictures ([`super::targets`]): `±X`,
//! `±Y` are ends, `+Z` is the components face.

use serde::Serialize;

use super::coverage::{region_directions, region_name, Coverage};
use super::targets::direction_name;
use crate::device::UnitSample;
use crate::fit::Vec3;

/// A tilt smaller than this leaves the field inside the target's region, so a heading turn is
/// enough: half the smallest angle between two region centres (edge to corner, acos √(2/3) =
/// 35.3°), the radius of the cap around a centre that lies wholly inside its region.
pub const HEADING_ONLY_DEG: f64 = 17.6;

/// What the person should do next.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Turn {
    /// The field already points into the target region: keep sweeping slowly around here.
    Hold,
    /// Keep the tilt and turn about the vertical.
    Heading {
        /// Clockwise as seen from above.
        clockwise: bool,
        /// Angle, degrees (rounded to 5°).
        degrees: f64,
    },
    /// Tilt the board so that `raise` goes up (and its opposite down).
    Tilt {
        /// Board end(s) or face that rises, e.g. `+X` or `-Y+Z`.
        raise: String,
        /// The opposite side, which goes down.
        lower: String,
        /// Angle, degrees (rounded to 5°).
        degrees: f64,
    },
}

/// One instruction towards an empty coverage region.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MagGuidance {
    /// The region aimed at (a board-frame field direction, e.g. `+X-Z`).
    pub target: String,
    /// The movement.
    pub turn: Turn,
    /// The instruction as a sentence.
    pub text: String,
}

/// Round to the nearest 5°, at least 5° (a person cannot act on less).
fn round_degrees(deg: f64) -> f64 {
    ((deg / 5.0).round() * 5.0).max(5.0)
}

/// Share of a unit tilt direction below which an axis is left unnamed: sin 22.5°, an axis that
/// adds less than half the 45° between neighbouring region axes to the direction.
const NAMED_SHARE: f64 = 0.383;

/// `d` with the axes it barely involves set to zero, so that it names one end, one corner or one
/// end with a face.
fn prominent(d: &Vec3) -> Vec3 {
    d.map(|v| if v.abs() >= NAMED_SHARE { v } else { 0.0 })
}

/// Words for the side of the board at `side` (from [`prominent`]) and whether they are plural:
/// `the +X end`, `the +X-Y corner`, `the components face (+Z)`, `the -Y end and the underside
/// (-Z)`.
fn side_words(side: &Vec3) -> (String, bool) {
    let mut ends = String::new();
    for (i, axis) in ['X', 'Y'].iter().enumerate() {
        if side[i] != 0.0 {
            ends.push(if side[i] > 0.0 { '+' } else { '-' });
            ends.push(*axis);
        }
    }
    let ends = match ends.len() {
        0 => None,
        2 => Some(format!("the {ends} end")),
        _ => Some(format!("the {ends} corner")),
    };
    let face = if side.z > 0.0 {
        Some("the components face (+Z)")
    } else if side.z < 0.0 {
        Some("the underside (-Z)")
    } else {
        None
    };
    match (ends, face) {
        (Some(e), Some(f)) => (format!("{e} and {f}"), true),
        (Some(e), None) => (e, false),
        (None, Some(f)) => (f.to_string(), false),
        (None, None) => (direction_name(side), false),
    }
}

fn angle_deg(a: &Vec3, b: &Vec3) -> f64 {
    a.dot(b).clamp(-1.0, 1.0).acos().to_degrees()
}

/// Any unit vector perpendicular to `v` (unit).
fn any_perpendicular(v: &Vec3) -> Vec3 {
    let helper = if v.x.abs() < 0.9 {
        Vec3::x()
    } else {
        Vec3::y()
    };
    v.cross(&helper).normalize()
}

/// The up direction nearest `u` (unit) at `delta_deg` from `t` (unit): where the smallest tilt
/// takes it, so that a heading turn then brings the field onto `t`.
fn tilted_up(u: &Vec3, delta_deg: f64, t: &Vec3) -> Vec3 {
    let p = (u - t * t.dot(u))
        .try_normalize(1e-9)
        .unwrap_or_else(|| any_perpendicular(t));
    let delta = delta_deg.to_radians();
    t * delta.cos() + p * delta.sin()
}

/// How to turn the board so the field, seen in the board frame, points along `target`.
///
/// `up` is the accelerometer's reading (at rest it points up in the board frame), `field` the
/// magnetometer's reading less its hard-iron centre; only directions matter. `None` when either
/// vector is zero or not finite.
pub fn guidance(up: &Vec3, field: &Vec3, target: &Vec3) -> Option<MagGuidance> {
    let finite = |v: &Vec3| v.iter().all(|x| x.is_finite());
    if !(finite(up) && finite(field) && finite(target)) {
        return None;
    }
    let u = up.try_normalize(1e-12)?;
    let f = field.try_normalize(1e-12)?;
    let t = target.try_normalize(1e-12)?;
    let target_name = region_name(&t);
    let delta = angle_deg(&u, &f);
    let tilt_deg = angle_deg(&u, &t) - delta;
    let (turn, text) = if angle_deg(&f, &t) <= HEADING_ONLY_DEG {
        (
            Turn::Hold,
            format!("{target_name} is here: sweep slowly around this attitude"),
        )
    } else if tilt_deg.abs() <= HEADING_ONLY_DEG {
        // Both on the cone around up: the field's horizontal part has to swing from f to t.
        let horizontal = |v: &Vec3| v - u * u.dot(v);
        let (fh, th) = (horizontal(&f), horizontal(&t));
        // Signed angle of the field about up (counter-clockwise seen from above); the board
        // turns the other way.
        let phi = u.dot(&fh.cross(&th)).atan2(fh.dot(&th)).to_degrees();
        let degrees = round_degrees(phi.abs());
        let clockwise = phi > 0.0;
        (
            Turn::Heading { clockwise, degrees },
            format!(
                "for {target_name}: keep the tilt, turn about {degrees:.0}° {} seen from above",
                if clockwise {
                    "clockwise"
                } else {
                    "counter-clockwise"
                }
            ),
        )
    } else {
        let new_up = tilted_up(&u, delta, &t);
        // The board direction up moves towards rises.
        let towards = (new_up - u * u.dot(&new_up))
            .try_normalize(1e-9)
            .unwrap_or_else(|| any_perpendicular(&u));
        let degrees = round_degrees(tilt_deg.abs());
        let (raise, lower) = (prominent(&towards), prominent(&-towards));
        let ((up_words, plural), (down_words, _)) = (side_words(&raise), side_words(&lower));
        let (rise, go) = if plural {
            ("rise", "go")
        } else {
            ("rises", "goes")
        };
        (
            Turn::Tilt {
                raise: direction_name(&raise),
                lower: direction_name(&lower),
                degrees,
            },
            format!(
                "for {target_name}: tilt about {degrees:.0}° so {up_words} {rise} and \
                 {down_words} {go} down (a turn about the vertical alone cannot reach it)"
            ),
        )
    };
    Some(MagGuidance {
        target: target_name,
        turn,
        text,
    })
}

/// Guidance towards the empty region (fewer than `min_samples`) nearest the current field
/// direction `field` (reading less `cover.centre`); `None` when every region is full or the
/// attitude is unknown.
pub fn towards_nearest_empty(
    cover: &Coverage,
    min_samples: usize,
    up: &Vec3,
    field: &Vec3,
) -> Option<MagGuidance> {
    let f = field.try_normalize(1e-12)?;
    let target = region_directions()
        .into_iter()
        .zip(&cover.counts)
        .filter(|(_, &c)| c < min_samples)
        .map(|(d, _)| d)
        .max_by(|a, b| a.dot(&f).total_cmp(&b.dot(&f)))?;
    guidance(up, field, &target)
}

/// Running attitude for the guidance: exponentially weighted means of the accelerometer and the
/// raw magnetometer over about the last [`Attitude::SAMPLES`] samples, which smooths the hand's
/// shake and the accelerations of the turn while following the board within a fraction of a
/// second.
#[derive(Debug, Clone, Default)]
pub struct Attitude {
    accel: Option<Vec3>,
    mag: Option<Vec3>,
}

impl Attitude {
    /// Memory of the running means, samples (0.1–0.2 s at the streams' 100–200 Hz).
    pub const SAMPLES: f64 = 20.0;

    /// Take one sample.
    pub fn push(&mut self, sample: &UnitSample) {
        let weight = 1.0 / Self::SAMPLES;
        let blend = |mean: Option<Vec3>, x: Vec3| {
            Some(mean.map_or(x, |m| m + (x - m) * weight))
                .filter(|v| v.iter().all(|c| c.is_finite()))
        };
        self.accel = blend(self.accel, Vec3::from(sample.accel));
        self.mag = blend(self.mag, Vec3::from(sample.mag));
    }

    /// Guidance towards the nearest empty region of `cover` from the current attitude.
    pub fn guidance(&self, cover: &Coverage, min_samples: usize) -> Option<MagGuidance> {
        let (up, mag) = (self.accel?, self.mag?);
        towards_nearest_empty(cover, min_samples, &up, &(mag - cover.centre))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Unit};

    /// Field in the room: north along world x, dipping `dip_deg` below the horizon (world z up).
    fn world_field(dip_deg: f64) -> Vec3 {
        let dip = dip_deg.to_radians();
        Vec3::new(dip.cos(), 0.0, -dip.sin())
    }

    /// Up and field in the board frame for a board turned by `body_to_world`.
    fn seen(body_to_world: &Rotation3<f64>, dip_deg: f64) -> (Vec3, Vec3) {
        let inv = body_to_world.inverse();
        (inv * Vec3::z(), inv * world_field(dip_deg))
    }

    /// Rotation about a board axis.
    fn about(axis: Vec3, deg: f64) -> Rotation3<f64> {
        Rotation3::from_axis_angle(&Unit::new_normalize(axis), deg.to_radians())
    }

    #[test]
    fn flat_board_needs_a_tilt_to_bring_the_field_along_its_x_axis() {
        // Flat, components up, +X pointing north; the field dips 60°.
        let (up, field) = seen(&Rotation3::identity(), 60.0);
        let g = guidance(&up, &field, &Vec3::x()).expect("guidance");
        // Lowering the north (+X) end by the dip lines +X up with the field.
        assert_eq!(
            g.turn,
            Turn::Tilt {
                raise: "-X".into(),
                lower: "+X".into(),
                degrees: 60.0
            }
        );
        assert!(g.text.contains("the -X end rises"), "{}", g.text);
        assert!(g.text.contains("the +X end goes down"), "{}", g.text);
        assert!(g.text.contains("cannot reach"), "{}", g.text);
    }

    #[test]
    fn the_smallest_tilt_then_the_heading_turn_bring_the_field_onto_every_target() {
        // Carry the two steps out exactly (unrounded) for several attitudes and every region:
        // the room turns rigidly in the board frame, so up and field move together.
        for (k, axis) in [Vec3::new(0.3, -0.8, 0.5), Vec3::new(-0.6, 0.2, 0.7)]
            .into_iter()
            .enumerate()
        {
            let (up, field) = seen(&about(axis, 35.0 + 50.0 * k as f64), 55.0);
            let delta = angle_deg(&up, &field);
            for t in region_directions() {
                let new_up = tilted_up(&up, delta, &t);
                let tilt =
                    Rotation3::rotation_between(&up, &new_up).unwrap_or_else(Rotation3::identity);
                let (u2, f2) = (tilt * up, tilt * field);
                assert!((angle_deg(&u2, &t) - delta).abs() < 1e-6);
                // The tilt is the smallest that puts t on the field's cone around up.
                let smallest = (angle_deg(&up, &t) - delta).abs();
                assert!((angle_deg(&up, &u2) - smallest).abs() < 1e-6);
                // After it, the guidance is a heading turn (or nothing), and that turn is exact.
                let then = guidance(&u2, &f2, &t).expect("guidance");
                let h = |v: &Vec3| v - u2 * u2.dot(v);
                let signed = u2.dot(&h(&f2).cross(&h(&t))).atan2(h(&f2).dot(&h(&t)));
                match then.turn {
                    Turn::Hold => assert!(angle_deg(&f2, &t) <= HEADING_ONLY_DEG),
                    Turn::Heading { clockwise, degrees } => {
                        assert_eq!(clockwise, signed > 0.0);
                        assert!((degrees - signed.abs().to_degrees()).abs() <= 2.5 + 1e-9);
                    }
                    Turn::Tilt { .. } => panic!("still a tilt after tilting: {then:?}"),
                }
                // The board turns by -φ about up, the room (and the field) by +φ in its frame.
                let f3 = Rotation3::from_axis_angle(&Unit::new_normalize(u2), signed) * f2;
                // acos near 1 resolves angles to about √ε rad ≈ 1e-6°.
                assert!(angle_deg(&f3, &t) < 1e-4, "{}: {then:?}", region_name(&t));
            }
        }
    }

    #[test]
    fn a_target_on_the_cone_around_up_needs_only_a_heading_turn_in_the_right_sense() {
        // Flat, +X north, field horizontal (dip 0): the field is +X in the board frame. Turning
        // the board 90° clockwise seen from above points +X east and +Y north.
        let (up, field) = seen(&Rotation3::identity(), 0.0);
        let g = guidance(&up, &field, &Vec3::y()).expect("guidance");
        assert_eq!(
            g.turn,
            Turn::Heading {
                clockwise: true,
                degrees: 90.0
            }
        );
        let turned = about(Vec3::z(), -90.0);
        let (_, after) = seen(&turned, 0.0);
        assert!((after - Vec3::y()).norm() < 1e-9, "{after}");
        let g = guidance(&up, &field, &-Vec3::y()).expect("guidance");
        assert!(matches!(
            g.turn,
            Turn::Heading {
                clockwise: false,
                ..
            }
        ));
        assert!(g.text.contains("counter-clockwise"), "{}", g.text);
    }

    #[test]
    fn a_heading_turn_cannot_reach_a_direction_off_the_cone_and_says_so() {
        // Flat; the field dips 60°, so it is 150° from up; -Z is 180° from up: a 30° tilt.
        let (up, field) = seen(&Rotation3::identity(), 60.0);
        let g = guidance(&up, &field, &-Vec3::z()).expect("guidance");
        match &g.turn {
            Turn::Tilt { degrees, .. } => assert_eq!(*degrees, 30.0),
            other => panic!("expected a tilt, got {other:?}"),
        }
        assert!(g
            .text
            .contains("a turn about the vertical alone cannot reach it"));
    }

    #[test]
    fn the_components_face_is_named_when_it_has_to_come_up() {
        // Standing on its -X end (+X up), the components face (+Z) towards north, field
        // horizontal. For the field along -X+Z the board leans back 45°: the face rises.
        let standing = Rotation3::from_matrix_unchecked(nalgebra::Matrix3::from_columns(&[
            Vec3::z(),
            -Vec3::y(),
            Vec3::x(),
        ]));
        let (up, field) = seen(&standing, 0.0);
        assert!((up - Vec3::x()).norm() < 1e-9 && (field - Vec3::z()).norm() < 1e-9);
        let g = guidance(&up, &field, &Vec3::new(-1.0, 0.0, 1.0)).expect("guidance");
        assert_eq!(
            g.turn,
            Turn::Tilt {
                raise: "+Z".into(),
                lower: "-Z".into(),
                degrees: 45.0
            }
        );
        assert!(
            g.text.contains("the components face (+Z) rises"),
            "{}",
            g.text
        );
        assert!(
            g.text.contains("the underside (-Z) goes down"),
            "{}",
            g.text
        );
    }

    #[test]
    fn a_diagonal_tilt_names_the_corner_that_rises() {
        // Flat, field horizontal along +X: the +X+Y-Z corner direction needs the +X+Y corner up.
        let g = guidance(&Vec3::z(), &Vec3::x(), &Vec3::new(1.0, 1.0, -1.0)).expect("guidance");
        assert_eq!(
            g.turn,
            Turn::Tilt {
                raise: "+X+Y".into(),
                lower: "-X-Y".into(),
                degrees: 35.0
            }
        );
        assert!(
            g.text
                .contains("the +X+Y corner rises and the -X-Y corner goes down"),
            "{}",
            g.text
        );
    }

    #[test]
    fn a_field_already_in_the_target_region_says_hold() {
        let (up, field) = seen(&Rotation3::identity(), 60.0);
        let g = guidance(&up, &field, &field).expect("guidance");
        assert_eq!(g.turn, Turn::Hold);
    }

    #[test]
    fn zero_or_non_finite_readings_give_no_guidance() {
        assert!(guidance(&Vec3::zeros(), &Vec3::x(), &Vec3::y()).is_none());
        assert!(guidance(&Vec3::z(), &Vec3::zeros(), &Vec3::y()).is_none());
        assert!(guidance(&Vec3::new(f64::NAN, 0.0, 1.0), &Vec3::x(), &Vec3::y()).is_none());
    }

    #[test]
    fn the_nearest_empty_region_is_the_one_aimed_at() {
        let mut counts = vec![50usize; crate::session::coverage::REGIONS];
        let names: Vec<String> = region_directions().iter().map(region_name).collect();
        for empty in ["-Z", "+X-Z"] {
            let i = names.iter().position(|n| n == empty).expect("a region");
            counts[i] = 0;
        }
        let cover = Coverage {
            counts,
            centre: Vec3::new(10.0, -20.0, 5.0),
        };
        // Field along +X: +X-Z (45° away) is nearer than -Z (90°).
        let g = towards_nearest_empty(&cover, 10, &Vec3::z(), &Vec3::x()).expect("guidance");
        assert_eq!(g.target, "+X-Z");
        let full = Coverage {
            counts: vec![50; crate::session::coverage::REGIONS],
            centre: Vec3::zeros(),
        };
        assert!(towards_nearest_empty(&full, 10, &Vec3::z(), &Vec3::x()).is_none());
    }
}
