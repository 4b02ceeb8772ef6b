//! The simulated UR5: a rapier3d reduced-coordinate multibody built from the URDF by
//! rapier3d-urdf, with the arm's own joint servo running at the physics rate.
//!
//! Conventions: joint angles in rad, velocities in rad/s, torques in N·m, positions in m in the
//! arm base frame (the URDF root link frame, z up, gravity −9.81 m/s² along z). The physics runs
//! in rapier's f32; this API is f64.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rapier3d::glamx::Vec3;
use rapier3d::prelude::*;
use rapier3d_urdf::{UrdfLoaderOptions, UrdfMultibodyOptions, UrdfRobot};
use ur5_shared::config::{ActionMode, SimConfig};
use ur5_shared::layout::N_JOINTS;

use std::sync::Arc;

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use ur5_shared::kinematics::Joints6;

use crate::model::ArmModel;
use crate::servo::{joint_servo_torque, wrist_velocity_gain};
use crate::SimError;

#[cfg(test)]
mod aba_check;
mod state;

/// Standard gravity (m/s²), along −z of the base frame.
pub const GRAVITY: f64 = 9.81;

/// What the arm's sensors report (before or after sensor noise).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Observation {
    /// Angles of the first three active joints (rad); a six-joint arm's wrist:
    /// [`Ur5Sim::arm_joints`].
    pub q: [f64; N_JOINTS],
    /// Velocities of the first three active joints (rad/s).
    pub qd: [f64; N_JOINTS],
    /// End-effector point (m, base frame).
    pub ee_pos: [f64; 3],
    /// End-effector linear velocity (m/s, base frame), from the multibody's body Jacobian.
    pub ee_vel: [f64; 3],
}

impl Observation {
    /// The task state s ∈ R^12 (layout in `ur5_shared::layout`) for goal point `goal` (m).
    pub fn state(&self, goal: &[f64; 3]) -> [f64; ur5_shared::DX] {
        ur5_shared::state_vector(&self.q, &self.qd, &self.ee_pos, &self.ee_vel, goal)
    }
}

/// One active joint inside the rapier multibody.
#[derive(Clone, Copy, Debug)]
struct ActiveDof {
    /// Multibody link id of the joint's child link.
    link: usize,
    /// Index of the joint's degree of freedom in the multibody's generalized vectors.
    dof: usize,
    parent_body: RigidBodyHandle,
    child_body: RigidBodyHandle,
    /// The joint's axis in the child body's frame (`local_axis2` of its joint, fixed).
    axis_in_child: Vec3,
}

/// The state of a rapier world without its pipelines (which hold only scratch memory):
/// enough to rebuild the world exactly as it was.
#[derive(Clone)]
struct Pristine {
    gravity: Vec3,
    integration_parameters: IntegrationParameters,
    islands: IslandManager,
    broad_phase: BroadPhaseBvh,
    narrow_phase: NarrowPhase,
    bodies: RigidBodySet,
    colliders: ColliderSet,
    impulse_joints: ImpulseJointSet,
    multibody_joints: MultibodyJointSet,
    soft_bodies: SoftBodySet,
    ccd_solver: CCDSolver,
}

impl Pristine {
    fn take(w: &PhysicsWorld) -> Self {
        Self {
            gravity: w.gravity,
            integration_parameters: w.integration_parameters,
            islands: w.islands.clone(),
            broad_phase: w.broad_phase.clone(),
            narrow_phase: w.narrow_phase.clone(),
            bodies: w.bodies.clone(),
            colliders: w.colliders.clone(),
            impulse_joints: w.impulse_joints.clone(),
            multibody_joints: w.multibody_joints.clone(),
            soft_bodies: w.soft_bodies.clone(),
            ccd_solver: w.ccd_solver.clone(),
        }
    }

    /// The world again, with new (empty) pipelines.
    fn world(&self) -> PhysicsWorld {
        let p = self.clone();
        PhysicsWorld {
            gravity: p.gravity,
            integration_parameters: p.integration_parameters,
            islands: p.islands,
            broad_phase: p.broad_phase,
            narrow_phase: p.narrow_phase,
            bodies: p.bodies,
            colliders: p.colliders,
            impulse_joints: p.impulse_joints,
            multibody_joints: p.multibody_joints,
            soft_bodies: p.soft_bodies,
            ccd_solver: p.ccd_solver,
            ..PhysicsWorld::new()
        }
    }
}

