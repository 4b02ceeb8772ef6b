//! Behaviour of the simulated arm: kinematics against the UR5 DH table, the servo, the
//! perturbation knobs, and clear errors on bad input.

use hil_sim::{Observation, SimError, Ur5Sim};
use nalgebra::{Matrix4, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use ur5_shared::config::{ActionMode, Perturbation, SimConfig, TaskConfig};
use ur5_shared::layout::{EE_MINUS_GOAL, EE_VEL, Q, QD};

/// Universal Robots' published UR5 (CB3) standard DH table: (a, d, α) per joint.
const UR5_DH: [(f64, f64, f64); 6] = [
    (0.0, 0.089159, std::f64::consts::FRAC_PI_2),
    (-0.425, 0.0, 0.0),
    (-0.39225, 0.0, 0.0),
    (0.0, 0.10915, std::f64::consts::FRAC_PI_2),
    (0.0, 0.09465, -std::f64::consts::FRAC_PI_2),
    (0.0, 0.0823, 0.0),
];

/// Flange position from standard DH: T = Π Rz(θ) Tz(d) Tx(a) Rx(α).
fn dh_fk(theta: [f64; 6]) -> Vector3<f64> {
    let mut t = Matrix4::identity();
    for (i, &(a, d, alpha)) in UR5_DH.iter().enumerate() {
        let (st, ct) = theta[i].sin_cos();
        let (sa, ca) = alpha.sin_cos();
        #[rustfmt::skip]
        let ti = Matrix4::new(
            ct, -st * ca,  st * sa, a * ct,
            st,  ct * ca, -ct * sa, a * st,
            0.0,      sa,       ca,      d,
            0.0,     0.0,      0.0,    1.0,
        );
        t *= ti;
    }
    Vector3::new(t[(0, 3)], t[(1, 3)], t[(2, 3)])
}

fn random_q(rng: &mut ChaCha8Rng) -> [f64; 3] {
    [
        rng.random_range(-3.0..3.0),
        rng.random_range(-3.0..0.0),
        rng.random_range(-2.8..2.8),
    ]
}

#[test]
fn end_effector_matches_ur5_dh_forward_kinematics() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for wrist_q in [
        [
            -std::f64::consts::FRAC_PI_2,
            std::f64::consts::FRAC_PI_2,
            0.0,
        ],
        [0.3, -0.7, 1.1],
    ] {
        let cfg = SimConfig {
            wrist_q,
            ..SimConfig::default()
        };
        let mut sim = Ur5Sim::new(cfg, 0.1).unwrap();
        let mut worst = 0.0f64;
        for _ in 0..25 {
            let q = random_q(&mut rng);
            sim.set_joint_state(q, [0.0; 3]);
            let ee = sim.true_observation().ee_pos;
            let dh = dh_fk([q[0], q[1], q[2], wrist_q[0], wrist_q[1], wrist_q[2]]);
            let err = (Vector3::from(ee) - dh).norm();
            worst = worst.max(err);
        }
        eprintln!("wrist {wrist_q:?}: max |ee − DH FK| = {worst:.3e} m");
        assert!(
            worst <= 1e-6,
            "wrist {wrist_q:?}: max |ee − DH FK| = {worst:.3e} m > 1e-6 m"
        );
    }
}

