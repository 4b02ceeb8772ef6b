//! Conformance with the GPS reference vectors (copies in tests/data/gps-vectors).

use gps::conformance::{run_file, run_value, Status};

fn data(name: &str) -> String {
    format!(
        "{}/tests/data/gps-vectors/{name}",
        env!("CARGO_MANIFEST_DIR")
    )
}

fn assert_conforms(name: &str, min_pass: usize) {
    let rep = run_file(&data(name)).expect("vectors file loads");
    let failed: Vec<_> = rep
        .lines
        .iter()
        .filter(|l| l.status == Status::Fail)
        .collect();
    assert!(failed.is_empty(), "{}", rep.to_text());
    // Guard against a runner that silently skips everything.
    assert!(rep.count(Status::Pass) >= min_pass, "{}", rep.to_text());
    assert_passing_lines(
        &rep,
        &[
            "new_controller.K",
            "dgd_trace.attempt_etas",
            "gmm.ll_trace",
            "dynamics.Fm (recorded prior)",
            "x0sigma",
        ],
    );
}

/// Each of `keys` ends the name of a passing line of `rep`.
fn assert_passing_lines(rep: &gps::conformance::Report, keys: &[&str]) {
    for key in keys {
        assert!(
            rep.lines
                .iter()
                .any(|l| l.name.ends_with(key) && l.status == Status::Pass),
            "no passing line for {key}:\n{}",
            rep.to_text()
        );
    }
}

#[test]
fn problem_a_conforms() {
    assert_conforms("problem_A.json", 170);
}

#[test]
fn problem_b_conforms() {
    assert_conforms("problem_B.json", 150);
}

/// The held-out layout may have null or absent fields; those must be skipped, not failed.
#[test]
fn absent_fields_are_skipped_not_failed() {
    let text = std::fs::read_to_string(data("problem_B.json")).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["iterations"][1]["inputs"]["cost_derivs_per_sample"] = serde_json::Value::Null;
    v["iterations"][0]["outputs"]
        .as_object_mut()
        .unwrap()
        .remove("prev_forward");
    for c in v["unit"]["backward_fixed_eta"]["cases"]
        .as_array_mut()
        .unwrap()
    {
        c.as_object_mut().unwrap().remove("forward");
    }
    let rep = run_value(&v).unwrap();
    assert!(rep.all_pass(), "{}", rep.to_text());
    let skipped: Vec<&str> = rep
        .lines
        .iter()
        .filter(|l| l.status == Status::Skipped)
        .map(|l| l.name.as_str())
        .collect();
    assert!(skipped.contains(&"iter1.cost"), "{skipped:?}");
    assert!(skipped.contains(&"iter0.prev_forward.mu"), "{skipped:?}");
    assert!(
        skipped
            .iter()
            .any(|s| s.ends_with("forward.sigma") && s.starts_with("unit.backward_fixed_eta")),
        "{skipped:?}"
    );
}

/// A wrong recorded value must fail (the runner can fail).
#[test]
fn corrupted_output_fails() {
    let text = std::fs::read_to_string(data("problem_A.json")).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let x = v["iterations"][0]["outputs"]["new_controller"]["K"][3][1][2]
        .as_f64()
        .unwrap();
    v["iterations"][0]["outputs"]["new_controller"]["K"][3][1][2] =
        serde_json::json!(x * (1.0 + 1e-7));
    let rep = run_value(&v).unwrap();
    let l = rep
        .lines
        .iter()
        .find(|l| l.name == "iter0.new_controller.K")
        .unwrap();
    assert_eq!(l.status, Status::Fail, "{}", rep.to_text());
}

/// PI2 and PILQR against GPS's recorded `TrajOptPILQR.update`, `approximated_cost`, the
/// `res_percent` step rule and `update_pi2` (vectors from `make_pilqr_vectors.py`).
fn assert_pilqr_conforms(name: &str) {
    let rep = run_file(&data(name)).expect("vectors file loads");
    assert!(rep.all_pass(), "{}", rep.to_text());
    assert_passing_lines(
        &rep,
        &[
            "approximated_cost.predicted_cost",
            "pilqr_update.lqr_controller.K",
            "pilqr_update.residual_cost",
            "pilqr_update.controller (GPS temperatures).k",
            "pilqr_update.controller (fitted temperatures).k",
            "dual at ours <= dual at GPS's",
            "step_rule_res_percent[3].step_mult_after",
            "pi2_update[4].chol_cov_new",
        ],
    );
}

#[test]
fn pilqr_a_conforms() {
    assert_pilqr_conforms("pilqr_A.json");
}

#[test]
fn pilqr_b_conforms() {
    assert_pilqr_conforms("pilqr_B.json");
}