/// Most joints the simulator moves (the whole UR arm).
pub const MAX_JOINTS: usize = 6;

/// The simulated arm: three active joints with the wrist locked ([`Ur5Sim::new`]), or all six
/// ([`Ur5Sim::with_joints`]). The three-joint API (`reset`, `step`, `joint_state`, …, arrays of
/// three) drives the first three joints; with six active joints it holds the wrist at
/// `sim.wrist_q`. The `*_all` API takes and gives every active joint (slices of length
/// [`Ur5Sim::joints`], or arrays of six whose first `joints()` entries are the active ones).
pub struct Ur5Sim {
    model: ArmModel,
    cfg: SimConfig,
    control_dt: f64,
    physics_steps_per_control: usize,
    world: PhysicsWorld,
    /// The world as [`Ur5Sim::new`] left it: every reset starts from it, so an episode does
    /// not depend on the ones before it (docs/design.md §5 D29).
    pristine: Arc<Pristine>,
    mb: MultibodyIndex,
    /// Active joints: 3 or 6.
    n: usize,
    /// The active joints' degrees of freedom (first `n` entries).
    dofs: [ActiveDof; MAX_JOINTS],
    /// Velocity-loop gains of the active joints (N·m·s/rad): `servo.velocity_gain`, then the
    /// model's wrist gains ([`wrist_velocity_gain`]).
    velocity_gain: [f64; MAX_JOINTS],
    /// (multibody link id, nominal mass kg) of every moving link, for gravity compensation.
    nominal_masses: Vec<(usize, f64)>,
    /// Multibody link and body that carry the end-effector link (after merging, the forearm).
    ee_link: usize,
    ee_body: RigidBodyHandle,
    /// The end-effector point in that link's frame (m): `ee_offset` moved through the locked
    /// joints between the end-effector link and its carrier.
    ee_point: Vec3,
    /// Pose of the end-effector link's frame (no offset) in its carrier's frame.
    ee_frame: Isometry3<f64>,
    rng: ChaCha8Rng,
    /// Action waiting one control period when `latency_steps == 1`.
    pending: Option<[f64; MAX_JOINTS]>,
    /// Action the servo (or torque mode) currently executes (first `n` entries).
    current: [f64; MAX_JOINTS],
    /// Torques applied in the last physics step (N·m, after clamping and actuator noise).
    last_tau: [f64; MAX_JOINTS],
    /// Largest |τ| per joint since the last reset (N·m).
    max_abs_tau: [f64; MAX_JOINTS],
    goal: [f64; 3],
    time: f64,
    /// Step through rapier's whole pipeline even when the multibody could step alone
    /// ([`Ur5Sim::set_pipeline_only`]).
    pipeline_only: bool,
    /// Physics steps since the arm was built: (multibody stepped alone, whole pipeline).
    step_counts: (u64, u64),
}

impl Ur5Sim {
    /// Builds the arm with three active joints, the wrist locked at `sim.wrist_q`.
    /// `control_dt` (s) is how long each action is held (the paper: 0.1 s); it must be a whole
    /// number of physics steps.
    pub fn new(cfg: SimConfig, control_dt: f64) -> Result<Self, SimError> {
        Self::with_joints(cfg, control_dt, N_JOINTS)
    }

