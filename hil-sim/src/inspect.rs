//! `hil-sim inspect`: the model at one state, as one JSON object (for checking a URDF, and the
//! flange's pose as UR's p[x, y, z, rx, ry, rz]).

use std::path::PathBuf;

use anyhow::Result;
use ur5_shared::config::SimConfig;
use ur5_shared::UrModel;

use hil_sim::Ur5Sim;

/// One value per joint, 3 or 6 (one command-line argument).
#[derive(Clone, Debug)]
pub struct JointValues(Vec<f64>);

/// Comma-separated joint values: 3 or 6 finite numbers.
pub fn parse_joints(s: &str) -> Result<JointValues, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>().map_err(|e| format!("`{x}`: {e}")))
        .collect::<Result<_, _>>()?;
    if v.len() != 3 && v.len() != 6 {
        return Err(format!(
            "expected 3 or 6 comma-separated numbers, got {}",
            v.len()
        ));
    }
    if v.iter().any(|x| !x.is_finite()) {
        return Err("values must be finite".into());
    }
    Ok(JointValues(v))
}

/// `hil-sim inspect`: one JSON object describing the model at the state (q, q̇, τ).
pub fn inspect(
    model: UrModel,
    q: JointValues,
    qd: Option<JointValues>,
    tau: Option<JointValues>,
    substep: f64,
    urdf: Option<PathBuf>,
) -> Result<()> {
    let q = q.0;
    let n = q.len();
    let qd = qd.map_or_else(|| vec![0.0; n], |v| v.0);
    let tau = tau.map_or_else(|| vec![0.0; n], |v| v.0);
    anyhow::ensure!(
        qd.len() == n && tau.len() == n,
        "--q has {n} values, --qd {} and --tau {}: give as many of each",
        qd.len(),
        tau.len()
    );
    let sim_cfg = SimConfig {
        urdf,
        physics_dt: substep,
        substeps: 1,
        ..SimConfig::for_model(model)
    };
    let mut sim = Ur5Sim::with_joints(sim_cfg, substep, n)?;
    // Every input within the arm's limits, so that every output is a number.
    for j in 0..n {
        let l = sim.model().joint(j);
        let name = &l.name;
        anyhow::ensure!(
            q[j] >= l.lower && q[j] <= l.upper,
            "--q: joint `{name}` at {:?} rad is outside its limits [{}, {}]",
            q[j],
            l.lower,
            l.upper
        );
        anyhow::ensure!(
            qd[j].abs() <= l.velocity,
            "--qd: joint `{name}` at {:?} rad/s is beyond its speed limit {} rad/s",
            qd[j],
            l.velocity
        );
        anyhow::ensure!(
            tau[j].abs() <= l.effort,
            "--tau: joint `{name}` at {:?} N·m is beyond its effort limit {} N·m",
            tau[j],
            l.effort
        );
    }
    sim.set_joint_state_all(&q, &qd);
    let obs = sim.true_observation();
    let (q6, _) = sim.arm_joints();
    let flange = hil_sim::sim::ur_pose(&sim.ee_frame_pose());
    let qdd = sim.joint_acceleration_all(&q, &qd, &tau)[..n].to_vec();
    anyhow::ensure!(
        obs.ee_pos.iter().chain(&obs.ee_vel).chain(&qdd).chain(&flange).all(|v| v.is_finite()),
        "the model gives non-finite results at this state (ee_pos {:?}, ee_vel {:?}, qdd {:?}): check the URDF's inertias and origins",
        obs.ee_pos,
        obs.ee_vel,
        qdd
    );
    let m = sim.model();
    println!(
        "{}",
        serde_json::json!({
            "model": model.name(), "joints": n, "q": q6, "ee_pos": obs.ee_pos, "ee_vel": obs.ee_vel,
            "flange_pose": flange, "qdd": qdd, "wrist_q": m.wrist_q,
            "wrist_joints": m.wrist_joints, "ee_link": m.ee_link, "ee_offset": m.ee_offset,
            "urdf": m.source.display().to_string(),
        })
    );
    Ok(())
}
