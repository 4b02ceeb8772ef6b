//! The simulated arm's state: joint angles and velocities, the flange's frame, observations
//! (true and as measured), gravity torques and joint accelerations, read from the multibody
//! (conventions as in [`super`]).

use super::*;

impl Ur5Sim {
    /// World direction of active joint `j`'s axis.
    pub(super) fn axis_world(&self, j: usize, child: &RigidBody) -> Vec3 {
        child.position().rotation * self.dofs[j].axis_in_child
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

    /// True position (m) and linear velocity (m/s), base frame, of the tool point `offset`
    /// (m, end-effector link frame, added to `sim.ee_offset`): the end-effector point at offset
    /// 0. From the multibody's link pose (f32) and the body Jacobian of the carrier link: the
    /// Jacobian gives the carrier's centre-of-mass velocity v and angular velocity ω; the
    /// point moves at v + ω × (p − c).
    fn tool_point(&self, offset: &[f64; 3], qd: &[f64; MAX_JOINTS]) -> ([f64; 3], [f64; 3]) {
        let mb = self.multibody();
        let pose = *mb.link(self.ee_link).expect("ee link").local_to_world();
        let local = if *offset == [0.0; 3] {
            self.ee_point
        } else {
            let o = &self.cfg.ee_offset;
            let p = self.ee_frame
                * nalgebra::Point3::new(o[0] + offset[0], o[1] + offset[1], o[2] + offset[2]);
            Vec3::new(p.x as f32, p.y as f32, p.z as f32)
        };
        let ee = pose.transform_point(local);
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
        let r = [
            (ee.x - com.x) as f64,
            (ee.y - com.y) as f64,
            (ee.z - com.z) as f64,
        ];
        let vel = [
            v[0] + w[1] * r[2] - w[2] * r[1],
            v[1] + w[2] * r[0] - w[0] * r[2],
            v[2] + w[0] * r[1] - w[1] * r[0],
        ];
        ([ee.x as f64, ee.y as f64, ee.z as f64], vel)
    }

    /// True positions (m, base frame) of the tool points at `offsets` (m, end-effector link
    /// frame, relative to the end-effector point), into `out` (one per offset).
    pub fn true_points(&self, offsets: &[[f64; 3]], out: &mut [[f64; 3]]) {
        let (_, qd) = self.joint_state_all();
        for (o, p) in offsets.iter().zip(out.iter_mut()) {
            *p = self.tool_point(o, &qd).0;
        }
    }

    /// The true observation (no sensor noise).
    pub fn true_observation(&self) -> Observation {
        let (q, qd) = self.joint_state_all();
        let (ee_pos, ee_vel) = self.tool_point(&[0.0; 3], &qd);
        Observation {
            q: first3(&q),
            qd: first3(&qd),
            ee_pos,
            ee_vel,
        }
    }

    /// What the arm's sensors report: the true observation plus the configured sensor noise.
    pub fn observe(&mut self) -> Observation {
        let mut o = self.true_observation();
        let (mut points, mut velocities) = ([o.ee_pos], [o.ee_vel]);
        self.add_sensor_noise(&mut o.q, &mut o.qd, &mut points, &mut velocities);
        (o.ee_pos, o.ee_vel) = (points[0], velocities[0]);
        o
    }

    /// What the sensors report for a task: the angles `q` and velocities `qd` of every active
    /// joint ([`Ur5Sim::joints`] each), and the positions (m) and linear velocities (m/s),
    /// base frame, of the tool points at `offsets` (m, end-effector link frame, relative to the
    /// end-effector point; one per entry of `points` and `velocities`), with the configured
    /// sensor noise drawn in that order (joints, then points: for three joints and the one
    /// point at offset 0 the draws of [`Ur5Sim::observe`]).
    pub fn observe_points(
        &mut self,
        offsets: &[[f64; 3]],
        q: &mut [f64],
        qd: &mut [f64],
        points: &mut [[f64; 3]],
        velocities: &mut [[f64; 3]],
    ) {
        self.check_len(q.len());
        self.check_len(qd.len());
        assert!(offsets.len() == points.len() && offsets.len() == velocities.len());
        let (q_all, qd_all) = self.joint_state_all();
        q.copy_from_slice(&q_all[..self.n]);
        qd.copy_from_slice(&qd_all[..self.n]);
        for ((o, p), v) in offsets
            .iter()
            .zip(points.iter_mut())
            .zip(velocities.iter_mut())
        {
            (*p, *v) = self.tool_point(o, &qd_all);
        }
        self.add_sensor_noise(q, qd, points, velocities);
    }

    /// Adds the configured sensor noise, in this order: angles, velocities, points, point
    /// velocities (each value one `StandardNormal` draw when its level is > 0).
    fn add_sensor_noise(
        &mut self,
        q: &mut [f64],
        qd: &mut [f64],
        points: &mut [[f64; 3]],
        velocities: &mut [[f64; 3]],
    ) {
        let p = &self.cfg.perturbation;
        let (sq, sqd, see) = (
            p.sensor_noise_q_std,
            p.sensor_noise_qd_std,
            p.sensor_noise_ee_std,
        );
        let mut draw = |vals: &mut [f64], std: f64| {
            if std > 0.0 {
                for v in vals.iter_mut() {
                    let n: f64 = StandardNormal.sample(&mut self.rng);
                    *v += std * n;
                }
            }
        };
        draw(q, sq);
        draw(qd, sqd);
        draw(points.as_flattened_mut(), see);
        draw(velocities.as_flattened_mut(), see);
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
