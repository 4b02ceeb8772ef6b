//! The arm's motion to the last bit: every model at three and six active joints, seeded
//! servo goals, the multibody stepped alone and through rapier's whole pipeline, and the
//! perturbed and torque-mode arms that fall back to the pipeline. Every state bit of every
//! physics step (joint angles and velocities, the applied torques, the flange's pose, the
//! gravity torques read from the body Jacobians, the observation) goes into a digest.
//!
//! The three-joint digests below were recorded from the code before the speed-up of the
//! multibody's mass matrix and step (docs/design.md §5 D38), the six-joint ones when six
//! joints moved to the articulated-body algorithm (D43): work on the step may make it faster,
//! but the test fails if any bit of any trajectory moves. A change meant to alter the physics
//! must say so and record new digests.

use hil_sim::Ur5Sim;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use ur5_shared::config::{ActionMode, Perturbation, SimConfig, TaskConfig};
use ur5_shared::UrModel;

/// Word-wise FNV-1a over 64-bit words: enough to see any bit move.
struct Digest(u64);

impl Digest {
    fn new() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }

    fn add(&mut self, values: &[f64]) {
        for v in values {
            self.0 = (self.0 ^ v.to_bits()).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
}

/// Physics steps per run: 3 s at the configuration's 1 ms step.
const STEPS: usize = 3000;
/// A new goal every this many physics steps (the paper's 0.1 s control period).
const HOLD: usize = 100;

/// Runs `STEPS` physics steps of `cfg`'s arm with `joints` active joints from the task's start,
/// one action per physics step (a new seeded goal, or torque, every `HOLD` steps), and returns
/// the digest of every state bit after every step and the step counts (alone, pipeline).
fn run(cfg: &SimConfig, joints: usize, pipeline_only: bool) -> (u64, (u64, u64)) {
    let task = TaskConfig::for_model(cfg.model);
    let mut sim = Ur5Sim::with_joints(cfg.clone(), cfg.physics_dt, joints).unwrap();
    sim.set_pipeline_only(pipeline_only);
    sim.reseed(3);
    let wrist = sim.model().wrist_q;
    let s = task.start_q;
    let start = [s[0], s[1], s[2], wrist[0], wrist[1], wrist[2]];
    sim.reset_all(&start[..joints], task.goal).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    let mut digest = Digest::new();
    let mut action = start;
    for k in 0..STEPS {
        if k % HOLD == 0 {
            action = match cfg.mode {
                ActionMode::GoalAngles => core::array::from_fn(|j| {
                    let l = sim.model().joint(j.min(joints - 1));
                    // Every fourth goal at a joint limit, the others inside the limits.
                    match (k / HOLD) % 4 {
                        3 if j < joints => l.upper,
                        _ => rng.random_range(l.lower.max(-3.1)..l.upper.min(3.1)),
                    }
                }),
                // Spin the elbow past its limit, the other joints held loosely.
                ActionMode::Torque => core::array::from_fn(|j| match j {
                    1 => -60.0 + 5.0 * rng.random::<f64>(),
                    2 if k < STEPS / 2 => 40.0,
                    2 => -5.0,
                    _ => rng.random_range(-1.0..1.0),
                }),
            };
        }
        let o = sim.step_all(&action[..joints]);
        let (q, qd) = sim.joint_state_all();
        let pose = sim.ee_frame_pose();
        let (t, r) = (pose.translation, pose.rotation);
        digest.add(&q);
        digest.add(&qd);
        digest.add(&sim.last_torque_all());
        digest.add(&sim.gravity_torque_all());
        digest.add(&[t.x, t.y, t.z, r.w, r.i, r.j, r.k]);
        digest.add(&o.q);
        digest.add(&o.qd);
        digest.add(&o.ee_pos);
        digest.add(&o.ee_vel);
    }
    (digest.0, sim.step_counts())
}

/// The nominal arm of every model, at three and six joints, 1 ms steps, one substep.
const NOMINAL: [(UrModel, u64, u64); 13] = [
    (UrModel::Ur3, 0xdc917754589b628a, 0xf616eccb8c01203e),
    (UrModel::Ur5, 0x00d36d2ac06010cc, 0x2eed8fb23e2f95a7),
    (UrModel::Ur10, 0x06227719afcfd410, 0x668b47c5e54795a3),
    (UrModel::Ur3e, 0x2ab17e2e98f2dc9f, 0xe01fb716edae9ad0),
    (UrModel::Ur5e, 0xde943a05708b1cfa, 0xe9acf88ffdfb3ca7),
    (UrModel::Ur7e, 0x20752f16b5b04cd4, 0xd3b4d4490ee0fd78),
    (UrModel::Ur10e, 0xbcdedfe5856f6c18, 0x0b66fe5ce4cc41f4),
    (UrModel::Ur12e, 0xbcdedfe5856f6c18, 0x0b66fe5ce4cc41f4),
    (UrModel::Ur16e, 0xb277c32b89c7f96a, 0x6c5865310c691bbb),
    (UrModel::Ur15, 0xabd5a07a5df7c1bb, 0x0f35734c7991bec4),
    (UrModel::Ur18, 0x348494296a647aa5, 0xf066d58073558528),
    (UrModel::Ur20, 0x29434ad0c4fec5ce, 0xdcde8929ce8fb2c5),
    (UrModel::Ur30, 0xd39e866bdde490d5, 0x27246fbfbb59a1ad),
];

/// Same bits as before the speed-up, and the same bits alone and through the pipeline; a
/// line for the report when the digest moved. `direct`: whether the multibody may step alone
/// (the pipeline then steps only while a joint constraint acts).
fn check(
    name: &str,
    cfg: &SimConfig,
    joints: usize,
    expected: u64,
    direct: bool,
) -> Option<String> {
    let (through_pipeline, (alone, _)) = run(cfg, joints, true);
    assert_eq!(alone, 0, "{name}, {joints} joints: pipeline only");
    let (fast, (alone, pipeline)) = run(cfg, joints, false);
    assert_eq!(
        fast, through_pipeline,
        "{name}, {joints} joints: the direct step's bits differ from the pipeline's"
    );
    assert_eq!(
        alone > 0,
        direct,
        "{name}, {joints} joints: {alone} steps alone"
    );
    if cfg.mode == ActionMode::Torque {
        assert!(
            pipeline > 0,
            "{name}, {joints} joints: the elbow limit never acted"
        );
    }
    (fast != expected)
        .then(|| format!("{name}, {joints} joints: {fast:#018x}, recorded {expected:#018x}"))
}

#[test]
fn every_bit_of_the_nominal_arms_motion_is_as_recorded() {
    let mut wrong = Vec::new();
    for (model, three, six) in NOMINAL {
        let cfg = SimConfig {
            substeps: 1,
            ..SimConfig::for_model(model)
        };
        wrong.extend(check(model.name(), &cfg, 3, three, true));
        wrong.extend(check(model.name(), &cfg, 6, six, true));
    }
    assert!(wrong.is_empty(), "digests moved:\n{}", wrong.join("\n"));
}

/// The UR5e and UR10 perturbed (damping, heavier links, actuator noise, latency), with two
/// substeps, with dry friction (every step through the pipeline), and in torque mode driven
/// through the elbow's limit (the pipeline while the limit acts): (name, model, joints, digest).
const PERTURBED: [(&str, UrModel, usize, u64); 16] = [
    ("damped", UrModel::Ur5e, 3, 0x592e76ea448f484e),
    ("damped", UrModel::Ur5e, 6, 0xf0590af786529d44),
    ("damped", UrModel::Ur10, 3, 0x9261be11ddb26da4),
    ("damped", UrModel::Ur10, 6, 0x2e06ee5fd2c2ee73),
    ("two substeps", UrModel::Ur5e, 3, 0x1ae24a7fd70ae12c),
    ("two substeps", UrModel::Ur5e, 6, 0xfb8a80e724d97124),
    ("two substeps", UrModel::Ur10, 3, 0x9b45bac681a8cf87),
    ("two substeps", UrModel::Ur10, 6, 0x3b60ce9149ec10de),
    ("dry friction", UrModel::Ur5e, 3, 0xd3618beac2990aee),
    ("dry friction", UrModel::Ur5e, 6, 0x5eca112f42de7af4),
    ("dry friction", UrModel::Ur10, 3, 0xc0b309ca44ada454),
    ("dry friction", UrModel::Ur10, 6, 0x388a133084253609),
    ("torque", UrModel::Ur5e, 3, 0x499c4178adf51feb),
    ("torque", UrModel::Ur5e, 6, 0x5b59bb36ffa4898a),
    ("torque", UrModel::Ur10, 3, 0x8a09e35c171b9410),
    ("torque", UrModel::Ur10, 6, 0xd2646757335558f2),
];

#[test]
fn every_bit_of_the_perturbed_arms_motion_is_as_recorded() {
    let mut wrong = Vec::new();
    for (name, model, joints, expected) in PERTURBED {
        let nominal = SimConfig {
            substeps: 1,
            ..SimConfig::for_model(model)
        };
        let (cfg, direct) = match name {
            "damped" => (
                SimConfig {
                    perturbation: Perturbation {
                        joint_friction: [0.0; 3],
                        ..Perturbation::physical_stand_in(5)
                    },
                    ..nominal
                },
                true,
            ),
            "two substeps" => (
                SimConfig {
                    substeps: 2,
                    ..nominal
                },
                true,
            ),
            "dry friction" => (
                SimConfig {
                    perturbation: Perturbation::physical_stand_in(5),
                    ..nominal
                },
                false,
            ),
            _ => (
                SimConfig {
                    mode: ActionMode::Torque,
                    ..nominal
                },
                true,
            ),
        };
        wrong.extend(check(name, &cfg, joints, expected, direct));
    }
    assert!(wrong.is_empty(), "digests moved:\n{}", wrong.join("\n"));
}
