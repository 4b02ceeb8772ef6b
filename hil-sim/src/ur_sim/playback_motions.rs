//! Any motion taught by hand: given joint paths (a drawn shape, a stroke, a way around
//! something) played as a person would move the arm through them in freedrive, one after
//! another, each between two rests (docs/ur.md, "Teaching a motion by hand").
//!
//! [`play_motions`] writes a playback file ([`super::playback`]) from motions given as joint
//! paths (e.g. a tool path through the inverse kinematics, `learner dataset playback`): per
//! motion, a rest at its first pose, the motion at its own pace, a rest at its last pose, and a
//! minimum-jerk return by hand to the next motion's first pose (after the last, to the first
//! motion's), then a final rest there. The rests are those of [`super::playback::generate`]'s
//! reaches (at least the recording rule's 1 s plus a seeded draw), and the same tremor rides on
//! everything the hand moves, faded in and out with each movement, so the rests are still. The
//! same motions and seed give the same file, bit for bit.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use ur5_shared::kinematics::Joints6;
use ur5_shared::UrModel;

use super::playback::{
    min_jerk, tremor, uni, Playback, PlaybackError, MAX_ROWS, REACH_S, REST_EXTRA_S,
};

/// One motion as joint paths: sample times (s, strictly increasing, from any origin) and the
/// six joint angles there (rad); the file interpolates linearly between samples.
#[derive(Clone, Debug, PartialEq)]
pub struct Motion {
    /// Sample times (s).
    pub t: Vec<f64>,
    /// Joint angles at each sample (rad, base to wrist 3).
    pub q: Vec<Joints6>,
}

/// Settings of [`play_motions`].
#[derive(Clone, Debug, PartialEq)]
pub struct MotionsConfig {
    /// The arm model (joint limits and velocity limits the file is checked against).
    pub model: UrModel,
    /// The motions, in the order they are taught.
    pub motions: Vec<Motion>,
    /// Row rate of the file (Hz, 10 to 1000).
    pub rate_hz: f64,
    /// Seed of the rests' lengths, the returns' durations and the tremor.
    pub seed: u64,
}

/// The fraction of a joint's velocity limit a return by hand may reach at its fastest (a
/// minimum-jerk movement's peak speed is 1.875 times its mean).
const RETURN_SPEED_FRACTION: f64 = 0.5;

/// What the hand does over one stretch of the file.
enum Stretch {
    /// Holds the arm still at a pose.
    Rest(Joints6),
    /// Moves it by a minimum-jerk movement from one pose to another.
    Return(Joints6, Joints6),
    /// Moves it along motion `i`.
    Along(usize),
}