    /// Builds the arm with `joints` active joints: 3 (as [`Ur5Sim::new`]) or 6 (every joint of
    /// the URDF moves; no link is merged into another). At six the wrist joints' servo gains
    /// are [`wrist_velocity_gain`] of the model, and the perturbation's per-joint damping and
    /// friction (three values) act on the first three joints only.
    pub fn with_joints(cfg: SimConfig, control_dt: f64, joints: usize) -> Result<Self, SimError> {
        cfg.validate()?;
        let model = ArmModel::load_joints(
            cfg.urdf.as_deref(),
            cfg.model,
            cfg.wrist_q,
            &cfg.ee_link,
            cfg.ee_offset,
            joints,
        )?;
        let n = model.n_active;
        let ratio = control_dt / cfg.physics_dt;
        if !(control_dt > 0.0 && (ratio - ratio.round()).abs() < 1e-9 && ratio.round() >= 1.0) {
            return Err(SimError::Config(ur5_shared::config::ConfigError::Invalid {
                key: "task.dt",
                why: format!(
                    "control period {control_dt} s must be a whole multiple of physics_dt {} s",
                    cfg.physics_dt
                ),
            }));
        }
        let physics_steps_per_control = ratio.round() as usize;

        let mut world = PhysicsWorld::new();
        world.gravity = Vec3::new(0.0, 0.0, -GRAVITY as f32);
        world.integration_parameters.dt = cfg.physics_dt as f32;
        world.integration_parameters.num_solver_iterations = cfg.substeps;

        let options = UrdfLoaderOptions {
            create_colliders_from_collision_shapes: false,
            create_colliders_from_visual_shapes: false,
            apply_imported_mass_props: true,
            make_roots_fixed: true,
            // UR5.md: squeezing empty links drops the root's fixed transform.
            squeeze_empty_fixed_links: false,
            rigid_body_blueprint: RigidBodyBuilder::dynamic().can_sleep(false),
            ..Default::default()
        };
        // One multibody link per rigid body: the locked wrists ride on the forearm.
        let robot = model.rigid_robot(cfg.perturbation.mass_scale);
        let nominal = &model.rigid_robot(1.0);
        let urdf_robot = UrdfRobot::from_robot(&robot, options, std::path::Path::new("."));
        let link_names: Vec<String> = urdf_robot
            .links
            .iter()
            .map(|l| robot.links[l.urdf_link_index].name.clone())
            .collect();
        let joint_names: Vec<String> = urdf_robot
            .joints
            .iter()
            .map(|j| robot.joints[j.urdf_joint_index].name.clone())
            .collect();
        let handles = urdf_robot.insert_using_multibody_joints(
            &mut world.bodies,
            &mut world.colliders,
            &mut world.multibody_joints,
            UrdfMultibodyOptions::DISABLE_SELF_CONTACTS,
        );

        // rapier applies the URDF mass properties only inside the first step(); until then
        // every COM sits at its link origin and the body Jacobians (and so the servo's gravity
        // feed-forward) are wrong. Apply them now.
        for (_, rb) in world.bodies.iter_mut() {
            rb.recompute_mass_properties_from_colliders(&world.colliders);
        }
        let link_of = |body: RigidBodyHandle, world: &PhysicsWorld| {
            *world
                .multibody_joints
                .rigid_body_link(body)
                .expect("every URDF link is in the multibody")
        };
        let root = link_of(handles.links[0].body, &world);
        let mb = root.multibody;
        // The root's multibody joint follows its body type (fixed) only after a forward
        // kinematics pass that reads the root body; do it before reading any dof index.
        world
            .multibody_joints
            .get_multibody_mut(mb)
            .expect("multibody")
            .forward_kinematics(&world.bodies, true);

        let mut dofs = Vec::with_capacity(MAX_JOINTS);
        for limits in (0..n).map(|j| model.joint(j)) {
            let ji = joint_names
                .iter()
                .position(|n| *n == limits.name)
                .expect("active joint was checked");
            let jh = &handles.joints[ji];
            let link = link_of(jh.link2, &world).id;
            let mb_link = world.multibody_joints[mb].link(link).expect("link");
            dofs.push(ActiveDof {
                link,
                dof: mb_link.assembly_id(),
                parent_body: jh.link1,
                child_body: jh.link2,
                axis_in_child: mb_link.joint().data.local_axis2(),
            });
        }
        let unused = dofs[0];
        dofs.resize(MAX_JOINTS, unused);
        let dofs: [ActiveDof; MAX_JOINTS] = dofs.try_into().expect("six entries");
        let wrist_gain = wrist_velocity_gain(cfg.model);
        let velocity_gain: [f64; MAX_JOINTS] = core::array::from_fn(|j| {
            if j < N_JOINTS {
                cfg.servo.velocity_gain[j]
            } else {
                wrist_gain[j - N_JOINTS]
            }
        });

        let mut nominal_masses = Vec::new();
        for (li, name) in link_names.iter().enumerate() {
            let link = link_of(handles.links[li].body, &world).id;
            if link == 0 {
                continue; // the fixed base does not load the joints
            }
            let mass = nominal
                .links
                .iter()
                .find(|l| l.name == *name)
                .expect("same links")
                .inertial
                .mass
                .value;
            nominal_masses.push((link, mass));
        }
        let (ee_carrier, ee_in_carrier) = model
            .carrier_of(&model.ee_link)
            .expect("ee link was checked");
        let ee_frame = ee_in_carrier;
        let ee_point = ee_in_carrier * nalgebra::Point3::from(cfg.ee_offset);
        let ee_point = Vec3::new(ee_point.x as f32, ee_point.y as f32, ee_point.z as f32);
        let ee_index = link_names
            .iter()
            .position(|n| *n == ee_carrier)
            .expect("the carrier is a link of the merged robot");
        let ee_body = handles.links[ee_index].body;
        let ee_link = link_of(ee_body, &world).id;

        {
            let multibody = world
                .multibody_joints
                .get_multibody_mut(mb)
                .expect("multibody");

            if multibody.ndofs() != n {
                return Err(SimError::BadJoint {
                    name: "<multibody>".into(),
                    why: format!(
                        "the multibody has {} degrees of freedom, expected {n}",
                        multibody.ndofs()
                    ),
                });
            }
            // UR5.md: rapier puts 0.1 N·m·s/rad on every multibody joint by default; the nominal arm
            // has none. Damping and dry friction are perturbation knobs.
            multibody.damping_mut().fill(0.0);
            for (j, d) in dofs.iter().enumerate().take(N_JOINTS) {
                multibody.damping_mut()[d.dof] = cfg.perturbation.joint_damping[j] as f32;
                multibody.frictions_mut()[d.dof] = cfg.perturbation.joint_friction[j] as f32;
            }
            // Six joints: the free accelerations by the articulated-body algorithm (vendored
            // rapier3d, docs/design.md §5 D43); three joints keep the mass-matrix route, bit
            // for bit.
            multibody.set_articulated_body_dynamics(n == MAX_JOINTS);
        }

        let rng = ChaCha8Rng::seed_from_u64(cfg.perturbation.seed);
        let pristine = Arc::new(Pristine::take(&world));
        let mut sim = Self {
            model,
            cfg,
            control_dt,
            physics_steps_per_control,
            world,
            pristine,
            mb,
            n,
            dofs,
            velocity_gain,
            nominal_masses,
            ee_link,
            ee_body,
            ee_point,
            ee_frame,
            rng,
            pending: None,
            current: [0.0; MAX_JOINTS],
            last_tau: [0.0; MAX_JOINTS],
            max_abs_tau: [0.0; MAX_JOINTS],
            goal: [0.0; 3],
            time: 0.0,
            pipeline_only: false,
            step_counts: (0, 0),
        };
        sim.set_joint_state_all(&[0.0; MAX_JOINTS][..n], &[0.0; MAX_JOINTS][..n]);
        sim.pristine = Arc::new(Pristine::take(&sim.world));
        Ok(sim)
    }

