//! RTDE variables: their wire types, the names this project knows, and negotiated recipes.
//!
//! A recipe is the ordered list of variables a client asked for in SETUP_OUTPUTS (or
//! SETUP_INPUTS). The robot answers a recipe id and one type name per variable; a data package
//! then carries the values in that order, each in its type's fixed size. Names in the request
//! are comma-separated; empty names (a trailing comma, as SDU's ur_rtde sends) are ignored on
//! both sides.
//!
//! Recipes hold at most [`MAX_FIELDS`] variables in a `heapless::Vec`: building one does not
//! allocate, decoding with one does not either.

use heapless::Vec;

/// Most variables in one recipe (a real controller allows more; this project needs < 20).
pub const MAX_FIELDS: usize = 64;

/// Number of general-purpose registers of each kind (`…_register_0` … `_47`).
pub const N_REGISTERS: usize = 48;

/// An RTDE variable type and its size on the wire (all big-endian).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum VarType {
    /// `u8`, 0 or 1.
    Bool,
    /// `u8`.
    Uint8,
    /// `u32`.
    Uint32,
    /// `u64`.
    Uint64,
    /// `i32`.
    Int32,
    /// `f64`.
    Double,
    /// 3 × `f64`.
    Vector3d,
    /// 6 × `f64`.
    Vector6d,
    /// 6 × `i32`.
    Vector6Int32,
    /// 6 × `u32`.
    Vector6Uint32,
}

impl VarType {
    /// Every type, for tables and tests.
    pub const ALL: [VarType; 10] = [
        VarType::Bool,
        VarType::Uint8,
        VarType::Uint32,
        VarType::Uint64,
        VarType::Int32,
        VarType::Double,
        VarType::Vector3d,
        VarType::Vector6d,
        VarType::Vector6Int32,
        VarType::Vector6Uint32,
    ];

    /// Bytes one value takes in a data package.
    pub const fn size(self) -> usize {
        match self {
            VarType::Bool | VarType::Uint8 => 1,
            VarType::Uint32 | VarType::Int32 => 4,
            VarType::Uint64 | VarType::Double => 8,
            VarType::Vector3d => 24,
            VarType::Vector6d => 48,
            VarType::Vector6Int32 | VarType::Vector6Uint32 => 24,
        }
    }

    /// The type's name in a SETUP answer.
    pub const fn name(self) -> &'static str {
        match self {
            VarType::Bool => "BOOL",
            VarType::Uint8 => "UINT8",
            VarType::Uint32 => "UINT32",
            VarType::Uint64 => "UINT64",
            VarType::Int32 => "INT32",
            VarType::Double => "DOUBLE",
            VarType::Vector3d => "VECTOR3D",
            VarType::Vector6d => "VECTOR6D",
            VarType::Vector6Int32 => "VECTOR6INT32",
            VarType::Vector6Uint32 => "VECTOR6UINT32",
        }
    }

    /// The type for a name in a SETUP answer.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|t| t.name() == name)
    }
}

/// What the robot answers for one requested variable.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Answered {
    /// Known, with this type.
    Type(VarType),
    /// `NOT_FOUND`: the controller has no variable of that name.
    NotFound,
    /// `IN_USE`: an input another RTDE client already writes.
    InUse,
}

impl Answered {
    /// The token in a SETUP answer.
    pub const fn name(self) -> &'static str {
        match self {
            Answered::Type(t) => t.name(),
            Answered::NotFound => "NOT_FOUND",
            Answered::InUse => "IN_USE",
        }
    }

    /// Parses one token of a SETUP answer; `None` for an unknown token.
    pub fn from_name(s: &str) -> Option<Self> {
        match s {
            "NOT_FOUND" => Some(Answered::NotFound),
            "IN_USE" => Some(Answered::InUse),
            _ => VarType::from_name(s).map(Answered::Type),
        }
    }
}

/// The non-empty names of a comma-separated list (a trailing or doubled comma adds nothing).
pub fn names(list: &str) -> impl Iterator<Item = &str> {
    list.split(',').filter(|n| !n.is_empty())
}

