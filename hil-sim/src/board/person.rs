//! The simulated person holding the board during a guided session: follows the prompts by
//! watching the firmware, not a clock.
//!
//! Schedule of [`PersonSchedule::Guided`]:
//! 1. The twelve positions of seed 003 (Chen et al. 2012, §2.2) in their fixed order, with the
//!    placement errors, headings and hand tremor drawn by [`crate::poser::build_schedule`]
//!    (`twelve`) from the seed. The first position is held, without a time limit, until the host
//!    first asks for a pose. From then on each position is held until the firmware has sent a
//!    `PoseStats` reply during that hold and the host has shown its next prompt (it starts the
//!    stream again; without that the person moves on [`NO_PROMPT_MOVE_ON_S`] after the capture)
//!    and a reaction time [`REACTION_S`] has passed,
//!    or for at most `max_hold_s` (counted from the later of the hold's start and the first
//!    request), then the person turns to the next one. A person does not know the order the tool
//!    will prompt in; the host accepts poses in any order. The turns between positions tilt the
//!    board (the twelve differ in their up direction), which the gyroscope's scale fit needs.
//! 2. The eight corner positions (the board balanced on a corner, [`crate::poser::corner_holds`]),
//!    which a host may ask for after the twelve: each is held like the twelve while the host
//!    captures it. A person who can read the host's screen ([`Screen`]) takes the corner it
//!    names, waits after each capture until the screen names the next step, and goes on to the
//!    tumble as soon as it asks for turning. Without the screen the
//!    corners are held in a fixed order, and a corner the host has not asked to capture within
//!    [`CORNER_PATIENCE_S`] means it wants something else: the person goes on to the tumble.
//! 3. A tumble for the magnetometer that fills in what the turns between the positions have not
//!    shown yet: the waypoints of the `tumble` schedule whose body-frame field direction is more
//!    than [`crate::poser::SEEN_ANGLE_DEG`] from every direction shown so far, nearest first
//!    ([`crate::poser::fill_in_tumble`]), then the rest of the spiral. The person stops tumbling
//!    as soon as the host stops a stream it watched for at least [`WATCHED_TUMBLE_S`] (it has
//!    the coverage it needs).
//! 4. A rest in the first position, with the hand off the board (no tremor), until stopped: what
//!    the host's at-rest verification needs.
//!
//! [`PersonSchedule::Rounds`] is the same with step 1 repeated: the twelve positions are gone
//! through `n` times over (position 0 follows position 11), so that a session can capture each
//! of them at several moments, e.g. across a temperature sweep.
//!
//! [`PersonSchedule::Rest`] keeps the board in the first position without tremor all the time.
//!
//! A hold ends smoothly: the tremor fades out over its edge ramp after the capture, so orientation
//! and rate stay continuous and integrating the gyroscope between holds stays exact. The motion is
//! a function of the seed and of when the firmware finishes each capture.

use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::SimError;
use crate::poser::{
    build_schedule, corner_holds, fill_in_tumble, PlacedHold, PoserOptions, ScheduleKind,
    SEEN_ANGLE_DEG,
};
use crate::world::{EarthField, Motion, Segment, Trajectory, TrajectoryBuilder};

/// Length given to a hold that ends only on an observation, s (about 30 years).
const OPEN_HOLD_S: f64 = 1.0e9;

/// A person who sees no new prompt after a capture moves on after this long, s.
pub const NO_PROMPT_MOVE_ON_S: f64 = 1.0;

/// A stream that ran this long during the tumble and then stopped ends the tumble, s.
const WATCHED_TUMBLE_S: f64 = 1.0;

/// Time from seeing a prompt to starting to move, s (a simple visual reaction time).
pub const REACTION_S: f64 = 0.25;

/// How long a person holds a corner the host has not asked to capture before concluding that
/// the host wants something else, s: the host's stillness window (0.5 s) and settle time
/// (0.15 s) after the hold's tremor ramp (0.3 s), plus a look at the screen.
pub const CORNER_PATIENCE_S: f64 = 2.5;

/// A screen's up direction names the corner within this angle of it, degrees (corners are at
/// least 70.5° apart, and a corner is held within a few degrees of its direction).
const NAMED_CORNER_DEG: f64 = 25.0;

/// A held position's up direction names a hold of the person's within this angle, degrees
/// (holds are at least 35° apart, and placed within a few degrees of their direction).
const HELD_MATCH_DEG: f64 = 15.0;