/// The f64 chain the `ur` controller backend uses (`ur5_shared::kinematics`) against the rapier3d
/// multibody: the end-effector point and its velocity, with an ee offset and two wrist poses.
#[test]
fn shared_kinematics_match_the_simulated_arm() {
    use ur5_shared::kinematics::UrKinematics;
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for (wrist_q, ee_offset) in [
        (SimConfig::default().wrist_q, [0.0; 3]),
        ([0.3, -0.7, 1.1], [0.02, -0.01, 0.05]),
    ] {
        let cfg = SimConfig {
            wrist_q,
            ee_offset,
            ..SimConfig::default()
        };
        let kin = UrKinematics::new(ur5_shared::UrModel::Ur5, ee_offset);
        let mut sim = Ur5Sim::new(cfg, 0.1).unwrap();
        let (mut worst_p, mut worst_v) = (0.0f64, 0.0f64);
        for _ in 0..25 {
            let q = random_q(&mut rng);
            let qd = [
                rng.random_range(-2.0..2.0),
                rng.random_range(-2.0..2.0),
                rng.random_range(-2.0..2.0),
            ];
            sim.set_joint_state(q, qd);
            let o = sim.true_observation();
            let (p, v) = kin.ee_point_velocity(
                &UrKinematics::six(&o.q, &wrist_q),
                &UrKinematics::six(&o.qd, &[0.0; 3]),
            );
            worst_p = worst_p.max((Vector3::from(p) - Vector3::from(o.ee_pos)).norm());
            worst_v = worst_v.max((Vector3::from(v) - Vector3::from(o.ee_vel)).norm());
        }
        eprintln!(
            "wrist {wrist_q:?}, offset {ee_offset:?}: |Δp| {worst_p:.2e} m, |Δv| {worst_v:.2e} m/s"
        );
        assert!(worst_p <= 1e-6, "|Δp| = {worst_p:.3e} m");
        // rapier's Jacobian is f32: 1e-5 m/s at speeds of a few m/s.
        assert!(worst_v <= 1e-4, "|Δv| = {worst_v:.3e} m/s");
    }
}

#[test]
fn state_vector_follows_the_layout() {
    let mut sim = Ur5Sim::new(SimConfig::default(), 0.1).unwrap();
    let task = TaskConfig::default();
    sim.reset(task.start_arm_joints(), task.goal).unwrap();
    let obs = sim.step([0.3, -1.5, 1.9]);
    let s = obs.state(&task.goal);
    assert_eq!(&s[Q], &obs.q);
    assert_eq!(&s[QD], &obs.qd);
    assert_eq!(&s[EE_VEL], &obs.ee_vel);
    for (k, i) in EE_MINUS_GOAL.enumerate() {
        assert_eq!(s[i], obs.ee_pos[k] - task.goal[k]);
    }
}

/// A step of Δ rad must be reached within the time a velocity-limited, effort-limited move
/// takes: Δ / v_max at cruise, plus the time to accelerate to v_max and to settle (≤ 0.6 s for
/// this servo's 0.1 s position-loop time constant: ln(Δ·ω_p/tol)/ω_p ≈ 0.6 s for 5 mrad).
#[test]
fn servo_reaches_goal_within_velocity_limit_time_and_respects_effort() {
    let task = TaskConfig::default();
    let cfg = SimConfig::default();
    let v_max = cfg.servo.max_velocity;
    let mut sim = Ur5Sim::new(cfg, task.dt).unwrap();
    let start = [0.0, -1.6, 1.6];
    for (j, delta) in [(0usize, 1.2f64), (1, 0.8), (2, -1.0), (1, -0.6)] {
        sim.reset(start, task.goal).unwrap();
        let mut goal = start;
        goal[j] += delta;
        let allowed = delta.abs() / v_max + 0.3 + 0.6;
        let mut reached_at = None;
        let mut max_speed = 0.0f64;
        for k in 1..=40 {
            let obs = sim.step(goal);
            max_speed = max_speed.max(obs.qd[j].abs());
            let err = (0..3)
                .map(|i| (obs.q[i] - goal[i]).abs())
                .fold(0.0, f64::max);
            if reached_at.is_none() && err < 5e-3 {
                reached_at = Some(k as f64 * task.dt);
            }
        }
        let reached = reached_at
            .unwrap_or_else(|| panic!("joint {j}: goal {goal:?} never reached within 4 s"));
        assert!(
            reached <= allowed + 1e-9,
            "joint {j} Δ {delta}: reached after {reached:.2} s > allowed {allowed:.2} s"
        );
        assert!(
            max_speed <= v_max * 1.05,
            "joint {j}: speed {max_speed:.3} rad/s beyond the limit {v_max:.3}"
        );
        let effort = sim
            .model()
            .active
            .iter()
            .map(|l| l.effort)
            .collect::<Vec<_>>();
        for (i, t) in sim.max_abs_torque().iter().enumerate() {
            assert!(
                *t <= effort[i],
                "joint {i}: |τ| {t} N·m beyond effort limit {}",
                effort[i]
            );
        }
    }
    // A far goal saturates at least one joint's effort and still never exceeds it.
    sim.reset([0.0, -2.0, 2.4], task.goal).unwrap();
    sim.step([2.0, -0.5, -0.5]);
    let tau = sim.max_abs_torque();
    assert!(
        (tau[1] - 150.0).abs() < 1e-9,
        "shoulder lift should saturate at 150 N·m, got {tau:?}"
    );
}

