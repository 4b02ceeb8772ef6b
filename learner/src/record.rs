//! Teaching by hand (`learner record`, docs/ur.md "Teaching by hand", docs/data.md "The
//! recording rule"): demonstrations cut from a UR's stream of joint states while a person
//! guides the arm (freedrive) or any program moves it.
//!
//! **The rule.** A package is *still* when the end-effector point (forward kinematics of its
//! six joints) moved at most [`REST_TRAVEL_M`] along each base axis over the last
//! [`REST_WINDOW_S`]: a displacement over a window, not a speed, so that the tremor of a hand
//! holding the arm (0.1–1 mm at 8–12 Hz, speeds of a deliberate motion's order) does not hide a
//! rest. A *rest* is a run of still packages; it began at the start of its first package's
//! window. The first rest of at least [`REST_S`] defines the *start pose* (the mean pose of
//! that rest). A demonstration *starts* when the arm leaves a rest of at least [`REST_S`]
//! within [`NEAR_START`] of the start pose (its first package is the first of the window in
//! which the motion was seen, still at rest) and *ends* once the arm has rested [`REST_S`]
//! elsewhere. A motion that comes back to rest near the start pose is not a demonstration (the
//! person gave up); nor is a motion from anywhere else (e.g. the way back to the start pose).
//! Poses are compared by their joints' mean over the window (a tremor averaged out). While it
//! waits, the recorder says what for and what it measures ([`Segmenter::status`]).
//!
//! **To T steps.** A demonstration is resampled at the control period (t_k = onset + k dt,
//! joint angles and velocities linearly interpolated between the arm's packages by their
//! timestamps, so 500 Hz and 125 Hz streams and lost packages give the same steps) for
//! k = 0 … T − 1; past the end of the recorded rest it is padded with the resting pose at zero
//! velocity. One whose motion has not come to rest within T steps is skipped (the message says
//! how long it took against T dt). Its end-effector point and velocity come from all six joints
//! by the model's forward kinematics (`ur5_shared::kinematics`), as the `ur` backend builds the
//! state. A three-joint task (`[task] joints = 3`, the default) keeps the wrist locked: the
//! wrist must stay within [`WRIST_TOLERANCE`] of the wrist lock (`sim.wrist_q`) the learner's
//! arm keeps, or the demonstration is skipped. A six-joint task (`joints = 6`) records the
//! wrist as it moves: all six joints are in the state (layout of six joints and one tool point,
//! dX = 18, dU = 6).
//!
//! **The task.** start_q = the start pose's active joints; goal = the mean end-effector point
//! at the demonstrations' last step, its spread reported; with `pose` (six joints) a pose goal,
//! the mean of their last tool poses, and the state's three tool points (dX = 30, dU = 6).
//! C_expert and C_random are derived as
//! for any imported demonstrations (`io::foreign`): the demonstrations' mean task cost, and the
//! expert's random initial controller run on the task in the simulator.

use std::collections::VecDeque;

use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::joints::Joints;
use ur5_shared::kinematics::{Joints6, UrKinematics};
use ur5_shared::UrModel;

use imitation::demos::Demos;

use crate::io::foreign::{mean_tool_pose, to_demos, DERIVED_SEED};
use crate::io::lerobot::{TaskMeta, Trajectories};
use crate::io::tool_path::arm_states;