/// Body-frame field directions are remembered when they differ by more than this from the last
/// one remembered, degrees (a tenth of the angle that counts as seen).
const FIELD_TRACE_STEP_DEG: f64 = SEEN_ANGLE_DEG / 10.0;

/// What the simulated person does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PersonSchedule {
    /// Twelve positions as prompted, a tumble, then rest (see the module documentation).
    #[default]
    Guided,
    /// As `Guided`, with the twelve positions gone through this many times (0 counts as 1).
    Rounds(u8),
    /// Rest in the first position all the time.
    Rest,
}

impl PersonSchedule {
    /// How many times the twelve positions are held (0 for `Rest`).
    pub fn rounds(self) -> usize {
        match self {
            Self::Guided => 1,
            Self::Rounds(n) => usize::from(n.max(1)),
            Self::Rest => 0,
        }
    }
}

impl std::str::FromStr for PersonSchedule {
    type Err = SimError;

    fn from_str(s: &str) -> Result<Self, SimError> {
        match s {
            "guided" => Ok(Self::Guided),
            "rest" => Ok(Self::Rest),
            other => match other.strip_prefix("rounds:").map(str::parse::<u8>) {
                Some(Ok(n)) if n > 0 => Ok(Self::Rounds(n)),
                _ => Err(SimError::UnknownSchedule(other.to_string())),
            },
        }
    }
}

/// Where the person is in the schedule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PersonPhase {
    /// Holding hold `index` of the schedule: position `index % 12` of the twelve, or after the
    /// last round corner `index − 12·rounds`.
    Hold {
        /// Hold index (the position index in the first round).
        index: usize,
    },
    /// Turning towards hold `index` of the schedule.
    TurnToHold {
        /// Hold index being approached.
        index: usize,
    },
    /// Tumbling towards waypoint `index`.
    Tumble {
        /// Waypoint index.
        index: usize,
    },
    /// Turning to the rest position or resting there.
    Rest,
}

/// What the person sees of the firmware.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Prompts {
    /// `CapturePose` requests seen so far.
    pub capture_requests: u64,
    /// `PoseStats` replies seen so far.
    pub poses_captured: u64,
    /// `StartStream` requests seen so far (the host shows a new prompt and watches).
    pub stream_starts: u64,
    /// `StopStream` requests seen so far.
    pub stream_stops: u64,
    /// Whether the host's last stream request started a stream.
    pub streaming: bool,
    /// What the host's screen asks for, when the person can read it.
    pub screen: Screen,
}

/// What the host's screen asks of the person holding the board. A person who can read it takes
/// the corner it names and goes on to the tumble as soon as it asks for turning; without it
/// ([`Screen::Unknown`]) the person guesses from the firmware's traffic, holding each corner in
/// turn until [`CORNER_PATIENCE_S`] passes without a capture request. The twelve positions are
/// held in the person's own order either way (the host accepts them in any order).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Screen {
    /// Nothing the person can read.
    #[default]
    Unknown,
    /// Hold the board with this body-frame direction up (need not be unit length).
    Pose {
        /// The direction, body frame.
        up: [f64; 3],
    },
    /// Turn the board slowly through many directions (the magnetometer's phase).
    Turn,
    /// Put the board down and leave it.
    Rest,
}

