//! The bundled URDF of every UR model (`hil-sim/urdf/<model>.urdf`), written by
//! [`write_urdf`] from numbers with named sources (docs/ur.md, "Arm models"):
//!
//! - joint origins: the model's DH table ([`UrModel::dh`], Universal Robots' published values)
//!   in the layout of ROS 2 `ur_description` ([`ur5_shared::kinematics::urdf_origins`]), so
//!   the root is the DH base frame and joint angles are DH angles;
//! - joint limits: [`UrModel::joint_limits`] (`ur_description`'s `joint_limits.yaml`);
//! - inertials: `ur_description`'s `config/<model>/physical_parameters.yaml`
//!   (UniversalRobots/Universal_Robots_ROS2_Description, BSD-3-Clause, commit 2221ec0f,
//!   2024-10-14; for the models that commit lacks, the package's later commits 305c5cef
//!   (UR7e), 9743c966 (UR12e), 2cb0bf15 (UR15), 6ffee81d (UR18)): link masses, centres of
//!   mass and inertia tensors, copied below; each file's header names its sources; the base's
//!   tensor is the package's solid cylinder (`links.base` radius and length). Each tensor is
//!   written already rotated into the link frame (R I Rᵀ, R = the package's inertial rpy)
//!   because rapier3d-urdf ignores `<inertial><origin rpy>` (UR5.md).
//!
//! The UR5's file is the hand-written one the project's results were made with (its inertias
//! rounded to 7 digits); hil-sim's tests check that [`write_urdf`] gives the same UR5 to that
//! rounding, and that every other committed file is exactly what [`write_urdf`] writes
//! (`UPDATE_URDF=1` rewrites them).

use std::f64::consts::FRAC_PI_2;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Rotation3};
use ur5_shared::kinematics::urdf_origins;
use ur5_shared::UrModel;

/// The bundled URDF of `model` (its file's text).
pub fn bundled_urdf(model: UrModel) -> &'static str {
    match model {
        UrModel::Ur3 => include_str!("../urdf/ur3.urdf"),
        UrModel::Ur5 => include_str!("../urdf/ur5.urdf"),
        UrModel::Ur10 => include_str!("../urdf/ur10.urdf"),
        UrModel::Ur3e => include_str!("../urdf/ur3e.urdf"),
        UrModel::Ur5e => include_str!("../urdf/ur5e.urdf"),
        UrModel::Ur7e => include_str!("../urdf/ur7e.urdf"),
        UrModel::Ur10e => include_str!("../urdf/ur10e.urdf"),
        UrModel::Ur12e => include_str!("../urdf/ur12e.urdf"),
        UrModel::Ur16e => include_str!("../urdf/ur16e.urdf"),
        UrModel::Ur15 => include_str!("../urdf/ur15.urdf"),
        UrModel::Ur18 => include_str!("../urdf/ur18.urdf"),
        UrModel::Ur20 => include_str!("../urdf/ur20.urdf"),
        UrModel::Ur30 => include_str!("../urdf/ur30.urdf"),
    }
}

/// Where the bundled URDF of `model` lives in the source tree.
pub fn bundled_urdf_path(model: UrModel) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("urdf/{}.urdf", model.name()))
}

/// One moving link's inertial as `ur_description` writes it.
struct Link {
    /// kg.
    mass: f64,
    /// Centre of mass in the link frame (m).
    com: [f64; 3],
    /// Orientation of the tensor's frame in the link frame (URDF rpy, rad).
    rpy: [f64; 3],
    /// ixx, ixy, ixz, iyy, iyz, izz (kg·m²) in the rpy frame.
    tensor: [f64; 6],
}

const fn link(mass: f64, com: [f64; 3], rpy: [f64; 3], tensor: [f64; 6]) -> Link {
    Link {
        mass,
        com,
        rpy,
        tensor,
    }
}

/// A model's inertials: the base (mass kg, cylinder radius m, length m) and the six moving
/// links, shoulder to wrist 3.
struct Inertials {
    base: (f64, f64, f64),
    links: [Link; 6],
}

