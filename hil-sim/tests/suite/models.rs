//! Every UR model's bundled URDF (docs/ur.md, "Arm models"): the committed files are what the
//! generator writes, each URDF's forward kinematics is its model's DH table, and the simulator
//! built from each gives the DH flange, the shared kinematics, Newton–Euler accelerations, a
//! servo that holds the arm stretched out, and each model's default task.

use hil_sim::urdf::{bundled_urdf, bundled_urdf_path, write_urdf};
use hil_sim::Ur5Sim;
use nalgebra::{Isometry3, Matrix4, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use ur5_shared::config::{ArmLimits, ServoConfig, SimConfig, TaskConfig};
use ur5_shared::kinematics::UrKinematics;
use ur5_shared::UrModel;

use crate::dynamics::{random_q, Arm};

/// The flange's pose from UR's DH convention, T = Π Rz(θ_i) Tz(d_i) Tx(a_i) Rx(α_i), entry by
/// entry.
pub(crate) fn dh_pose(model: UrModel, q: &[f64; 6]) -> Matrix4<f64> {
    let t = model.dh();
    let mut m = Matrix4::identity();
    for i in 0..6 {
        let (st, ct) = q[i].sin_cos();
        let (sa, ca) = t.alpha[i].sin_cos();
        #[rustfmt::skip]
        let ti = Matrix4::new(
            ct, -st * ca,  st * sa, t.a[i] * ct,
            st,  ct * ca, -ct * sa, t.a[i] * st,
            0.0,      sa,       ca,      t.d[i],
            0.0,     0.0,      0.0,         1.0,
        );
        m *= ti;
    }
    m
}

/// The flange's position from UR's DH convention ([`dh_pose`]).
fn dh_flange(model: UrModel, q: &[f64; 6]) -> Vector3<f64> {
    dh_pose(model, q).fixed_view::<3, 1>(0, 3).into_owned()
}

/// The pose of `wrist_3_link` from the URDF text alone: each joint's origin (xyz, then
/// rpy = Rz·Ry·Rx), then its rotation about its axis, base to wrist 3.
fn urdf_flange(text: &str, q: &[f64; 6]) -> Isometry3<f64> {
    let robot = urdf_rs::read_from_string(text).expect("the URDF parses");
    let names = [
        "shoulder_pan_joint",
        "shoulder_lift_joint",
        "elbow_joint",
        "wrist_1_joint",
        "wrist_2_joint",
        "wrist_3_joint",
    ];
    let mut t = Isometry3::identity();
    for (k, name) in names.iter().enumerate() {
        let j = robot.joints.iter().find(|j| j.name == *name).expect(name);
        let [r, p, y] = j.origin.rpy.0;
        let origin = Isometry3::from_parts(
            Translation3::from(Vector3::from(j.origin.xyz.0)),
            UnitQuaternion::from_euler_angles(r, p, y),
        );
        let axis = nalgebra::Unit::new_normalize(Vector3::from(j.axis.xyz.0));
        let rot = Isometry3::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_axis_angle(&axis, q[k]),
        );
        t = t * origin * rot;
    }
    t
}

#[test]
fn the_committed_urdfs_are_what_the_generator_writes() {
    let update = std::env::var_os("UPDATE_URDF").is_some();
    for model in UrModel::ALL {
        if model == UrModel::Ur5 {
            continue; // hand-written; checked against the generator below
        }
        let want = write_urdf(model);
        let path = bundled_urdf_path(model);
        if update {
            std::fs::write(&path, &want).unwrap();
            eprintln!("wrote {}", path.display());
            continue;
        }
        assert!(
            bundled_urdf(model) == want,
            "{} is stale: rewrite it with UPDATE_URDF=1 and this test",
            path.display()
        );
    }
}

