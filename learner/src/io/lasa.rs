//! The LASA handwriting dataset (Khansari-Zadeh and Billard 2011) as tool-path
//! demonstrations (docs/design.md §4.18): the standard benchmark of learning motions from
//! demonstration, 2-D shapes drawn 7 times each, every drawing ending at the origin.
//!
//! The 26 single-pattern shapes are built into the program
//! (`learner/assets/lasa/lasa_handwriting.npz`, converted by `scripts/lasa/convert.py`, its
//! provenance and licence in `learner/assets/lasa/README.md`): positions in mm as in the source,
//! 201 of each drawing's 1000 samples, numbers unchanged. A [`Placement`] puts a shape in the
//! arm's workspace: a plane, the point where the shape ends, its size and duration, and for the
//! whole arm the tool's orientation, held along the drawing (a pen at a fixed angle to the
//! page); the result is a set of [`ToolPath`]s, written as a tool-path CSV file
//! ([`write_csv`]) that `--demos` takes.

use std::path::Path;

use super::npz::NpzFile;
use ur5_shared::ik::UrIk;
use ur5_shared::kinematics::UrKinematics;
use ur5_shared::UrModel;

use super::tool_path::{ToolPath, COLUMNS, ROTATION_COLUMNS};
use super::IoError;
use crate::error::ensure;

/// The converted dataset, built into the program.
const FILE: &[u8] = include_bytes!("../../assets/lasa/lasa_handwriting.npz");

/// The 26 single-pattern shapes, in the dataset's names (the four `Multi_Models_*` shapes,
/// whose drawings start in separate regions, are not included: an arm starts every episode
/// from one pose).
pub const SHAPES: [&str; 26] = [
    "Angle",
    "BendedLine",
    "CShape",
    "DoubleBendedLine",
    "GShape",
    "JShape",
    "JShape_2",
    "Khamesh",
    "LShape",
    "Leaf_1",
    "Leaf_2",
    "Line",
    "NShape",
    "PShape",
    "RShape",
    "Saeghe",
    "Sharpc",
    "Sine",
    "Snake",
    "Spoon",
    "Sshape",
    "Trapezoid",
    "WShape",
    "Worm",
    "Zshape",
    "heee",
];

/// One shape's drawings as in the dataset.
#[derive(Clone, Debug, PartialEq)]
pub struct Shape {
    /// The shape's name.
    pub name: &'static str,
    /// Per drawing: sample times (s).
    pub t: Vec<Vec<f64>>,
    /// Per drawing: positions (mm), ending at (0, 0).
    pub pos: Vec<Vec<[f64; 2]>>,
}

/// The shape `name` (one of [`SHAPES`], case-insensitive).
pub fn shape(name: &str) -> Result<Shape, IoError> {
    let here = Path::new("lasa_handwriting.npz");
    let Some(name) = SHAPES.iter().find(|s| s.eq_ignore_ascii_case(name.trim())) else {
        return Err(IoError::content(
            here,
            format!(
                "no LASA shape `{name}`; the shapes are {}",
                SHAPES.join(", ")
            ),
        ));
    };
    let f = NpzFile::from_bytes(here, FILE)?;
    let (shape, pos) = f.f64(&format!("{name}_pos"))?;
    let (tshape, t) = f.f64(&format!("{name}_t"))?;
    ensure!(
        shape.len() == 3 && shape[2] == 2 && tshape == shape[..2],
        IoError::content(here, format!("{name}: shapes {shape:?} and {tshape:?}"))
    );
    let (d, n) = (shape[0] as usize, shape[1] as usize);
    Ok(Shape {
        name,
        t: t.chunks(n).map(<[f64]>::to_vec).collect(),
        pos: (0..d)
            .map(|i| {
                (0..n)
                    .map(|k| [pos[(i * n + k) * 2], pos[(i * n + k) * 2 + 1]])
                    .collect()
            })
            .collect(),
    })
}