    /// A new arm as [`Ur5Sim::new`] built this one (same model and configuration, at rest,
    /// perturbation RNG at its seed), without parsing and building the URDF again: what
    /// parallel episodes run on (docs/design.md §5 D29).
    pub fn fresh(&self) -> Self {
        let mut sim = Self {
            model: self.model.clone(),
            cfg: self.cfg.clone(),
            world: self.pristine.world(),
            pristine: self.pristine.clone(),
            nominal_masses: self.nominal_masses.clone(),
            rng: ChaCha8Rng::seed_from_u64(self.cfg.perturbation.seed),
            ..*self
        };
        (sim.pending, sim.current, sim.goal, sim.time) = (None, [0.0; MAX_JOINTS], [0.0; 3], 0.0);
        (sim.last_tau, sim.max_abs_tau) = ([0.0; MAX_JOINTS], [0.0; MAX_JOINTS]);
        sim.step_counts = (0, 0);
        sim
    }

    /// Restarts the perturbation RNG (actuator and sensor noise) on its own stream `stream` of
    /// the configured `perturbation.seed`: an episode that calls it first draws the same
    /// noise whatever ran before it.
    pub fn reseed(&mut self, stream: u64) {
        self.rng = ChaCha8Rng::seed_from_u64(self.cfg.perturbation.seed);
        self.rng.set_stream(stream);
    }

    /// The checked model (limits, wrist lock, end-effector definition).
    pub fn model(&self) -> &ArmModel {
        &self.model
    }

    /// The configuration the arm was built with.
    pub fn config(&self) -> &SimConfig {
        &self.cfg
    }