/// The person and the motion they produce.
#[derive(Debug, Clone)]
pub struct Person {
    holds: Vec<PlacedHold>,
    /// Holds in the whole schedule: the twelve times the rounds.
    hold_count: usize,
    /// The eight corners, held after the last round while the host captures them.
    corners: Vec<PlacedHold>,
    /// `CapturePose` count when the current hold began.
    hold_requests_at_start: u64,
    /// Set when a corner went without a capture request: the tumble comes next.
    corners_done: bool,
    /// Waypoints of the tumble schedule (the spiral).
    tumble: Vec<UnitQuaternion<f64>>,
    /// The order the tumble goes through, chosen when it begins.
    tumble_plan: Vec<UnitQuaternion<f64>>,
    /// Since when the host has been streaming during the tumble, s, and the `StopStream` count
    /// then: a stop after a stream of at least [`WATCHED_TUMBLE_S`] means it has the directions
    /// it needs. The stop is told by the count, as a host may start its next stream before the
    /// next sample.
    tumble_watched_since_s: Option<(f64, u64)>,
    /// Field direction in the world frame (unit), if there is a field.
    field_world: Option<Vector3<f64>>,
    /// Body-frame field directions shown so far.
    field_seen: Vec<Vector3<f64>>,
    rest: UnitQuaternion<f64>,
    turn_peak_rate_dps: f64,
    tumble_peak_rate_dps: f64,
    max_hold_s: f64,
    phase: PersonPhase,
    /// The current motion segment, in time since `segment_start_s`.
    segment: Trajectory,
    segment_start_s: f64,
    segment_end_s: f64,
    /// `PoseStats` count when the current hold began; `None` once the hold is ending.
    hold_captures_at_start: Option<u64>,
    /// When this hold's pose was captured, s, and the `StartStream` count before the reply: a
    /// host may start its next stream (its prompt) before the next sample is taken.
    captured: Option<(f64, u64)>,
    /// `StartStream` count at the previous observation.
    stream_starts_seen: u64,
    /// When the person starts to move after seeing the next prompt, s.
    moving_at_s: Option<f64>,
    first_prompt_s: Option<f64>,
    /// What the host's screen shows, and since when, s.
    screen: (Screen, f64),
    /// Body-frame up directions of the positions a resumed session already holds (unit): the
    /// person skips them in the first round and among the corners.
    held: Vec<Vector3<f64>>,
}

/// Minimum-jerk turn length for a peak rate: the peak of `ṡ` is 1.875 times the mean.
fn turn_duration_s(from: &UnitQuaternion<f64>, to: &UnitQuaternion<f64>, peak_dps: f64) -> f64 {
    (1.875 * from.angle_to(to) / peak_dps.to_radians()).max(0.6)
}

impl Person {
    /// The person for `schedule`, drawing positions and tremor from `seed`.
    pub fn new(
        schedule: PersonSchedule,
        options: &PoserOptions,
        max_hold_s: f64,
        field: &EarthField,
        seed: u64,
    ) -> Result<Self, SimError> {
        crate::error::require_positive("maximum hold time (s)", max_hold_s)?;
        let twelve = build_schedule(ScheduleKind::Twelve, options, field, seed)?;
        let tumble = build_schedule(ScheduleKind::Tumble, options, field, seed)?;
        let holds: Vec<PlacedHold> = twelve
            .trajectory
            .segments()
            .iter()
            .filter_map(|segment| match segment {
                Segment::Hold {
                    orientation,
                    tremor,
                    ..
                } => Some(PlacedHold {
                    orientation: *orientation,
                    tremor: tremor.clone(),
                }),
                Segment::Turn { .. } => None,
            })
            .collect();
        let mut waypoints = Vec::new();
        for segment in tumble.trajectory.segments() {
            match segment {
                Segment::Hold { orientation, .. } if waypoints.is_empty() => {
                    waypoints.push(*orientation);
                }
                Segment::Turn { to, .. } => waypoints.push(*to),
                Segment::Hold { .. } => {}
            }
        }
        let corners = corner_holds(options, seed)?;
        let first = holds.first().cloned().ok_or(SimError::EmptyTrajectory)?;
        let rest = first.orientation;
        let hold_count = holds.len() * schedule.rounds();
        let mut person = Self {
            holds,
            hold_count,
            corners,
            hold_requests_at_start: 0,
            corners_done: false,
            tumble: waypoints,
            tumble_plan: Vec::new(),
            tumble_watched_since_s: None,
            field_world: field.world_vector_ut().try_normalize(0.0),
            field_seen: Vec::new(),
            rest,
            turn_peak_rate_dps: options.turn_peak_rate_dps,
            tumble_peak_rate_dps: options.tumble_peak_rate_dps,
            max_hold_s,
            phase: PersonPhase::Rest,
            segment: TrajectoryBuilder::new(rest)
                .hold(OPEN_HOLD_S, None)?
                .build()?,
            segment_start_s: 0.0,
            segment_end_s: OPEN_HOLD_S,
            hold_captures_at_start: None,
            captured: None,
            stream_starts_seen: 0,
            moving_at_s: None,
            first_prompt_s: None,
            screen: (Screen::Unknown, 0.0),
            held: Vec::new(),
        };
        if hold_count > 0 {
            person.begin_hold(0, 0.0, Prompts::default())?;
        }
        Ok(person)
    }

    /// Where the person is now.
    pub fn phase(&self) -> PersonPhase {
        self.phase
    }