/// Why a recording cannot be turned into the learner's demonstrations, or why it stopped.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// Nothing was recorded (no segment was taken for a demonstration).
    #[error("no demonstrations were recorded")]
    NoDemonstrations,
    /// A package the recorder cannot trust.
    #[error(transparent)]
    Measured(#[from] MeasuredFault),
    /// The demonstrations checked against the arm.
    #[error(transparent)]
    Demos(#[from] crate::io::demos::DemosError),
    /// The recorded trajectories as demonstrations of the arm.
    #[error(transparent)]
    Io(#[from] crate::io::IoError),
    /// A pose goal asked of a task that keeps the wrist locked.
    #[error("a pose goal needs the whole arm: [task] joints = 6 (the config has joints = {0})")]
    PoseNeedsSixJoints(usize),
}

/// A measured joint state no arm in working order sends (a fault of the robot or of its
/// controller, or another arm model than the recorder was told): recording stops there.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum MeasuredFault {
    /// `actual_q` or `actual_qd` not finite.
    #[error("at arm time {t} s the robot measured a non-finite joint state: joint {joint} actual_q = {q} rad, actual_qd = {qd} rad/s; a fault of the robot or its controller (not of the network): see the robot's log")]
    NonFinite {
        /// Arm time (s).
        t: f64,
        /// Joint index 0..6.
        joint: usize,
        /// Its angle (rad).
        q: f64,
        /// Its speed (rad/s).
        qd: f64,
    },
    /// A joint's `actual_q` outside the model's limits by more than [`LIMIT_MARGIN_RAD`].
    #[error("at arm time {t} s the robot measured joint {joint} at {q} rad, outside the {model}'s limits {lower} ..= {upper} rad: check --model (or [sim] model) against the robot, and the robot's joint readings")]
    OutsideLimits {
        /// Arm time (s).
        t: f64,
        /// Joint index 0..6.
        joint: usize,
        /// Its angle (rad).
        q: f64,
        /// Lower limit (rad).
        lower: f64,
        /// Upper limit (rad).
        upper: f64,
        /// The model whose limits these are.
        model: UrModel,
    },
}

/// A measured joint may be this far (rad) outside its limit (a servo's overshoot at a limit)
/// before the package counts as a fault; the controller's margin for the same check.
pub const LIMIT_MARGIN_RAD: f64 = 0.05;

/// How long the end-effector point's travel is measured over to tell a rest from a motion
/// (s of arm time): two periods of the slowest physiological tremor (8 Hz).
pub const REST_WINDOW_S: f64 = 0.25;

/// Largest travel of the end-effector point within [`REST_WINDOW_S`] of an arm at rest (m,
/// its range along each base axis): a hand's tremor moves a held arm by 0.1–1 mm at 8–12 Hz
/// (a range of up to 2 mm), a deliberate motion by centimetres in that time (this bound is a
/// steady 12 mm/s).
pub const REST_TRAVEL_M: f64 = 0.003;

/// How long a rest starts or ends a demonstration (s of arm time).
pub const REST_S: f64 = 1.0;

/// How close to the start pose a rest starts a demonstration (rad, every joint, the joints'
/// mean over [`REST_WINDOW_S`]): the tolerance imported demonstrations are checked with
/// (`io::demos::CONSISTENCY_TOLERANCE`).
pub const NEAR_START: f64 = 0.01;

/// How far the wrist may be from the learner's wrist lock (rad, each wrist joint).
pub const WRIST_TOLERANCE: f64 = 0.01;

/// One package of the stream: arm time (s) and the six joints' angles (rad) and velocities
/// (rad/s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Arm time (RTDE `timestamp`, s).
    pub t: f64,
    /// `actual_q` (rad).
    pub q: Joints6,
    /// `actual_qd` (rad/s).
    pub qd: Joints6,
}

impl Sample {
    /// Refuses a package no arm sends: a joint angle or speed not finite, or an angle outside
    /// `model`'s limits by more than [`LIMIT_MARGIN_RAD`].
    pub fn check(&self, model: UrModel) -> Result<(), MeasuredFault> {
        let limits = model.joint_limits();
        for j in 0..6 {
            let (q, qd) = (self.q[j], self.qd[j]);
            if !q.is_finite() || !qd.is_finite() {
                return Err(MeasuredFault::NonFinite {
                    t: self.t,
                    joint: j,
                    q,
                    qd,
                });
            }
            let (lower, upper) = (limits.lower[j], limits.upper[j]);
            if q < lower - LIMIT_MARGIN_RAD || q > upper + LIMIT_MARGIN_RAD {
                return Err(MeasuredFault::OutsideLimits {
                    t: self.t,
                    joint: j,
                    q,
                    lower,
                    upper,
                    model,
                });
            }
        }
        Ok(())
    }
}

/// A demonstration as the stream gave it.
#[derive(Clone, Debug, PartialEq)]
pub struct Taught {
    /// Its packages, from the first of the window in which the motion was seen to the one
    /// that completed the final rest.
    pub samples: Vec<Sample>,
    /// Arm time the final rest began (s): the motion's end.
    pub motion_end: f64,
}

/// What the stream said, per [`Segmenter::push`].
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// The start pose is known (the first rest).
    StartPose(Joints6),
    /// A demonstration.
    Demonstration(Taught),
    /// A motion that is not a demonstration, and why.
    Discarded {
        /// Arm time the motion started (s).
        at: f64,
        /// Why.
        why: String,
    },
}

/// What the recorder waits for ([`Status`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Waiting {
    /// The first rest, which sets the start pose.
    StartPose,
    /// A motion from the start pose, where the arm rests.
    Motion,
    /// The end of the demonstration under way: a rest away from the start pose.
    End,
    /// A rest at the start pose (the arm is elsewhere, or moves from elsewhere).
    Start,
}

/// What the recorder waits for and what it measures, for its messages while it waits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Status {
    /// What it waits for.
    pub waiting: Waiting,
    /// The end-effector point's travel over the last [`REST_WINDOW_S`] (m; NaN until the
    /// stream spans that long).
    pub travel_m: f64,
    /// How long the arm has rested (s of arm time; 0 while it moves).
    pub rest_s: f64,
    /// How long the demonstration under way has lasted (s of arm time).
    pub demonstration_s: f64,
    /// The largest difference of a joint (window mean) from the start pose (rad), once known.
    pub from_start_rad: Option<f64>,
}