/// An output variable this project knows (the table a controller serves; its values live in
/// [`crate::RobotState`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Output {
    /// `timestamp` DOUBLE: s since the controller started.
    Timestamp,
    /// `target_q` VECTOR6D: target joint angles (rad).
    TargetQ,
    /// `target_qd` VECTOR6D: target joint velocities (rad/s).
    TargetQd,
    /// `actual_q` VECTOR6D: measured joint angles (rad).
    ActualQ,
    /// `actual_qd` VECTOR6D: measured joint velocities (rad/s).
    ActualQd,
    /// `actual_current` VECTOR6D: joint currents (A).
    ActualCurrent,
    /// `actual_TCP_pose` VECTOR6D: tool pose (m, axis-angle rad).
    ActualTcpPose,
    /// `actual_TCP_speed` VECTOR6D: tool speed (m/s, rad/s).
    ActualTcpSpeed,
    /// `joint_temperatures` VECTOR6D (°C).
    JointTemperatures,
    /// `robot_mode` INT32 ([`crate::RobotMode`]).
    RobotMode,
    /// `safety_mode` INT32 ([`crate::SafetyMode`]).
    SafetyMode,
    /// `safety_status` INT32.
    SafetyStatus,
    /// `joint_mode` VECTOR6INT32.
    JointMode,
    /// `runtime_state` UINT32 (1 stopped, 2 playing, …).
    RuntimeState,
    /// `robot_status_bits` UINT32.
    RobotStatusBits,
    /// `speed_scaling` DOUBLE: the speed scaling in force (0..1).
    SpeedScaling,
    /// `target_speed_fraction` DOUBLE: the speed slider (0..1).
    TargetSpeedFraction,
    /// `actual_execution_time` DOUBLE: controller real-time thread time (ms).
    ActualExecutionTime,
    /// `target_qdd` VECTOR6D: target joint accelerations (rad/s²).
    TargetQdd,
    /// `target_current` VECTOR6D: target joint currents (A).
    TargetCurrent,
    /// `target_moment` VECTOR6D: target joint torques (N·m).
    TargetMoment,
    /// `joint_control_output` VECTOR6D: joint control currents (A).
    JointControlOutput,
    /// `actual_TCP_force` VECTOR6D: generalised tool force (N, N·m).
    ActualTcpForce,
    /// `target_TCP_pose` VECTOR6D (m, axis-angle rad).
    TargetTcpPose,
    /// `target_TCP_speed` VECTOR6D (m/s, rad/s).
    TargetTcpSpeed,
    /// `actual_joint_voltage` VECTOR6D (V).
    ActualJointVoltage,
    /// `actual_digital_input_bits` UINT64.
    ActualDigitalInputBits,
    /// `actual_digital_output_bits` UINT64.
    ActualDigitalOutputBits,
    /// `actual_tool_accelerometer` VECTOR3D (m/s²).
    ActualToolAccelerometer,
    /// `actual_momentum` DOUBLE: norm of the Cartesian momentum (kg·m/s).
    ActualMomentum,
    /// `actual_main_voltage` DOUBLE (V).
    ActualMainVoltage,
    /// `actual_robot_voltage` DOUBLE (V).
    ActualRobotVoltage,
    /// `actual_robot_current` DOUBLE (A).
    ActualRobotCurrent,
    /// `joint_position_deviation_ratio` DOUBLE.
    JointPositionDeviationRatio,
    /// `safety_status_bits` UINT32.
    SafetyStatusBits,
    /// `standard_analog_input0` (A or V).
    StandardAnalogInput0,
    /// `standard_analog_input1` (A or V).
    StandardAnalogInput1,
    /// `standard_analog_output0` (A or V).
    StandardAnalogOutput0,
    /// `standard_analog_output1` (A or V).
    StandardAnalogOutput1,
    /// `ft_raw_wrench`: raw force/torque sensor wrench (N, N·m).
    FtRawWrench,
    /// `payload`: payload mass (kg).
    Payload,
    /// `payload_cog`: payload centre of gravity (m).
    PayloadCog,
    /// `payload_inertia` (kg·m²).
    PayloadInertia,
    /// `output_int_register_N` INT32, N < [`N_REGISTERS`].
    OutputIntRegister(u8),
    /// `output_double_register_N` DOUBLE, N < [`N_REGISTERS`].
    OutputDoubleRegister(u8),
}