    /// Position (ChaCha8 word position) of the stream of the arm's actuator and sensor noise,
    /// seeded from `perturbation.seed` when the arm is built; in-process episodes restart it
    /// on their own stream ([`Ur5Sim::reseed`]), so it matters only to an arm that runs on
    /// across episodes; an exact checkpoint of an in-process run stores it (docs/design.md
    /// §4.11).
    pub fn noise_position(&self) -> u128 {
        self.rng.get_word_pos()
    }

    /// Moves the noise stream to `pos` (a [`Ur5Sim::noise_position`] of an arm of the same
    /// configuration).
    pub fn set_noise_position(&mut self, pos: u128) {
        self.rng.set_word_pos(pos);
    }

    /// How many joints move: 3 (wrist locked) or 6.
    pub fn joints(&self) -> usize {
        self.n
    }

    /// Limits of the active joints (3 or 6) as written in the URDF, for the action clamp
    /// (`ur5_shared::safety::clamp_action`).
    pub fn limits(&self) -> ur5_shared::config::ArmLimits {
        let a = &self.model.active;
        let w = &self.model.wrist_limits;
        let joint = |j: usize| {
            if j < N_JOINTS {
                &a[j]
            } else {
                &w[j - N_JOINTS]
            }
        };
        let of = |f: fn(&crate::model::JointLimits) -> f64| {
            let v: [f64; MAX_JOINTS] =
                core::array::from_fn(|j| if j < self.n { f(joint(j)) } else { 0.0 });
            ur5_shared::joints::Joints::from_slice(&v[..self.n])
        };
        ur5_shared::config::ArmLimits {
            lower: of(|l| l.lower),
            upper: of(|l| l.upper),
            velocity: of(|l| l.velocity),
            effort: of(|l| l.effort),
        }
    }

    /// Control period (s): how long each action is held.
    pub fn control_dt(&self) -> f64 {
        self.control_dt
    }

    /// Simulated time since the last reset (s).
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Goal point of the current episode (m, base frame).
    pub fn goal(&self) -> [f64; 3] {
        self.goal
    }

    /// Torques applied in the last physics step to the first three joints (N·m).
    pub fn last_torque(&self) -> [f64; N_JOINTS] {
        first3(&self.last_tau)
    }

    /// Torques applied in the last physics step to the six joints (N·m; a locked wrist's 0).
    pub fn last_torque_all(&self) -> Joints6 {
        self.last_tau
    }

    /// Largest |τ| per joint of the first three applied since the last reset (N·m).
    pub fn max_abs_torque(&self) -> [f64; N_JOINTS] {
        first3(&self.max_abs_tau)
    }

    /// Largest |τ| per active joint since the last reset (N·m; first [`Ur5Sim::joints`]
    /// entries).
    pub fn max_abs_torque_all(&self) -> [f64; MAX_JOINTS] {
        self.max_abs_tau
    }

    /// `q` (three joint values) extended to every active joint: the wrist at `sim.wrist_q`.
    fn extend(&self, q: &[f64; N_JOINTS]) -> [f64; MAX_JOINTS] {
        let w = self.model.wrist_q;
        [q[0], q[1], q[2], w[0], w[1], w[2]]
    }

    /// Starts an episode: puts the arm at rest at `start_q` and sets the goal. The physics
    /// restarts from the world [`Ur5Sim::new`] built (not from the last episode's end), so the
    /// episode's motion does not depend on what ran before (docs/design.md §5 D29). Re-seeds
    /// nothing: the perturbation RNG runs on across episodes unless [`Ur5Sim::reseed`] is
    /// called, so a run replays as a whole.
    ///
    /// With six active joints the wrist starts (and is held by the servo) at `sim.wrist_q`.
    pub fn reset(
        &mut self,
        start_q: [f64; N_JOINTS],
        goal: [f64; 3],
    ) -> Result<Observation, SimError> {
        let q = self.extend(&start_q);
        self.reset_all(&q[..self.n], goal)
    }

    /// [`Ur5Sim::reset`] with the angles of every active joint (`start_q.len()` =
    /// [`Ur5Sim::joints`], rad).
    pub fn reset_all(&mut self, start_q: &[f64], goal: [f64; 3]) -> Result<Observation, SimError> {
        self.restart(start_q, goal)?;
        Ok(self.observe())
    }

