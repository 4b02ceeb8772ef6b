//! Robot, safety and control modes: the numbers on the wire and their names for error messages.
//!
//! `robot_mode` and `safety_mode` are RTDE outputs (INT32); the control mode is the last word of
//! the reverse-interface command ([`crate::reverse`]). Values as in docs/design.md §3.10.

macro_rules! wire_enum {
    ($(#[$m:meta])* $name:ident { $($(#[$vm:meta])* $var:ident = $val:expr, $text:expr;)* }) => {
        $(#[$m])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub enum $name {
            $($(#[$vm])* $var,)*
        }

        impl $name {
            /// The value on the wire.
            pub const fn code(self) -> i32 {
                match self { $(Self::$var => $val,)* }
            }

            /// The mode for a wire value, `None` if unknown.
            pub const fn from_code(code: i32) -> Option<Self> {
                match code { $($val => Some(Self::$var),)* _ => None }
            }

            /// The name Universal Robots' documentation uses.
            pub const fn name(self) -> &'static str {
                match self { $(Self::$var => $text,)* }
            }
        }

        impl core::fmt::Display for $name {
            fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                write!(f, "{} ({})", self.name(), self.code())
            }
        }
    };
}

wire_enum! {
    /// The robot's mode (RTDE output `robot_mode`). A driver may only command the arm in
    /// [`RobotMode::Running`].
    RobotMode {
        /// No controller.
        NoController = -1, "NO_CONTROLLER";
        /// Controller not connected to the arm.
        Disconnected = 0, "DISCONNECTED";
        /// Safety configuration waiting for confirmation.
        ConfirmSafety = 1, "CONFIRM_SAFETY";
        /// Booting.
        Booting = 2, "BOOTING";
        /// Arm power off.
        PowerOff = 3, "POWER_OFF";
        /// Arm power on, brakes engaged.
        PowerOn = 4, "POWER_ON";
        /// Powered, brakes released, no program running.
        Idle = 5, "IDLE";
        /// Back-drive mode.
        Backdrive = 6, "BACKDRIVE";
        /// Running: a program may move the arm.
        Running = 7, "RUNNING";
        /// Firmware update.
        UpdatingFirmware = 8, "UPDATING_FIRMWARE";
    }
}

wire_enum! {
    /// The safety system's mode (RTDE output `safety_mode`). Only [`SafetyMode::Normal`] (and
    /// `Reduced`) let the arm move.
    SafetyMode {
        /// Normal operation.
        Normal = 1, "NORMAL";
        /// Reduced limits in force.
        Reduced = 2, "REDUCED";
        /// Protective stop: the arm stopped on a limit or collision; needs unlocking.
        ProtectiveStop = 3, "PROTECTIVE_STOP";
        /// Recovery mode: outside the safety limits.
        Recovery = 4, "RECOVERY";
        /// Safeguard stop input.
        SafeguardStop = 5, "SAFEGUARD_STOP";
        /// System emergency stop.
        SystemEmergencyStop = 6, "SYSTEM_EMERGENCY_STOP";
        /// Robot emergency stop.
        RobotEmergencyStop = 7, "ROBOT_EMERGENCY_STOP";
        /// Safety violation.
        Violation = 8, "VIOLATION";
        /// Safety fault.
        Fault = 9, "FAULT";
        /// Validate joint identification.
        ValidateJointId = 10, "VALIDATE_JOINT_ID";
        /// Undefined safety mode.
        UndefinedSafetyMode = 11, "UNDEFINED_SAFETY_MODE";
        /// Automatic-mode safeguard stop.
        AutomaticModeSafeguardStop = 12, "AUTOMATIC_MODE_SAFEGUARD_STOP";
        /// Three-position enabling device stop.
        SystemThreePositionEnablingStop = 13, "SYSTEM_THREE_POSITION_ENABLING_STOP";
    }
}

wire_enum! {
    /// What the robot-side program does with a reverse-interface command (its last word).
    /// This project's program implements [`ControlMode::Servoj`] and [`ControlMode::Stopped`];
    /// it treats the others as "hold".
    ControlMode {
        /// Stop the program.
        Stopped = -2, "STOPPED";
        /// Not yet commanded.
        Uninitialized = -1, "UNINITIALIZED";
        /// Keep the connection, do not move.
        Idle = 0, "IDLE";
        /// Servo to joint targets (rad).
        Servoj = 1, "SERVOJ";
        /// Joint speeds (rad/s).
        Speedj = 2, "SPEEDJ";
        /// Trajectory forwarding.
        Forward = 3, "FORWARD";
        /// Tool speed.
        Speedl = 4, "SPEEDL";
        /// Tool pose.
        Pose = 5, "POSE";
        /// Freedrive.
        Freedrive = 6, "FREEDRIVE";
        /// Joint torques.
        Torque = 8, "TORQUE";
    }
}

/// A mode number for messages: the name when known, else the bare number.
pub fn robot_mode_name(code: i32) -> &'static str {
    RobotMode::from_code(code).map_or("unknown robot mode", RobotMode::name)
}

/// A mode number for messages: the name when known, else the bare number.
pub fn safety_mode_name(code: i32) -> &'static str {
    SafetyMode::from_code(code).map_or("unknown safety mode", SafetyMode::name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_and_names() {
        for c in -3..15 {
            if let Some(m) = RobotMode::from_code(c) {
                assert_eq!(m.code(), c);
            }
            if let Some(m) = SafetyMode::from_code(c) {
                assert_eq!(m.code(), c);
            }
            if let Some(m) = ControlMode::from_code(c) {
                assert_eq!(m.code(), c);
            }
        }
        assert_eq!(RobotMode::Running.to_string(), "RUNNING (7)");
        assert_eq!(safety_mode_name(3), "PROTECTIVE_STOP");
        assert_eq!(ControlMode::from_code(7), None);
    }
}