impl std::fmt::Display for Status {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let rest = format!(
            "a rest is the end-effector point within {:.0} mm over every {} s for {REST_S} s",
            REST_TRAVEL_M * 1e3,
            REST_WINDOW_S
        );
        match self.waiting {
            Waiting::StartPose => write!(
                f,
                "waiting for the first rest, which sets the start pose ({rest})"
            )?,
            Waiting::Motion => write!(
                f,
                "at the start pose: waiting for a motion (the end-effector point moving more \
                 than {:.0} mm in {REST_WINDOW_S} s)",
                REST_TRAVEL_M * 1e3
            )?,
            Waiting::End => write!(
                f,
                "demonstration under way for {:.1} s: waiting for its end, a rest away from the \
                 start pose ({rest})",
                self.demonstration_s
            )?,
            Waiting::Start => write!(
                f,
                "waiting for a rest at the start pose (every joint within {NEAR_START} rad of it; \
                 {rest})"
            )?,
        }
        if self.travel_m.is_nan() {
            write!(
                f,
                "; measuring (less than {REST_WINDOW_S} s of packages so far)"
            )?;
        } else {
            write!(
                f,
                "; the end-effector point moved {:.1} mm in the last {REST_WINDOW_S} s",
                self.travel_m * 1e3
            )?;
        }
        if self.rest_s > 0.0 {
            write!(f, ", at rest for {:.1} s", self.rest_s)?;
        }
        if let (Some(d), Waiting::Start | Waiting::Motion) = (self.from_start_rad, self.waiting) {
            write!(f, ", {d:.3} rad from the start pose")?;
        }
        Ok(())
    }
}

/// Cuts a stream of packages into demonstrations by the rule of the module docs.
#[derive(Debug)]
pub struct Segmenter {
    kin: UrKinematics,
    start: Option<Joints6>,
    /// The packages of the last [`REST_WINDOW_S`] and the one before, with their end-effector
    /// points (m).
    window: VecDeque<(Sample, [f64; 3])>,
    /// The end-effector point's travel over the window (m; NaN while it spans less).
    travel: f64,
    /// Packages kept: the current rest's, or since a demonstration's onset.
    buf: Vec<Sample>,
    /// The current rest: the arm time it began (s) and the index in `buf` of its first package.
    rest: Option<(f64, usize)>,
    /// Whether a demonstration is under way (it starts at `buf[0]`).
    moving: bool,
    /// Whether the last package ended a qualifying rest near the start pose.
    armed: bool,
}

fn max_diff(a: &Joints6, b: &Joints6) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

impl Segmenter {
    /// A segmenter for an arm of kinematics `kin` (its end-effector point measures rests).
    pub fn new(kin: UrKinematics) -> Self {
        Self {
            kin,
            start: None,
            window: VecDeque::new(),
            travel: f64::NAN,
            buf: Vec::new(),
            rest: None,
            moving: false,
            armed: false,
        }
    }

    /// The start pose, once known.
    pub fn start_pose(&self) -> Option<Joints6> {
        self.start
    }

    /// The mean joint angles over the window (rad): a tremor averaged out.
    fn window_mean(&self) -> Joints6 {
        let n = self.window.len() as f64;
        core::array::from_fn(|j| self.window.iter().map(|(s, _)| s.q[j]).sum::<f64>() / n)
    }

    /// What it waits for and what it measures.
    pub fn status(&self) -> Status {
        let now = self.window.back().map_or(0.0, |(s, _)| s.t);
        let waiting = match (self.start, self.moving, self.armed) {
            (None, _, _) => Waiting::StartPose,
            (Some(_), true, _) => Waiting::End,
            (Some(_), false, true) => Waiting::Motion,
            (Some(_), false, false) => Waiting::Start,
        };
        Status {
            waiting,
            travel_m: self.travel,
            rest_s: self.rest.map_or(0.0, |(begin, _)| now - begin),
            demonstration_s: if self.moving {
                now - self.buf[0].t
            } else {
                0.0
            },
            from_start_rad: self
                .start
                .filter(|_| !self.window.is_empty())
                .map(|p| max_diff(&self.window_mean(), &p)),
        }
    }

    /// The robot stopped the arm (a protective stop, an emergency stop, the arm not running:
    /// `why` says which, at arm time `at`): a demonstration under way is cut short, not taught,
    /// and is discarded; the rest and the window start again once the robot runs.
    pub fn interrupt(&mut self, at: f64, why: &str) -> Option<Event> {
        let event = self.moving.then(|| Event::Discarded {
            at: self.buf[0].t,
            why: format!("{why} at t = {at:.2} s cut it short"),
        });
        self.window.clear();
        self.travel = f64::NAN;
        self.buf.clear();
        self.rest = None;
        self.moving = false;
        self.armed = false;
        event
    }