/// The hand-written UR5 file is the generator's UR5 to its rounding (6 significant digits in
/// the moving links' inertias, 3 in the fixed base's; every other number equal).
#[test]
fn the_hand_written_ur5_is_the_generators_ur5() {
    let hand = urdf_rs::read_from_string(bundled_urdf(UrModel::Ur5)).unwrap();
    let generated = urdf_rs::read_from_string(&write_urdf(UrModel::Ur5)).unwrap();
    assert_eq!(hand.joints.len(), generated.joints.len());
    for (h, g) in hand.joints.iter().zip(&generated.joints) {
        assert_eq!(h.name, g.name);
        assert_eq!(h.origin.xyz.0, g.origin.xyz.0, "{}", h.name);
        assert_eq!(h.origin.rpy.0, g.origin.rpy.0, "{}", h.name);
        let (hl, gl) = (&h.limit, &g.limit);
        assert_eq!(
            [hl.lower, hl.upper, hl.effort, hl.velocity],
            [gl.lower, gl.upper, gl.effort, gl.velocity],
            "{}",
            h.name
        );
    }
    for (h, g) in hand.links.iter().zip(&generated.links) {
        let rel = if h.name == "base_link" { 1e-3 } else { 1e-5 };
        let close = |a: f64, b: f64| (a - b).abs() <= rel * a.abs().max(b.abs());
        assert_eq!(h.name, g.name);
        let (hi, gi) = (&h.inertial, &g.inertial);
        assert_eq!(hi.mass.value, gi.mass.value, "{}", h.name);
        assert_eq!(hi.origin.xyz.0, gi.origin.xyz.0, "{}", h.name);
        let (a, b) = (&hi.inertia, &gi.inertia);
        for (x, y) in [
            (a.ixx, b.ixx),
            (a.ixy, b.ixy),
            (a.ixz, b.ixz),
            (a.iyy, b.iyy),
            (a.iyz, b.iyz),
            (a.izz, b.izz),
        ] {
            assert!(close(x, y), "{}: {x} vs {y}", h.name);
        }
    }
}

/// Each URDF's flange against its model's DH table: position (m) and orientation (rad; the
/// frames coincide, ‖R − R_dh‖_F = 2√2 sin(θ/2)).
#[test]
fn every_urdfs_flange_is_its_models_dh_flange() {
    let mut rng = ChaCha8Rng::seed_from_u64(270);
    for model in UrModel::ALL {
        let text = bundled_urdf(model);
        let (mut worst, mut worst_angle) = (0.0f64, 0.0f64);
        for _ in 0..100 {
            let q: [f64; 6] = core::array::from_fn(|_| rng.random_range(-3.1..3.1));
            let (u, d) = (urdf_flange(text, &q), dh_pose(model, &q));
            worst = worst.max((u.translation.vector - dh_flange(model, &q)).norm());
            let dr =
                (u.rotation.to_rotation_matrix().into_inner() - d.fixed_view::<3, 3>(0, 0)).norm();
            worst_angle = worst_angle.max(2.0 * (dr / (2.0 * std::f64::consts::SQRT_2)).asin());
        }
        eprintln!(
            "{model}: max |URDF flange − DH flange| = {worst:.2e} m, angle {worst_angle:.2e} rad"
        );
        assert!(worst <= 1e-6, "{model}: {worst:.3e} m");
        assert!(worst_angle <= 1e-6, "{model}: {worst_angle:.3e} rad");
    }
}

#[test]
fn every_simulated_model_gives_the_dh_flange_and_the_shared_kinematics() {
    let mut rng = ChaCha8Rng::seed_from_u64(271);
    for model in UrModel::ALL {
        for (wrist_q, ee_offset) in [
            (model.default_wrist_q(), [0.0; 3]),
            ([0.3, -0.7, 1.1], [0.02, -0.01, 0.05]),
        ] {
            let cfg = SimConfig {
                wrist_q,
                ee_offset,
                ..SimConfig::for_model(model)
            };
            let mut sim = Ur5Sim::new(cfg, 0.1).unwrap();
            let kin = UrKinematics::new(model, ee_offset);
            let (mut worst_dh, mut worst_kin) = (0.0f64, 0.0f64);
            for _ in 0..25 {
                let q = random_q(&mut rng, &sim);
                sim.set_joint_state(q, [0.0; 3]);
                let ee = Vector3::from(sim.true_observation().ee_pos);
                let six = UrKinematics::six(&q, &wrist_q);
                if ee_offset == [0.0; 3] {
                    worst_dh = worst_dh.max((ee - dh_flange(model, &six)).norm());
                }
                worst_kin = worst_kin.max((ee - Vector3::from(kin.ee_point(&six))).norm());
            }
            eprintln!("{model} wrist {wrist_q:?}: |ee − DH| {worst_dh:.2e} m, |ee − shared| {worst_kin:.2e} m");
            // rapier is f32: its rounding grows with the arm's size (the UR5's 1e-6 m at 0.85 m
            // reach, ≈ 2e-6 m at the UR20's 1.8 m).
            let tol = 1e-6 * (model.reach() / UrModel::Ur5.reach()).max(1.0);
            assert!(
                worst_dh <= tol && worst_kin <= tol,
                "{model}: {worst_dh:.3e} / {worst_kin:.3e} m > {tol:.1e} m"
            );
        }
    }
}

