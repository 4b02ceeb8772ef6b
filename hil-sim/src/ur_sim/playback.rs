//! `hil-sim ur-sim --playback FILE.csv`: the arm moved by hand (freedrive), as a recorded or
//! generated motion says (docs/data.md, "Playback files"; docs/ur.md, "Teaching by hand").
//!
//! A playback file is plain CSV with the header `t,q0,q1,q2,q3,q4,q5`: arm time t (s, from
//! 0) and the six joint angles (rad, base to wrist 3), one row per sample, typically several
//! motions one after another separated by pauses. [`Playback::parse`] checks it and names the
//! line and column of what is wrong: the header, numbers that do not parse or are not finite,
//! t not strictly increasing, rows less than [`MIN_ROW_STEP_S`] or more than
//! [`MAX_ROW_STEP_S`] apart, angles outside the model's joint limits, and joint speeds between
//! rows above the model's velocity limits.
//!
//! The file starts (its t = 0) when the first RTDE client connects, as a person starts
//! teaching once the recorder listens; until then the arm rests at the first row's pose.
//! While it plays ([`Player`]), the arm is where the file says at each arm cycle: the joint
//! angles linearly interpolated at the file time t, the joint velocities the slope of
//! the row interval containing t (what a person's hand does to the arm; the physics is not
//! stepped, as in freedrive the controller only follows). RTDE reports them as `actual_q`,
//! `actual_qd` and `target_q`, and the end-effector point of all six joints (shared forward
//! kinematics) as `actual_tcp_pose`. After the last row the arm holds the last pose, with
//! zero velocities, and every RTDE client is told so. A program's servo targets do not move
//! the arm while a playback is loaded (the person holds it).
//!
//! [`generate`] writes such files: human-like reaches from the start pose to a goal region
//! (`hil-sim playback-gen`).

use std::path::Path;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use ur5_shared::kinematics::{Joints6, UrKinematics};
use ur5_shared::layout::N_JOINTS;
use ur5_shared::UrModel;

/// The header every playback file starts with.
pub const HEADER: &str = "t,q0,q1,q2,q3,q4,q5";

/// Column names, in the header's order.
const COLUMNS: [&str; 7] = ["t", "q0", "q1", "q2", "q3", "q4", "q5"];

/// Smallest time between two rows (s): 1 kHz, above any arm's rate.
pub const MIN_ROW_STEP_S: f64 = 1e-3;

/// Largest time between two rows (s): 10 Hz. A pause is rows of the same pose; a longer gap
/// would interpolate a straight line through joint space no hand draws.
pub const MAX_ROW_STEP_S: f64 = 0.1;

/// What is wrong with a playback file.
#[derive(Debug, thiserror::Error)]
pub enum PlaybackError {
    /// The file cannot be read.
    #[error("cannot read playback file {path}: {source}")]
    Read {
        /// The file.
        path: String,
        /// I/O error.
        source: std::io::Error,
    },
    /// A line of the file is wrong.
    #[error("{path}: line {line}{}: {why}", column.map(|c| format!(", column {c}")).unwrap_or_default())]
    Line {
        /// The file.
        path: String,
        /// Line number (1 = the header).
        line: usize,
        /// Column name, if one is at fault.
        column: Option<&'static str>,
        /// What is wrong.
        why: String,
    },
    /// The playback cannot be generated.
    #[error("playback-gen: {0}")]
    Generate(String),
}

/// A checked playback: rows of (t, six joint angles).
#[derive(Clone, Debug, PartialEq)]
pub struct Playback {
    /// Arm time of each row (s), strictly increasing.
    pub t: Vec<f64>,
    /// Joint angles of each row (rad, base to wrist 3).
    pub q: Vec<Joints6>,
}

impl Playback {
    /// Reads and checks the file at `path` for `model` ([`Playback::parse`]).
    pub fn load(path: &Path, model: UrModel) -> Result<Self, PlaybackError> {
        let text = std::fs::read_to_string(path).map_err(|source| PlaybackError::Read {
            path: path.display().to_string(),
            source,
        })?;
        Self::parse(&text, &path.display().to_string(), model)
    }