    /// Takes the next package (in time order) and says what it completed, if anything.
    pub fn push(&mut self, s: Sample) -> Option<Event> {
        if let Some((last, _)) = self.window.back() {
            if s.t <= last.t {
                return None; // a repeat (or out of order): nothing new
            }
        }
        self.window.push_back((s, self.kin.ee_point(&s.q)));
        while self.window.len() > 2 && self.window[1].0.t <= s.t - REST_WINDOW_S {
            self.window.pop_front();
        }
        self.travel = if s.t - self.window[0].0.t >= REST_WINDOW_S {
            (0..3)
                .map(|k| {
                    let (lo, hi) = self
                        .window
                        .iter()
                        .fold((f64::MAX, f64::MIN), |(lo, hi), w| {
                            (lo.min(w.1[k]), hi.max(w.1[k]))
                        });
                    hi - lo
                })
                .fold(0.0, f64::max)
        } else {
            f64::NAN
        };
        if !(self.travel <= REST_TRAVEL_M) {
            self.rest = None;
            if self.armed && !self.moving {
                // Onset: the motion began within the window, whose first package still rests
                // at the start pose: the demonstration starts there.
                self.buf.clear();
                self.buf.extend(self.window.iter().map(|(w, _)| *w));
                self.moving = true;
            } else if self.moving {
                self.buf.push(s);
            } else {
                self.buf.clear();
            }
            self.armed = false;
            return None;
        }
        if self.rest.is_none() {
            if !self.moving {
                self.buf.clear();
            }
            // The window of the first still package was still: the rest began at its start.
            self.rest = Some((self.window[0].0.t, self.buf.len()));
        }
        self.buf.push(s);
        let (begin, from) = self.rest.expect("set");
        if s.t - begin < REST_S {
            return None;
        }
        let mut event = None;
        let start = match self.start {
            Some(p) => p,
            None => {
                let rest = &self.buf[from..];
                let n = rest.len() as f64;
                let mean: Joints6 =
                    core::array::from_fn(|j| rest.iter().map(|r| r.q[j]).sum::<f64>() / n);
                self.start = Some(mean);
                event = Some(Event::StartPose(mean));
                mean
            }
        };
        let near = max_diff(&self.window_mean(), &start) <= NEAR_START;
        if self.moving {
            self.moving = false;
            let at = self.buf[0].t;
            event = Some(if near {
                Event::Discarded {
                    at,
                    why: "it came back to rest at the start pose".into(),
                }
            } else {
                Event::Demonstration(Taught {
                    samples: std::mem::take(&mut self.buf),
                    motion_end: begin,
                })
            });
            // Keep only this rest's last package, as the rest goes on.
            self.buf.clear();
            self.buf.push(s);
            self.rest = Some((begin, 0));
        } else if self.buf.len() > 1 {
            // Waiting: the rest's first package and the newest are all that matter.
            let first = self.buf[from];
            self.buf.clear();
            self.buf.extend([first, s]);
            self.rest = Some((begin, 0));
        }
        self.armed = near;
        event
    }
}

/// Linear interpolation of the packages' joints at arm time `t` (s), within their span.
fn interpolate(samples: &[Sample], t: f64) -> (Joints6, Joints6) {
    let k = samples
        .partition_point(|s| s.t <= t)
        .clamp(1, samples.len() - 1);
    let (a, b) = (&samples[k - 1], &samples[k]);
    let w = ((t - a.t) / (b.t - a.t)).clamp(0.0, 1.0);
    (
        core::array::from_fn(|j| a.q[j] + w * (b.q[j] - a.q[j])),
        core::array::from_fn(|j| a.qd[j] + w * (b.qd[j] - a.qd[j])),
    )
}

/// A demonstration as T steps of the control period `dt` (module docs), six joints each, or
/// why it cannot be one.
pub fn resample(demo: &Taught, dt: f64, horizon: usize) -> Result<Vec<(Joints6, Joints6)>, String> {
    let samples = &demo.samples;
    if samples.len() < 2 {
        return Err("fewer than 2 packages".into());
    }
    let onset = samples[0].t;
    let span = (horizon - 1) as f64 * dt;
    if demo.motion_end - onset > span {
        return Err(format!(
            "its motion took {:.2} s, longer than the horizon's (T − 1) dt = {span:.2} s: move \
             faster, or raise task.horizon",
            demo.motion_end - onset
        ));
    }
    let end = samples.last().expect("2 packages");
    Ok((0..horizon)
        .map(|k| {
            let t = onset + k as f64 * dt;
            if t <= end.t {
                interpolate(samples, t)
            } else {
                (end.q, [0.0; 6])
            }
        })
        .collect())
}

/// What a recording gave, beside its demonstrations.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RecordReport {
    /// Demonstrations kept.
    pub episodes: usize,
    /// Start pose (rad, active joints).
    pub start_q: Joints,
    /// Goal: the mean end-effector point at the demonstrations' last step (m, base frame).
    pub goal: [f64; 3],
    /// A pose goal: the mean of the demonstrations' last tool poses (UR's p[x, y, z, rx, ry,
    /// rz]: m, rotation vector, base frame); `None` for a point goal.
    pub goal_pose: Option<[f64; 6]>,
    /// Largest distance of a demonstration's last end-effector point from the goal (m).
    pub goal_spread_max_m: f64,
    /// Root mean square of those distances (m).
    pub goal_spread_rms_m: f64,
    /// Mean task cost of the demonstrations (C_expert).
    pub cost_expert: f64,
    /// Mean task cost of the random initial controller on the task (C_random).
    pub cost_random: f64,
}

