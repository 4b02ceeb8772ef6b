//! The simulated arm's state: joint angles and velocities, the flange's frame, observations
//! (true and as measured), gravity torques and joint accelerations, read from the multibody
//! (conventions as in [`super`]).

use super::*;

impl Ur5Sim {
    /// World direction of active joint `j`'s axis.
    pub(super) fn axis_world(&self, j: usize, child: &RigidBody) -> Vec3 {
        let link = self.world.multibody_joints[self.mb]
            .link(self.dofs[j].link)
            .expect("link");
        child.position().rotation * link.joint().data.local_axis2()
    }

    /// The rapier multibody. Invariant: its link poses and body Jacobians are always those of
    /// the current joint angles, because every change of state ends with a forward-kinematics
    /// pass (rapier's step does one after integrating; [`Self::set_joint_state`] does one).
    pub(super) fn multibody(&self) -> &Multibody {
        self.world
            .multibody_joints
            .get_multibody(self.mb)
            .expect("multibody")
    }

    /// True angles and velocities of the first three joints (no sensor noise).
    pub fn joint_state(&self) -> ([f64; N_JOINTS], [f64; N_JOINTS]) {
        let (q, qd) = self.joint_state_all();
        (first3(&q), first3(&qd))
    }

    /// All six joints of the arm (rad, rad/s; layout order): the active ones' true values, and
    /// a locked wrist at `sim.wrist_q` at rest. What an arm reports for its six joints.
    pub fn arm_joints(&self) -> (Joints6, Joints6) {
        let (mut q, qd) = self.joint_state_all();
        if self.n == N_JOINTS {
            q[N_JOINTS..].copy_from_slice(&self.model.wrist_q);
        }
        (q, qd)
    }

    /// True angles and velocities of the active joints (first [`Ur5Sim::joints`] entries; the
    /// others 0).
    pub fn joint_state_all(&self) -> ([f64; MAX_JOINTS], [f64; MAX_JOINTS]) {
        let mb = self.multibody();
        let v = mb.generalized_velocity();
        let mut q = [0.0; MAX_JOINTS];
        let mut qd = [0.0; MAX_JOINTS];
        for (j, d) in self.dofs.iter().enumerate().take(self.n) {
            // Revolute joints from rapier3d-urdf rotate about the joint frame's x axis.
            q[j] = mb.link(d.link).expect("link").joint().coords()[3] as f64;
            qd[j] = v[d.dof] as f64;
        }
        (q, qd)
    }

    /// Puts the arm at joint angles `q` (rad) with velocities `qd` (rad/s) and updates every
    /// link pose and Jacobian. With six active joints the wrist goes to `sim.wrist_q`, at rest.
    pub fn set_joint_state(&mut self, q: [f64; N_JOINTS], qd: [f64; N_JOINTS]) {
        let (q, qd) = (self.extend(&q), [qd[0], qd[1], qd[2], 0.0, 0.0, 0.0]);
        self.set_joint_state_all(&q[..self.n], &qd[..self.n]);
    }

    /// [`Ur5Sim::set_joint_state`] for every active joint (slices of length
    /// [`Ur5Sim::joints`]).
    pub fn set_joint_state_all(&mut self, q: &[f64], qd: &[f64]) {
        self.check_len(q.len());
        self.check_len(qd.len());
        let (q0, _) = self.joint_state_all();
        let mb = self
            .world
            .multibody_joints
            .get_multibody_mut(self.mb)
            .expect("multibody");
        let mut disp = vec![0.0f32; mb.ndofs()];
        let mut vel = mb.generalized_velocity_mut();
        for (j, d) in self.dofs.iter().enumerate().take(self.n) {
            disp[d.dof] = (q[j] - q0[j]) as f32;
            vel[d.dof] = qd[j] as f32;
        }
        // Coordinates are f32 in rapier: q is reproduced to within one f32 ulp.
        mb.apply_displacements(&disp);
        mb.forward_kinematics(&self.world.bodies, false);
        mb.update_rigid_bodies(&mut self.world.bodies, true);
        for (_, rb) in self.world.bodies.iter_mut() {
            rb.set_linvel(Vec3::ZERO, false);
            rb.set_angvel(Vec3::ZERO, false);
        }
    }

    /// Gravity torque of the nominal model at the current pose on the first three joints (N·m).
    pub fn gravity_torque(&self) -> [f64; N_JOINTS] {
        first3(&self.gravity_torque_all())
    }

    /// Gravity torque of the nominal model at the current pose (N·m, first
    /// [`Ur5Sim::joints`] entries): the torque that holds the nominal arm still,
    /// τ_g = −Σ_i J_com,iᵀ m_i g over the moving links.
    pub fn gravity_torque_all(&self) -> [f64; MAX_JOINTS] {
        let mb = self.multibody();
        let mut tau = [0.0; MAX_JOINTS];
        for &(link, mass) in &self.nominal_masses {
            let jac = mb.body_jacobian(link);
            for (j, d) in self.dofs.iter().enumerate().take(self.n) {
                // Row 2 is the z component of the COM's linear velocity.
                tau[j] += mass * GRAVITY * jac[(2, d.dof)] as f64;
            }
        }
        tau
    }