    /// Nominal orientation (without tremor) of each of the twelve positions, body to world.
    pub fn hold_orientations(&self) -> Vec<UnitQuaternion<f64>> {
        self.holds.iter().map(|h| h.orientation).collect()
    }

    /// Tell the person which positions a resumed session already holds (body-frame up
    /// directions, as the host lists them when it resumes): the host does not ask for them
    /// again, so the person skips them, leaving one held now at the next observation.
    pub fn skip_held(&mut self, ups: &[[f64; 3]]) {
        self.held = ups
            .iter()
            .filter_map(|up| Vector3::from(*up).try_normalize(0.0))
            .collect();
    }

    /// React to what the firmware did up to time `t_s`, moving on through the schedule.
    pub fn observe(&mut self, t_s: f64, prompts: Prompts) -> Result<(), SimError> {
        if prompts.capture_requests > 0 && self.first_prompt_s.is_none() {
            self.first_prompt_s = Some(t_s);
        }
        let starts_before = std::mem::replace(&mut self.stream_starts_seen, prompts.stream_starts);
        self.trace_field(t_s);
        if prompts.screen != self.screen.0 {
            self.screen = (prompts.screen, t_s);
        }
        if let (PersonPhase::Hold { index }, Some(at_start)) =
            (self.phase, self.hold_captures_at_start)
        {
            if self.captured.is_none() && prompts.poses_captured > at_start {
                self.captured = Some((t_s, starts_before));
            }
            // After a corner, a person who reads the screen waits for it to name the next step
            // rather than guess: the host may take a while to choose (at simulated speeds its
            // computing time is many simulated seconds).
            let waits_for_screen = index >= self.hold_count && self.screen.0 != Screen::Unknown;
            let prompted = self.captured.is_some_and(|(at_s, starts)| {
                if waits_for_screen {
                    self.screen.1 >= at_s
                } else {
                    prompts.stream_starts > starts || t_s - at_s >= NO_PROMPT_MOVE_ON_S
                }
            });
            if prompted && self.moving_at_s.is_none() {
                self.moving_at_s = Some(t_s + REACTION_S);
            }
            let prompted_on = self.moving_at_s.is_some_and(|at| t_s >= at);
            let timed_out = self
                .first_prompt_s
                .is_some_and(|first| t_s - first.max(self.segment_start_s) >= self.max_hold_s);
            let unwanted_corner = if self.screen.0 == Screen::Unknown {
                self.is_corner()
                    && prompts.capture_requests == self.hold_requests_at_start
                    && t_s - self.segment_start_s >= CORNER_PATIENCE_S
            } else {
                self.captured.is_none()
                    && t_s - self.screen.1 >= REACTION_S
                    && self.screen_asks_for_another_corner_or_none()
            };
            if unwanted_corner && self.screen.0 == Screen::Unknown {
                self.corners_done = true;
            }
            let held_already = self.captured.is_none() && self.is_held(index);
            if prompted_on || timed_out || unwanted_corner || held_already {
                self.end_hold(t_s)?;
            }
        }
        let told_to_rest = self.screen.0 == Screen::Rest && t_s - self.screen.1 >= REACTION_S;
        if let (PersonPhase::Tumble { .. }, true) = (self.phase, told_to_rest) {
            // The screen asks to put the board down, however short the turning was.
            self.put_down(t_s)?;
        }
        if let PersonPhase::Tumble { .. } = self.phase {
            match self.tumble_watched_since_s {
                None if prompts.streaming => {
                    self.tumble_watched_since_s = Some((t_s, prompts.stream_stops));
                }
                Some((since, stops)) if prompts.stream_stops > stops => {
                    if t_s - since >= WATCHED_TUMBLE_S {
                        // The host has the directions it needs: put the board down from here.
                        self.put_down(t_s)?;
                    } else {
                        // A stream stopped at once (the end of the positions) does not count.
                        self.tumble_watched_since_s =
                            prompts.streaming.then_some((t_s, prompts.stream_stops));
                    }
                }
                _ => {}
            }
        }
        // Segments may be shorter than a sample period; catch up through all that ended.
        while t_s >= self.segment_end_s {
            self.next_segment(prompts)?;
        }
        Ok(())
    }

    /// Stop tumbling and turn from where the board is at `t_s` to the rest position.
    fn put_down(&mut self, t_s: f64) -> Result<(), SimError> {
        let here = self.motion_at(t_s).q_body_to_world;
        self.turn(here, self.rest, t_s)?;
        self.phase = PersonPhase::Rest;
        self.tumble_watched_since_s = None;
        Ok(())
    }