/// The plane a shape is drawn in; the shape's x axis along its first axis, y along its
/// second.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Plane {
    /// Vertical, facing the arm: the shape's x to the right seen from the base towards the
    /// shape's end, its y up.
    Facing,
    /// The base frame's x–z plane (x, then z up).
    Xz,
    /// The base frame's y–z plane (y, then z up).
    Yz,
    /// Horizontal: the base frame's x–y plane.
    Xy,
}

/// Where and how a shape is drawn in the arm's workspace.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    /// The plane.
    pub plane: Plane,
    /// Where every drawing ends (m, base frame): the task's goal.
    pub end: [f64; 3],
    /// The shape's larger extent, over all its drawings (m).
    pub size: f64,
    /// The drawings' mean duration (s); each keeps its pace relative to the others.
    pub duration: f64,
    /// The tool's orientation at every sample (rotation vector, rad, base frame, UR's
    /// convention), or none: the drawings give the tool point alone (enough for three joints;
    /// six joints need it, e.g. [`held_rotation`]).
    pub rotation: Option<[f64; 3]>,
}

/// The orientation (rotation vector, rad, base frame) of the tool of `model` with its tool
/// point at `end` (m) and its wrist locked at the home posture ([`UrModel::default_wrist_q`]),
/// on the branch nearest the model's default start: the orientation a three-joint arm
/// ends a drawing with, the default a whole arm holds along it.
pub fn held_rotation(
    model: UrModel,
    ee_offset: [f64; 3],
    end: [f64; 3],
) -> Result<[f64; 3], String> {
    let wrist = model.default_wrist_q();
    let q = UrIk::new(model, ee_offset)
        .nearest_point(end, wrist, &model.default_start_q())
        .map_err(|e| {
            format!("the tool at the shape's end {end:?} m with the wrist at its home posture: {e}")
        })?;
    let pose = UrKinematics::new(model, ee_offset).tool_pose(&UrKinematics::six(&q, &wrist));
    Ok(ur5_shared::pose::rotation_vector(&pose.rotation))
}