/// `physical_parameters.yaml` of each model (module docs), the `rotation` entries of ±π/2
/// written as ±`FRAC_PI_2`.
#[rustfmt::skip]
fn inertials(model: UrModel) -> Inertials {
    match model {
        UrModel::Ur3 => Inertials {
            base: (2.0, 0.075, 0.038),
            links: [
                link(2.0, [0.0, 0.0, -0.02], [0.0, 0.0, 0.0], [0.008093166666666665, 0.0, 0.0, 0.008093166666666665, 0.0, 0.005625]),
                link(3.42, [-0.11365, 0.0, 0.1157], [0.0, FRAC_PI_2, 0.0], [0.021728491912499998, 0.0, 0.0, 0.021728491912499998, 0.0, 0.00961875]),
                link(1.26, [-0.16325, 0.0, 0.0238], [0.0, FRAC_PI_2, 0.0], [0.0065468090625, 0.0, 0.0, 0.0065468090625, 0.0, 0.00354375]),
                link(0.8, [0.0, -0.01, 0.0], [0.0, 0.0, 0.0], [0.0016106414999999998, 0.0, 0.0, 0.0016106414999999998, 0.0, 0.00225]),
                link(0.8, [0.0, 0.01, 0.0], [0.0, 0.0, 0.0], [0.0015721739999999998, 0.0, 0.0, 0.0015721739999999998, 0.0, 0.00225]),
                link(0.35, [0.0, 0.0, -0.02], [0.0, 0.0, 0.0], [0.00013626666666666665, 0.0, 0.0, 0.00013626666666666665, 0.0, 0.0001792]),
            ],
        },
        UrModel::Ur5 => Inertials {
            base: (4.0, 0.06, 0.05),
            links: [
                link(3.7, [0.0, -0.00193, -0.02561], [0.0, 0.0, 0.0], [0.014972358333333331, 0.0, 0.0, 0.014972358333333331, 0.0, 0.01040625]),
                link(8.393, [-0.2125, 0.0, 0.11336], [0.0, FRAC_PI_2, 0.0], [0.13388583541666665, 0.0, 0.0, 0.13388583541666665, 0.0, 0.0151074]),
                link(2.33, [-0.24225, 0.0, 0.0265], [0.0, FRAC_PI_2, 0.0], [0.031216803515624995, 0.0, 0.0, 0.031216803515624995, 0.0, 0.004095]),
                link(1.219, [0.0, -0.01634, -0.0018], [0.0, 0.0, 0.0], [0.002013889583333333, 0.0, 0.0, 0.002013889583333333, 0.0, 0.0021942]),
                link(1.219, [0.0, 0.01634, -0.0018], [0.0, 0.0, 0.0], [0.0018310395833333333, 0.0, 0.0, 0.0018310395833333333, 0.0, 0.0021942]),
                link(0.1879, [0.0, 0.0, -0.001159], [0.0, 0.0, 0.0], [8.062475833333332e-05, 0.0, 0.0, 8.062475833333332e-05, 0.0, 0.0001321171875]),
            ],
        },
        UrModel::Ur10 => Inertials {
            base: (4.0, 0.075, 0.038),
            links: [
                link(7.1, [0.021, -0.027, 0.0], [FRAC_PI_2, 0.0, 0.0], [0.03408, 2e-05, -0.00425, 0.03529, 8e-05, 0.02156]),
                link(12.7, [-0.232, 0.0, 0.158], [0.0, 0.0, 0.0], [0.02814, 5e-05, -0.01561, 0.77068, 2e-05, 0.76943]),
                link(4.27, [-0.3323, 0.0, 0.068], [0.0, 0.0, 0.0], [0.01014, 8e-05, 0.00916, 0.30928, 0.0, 0.30646]),
                link(2.0, [0.0, -0.018, 0.007], [FRAC_PI_2, 0.0, 0.0], [0.00296, -1e-05, 0.0, 0.00222, -0.00024, 0.00258]),
                link(2.0, [0.0, 0.018, -0.007], [-FRAC_PI_2, 0.0, 0.0], [0.00296, -1e-05, 0.0, 0.00222, -0.00024, 0.00258]),
                link(0.365, [0.0, 0.0, -0.026], [0.0, 0.0, 0.0], [0.0004, 0.0, 0.0, 0.00041, 0.0, 0.00034]),
            ],
        },
        UrModel::Ur3e => Inertials {
            base: (2.0, 0.075, 0.038),
            links: [
                link(1.98, [0.0, 0.0, -0.02], [0.0, 0.0, 0.0], [0.008093166666666665, 0.0, 0.0, 0.008093166666666665, 0.0, 0.005625]),
                link(3.4445, [-0.11355, 0.0, 0.1157], [0.0, FRAC_PI_2, 0.0], [0.021728491912499998, 0.0, 0.0, 0.021728491912499998, 0.0, 0.00961875]),
                link(1.437, [-0.1632, 0.0, 0.0238], [0.0, FRAC_PI_2, 0.0], [0.006544570199999999, 0.0, 0.0, 0.006544570199999999, 0.0, 0.00354375]),
                link(0.871, [0.0, -0.01, 0.0], [0.0, 0.0, 0.0], [0.0020849999999999996, 0.0, 0.0, 0.0020849999999999996, 0.0, 0.00225]),
                link(0.805, [0.0, 0.01, 0.0], [0.0, 0.0, 0.0], [0.0020849999999999996, 0.0, 0.0, 0.0020849999999999996, 0.0, 0.00225]),
                link(0.261, [0.0, 0.0, -0.02], [0.0, 0.0, 0.0], [0.00013626666666666665, 0.0, 0.0, 0.00013626666666666665, 0.0, 0.0001792]),
            ],
        },
        UrModel::Ur5e => Inertials {
            base: (4.0, 0.06, 0.05),
            links: [
                link(3.761, [0.0, -0.00193, -0.02561], [0.0, 0.0, 0.0], [0.010267499999999999, 0.0, 0.0, 0.010267499999999999, 0.0, 0.00666]),
                link(8.058, [-0.2125, 0.0, 0.11336], [0.0, FRAC_PI_2, 0.0], [0.13388583541666665, 0.0, 0.0, 0.13388583541666665, 0.0, 0.0151074]),
                link(2.846, [-0.2422, 0.0, 0.0265], [0.0, FRAC_PI_2, 0.0], [0.03120936758333333, 0.0, 0.0, 0.03120936758333333, 0.0, 0.004095]),
                link(1.37, [0.0, -0.01634, -0.0018], [0.0, 0.0, 0.0], [0.0025599, 0.0, 0.0, 0.0025599, 0.0, 0.0021942]),
                link(1.3, [0.0, 0.01634, -0.0018], [0.0, 0.0, 0.0], [0.0025599, 0.0, 0.0, 0.0025599, 0.0, 0.0021942]),
                link(0.365, [0.0, 0.0, -0.001159], [0.0, 0.0, 0.0], [9.890414008333333e-05, 0.0, 0.0, 9.890414008333333e-05, 0.0, 0.0001321171875]),
            ],
        },
        UrModel::Ur7e => Inertials {
            base: (4.0, 0.06, 0.05),
            links: [
                link(3.761, [0.0, -0.00193, -0.02561], [FRAC_PI_2, 0.0, 0.0], [0.0070021, 0.00000073, -0.00001053, 0.00648091, 0.00049994, 0.00657286]),
                link(8.058, [-0.2125, 0.0, 0.11336], [0.0, 0.0, 0.0], [0.01505885, -0.000054, 0.00000563, 0.33388086, -0.00000181, 0.33247207]),
                link(2.846, [-0.2422, 0.0, 0.0265], [0.0, 0.0, 0.0], [0.00399632, -0.00001365, 0.00137272, 0.07879254, -0.0000066, 0.0784851]),
                link(1.37, [0.0, -0.01634, -0.0018], [FRAC_PI_2, 0.0, 0.0], [0.00165491, -0.00000282, -0.00000438, 0.00135962, 0.00010157, 0.00126279]),
                link(1.3, [0.0, 0.01634, -0.0018], [-FRAC_PI_2, 0.0, 0.0], [0.00135617, -0.00000274, 0.00000444, 0.00127827, -0.00005048, 0.00096614]),
                link(0.365, [0.0, 0.0, -0.001159], [0.0, 0.0, 0.0], [0.00018694, 0.00000006, -0.00000017, 0.00018908, -0.00000092, 0.00025756]),
            ],
        },
        // The UR12e's file is the UR10e's, number for number.
        UrModel::Ur10e | UrModel::Ur12e => Inertials {
            base: (4.0, 0.075, 0.038),
            links: [
                link(7.369, [0.021, -0.027, 0.0], [FRAC_PI_2, 0.0, 0.0], [0.03408, 2e-05, -0.00425, 0.03529, 8e-05, 0.02156]),
                link(13.051, [-0.2327, 0.0, 0.158], [0.0, 0.0, 0.0], [0.02814, 5e-05, -0.01561, 0.77068, 2e-05, 0.76943]),
                link(3.989, [-0.33155, 0.0, 0.068], [0.0, 0.0, 0.0], [0.01014, 8e-05, 0.00916, 0.30928, 0.0, 0.30646]),
                link(2.1, [0.0, -0.018, 0.007], [FRAC_PI_2, 0.0, 0.0], [0.00296, -1e-05, 0.0, 0.00222, -0.00024, 0.00258]),
                link(1.98, [0.0, 0.018, -0.007], [-FRAC_PI_2, 0.0, 0.0], [0.00296, -1e-05, 0.0, 0.00222, -0.00024, 0.00258]),
                link(0.615, [0.0, 0.0, -0.026], [0.0, 0.0, 0.0], [0.0004, 0.0, 0.0, 0.00041, 0.0, 0.00034]),
            ],
        },
        UrModel::Ur16e => Inertials {
            base: (4.0, 0.075, 0.038),
            links: [
                link(7.369, [0.0, -0.03, -0.016], [FRAC_PI_2, 0.0, 0.0], [0.03351, 2e-05, -1e-05, 0.03374, 0.00374, 0.021]),
                link(10.45, [-0.1764, 0.0, 0.16], [0.0, 0.0, 0.0], [0.02796, -0.0001, -0.0072, 0.47558, 3e-05, 0.47635]),
                link(4.321, [-0.166, 0.0, 0.065], [0.0, 0.0, 0.0], [0.01091, 6e-05, 0.01012, 0.1206, 1e-05, 0.11714]),
                link(2.18, [0.0, -0.011, -0.009], [FRAC_PI_2, 0.0, 0.0], [0.00609, -1e-05, 0.0, 0.00245, 0.00083, 0.00579]),
                link(2.033, [0.0, 0.012, -0.018], [-FRAC_PI_2, 0.0, 0.0], [0.00389, -1e-05, 0.0, 0.00219, -0.00045, 0.00363]),
                link(0.907, [0.0, 0.0, -0.044], [0.0, 0.0, 0.0], [0.00117, 0.0, 0.0, 0.00118, 0.0, 0.00084]),
            ],
        },
        UrModel::Ur15 | UrModel::Ur18 => {
            let (upper_arm, forearm) = if model == UrModel::Ur15 {
                (
                    link(14.9255, [-0.228491, -0.000083, 0.192787], [0.0, 0.0, 0.0], [0.048202, 0.000232, -0.032135, 1.188499, -0.000017, 1.182771]),
                    link(6.1015, [-0.210929, 0.000019, 0.070552], [0.0, 0.0, 0.0], [0.018481, -0.000005, 0.013601, 0.303502, 0.000003, 0.296843]),
                )
            } else {
                (
                    link(14.2009, [-0.166336, -0.000088, 0.190204], [0.0, 0.0, 0.0], [0.045094, 0.000179, -0.024705, 0.630805, -0.00002, 0.625724]),
                    link(5.52, [-0.139248, 0.000021, 0.073101], [0.0, 0.0, 0.0], [0.016891, 0.0, 0.009081, 0.129732, 0.000003, 0.123451]),
                )
            };
            // The two files share the shoulder and the wrists.
            Inertials {
                base: (4.0, 0.17, 0.1),
                links: [
                    link(9.9883, [0.000024, -0.025304, -0.033309], [FRAC_PI_2, 0.0, 0.0], [0.051334, 0.000025, -0.000016, 0.047702, 0.008805, 0.034263]),
                    upper_arm,
                    forearm,
                    link(2.089, [0.000025, -0.016413, -0.019695], [FRAC_PI_2, 0.0, 0.0], [0.004339, 0.000019, 0.000001, 0.002548, 0.000706, 0.003912]),
                    link(2.0869, [0.000025, 0.015886, -0.01996], [-FRAC_PI_2, 0.0, 0.0], [0.004288, 0.000017, -0.000003, 0.002566, -0.000716, 0.003927]),
                    link(1.0666, [-0.000018, -0.000112, -0.053397], [0.0, 0.0, 0.0], [0.001406, -0.000003, 0.00001, 0.001404, -0.000024, 0.001002]),
                ],
            }
        }
        UrModel::Ur20 => Inertials {
            base: (4.0, 0.075, 0.038),
            links: [
                link(16.343, [0.0, -0.0062, -0.061], [FRAC_PI_2, 0.0, 0.0], [0.08866, -0.00011, -0.00011, 0.07632, 0.0072, 0.08418]),
                link(29.632, [-0.3394, 0.0, 0.2098], [0.0, 0.0, 0.0], [0.1467, 0.00019, -0.05163, 4.6659, 4e-05, 4.6348]),
                link(7.879, [-0.4053, 0.0, 0.0604], [0.0, 0.0, 0.0], [0.02612, -5e-05, -0.02898, 0.75763, -1e-05, 0.75327]),
                link(3.054, [0.0, -0.0393, -0.0026], [FRAC_PI_2, 0.0, 0.0], [0.00555, -1e-05, -2e-05, 0.00537, 0.00036, 0.00402]),
                link(3.126, [0.0, 0.0379, -0.0024], [-FRAC_PI_2, 0.0, 0.0], [0.00586, -1e-05, -2e-05, 0.00578, -0.00037, 0.00427]),
                link(0.926, [0.0, 0.0, -0.0293], [0.0, 0.0, 0.0], [0.00092, 0.0, 0.0, 0.00091, 0.0, 0.00117]),
            ],
        },
        UrModel::Ur30 => Inertials {
            base: (4.0, 0.075, 0.038),
            links: [
                link(16.343, [-0.0001, -0.0069, -0.06], [FRAC_PI_2, 0.0, 0.0], [0.03351, 2e-05, -1e-05, 0.03374, 0.00374, 0.021]),
                link(28.542, [-0.2476, 0.0, 0.2103], [0.0, 0.0, 0.0], [0.02796, -0.0001, -0.0072, 0.47558, 3e-05, 0.47635]),
                link(7.156, [-0.278, 0.0, 0.0629], [0.0, 0.0, 0.0], [0.01091, 6e-05, 0.01012, 0.1206, 1e-05, 0.11714]),
                link(3.054, [0.0, -0.0353, -0.0048], [FRAC_PI_2, 0.0, 0.0], [0.00609, -1e-05, 0.0, 0.00245, 0.00083, 0.00579]),
                link(3.126, [0.0, 0.0341, -0.0046], [-FRAC_PI_2, 0.0, 0.0], [0.00389, 1e-05, 0.0, 0.00219, -0.00045, 0.00363]),
                link(0.926, [0.0, 0.0, -0.0293], [0.0, 0.0, 0.0], [0.00117, 0.0, 0.0, 0.00118, 0.0, 0.00084]),
            ],
        },
    }
}