/// Names and types of the fixed outputs (registers are matched by pattern).
#[rustfmt::skip]
const OUTPUT_TABLE: [(Output, &str, VarType); 43] = [
    (Output::Timestamp, "timestamp", VarType::Double),
    (Output::TargetQ, "target_q", VarType::Vector6d),
    (Output::TargetQd, "target_qd", VarType::Vector6d),
    (Output::ActualQ, "actual_q", VarType::Vector6d),
    (Output::ActualQd, "actual_qd", VarType::Vector6d),
    (Output::ActualCurrent, "actual_current", VarType::Vector6d),
    (Output::ActualTcpPose, "actual_TCP_pose", VarType::Vector6d),
    (Output::ActualTcpSpeed, "actual_TCP_speed", VarType::Vector6d),
    (Output::JointTemperatures, "joint_temperatures", VarType::Vector6d),
    (Output::RobotMode, "robot_mode", VarType::Int32),
    (Output::SafetyMode, "safety_mode", VarType::Int32),
    (Output::SafetyStatus, "safety_status", VarType::Int32),
    (Output::JointMode, "joint_mode", VarType::Vector6Int32),
    (Output::RuntimeState, "runtime_state", VarType::Uint32),
    (Output::RobotStatusBits, "robot_status_bits", VarType::Uint32),
    (Output::SpeedScaling, "speed_scaling", VarType::Double),
    (Output::TargetSpeedFraction, "target_speed_fraction", VarType::Double),
    (Output::ActualExecutionTime, "actual_execution_time", VarType::Double),
    (Output::TargetQdd, "target_qdd", VarType::Vector6d),
    (Output::TargetCurrent, "target_current", VarType::Vector6d),
    (Output::TargetMoment, "target_moment", VarType::Vector6d),
    (Output::JointControlOutput, "joint_control_output", VarType::Vector6d),
    (Output::ActualTcpForce, "actual_TCP_force", VarType::Vector6d),
    (Output::TargetTcpPose, "target_TCP_pose", VarType::Vector6d),
    (Output::TargetTcpSpeed, "target_TCP_speed", VarType::Vector6d),
    (Output::ActualJointVoltage, "actual_joint_voltage", VarType::Vector6d),
    (Output::ActualDigitalInputBits, "actual_digital_input_bits", VarType::Uint64),
    (Output::ActualDigitalOutputBits, "actual_digital_output_bits", VarType::Uint64),
    (Output::ActualToolAccelerometer, "actual_tool_accelerometer", VarType::Vector3d),
    (Output::ActualMomentum, "actual_momentum", VarType::Double),
    (Output::ActualMainVoltage, "actual_main_voltage", VarType::Double),
    (Output::ActualRobotVoltage, "actual_robot_voltage", VarType::Double),
    (Output::ActualRobotCurrent, "actual_robot_current", VarType::Double),
    (Output::JointPositionDeviationRatio, "joint_position_deviation_ratio", VarType::Double),
    (Output::SafetyStatusBits, "safety_status_bits", VarType::Uint32),
    (Output::StandardAnalogInput0, "standard_analog_input0", VarType::Double),
    (Output::StandardAnalogInput1, "standard_analog_input1", VarType::Double),
    (Output::StandardAnalogOutput0, "standard_analog_output0", VarType::Double),
    (Output::StandardAnalogOutput1, "standard_analog_output1", VarType::Double),
    (Output::FtRawWrench, "ft_raw_wrench", VarType::Vector6d),
    (Output::Payload, "payload", VarType::Double),
    (Output::PayloadCog, "payload_cog", VarType::Vector3d),
    (Output::PayloadInertia, "payload_inertia", VarType::Vector6d),
];

/// `prefix` followed by a register number below [`N_REGISTERS`].
fn register(name: &str, prefix: &str) -> Option<u8> {
    let digits = name.strip_prefix(prefix)?;
    // Canonical spelling only ("7", not "07" or "+7"), as a controller knows them.
    let canonical = matches!(digits.len(), 1 | 2)
        && digits.bytes().all(|b| b.is_ascii_digit())
        && !(digits.len() == 2 && digits.starts_with('0'));
    let n: u8 = digits.parse().ok().filter(|_| canonical)?;
    (usize::from(n) < N_REGISTERS).then_some(n)
}

impl Output {
    /// The output of that name, `None` if this project's table does not have it.
    pub fn from_name(name: &str) -> Option<Self> {
        if let Some((o, _, _)) = OUTPUT_TABLE.iter().find(|(_, n, _)| *n == name) {
            return Some(*o);
        }
        register(name, "output_int_register_")
            .map(Output::OutputIntRegister)
            .or_else(|| register(name, "output_double_register_").map(Output::OutputDoubleRegister))
    }

    /// Its type on the wire.
    pub fn var_type(self) -> VarType {
        match self {
            Output::OutputIntRegister(_) => VarType::Int32,
            Output::OutputDoubleRegister(_) => VarType::Double,
            o => OUTPUT_TABLE
                .iter()
                .find(|(x, _, _)| *x == o)
                .map_or(VarType::Int32, |(_, _, t)| *t),
        }
    }