/// The playback of `cfg.motions` taught by hand (module docs).
pub fn play_motions(cfg: &MotionsConfig) -> Result<Playback, PlaybackError> {
    let bad = |why: String| PlaybackError::Generate(why);
    if !(10.0..=1000.0).contains(&cfg.rate_hz) {
        return Err(bad(format!("--rate {} Hz: 10 to 1000", cfg.rate_hz)));
    }
    if cfg.motions.is_empty() {
        return Err(bad("no motions to play".into()));
    }
    for (i, m) in cfg.motions.iter().enumerate() {
        if m.t.len() < 2 || m.t.len() != m.q.len() {
            return Err(bad(format!(
                "motion {i}: {} times and {} poses; a motion needs at least 2 of each, as many \
                 times as poses",
                m.t.len(),
                m.q.len()
            )));
        }
        if let Some(k) = (1..m.t.len()).find(|&k| !(m.t[k] > m.t[k - 1])) {
            return Err(bad(format!(
                "motion {i}: sample {k} at t = {} s after {} s: times must increase",
                m.t[k],
                m.t[k - 1]
            )));
        }
        if m.q.iter().flatten().any(|v| !v.is_finite()) {
            return Err(bad(format!("motion {i}: a joint angle is not finite")));
        }
    }
    let limits = cfg.model.joint_limits();
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let rest = |rng: &mut ChaCha8Rng| 1.0 + uni(rng, REST_EXTRA_S);
    // A return's duration: a person's unhurried movement, slower if the way is long.
    let return_s = |rng: &mut ChaCha8Rng, a: &Joints6, b: &Joints6| {
        let needed = (0..6)
            .map(|j| 1.875 * (b[j] - a[j]).abs() / (RETURN_SPEED_FRACTION * limits.velocity[j]))
            .fold(0.0, f64::max);
        uni(rng, REACH_S).max(needed)
    };
    let first = |i: usize| cfg.motions[i].q[0];
    let last = |i: usize| *cfg.motions[i].q.last().expect("2 samples");
    let mut stretches: Vec<(f64, Stretch)> = vec![(rest(&mut rng), Stretch::Rest(first(0)))];
    for i in 0..cfg.motions.len() {
        let m = &cfg.motions[i];
        stretches.push((m.t[m.t.len() - 1] - m.t[0], Stretch::Along(i)));
        stretches.push((rest(&mut rng), Stretch::Rest(last(i))));
        let next = first((i + 1) % cfg.motions.len());
        stretches.push((
            return_s(&mut rng, &last(i), &next),
            Stretch::Return(last(i), next),
        ));
        stretches.push((rest(&mut rng), Stretch::Rest(next)));
    }
    // Bounded before the rows are allocated.
    let total_s: f64 = stretches.iter().map(|(d, _)| d).sum();
    if total_s * cfg.rate_hz > MAX_ROWS as f64 {
        return Err(bad(format!(
            "{total_s:.0} s of motions and rests at --rate {} Hz: {:.0} rows, more than \
             {MAX_ROWS}: fewer or shorter motions, or a lower rate",
            cfg.rate_hz,
            total_s * cfg.rate_hz
        )));
    }
    // Two tremor sinusoids per joint.
    let tremor: [_; 6] = tremor(&mut rng);
    let dt = 1.0 / cfg.rate_hz;
    let (mut t, mut q) = (Vec::new(), Vec::new());
    let (mut t0, mut row) = (0.0, 0u64);
    for (dur, what) in &stretches {
        let end = t0 + dur;
        loop {
            let time = row as f64 * dt;
            if time >= end {
                break;
            }
            let tau = (time - t0) / dur;
            let (pose, moving) = match what {
                Stretch::Rest(p) => (*p, false),
                Stretch::Return(a, b) => {
                    let s = min_jerk(tau);
                    (core::array::from_fn(|j| a[j] + s * (b[j] - a[j])), true)
                }
                Stretch::Along(i) => {
                    let m = &cfg.motions[*i];
                    (along(m, m.t[0] + (time - t0)), true)
                }
            };
            // The tremor fades in and out with each movement (sin² envelope).
            let env = if moving {
                (std::f64::consts::PI * tau).sin().powi(2)
            } else {
                0.0
            };
            t.push(time);
            q.push(core::array::from_fn(|j| {
                let tr: f64 = tremor[j]
                    .iter()
                    .map(|(a, f, p)| a * (std::f64::consts::TAU * f * time + p).sin())
                    .sum();
                (pose[j] + env * tr).clamp(limits.lower[j], limits.upper[j])
            }));
            row += 1;
        }
        t0 = end;
    }
    // The last row at the end of the final rest.
    t.push(row as f64 * dt);
    q.push(first(0));
    let p = Playback { t, q };
    // What is written, `--playback` takes: the limits and joint speeds checked, row by row.
    Playback::parse(&p.to_csv(), "the motions' playback", cfg.model)?;
    Ok(p)
}

/// The joints of motion `m` at its time `time` (s), linearly interpolated; its ends outside.
fn along(m: &Motion, time: f64) -> Joints6 {
    let n = m.t.len();
    if time <= m.t[0] {
        return m.q[0];
    }
    if time >= m.t[n - 1] {
        return m.q[n - 1];
    }
    let k = m.t.partition_point(|&x| x <= time) - 1;
    let w = (time - m.t[k]) / (m.t[k + 1] - m.t[k]);
    core::array::from_fn(|j| m.q[k][j] + w * (m.q[k + 1][j] - m.q[k][j]))
}

#[cfg(test)]
mod tests {
    use super::super::playback::TREMOR_RAD;
    use super::*;

