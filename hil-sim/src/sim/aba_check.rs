//! The six-joint arm's free accelerations by the articulated-body algorithm (vendored rapier3d,
//! docs/design.md §5 D43) against rapier's mass-matrix route, (M + diag)⁻¹ (τ − b) from
//! rapier's own mass matrix and LU, on random states with nonzero velocities (Coriolis,
//! centripetal and gyroscopic terms), joint torques, damping and armature.
//!
//! The mass-matrix route is run at `dt = 0`, where its solved matrix is M + armature exactly
//! (the semi-implicit `dt`-terms vanish); the algorithm runs at the physics step, its diagonal
//! `damping·dt + armature` given to the reference as armature.

use super::*;
use rand::Rng;
use ur5_shared::UrModel;

/// Free accelerations (rad/s²) of the arm's six dofs at its current state and user torques,
/// by the articulated-body algorithm (`aba`) or the mass-matrix route, with the multibody's
/// damping and armature as they are set, for a step of `dt`.
fn free_accelerations(sim: &mut Ur5Sim, aba: bool, dt: f32) -> [f64; MAX_JOINTS] {
    let w = &mut sim.world;
    let mb = w.multibody_joints.get_multibody_mut(sim.mb).expect("mb");
    mb.set_articulated_body_dynamics(aba);
    assert_eq!(mb.articulated_body_applies(&w.bodies), aba);
    let a = mb.compute_free_accelerations(&mut w.bodies, w.gravity, dt);
    core::array::from_fn(|j| a[sim.dofs[j].dof] as f64)
}

#[test]
fn articulated_body_accelerations_equal_the_mass_matrix_routes() {
    let mut rng = ChaCha8Rng::seed_from_u64(46);
    for model in [UrModel::Ur5e, UrModel::Ur10] {
        let cfg = SimConfig {
            substeps: 1,
            ..SimConfig::for_model(model)
        };
        let mut sim = Ur5Sim::with_joints(cfg.clone(), cfg.physics_dt, MAX_JOINTS).unwrap();
        let dt = cfg.physics_dt as f32;
        let mut worst = 0.0f64;
        let mut worst_coriolis = 0.0f64;
        for sample in 0..40 {
            let q: [f64; MAX_JOINTS] = core::array::from_fn(|j| {
                let l = sim.model().joint(j);
                rng.random_range(l.lower.max(-3.1)..l.upper.min(3.1))
            });
            let qd: [f64; MAX_JOINTS] = core::array::from_fn(|_| rng.random_range(-2.0..2.0));
            let tau: [f64; MAX_JOINTS] = core::array::from_fn(|j| {
                let e = sim.model().joint(j).effort;
                rng.random_range(-0.3 * e..0.3 * e)
            });
            // Half the samples without damping and armature.
            let extra = sample % 2 == 1;
            let damping: [f32; MAX_JOINTS] = core::array::from_fn(|_| {
                if extra {
                    rng.random_range(0.0..3.0)
                } else {
                    0.0
                }
            });
            let armature: [f32; MAX_JOINTS] = core::array::from_fn(|_| {
                if extra {
                    rng.random_range(0.0..0.2)
                } else {
                    0.0
                }
            });
            sim.set_joint_state_all(&q, &qd);
            sim.apply_joint_torques(&tau);
            let set = |sim: &mut Ur5Sim, arm: &dyn Fn(usize) -> f32| {
                let dofs = sim.dofs;
                let mb = sim
                    .world
                    .multibody_joints
                    .get_multibody_mut(sim.mb)
                    .expect("mb");
                for (j, d) in dofs.iter().enumerate() {
                    mb.damping_mut()[d.dof] = damping[j];
                    mb.armature_mut()[d.dof] = arm(j);
                }
            };
            set(&mut sim, &|j| armature[j]);
            let aba = free_accelerations(&mut sim, true, dt);
            set(&mut sim, &|j| armature[j] + damping[j] * dt);
            let reference = free_accelerations(&mut sim, false, 0.0);
            // The same state at rest: the velocity terms' share of the accelerations.
            set(&mut sim, &|j| armature[j]);
            sim.set_joint_state_all(&q, &[0.0; MAX_JOINTS]);
            sim.apply_joint_torques(&tau);
            let at_rest = free_accelerations(&mut sim, true, dt);

            let scale = reference.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for j in 0..MAX_JOINTS {
                let err = (aba[j] - reference[j]).abs() / scale;
                worst = worst.max(err);
                assert!(
                    err < 1e-5,
                    "{model} sample {sample} joint {j}: ABA {} mass matrix {} (scale {scale})",
                    aba[j],
                    reference[j]
                );
                worst_coriolis = worst_coriolis.max((aba[j] - at_rest[j]).abs() / scale);
            }
        }
        eprintln!(
            "{model}: ABA vs M⁻¹(τ − b), max error {worst:.2e} of the largest |q̈|; \
             velocity terms up to {worst_coriolis:.2e} of it"
        );
        // The samples exercise the velocity terms well above the agreement.
        assert!(worst_coriolis > 1e-2, "{model}: {worst_coriolis:.2e}");
    }
}

/// The switch is on for six joints only; three joints keep the mass-matrix route.
#[test]
fn the_articulated_body_algorithm_runs_at_six_joints_only() {
    for (joints, on) in [(3, false), (6, true)] {
        let cfg = SimConfig::for_model(UrModel::Ur5e);
        let sim = Ur5Sim::with_joints(cfg.clone(), cfg.physics_dt, joints).unwrap();
        let mb = sim.world.multibody_joints.get_multibody(sim.mb).unwrap();
        assert_eq!(mb.articulated_body_dynamics(), on, "{joints} joints");
        assert_eq!(
            mb.articulated_body_applies(&sim.world.bodies),
            on,
            "{joints} joints"
        );
    }
}
