//! Teaching by hand (`learner record`, docs/ur.md "Teaching by hand", docs/data.md "The
//! recording rule"): demonstrations cut from a UR's stream of joint states while a person
//! guides the arm (freedrive) or any program moves it.
//!
//! **The rule.** The arm is *at rest* while every joint is slower than [`REST_SPEED`]. The
//! first rest of at least [`REST_S`] defines the *start pose* (the mean pose of that rest). A
//! demonstration *starts* when the arm leaves a rest of at least [`REST_S`] within
//! [`NEAR_START`] of the start pose (its first step is the last resting sample) and *ends* once
//! the arm has rested [`REST_S`] elsewhere. A motion that comes back to rest near the start
//! pose is not a demonstration (the person gave up); nor is a motion from anywhere else (e.g.
//! the way back to the start pose).
//!
//! **To T steps.** A demonstration is resampled at the control period (t_k = onset + k dt,
//! joint angles and velocities linearly interpolated between the arm's packages by their
//! timestamps, so 500 Hz and 125 Hz streams and lost packages give the same steps) for
//! k = 0 … T − 1; past the end of the recorded rest it is padded with the resting pose at zero
//! velocity. One whose motion has not come to rest within T steps is skipped (the message says
//! how long it took against T dt). Its end-effector point and velocity come from all six joints
//! by the model's forward kinematics (`ur5_shared::kinematics`), as the `ur` backend builds the
//! state; the wrist must stay within [`WRIST_TOLERANCE`] of the wrist lock (`sim.wrist_q`) the
//! learner's arm keeps, or the demonstration is skipped.
//!
//! **The task.** start_q = the start pose's active joints; goal = the mean end-effector point
//! at the demonstrations' last step, its spread reported. C_expert and C_random are derived as
//! for any imported demonstrations (`io::foreign`): the demonstrations' mean task cost, and the
//! expert's random initial controller run on the task in the simulator.

use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::kinematics::{Joints6, UrKinematics};
use ur5_shared::layout::{state_vector, DX};

use imitation::demos::Demos;

use crate::io::foreign::{to_demos, DERIVED_SEED};
use crate::io::lerobot::{TaskMeta, Trajectories};

/// Why recorded demonstrations cannot be turned into the learner's.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// Nothing was recorded (no segment was taken for a demonstration).
    #[error("no demonstrations were recorded")]
    NoDemonstrations,
    /// The demonstrations checked against the arm.
    #[error(transparent)]
    Demos(#[from] crate::io::demos::DemosError),
    /// The recorded trajectories as demonstrations of the arm.
    #[error(transparent)]
    Io(#[from] crate::io::IoError),
}

/// Joint speed below which the arm counts as at rest (rad/s, every joint): above a held arm's
/// tremor, well below a deliberate motion's speed (tenths of rad/s).
pub const REST_SPEED: f64 = 0.05;

/// How long a rest starts or ends a demonstration (s of arm time).
pub const REST_S: f64 = 1.0;

/// How close to the start pose a rest starts a demonstration (rad, every joint): the
/// tolerance imported demonstrations are checked with (`io::demos::CONSISTENCY_TOLERANCE`).
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
    fn at_rest(&self) -> bool {
        self.qd.iter().all(|v| v.abs() < REST_SPEED)
    }
}

/// What the stream said, per [`Segmenter::push`].
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// The start pose is known (the first rest).
    StartPose(Joints6),
    /// A demonstration: its packages from the last resting one before the motion to the one
    /// that completed the final rest.
    Demonstration(Vec<Sample>),
    /// A motion that is not a demonstration, and why.
    Discarded {
        /// Arm time the motion started (s).
        at: f64,
        /// Why.
        why: String,
    },
}

