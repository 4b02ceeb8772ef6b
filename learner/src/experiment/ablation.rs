//! The ablation's variants: LQR+GAIfO's settings with one decision for precision undone
//! ([`ABLATION_VARIANTS`]) or one candidate applied ([`PRECISION_VARIANTS`]), by name.

use imitation::gaifo::GaifoConfig;

use super::ExperimentError;

/// The ablation's variants: `lqr_gaifo` as configured (`default`), and the same with the
/// critic decisions of docs/design.md §5 D25 and D36 undone one at a time.
pub const ABLATION_VARIANTS: [(&str, &str); 5] = [
    ("default", "LQR+GAIfO as configured"),
    (
        "no-near-goal",
        "critic inputs ee − goal not warped (near_goal_scale = 0, before D36)",
    ),
    (
        "raw-penalty",
        "gradient penalty on the raw-unit gradient ‖∇ₓD‖, inputs not warped (before D25)",
    ),
    (
        "constant-critic-lr",
        "critic learning rate kept at its start value (no half-life)",
    ),
    (
        "before-d25",
        "raw-unit penalty, critic learning rate 1e-3, constant: the critic before D25",
    ),
];

/// Candidates for steady precision near the goal (docs/design.md §5 D36), run with
/// `ablation_variants` beside `default`; not in the default list.
pub const PRECISION_VARIANTS: [(&str, &str); 12] = [
    (
        "near-goal-1cm-keep-raw",
        "critic inputs ee − goal warped, c = 1 cm, and also fed raw (six more inputs)",
    ),
    (
        "near-goal-2cm-keep-raw",
        "critic inputs ee − goal warped, c = 2 cm, and also fed raw (six more inputs)",
    ),
    (
        "near-goal-1cm",
        "critic inputs ee − goal warped as c·asinh(x/c), c = 1 cm",
    ),
    (
        "near-goal-2cm",
        "critic inputs ee − goal warped as c·asinh(x/c), c = 2 cm",
    ),
    (
        "near-goal-3cm",
        "critic inputs ee − goal warped as c·asinh(x/c), c = 3 cm",
    ),
    (
        "near-goal-1cm-far-0.2",
        "critic inputs ee − goal warped as 0.2·x + 0.8·c·asinh(x/c), c = 1 cm",
    ),
    (
        "critic-half-life-10",
        "critic learning rate halved every 10 iterations (40 by default)",
    ),
    ("kl-step-half", "KL step ε/T halved (0.1 instead of 0.2)"),
    (
        "critic-half-life-25",
        "critic learning rate halved every 25 iterations (the default before D37)",
    ),
    (
        "critic-half-life-60",
        "critic learning rate halved every 60 iterations (40 by default)",
    ),
    (
        "critic-average-0.5",
        "cost from the critic's running weight average, β = 0.5",
    ),
    (
        "critic-average-0.8",
        "cost from the critic's running weight average, β = 0.8",
    ),
];

/// `base` changed as ablation variant `name` says ([`ABLATION_VARIANTS`],
/// [`PRECISION_VARIANTS`]).
pub fn ablation_variant(name: &str, base: &GaifoConfig) -> Result<GaifoConfig, ExperimentError> {
    use imitation::discriminator::PenaltySpace;
    let mut c = base.clone();
    match name {
        "default" => {}
        "no-near-goal" => {
            c.discriminator.near_goal_scale = 0.0;
            c.discriminator.near_goal_keep_raw = false;
        }
        // The warp needs the penalty in normalised inputs, so undoing D25 undoes D36 too.
        "raw-penalty" => {
            c.discriminator.penalty_space = PenaltySpace::Raw;
            c.discriminator.near_goal_scale = 0.0;
            c.discriminator.near_goal_keep_raw = false;
        }
        "constant-critic-lr" => c.critic_lr_half_life = 0.0,
        "before-d25" => {
            c.discriminator.adam.lr = 1e-3;
            c.discriminator.penalty_space = PenaltySpace::Raw;
            c.discriminator.near_goal_scale = 0.0;
            c.discriminator.near_goal_keep_raw = false;
            c.critic_lr_half_life = 0.0;
        }
        "near-goal-1cm" | "near-goal-2cm" | "near-goal-3cm" => {
            c.discriminator.near_goal_scale = match name {
                "near-goal-1cm" => 0.01,
                "near-goal-2cm" => 0.02,
                _ => 0.03,
            };
            c.discriminator.near_goal_keep_raw = false;
        }
        "near-goal-1cm-far-0.2" => {
            c.discriminator.near_goal_scale = 0.01;
            c.discriminator.near_goal_far_slope = 0.2;
            c.discriminator.near_goal_keep_raw = false;
        }
        "near-goal-1cm-keep-raw" => {
            c.discriminator.near_goal_scale = 0.01;
            c.discriminator.near_goal_keep_raw = true;
        }
        "near-goal-2cm-keep-raw" => {
            c.discriminator.near_goal_scale = 0.02;
            c.discriminator.near_goal_keep_raw = true;
        }
        "critic-half-life-10" => c.critic_lr_half_life = 10.0,
        "critic-half-life-25" => c.critic_lr_half_life = 25.0,
        "critic-half-life-60" => c.critic_lr_half_life = 60.0,
        "kl-step-half" => c.algorithm.kl_step *= 0.5,
        "critic-average-0.5" => c.discriminator.param_average = 0.5,
        "critic-average-0.8" => c.discriminator.param_average = 0.8,
        _ => {
            return Err(ExperimentError::Settings(format!(
                "unknown ablation variant `{name}`; known: {}",
                ABLATION_VARIANTS
                    .iter()
                    .chain(&PRECISION_VARIANTS)
                    .map(|(n, _)| *n)
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
            .into())
        }
    }
    Ok(c)
}