/// rapier's accelerations against the f64 Newton–Euler reference of each URDF, at 0.1 ms (the
/// UR5's own check, `joint_accelerations_match_newton_euler`, with torques scaled to the
/// model's effort limits).
#[test]
fn every_models_accelerations_match_newton_euler() {
    let mut rng = ChaCha8Rng::seed_from_u64(272);
    for model in UrModel::ALL {
        let cfg = SimConfig {
            physics_dt: 1e-4,
            substeps: 1,
            ..SimConfig::for_model(model)
        };
        let arm = Arm::of(bundled_urdf(model), cfg.wrist_q);
        let mut sim = Ur5Sim::new(cfg, 1e-4).unwrap();
        let effort = ArmLimits::for_model(model).effort;
        let mut worst = 0.0f64;
        for _ in 0..20 {
            let q = random_q(&mut rng, &sim);
            let qd = [0, 1, 2].map(|_| rng.random_range(-1.5..1.5));
            let tau = [0, 1, 2].map(|j| rng.random_range(-0.25..0.25) * effort[j]);
            sim.set_joint_state(q, qd);
            let (q, qd) = sim.joint_state();
            let a_sim = sim.joint_acceleration(q, qd, tau);
            let a_ref = arm.forward(&q, &qd, &tau);
            let scale = a_ref.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let err = (0..3)
                .map(|j| (a_sim[j] - a_ref[j]).abs())
                .fold(0.0, f64::max)
                / scale;
            worst = worst.max(err);
        }
        eprintln!("{model}: joint accelerations, max relative error {worst:.2e}");
        assert!(
            worst < 0.01,
            "{model}: accelerations off by {worst:.3e} relative"
        );
    }
}

/// Each model's servo holds the arm stretched out (the largest gravity load) within 1 mrad, and
/// each model's default task is accepted: the start pose within the limits, the goal within
/// reach.
#[test]
fn every_models_servo_holds_and_its_default_task_is_valid() {
    for model in UrModel::ALL {
        let task = TaskConfig::for_model(model);
        let mut sim = Ur5Sim::new(SimConfig::for_model(model), task.dt).unwrap();
        let q = [0.0, 0.0, 0.0];
        sim.reset(q, task.goal).unwrap();
        let mut obs = sim.step(q);
        for _ in 0..20 {
            obs = sim.step(q);
        }
        let sag = (0..3).map(|j| (obs.q[j] - q[j]).abs()).fold(0.0, f64::max);
        assert!(
            sag < 1e-3,
            "{model}: servo sags {sag:.2e} rad at full reach"
        );
        let obs = sim.reset(task.start_arm_joints(), task.goal).unwrap();
        let start = UrKinematics::new(model, [0.0; 3]).ee_point(&UrKinematics::six(
            &task.start_arm_joints(),
            &model.default_wrist_q(),
        ));
        assert!(
            (Vector3::from(obs.ee_pos) - Vector3::from(start)).norm() < 1e-6,
            "{model}"
        );
        let limits = sim.limits();
        assert_eq!(
            limits,
            ArmLimits::for_model(model),
            "{model}: the URDF's limits are the model's"
        );
    }
}

/// Each model's servo velocity gains are the UR5's scaled by the model's joint inertia at full
/// reach, to two significant digits (the rule of `ServoConfig::for_model`, from the masses in
/// the bundled URDF): upper arm, forearm and the three wrist links as point masses at |a2|/2,
/// |a2| + |a3|/2 and |a2| + |a3| from the shoulder; forearm and wrists about the elbow.
#[test]
fn every_models_servo_gains_follow_its_inertia() {
    let inertia = |model: UrModel| {
        let robot = urdf_rs::read_from_string(bundled_urdf(model)).unwrap();
        let mass = |name: &str| {
            let link = robot.links.iter().find(|l| l.name == name).expect(name);
            link.inertial.mass.value
        };
        let t = model.dh();
        let (a2, a3) = (t.a[1].abs(), t.a[2].abs());
        let (upper, fore) = (mass("upper_arm_link"), mass("forearm_link"));
        let wrists = mass("wrist_1_link") + mass("wrist_2_link") + mass("wrist_3_link");
        let shoulder = upper * (a2 / 2.0).powi(2)
            + fore * (a2 + a3 / 2.0).powi(2)
            + wrists * (a2 + a3).powi(2);
        let elbow = fore * (a3 / 2.0).powi(2) + wrists * a3 * a3;
        [shoulder, shoulder, elbow]
    };
    let (ur5, ur5_gain) = (
        inertia(UrModel::Ur5),
        ServoConfig::for_model(UrModel::Ur5).velocity_gain,
    );
    for model in UrModel::ALL {
        let (i, gain) = (inertia(model), ServoConfig::for_model(model).velocity_gain);
        for j in 0..3 {
            let exact = ur5_gain[j] * i[j] / ur5[j];
            let unit = 10f64.powf(exact.log10().floor() - 1.0);
            let want = (exact / unit).round() * unit;
            assert!(
                (gain[j] - want).abs() <= 1e-9 * want,
                "{model} joint {j}: gain {}, the rule gives {want} ({exact:.1})",
                gain[j]
            );
        }
    }
}