    /// Its name on the wire (registers: the prefix; the number is the variant's field).
    pub fn base_name(self) -> &'static str {
        match self {
            Output::OutputIntRegister(_) => "output_int_register_",
            Output::OutputDoubleRegister(_) => "output_double_register_",
            o => OUTPUT_TABLE
                .iter()
                .find(|(x, _, _)| *x == o)
                .map_or("", |(_, n, _)| n),
        }
    }

    /// Every fixed output (without the registers), for tests and listings.
    pub fn fixed() -> impl Iterator<Item = Output> {
        OUTPUT_TABLE.iter().map(|(o, _, _)| *o)
    }
}

/// An input variable this project knows (what a client may write).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Input {
    /// `input_double_register_N` DOUBLE.
    DoubleRegister(u8),
    /// `input_int_register_N` INT32.
    IntRegister(u8),
}

impl Input {
    /// The input of that name, `None` if unknown.
    pub fn from_name(name: &str) -> Option<Self> {
        register(name, "input_double_register_")
            .map(Input::DoubleRegister)
            .or_else(|| register(name, "input_int_register_").map(Input::IntRegister))
    }

    /// Its type on the wire.
    pub const fn var_type(self) -> VarType {
        match self {
            Input::DoubleRegister(_) => VarType::Double,
            Input::IntRegister(_) => VarType::Int32,
        }
    }
}

/// Why a SETUP answer does not give a usable recipe.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RecipeError {
    /// The controller does not know a variable.
    #[error("the controller does not know RTDE variable `{name}` (NOT_FOUND); check the name and the controller's software version")]
    NotFound {
        /// Variable name.
        name: heapless::String<64>,
    },
    /// An input is written by another RTDE client.
    #[error("RTDE input `{name}` is IN_USE by another client (e.g. a fieldbus or another driver); stop it or use other registers")]
    InUse {
        /// Variable name.
        name: heapless::String<64>,
    },
    /// The answer has a different number of types than variables asked for.
    #[error("SETUP answer has {got} types for {asked} variables")]
    CountMismatch {
        /// Variables asked for.
        asked: usize,
        /// Types answered.
        got: usize,
    },
    /// A type token that is not an RTDE type.
    #[error("SETUP answer has an unknown type `{token}` for `{name}`")]
    UnknownType {
        /// Variable name.
        name: heapless::String<64>,
        /// The token.
        token: heapless::String<32>,
    },
    /// The controller's type differs from this project's table.
    #[error("RTDE variable `{name}` has type {got} on this controller, expected {expected}")]
    TypeMismatch {
        /// Variable name.
        name: heapless::String<64>,
        /// Type answered.
        got: &'static str,
        /// Type in this project's table.
        expected: &'static str,
    },
    /// A variable name this project's table does not have (client side, before asking).
    #[error("`{name}` is not an RTDE variable this project decodes")]
    Unknown {
        /// Variable name.
        name: heapless::String<64>,
    },
    /// More variables than [`MAX_FIELDS`].
    #[error("a recipe holds at most {MAX_FIELDS} variables")]
    TooMany,
    /// Recipe id 0: the controller refused the recipe (its text messages say why; a real
    /// controller also answers 0 while streaming, or for a recipe it cannot set up).
    #[error("the controller refused the recipe (recipe id 0; its text messages say why)")]
    Refused,
}

fn short<const N: usize>(s: &str) -> heapless::String<N> {
    let mut out = heapless::String::new();
    for c in s.chars() {
        if out.push(c).is_err() {
            break;
        }
    }
    out
}

/// A negotiated output recipe: the id the robot gave and the variables in order.
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub struct OutputRecipe {
    /// Recipe id (1..=255) the robot assigned.
    pub id: u8,
    /// Variables in package order.
    pub fields: Vec<Output, MAX_FIELDS>,
}

