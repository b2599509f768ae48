//! The orientations a guided session asks for: the twelve positions of seed 003 (Chen et al.
//! 2012, §2.2: the six faces up, then the XY, YZ and XZ planes at 45° and 135°), and the eight
//! corner directions offered as extra positions when the covariance says they help. A target is
//! the body-frame direction that points up; the board is "in" a target when its measured up
//! direction is within [`MATCH_ANGLE_DEG`] of it.

use crate::fit::Vec3;

/// The board counts as being in a target when its up direction is within this angle of it.
///
/// Neighbouring targets are 45° apart, so 20° never matches two; a person places the board
/// within a few degrees, and the raw (uncalibrated) reading tilts the direction by at most a
/// few degrees more (±0.3 m/s² bias and ±3 % scale of a consumer part).
pub const MATCH_ANGLE_DEG: f64 = 20.0;

/// One orientation to capture.
#[derive(Debug, Clone, PartialEq)]
pub struct Target {
    /// Index in the session's target list.
    pub index: usize,
    /// Body-frame direction that points up (unit).
    pub up: Vec3,
    /// Short name, e.g. `"+Z up"` or `"+X+Y up (45°)"`.
    pub name: String,
}

fn axis_name(index: usize) -> char {
    match index {
        0 => 'X',
        1 => 'Y',
        _ => 'Z',
    }
}

/// Name of an up direction from its signed components above 0.3, e.g. `+X-Y`.
pub fn direction_name(up: &Vec3) -> String {
    let mut name = String::new();
    for (i, v) in up.iter().enumerate() {
        if v.abs() > 0.3 {
            name.push(if *v > 0.0 { '+' } else { '-' });
            name.push(axis_name(i));
        }
    }
    name
}

impl Target {
    fn new(index: usize, up: Vec3) -> Self {
        let up = up.normalize();
        let axes = up.iter().filter(|v| v.abs() > 0.3).count();
        let name = match axes {
            1 => format!("{} up", direction_name(&up)),
            2 => format!("{} up (45° tilt)", direction_name(&up)),
            _ => format!("{} corner up", direction_name(&up)),
        };
        Self { index, up, name }
    }

    /// A five-line picture of how to hold the board for this target. The words name what
    /// points up (the raised edges or corner, and whether the components face up or down), so
    /// no two targets share a picture and each can be checked against [`Target::up`].
    pub fn picture(&self) -> [String; 5] {
        let label = direction_name(&self.up);
        let raised: Vec<(usize, f64)> = (0..3)
            .filter(|&i| self.up[i].abs() > 0.3)
            .map(|i| (i, self.up[i]))
            .collect();
        let edge =
            |(i, v): (usize, f64)| format!("{}{}", if v > 0.0 { '+' } else { '-' }, axis_name(i));
        let face = |z: f64| {
            if z > 0.0 {
                "components up"
            } else {
                "upside down"
            }
        };
        match raised.as_slice() {
            [(2, z)] => [
                format!("        ^ {label} up"),
                "    +----------+".to_string(),
                format!("    |   IMU    |   lying flat, {}", face(*z)),
                "    +----------+".to_string(),
                "    ============ table".to_string(),
            ],
            [(i, v)] => {
                let top = edge((*i, *v));
                [
                    format!("        ^ {label} up"),
                    format!("       +--+  <- the {top} edge at the top"),
                    "       |  |   standing on the opposite edge,".to_string(),
                    "       |  |   the board's faces vertical".to_string(),
                    "    ===+--+=== table".to_string(),
                ]
            }
            [first, (2, z)] => {
                let rising = edge(*first);
                // Side view: the raised edge on the right for +, on the left for -.
                let (slope, indents) = if first.1 > 0.0 {
                    ("/", [12, 11, 10])
                } else {
                    ("\\", [10, 11, 12])
                };
                let line = |k: usize, text: &str| {
                    format!(
                        "{}{slope}{}{text}",
                        " ".repeat(indents[k]),
                        " ".repeat(16 - indents[k])
                    )
                };
                [
                    format!("        ^ {label} up"),
                    line(0, &format!("the {rising} edge raised 45°,")),
                    line(1, &format!("{}, resting on the opposite edge", face(*z))),
                    line(2, "(side view)"),
                    "    ------------------ table".to_string(),
                ]
            }
            [first, second] => {
                let top = format!("{}{}", edge(*first), edge(*second));
                [
                    format!("        ^ {label} up"),
                    format!("          /\\   <- the {top} corner at the top"),
                    "         /  \\   standing on its side, the board's faces vertical,"
                        .to_string(),
                    "         \\  /   turned 45° onto the opposite corner".to_string(),
                    "    ======\\/===== table".to_string(),
                ]
            }
            [a, b, (2, z)] => {
                let corner = format!("{}{}", edge(*a), edge(*b));
                [
                    format!("        ^ {label} up"),
                    format!("           _/|   <- the {corner} corner highest"),
                    format!("         _/  /   tilted about 55° from flat, {}", face(*z)),
                    "        /  _/    resting on the opposite corner".to_string(),
                    "    ===|_/====== table".to_string(),
                ]
            }
            // Not a direction a session asks for; named only.
            _ => [
                format!("        ^ {label} up"),
                String::new(),
                format!("    hold the board with {label} pointing up"),
                String::new(),
                String::new(),
            ],
        }
    }
}