/// Where a model's numbers come from, as its URDF's header names them (module docs): the file
/// with its DH values, its `physical_parameters.yaml` and its `joint_limits.yaml`, each with
/// its package and commit when that is not the ROS 2 package's commit 2221ec0f.
struct Sources {
    kinematics: String,
    inertials: String,
    limits: String,
}

/// The ROS 1 description package (UR's own, for ROS 1), which has the newer models' kinematics.
const ROS1: &str = "ROS 1 ur_description (ros-industrial/universal_robot, BSD)";

fn sources(model: UrModel) -> Sources {
    let n = model.name();
    let (kinematics, inertials, limits) = match model {
        UrModel::Ur7e => (
            format!(
                "config/{n}/default_kinematics.yaml,\n     \
                 which is the UR5e's: {ROS1}\n     \
                 links config/{n} to config/ur5e (commit 3be81362)"
            ),
            format!("config/{n}/physical_parameters.yaml (commit 305c5cef)"),
            format!("config/{n}/joint_limits.yaml, the UR5e's by the link above"),
        ),
        UrModel::Ur12e | UrModel::Ur15 | UrModel::Ur18 => {
            let (kin, phys, lim) = match model {
                UrModel::Ur12e => ("2f339257", "9743c966", "at commit 49d2ca22"),
                UrModel::Ur15 => (
                    "499e728e",
                    "2cb0bf15",
                    "of the ROS 1 package at commit 499e728e",
                ),
                _ => ("34b13710", "6ffee81d", "at commit 272bdddb"),
            };
            (
                format!(
                    "config/{n}/default_kinematics.yaml;\n     \
                     the values from {ROS1}\n     \
                     ur_description/config/{n}/default_kinematics.yaml, commit {kin}"
                ),
                format!("config/{n}/physical_parameters.yaml (commit {phys})"),
                format!("config/{n}/joint_limits.yaml {lim}"),
            )
        }
        _ => (
            format!("config/{n}/default_kinematics.yaml"),
            format!("config/{n}/physical_parameters.yaml (commit 2221ec0f, 2024-10-14)"),
            format!("config/{n}/joint_limits.yaml"),
        ),
    };
    Sources {
        kinematics,
        inertials,
        limits,
    }
}