impl OutputRecipe {
    /// Client side: the recipe for the names asked (`requested`, comma list) and the robot's
    /// answer (`id`, comma list of types). Fails on NOT_FOUND, IN_USE, a count mismatch, a
    /// type different from this project's table, or recipe id 0 (refused).
    pub fn from_answer(requested: &str, id: u8, types: &str) -> Result<Self, RecipeError> {
        let asked = names(requested).count();
        let got = names(types).count();
        if asked != got {
            return Err(RecipeError::CountMismatch { asked, got });
        }
        let mut fields = Vec::new();
        for (name, token) in names(requested).zip(names(types)) {
            let answered = Answered::from_name(token).ok_or_else(|| RecipeError::UnknownType {
                name: short(name),
                token: short(token),
            })?;
            let t = match answered {
                Answered::NotFound => return Err(RecipeError::NotFound { name: short(name) }),
                Answered::InUse => return Err(RecipeError::InUse { name: short(name) }),
                Answered::Type(t) => t,
            };
            let o = Output::from_name(name).ok_or(RecipeError::Unknown { name: short(name) })?;
            if o.var_type() != t {
                return Err(RecipeError::TypeMismatch {
                    name: short(name),
                    got: t.name(),
                    expected: o.var_type().name(),
                });
            }
            fields.push(o).map_err(|_| RecipeError::TooMany)?;
        }
        if id == 0 {
            return Err(RecipeError::Refused);
        }
        Ok(Self { id, fields })
    }

    /// Bytes of a data package's values (after the recipe id).
    pub fn data_len(&self) -> usize {
        self.fields.iter().map(|f| f.var_type().size()).sum()
    }
}

/// Server side: the answer to a SETUP request's names. Each non-empty name gets a type, or
/// NOT_FOUND; `lookup` gives the answer for one name. Writes the comma-separated type list into
/// `out` and returns whether every name was found (only then is the recipe usable).
pub fn answer_types<W: core::fmt::Write>(
    requested: &str,
    mut lookup: impl FnMut(&str) -> Answered,
    out: &mut W,
) -> Result<bool, core::fmt::Error> {
    let mut usable = true;
    for (i, name) in names(requested).enumerate() {
        let a = lookup(name);
        usable &= matches!(a, Answered::Type(_));
        if i > 0 {
            out.write_char(',')?;
        }
        out.write_str(a.name())?;
    }
    Ok(usable)
}

/// A negotiated input recipe (server side: what a client will write).
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub struct InputRecipe {
    /// Recipe id.
    pub id: u8,
    /// Variables in package order.
    pub fields: Vec<Input, MAX_FIELDS>,
}

impl InputRecipe {
    /// Bytes of a data package's values (after the recipe id).
    pub fn data_len(&self) -> usize {
        self.fields.iter().map(|f| f.var_type().size()).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables() {
        assert_eq!(Output::from_name("actual_q"), Some(Output::ActualQ));
        assert_eq!(Output::ActualQ.var_type(), VarType::Vector6d);
        assert_eq!(
            Output::from_name("actual_TCP_pose"),
            Some(Output::ActualTcpPose)
        );
        assert_eq!(
            Output::from_name("output_int_register_47"),
            Some(Output::OutputIntRegister(47))
        );
        assert_eq!(Output::from_name("output_int_register_48"), None);
        assert_eq!(Output::from_name("output_int_register_07"), None);
        assert_eq!(Output::from_name("nonexistent"), None);
        assert_eq!(
            Input::from_name("input_double_register_24"),
            Some(Input::DoubleRegister(24))
        );
        for t in VarType::ALL {
            assert_eq!(VarType::from_name(t.name()), Some(t));
        }
        for o in Output::fixed() {
            assert_eq!(Output::from_name(o.base_name()), Some(o));
        }
    }

    #[test]
    fn trailing_comma_is_ignored_and_errors_name_the_variable() {
        let r = OutputRecipe::from_answer("timestamp,actual_q,", 3, "DOUBLE,VECTOR6D").unwrap();
        assert_eq!(r.id, 3);
        assert_eq!(&r.fields[..], &[Output::Timestamp, Output::ActualQ]);
        assert_eq!(r.data_len(), 56);
        let e = OutputRecipe::from_answer("timestamp,bogus", 1, "DOUBLE,NOT_FOUND").unwrap_err();
        assert!(e.to_string().contains("`bogus`"), "{e}");
        let e = OutputRecipe::from_answer("timestamp", 1, "INT32").unwrap_err();
        assert!(matches!(e, RecipeError::TypeMismatch { .. }), "{e}");
        let e = OutputRecipe::from_answer("timestamp,actual_q", 1, "DOUBLE").unwrap_err();
        assert_eq!(e, RecipeError::CountMismatch { asked: 2, got: 1 });

        let mut s = String::new();
        let usable = answer_types(
            "timestamp,,nope,",
            |n| Output::from_name(n).map_or(Answered::NotFound, |o| Answered::Type(o.var_type())),
            &mut s,
        )
        .unwrap();
        assert_eq!(s, "DOUBLE,NOT_FOUND");
        assert!(!usable);
    }
}
