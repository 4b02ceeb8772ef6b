//! Pictures of the arm reaching (`learner plot arm RUN_DIR`; docs/design.md §4.8): a
//! filmstrip PNG (side and top views at a few moments of the episode) and an animated GIF
//! (both views, every step), each overlaying the expert and the imitator at a few iterations.
//!
//! The links are drawn from forward kinematics (`ur5_shared::kinematics`) of the recorded
//! joint angles. A `learner train` run records no states of its noise-free episodes, only
//! the controller of every iteration (`iter_NNN_table.npz`) and the expert's
//! (`expert/expert_table.npz`): each is run again without exploration noise on hil-sim's
//! default arm at the demonstrations' task, which gives the noise-free episode of that
//! iteration's controller (the run's own evaluation episode when the run used the default arm).

use std::path::{Path, PathBuf};

use plotters::prelude::*;
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::kinematics::UrKinematics;
use ur5_shared::layout::StateLayout;

use crate::io::IoError;
use crate::plot::{register_font, write_png, PlotError, PALETTE};

type Result<T> = std::result::Result<T, PlotError>;

/// One arm to draw: a legend label and its chain points per step (m, base frame).
pub struct Motion {
    /// Legend text.
    pub label: String,
    /// Per step: base, 6 joint origins, end-effector point.
    pub chain: Vec<[[f64; 3]; 8]>,
}

/// The chain points of every state in `states` ((T, dX), row-major, layout `layout`) on the
/// arm of `sim` (a three-joint task's wrist at `sim.wrist_q`).
pub fn chain_of_states(
    states: &[f64],
    layout: &StateLayout,
    sim: &SimConfig,
) -> Vec<[[f64; 3]; 8]> {
    let k = UrKinematics::new(sim.model, sim.ee_offset);
    states
        .chunks(layout.dx())
        .map(|s| {
            let q = &s[layout.q()];
            let six = if q.len() >= 6 {
                core::array::from_fn(|j| q[j])
            } else {
                UrKinematics::six(&[q[0], q[1], q[2]], &sim.wrist_q)
            };
            k.chain_points(&six)
        })
        .collect()
}

/// The states of the noise-free episode of the gain table in `table_path` on a fresh arm of
/// `sim` at `task`.
pub fn rerun_table(table_path: &Path, task: &TaskConfig, sim: &SimConfig) -> Result<Vec<f64>> {
    let (mut table, _) =
        crate::io::table::load_table(table_path, &ur5_shared::GainBounds::default())
            .map_err(IoError::from)?;
    let mut arm = crate::arm::SimArm::for_task(sim.clone(), task)?;
    let ep = imitation::rollout::run_episode(&mut arm, task, &mut *table, None)?;
    Ok(ep.x)
}

/// The motions of the run in `dir`: the expert (`expert/expert_table.npz`, else the first
/// demonstration) and the controllers of up to `count` iterations evenly spread from the
/// first to the last `iter_NNN_table.npz`; and the goal (m) and control period (s).
pub fn run_motions(dir: &Path, demos: &Path, count: usize) -> Result<(Vec<Motion>, [f64; 3], f64)> {
    let sim = SimConfig::default();
    let d = crate::io::demos::load_checked(demos, &sim)?;
    let task = d.task()?;
    let mut motions = Vec::new();
    let expert_table = demos.with_file_name("expert_table.npz");
    let expert_states = if expert_table.is_file() {
        rerun_table(&expert_table, &task, &sim)?
    } else {
        d.states[..d.horizon * task.layout().dx()].to_vec()
    };
    motions.push(Motion {
        label: "expert".into(),
        chain: chain_of_states(&expert_states, &task.layout(), &sim),
    });
    let mut iters: Vec<(usize, PathBuf)> = std::fs::read_dir(dir)
        .map_err(IoError::file("reading", dir))?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let n = name
                .strip_prefix("iter_")?
                .strip_suffix("_table.npz")?
                .parse()
                .ok()?;
            Some((n, e.path()))
        })
        .collect();
    iters.sort();
    if iters.is_empty() {
        return Err(PlotError::NoTables {
            dir: dir.to_owned(),
        });
    }
    let n = count.clamp(1, iters.len());
    let mut picked: Vec<usize> = (0..n)
        .map(|i| {
            if n == 1 {
                iters.len() - 1
            } else {
                i * (iters.len() - 1) / (n - 1)
            }
        })
        .collect();
    picked.dedup();
    for i in picked {
        let (k, path) = &iters[i];
        motions.push(Motion {
            label: format!("imitator, {k} iterations"),
            chain: chain_of_states(&rerun_table(path, &task, &sim)?, &task.layout(), &sim),
        });
    }
    Ok((motions, d.goal, d.dt))
}