    /// A 2 s arc of the three arm joints from `from` (wrist fixed), sampled every 0.05 s: the
    /// base turns by `turn` (rad), the shoulder bends by `bend` on the way.
    fn arc(from: Joints6, turn: f64, bend: f64) -> Motion {
        let t: Vec<f64> = (0..=40).map(|k| 10.0 + k as f64 * 0.05).collect();
        let q = t
            .iter()
            .map(|&x| {
                let s = (x - 10.0) / 2.0;
                let mut q = from;
                q[0] += turn * s;
                q[1] += bend * (std::f64::consts::PI * s).sin();
                q[2] -= 0.2 * s;
                q
            })
            .collect();
        Motion { t, q }
    }

    fn cfg(seed: u64) -> MotionsConfig {
        let m = UrModel::Ur5;
        let mut start = [0.0; 6];
        start[..3].copy_from_slice(&m.default_start_q());
        start[3..].copy_from_slice(&m.default_wrist_q());
        MotionsConfig {
            model: m,
            motions: vec![arc(start, 0.3, 0.1), arc(start, 0.25, -0.05)],
            rate_hz: 100.0,
            seed,
        }
    }

    /// Each motion is played at its own pace between rests of at least 1 s at its ends, the
    /// arm is put back to the next start between them, the file is seeded and `--playback`
    /// takes it.
    #[test]
    fn motions_are_played_between_rests_at_their_pace() {
        let c = cfg(3);
        let p = play_motions(&c).unwrap();
        assert_eq!(p, play_motions(&cfg(3)).unwrap(), "same seed, same file");
        assert_ne!(p, play_motions(&cfg(4)).unwrap());
        assert_eq!(Playback::parse(&p.to_csv(), "g", c.model).unwrap(), p);
        let start = c.motions[0].q[0];
        let rows_1s = 100;
        assert!(p.q[..rows_1s].iter().all(|q| *q == start));
        assert_eq!(*p.q.last().unwrap(), start, "ends where it started");
        // The first motion's end is held still for at least 1 s, then left.
        let end0 = *c.motions[0].q.last().unwrap();
        let held: Vec<usize> = (0..p.q.len()).filter(|&k| p.q[k] == end0).collect();
        assert!(held.len() >= rows_1s, "{} rows at the end pose", held.len());
        let (a, b) = (held[0], *held.last().unwrap());
        assert_eq!(b - a + 1, held.len(), "one rest");
        // The motion itself: from the first rest's end to the second rest, 2 s at 100 Hz
        // (rows at the grid's times), within the tremor of the given path.
        let onset = p.q.iter().position(|q| *q != start).unwrap();
        assert!(
            (a - onset) as f64 >= 199.0 && (a - onset) as f64 <= 201.0,
            "{onset} {a}"
        );
        for k in onset..a {
            let want = along(&c.motions[0], 10.0 + p.t[k] - p.t[onset - 1]);
            let off = (0..6)
                .map(|j| (p.q[k][j] - want[j]).abs())
                .fold(0.0, f64::max);
            assert!(off <= 2.0 * TREMOR_RAD + 0.005, "row {k}: {off}");
        }
        // The second motion starts from a rest at its first pose after the return.
        let second = c.motions[1].q[0];
        let rest2 = (b..p.q.len()).filter(|&k| p.q[k] == second).count();
        assert!(rest2 >= rows_1s, "{rest2}");
    }

    #[test]
    fn bad_motions_are_refused_naming_them() {
        let mut c = cfg(1);
        c.motions[1].t[5] = c.motions[1].t[4];
        let e = play_motions(&c).unwrap_err().to_string();
        assert!(
            e.contains("motion 1: sample 5") && e.contains("must increase"),
            "{e}"
        );
        let mut c = cfg(1);
        c.motions[0].q.pop();
        let e = play_motions(&c).unwrap_err().to_string();
        assert!(e.contains("motion 0: 41 times and 40 poses"), "{e}");
        // Too fast for the arm: the file's check names the row and the joint.
        let mut c = cfg(1);
        for (k, t) in c.motions[0].t.iter_mut().enumerate() {
            *t = 10.0 + k as f64 * 1e-3;
        }
        let e = play_motions(&c).unwrap_err().to_string();
        assert!(
            e.contains("joint 0 moves at") && e.contains("ur5's limit"),
            "{e}"
        );
        let e = play_motions(&MotionsConfig {
            motions: vec![],
            ..cfg(1)
        })
        .unwrap_err()
        .to_string();
        assert!(e.contains("no motions"), "{e}");
    }
}