    /// Parses and checks playback CSV `text` (named `path` in errors) for `model` (module
    /// docs). Empty lines are ignored.
    pub fn parse(text: &str, path: &str, model: UrModel) -> Result<Self, PlaybackError> {
        let err = |line: usize, column: Option<&'static str>, why: String| PlaybackError::Line {
            path: path.to_string(),
            line,
            column,
            why,
        };
        let mut lines = text.lines().enumerate();
        let header = lines
            .by_ref()
            .find(|(_, l)| !l.trim().is_empty())
            .map(|(i, l)| (i + 1, l));
        match header {
            Some((_, h)) if h.split(',').map(str::trim).eq(COLUMNS.iter().copied()) => {}
            Some((n, h)) => {
                return Err(err(
                    n,
                    None,
                    format!("header `{}`, expected `{HEADER}`", h.trim()),
                ))
            }
            None => return Err(err(1, None, format!("empty file; expected `{HEADER}`"))),
        }
        let limits = model.joint_limits();
        let (mut t, mut q): (Vec<f64>, Vec<Joints6>) = (Vec::new(), Vec::new());
        let mut prev_line = 0;
        for (i, line) in lines {
            let n = i + 1;
            if line.trim().is_empty() {
                continue;
            }
            let fields: Vec<&str> = line.split(',').map(str::trim).collect();
            if fields.len() != COLUMNS.len() {
                return Err(err(
                    n,
                    None,
                    format!("{} fields, expected 7 ({HEADER})", fields.len()),
                ));
            }
            let mut row = [0.0; 7];
            for (k, f) in fields.iter().enumerate() {
                let v: f64 = f
                    .parse()
                    .map_err(|_| err(n, Some(COLUMNS[k]), format!("`{f}` is not a number")))?;
                if !v.is_finite() {
                    return Err(err(n, Some(COLUMNS[k]), format!("{v} is not finite")));
                }
                row[k] = v;
            }
            let (time, angles): (f64, Joints6) = (row[0], row[1..].try_into().expect("six joints"));
            if let Some(&last) = t.last() {
                let step = time - last;
                if step <= 0.0 {
                    return Err(err(
                        n,
                        Some("t"),
                        format!(
                            "t = {time} s after t = {last} s (line {prev_line}): t must increase"
                        ),
                    ));
                }
                if !(MIN_ROW_STEP_S * (1.0 - 1e-9)..=MAX_ROW_STEP_S * (1.0 + 1e-9)).contains(&step)
                {
                    return Err(err(
                        n,
                        Some("t"),
                        format!(
                            "{step} s after the previous row (line {prev_line}): rows must be \
                             {MIN_ROW_STEP_S} to {MAX_ROW_STEP_S} s apart (1 kHz to 10 Hz); write \
                             a pause as rows of the same pose"
                        ),
                    ));
                }
                let before: &Joints6 = q.last().expect("a row per time");
                for j in 0..6 {
                    let speed = (angles[j] - before[j]).abs() / step;
                    if speed > limits.velocity[j] {
                        return Err(err(
                            n,
                            Some(COLUMNS[j + 1]),
                            format!(
                                "joint {j} moves at {speed:.3} rad/s since the previous row (line \
                                 {prev_line}), above the {model}'s limit {:.3} rad/s",
                                limits.velocity[j]
                            ),
                        ));
                    }
                }
            } else if time < 0.0 {
                return Err(err(
                    n,
                    Some("t"),
                    format!("t = {time} s: arm time starts at 0"),
                ));
            }
            for j in 0..6 {
                if !(angles[j] >= limits.lower[j] && angles[j] <= limits.upper[j]) {
                    return Err(err(
                        n,
                        Some(COLUMNS[j + 1]),
                        format!(
                            "joint {j} at {} rad, outside the {model}'s limits [{}, {}]",
                            angles[j], limits.lower[j], limits.upper[j]
                        ),
                    ));
                }
            }
            t.push(time);
            q.push(angles);
            prev_line = n;
        }
        if t.len() < 2 {
            return Err(err(
                prev_line.max(1),
                None,
                format!("{} rows: a playback needs at least 2", t.len()),
            ));
        }
        Ok(Self { t, q })
    }

    /// The file's text: the header and one row per sample, each number in Rust's shortest
    /// round-trip form (parsing it gives the same bits).
    pub fn to_csv(&self) -> String {
        let mut s = String::with_capacity(self.t.len() * 120);
        s.push_str(HEADER);
        s.push('\n');
        for (t, q) in self.t.iter().zip(&self.q) {
            s.push_str(&format!("{t:?}"));
            for v in q {
                s.push_str(&format!(",{v:?}"));
            }
            s.push('\n');
        }
        s
    }

    /// Duration (s): the last row's t.
    pub fn duration(&self) -> f64 {
        *self.t.last().expect("at least 2 rows")
    }

    /// Joint angles (rad) and velocities (rad/s) at arm time `time` (s): linear interpolation
    /// between rows, the slope of the row interval; before the first row its pose, after the
    /// last the last pose, at rest.
    pub fn at(&self, time: f64) -> (Joints6, Joints6) {
        let n = self.t.len();
        if time <= self.t[0] {
            return (self.q[0], [0.0; 6]);
        }
        if time >= self.t[n - 1] {
            return (self.q[n - 1], [0.0; 6]);
        }
        // The interval [t[k], t[k + 1]) containing `time`.
        let k = self.t.partition_point(|&x| x <= time) - 1;
        let (t0, t1) = (self.t[k], self.t[k + 1]);
        let w = (time - t0) / (t1 - t0);
        let (a, b) = (&self.q[k], &self.q[k + 1]);
        (
            core::array::from_fn(|j| a[j] + w * (b[j] - a[j])),
            core::array::from_fn(|j| (b[j] - a[j]) / (t1 - t0)),
        )
    }
}