    /// Remember the body-frame field direction at `t_s` when it is new enough.
    fn trace_field(&mut self, t_s: f64) {
        let Some(field) = self.field_world else {
            return;
        };
        let body = self.motion_at(t_s).q_body_to_world.inverse() * field;
        let step = FIELD_TRACE_STEP_DEG.to_radians().cos();
        if self
            .field_seen
            .last()
            .is_none_or(|last| last.dot(&body) < step)
        {
            self.field_seen.push(body);
        }
    }

    /// Orientation and body rate at `t_s` (call [`Self::observe`] first).
    pub fn motion_at(&self, t_s: f64) -> Motion {
        self.segment.motion_at(t_s - self.segment_start_s)
    }

    /// The plan of hold `index` of the schedule: one of the twelve, then the corners; `None`
    /// after the last corner.
    fn hold_plan(&self, index: usize) -> Option<&PlacedHold> {
        if index >= self.hold_count {
            return self.corners.get(index - self.hold_count);
        }
        self.holds.get(index.checked_rem(self.holds.len())?)
    }

    /// Whether hold `index` is a position a resumed session already holds: one of the twelve
    /// in the first round, or a corner.
    fn is_held(&self, index: usize) -> bool {
        if (self.holds.len()..self.hold_count).contains(&index) {
            return false;
        }
        let Some(plan) = self.hold_plan(index) else {
            return false;
        };
        let up = plan.orientation.inverse() * Vector3::z();
        let cos_limit = HELD_MATCH_DEG.to_radians().cos();
        self.held.iter().any(|held| held.dot(&up) >= cos_limit)
    }

    /// Whether the current hold is one of the corners.
    fn is_corner(&self) -> bool {
        matches!(self.phase, PersonPhase::Hold { index } if index >= self.hold_count)
    }

    /// The hold index of the corner the screen names, if it names one.
    fn named_corner(&self) -> Option<usize> {
        let Screen::Pose { up } = self.screen.0 else {
            return None;
        };
        let up = Vector3::from(up).try_normalize(0.0)?;
        let cos_limit = NAMED_CORNER_DEG.to_radians().cos();
        self.corners
            .iter()
            .position(|c| (c.orientation.inverse() * Vector3::z()).dot(&up) >= cos_limit)
            .map(|j| self.hold_count + j)
    }

    /// Whether the person, holding a corner, reads on the screen that the host wants another
    /// corner, or no corner at all.
    fn screen_asks_for_another_corner_or_none(&self) -> bool {
        let PersonPhase::Hold { index } = self.phase else {
            return false;
        };
        if index < self.hold_count {
            return false;
        }
        match self.screen.0 {
            Screen::Unknown => false,
            Screen::Turn | Screen::Rest => true,
            Screen::Pose { .. } => self.named_corner().is_some_and(|named| named != index),
        }
    }

    /// Where the person goes after hold `index`: the next hold, or `None` for the tumble. After
    /// the twelve the screen, when it can be read, decides: the corner it names, or the tumble
    /// when it asks for turning.
    fn after_hold(&self, index: usize) -> Option<usize> {
        // Positions a resumed session holds are skipped (the holds after them end).
        let next = (index + 1..)
            .find(|&i| !self.is_held(i))
            .unwrap_or(index + 1);
        if next < self.hold_count {
            return Some(next);
        }
        if self.corners_done {
            return None;
        }
        match self.screen.0 {
            Screen::Turn | Screen::Rest => None,
            Screen::Pose { .. } => match self.named_corner() {
                Some(named) if named != index => Some(named),
                _ => self.hold_plan(next).map(|_| next),
            },
            Screen::Unknown => self.hold_plan(next).map(|_| next),
        }
    }

    fn begin_hold(&mut self, index: usize, start_s: f64, prompts: Prompts) -> Result<(), SimError> {
        let captures = prompts.poses_captured;
        self.hold_requests_at_start = prompts.capture_requests;
        let Some(plan) = self.hold_plan(index) else {
            return self.begin_tumble(0, start_s);
        };
        self.segment = TrajectoryBuilder::new(plan.orientation)
            .hold(OPEN_HOLD_S, plan.tremor.clone())?
            .build()?;
        self.phase = PersonPhase::Hold { index };
        self.segment_start_s = start_s;
        self.segment_end_s = start_s + OPEN_HOLD_S;
        self.hold_captures_at_start = Some(captures);
        self.captured = None;
        self.moving_at_s = None;
        Ok(())
    }