#[test]
fn servo_holds_a_pose_without_sag() {
    let task = TaskConfig::default();
    let mut sim = Ur5Sim::new(SimConfig::default(), task.dt).unwrap();
    // Arm stretched out horizontally: the largest gravity load.
    let q = [0.0, 0.0, 0.0];
    sim.reset(q, task.goal).unwrap();
    let mut obs = sim.step(q);
    for _ in 0..20 {
        obs = sim.step(q);
    }
    let sag = (0..3).map(|j| (obs.q[j] - q[j]).abs()).fold(0.0, f64::max);
    assert!(sag < 1e-3, "servo sags {sag:.2e} rad at full reach");
}

#[test]
fn torque_mode_clamps_to_effort_limits() {
    let cfg = SimConfig {
        mode: ActionMode::Torque,
        ..SimConfig::default()
    };
    let task = TaskConfig::default();
    let mut sim = Ur5Sim::new(cfg, task.dt).unwrap();
    sim.reset(task.start_arm_joints(), task.goal).unwrap();
    sim.step([500.0, -500.0, 20.0]);
    assert_eq!(sim.last_torque(), [150.0, -150.0, 20.0]);
}

fn run_perturbed(seed: u64) -> Vec<[f64; 12]> {
    let task = TaskConfig::default();
    let cfg = SimConfig {
        perturbation: Perturbation::physical_stand_in(seed),
        ..SimConfig::default()
    };
    let mut sim = Ur5Sim::new(cfg, task.dt).unwrap();
    let mut out = Vec::new();
    for episode in 0..2 {
        sim.reset(task.start_arm_joints(), task.goal).unwrap();
        for t in 0..15 {
            let x = (t + episode) as f64 * 0.1;
            out.push(
                sim.step([0.3 * x.sin(), -1.8 + 0.2 * x, 2.0])
                    .state(&task.goal),
            );
        }
    }
    out
}

#[test]
fn perturbation_with_fixed_seed_replays_bit_for_bit() {
    let a = run_perturbed(42);
    let b = run_perturbed(42);
    let bits = |v: &Vec<[f64; 12]>| {
        v.iter()
            .flat_map(|s| s.iter().map(|x| x.to_bits()))
            .collect::<Vec<_>>()
    };
    assert_eq!(bits(&a), bits(&b), "same seed must give the same run");
    let c = run_perturbed(43);
    assert_ne!(
        bits(&a),
        bits(&c),
        "another seed must give another run (noise is on)"
    );
}

#[test]
fn perturbations_change_the_dynamics() {
    let task = TaskConfig::default();
    let run = |p: Perturbation| {
        let mut sim = Ur5Sim::new(
            SimConfig {
                perturbation: p,
                ..SimConfig::default()
            },
            task.dt,
        )
        .unwrap();
        sim.reset(task.start_arm_joints(), task.goal).unwrap();
        let mut o = sim.step([0.5, -1.2, 1.5]);
        for _ in 0..3 {
            o = sim.step([0.5, -1.2, 1.5]);
        }
        o.q
    };
    let nominal = run(Perturbation::default());
    let heavy = run(Perturbation {
        mass_scale: 1.5,
        ..Perturbation::default()
    });
    let damped = run(Perturbation {
        joint_damping: [30.0; 3],
        ..Perturbation::default()
    });
    let late = run(Perturbation {
        latency_steps: 1,
        ..Perturbation::default()
    });
    for (name, q) in [("mass", heavy), ("damping", damped), ("latency", late)] {
        let d = (0..3)
            .map(|j| (q[j] - nominal[j]).abs())
            .fold(0.0, f64::max);
        assert!(
            d > 1e-4,
            "{name} perturbation had no visible effect ({d:.2e} rad)"
        );
    }
}