/// A playback loaded into the arm: the file, the kinematics of the end-effector point, when
/// it started, and whether the end was announced.
pub struct Player {
    playback: Playback,
    kin: UrKinematics,
    /// The file's name, for messages.
    pub name: String,
    /// Whether the file has started ([`Player::start`]).
    started: bool,
    /// File time (s): the arm time the file has played for.
    file_s: f64,
    /// Arm time (s) of the last [`Player::start`] or [`Player::advance`].
    last: f64,
    /// Whether the arm is held (not RUNNING, or a stop in force): it rests where the file is.
    held: bool,
    ended: bool,
}

/// Where the arm is at one cycle of a playback.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlayedState {
    /// Joint angles (rad, six joints).
    pub q: Joints6,
    /// Joint velocities (rad/s).
    pub qd: Joints6,
    /// End-effector point (m, base frame).
    pub ee: [f64; 3],
    /// Its linear velocity (m/s).
    pub ee_vel: [f64; 3],
}

impl Player {
    /// Plays `playback` on `model` with the end-effector point `ee_offset` (m, flange frame).
    pub fn new(playback: Playback, model: UrModel, ee_offset: [f64; 3], name: String) -> Self {
        Self {
            playback,
            kin: UrKinematics::new(model, ee_offset),
            name,
            started: false,
            file_s: 0.0,
            last: 0.0,
            held: false,
            ended: false,
        }
    }

    /// Starts the file at arm time `time` (s), if not started yet: until then the arm rests at
    /// the first row's pose.
    pub fn start(&mut self, time: f64) {
        if !self.started {
            self.started = true;
            self.last = time;
        }
    }

    /// Arm time goes on to `time` (s): the file plays on only while `moves` (freedrive needs
    /// the arm powered, its brakes released and no stop in force); otherwise the arm holds
    /// where the file is.
    pub fn advance(&mut self, time: f64, moves: bool) {
        if self.started {
            if moves {
                self.file_s += time - self.last;
            }
            self.last = time;
        }
        self.held = !moves;
    }

    /// File time (s): before the start, before the first row.
    fn file_time(&self) -> f64 {
        if self.started {
            self.file_s
        } else {
            f64::NEG_INFINITY
        }
    }

    /// The first row's six joints (rad): where the arm starts.
    pub fn start_pose(&self) -> Joints6 {
        self.playback.q[0]
    }

    /// The arm now (at rest while it is held).
    pub fn state(&self) -> PlayedState {
        let (q, mut qd) = self.playback.at(self.file_time());
        if self.held {
            qd = [0.0; 6];
        }
        let (ee, ee_vel) = self.kin.ee_point_velocity(&q, &qd);
        PlayedState { q, qd, ee, ee_vel }
    }

    /// Once, when the file has played past its last row: the message that says so.
    pub fn end_message(&mut self) -> Option<String> {
        if self.ended || self.file_time() < self.playback.duration() {
            return None;
        }
        self.ended = true;
        Some(format!(
            "playback {} ended at t = {} s: the arm holds its last pose",
            self.name,
            self.playback.duration()
        ))
    }
}

/// Settings of [`generate`] (`hil-sim playback-gen`): seeded human-like reaches.
#[derive(Clone, Debug, PartialEq)]
pub struct GenConfig {
    /// The arm model (joint limits, kinematics).
    pub model: UrModel,
    /// Start pose of the three arm joints (rad).
    pub start_q: [f64; N_JOINTS],
    /// Wrist angles (rad, wrist 1–3): kept throughout for a point goal, the start pose's
    /// wrist for a pose goal.
    pub wrist_q: [f64; 3],
    /// End-effector offset (m, flange frame).
    pub ee_offset: [f64; 3],
    /// Centre of the goal region (m, base frame); for a pose goal, its position.
    pub goal: [f64; 3],
    /// A pose goal (UR's p[x, y, z, rx, ry, rz]: m, rotation vector, base frame): the whole
    /// arm reaches, all six joints moving and trembling, to the pose; each reach's tool point
    /// aims into the goal region around the pose's position, its orientation the pose's
    /// tilted by a seeded rotation of up to [`POSE_TILT_RAD`] about each base axis (joint goal
    /// by the inverse kinematics nearest the start pose). `None`: a point goal, the wrist kept
    /// at `wrist_q`.
    pub goal_pose: Option<[f64; 6]>,
    /// Half side of the cubic goal region (m): each reach aims at a point drawn uniformly in it.
    pub goal_half_side: f64,
    /// Number of reaches.
    pub motions: usize,
    /// Row rate of the file (Hz, 10 to 1000).
    pub rate_hz: f64,
    /// Seed.
    pub seed: u64,
}