    /// [`Ur5Sim::reset_all`] without the observation (read it with
    /// [`Ur5Sim::observe_points`]); `goal` is checked against the arm's reach.
    pub fn restart(&mut self, start_q: &[f64], goal: [f64; 3]) -> Result<(), SimError> {
        self.check_len(start_q.len());
        for j in 0..self.n {
            let l = self.model.joint(j);
            if !(start_q[j].is_finite() && start_q[j] >= l.lower && start_q[j] <= l.upper) {
                return Err(SimError::OutOfLimits {
                    joint: l.name.clone(),
                    value: start_q[j],
                    lower: l.lower,
                    upper: l.upper,
                });
            }
        }
        self.check_goal(goal)?;
        self.world = self.pristine.world();
        self.set_joint_state_all(start_q, &[0.0; MAX_JOINTS][..self.n]);
        self.goal = goal;
        self.pending = None;
        self.current = [0.0; MAX_JOINTS];
        if self.cfg.mode == ActionMode::GoalAngles {
            self.current[..self.n].copy_from_slice(start_q);
        }
        self.max_abs_tau = [0.0; MAX_JOINTS];
        self.time = 0.0;
        Ok(())
    }

    /// Rejects a goal that is not finite or farther from the shoulder than the arm reaches.
    pub fn check_goal(&self, goal: [f64; 3]) -> Result<(), SimError> {
        let lift = self.world.bodies[self.dofs[1].child_body]
            .position()
            .translation;
        let d = ((goal[0] - lift.x as f64).powi(2)
            + (goal[1] - lift.y as f64).powi(2)
            + (goal[2] - lift.z as f64).powi(2))
        .sqrt();
        let reach = self.model.reach();
        if goal.iter().all(|g| g.is_finite()) && d <= reach {
            Ok(())
        } else {
            Err(SimError::GoalOutOfReach {
                goal,
                distance: d,
                reach,
            })
        }
    }

    /// Executes one action for one control period and returns the measured observation.
    ///
    /// In goal-angle mode the action is goal joint angles (rad), clamped to the joint limits;
    /// the servo tracks it at the physics rate. In torque mode it is joint torques (N·m),
    /// clamped to the effort limits. Non-finite actions are replaced by a hold of the current
    /// goal (or zero torque). With one-step latency the arm executes the previous action.
    ///
    /// With six active joints the wrist's goal is `sim.wrist_q` (torque mode: zero torque).
    pub fn step(&mut self, action: [f64; N_JOINTS]) -> Observation {
        let a = match self.cfg.mode {
            ActionMode::GoalAngles => self.extend(&action),
            ActionMode::Torque => [action[0], action[1], action[2], 0.0, 0.0, 0.0],
        };
        self.step_all(&a[..self.n])
    }

    /// [`Ur5Sim::step`] with an action for every active joint (`action.len()` =
    /// [`Ur5Sim::joints`]).
    pub fn step_all(&mut self, action: &[f64]) -> Observation {
        self.advance(action);
        self.observe()
    }

    /// [`Ur5Sim::step_all`] without the observation (read it with
    /// [`Ur5Sim::observe_points`]).
    pub fn advance(&mut self, action: &[f64]) {
        self.check_len(action.len());
        let mut a = [0.0; MAX_JOINTS];
        a[..self.n].copy_from_slice(action);
        let action = self.sanitize(a);
        let applied = if self.cfg.perturbation.latency_steps == 1 {
            let prev = self.pending.replace(action);
            prev.unwrap_or(self.current)
        } else {
            action
        };
        self.current = applied;
        for _ in 0..self.physics_steps_per_control {
            self.physics_step();
        }
    }

    /// Panics unless `len` is the number of active joints (a caller's bug, like a slice index).
    pub(super) fn check_len(&self, len: usize) {
        assert_eq!(
            len, self.n,
            "{len} joint values for an arm with {} active joints",
            self.n
        );
    }

    fn sanitize(&self, mut a: [f64; MAX_JOINTS]) -> [f64; MAX_JOINTS] {
        if a[..self.n].iter().any(|v| !v.is_finite()) {
            return self.current;
        }
        for j in 0..self.n {
            let l = self.model.joint(j);
            a[j] = match self.cfg.mode {
                ActionMode::GoalAngles => a[j].clamp(l.lower, l.upper),
                ActionMode::Torque => a[j].clamp(-l.effort, l.effort),
            };
        }
        a
    }