    /// Shorten the open hold so that it ends after the tremor has faded out from `t_s` on; the
    /// motion before `t_s` is unchanged because the tremor window there is still 1.
    fn end_hold(&mut self, t_s: f64) -> Result<(), SimError> {
        let PersonPhase::Hold { index } = self.phase else {
            return Ok(());
        };
        let Some(plan) = self.hold_plan(index) else {
            return Ok(());
        };
        let ramp = plan.tremor.as_ref().map_or(0.0, |t| t.edge_ramp_s);
        let elapsed = (t_s - self.segment_start_s).max(0.0);
        let duration = (elapsed + ramp).max(2.0 * ramp).max(1e-6);
        self.segment = TrajectoryBuilder::new(plan.orientation)
            .hold(duration, plan.tremor.clone())?
            .build()?;
        self.segment_end_s = self.segment_start_s + duration;
        self.hold_captures_at_start = None;
        Ok(())
    }

    fn next_segment(&mut self, prompts: Prompts) -> Result<(), SimError> {
        let start = self.segment_end_s;
        match self.phase {
            PersonPhase::Hold { index } => {
                let from = self.hold_plan(index).map_or(self.rest, |h| h.orientation);
                let next = self
                    .after_hold(index)
                    .and_then(|i| self.hold_plan(i).map(|h| (i, h.orientation)));
                match next {
                    Some((next, to)) => {
                        self.turn(from, to, start)?;
                        self.phase = PersonPhase::TurnToHold { index: next };
                    }
                    None => {
                        self.plan_tumble(&from);
                        self.begin_tumble(0, start)?;
                    }
                }
            }
            PersonPhase::TurnToHold { index } => self.begin_hold(index, start, prompts)?,
            PersonPhase::Tumble { index } => self.begin_tumble(index + 1, start)?,
            PersonPhase::Rest => {
                let here = self.segment.motion_at(self.segment.duration_s());
                self.segment = TrajectoryBuilder::new(here.q_body_to_world)
                    .hold(OPEN_HOLD_S, None)?
                    .build()?;
                self.segment_start_s = start;
                self.segment_end_s = start + OPEN_HOLD_S;
            }
        }
        Ok(())
    }

    /// Choose the tumble's order from `from`: first what the field has not shown yet.
    fn plan_tumble(&mut self, from: &UnitQuaternion<f64>) {
        self.tumble_plan = match self.field_world {
            Some(field) => fill_in_tumble(&self.tumble, &self.field_seen, &field, from),
            None => self.tumble.clone(),
        };
        self.tumble_watched_since_s = None;
    }

    /// Turn to tumble waypoint `index` of the plan, or to rest after the last one.
    fn begin_tumble(&mut self, index: usize, start_s: f64) -> Result<(), SimError> {
        if self.tumble_plan.is_empty() && index == 0 {
            self.tumble_plan = self.tumble.clone();
        }
        let from = self
            .segment
            .motion_at(self.segment.duration_s())
            .q_body_to_world;
        match self.tumble_plan.get(index).copied() {
            // The first waypoint is reached by an ordinary turn; later ones at the tumble's pace.
            Some(to) if index == 0 => self.turn(from, to, start_s)?,
            Some(to) => {
                let duration = turn_duration_s(&from, &to, self.tumble_peak_rate_dps);
                self.segment = TrajectoryBuilder::new(from)
                    .turn_to(to, duration)?
                    .build()?;
                self.segment_start_s = start_s;
                self.segment_end_s = start_s + duration;
            }
            None => {
                self.turn(from, self.rest, start_s)?;
                self.phase = PersonPhase::Rest;
                return Ok(());
            }
        }
        self.phase = PersonPhase::Tumble { index };
        Ok(())
    }