    /// Pose of the end-effector link's frame (`sim.ee_link`, no offset; the default
    /// `wrist_3_link` is the flange) in the base frame, from rapier's f32 link pose.
    pub fn ee_frame_pose(&self) -> Isometry3<f64> {
        let pose = *self
            .multibody()
            .link(self.ee_link)
            .expect("ee link")
            .local_to_world();
        let (t, r) = (pose.translation, pose.rotation);
        let link = Isometry3::from_parts(
            Translation3::new(t.x as f64, t.y as f64, t.z as f64),
            UnitQuaternion::new_normalize(nalgebra::Quaternion::new(
                r.w as f64, r.x as f64, r.y as f64, r.z as f64,
            )),
        );
        link * self.ee_frame
    }

    /// The true observation (no sensor noise).
    pub fn true_observation(&self) -> Observation {
        let (q, qd) = self.joint_state_all();
        let mb = self.multibody();
        let pose = *mb.link(self.ee_link).expect("ee link").local_to_world();
        let ee = pose.transform_point(self.ee_point);
        let com = pose.transform_point(self.world.bodies[self.ee_body].local_center_of_mass());
        let jac = mb.body_jacobian(self.ee_link);
        let mut v = [0.0f64; 3];
        let mut w = [0.0f64; 3];
        for r in 0..3 {
            for (j, d) in self.dofs.iter().enumerate().take(self.n) {
                v[r] += jac[(r, d.dof)] as f64 * qd[j];
                w[r] += jac[(r + 3, d.dof)] as f64 * qd[j];
            }
        }
        // The Jacobian gives the COM velocity; shift it to the end-effector point: v + ω × r.
        let r = [
            (ee.x - com.x) as f64,
            (ee.y - com.y) as f64,
            (ee.z - com.z) as f64,
        ];
        let ee_vel = [
            v[0] + w[1] * r[2] - w[2] * r[1],
            v[1] + w[2] * r[0] - w[0] * r[2],
            v[2] + w[0] * r[1] - w[1] * r[0],
        ];
        Observation {
            q: first3(&q),
            qd: first3(&qd),
            ee_pos: [ee.x as f64, ee.y as f64, ee.z as f64],
            ee_vel,
        }
    }

    /// What the arm's sensors report: the true observation plus the configured sensor noise.
    pub fn observe(&mut self) -> Observation {
        let mut o = self.true_observation();
        let p = &self.cfg.perturbation;
        let groups: [(&mut [f64; 3], f64); 4] = [
            (&mut o.q, p.sensor_noise_q_std),
            (&mut o.qd, p.sensor_noise_qd_std),
            (&mut o.ee_pos, p.sensor_noise_ee_std),
            (&mut o.ee_vel, p.sensor_noise_ee_std),
        ];
        for (vals, std) in groups {
            if std > 0.0 {
                for v in vals.iter_mut() {
                    let n: f64 = StandardNormal.sample(&mut self.rng);
                    *v += std * n;
                }
            }
        }
        o
    }

    /// Joint accelerations (rad/s²) over one physics step from state (q, q̇) under raw joint
    /// torques τ (servo bypassed, no clamping, gravity on): (q̇⁺ − q̇) / physics_dt. Leaves the
    /// arm in the stepped state.
    pub fn joint_acceleration(
        &mut self,
        q: [f64; N_JOINTS],
        qd: [f64; N_JOINTS],
        tau: [f64; N_JOINTS],
    ) -> [f64; N_JOINTS] {
        self.set_joint_state(q, qd);
        let (_, v0) = self.joint_state();
        self.apply_torque_and_step([tau[0], tau[1], tau[2], 0.0, 0.0, 0.0]);
        let (_, v1) = self.joint_state();
        [0, 1, 2].map(|j| (v1[j] - v0[j]) / self.cfg.physics_dt)
    }

    /// [`Ur5Sim::joint_acceleration`] for every active joint (slices of length
    /// [`Ur5Sim::joints`]; the result's first `joints()` entries, rad/s²).
    pub fn joint_acceleration_all(
        &mut self,
        q: &[f64],
        qd: &[f64],
        tau: &[f64],
    ) -> [f64; MAX_JOINTS] {
        self.check_len(tau.len());
        self.set_joint_state_all(q, qd);
        let (_, v0) = self.joint_state_all();
        let mut t = [0.0; MAX_JOINTS];
        t[..self.n].copy_from_slice(tau);
        self.apply_torque_and_step(t);
        let (_, v1) = self.joint_state_all();
        core::array::from_fn(|j| (v1[j] - v0[j]) / self.cfg.physics_dt)
    }

    /// Advances one physics step under raw torques on the first three joints (N·m, servo
    /// bypassed, not clamped; a six-joint arm's wrist gets none).
    pub fn step_torque_raw(&mut self, tau: [f64; N_JOINTS]) {
        self.apply_torque_and_step([tau[0], tau[1], tau[2], 0.0, 0.0, 0.0]);
    }
}
