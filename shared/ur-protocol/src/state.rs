//! The robot state carried by RTDE data packages, decoded (client) and encoded (controller)
//! through a negotiated recipe, without allocation.
//!
//! A data package's values are the recipe's variables in order, each in its type's size
//! ([`crate::VarType::size`]), big-endian. Every output of [`crate::Output`] has a field here,
//! so a decode followed by an encode with the same recipe reproduces the bytes.

use crate::recipe::{Input, InputRecipe, Output, OutputRecipe, N_REGISTERS};
use crate::rtde::{RobotMessage, HEADER_LEN};
use crate::wire::{Reader, Writer};
use crate::{DecodeError, EncodeError};

/// Six joint values, base to wrist 3.
pub type Joints = [f64; 6];

/// One output's storage, typed as it travels (its [`crate::VarType`]).
enum Slot<'a> {
    F64(&'a mut f64),
    U32(&'a mut u32),
    I32(&'a mut i32),
    U64(&'a mut u64),
    V3(&'a mut [f64; 3]),
    V6(&'a mut [f64; 6]),
    V6I32(&'a mut [i32; 6]),
}

impl Slot<'_> {
    fn read(self, r: &mut Reader<'_>) -> Result<(), DecodeError> {
        match self {
            Slot::F64(v) => *v = r.f64()?,
            Slot::U32(v) => *v = r.u32()?,
            Slot::I32(v) => *v = r.i32()?,
            Slot::U64(v) => *v = r.u64()?,
            Slot::V3(v) => v.iter_mut().try_for_each(|x| r.f64().map(|y| *x = y))?,
            Slot::V6(v) => v.iter_mut().try_for_each(|x| r.f64().map(|y| *x = y))?,
            Slot::V6I32(v) => v.iter_mut().try_for_each(|x| r.i32().map(|y| *x = y))?,
        }
        Ok(())
    }

    fn write(self, w: &mut Writer<'_>) -> Result<(), EncodeError> {
        match self {
            Slot::F64(v) => w.f64(*v),
            Slot::U32(v) => w.u32(*v),
            Slot::I32(v) => w.i32(*v),
            Slot::U64(v) => w.u64(*v),
            Slot::V3(v) => v.iter().try_for_each(|x| w.f64(*x)),
            Slot::V6(v) => v.iter().try_for_each(|x| w.f64(*x)),
            Slot::V6I32(v) => v.iter().try_for_each(|x| w.i32(*x)),
        }
    }

    /// Bytes on the wire (checked against the output table in the tests).
    #[cfg(test)]
    fn size(&self) -> usize {
        match self {
            Slot::F64(_) | Slot::U64(_) => 8,
            Slot::U32(_) | Slot::I32(_) => 4,
            Slot::V3(_) | Slot::V6I32(_) => 24,
            Slot::V6(_) => 48,
        }
    }
}

/// Declares [`RobotState`] and its output → field map from one list.
macro_rules! robot_state {
    ($($(#[$doc:meta])* $output:ident => $field:ident : $ty:ty = $slot:ident,)*) => {
        /// The controller's outputs this project knows, one field per [`Output`]. Units: rad,
        /// rad/s, rad/s², s, A, V, N, N·m, m, °C.
        #[derive(Clone, Copy, Debug, PartialEq)]
        pub struct RobotState {
            $($(#[$doc])* pub $field: $ty,)*
            /// `output_int_register_N`.
            pub output_int_registers: [i32; N_REGISTERS],
            /// `output_double_register_N`.
            pub output_double_registers: [f64; N_REGISTERS],
        }

        impl Default for RobotState {
            fn default() -> Self {
                Self {
                    $($field: Default::default(),)*
                    output_int_registers: [0; N_REGISTERS],
                    output_double_registers: [0.0; N_REGISTERS],
                }
            }
        }

        impl RobotState {
            /// The storage of output `o`; `None` for a register number out of range.
            fn slot(&mut self, o: Output) -> Option<Slot<'_>> {
                Some(match o {
                    $(Output::$output => Slot::$slot(&mut self.$field),)*
                    Output::OutputIntRegister(n) => Slot::I32(self.output_int_registers.get_mut(usize::from(n))?),
                    Output::OutputDoubleRegister(n) => Slot::F64(self.output_double_registers.get_mut(usize::from(n))?),
                })
            }
        }
    };
}

robot_state! {
    /// `timestamp`: s since the controller started.
    Timestamp => timestamp: f64 = F64,
    /// `target_q` (rad).
    TargetQ => target_q: Joints = V6,
    /// `target_qd` (rad/s).
    TargetQd => target_qd: Joints = V6,
    /// `target_qdd` (rad/s²).
    TargetQdd => target_qdd: Joints = V6,
    /// `target_current` (A).
    TargetCurrent => target_current: Joints = V6,
    /// `target_moment` (N·m).
    TargetMoment => target_moment: Joints = V6,
    /// `actual_q` (rad).
    ActualQ => actual_q: Joints = V6,
    /// `actual_qd` (rad/s).
    ActualQd => actual_qd: Joints = V6,
    /// `actual_current` (A).
    ActualCurrent => actual_current: Joints = V6,
    /// `joint_control_output` (A).
    JointControlOutput => joint_control_output: Joints = V6,
    /// `actual_TCP_pose`: x, y, z (m), rx, ry, rz (axis-angle, rad).
    ActualTcpPose => actual_tcp_pose: Joints = V6,
    /// `actual_TCP_speed` (m/s, rad/s).
    ActualTcpSpeed => actual_tcp_speed: Joints = V6,
    /// `actual_TCP_force` (N, N·m).
    ActualTcpForce => actual_tcp_force: Joints = V6,
    /// `target_TCP_pose` (m, rad).
    TargetTcpPose => target_tcp_pose: Joints = V6,
    /// `target_TCP_speed` (m/s, rad/s).
    TargetTcpSpeed => target_tcp_speed: Joints = V6,
    /// `joint_temperatures` (°C).
    JointTemperatures => joint_temperatures: Joints = V6,
    /// `actual_joint_voltage` (V).
    ActualJointVoltage => actual_joint_voltage: Joints = V6,
    /// `actual_digital_input_bits`.
    ActualDigitalInputBits => actual_digital_input_bits: u64 = U64,
    /// `actual_digital_output_bits`.
    ActualDigitalOutputBits => actual_digital_output_bits: u64 = U64,
    /// `actual_tool_accelerometer` (m/s²).
    ActualToolAccelerometer => actual_tool_accelerometer: [f64; 3] = V3,
    /// `robot_mode` ([`crate::RobotMode`] code).
    RobotMode => robot_mode: i32 = I32,
    /// `safety_mode` ([`crate::SafetyMode`] code).
    SafetyMode => safety_mode: i32 = I32,
    /// `safety_status`.
    SafetyStatus => safety_status: i32 = I32,
    /// `safety_status_bits`.
    SafetyStatusBits => safety_status_bits: u32 = U32,
    /// `joint_mode` per joint.
    JointMode => joint_mode: [i32; 6] = V6I32,
    /// `runtime_state`: 1 stopped, 2 playing, 3 pausing, 4 paused, 5 resuming.
    RuntimeState => runtime_state: u32 = U32,
    /// `robot_status_bits`.
    RobotStatusBits => robot_status_bits: u32 = U32,
    /// `speed_scaling` (0..1).
    SpeedScaling => speed_scaling: f64 = F64,
    /// `target_speed_fraction` (0..1).
    TargetSpeedFraction => target_speed_fraction: f64 = F64,
    /// `actual_execution_time` (ms).
    ActualExecutionTime => actual_execution_time: f64 = F64,
    /// `actual_momentum` (kg·m/s).
    ActualMomentum => actual_momentum: f64 = F64,
    /// `actual_main_voltage` (V).
    ActualMainVoltage => actual_main_voltage: f64 = F64,
    /// `actual_robot_voltage` (V).
    ActualRobotVoltage => actual_robot_voltage: f64 = F64,
    /// `actual_robot_current` (A).
    ActualRobotCurrent => actual_robot_current: f64 = F64,
    /// `joint_position_deviation_ratio`.
    JointPositionDeviationRatio => joint_position_deviation_ratio: f64 = F64,
    /// `standard_analog_input0` (A or V).
    StandardAnalogInput0 => standard_analog_input0: f64 = F64,
    /// `standard_analog_input1` (A or V).
    StandardAnalogInput1 => standard_analog_input1: f64 = F64,
    /// `standard_analog_output0` (A or V).
    StandardAnalogOutput0 => standard_analog_output0: f64 = F64,
    /// `standard_analog_output1` (A or V).
    StandardAnalogOutput1 => standard_analog_output1: f64 = F64,
    /// `ft_raw_wrench`: raw force/torque sensor wrench (N, N·m).
    FtRawWrench => ft_raw_wrench: Joints = V6,
    /// `payload`: payload mass (kg).
    Payload => payload: f64 = F64,
    /// `payload_cog`: payload centre of gravity (m).
    PayloadCog => payload_cog: [f64; 3] = V3,
    /// `payload_inertia` (kg·m²).
    PayloadInertia => payload_inertia: Joints = V6,
}

/// `runtime_state` values.
pub mod runtime_state {
    /// No program running.
    pub const STOPPED: u32 = 1;
    /// A program is running.
    pub const PLAYING: u32 = 2;
}

impl RobotState {
    /// Client side: overwrites the fields of `recipe` from a data package's `recipe_id` and
    /// `values`. On error the state may be partly updated; treat the package as lost.
    pub fn decode_from(
        &mut self,
        recipe: &OutputRecipe,
        recipe_id: u8,
        values: &[u8],
    ) -> Result<(), DecodeError> {
        if recipe_id != recipe.id {
            return Err(DecodeError::WrongRecipe {
                got: recipe_id,
                expected: recipe.id,
            });
        }
        let mut r = Reader::new(values, "DATA_PACKAGE values");
        for f in &recipe.fields {
            match self.slot(*f) {
                Some(slot) => slot.read(&mut r)?,
                // A register beyond the table (not produced by `OutputRecipe`): skip its bytes.
                None => {
                    r.bytes(f.var_type().size())?;
                }
            }
        }
        r.end()
    }

    /// Client side: decodes a received package if it is a data package (returns `Ok(true)`),
    /// leaves the state alone for any other package (`Ok(false)`).
    pub fn update(
        &mut self,
        recipe: &OutputRecipe,
        message: &RobotMessage<'_>,
    ) -> Result<bool, DecodeError> {
        match *message {
            RobotMessage::DataPackage { recipe_id, values } => {
                self.decode_from(recipe, recipe_id, values)?;
                Ok(true)
            }
            _ => Ok(false),
        }
    }

    /// Controller side: writes a whole DATA_PACKAGE frame for `recipe` into `buf`; returns
    /// its length.
    pub fn encode_package(
        &self,
        recipe: &OutputRecipe,
        buf: &mut [u8],
    ) -> Result<usize, EncodeError> {
        let mut w = Writer::after_header(buf, HEADER_LEN)?;
        w.u8(recipe.id)?;
        // The slots borrow mutably; encode from a copy (plain data, no allocation).
        let mut s = *self;
        for f in &recipe.fields {
            match s.slot(*f) {
                Some(slot) => slot.write(&mut w)?,
                None => w.put(&[0u8; 48][..f.var_type().size()])?,
            }
        }
        w.finish_package(crate::PackageType::DataPackage as u8)
    }
}

/// The input registers a client writes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InputRegisters {
    /// `input_double_register_N`.
    pub double: [f64; N_REGISTERS],
    /// `input_int_register_N`.
    pub int: [i32; N_REGISTERS],
}

impl Default for InputRegisters {
    fn default() -> Self {
        Self {
            double: [0.0; N_REGISTERS],
            int: [0; N_REGISTERS],
        }
    }
}

impl InputRegisters {
    /// Controller side: applies a client's data package for `recipe`.
    pub fn decode_from(
        &mut self,
        recipe: &InputRecipe,
        recipe_id: u8,
        values: &[u8],
    ) -> Result<(), DecodeError> {
        if recipe_id != recipe.id {
            return Err(DecodeError::WrongRecipe {
                got: recipe_id,
                expected: recipe.id,
            });
        }
        let mut r = Reader::new(values, "input DATA_PACKAGE values");
        for f in &recipe.fields {
            match *f {
                Input::DoubleRegister(n) => {
                    let v = r.f64()?;
                    if let Some(s) = self.double.get_mut(usize::from(n)) {
                        *s = v;
                    }
                }
                Input::IntRegister(n) => {
                    let v = r.i32()?;
                    if let Some(s) = self.int.get_mut(usize::from(n)) {
                        *s = v;
                    }
                }
            }
        }
        r.end()
    }

    /// Client side: writes the values of `recipe` (no header, no recipe id) into `buf`;
    /// returns their length. Send them with [`crate::ClientMessage::DataPackage`].
    pub fn encode_values(
        &self,
        recipe: &InputRecipe,
        buf: &mut [u8],
    ) -> Result<usize, EncodeError> {
        let mut w = Writer::raw(buf);
        for f in &recipe.fields {
            match *f {
                Input::DoubleRegister(n) => {
                    w.f64(self.double.get(usize::from(n)).copied().unwrap_or(0.0))?
                }
                Input::IntRegister(n) => {
                    w.i32(self.int.get(usize::from(n)).copied().unwrap_or(0))?
                }
            }
        }
        Ok(w.pos())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rtde::{Frame, Protocol};

    #[test]
    fn urcl_vector_decodes_into_the_state() {
        // Recipe 1 = timestamp, speed_scaling: the 20-byte package of docs/design.md §3.10.
        let recipe =
            OutputRecipe::from_answer("timestamp,speed_scaling", 1, "DOUBLE,DOUBLE").unwrap();
        let bytes = hex("00145501 40d0070d2f1a9fbe 3ff0000000000000");
        let (f, _) = Frame::parse(&bytes, 64).unwrap().unwrap();
        let m = RobotMessage::decode(&f, Protocol::V2).unwrap();
        let mut s = RobotState::default();
        assert!(s.update(&recipe, &m).unwrap());
        assert!((s.timestamp - 16412.206).abs() < 1e-3);
        assert_eq!(s.speed_scaling, 1.0);
        let mut out = [0u8; 64];
        let n = s.encode_package(&recipe, &mut out).unwrap();
        assert_eq!(&out[..n], &bytes[..]);
    }

    #[test]
    fn every_output_slot_has_its_wire_size() {
        let mut s = RobotState::default();
        let regs = [
            Output::OutputIntRegister(47),
            Output::OutputDoubleRegister(0),
        ];
        for o in Output::fixed().chain(regs) {
            assert_eq!(s.slot(o).unwrap().size(), o.var_type().size(), "{o:?}");
        }
    }

    #[test]
    fn wrong_recipe_and_short_package_are_errors() {
        let recipe = OutputRecipe::from_answer("actual_q", 2, "VECTOR6D").unwrap();
        let mut s = RobotState::default();
        assert_eq!(
            s.decode_from(&recipe, 1, &[0; 48]),
            Err(DecodeError::WrongRecipe {
                got: 1,
                expected: 2
            })
        );
        assert!(matches!(
            s.decode_from(&recipe, 2, &[0; 47]),
            Err(DecodeError::Truncated { .. })
        ));
    }

    #[test]
    fn inputs_round_trip() {
        let recipe = InputRecipe {
            id: 4,
            fields: [Input::IntRegister(24), Input::DoubleRegister(3)]
                .into_iter()
                .collect(),
        };
        let mut regs = InputRegisters::default();
        regs.int[24] = -7;
        regs.double[3] = 2.5;
        let mut buf = [0u8; 16];
        let n = regs.encode_values(&recipe, &mut buf).unwrap();
        assert_eq!(n, 12);
        let mut back = InputRegisters::default();
        back.decode_from(&recipe, 4, &buf[..n]).unwrap();
        assert_eq!(back, regs);
    }

    pub(crate) fn hex(s: &str) -> std::vec::Vec<u8> {
        let s: String = s.split_whitespace().collect();
        (0..s.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
            .collect()
    }
}