/// A draw uniform in `[lo, hi)`.
pub(crate) fn uni(rng: &mut ChaCha8Rng, (lo, hi): (f64, f64)) -> f64 {
    lo + (hi - lo) * rng.random::<f64>()
}

/// A hand's tremor on `N` joints: two sinusoids per joint, each (amplitude [`TREMOR_RAD`] rad,
/// frequency in [`TREMOR_HZ`], phase in [0, 2π)), drawn joint by joint in that order.
pub(crate) fn tremor<const N: usize>(rng: &mut ChaCha8Rng) -> [[(f64, f64, f64); 2]; N] {
    core::array::from_fn(|_| {
        core::array::from_fn(|_| {
            (
                TREMOR_RAD,
                uni(rng, TREMOR_HZ),
                uni(rng, (0.0, std::f64::consts::TAU)),
            )
        })
    })
}

/// Duration of a reach (s), drawn uniformly: a person's unhurried reach of half a metre.
pub const REACH_S: (f64, f64) = (1.2, 2.0);
/// Rests (s): at the start pose before each reach and at the goal after it, each at least 1 s
/// (the recording rule's rest) plus a draw from this range.
pub const REST_EXTRA_S: (f64, f64) = (0.4, 0.9);
/// Overshoot of a reach past its target, as a fraction of the reach, then a corrective
/// submovement back of [`CORRECTION_S`].
pub const OVERSHOOT: (f64, f64) = (0.02, 0.06);
/// Duration of the corrective submovement (s).
pub const CORRECTION_S: (f64, f64) = (0.3, 0.5);
/// Tremor while the hand moves the arm: amplitude (rad) of each of two sinusoids of
/// physiological tremor frequency [`TREMOR_HZ`], faded in and out with the motion.
pub const TREMOR_RAD: f64 = 2e-4;
/// Frequency range of the tremor (Hz).
pub const TREMOR_HZ: (f64, f64) = (8.0, 12.0);
/// How far from the start pose a person puts the arm back (rad, each active joint, uniform).
pub const RETURN_SPREAD_RAD: f64 = 2e-3;
/// How far a person holding a tool at a pose misses its orientation (rad, the rotation
/// vector's component about each base axis, uniform): 0.17°, a tenth of a 10 cm tool's
/// 5 mm goal region.
pub const POSE_TILT_RAD: f64 = 3e-3;

/// The most rows a generated file may have (about 100 MB of CSV): 120 motions at 1 kHz, 1204
/// at the default 100 Hz.
pub const MAX_ROWS: usize = 1_000_000;

/// The longest a file of `motions` reaches can last (s): every draw at its maximum.
fn longest_s(motions: usize) -> f64 {
    let rest = 1.0 + REST_EXTRA_S.1;
    rest + motions as f64 * (2.0 * REACH_S.1 + CORRECTION_S.1 + 2.0 * rest)
}

/// Minimum-jerk profile s(τ) = 10τ³ − 15τ⁴ + 6τ⁵ on τ ∈ [0, 1] (Flash & Hogan 1985).
pub(crate) fn min_jerk(tau: f64) -> f64 {
    let t = tau.clamp(0.0, 1.0);
    t * t * t * (10.0 + t * (-15.0 + 6.0 * t))
}

/// The active joints (rad) that put the end-effector point at `target` (m): Newton's method
/// on the shared forward kinematics with a finite-difference Jacobian, from `guess`.
pub fn inverse_kinematics(
    kin: &UrKinematics,
    wrist: &[f64; 3],
    target: [f64; 3],
    guess: [f64; N_JOINTS],
) -> Option<[f64; N_JOINTS]> {
    let fk = |q: &[f64; 3]| kin.ee_point(&UrKinematics::six(q, wrist));
    let mut q = guess;
    for _ in 0..100 {
        let p = fk(&q);
        let e = [target[0] - p[0], target[1] - p[1], target[2] - p[2]];
        if e.iter().map(|v| v * v).sum::<f64>().sqrt() < 1e-10 {
            return Some(q);
        }
        let h = 1e-7;
        let mut jac = nalgebra::Matrix3::zeros();
        for c in 0..3 {
            let mut qh = q;
            qh[c] += h;
            let ph = fk(&qh);
            for r in 0..3 {
                jac[(r, c)] = (ph[r] - p[r]) / h;
            }
        }
        let dq = jac.lu().solve(&nalgebra::Vector3::from(e))?;
        for c in 0..3 {
            q[c] += dq[c].clamp(-0.2, 0.2);
        }
    }
    None
}