    fn turn(
        &mut self,
        from: UnitQuaternion<f64>,
        to: UnitQuaternion<f64>,
        start_s: f64,
    ) -> Result<(), SimError> {
        let duration = turn_duration_s(&from, &to, self.turn_peak_rate_dps);
        self.segment = TrajectoryBuilder::new(from)
            .turn_to(to, duration)?
            .build()?;
        self.segment_start_s = start_s;
        self.segment_end_s = start_s + duration;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sample period of the drive below, s.
    const STEP_S: f64 = 0.01;

    fn guided_person() -> Person {
        Person::new(
            PersonSchedule::Guided,
            &PoserOptions::default(),
            30.0,
            &EarthField::default(),
            3,
        )
        .expect("a guided person")
    }

    /// A host that captures every hold 0.8 s after it begins and then starts its next stream,
    /// showing `screen` from the last of the twelve on. Runs until `done` or 120 s; returns
    /// the time.
    fn drive(person: &mut Person, screen: Screen, done: impl Fn(&Person) -> bool) -> Option<f64> {
        let mut prompts = Prompts {
            streaming: true,
            ..Prompts::default()
        };
        let mut hold_began: Option<(usize, f64)> = None;
        let mut t_s = 0.0;
        while t_s < 120.0 {
            person.observe(t_s, prompts).ok()?;
            if done(person) {
                return Some(t_s);
            }
            match person.phase() {
                PersonPhase::Hold { index } => {
                    if index >= 11 {
                        prompts.screen = screen;
                    }
                    // The corners are captured only when the screen names them.
                    let wanted = index < 12 || person.named_corner() == Some(index);
                    if hold_began.is_none_or(|(i, _)| i != index) {
                        hold_began = Some((index, t_s));
                        if wanted {
                            prompts.capture_requests += 1;
                        }
                    }
                    let began = hold_began.map_or(t_s, |(_, at)| at);
                    let captured_here = prompts.poses_captured >= prompts.capture_requests;
                    if wanted && !captured_here && t_s - began >= 0.8 {
                        prompts.poses_captured += 1;
                        prompts.stream_starts += 1;
                    }
                }
                _ => hold_began = None,
            }
            t_s += STEP_S;
        }
        None
    }

    #[test]
    fn a_person_moves_on_a_reaction_time_after_a_prompt_that_arrives_with_the_capture_reply() {
        // `drive` captures the first hold at 0.8 s and starts the next stream in the same step,
        // as a fast host does before the board's next sample.
        let mut person = guided_person();
        let turning = drive(&mut person, Screen::Unknown, |p| {
            p.phase() == PersonPhase::TurnToHold { index: 1 }
        })
        .expect("the person turns to the second position");
        assert!(
            (0.8 + REACTION_S..0.8 + NO_PROMPT_MOVE_ON_S).contains(&turning),
            "turning began at {turning:.2} s, after a capture and prompt at 0.8 s"
        );
    }

    #[test]
    fn a_person_who_reads_the_screen_takes_the_corner_it_names() {
        let mut person = guided_person();
        // Corner 5 of the person's own order, named by its up direction.
        let up = crate::poser::corner_up_directions()[5];
        let screen = Screen::Pose {
            up: [up.x, up.y, up.z],
        };
        let reached = drive(
            &mut person,
            screen,
            |p| matches!(p.phase(), PersonPhase::Hold { index } if index >= 12),
        );
        assert!(reached.is_some(), "no corner was reached");
        assert_eq!(person.phase(), PersonPhase::Hold { index: 12 + 5 });
    }

    #[test]
    fn a_person_who_reads_the_screen_turns_the_board_when_asked_without_holding_a_corner() {
        let mut with_screen = guided_person();
        let tumbling = |p: &Person| matches!(p.phase(), PersonPhase::Tumble { .. });
        let read = drive(&mut with_screen, Screen::Turn, tumbling).expect("the tumble begins");
        // Without the screen the person holds the first corner until their patience runs out.
        let mut guessing = guided_person();
        let guessed = drive(&mut guessing, Screen::Unknown, tumbling).expect("the tumble begins");
        assert!(
            guessed - read >= CORNER_PATIENCE_S,
            "tumble at {read:.2} s reading the screen, {guessed:.2} s guessing"
        );
    }

    #[test]
    fn a_person_who_reads_the_screen_puts_the_board_down_when_asked_however_short_the_turning() {
        let mut person = guided_person();
        drive(&mut person, Screen::Turn, |p| {
            matches!(p.phase(), PersonPhase::Tumble { .. })
        })
        .expect("the tumble begins");
        // The host needed no turning: it shows the rest prompt at once, and never streamed.
        let start = person.segment_start_s;
        let prompts = Prompts {
            screen: Screen::Rest,
            ..Prompts::default()
        };
        let mut t_s = start;
        while t_s < start + 1.0 && person.phase() != PersonPhase::Rest {
            person.observe(t_s, prompts).expect("the person moves");
            t_s += STEP_S;
        }
        assert_eq!(person.phase(), PersonPhase::Rest);
    }

    #[test]
    fn a_person_holding_a_corner_the_screen_does_not_name_moves_to_the_named_one() {
        let mut person = guided_person();
        let corners = crate::poser::corner_up_directions();
        // The screen names the third corner only once the person holds the first one.
        let up = corners[2];
        let named = Screen::Pose {
            up: [up.x, up.y, up.z],
        };
        drive(&mut person, Screen::Unknown, |p| {
            p.phase() == PersonPhase::Hold { index: 12 }
        })
        .expect("the first corner is held");
        let at_first = person.segment_start_s;
        let prompts = Prompts {
            streaming: true,
            capture_requests: 12,
            poses_captured: 12,
            stream_starts: 12,
            screen: named,
            ..Prompts::default()
        };
        let mut t_s = at_first;
        while t_s < at_first + 10.0 {
            person.observe(t_s, prompts).expect("the person moves");
            if person.phase() == (PersonPhase::Hold { index: 14 }) {
                break;
            }
            t_s += STEP_S;
        }
        assert_eq!(person.phase(), PersonPhase::Hold { index: 14 });
    }

    #[test]
    fn a_person_who_reads_the_screen_stays_on_a_captured_corner_until_it_names_the_next_step() {
        let mut person = guided_person();
        let corners = crate::poser::corner_up_directions();
        let screen = |up: Vector3<f64>| Screen::Pose {
            up: [up.x, up.y, up.z],
        };
        drive(&mut person, screen(corners[5]), |p| {
            p.phase() == PersonPhase::Hold { index: 17 }
        })
        .expect("the named corner is held");
        let start = person.segment_start_s;
        let mut prompts = Prompts {
            streaming: true,
            capture_requests: 13,
            poses_captured: 12,
            stream_starts: 12,
            screen: screen(corners[5]),
            ..Prompts::default()
        };
        // Captured at 0.8 s and streaming again; the host takes 10 s to choose the next corner
        // (at 60× real time, a sixth of a second of its computing).
        let mut t_s = start;
        while t_s < start + 10.0 {
            if t_s - start >= 0.8 {
                prompts.poses_captured = 13;
                prompts.stream_starts = 13;
            }
            person.observe(t_s, prompts).expect("the person moves");
            t_s += STEP_S;
        }
        assert_eq!(person.phase(), PersonPhase::Hold { index: 17 }, "waited");
        prompts.screen = screen(corners[2]);
        while t_s < start + 20.0 && person.phase() != (PersonPhase::Hold { index: 14 }) {
            person.observe(t_s, prompts).expect("the person moves");
            t_s += STEP_S;
        }
        assert_eq!(person.phase(), PersonPhase::Hold { index: 14 });
    }

    #[test]
    fn a_person_told_what_a_resumed_session_holds_skips_those_positions() {
        let mut person = guided_person();
        // The host holds the first five positions: the person leaves the first (held) at once,
        // although no pose was asked for there, and turns to the sixth.
        let ups: Vec<[f64; 3]> = person.hold_orientations()[..5]
            .iter()
            .map(|q| {
                let up = q.inverse() * Vector3::z();
                [up.x, up.y, up.z]
            })
            .collect();
        person.skip_held(&ups);
        let mut t_s = 0.0;
        while t_s < 5.0 && person.phase() == (PersonPhase::Hold { index: 0 }) {
            person
                .observe(t_s, Prompts::default())
                .expect("the person moves");
            t_s += STEP_S;
        }
        assert_eq!(person.phase(), PersonPhase::TurnToHold { index: 5 });
    }

    #[test]
    fn a_rounds_schedule_is_read_from_its_name_and_counts_its_rounds() {
        assert_eq!(
            "rounds:3".parse::<PersonSchedule>().ok(),
            Some(PersonSchedule::Rounds(3))
        );
        assert_eq!(PersonSchedule::Rounds(3).rounds(), 3);
        assert_eq!(PersonSchedule::Rounds(0).rounds(), 1);
        assert_eq!(PersonSchedule::Guided.rounds(), 1);
        assert_eq!(PersonSchedule::Rest.rounds(), 0);
        for bad in ["rounds:0", "rounds:x", "rounds:300", "rounds"] {
            assert!(bad.parse::<PersonSchedule>().is_err(), "{bad} was accepted");
        }
    }
}
