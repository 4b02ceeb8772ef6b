//! The robot state carried by RTDE data packages, decoded (client) and encoded (controller)
//! through a negotiated recipe, without allocation.
//!
//! A data package's values are the recipe's variables in order, each in its type's size
//! ([`crate::VarType::size`]), big-endian. Every output of [`crate::Output`] has a field here,
//! so a decode followed by an encode with the same recipe reproduces the bytes.

use crate::recipe::{Input, InputRecipe, Output, OutputRecipe, N_REGISTERS};
use crate::rtde::RobotMessage;
use crate::wire::{Reader, Writer};
use crate::{DecodeError, EncodeError};

/// Six joint values, base to wrist 3.
pub type Joints = [f64; 6];

/// The controller's outputs this project knows. Units: rad, rad/s, s, A, m, °C.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RobotState {
    /// `timestamp`: s since the controller started.
    pub timestamp: f64,
    /// `target_q` (rad).
    pub target_q: Joints,
    /// `target_qd` (rad/s).
    pub target_qd: Joints,
    /// `actual_q` (rad).
    pub actual_q: Joints,
    /// `actual_qd` (rad/s).
    pub actual_qd: Joints,
    /// `actual_current` (A).
    pub actual_current: Joints,
    /// `actual_TCP_pose`: x, y, z (m), rx, ry, rz (axis-angle, rad).
    pub actual_tcp_pose: Joints,
    /// `actual_TCP_speed` (m/s, rad/s).
    pub actual_tcp_speed: Joints,
    /// `joint_temperatures` (°C).
    pub joint_temperatures: Joints,
    /// `robot_mode` ([`crate::RobotMode`] code).
    pub robot_mode: i32,
    /// `safety_mode` ([`crate::SafetyMode`] code).
    pub safety_mode: i32,
    /// `safety_status`.
    pub safety_status: i32,
    /// `joint_mode` per joint.
    pub joint_mode: [i32; 6],
    /// `runtime_state`: 1 stopped, 2 playing, 3 pausing, 4 paused, 5 resuming.
    pub runtime_state: u32,
    /// `robot_status_bits`.
    pub robot_status_bits: u32,
    /// `speed_scaling` (0..1).
    pub speed_scaling: f64,
    /// `target_speed_fraction` (0..1).
    pub target_speed_fraction: f64,
    /// `actual_execution_time` (ms).
    pub actual_execution_time: f64,
    /// `output_int_register_N`.
    pub output_int_registers: [i32; N_REGISTERS],
}

impl Default for RobotState {
    fn default() -> Self {
        Self {
            timestamp: 0.0,
            target_q: [0.0; 6],
            target_qd: [0.0; 6],
            actual_q: [0.0; 6],
            actual_qd: [0.0; 6],
            actual_current: [0.0; 6],
            actual_tcp_pose: [0.0; 6],
            actual_tcp_speed: [0.0; 6],
            joint_temperatures: [0.0; 6],
            robot_mode: 0,
            safety_mode: 0,
            safety_status: 0,
            joint_mode: [0; 6],
            runtime_state: 0,
            robot_status_bits: 0,
            speed_scaling: 0.0,
            target_speed_fraction: 0.0,
            actual_execution_time: 0.0,
            output_int_registers: [0; N_REGISTERS],
        }
    }
}

/// `runtime_state` values.
pub mod runtime_state {
    /// No program running.
    pub const STOPPED: u32 = 1;
    /// A program is running.
    pub const PLAYING: u32 = 2;
}

fn read6(r: &mut Reader<'_>) -> Result<Joints, DecodeError> {
    let mut v = [0.0; 6];
    for x in &mut v {
        *x = r.f64()?;
    }
    Ok(v)
}

fn write6(w: &mut Writer<'_>, v: &Joints) -> Result<(), EncodeError> {
    v.iter().try_for_each(|x| w.f64(*x))
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
            match *f {
                Output::Timestamp => self.timestamp = r.f64()?,
                Output::TargetQ => self.target_q = read6(&mut r)?,
                Output::TargetQd => self.target_qd = read6(&mut r)?,
                Output::ActualQ => self.actual_q = read6(&mut r)?,
                Output::ActualQd => self.actual_qd = read6(&mut r)?,
                Output::ActualCurrent => self.actual_current = read6(&mut r)?,
                Output::ActualTcpPose => self.actual_tcp_pose = read6(&mut r)?,
                Output::ActualTcpSpeed => self.actual_tcp_speed = read6(&mut r)?,
                Output::JointTemperatures => self.joint_temperatures = read6(&mut r)?,
                Output::RobotMode => self.robot_mode = r.i32()?,
                Output::SafetyMode => self.safety_mode = r.i32()?,
                Output::SafetyStatus => self.safety_status = r.i32()?,
                Output::JointMode => {
                    for m in &mut self.joint_mode {
                        *m = r.i32()?;
                    }
                }
                Output::RuntimeState => self.runtime_state = r.u32()?,
                Output::RobotStatusBits => self.robot_status_bits = r.u32()?,
                Output::SpeedScaling => self.speed_scaling = r.f64()?,
                Output::TargetSpeedFraction => self.target_speed_fraction = r.f64()?,
                Output::ActualExecutionTime => self.actual_execution_time = r.f64()?,
                Output::OutputIntRegister(n) => {
                    let v = r.i32()?;
                    if let Some(slot) = self.output_int_registers.get_mut(usize::from(n)) {
                        *slot = v;
                    }
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
        let mut w = Writer::package(buf)?;
        w.u8(recipe.id)?;
        for f in &recipe.fields {
            match *f {
                Output::Timestamp => w.f64(self.timestamp)?,
                Output::TargetQ => write6(&mut w, &self.target_q)?,
                Output::TargetQd => write6(&mut w, &self.target_qd)?,
                Output::ActualQ => write6(&mut w, &self.actual_q)?,
                Output::ActualQd => write6(&mut w, &self.actual_qd)?,
                Output::ActualCurrent => write6(&mut w, &self.actual_current)?,
                Output::ActualTcpPose => write6(&mut w, &self.actual_tcp_pose)?,
                Output::ActualTcpSpeed => write6(&mut w, &self.actual_tcp_speed)?,
                Output::JointTemperatures => write6(&mut w, &self.joint_temperatures)?,
                Output::RobotMode => w.i32(self.robot_mode)?,
                Output::SafetyMode => w.i32(self.safety_mode)?,
                Output::SafetyStatus => w.i32(self.safety_status)?,
                Output::JointMode => self.joint_mode.iter().try_for_each(|m| w.i32(*m))?,
                Output::RuntimeState => w.u32(self.runtime_state)?,
                Output::RobotStatusBits => w.u32(self.robot_status_bits)?,
                Output::SpeedScaling => w.f64(self.speed_scaling)?,
                Output::TargetSpeedFraction => w.f64(self.target_speed_fraction)?,
                Output::ActualExecutionTime => w.f64(self.actual_execution_time)?,
                Output::OutputIntRegister(n) => w.i32(
                    self.output_int_registers
                        .get(usize::from(n))
                        .copied()
                        .unwrap_or(0),
                )?,
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