    /// One physics step with the current action.
    fn physics_step(&mut self) {
        let (q, qd) = self.joint_state_all();
        let mut tau = match self.cfg.mode {
            ActionMode::GoalAngles => {
                let tau_g = self.gravity_torque_all();
                let mut tau = [0.0; MAX_JOINTS];
                for (j, t) in tau.iter_mut().enumerate().take(self.n) {
                    let l = self.model.joint(j);
                    *t = joint_servo_torque(
                        &self.cfg.servo,
                        self.velocity_gain[j],
                        (l.effort, l.velocity),
                        q[j],
                        qd[j],
                        self.current[j],
                        tau_g[j],
                    );
                }
                tau
            }
            ActionMode::Torque => self.current,
        };
        let noise = self.cfg.perturbation.actuator_noise_std;
        for (j, t) in tau.iter_mut().enumerate().take(self.n) {
            if noise > 0.0 {
                let n: f64 = StandardNormal.sample(&mut self.rng);
                *t += noise * n;
            }
            let e = self.model.joint(j).effort;
            *t = t.clamp(-e, e);
        }
        self.apply_torque_and_step(tau);
    }

    /// Applies raw joint torques (N·m, not clamped; first [`Ur5Sim::joints`] entries) for one
    /// physics step.
    fn apply_torque_and_step(&mut self, tau: [f64; MAX_JOINTS]) {
        self.apply_joint_torques(&tau);
        for j in 0..self.n {
            self.last_tau[j] = tau[j];
            self.max_abs_tau[j] = self.max_abs_tau[j].max(tau[j].abs());
        }
        self.step_world();
        self.time += self.cfg.physics_dt;
    }

    /// Replaces the links' user torques by the joint torques `tau` (N·m, first
    /// [`Ur5Sim::joints`] entries): each an equal and opposite couple about the joint's axis
    /// on child and parent (UR5.md).
    fn apply_joint_torques(&mut self, tau: &[f64; MAX_JOINTS]) {
        for rb in self.world.bodies.iter_mut() {
            rb.1.reset_torques(false);
        }
        for (j, d) in self.dofs.iter().enumerate().take(self.n) {
            let child = &self.world.bodies[d.child_body];
            let axis = self.axis_world(j, child);
            let couple = axis * tau[j] as f32;
            self.world.bodies[d.child_body].add_torque(couple, false);
            self.world.bodies[d.parent_body].add_torque(-couple, false);
        }
    }

    /// One physics step of the world: the multibody stepped alone by rapier's own routines
    /// (`Multibody::step_alone`, vendored rapier3d), or rapier's whole pipeline step when a
    /// joint constraint acts (a joint beyond its limit, dry friction). Both give the same bits
    /// (test `the_direct_step_equals_the_pipeline_step`; docs/design.md §5 D30).
    fn step_world(&mut self) {
        let w = &mut self.world;
        let alone = !self.pipeline_only
            && w.multibody_joints
                .get_multibody_mut(self.mb)
                .expect("multibody")
                .step_alone(&mut w.bodies, w.gravity, &w.integration_parameters);
        if alone {
            self.step_counts.0 += 1;
        } else {
            w.step();
            self.step_counts.1 += 1;
        }
    }

    /// Physics steps since the arm was built (or copied by [`Ur5Sim::fresh`]): how many the
    /// multibody took alone, and how many through rapier's whole pipeline.
    pub fn step_counts(&self) -> (u64, u64) {
        self.step_counts
    }

    /// With `true`, every physics step runs rapier's whole pipeline (`PhysicsWorld::step`), as
    /// before docs/design.md §5 D30: for checking that the direct step gives the same bits.
    pub fn set_pipeline_only(&mut self, on: bool) {
        self.pipeline_only = on;
    }
}

/// The first three entries.
fn first3(a: &[f64; MAX_JOINTS]) -> [f64; N_JOINTS] {
    [a[0], a[1], a[2]]
}

/// UR's rotation vector and pose p[x, y, z, rx, ry, rz] of an orientation or a frame: the
/// contract's (`ur5_shared::pose`), re-exported for the simulator's users.
pub use ur5_shared::pose::{rotation_vector, ur_pose};