/// The demonstrations `demos` (each a [`Segmenter`] demonstration) recorded on the arm of
/// `sim`, with start pose `start` (six joints, rad), as T = `task.horizon` steps of
/// `task.dt` (module docs), in the layout of `task.joints` active joints and a point goal, or
/// with `pose` (six joints only) a pose goal: the mean of the demonstrations' last tool poses
/// ([`ur5_shared::pose::mean_pose`]), the state's three tool points `task.tool_points`.
/// Each is first [`resample`]d and, for three joints, checked against the wrist lock by the
/// caller ([`steps_checked`]).
pub fn to_recorded_demos(
    episodes: &[Vec<(Joints6, Joints6)>],
    start: &Joints6,
    task: &TaskConfig,
    sim: &SimConfig,
    pose: bool,
) -> Result<(Demos, RecordReport), RecordError> {
    if episodes.is_empty() {
        return Err(RecordError::NoDemonstrations);
    }
    let joints = task.joints;
    if pose && joints != 6 {
        return Err(RecordError::PoseNeedsSixJoints(joints));
    }
    let kin = UrKinematics::new(sim.model, sim.ee_offset);
    let last = |ep: &Vec<(Joints6, Joints6)>| ep.last().expect("T ≥ 2").0;
    let goal_pose = pose.then(|| mean_tool_pose(&kin, episodes.iter().map(last)));
    let ends: Vec<[f64; 3]> = episodes
        .iter()
        .map(|ep| kin.ee_point_velocity(&last(ep), &[0.0; 6]).0)
        .collect();
    let n = episodes.len() as f64;
    let goal: [f64; 3] = match goal_pose {
        Some(p) => [p[0], p[1], p[2]],
        None => core::array::from_fn(|k| ends.iter().map(|e| e[k]).sum::<f64>() / n),
    };
    let dist: Vec<f64> = ends
        .iter()
        .map(|e| (0..3).map(|k| (e[k] - goal[k]).powi(2)).sum::<f64>().sqrt())
        .collect();
    let goal_task = TaskConfig {
        goal,
        goal_pose,
        ..task.clone()
    };
    let layout = goal_task.layout();
    let mut states = vec![0.0; episodes.len() * task.horizon * layout.dx()];
    arm_states(
        &kin,
        &goal_task,
        episodes.iter().flatten().copied(),
        &mut states,
    );
    let start_q = Joints::from_slice(&start[..joints]);
    let traj = Trajectories {
        layout,
        states,
        actions: None,
        count: episodes.len(),
        horizon: task.horizon,
        dt: task.dt,
        task: Some(TaskMeta {
            goal,
            start_q,
            seed: DERIVED_SEED,
            cost_random: None,
            cost_expert: None,
            goal_pose,
            tool_points: (pose && task.tool_points != ur5_shared::config::DEFAULT_TOOL_POINTS)
                .then_some(task.tool_points),
        }),
        model: Some(sim.model),
    };
    let demos = to_demos(traj, sim)?;
    crate::io::demos::check_against_arm(&demos, sim)?;
    let report = RecordReport {
        episodes: demos.count,
        start_q,
        goal,
        goal_pose,
        goal_spread_max_m: dist.iter().copied().fold(0.0, f64::max),
        goal_spread_rms_m: (dist.iter().map(|d| d * d).sum::<f64>() / n).sqrt(),
        cost_expert: demos.cost_expert,
        cost_random: demos.cost_random,
    };
    Ok((demos, report))
}

/// [`resample`], then, for a three-joint task, the wrist against `sim.wrist_q`
/// ([`WRIST_TOLERANCE`]); a six-joint task's wrist moves freely.
pub fn steps_checked(
    demo: &Taught,
    task: &TaskConfig,
    sim: &SimConfig,
) -> Result<Vec<(Joints6, Joints6)>, String> {
    let steps = resample(demo, task.dt, task.horizon)?;
    if task.joints == 6 {
        return Ok(steps);
    }
    for (k, (q, _)) in steps.iter().enumerate() {
        for w in 0..3 {
            let d = q[3 + w] - sim.wrist_q[w];
            if d.abs() > WRIST_TOLERANCE {
                return Err(format!(
                    "at step {k} wrist {} is at {:.4} rad, {:.4} rad from the wrist lock {:.4} \
                     rad (sim.wrist_q) the learner's arm keeps: keep the wrist still while \
                     teaching, or set sim.wrist_q",
                    w + 1,
                    q[3 + w],
                    d,
                    sim.wrist_q[w]
                ));
            }
        }
    }
    Ok(steps)
}

#[cfg(test)]
mod tests {
    use super::*;

    const W: [f64; 3] = [
        -std::f64::consts::FRAC_PI_2,
        std::f64::consts::FRAC_PI_2,
        0.0,
    ];

    /// A hand's tremor on the active joints: amplitude (rad, each joint) and frequency (Hz).
    #[derive(Clone, Copy)]
    struct Tremor {
        rad: f64,
        hz: f64,
    }

    /// A stream at `rate` Hz: rest at A for `r0` s, a smooth move to B in 1 s, rest `r1` s;
    /// `tremor` throughout, rests included.
    fn stream_with(
        rate: f64,
        a: [f64; 3],
        b: [f64; 3],
        t0: f64,
        (r0, r1): (f64, f64),
        tremor: Option<Tremor>,
    ) -> Vec<Sample> {
        let dt = 1.0 / rate;
        let n = ((r0 + 1.0 + r1) * rate) as usize;
        (0..n)
            .map(|i| {
                let t = i as f64 * dt;
                let tau = ((t - r0) / 1.0).clamp(0.0, 1.0);
                let s = tau * tau * (3.0 - 2.0 * tau);
                let ds = if (0.0..1.0).contains(&((t - r0) / 1.0)) {
                    6.0 * tau * (1.0 - tau)
                } else {
                    0.0
                };
                let w = 2.0 * std::f64::consts::PI * tremor.map_or(0.0, |tr| tr.hz);
                let amp = tremor.map_or(0.0, |tr| tr.rad);
                let (tq, tqd) = (amp * (w * (t0 + t)).sin(), amp * w * (w * (t0 + t)).cos());
                let q: [f64; 3] = core::array::from_fn(|j| a[j] + s * (b[j] - a[j]) + tq);
                let qd: [f64; 3] = core::array::from_fn(|j| ds * (b[j] - a[j]) + tqd);
                Sample {
                    t: t0 + t,
                    q: UrKinematics::six(&q, &W),
                    qd: UrKinematics::six(&qd, &[0.0; 3]),
                }
            })
            .collect()
    }