/// Side (x–z) or top (x–y) view.
#[derive(Clone, Copy)]
enum View {
    Side,
    Top,
}

impl View {
    fn project(self, p: &[f64; 3]) -> (f64, f64) {
        match self {
            View::Side => (p[0], p[2]),
            View::Top => (p[0], p[1]),
        }
    }
    fn name(self) -> &'static str {
        match self {
            View::Side => "side (x, z)",
            View::Top => "top (x, y)",
        }
    }
}

fn colour(i: usize) -> RGBColor {
    if i == 0 {
        RGBColor(0, 0, 0)
    } else {
        PALETTE[(i - 1) % PALETTE.len()]
    }
}

fn err<E: std::fmt::Display>(e: E) -> PlotError {
    PlotError::Arm(e.to_string())
}

/// Square axis ranges (m) holding every point of every motion and the goal in `view`.
fn extent(
    motions: &[Motion],
    goal: &[f64; 3],
    view: View,
) -> (std::ops::Range<f64>, std::ops::Range<f64>) {
    let pts = motions
        .iter()
        .flat_map(|m| m.chain.iter().flatten())
        .chain(std::iter::once(goal))
        .map(|p| view.project(p));
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for (x, y) in pts {
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    let half = 0.55 * (x1 - x0).max(y1 - y0).max(0.1);
    let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    (cx - half..cx + half, cy - half..cy + half)
}

/// Draws every motion at step `t` (its end-effector trail up to `t` thin, the links thick)
/// and the goal (red cross) in `view` into `area`.
fn draw_view<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    motions: &[Motion],
    goal: &[f64; 3],
    view: View,
    t: usize,
    title: &str,
    legend: bool,
) -> Result<()> {
    let (xr, yr) = extent(motions, goal, view);
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 14))
        .margin(6)
        .x_label_area_size(22)
        .y_label_area_size(34)
        .build_cartesian_2d(xr, yr)
        .map_err(err)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_labels(4)
        .y_labels(4)
        .label_style(("sans-serif", 10))
        .draw()
        .map_err(err)?;
    for (i, m) in motions.iter().enumerate() {
        let c = colour(i);
        let k = t.min(m.chain.len() - 1);
        let trail: Vec<(f64, f64)> = m.chain[..=k].iter().map(|p| view.project(&p[7])).collect();
        chart
            .draw_series(LineSeries::new(trail, c.mix(0.5).stroke_width(1)))
            .map_err(err)?;
        let links: Vec<(f64, f64)> = m.chain[k].iter().map(|p| view.project(p)).collect();
        let s = chart
            .draw_series(LineSeries::new(links.clone(), c.stroke_width(3)))
            .map_err(err)?;
        if legend {
            s.label(&m.label).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 14, y)], c.stroke_width(3))
            });
        }
        chart
            .draw_series(links.iter().map(|p| Circle::new(*p, 2, c.filled())))
            .map_err(err)?;
    }
    let g = view.project(goal);
    chart
        .draw_series(std::iter::once(Cross::new(g, 6, RED.stroke_width(2))))
        .map_err(err)?;
    if legend {
        chart
            .configure_series_labels()
            .label_font(("sans-serif", 10))
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperLeft)
            .draw()
            .map_err(err)?;
    }
    Ok(())
}