/// Link names, base to wrist 3, and joint names, shoulder pan to wrist 3 (ROS 2
/// `ur_description`'s; the simulator looks the active joints up by name).
const LINKS: [&str; 7] = [
    "base_link",
    "shoulder_link",
    "upper_arm_link",
    "forearm_link",
    "wrist_1_link",
    "wrist_2_link",
    "wrist_3_link",
];
const JOINTS: [&str; 6] = [
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
];

/// Shortest text that parses back to `x` (no `-0`).
fn num(x: f64) -> String {
    format!("{}", x + 0.0)
}

fn triple(v: [f64; 3]) -> String {
    format!("{} {} {}", num(v[0]), num(v[1]), num(v[2]))
}

/// The tensor `t` (ixx, ixy, ixz, iyy, iyz, izz) of a frame at `rpy` expressed in the link
/// frame: R I Rᵀ. Every rotation in the tables is about one axis by a multiple of π/2, so R
/// is a signed permutation (rounded to one exactly) and the result is exact.
fn rotate(t: [f64; 6], rpy: [f64; 3]) -> [f64; 6] {
    let r = Rotation3::from_euler_angles(rpy[0], rpy[1], rpy[2]).into_inner();
    let r = r.map(|x| {
        let k = x.round();
        assert!(
            (x - k).abs() < 1e-9,
            "inertial rpy {rpy:?} is not a quarter turn"
        );
        k
    });
    #[rustfmt::skip]
    let i = Matrix3::new(
        t[0], t[1], t[2],
        t[1], t[3], t[4],
        t[2], t[4], t[5],
    );
    let o = r * i * r.transpose();
    [
        o[(0, 0)],
        o[(0, 1)],
        o[(0, 2)],
        o[(1, 1)],
        o[(1, 2)],
        o[(2, 2)],
    ]
}