/// The twelve positions of seed 003 (same order as the simulator's schedule).
pub fn twelve_positions() -> Vec<Target> {
    let h = std::f64::consts::FRAC_1_SQRT_2;
    [
        Vec3::new(0.0, 0.0, 1.0),
        Vec3::new(0.0, 0.0, -1.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(-1.0, 0.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::new(0.0, -1.0, 0.0),
        Vec3::new(h, h, 0.0),
        Vec3::new(-h, h, 0.0),
        Vec3::new(0.0, h, h),
        Vec3::new(0.0, -h, h),
        Vec3::new(h, 0.0, h),
        Vec3::new(-h, 0.0, h),
    ]
    .into_iter()
    .enumerate()
    .map(|(i, up)| Target::new(i, up))
    .collect()
}

/// The eight corner directions `(±1, ±1, ±1)/√3`, numbered from `first_index`: candidates for
/// extra positions (each is at least 35° from every one of the twelve).
pub fn corner_positions(first_index: usize) -> Vec<Target> {
    let mut out = Vec::with_capacity(8);
    for sx in [1.0, -1.0] {
        for sy in [1.0, -1.0] {
            for sz in [1.0, -1.0] {
                out.push(Target::new(first_index + out.len(), Vec3::new(sx, sy, sz)));
            }
        }
    }
    out
}

/// The target within [`MATCH_ANGLE_DEG`] of the measured up direction, if any.
pub fn target_at<'a>(targets: &'a [Target], up: &Vec3) -> Option<&'a Target> {
    let up = up.try_normalize(0.0)?;
    let cos_limit = MATCH_ANGLE_DEG.to_radians().cos();
    targets
        .iter()
        .map(|t| (t, t.up.dot(&up)))
        .filter(|(_, c)| *c >= cos_limit)
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(t, _)| t)
}