/// Steps of the filmstrip: `frames` moments from the first step to the last, quadratically
/// spaced (step (i / (n − 1))² (T − 1)), denser early where the arm moves most.
fn moments(horizon: usize, frames: usize) -> Vec<usize> {
    let n = frames.clamp(1, horizon);
    let mut v: Vec<usize> = (0..n)
        .map(|i| {
            if n == 1 {
                horizon - 1
            } else {
                let f = i as f64 / (n - 1) as f64;
                (f * f * (horizon - 1) as f64).round() as usize
            }
        })
        .collect();
    v.dedup();
    v
}

/// The filmstrip PNG: a column per moment ([`moments`], up to `frames` of them), side view above,
/// top view below; 240 px per panel.
pub fn filmstrip(
    path: &Path,
    motions: &[Motion],
    goal: &[f64; 3],
    dt: f64,
    frames: usize,
) -> Result<()> {
    register_font()?;
    let horizon = motions.iter().map(|m| m.chain.len()).max().unwrap_or(1);
    let ts = moments(horizon, frames);
    let (w, h) = (240 * ts.len() as u32, 480u32);
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let cells = root.split_evenly((2, ts.len()));
        for (i, t) in ts.iter().enumerate() {
            let time = format!("t = {:.1} s", *t as f64 * dt);
            draw_view(
                &cells[i],
                motions,
                goal,
                View::Side,
                *t,
                &format!("{time}, side"),
                i == 0,
            )?;
            draw_view(
                &cells[ts.len() + i],
                motions,
                goal,
                View::Top,
                *t,
                &format!("{time}, top"),
                false,
            )?;
        }
        root.present().map_err(err)?;
    }
    write_png(path, w, h, &rgb)
}

/// The animated GIF: side and top views side by side, one frame per `stride` steps, `dt`
/// × `stride` apart (at least 2 cs), the last frame held for a second; 640 × 320 px.
pub fn animation(
    path: &Path,
    motions: &[Motion],
    goal: &[f64; 3],
    dt: f64,
    stride: usize,
) -> Result<()> {
    register_font()?;
    let horizon = motions.iter().map(|m| m.chain.len()).max().unwrap_or(1);
    let (w, h) = (640u16, 320u16);
    let file = std::fs::File::create(path).map_err(IoError::file("cannot create", path))?;
    let mut enc = gif::Encoder::new(std::io::BufWriter::new(file), w, h, &[]).map_err(err)?;
    enc.set_repeat(gif::Repeat::Infinite).map_err(err)?;
    let steps: Vec<usize> = (0..horizon)
        .step_by(stride.max(1))
        .chain(std::iter::once(horizon - 1))
        .collect();
    let delay = ((dt * stride.max(1) as f64 * 100.0).round() as u16).max(2);
    for (i, t) in steps.iter().enumerate() {
        let mut rgb = vec![255u8; w as usize * h as usize * 3];
        {
            let root =
                BitMapBackend::with_buffer(&mut rgb, (w as u32, h as u32)).into_drawing_area();
            root.fill(&WHITE).map_err(err)?;
            let (l, r) = root.split_horizontally(w as u32 / 2);
            let time = format!("t = {:.1} s", *t as f64 * dt);
            for (area, view, legend) in [(&l, View::Side, true), (&r, View::Top, false)] {
                draw_view(
                    area,
                    motions,
                    goal,
                    view,
                    *t,
                    &format!("{time}, {}", view.name()),
                    legend,
                )?;
            }
            root.present().map_err(err)?;
        }
        let mut frame = gif::Frame::from_rgb_speed(w, h, &rgb, 20);
        frame.delay = if i + 1 == steps.len() { 100 } else { delay };
        enc.write_frame(&frame).map_err(err)?;
    }
    Ok(())
}