    fn stream(rate: f64, a: [f64; 3], b: [f64; 3], t0: f64, r0: f64, r1: f64) -> Vec<Sample> {
        stream_with(rate, a, b, t0, (r0, r1), None)
    }

    fn kin() -> UrKinematics {
        let sim = SimConfig::default();
        UrKinematics::new(sim.model, sim.ee_offset)
    }

    fn run(samples: &[Sample]) -> Vec<Event> {
        let mut seg = Segmenter::new(kin());
        samples.iter().filter_map(|s| seg.push(*s)).collect()
    }

    fn demonstrations(ev: &[Event]) -> Vec<&Taught> {
        ev.iter()
            .filter_map(|e| match e {
                Event::Demonstration(d) => Some(d),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn rests_cut_demonstrations_and_a_return_is_not_one() {
        let (a, b) = ([0.0, -2.0, 2.4], [0.3, -1.4, 2.1]);
        for rate in [500.0, 125.0] {
            let mut s = stream(rate, a, b, 0.0, 1.5, 1.2);
            let t1 = s.last().unwrap().t + 1.0 / rate;
            // The way back (not a demonstration), then a motion that gives up.
            s.extend(stream(rate, b, a, t1, 0.0, 1.5));
            let t2 = s.last().unwrap().t + 1.0 / rate;
            s.extend(stream(rate, a, a, t2, 0.2, 0.0));
            let ev = run(&s);
            assert!(
                matches!(ev[0], Event::StartPose(p) if max_diff(&p, &UrKinematics::six(&a, &W)) < 1e-12)
            );
            let demos = demonstrations(&ev);
            assert_eq!(demos.len(), 1, "{rate} Hz: {ev:?}");
            let d = demos[0];
            // From the first package of the window in which the motion (from t = 1.5 s) was
            // seen, still at the start pose, to 1 s of final rest; the motion ends at 2.5 s.
            let t_first = d.samples[0].t;
            assert!(
                t_first >= 1.5 - REST_WINDOW_S - 2.0 / rate && t_first <= 1.5,
                "{t_first}"
            );
            assert_eq!(d.samples[0].q, UrKinematics::six(&a, &W));
            assert!(
                d.motion_end > 2.5 - REST_WINDOW_S && d.motion_end <= 2.5,
                "{}",
                d.motion_end
            );
            let task = TaskConfig {
                dt: 0.1,
                horizon: 30,
                ..TaskConfig::default()
            };
            let steps = steps_checked(d, &task, &SimConfig::default()).unwrap();
            assert_eq!(steps.len(), 30);
            assert!(max_diff(&steps[0].0, &UrKinematics::six(&a, &W)) < 1e-3);
            let last = steps[29];
            assert!(max_diff(&last.0, &UrKinematics::six(&b, &W)) < 1e-9 && last.1 == [0.0; 6]);
            // Too short a horizon for the motion.
            let short = TaskConfig {
                horizon: 8,
                ..task.clone()
            };
            let e = steps_checked(d, &short, &SimConfig::default()).unwrap_err();
            assert!(e.contains("longer than the horizon"), "{e}");
            // A wrist that moved.
            let mut bent = d.clone();
            bent.samples.iter_mut().for_each(|s| s.q[4] += 0.05);
            let e = steps_checked(&bent, &task, &SimConfig::default()).unwrap_err();
            assert!(e.contains("wrist 2") && e.contains("sim.wrist_q"), "{e}");
        }
    }

    /// A six-joint task keeps the wrist's motion: all six joints in the demonstrations' states
    /// (six joints and a point goal, dX = 18), the start pose of six angles.
    #[test]
    fn the_whole_arm_is_recorded_with_its_wrist_moving() {
        let (a, b) = ([0.0, -2.0, 2.4], [0.3, -1.4, 2.1]);
        let ev = run(&stream(125.0, a, b, 0.0, 1.5, 1.2));
        let mut d = demonstrations(&ev)[0].clone();
        // The wrist turns with the arm (0.3 rad of wrist 1 and −0.2 of wrist 3 over the motion).
        for s in &mut d.samples {
            let f = (s.t - 1.5).clamp(0.0, 1.0);
            s.q[3] += 0.3 * f;
            s.q[5] -= 0.2 * f;
        }
        let sim = SimConfig::default();
        let three = TaskConfig {
            dt: 0.1,
            horizon: 30,
            ..TaskConfig::default()
        };
        assert!(steps_checked(&d, &three, &sim)
            .unwrap_err()
            .contains("wrist 1"));
        let start = UrKinematics::six(&a, &W);
        let task = TaskConfig {
            joints: 6,
            start_q: Joints::from_slice(&start),
            ..three
        };
        task.validate().unwrap();
        let steps = steps_checked(&d, &task, &sim).unwrap();
        let (demos, report) =
            to_recorded_demos(&[steps.clone()], &start, &task, &sim, false).unwrap();
        let layout = ur5_shared::StateLayout::of_task(6, false).unwrap();
        assert_eq!(demos.layout(), layout);
        assert_eq!(demos.states.len(), 30 * 18);
        assert_eq!((demos.start_q.len(), report.start_q.len()), (6, 6));
        let kin = kin();
        for t in [0, 15, 29] {
            let s = demos.state(0, t);
            let (q, qd) = steps[t];
            assert_eq!(&s[layout.q()], &q[..]);
            assert_eq!(&s[layout.qd()], &qd[..]);
            let (ee, v) = kin.ee_point_velocity(&q, &qd);
            for k in 0..3 {
                assert!((s[layout.point(0)][k] - (ee[k] - report.goal[k])).abs() < 1e-12);
                assert_eq!(s[layout.point_velocity(0)][k], v[k]);
            }
        }
        assert!(
            (steps[29].0[3] - (W[0] + 0.3)).abs() < 1e-9,
            "the wrist moved"
        );
        assert!(report.cost_random.is_finite() && report.cost_expert.is_finite());
        assert_eq!(demos.task().unwrap().joints, 6);
    }

    /// With a pose goal the state carries three tool points against the demonstrations' mean
    /// last tool pose (dX = 30); a task that keeps the wrist locked is refused.
    #[test]
    fn a_pose_goal_is_the_demonstrations_mean_last_tool_pose() {
        let (a, b) = ([0.0, -2.0, 2.4], [0.3, -1.4, 2.1]);
        let ev = run(&stream(125.0, a, b, 0.0, 1.5, 1.2));
        let mut d = demonstrations(&ev)[0].clone();
        for s in &mut d.samples {
            s.q[4] += 0.4 * (s.t - 1.5).clamp(0.0, 1.0);
        }
        let sim = SimConfig::default();
        let start = UrKinematics::six(&a, &W);
        let three = TaskConfig {
            dt: 0.1,
            horizon: 30,
            ..TaskConfig::default()
        };
        let task = TaskConfig {
            joints: 6,
            start_q: Joints::from_slice(&start),
            ..three.clone()
        };
        let steps = steps_checked(&d, &task, &sim).unwrap();
        let e = to_recorded_demos(&[steps.clone()], &start, &three, &sim, true).unwrap_err();
        assert!(matches!(e, RecordError::PoseNeedsSixJoints(3)), "{e}");
        let (demos, report) =
            to_recorded_demos(&[steps.clone()], &start, &task, &sim, true).unwrap();
        let layout = ur5_shared::StateLayout::POSE6;
        assert_eq!(demos.layout(), layout);
        let want = ur5_shared::pose::ur_pose(&kin().tool_pose(&steps[29].0));
        let p = report.goal_pose.expect("a pose goal");
        for k in 0..6 {
            assert!((p[k] - want[k]).abs() < 1e-9, "{p:?} against {want:?}");
        }
        assert_eq!(demos.task().unwrap().goal_pose, Some(p));
        assert_eq!(report.goal, [p[0], p[1], p[2]]);
        // Every tool point on its target at the last step, not at the first.
        let (first, end) = (demos.state(0, 0), demos.state(0, 29));
        for i in 0..3 {
            assert!(
                end[layout.point(i)].iter().all(|v| v.abs() < 1e-9),
                "point {i}"
            );
        }
        assert!((0..3).all(|i| first[layout.point(i)].iter().any(|v| v.abs() > 0.01)));
    }

    #[test]
    fn a_motion_back_to_the_start_is_discarded() {
        let a = [0.0, -2.0, 2.4];
        let mut s = stream(500.0, a, [0.1, -1.9, 2.3], 0.0, 1.5, 0.1);
        let t1 = s.last().unwrap().t + 0.002;
        s.extend(stream(500.0, [0.1, -1.9, 2.3], a, t1, 0.0, 1.5));
        let ev = run(&s);
        assert!(
            ev.iter()
                .any(|e| matches!(e, Event::Discarded { why, .. } if why.contains("start pose"))),
            "{ev:?}"
        );
        assert!(demonstrations(&ev).is_empty());
    }

    /// A reach the robot stopped (a protective stop) is not a demonstration, though the arm
    /// then rests away from the start pose; the next reach from the start pose is one.
    #[test]
    fn a_reach_cut_short_by_a_stop_is_not_a_demonstration() {
        let (a, b) = ([0.0, -2.0, 2.4], [0.3, -1.4, 2.1]);
        let first = stream(500.0, a, b, 0.0, 1.5, 1.5);
        let mut seg = Segmenter::new(kin());
        let mut ev = Vec::new();
        for s in &first {
            // The robot stops the arm in the middle of the reach.
            if (1.9..2.0).contains(&s.t) {
                ev.extend(seg.interrupt(s.t, "a protective stop (safety mode PROTECTIVE_STOP)"));
            } else {
                ev.extend(seg.push(*s));
            }
        }
        assert!(demonstrations(&ev).is_empty(), "{ev:?}");
        assert!(
            ev.iter().any(|e| matches!(e, Event::Discarded { why, .. }
                if why.contains("PROTECTIVE_STOP") && why.contains("cut it short"))),
            "{ev:?}"
        );
        // Back to the start pose (not a demonstration), then a whole reach: one.
        let t1 = first.last().unwrap().t + 0.002;
        let mut rest = stream(500.0, b, a, t1, 0.0, 1.5);
        let t2 = rest.last().unwrap().t + 0.002;
        rest.extend(stream(500.0, a, b, t2, 0.5, 1.5));
        ev.clear();
        ev.extend(rest.iter().filter_map(|s| seg.push(*s)));
        assert_eq!(demonstrations(&ev).len(), 1, "{ev:?}");
    }

    /// A held arm trembles (0.1–1 mm at the end-effector point, 8–12 Hz), rests included: the
    /// rests still cut the same demonstration as without tremor, though the tremor's joint
    /// speeds exceed the instantaneous rule's 0.05 rad/s. While it waits, the recorder says
    /// what for and what it measures.
    #[test]
    fn a_tremor_does_not_hide_a_rest() {
        let (a, b) = ([0.0, -2.0, 2.4], [0.3, -1.4, 2.1]);
        let k = kin();
        // The end-effector point's displacement per rad of all three active joints together.
        let p0 = k.ee_point(&UrKinematics::six(&a, &W));
        let p1 = k.ee_point(&UrKinematics::six(&a.map(|v| v + 1e-6), &W));
        let gain = (0..3).map(|i| (p1[i] - p0[i]).powi(2)).sum::<f64>().sqrt() / 1e-6;
        let task = TaskConfig {
            dt: 0.1,
            horizon: 30,
            ..TaskConfig::default()
        };
        let mut fastest = 0.0f64;
        for (mm, hz) in [
            (0.1, 8.0),
            (0.1, 12.0),
            (1.0, 8.0),
            (1.0, 12.0),
            (1.0, 10.0),
        ] {
            let tremor = Tremor {
                rad: mm * 1e-3 / gain,
                hz,
            };
            let s = stream_with(500.0, a, b, 0.0, (1.5, 1.5), Some(tremor));
            // The tremor is as large as said at the end-effector point.
            let range = (0..3)
                .map(|i| {
                    let v = s[..500].iter().map(|x| k.ee_point(&x.q)[i]);
                    v.clone().fold(f64::MIN, f64::max) - v.fold(f64::MAX, f64::min)
                })
                .fold(0.0, f64::max);
            assert!(range <= 2.0 * mm * 1e-3 * 1.01, "{mm} mm: range {range}");
            fastest = fastest.max(s[..500].iter().map(|x| x.qd[0].abs()).fold(0.0, f64::max));
            let mut seg = Segmenter::new(k);
            let mut ev = Vec::new();
            let mut said = Vec::new();
            for x in &s {
                ev.extend(seg.push(*x));
                if ((x.t * 500.0).round() as u64) % 250 == 0 {
                    said.push(seg.status().to_string());
                }
            }
            let demos = demonstrations(&ev);
            assert_eq!(demos.len(), 1, "{mm} mm at {hz} Hz: {ev:?}");
            let steps = steps_checked(demos[0], &task, &SimConfig::default()).unwrap();
            let (first, last) = (steps[0].0, steps[29].0);
            assert!(max_diff(&first, &UrKinematics::six(&a, &W)) < 2.0 * tremor.rad + 1e-9);
            assert!(max_diff(&last, &UrKinematics::six(&b, &W)) < 2.0 * tremor.rad + 1e-9);
            // What it said while it waited: the first rest, then a motion from the start pose,
            // then the demonstration's end; each with the measured travel.
            let joined = said.join("\n");
            for want in [
                "waiting for the first rest",
                "at the start pose: waiting for a motion",
                "demonstration under way",
                "mm in the last 0.25 s",
            ] {
                assert!(joined.contains(want), "{want}:\n{joined}");
            }
        }
        assert!(fastest > 0.05, "the tremor's speed {fastest} rad/s");
    }

    #[test]
    fn a_package_no_arm_sends_is_named() {
        let ok = Sample {
            t: 3.0,
            q: UrKinematics::six(&[0.0, -2.0, 2.4], &W),
            qd: [0.0; 6],
        };
        ok.check(UrModel::Ur5e).unwrap();
        let mut nan = ok;
        nan.q[2] = f64::NAN;
        let e = nan.check(UrModel::Ur5e).unwrap_err().to_string();
        assert!(
            e.contains("joint 2") && e.contains("NaN") && e.contains("3 s"),
            "{e}"
        );
        let mut far = ok;
        far.q[0] = 100.0;
        let e = far.check(UrModel::Ur5e).unwrap_err().to_string();
        assert!(
            e.contains("joint 0 at 100 rad") && e.contains("ur5e"),
            "{e}"
        );
    }
}