/// The round (0-based, at most `rounds − 1`) of each capture of a session, given the target
/// index of each capture in the order they were made: a session captures every position once
/// per round, so the `k`-th capture of a position belongs to round `k`. Captures beyond the last
/// round's stay in it.
pub fn round_of_each(indices: &[usize], rounds: usize) -> Vec<usize> {
    let last = rounds.max(1) - 1;
    let mut seen: std::collections::HashMap<usize, usize> = std::collections::HashMap::new();
    indices
        .iter()
        .map(|index| {
            let count = seen.entry(*index).or_insert(0);
            let round = (*count).min(last);
            *count += 1;
            round
        })
        .collect()
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_positions_second_capture_belongs_to_the_second_round() {
        // Round 1 complete (0, 1, 2), round 2 begun (1, 0), then a third capture of 1.
        let rounds = super::round_of_each(&[0, 1, 2, 1, 0, 1], 3);
        assert_eq!(rounds, vec![0, 0, 0, 1, 1, 2]);
        // One round: everything in it.
        assert_eq!(super::round_of_each(&[0, 0, 1], 1), vec![0, 0, 0]);
        // More captures than rounds: the extra ones stay in the last round.
        assert_eq!(super::round_of_each(&[4, 4, 4], 2), vec![0, 1, 1]);
    }

    use super::*;

    #[test]
    fn every_position_is_matched_by_its_own_direction_and_no_other() {
        let mut all = twelve_positions();
        all.extend(corner_positions(12));
        for target in &all {
            let found = target_at(&all, &(target.up * 9.8)).map(|t| t.index);
            assert_eq!(found, Some(target.index), "{}", target.name);
        }
    }

    #[test]
    fn a_direction_25_degrees_from_every_target_matches_none() {
        let targets = twelve_positions();
        // 25° from +Z towards the +X−Y diagonal: 25° from +Z, more from the others.
        let angle = 25f64.to_radians();
        let dir = Vec3::new(angle.sin() * 0.6, -angle.sin() * 0.8, angle.cos());
        assert!(target_at(&targets, &dir).is_none());
    }

    #[test]
    fn a_zero_vector_matches_nothing_instead_of_failing() {
        assert!(target_at(&twelve_positions(), &Vec3::zeros()).is_none());
    }

    #[test]
    fn pictures_name_the_axis_that_points_up() {
        let targets = twelve_positions();
        assert!(targets[1].picture()[0].contains("-Z up"));
        assert!(targets[6].picture()[0].contains("+X+Y up"));
        assert_eq!(targets[6].name, "+X+Y up (45° tilt)");
    }

    #[test]
    fn every_target_has_its_own_picture() {
        let mut targets = twelve_positions();
        targets.extend(corner_positions(targets.len()));
        let pictures: Vec<[String; 5]> = targets.iter().map(Target::picture).collect();
        for (i, a) in pictures.iter().enumerate() {
            for b in &pictures[i + 1..] {
                assert_ne!(a, b, "two targets share a picture: {a:?}");
            }
        }
        // The +X+Z tilt raises the +X edge with the components up; its mirror the -X edge.
        assert!(pictures[10].join("\n").contains("+X edge raised 45°"));
        assert!(pictures[11].join("\n").contains("-X edge raised 45°"));
        assert!(pictures[10].join("\n").contains("components up"));
    }

    /// The direction a person would hold up from reading a picture's words (not its title):
    /// every edge or corner named as raised or at the top, and the face the components turn to.
    fn up_from_words(picture: &[String; 5]) -> Vec3 {
        let words = picture[1..].join(" ");
        let mut up = Vec3::zeros();
        let tokens: Vec<&str> = words.split_whitespace().collect();
        for pair in tokens.windows(2) {
            if !matches!(pair[1].trim_end_matches(','), "edge" | "corner") {
                continue;
            }
            for signed in pair[0].as_bytes().chunks(2) {
                let sign = match signed.first() {
                    Some(b'+') => 1.0,
                    Some(b'-') => -1.0,
                    _ => continue,
                };
                let axis = match signed.get(1) {
                    Some(b'X') => 0,
                    Some(b'Y') => 1,
                    Some(b'Z') => 2,
                    _ => continue,
                };
                up[axis] += sign;
            }
        }
        if words.contains("components up") {
            up.z += 1.0;
        }
        if words.contains("upside down") {
            up.z -= 1.0;
        }
        up.normalize()
    }

    #[test]
    fn each_picture_shows_the_up_direction_of_its_own_pose() {
        let mut targets = twelve_positions();
        targets.extend(corner_positions(targets.len()));
        for target in &targets {
            let picture = target.picture();
            let read = up_from_words(&picture);
            assert!(
                read.dot(&target.up) > 0.999,
                "{}: the picture says {read:?} is up\n{}",
                target.name,
                picture.join("\n")
            );
            assert!(picture[0].contains(&format!("{} up", direction_name(&target.up))));
        }
    }

    #[test]
    fn tilts_lean_towards_their_raised_edge_in_the_side_view() {
        let targets = twelve_positions();
        // +X+Z: the board rises to the right ("/"); -X+Z to the left ("\").
        assert!(targets[10].picture()[1].contains('/'));
        assert!(targets[11].picture()[1].contains('\\'));
    }
}