impl Placement {
    /// The plane's two axes (unit vectors, base frame).
    pub fn axes(&self) -> Result<([f64; 3], [f64; 3]), String> {
        Ok(match self.plane {
            Plane::Facing => {
                let r = self.end[0].hypot(self.end[1]);
                if r < 1e-6 {
                    return Err(
                        "the shape's end is on the base's axis: no plane faces the arm there; \
                         choose --plane xz, yz or xy"
                            .into(),
                    );
                }
                let (x, y) = (self.end[0] / r, self.end[1] / r);
                // (x, y, 0) × z: to the right seen from the base.
                ([y, -x, 0.0], [0.0, 0.0, 1.0])
            }
            Plane::Xz => ([1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
            Plane::Yz => ([0.0, 1.0, 0.0], [0.0, 0.0, 1.0]),
            Plane::Xy => ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
        })
    }
}

/// `shape` placed by `placement`: one tool path a drawing, episodes numbered from 0.
pub fn place(shape: &Shape, placement: &Placement) -> Result<Vec<ToolPath>, String> {
    if !(placement.size > 0.0 && placement.size.is_finite())
        || !(placement.duration > 0.0 && placement.duration.is_finite())
        || placement.end.iter().any(|v| !v.is_finite())
    {
        return Err(format!(
            "size {} m and duration {} s must be positive, the end finite",
            placement.size, placement.duration
        ));
    }
    if placement
        .rotation
        .is_some_and(|r| r.iter().any(|v| !v.is_finite()))
    {
        return Err(format!(
            "the tool's rotation {:?} must be finite",
            placement.rotation
        ));
    }
    let (u, v) = placement.axes()?;
    let all = shape.pos.iter().flatten();
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in all {
        for r in 0..2 {
            lo[r] = lo[r].min(p[r]);
            hi[r] = hi[r].max(p[r]);
        }
    }
    let scale = placement.size / (hi[0] - lo[0]).max(hi[1] - lo[1]);
    let mean_duration = shape
        .t
        .iter()
        .map(|t| t.last().expect("samples") - t[0])
        .sum::<f64>()
        / shape.t.len() as f64;
    let time_scale = placement.duration / mean_duration;
    Ok(shape
        .pos
        .iter()
        .zip(&shape.t)
        .enumerate()
        .map(|(e, (pos, t))| ToolPath {
            episode: e as u64,
            t: t.iter().map(|x| (x - t[0]) * time_scale).collect(),
            points: pos
                .iter()
                .map(|p| {
                    core::array::from_fn(|r| placement.end[r] + scale * (p[0] * u[r] + p[1] * v[r]))
                })
                .collect(),
            rotations: placement.rotation.map(|r| vec![r; pos.len()]),
        })
        .collect())
}

/// Writes tool paths as a tool-path CSV file (`episode,t,x,y,z`, and `rx,ry,rz` when every
/// path has its orientations; shortest exact decimals).
pub fn write_csv(paths: &[ToolPath], out: &Path) -> Result<(), IoError> {
    let mut w = csv::Writer::from_path(out).map_err(IoError::csv("writing", out))?;
    let rotated = !paths.is_empty() && paths.iter().all(|p| p.rotations.is_some());
    let header = COLUMNS
        .iter()
        .chain(&ROTATION_COLUMNS[..if rotated { 3 } else { 0 }]);
    w.write_record(header)
        .map_err(IoError::csv("writing", out))?;
    for p in paths {
        for (k, (t, x)) in p.t.iter().zip(&p.points).enumerate() {
            let mut row = vec![p.episode.to_string(), format!("{t:?}")];
            row.extend(x.iter().map(|v| format!("{v:?}")));
            if let (true, Some(r)) = (rotated, &p.rotations) {
                row.extend(r[k].iter().map(|v| format!("{v:?}")));
            }
            w.write_record(&row).map_err(IoError::csv("writing", out))?;
        }
    }
    w.flush().map_err(IoError::file("writing", out))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every built-in shape reads: 7 drawings of 201 samples, ending at the origin, times
    /// increasing; the numbers are the source's (two values checked against the .mat file).
    #[test]
    fn every_shape_is_built_in_and_ends_at_the_origin() {
        for name in SHAPES {
            let s = shape(name).unwrap();
            assert_eq!(s.pos.len(), 7, "{name}");
            for (p, t) in s.pos.iter().zip(&s.t) {
                assert_eq!((p.len(), t.len()), (201, 201), "{name}");
                assert_eq!(p[200], [0.0, 0.0], "{name}");
                assert!(t.windows(2).all(|w| w[1] > w[0]), "{name}");
            }
        }
        // Sshape.mat, demonstration 1, sample 0: pos (36.71506531…, 41.03448476…) mm.
        let s = shape("sshape").unwrap();
        assert!(
            (s.pos[0][0][0] - 36.71506531).abs() < 1e-8,
            "{:?}",
            s.pos[0][0]
        );
        assert!((s.pos[0][0][1] - 41.03448476).abs() < 1e-8);
        let e = crate::error::line(&shape("Multi_Models_1").unwrap_err());
        assert!(e.contains("no LASA shape") && e.contains("Sshape"), "{e}");
    }

    #[test]
    fn a_placed_shape_ends_at_the_goal_with_its_size_and_duration() {
        let s = shape("Sshape").unwrap();
        let p = Placement {
            plane: Plane::Facing,
            end: [-0.45, -0.25, 0.25],
            size: 0.2,
            duration: 10.0,
            rotation: None,
        };
        let paths = place(&s, &p).unwrap();
        assert_eq!(paths.len(), 7);
        let mean_end: f64 = paths.iter().map(|p| *p.t.last().unwrap()).sum::<f64>() / 7.0;
        assert!((mean_end - 10.0).abs() < 1e-9, "{mean_end}");
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for path in &paths {
            assert_eq!(path.t[0], 0.0);
            let end = path.points.last().unwrap();
            assert!((0..3).all(|r| (end[r] - p.end[r]).abs() < 1e-12), "{end:?}");
            for q in &path.points {
                // In the vertical plane through the end, facing the base.
                let d = (q[0] - p.end[0]) * p.end[0] + (q[1] - p.end[1]) * p.end[1];
                assert!(d.abs() < 1e-12, "{q:?}");
                for r in 0..3 {
                    lo[r] = lo[r].min(q[r]);
                    hi[r] = hi[r].max(q[r]);
                }
            }
        }
        let horizontal = (hi[0] - lo[0]).hypot(hi[1] - lo[1]);
        let extent = horizontal.max(hi[2] - lo[2]);
        assert!((extent - 0.2).abs() < 1e-9, "{extent}");
        assert!(hi[2] > p.end[2] + 0.15, "the S rises above its end: {hi:?}");
        let bad = Placement {
            end: [0.0, 0.0, 0.5],
            ..p
        };
        assert!(place(&s, &bad).unwrap_err().contains("base's axis"));
    }

    /// A shape drawn by the whole arm: every sample carries the held orientation, the file
    /// reads back with it, and it solves into six-joint demonstrations whose tool ends at the
    /// drawings' end with that orientation; the default orientation is the three-joint arm's
    /// at the end (its forward kinematics there, within 1e-9).
    #[test]
    fn a_shape_held_at_one_orientation_becomes_six_joint_demonstrations() {
        use ur5_shared::config::SimConfig;
        use ur5_shared::layout::StateLayout;
        let model = UrModel::Ur5e;
        let end = model.default_goal();
        let r = held_rotation(model, [0.0; 3], end).unwrap();
        let wrist = model.default_wrist_q();
        let q = UrIk::new(model, [0.0; 3])
            .nearest_point(end, wrist, &model.default_start_q())
            .unwrap();
        let kin = UrKinematics::new(model, [0.0; 3]);
        let pose = kin.tool_pose(&UrKinematics::six(&q, &wrist));
        let back = ur5_shared::ik::pose_from_rotation_vector(end, r);
        assert!(pose.rotation.angle_to(&back.rotation) < 1e-9);
        let p = Placement {
            plane: Plane::Facing,
            end,
            size: 0.2,
            duration: 10.0,
            rotation: Some(r),
        };
        let paths = place(&shape("Worm").unwrap(), &p).unwrap();
        assert!(paths
            .iter()
            .all(|p| p.rotations.as_ref().unwrap() == &vec![r; p.t.len()]));
        let dir = std::env::temp_dir().join(format!("lasa-held-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("worm.csv");
        write_csv(&paths, &file).unwrap();
        let text = std::fs::read_to_string(&file).unwrap();
        assert!(
            text.starts_with("episode,t,x,y,z,rx,ry,rz\n"),
            "{}",
            &text[..40]
        );
        assert_eq!(super::super::tool_path::read(&file).unwrap(), paths);
        let sim = SimConfig {
            model,
            ..SimConfig::default()
        };
        let six = super::super::tool_path::solve(
            &paths,
            &sim,
            StateLayout::of_task(6, false).unwrap(),
            0.1,
        )
        .unwrap();
        let layout = StateLayout::of_task(6, false).unwrap();
        let (t, dx) = (six.horizon, layout.dx());
        let mut ends = Vec::new();
        for d in 0..paths.len() {
            let x = &six.states[(d * t + t - 1) * dx..(d * t + t) * dx];
            let q6: [f64; 6] = x[layout.q()].try_into().unwrap();
            let pose = kin.tool_pose(&q6);
            assert!(pose.rotation.angle_to(&back.rotation) < 1e-6, "drawing {d}");
            ends.push(pose.translation.vector);
        }
        let mean = ends.iter().sum::<nalgebra::Vector3<f64>>() / ends.len() as f64;
        assert!(
            (0..3).all(|k| (mean[k] - end[k]).abs() < 1e-6),
            "{mean:?} against {end:?}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