/// Cuts a stream of packages into demonstrations by the rule of the module docs.
#[derive(Debug, Default)]
pub struct Segmenter {
    start: Option<Joints6>,
    /// Packages kept: the current rest's, or since a demonstration's onset.
    buf: Vec<Sample>,
    /// Index in `buf` of the current rest's first package.
    rest_from: Option<usize>,
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
    /// The start pose, once known.
    pub fn start_pose(&self) -> Option<Joints6> {
        self.start
    }

    /// Takes the next package (in time order) and says what it completed, if anything.
    pub fn push(&mut self, s: Sample) -> Option<Event> {
        if let Some(last) = self.buf.last() {
            if s.t <= last.t {
                return None; // a repeat (or out of order): nothing new
            }
        }
        if !s.at_rest() {
            self.rest_from = None;
            if self.armed && !self.moving {
                // Onset: the demonstration starts at the last resting package.
                let last = *self.buf.last().expect("armed after a rest");
                self.buf.clear();
                self.buf.push(last);
                self.moving = true;
            }
            self.armed = false;
            if self.moving {
                self.buf.push(s);
            } else {
                self.buf.clear();
            }
            return None;
        }
        if self.rest_from.is_none() {
            if !self.moving {
                self.buf.clear();
            }
            self.rest_from = Some(self.buf.len());
        }
        self.buf.push(s);
        let from = self.rest_from.expect("set");
        let rest_s = s.t - self.buf[from].t;
        if rest_s < REST_S {
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
        let near = max_diff(&s.q, &start) <= NEAR_START;
        if self.moving {
            self.moving = false;
            let at = self.buf[0].t;
            event = Some(if near {
                Event::Discarded {
                    at,
                    why: "it came back to rest at the start pose".into(),
                }
            } else {
                Event::Demonstration(std::mem::take(&mut self.buf))
            });
            // Keep only this rest's last package, as a new rest.
            self.buf.clear();
            self.buf.push(s);
            self.rest_from = Some(0);
        } else if self.buf.len() > 1 {
            // Waiting: the rest's first and last packages are all that matter.
            let first = self.buf[from];
            self.buf.clear();
            self.buf.extend([first, s]);
            self.rest_from = Some(0);
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
pub fn resample(
    demo: &[Sample],
    dt: f64,
    horizon: usize,
) -> Result<Vec<(Joints6, Joints6)>, String> {
    if demo.len() < 2 {
        return Err("fewer than 2 packages".into());
    }
    let onset = demo[0].t;
    // The motion ends where the final rest began: the last moving package's successor.
    let rest_start = demo
        .iter()
        .rposition(|s| !s.at_rest())
        .map_or(onset, |k| demo[(k + 1).min(demo.len() - 1)].t);
    let span = (horizon - 1) as f64 * dt;
    if rest_start - onset > span {
        return Err(format!(
            "its motion took {:.2} s, longer than the horizon's (T − 1) dt = {span:.2} s: move \
             faster, or raise task.horizon",
            rest_start - onset
        ));
    }
    let end = demo.last().expect("2 packages");
    Ok((0..horizon)
        .map(|k| {
            let t = onset + k as f64 * dt;
            if t <= end.t {
                interpolate(demo, t)
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
    pub start_q: [f64; 3],
    /// Goal: the mean end-effector point at the demonstrations' last step (m, base frame).
    pub goal: [f64; 3],
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
/// `task.dt` (module docs). Each is first [`resample`]d and checked against the wrist lock by
/// the caller ([`steps_checked`]).
pub fn to_recorded_demos(
    episodes: &[Vec<(Joints6, Joints6)>],
    start: &Joints6,
    task: &TaskConfig,
    sim: &SimConfig,
) -> Result<(Demos, RecordReport), RecordError> {
    if episodes.is_empty() {
        return Err(RecordError::NoDemonstrations);
    }
    let kin = UrKinematics::new(sim.model, sim.ee_offset);
    let points: Vec<Vec<([f64; 3], [f64; 3])>> = episodes
        .iter()
        .map(|ep| {
            ep.iter()
                .map(|(q, qd)| kin.ee_point_velocity(q, qd))
                .collect()
        })
        .collect();
    let n = episodes.len() as f64;
    let ends: Vec<[f64; 3]> = points.iter().map(|p| p.last().expect("T ≥ 2").0).collect();
    let goal: [f64; 3] = core::array::from_fn(|k| ends.iter().map(|e| e[k]).sum::<f64>() / n);
    let dist: Vec<f64> = ends
        .iter()
        .map(|e| (0..3).map(|k| (e[k] - goal[k]).powi(2)).sum::<f64>().sqrt())
        .collect();
    let mut states = Vec::with_capacity(episodes.len() * task.horizon * DX);
    for (ep, pts) in episodes.iter().zip(&points) {
        for ((q, qd), (ee, ee_vel)) in ep.iter().zip(pts) {
            states.extend_from_slice(&state_vector(
                &[q[0], q[1], q[2]],
                &[qd[0], qd[1], qd[2]],
                ee,
                ee_vel,
                &goal,
            ));
        }
    }
    let start_q = [start[0], start[1], start[2]];
    let traj = Trajectories {
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
        }),
        model: Some(sim.model),
    };
    let demos = to_demos(traj, sim)?;
    crate::io::demos::check_against_arm(&demos, sim)?;
    let report = RecordReport {
        episodes: demos.count,
        start_q,
        goal,
        goal_spread_max_m: dist.iter().copied().fold(0.0, f64::max),
        goal_spread_rms_m: (dist.iter().map(|d| d * d).sum::<f64>() / n).sqrt(),
        cost_expert: demos.cost_expert,
        cost_random: demos.cost_random,
    };
    Ok((demos, report))
}

/// [`resample`], then the wrist against `sim.wrist_q` ([`WRIST_TOLERANCE`]).
pub fn steps_checked(
    demo: &[Sample],
    task: &TaskConfig,
    sim: &SimConfig,
) -> Result<Vec<(Joints6, Joints6)>, String> {
    let steps = resample(demo, task.dt, task.horizon)?;
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

    /// A stream at `rate` Hz: rest at A for `r0` s, a smooth move to B in 1 s, rest `r1` s.
    fn stream(rate: f64, a: [f64; 3], b: [f64; 3], t0: f64, r0: f64, r1: f64) -> Vec<Sample> {
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
                let q: [f64; 3] = core::array::from_fn(|j| a[j] + s * (b[j] - a[j]));
                let qd: [f64; 3] = core::array::from_fn(|j| ds * (b[j] - a[j]));
                Sample {
                    t: t0 + t,
                    q: UrKinematics::six(&q, &W),
                    qd: UrKinematics::six(&qd, &[0.0; 3]),
                }
            })
            .collect()
    }

    fn run(samples: &[Sample]) -> Vec<Event> {
        let mut seg = Segmenter::default();
        samples.iter().filter_map(|s| seg.push(*s)).collect()
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
            let demos: Vec<&Vec<Sample>> = ev
                .iter()
                .filter_map(|e| match e {
                    Event::Demonstration(d) => Some(d),
                    _ => None,
                })
                .collect();
            assert_eq!(demos.len(), 1, "{rate} Hz: {ev:?}");
            let d = demos[0];
            // From the last resting package before the motion (which starts at t = 1.5 s and
            // passes REST_SPEED 14 ms later) to 1 s of final rest.
            assert!(d[0].t >= 1.5 && d[0].t <= 1.514 + 1.0 / rate, "{}", d[0].t);
            assert!(d[0].at_rest() && !d[1].at_rest());
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
            bent.iter_mut().for_each(|s| s.q[4] += 0.05);
            let e = steps_checked(&bent, &task, &SimConfig::default()).unwrap_err();
            assert!(e.contains("wrist 2") && e.contains("sim.wrist_q"), "{e}");
        }
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
        assert!(!ev.iter().any(|e| matches!(e, Event::Demonstration(_))));
    }
}