#[test]
fn non_finite_actions_hold_the_previous_goal() {
    let task = TaskConfig::default();
    let mut sim = Ur5Sim::new(SimConfig::default(), task.dt).unwrap();
    sim.reset(task.start_arm_joints(), task.goal).unwrap();
    let obs = sim.step([f64::NAN, 0.0, 0.0]);
    assert!(
        obs.q
            .iter()
            .zip(task.start_arm_joints())
            .all(|(q, q0)| (q - q0).abs() < 1e-3),
        "{:?}",
        obs.q
    );
}

#[test]
fn bad_inputs_give_clear_errors() {
    let task = TaskConfig::default();
    // Missing file.
    let cfg = SimConfig {
        urdf: Some("/nonexistent/ur5.urdf".into()),
        ..SimConfig::default()
    };
    let e = Ur5Sim::new(cfg, 0.1).err().expect("missing URDF must fail");
    assert!(matches!(e, SimError::UrdfRead { .. }), "{e}");
    assert!(e.to_string().contains("/nonexistent/ur5.urdf"), "{e}");

    // Malformed XML.
    let dir = std::env::temp_dir().join(format!("hil-sim-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.urdf");
    std::fs::write(&bad, "<robot name=\"x\"><link name=\"a\"></robot>").unwrap();
    let e = Ur5Sim::new(
        SimConfig {
            urdf: Some(bad.clone()),
            ..SimConfig::default()
        },
        0.1,
    )
    .err()
    .unwrap();
    assert!(matches!(e, SimError::UrdfParse { .. }), "{e}");

    // Unknown joint name: rename the elbow.
    let renamed = dir.join("renamed.urdf");
    std::fs::write(
        &renamed,
        hil_sim::model::BUNDLED_URDF.replace("\"elbow_joint\"", "\"elbow\""),
    )
    .unwrap();
    let e = Ur5Sim::new(
        SimConfig {
            urdf: Some(renamed),
            ..SimConfig::default()
        },
        0.1,
    )
    .err()
    .unwrap();
    assert!(
        matches!(e, SimError::UnknownJoint { ref name, .. } if name == "elbow_joint"),
        "{e}"
    );

    // Unknown end-effector link.
    let e = Ur5Sim::new(
        SimConfig {
            ee_link: "tool9".into(),
            ..SimConfig::default()
        },
        0.1,
    )
    .err()
    .unwrap();
    assert!(matches!(e, SimError::UnknownLink { .. }), "{e}");

    // Goal outside reach, non-finite goal, start pose beyond a joint limit.
    let mut sim = Ur5Sim::new(SimConfig::default(), task.dt).unwrap();
    let e = sim
        .reset(task.start_arm_joints(), [2.0, 0.0, 0.5])
        .unwrap_err();
    assert!(matches!(e, SimError::GoalOutOfReach { .. }), "{e}");
    assert!(sim
        .reset(task.start_arm_joints(), [f64::NAN, 0.0, 0.5])
        .is_err());
    let e = sim.reset([0.0, -1.0, 3.5], task.goal).unwrap_err();
    assert!(matches!(e, SimError::OutOfLimits { .. }), "{e}");

    // Control period not a multiple of the physics step.
    assert!(Ur5Sim::new(SimConfig::default(), 0.1005).is_err());
    std::fs::remove_dir_all(&dir).ok();
}

/// Each malformed arm description is refused with a message that
/// names the problem, never a panic, an abort or a silently wrong model.
#[test]
fn malformed_urdfs_are_refused_naming_the_problem() {
    use hil_sim::model::{ArmModel, BUNDLED_URDF};
    let load = |text: &str| {
        ArmModel::from_str(
            text,
            "test.urdf".into(),
            SimConfig::default().wrist_q,
            &SimConfig::default().ee_link,
            [0.0; 3],
        )
    };
    load(BUNDLED_URDF).unwrap();
    let u = BUNDLED_URDF;
    let nested = format!(
        "<robot name=\"x\">{}{}</robot>",
        "<a>".repeat(200_000),
        "</a>".repeat(200_000)
    );
    let second_base = u.replacen(
        "<link name=\"shoulder_link\">",
        "<link name=\"base_link\"><inertial><mass value=\"1\"/><inertia ixx=\"1\" ixy=\"0\" ixz=\"0\" iyy=\"1\" iyz=\"0\" izz=\"1\"/></inertial></link>\n  <link name=\"shoulder_link\">",
        1,
    );
    let cases: Vec<(&str, String)> = vec![
        ("nested 200001 deep", nested),
        ("`base_link`: defined twice", second_base),
        (
            "`elbow_joint`: its child link `forearm` is not defined",
            u.replacen(
                "<child link=\"forearm_link\"/>",
                "<child link=\"forearm\"/>",
                1,
            ),
        ),
        (
            "already the child of another joint",
            u.replacen(
                "<child link=\"forearm_link\"/>",
                "<child link=\"upper_arm_link\"/>",
                1,
            ),
        ),
        ("hang from no joint", {
            let a = u.find("<joint name=\"wrist_3_joint\"").unwrap();
            let b = a + u[a..].find("</joint>").unwrap() + "</joint>".len();
            format!("{}{}", &u[..a], &u[b..])
        }),
        (
            "origin xyz [NaN",
            u.replacen("<origin xyz=\"-0.425 0 0\"", "<origin xyz=\"NaN 0 0\"", 1),
        ),
        (
            "axis [0.0, 0.0, 0.0] must be finite and non-zero",
            u.replacen("<axis xyz=\"0 0 1\"/>", "<axis xyz=\"0 0 0\"/>", 1),
        ),
        (
            "mass 1e30 kg",
            u.replacen("<mass value=\"8.393\"/>", "<mass value=\"1e30\"/>", 1),
        ),
        (
            "each at most the sum of the other two",
            u.replacen("ixx=\"0.0151074\"", "ixx=\"5.0\"", 1),
        ),
    ];
    for (what, text) in cases {
        let e = load(&text).expect_err(what).to_string();
        assert!(e.contains(what), "{what}: {e}");
    }
}

/// An episode (reset, then a sequence of actions) on an arm with any history gives the same
/// bits as on a new arm and on a `fresh` copy: reset restarts the physics from the built
/// world, and `reseed` restarts the perturbation noise (docs/design.md §5 D29). What makes
/// episodes of one iteration safe to run in parallel.
/// The bits of q, q̇, end-effector position and velocity, in that order.
fn observation_bits(o: &Observation) -> Vec<u64> {
    o.q.iter()
        .chain(&o.qd)
        .chain(&o.ee_pos)
        .chain(&o.ee_vel)
        .map(|v| v.to_bits())
        .collect()
}

#[test]
fn an_episode_does_not_depend_on_the_arm_history() {
    let task = TaskConfig::default();
    let episode = |sim: &mut Ur5Sim| -> Vec<u64> {
        sim.reseed(7);
        let mut bits = Vec::new();
        let o = sim.reset(task.start_arm_joints(), task.goal).unwrap();
        bits.extend(o.q.iter().chain(&o.ee_pos).map(|v| v.to_bits()));
        for k in 0..15 {
            let a = [0.1 * k as f64, -1.5 + 0.02 * k as f64, 1.8];
            bits.extend(observation_bits(&sim.step(a)));
        }
        bits
    };
    for perturbation in [Perturbation::default(), Perturbation::physical_stand_in(3)] {
        let cfg = SimConfig {
            perturbation,
            ..SimConfig::default()
        };
        let nominal = cfg.perturbation.is_nominal();
        let mut new = Ur5Sim::new(cfg.clone(), task.dt).unwrap();
        let reference = episode(&mut new);
        // History: another episode from another pose with other actions and noise.
        let mut used = Ur5Sim::new(cfg, task.dt).unwrap();
        used.reset([0.4, -1.2, 1.3], task.goal).unwrap();
        for k in 0..12 {
            used.step([0.5, -1.0 - 0.05 * k as f64, 1.0]);
        }
        let mut fresh = used.fresh();
        assert_eq!(episode(&mut used), reference, "after another episode");
        assert_eq!(episode(&mut used), reference, "run twice");
        assert_eq!(episode(&mut fresh), reference, "on a fresh copy");
        // Another stream draws other noise, so the test sees the perturbation noise.
        if !nominal {
            fresh.reseed(8);
            let o = fresh.reset(task.start_arm_joints(), task.goal).unwrap();
            assert_ne!(
                o.q[0].to_bits(),
                reference[0],
                "another stream, other noise"
            );
        }
    }
}

/// docs/design.md §5 D30: the multibody stepped alone (vendored rapier's `Multibody::step_alone`)
/// gives the same bits as rapier's whole pipeline step, on the nominal arm, with damping, mass
/// scale, noise and latency, with two solver substeps, and across the fallback to the pipeline
/// when a joint goes beyond its limit (torque mode) or has dry friction (the physical stand-in).
#[test]
fn the_direct_step_equals_the_pipeline_step() {
    let task = TaskConfig::default();
    let damped = Perturbation {
        joint_friction: [0.0; 3],
        ..Perturbation::physical_stand_in(5)
    };
    let cases = [
        ("nominal", SimConfig::default(), true),
        (
            "damped, heavier, noisy, late",
            SimConfig {
                perturbation: damped,
                ..SimConfig::default()
            },
            true,
        ),
        (
            "two substeps",
            SimConfig {
                substeps: 2,
                ..SimConfig::default()
            },
            true,
        ),
        (
            "dry friction",
            SimConfig {
                perturbation: Perturbation::physical_stand_in(5),
                ..SimConfig::default()
            },
            false,
        ),
        (
            "torque mode through the elbow limit",
            SimConfig {
                mode: ActionMode::Torque,
                ..SimConfig::default()
            },
            true,
        ),
    ];
    for (name, cfg, direct) in cases {
        let torque = cfg.mode == ActionMode::Torque;
        let run = |pipeline_only: bool| -> (Vec<u64>, (u64, u64)) {
            let mut sim = Ur5Sim::new(cfg.clone(), task.dt).unwrap();
            sim.set_pipeline_only(pipeline_only);
            let mut rng = ChaCha8Rng::seed_from_u64(11);
            let mut bits = Vec::new();
            for episode in 0..2 {
                sim.reseed(episode);
                sim.reset(task.start_arm_joints(), task.goal).unwrap();
                for k in 0..30 {
                    let a = if torque {
                        // Spin the elbow past +π (its limit), everything else held loosely.
                        [
                            0.0,
                            -60.0 + 5.0 * rng.random::<f64>(),
                            if k < 20 { 40.0 } else { -5.0 },
                        ]
                    } else {
                        let mut q = random_q(&mut rng);
                        // Every fifth goal at a joint limit.
                        if k % 5 == 4 {
                            q[2] = std::f64::consts::PI;
                        }
                        q
                    };
                    bits.extend(observation_bits(&sim.step(a)));
                    bits.extend(sim.last_torque().map(f64::to_bits));
                }
            }
            (bits, sim.step_counts())
        };
        let (pipeline, (alone, _)) = run(true);
        assert_eq!(alone, 0, "{name}: pipeline only");
        let (fast, (alone, through_pipeline)) = run(false);
        assert_eq!(fast, pipeline, "{name}: the bits differ");
        if direct {
            assert!(alone > 0, "{name}: the direct step never ran");
        } else {
            assert_eq!(alone, 0, "{name}: dry friction needs the solver");
        }
        if torque {
            assert!(through_pipeline > 0, "{name}: the elbow limit never acted");
        }
    }
}