fn inertial(out: &mut String, mass: f64, com: [f64; 3], t: [f64; 6]) {
    let _ = writeln!(out, "    <inertial>");
    let _ = writeln!(out, "      <origin xyz=\"{}\" rpy=\"0 0 0\"/>", triple(com));
    let _ = writeln!(out, "      <mass value=\"{}\"/>", num(mass));
    let _ = writeln!(
        out,
        "      <inertia ixx=\"{}\" ixy=\"{}\" ixz=\"{}\" iyy=\"{}\" iyz=\"{}\" izz=\"{}\"/>",
        num(t[0]),
        num(t[1]),
        num(t[2]),
        num(t[3]),
        num(t[4]),
        num(t[5])
    );
    let _ = writeln!(out, "    </inertial>");
}

/// The URDF of `model` (module docs): seven links with inertials, six revolute joints with
/// limits, no meshes and no collision shapes (the reaching task has no contacts).
pub fn write_urdf(model: UrModel) -> String {
    let dh = model.dh();
    let lim = model.joint_limits();
    let inr = inertials(model);
    let name = model.name();
    let mut out = String::new();
    let _ = writeln!(out, "<?xml version=\"1.0\"?>");
    let src = sources(model);
    let _ = writeln!(
        out,
        "<!-- {} for hil-sim, written by hil-sim/src/urdf.rs (`write_urdf`) from public parameters:\n     \
         kinematics: Universal Robots' published DH table (d1 = {}, a2 = {}, a3 = {}, d4 = {},\n     \
         d5 = {}, d6 = {} m; alpha = pi/2, 0, 0, pi/2, -pi/2, 0) laid out with the joint origins of\n     \
         the ROS 2 ur_description package (UniversalRobots/Universal_Robots_ROS2_Description,\n     \
         BSD-3-Clause, {}). Joint angles equal the DH angles (no\n     \
         offsets); the base_link frame is the DH base frame (z up); wrist_3_link's origin is the flange.\n     \
         Inertials: ur_description {}:\n     \
         masses, centres of mass, tensors; each tensor already rotated into its link frame\n     \
         (R I R^T with the package's inertial rpy) because rapier3d-urdf ignores inertial rpy.\n     \
         Limits: ur_description {} (position +-2 pi, elbow +-pi).\n     \
         No meshes and no collision shapes: the reaching task has no contacts. -->",
        name.to_uppercase(),
        num(dh.d[0]),
        num(dh.a[1]),
        num(dh.a[2]),
        num(dh.d[3]),
        num(dh.d[4]),
        num(dh.d[5]),
        src.kinematics,
        src.inertials,
        src.limits,
    );
    let _ = writeln!(out, "<robot name=\"{name}\">");
    let (m, r, h) = inr.base;
    let (ixx, izz) = (m * (3.0 * r * r + h * h) / 12.0, m * r * r / 2.0);
    let _ = writeln!(out, "  <link name=\"{}\">", LINKS[0]);
    inertial(&mut out, m, [0.0; 3], [ixx, 0.0, 0.0, ixx, 0.0, izz]);
    let _ = writeln!(out, "  </link>");
    for (l, name) in inr.links.iter().zip(&LINKS[1..]) {
        let _ = writeln!(out, "  <link name=\"{name}\">");
        inertial(&mut out, l.mass, l.com, rotate(l.tensor, l.rpy));
        let _ = writeln!(out, "  </link>");
    }
    for (j, (xyz, rpy)) in urdf_origins(model).into_iter().enumerate() {
        let _ = writeln!(out, "  <joint name=\"{}\" type=\"revolute\">", JOINTS[j]);
        let _ = writeln!(out, "    <parent link=\"{}\"/>", LINKS[j]);
        let _ = writeln!(out, "    <child link=\"{}\"/>", LINKS[j + 1]);
        let _ = writeln!(
            out,
            "    <origin xyz=\"{}\" rpy=\"{}\"/>",
            triple(xyz),
            triple(rpy)
        );
        let _ = writeln!(out, "    <axis xyz=\"0 0 1\"/>");
        let _ = writeln!(
            out,
            "    <limit lower=\"{}\" upper=\"{}\" effort=\"{}\" velocity=\"{}\"/>",
            num(lim.lower[j]),
            num(lim.upper[j]),
            num(lim.effort[j]),
            num(lim.velocity[j])
        );
        let _ = writeln!(out, "  </joint>");
    }
    let _ = writeln!(out, "</robot>");
    out
}