/// The joint angles (rad) that reach the UR5's default goal, the posture every model's
/// default goal comes from ([`UrModel::default_goal`]): the guess of the IK.
const GOAL_POSTURE: [f64; 3] = [0.293, -1.379, 2.092];

/// Generates `cfg.motions` reaches (module docs of `hil-sim playback-gen`): per motion, a
/// rest at the start pose, a minimum-jerk reach of seeded duration that overshoots its target
/// (a point of the goal region, or a pose there for [`GenConfig::goal_pose`], to joint space by
/// IK) by a seeded fraction, a corrective submovement back, a rest there, and a minimum-jerk
/// return to (near) the start pose; a final rest at the start. Tremor rides on the motions of
/// the moving joints (three, or six for a pose goal). The same settings give the same file, bit
/// for bit.
pub fn generate(cfg: &GenConfig) -> Result<Playback, PlaybackError> {
    let bad = |why: String| PlaybackError::Generate(why);
    if !(10.0..=1000.0).contains(&cfg.rate_hz) {
        return Err(bad(format!("--rate {} Hz: 10 to 1000", cfg.rate_hz)));
    }
    if cfg.motions == 0 {
        return Err(bad("--motions 0: at least 1".into()));
    }
    // Bounded before anything is allocated: the longest file these settings can give.
    let longest_s = longest_s(cfg.motions);
    if longest_s * cfg.rate_hz > MAX_ROWS as f64 {
        return Err(bad(format!(
            "--motions {} at --rate {} Hz: up to {:.0} rows ({longest_s:.0} s of reaches), more \
             than {MAX_ROWS}: fewer motions or a lower rate",
            cfg.motions,
            cfg.rate_hz,
            longest_s * cfg.rate_hz
        )));
    }
    let limits = cfg.model.joint_limits();
    let start = UrKinematics::six(&cfg.start_q, &cfg.wrist_q);
    // The joints the hand moves: the arm's three, or the whole arm for a pose goal.
    let n = if cfg.goal_pose.is_some() { 6 } else { 3 };
    for (j, &q) in start.iter().enumerate() {
        if !(q >= limits.lower[j] && q <= limits.upper[j]) {
            return Err(bad(format!(
                "the start pose's joint {j} ({}) at {q} rad is outside the {}'s limits \
                 [{}, {}] rad",
                if j < n { "task.start_q" } else { "sim.wrist_q" },
                cfg.model,
                limits.lower[j],
                limits.upper[j]
            )));
        }
    }
    if !(cfg.goal_half_side >= 0.0 && cfg.goal_half_side <= 0.1) {
        return Err(bad(format!(
            "goal region half side {} m: 0 to 0.1 m",
            cfg.goal_half_side
        )));
    }
    let centre = cfg.goal_pose.map_or(cfg.goal, |p| [p[0], p[1], p[2]]);
    let kin = UrKinematics::new(cfg.model, cfg.ee_offset);
    let ik = ur5_shared::ik::UrIk::new(cfg.model, cfg.ee_offset);
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    // Waypoints: (duration of the move to it, its six joints, whether a hand moves the arm).
    let mut segments: Vec<(f64, Joints6, bool)> = Vec::new();
    let rest = |rng: &mut ChaCha8Rng| 1.0 + uni(rng, REST_EXTRA_S);
    let mut here = start;
    segments.push((rest(&mut rng), here, false));
    for m in 0..cfg.motions {
        let h = cfg.goal_half_side;
        let target: [f64; 3] = core::array::from_fn(|k| centre[k] + uni(&mut rng, (-h, h)));
        let q_goal = match &cfg.goal_pose {
            None => inverse_kinematics(&kin, &cfg.wrist_q, target, GOAL_POSTURE)
                .map(|q| UrKinematics::six(&q, &cfg.wrist_q))
                .ok_or_else(|| {
                    bad(format!(
                        "motion {m}: no joint angles put the end effector at {target:?} m \
                         (outside the {}'s reach?)",
                        cfg.model
                    ))
                })?,
            Some(p) => {
                let tilt: [f64; 3] =
                    core::array::from_fn(|_| uni(&mut rng, (-POSE_TILT_RAD, POSE_TILT_RAD)));
                let goal = ur5_shared::pose::isometry(p);
                let pose = nalgebra::Isometry3::from_parts(
                    nalgebra::Translation3::from(nalgebra::Vector3::from(target)),
                    nalgebra::UnitQuaternion::from_scaled_axis(nalgebra::Vector3::from(tilt))
                        * goal.rotation,
                );
                ik.nearest_pose(&pose, &start).map_err(|e| {
                    bad(format!(
                        "motion {m}: no joint angles put the tool at p{:?} (m, rotation \
                         vector): {e}",
                        ur5_shared::pose::ur_pose(&pose)
                    ))
                })?
            }
        };
        let over = uni(&mut rng, OVERSHOOT);
        let past: Joints6 = core::array::from_fn(|j| q_goal[j] + over * (q_goal[j] - here[j]));
        segments.push((uni(&mut rng, REACH_S), past, true));
        segments.push((uni(&mut rng, CORRECTION_S), q_goal, true));
        segments.push((rest(&mut rng), q_goal, false));
        let mut back = start;
        for b in back.iter_mut().take(n) {
            *b += uni(&mut rng, (-RETURN_SPREAD_RAD, RETURN_SPREAD_RAD));
        }
        segments.push((uni(&mut rng, REACH_S), back, true));
        segments.push((rest(&mut rng), back, false));
        here = back;
    }
    // Two tremor sinusoids per moving joint.
    let tremor: Vec<[(f64, f64, f64); 2]> = if n == 6 {
        tremor::<6>(&mut rng).to_vec()
    } else {
        tremor::<3>(&mut rng).to_vec()
    };
    let dt = 1.0 / cfg.rate_hz;
    let (mut t, mut q) = (Vec::new(), Vec::new());
    let mut from = start;
    let mut t0 = 0.0;
    let mut row: u64 = 0;
    for &(dur, to, moving) in &segments {
        let end = t0 + dur;
        loop {
            let time = row as f64 * dt;
            if time >= end {
                break;
            }
            let s = min_jerk((time - t0) / dur);
            // The tremor fades in and out with the motion (sin² envelope), so rests are still.
            let env = if moving {
                (std::f64::consts::PI * (time - t0) / dur).sin().powi(2)
            } else {
                0.0
            };
            t.push(time);
            q.push(core::array::from_fn(|j| {
                if j >= n {
                    return from[j];
                }
                let tr: f64 = tremor[j]
                    .iter()
                    .map(|(a, f, p)| a * (std::f64::consts::TAU * f * time + p).sin())
                    .sum();
                (from[j] + s * (to[j] - from[j]) + env * tr).clamp(limits.lower[j], limits.upper[j])
            }));
            row += 1;
        }
        from = to;
        t0 = end;
    }
    // The last row at the end of the final rest.
    t.push(row as f64 * dt);
    q.push(from);
    let p = Playback { t, q };
    // What the generator writes, `--playback` takes.
    Playback::parse(&p.to_csv(), "generated", cfg.model)?;
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gen(seed: u64) -> GenConfig {
        let m = UrModel::Ur5e;
        GenConfig {
            model: m,
            start_q: m.default_start_q(),
            wrist_q: m.default_wrist_q(),
            ee_offset: [0.0; 3],
            goal: m.default_goal(),
            goal_pose: None,
            goal_half_side: 0.005,
            motions: 3,
            rate_hz: 100.0,
            seed,
        }
    }

    /// Settings that would allocate without bound, and a start pose outside the limits, are
    /// refused before anything is generated, naming the setting.
    #[test]
    fn generation_is_bounded_and_names_a_bad_start_pose() {
        let e = generate(&GenConfig {
            motions: 200_000,
            rate_hz: 1000.0,
            ..gen(1)
        })
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("--motions 200000") && e.contains("fewer motions"),
            "{e}"
        );
        let longest = longest_s(120) * 1000.0;
        assert!(longest <= MAX_ROWS as f64 && longest_s(121) * 1000.0 > MAX_ROWS as f64);
        let mut far = gen(1);
        far.start_q[2] = 7.0;
        let e = generate(&far).unwrap_err().to_string();
        assert!(
            e.contains("joint 2 (task.start_q) at 7 rad") && e.contains("ur5e's limits"),
            "{e}"
        );
        assert!(!e.contains("line"), "{e}");
    }

    #[test]
    fn each_bad_file_is_refused_naming_line_and_column() {
        let m = UrModel::Ur5e;
        let ok = "t,q0,q1,q2,q3,q4,q5\n0,0,-2,2.4,-1.57,1.57,0\n0.01,0,-2,2.4,-1.57,1.57,0\n";
        let p = Playback::parse(ok, "f.csv", m).unwrap();
        assert_eq!(p.t, vec![0.0, 0.01]);
        let cases = [
            ("t,q0,q1\n0,0,0\n", "line 1: header `t,q0,q1`"),
            (
                "t,q0,q1,q2,q3,q4,q5\n0,0,-2,2.4,-1.57,1.57,0\n0.01,0,x,2.4,-1.57,1.57,0\n",
                "line 3, column q1: `x` is not a number",
            ),
            (
                "t,q0,q1,q2,q3,q4,q5\n0,0,-2,2.4,-1.57,1.57,0\n0.01,0,-2,NaN,-1.57,1.57,0\n",
                "line 3, column q2: NaN is not finite",
            ),
            (
                "t,q0,q1,q2,q3,q4,q5\n0.02,0,-2,2.4,-1.57,1.57,0\n0.01,0,-2,2.4,-1.57,1.57,0\n",
                "line 3, column t: t = 0.01 s after t = 0.02 s (line 2): t must increase",
            ),
            (
                "t,q0,q1,q2,q3,q4,q5\n0,0,-2,2.4,-1.57,1.57,0\n0.5,0,-2,2.4,-1.57,1.57,0\n",
                "line 3, column t: 0.5 s after the previous row",
            ),
            (
                "t,q0,q1,q2,q3,q4,q5\n0,0,-2,3.5,-1.57,1.57,0\n",
                "line 2, column q2: joint 2 at 3.5 rad, outside the ur5e's limits",
            ),
            (
                "t,q0,q1,q2,q3,q4,q5\n0,0,-2,2.4,-1.57,1.57,0\n0.01,0.1,-2,2.4,-1.57,1.57,0\n",
                "line 3, column q0: joint 0 moves at 10.000 rad/s",
            ),
            (
                "t,q0,q1,q2,q3,q4,q5\n0,0,-2,2.4,-1.57,1.57\n",
                "line 2: 6 fields, expected 7",
            ),
            (
                "t,q0,q1,q2,q3,q4,q5\n0,0,-2,2.4,-1.57,1.57,0\n",
                "1 rows: a playback needs at least 2",
            ),
        ];
        for (text, want) in cases {
            let e = Playback::parse(text, "f.csv", m).unwrap_err().to_string();
            assert!(e.contains(want) && e.starts_with("f.csv: "), "{want}: {e}");
        }
    }

    #[test]
    fn playback_interpolates_and_holds_the_last_pose() {
        let text = "t,q0,q1,q2,q3,q4,q5\n0,0,-2,2,0,0,0\n0.1,0.1,-2,2,0,0,0.2\n";
        let p = Playback::parse(text, "f", UrModel::Ur5).unwrap();
        let (q, qd) = p.at(0.05);
        assert!((q[0] - 0.05).abs() < 1e-15 && (q[5] - 0.1).abs() < 1e-15);
        assert!((qd[0] - 1.0).abs() < 1e-12 && (qd[5] - 2.0).abs() < 1e-12);
        assert_eq!(p.at(5.0), (p.q[1], [0.0; 6]));
        let mut player = Player::new(p, UrModel::Ur5, [0.0; 3], "f".into());
        player.advance(3.0, true);
        assert_eq!(
            player.state().q,
            player.playback.q[0],
            "waits for its start"
        );
        assert_eq!(player.end_message(), None);
        player.start(1.0);
        player.start(2.0);
        player.advance(1.05, true);
        assert!(
            (player.state().q[0] - 0.05).abs() < 1e-12,
            "started once, at 1 s"
        );
        assert_eq!(player.end_message(), None);
        // Held (powered off, braked, stopped): the file waits, the arm rests.
        player.advance(1.5, false);
        assert!((player.state().q[0] - 0.05).abs() < 1e-12);
        assert_eq!(player.state().qd, [0.0; 6]);
        assert_eq!(player.end_message(), None);
        player.advance(1.525, true);
        assert!((player.state().q[0] - 0.075).abs() < 1e-12, "plays on");
        player.advance(1.575, true);
        assert!(player
            .end_message()
            .unwrap()
            .contains("holds its last pose"));
        assert_eq!(player.end_message(), None, "said once");
    }

    #[test]
    fn the_generator_is_seeded_valid_and_reaches_the_goal_region() {
        let a = generate(&gen(4)).unwrap();
        assert_eq!(
            a.to_csv(),
            generate(&gen(4)).unwrap().to_csv(),
            "same seed, same file"
        );
        assert_ne!(a.to_csv(), generate(&gen(5)).unwrap().to_csv());
        let parsed = Playback::parse(&a.to_csv(), "g", UrModel::Ur5e).unwrap();
        assert_eq!(parsed, a, "the CSV round-trips bit for bit");
        let c = gen(4);
        // Starts and ends at rest at the start pose for more than 1 s.
        let start6 = UrKinematics::six(&c.start_q, &c.wrist_q);
        let rows_1s = 100;
        assert!(a.q[..rows_1s].iter().all(|q| *q == start6));
        let end = &a.q[a.q.len() - rows_1s..];
        assert!(end.iter().all(|q| q == end.last().unwrap()));
        assert!((0..3).all(|j| (end[0][j] - c.start_q[j]).abs() <= RETURN_SPREAD_RAD));
        // Passes through the goal region: the poses closest to the goal are within it.
        let kin = UrKinematics::new(c.model, c.ee_offset);
        let dist: Vec<f64> =
            a.q.iter()
                .map(|q| {
                    let p = kin.ee_point(q);
                    (0..3)
                        .map(|k| (p[k] - c.goal[k]).powi(2))
                        .sum::<f64>()
                        .sqrt()
                })
                .collect();
        let near = dist
            .iter()
            .filter(|d| **d < 0.005 * 3f64.sqrt() + 1e-3)
            .count();
        assert!(
            near > 3 * 100,
            "about a second at each of 3 goals: {near} rows"
        );
    }

    /// A pose goal: the whole arm reaches, the wrist moving and trembling too; every reach
    /// comes to rest with the tool within the goal region around the pose's position and
    /// within the tilt of its orientation; the file is seeded and valid; a pose out of reach
    /// is refused naming the motion.
    #[test]
    fn pose_reaches_move_the_whole_arm_to_the_pose() {
        let m = UrModel::Ur5e;
        // The flange pose of q = (0.293, −1.379, 2.092, −1.9, 1.3, 0.4) rad.
        let kin = UrKinematics::new(m, [0.0; 3]);
        let goal_q = [0.293, -1.379, 2.092, -1.9, 1.3, 0.4];
        let goal = ur5_shared::pose::ur_pose(&kin.tool_pose(&goal_q));
        let c = GenConfig {
            goal_pose: Some(goal),
            ..gen(2)
        };
        let a = generate(&c).unwrap();
        assert_eq!(a, generate(&c).unwrap(), "same seed, same file");
        assert_eq!(Playback::parse(&a.to_csv(), "g", m).unwrap(), a);
        let start = UrKinematics::six(&c.start_q, &c.wrist_q);
        assert!(a.q[..100].iter().all(|q| *q == start));
        // The rests away from the start: runs of at least 1 s of one pose.
        let mut rests = Vec::new();
        let mut k = 0;
        while k < a.q.len() {
            let run = a.q[k..].iter().take_while(|q| **q == a.q[k]).count();
            if run >= 100 && (0..6).any(|j| (a.q[k][j] - start[j]).abs() > 0.1) {
                rests.push(a.q[k]);
            }
            k += run;
        }
        assert_eq!(rests.len(), 3, "one rest at the goal per reach");
        let target = ur5_shared::pose::isometry(&goal);
        for q in &rests {
            // The wrist moved from the start pose to the pose's.
            assert!((3..6).all(|j| (q[j] - goal_q[j]).abs() < 0.05), "{q:?}");
            let p = kin.tool_pose(q);
            let d = p.translation.vector - target.translation.vector;
            assert!(d.amax() <= c.goal_half_side + 1e-9, "{d}");
            let tilt = p.rotation.angle_to(&target.rotation);
            assert!(tilt <= 3f64.sqrt() * POSE_TILT_RAD + 1e-9, "{tilt} rad");
        }
        // The wrist trembles while the hand moves it.
        let wobble = a.q.windows(3).any(|w| {
            let acc = w[2][5] - 2.0 * w[1][5] + w[0][5];
            w[0][5] != w[1][5] && acc.abs() > 1e-6
        });
        assert!(wobble, "wrist 3 moves and trembles");
        let far = GenConfig {
            goal_pose: Some([2.0, 0.0, 0.3, 0.0, 3.1, 0.0]),
            ..c
        };
        let e = generate(&far).unwrap_err().to_string();
        assert!(
            e.contains("motion 0: no joint angles put the tool at"),
            "{e}"
        );
    }

    #[test]
    fn the_ik_inverts_the_forward_kinematics() {
        for m in UrModel::ALL {
            let kin = UrKinematics::new(m, [0.0; 3]);
            let w = m.default_wrist_q();
            let q = inverse_kinematics(&kin, &w, m.default_goal(), GOAL_POSTURE).unwrap();
            let p = kin.ee_point(&UrKinematics::six(&q, &w));
            let e = (0..3)
                .map(|k| (p[k] - m.default_goal()[k]).powi(2))
                .sum::<f64>();
            assert!(e.sqrt() < 1e-9, "{m}: {p:?}");
        }
    }
}
