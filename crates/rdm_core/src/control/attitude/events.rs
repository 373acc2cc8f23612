//! Commands, acknowledgements and events of the Spinal flight state machine
//! (`jsk-wire-protocols.md` sec. 3.7, `spinal/FlightConfigCmd`).

/// A `spinal/FlightConfigCmd` value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlightConfigCmd {
    /// 0: start control (if the preconditions hold).
    ArmOn,
    /// 1: stop control, reset gains and integrals, motors to idle.
    ArmOff,
    /// 2: start force landing.
    ForceLanding,
    /// 160: integrate the roll/pitch errors.
    IntegrationControlOn,
    /// 161: stop integrating.
    IntegrationControlOff,
}

impl FlightConfigCmd {
    /// The command for a wire byte, if it is known.
    pub fn from_wire(cmd: u8) -> Option<Self> {
        match cmd {
            0 => Some(Self::ArmOn),
            1 => Some(Self::ArmOff),
            2 => Some(Self::ForceLanding),
            160 => Some(Self::IntegrationControlOn),
            161 => Some(Self::IntegrationControlOff),
            _ => None,
        }
    }

    /// The wire byte.
    pub fn to_wire(self) -> u8 {
        match self {
            Self::ArmOn => 0,
            Self::ArmOff => 1,
            Self::ForceLanding => 2,
            Self::IntegrationControlOn => 160,
            Self::IntegrationControlOff => 161,
        }
    }
}

/// Why a message to the controller was rejected or ignored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CommandError {
    /// An array's length differs from the motor number (firmware logs an error).
    WrongLength {
        /// Which message field.
        field: &'static str,
        /// The motor number (or accepted length).
        expected: usize,
        /// The length received.
        got: usize,
    },
    /// A NaN or infinite value (not checked by the firmware; refused here).
    NonFinite(&'static str),
    /// A FourAxisCommand while not armed (firmware: silently ignored).
    NotArmed,
    /// A FourAxisCommand below `force_landing_thrust` during force landing (ignored).
    BelowForceLandingThrust,
    /// The motor number is not known yet (no `uav_info`), so the message is ignored.
    MotorNumberUnknown,
    /// More motors than the board drives (`AttitudeControlConfig::motor_outputs`).
    TooManyMotors(usize),
    /// ARM_ON while `motor_number > 0 && uav_model >= 0 && max_duty > min_duty` is false:
    /// ignored without ack.
    NotActivated,
    /// An unknown `FlightConfigCmd` byte.
    UnknownFlightConfig(u8),
    /// A `PwmInfo` that failed its checks.
    InvalidPwmInfo(crate::pwm::PwmInfoError),
}

impl core::fmt::Display for CommandError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::WrongLength {
                field,
                expected,
                got,
            } => write!(f, "{field}: length {got}, motor number is {expected}"),
            Self::NonFinite(field) => write!(f, "{field}: not finite"),
            Self::NotArmed => write!(f, "four_axes/command: ignored, not armed"),
            Self::BelowForceLandingThrust => write!(
                f,
                "base_thrust: average below force_landing_thrust during force landing"
            ),
            Self::MotorNumberUnknown => write!(f, "motor number unknown: send uav_info first"),
            Self::TooManyMotors(n) => {
                write!(
                    f,
                    "motor_num: {n} > the rotors of this core (its ESC outputs)"
                )
            }
            Self::NotActivated => write!(
                f,
                "ARM_ON ignored: need motor_num > 0, uav_model >= 0 and max_pwm > min_pwm"
            ),
            Self::UnknownFlightConfig(cmd) => write!(f, "flight_config_cmd: unknown value {cmd}"),
            Self::InvalidPwmInfo(e) => write!(f, "motor_info: {e}"),
        }
    }
}

impl std::error::Error for CommandError {}

/// Something the controller reports to the PC or the log.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpinalEvent {
    /// `flight_config_ack` with this command (ARM_ON 0, ARM_OFF 1, FORCE_LANDING 2).
    Ack(FlightConfigCmd),
    /// "failsafe: cannot connect with ROS" (no FourAxisCommand for more than 500 ms).
    FailsafeCommandTimeout,
    /// "failsafe: the roll pitch angles are too large" (estimated tilt).
    FailsafeTilt,
    /// "failsafe: target angles are too large" (commanded tilt).
    FailsafeCommandTilt,
    /// A message was rejected with a firmware log error.
    Rejected(CommandError),
    /// A battery voltage was rejected by the voltage guard (or was not finite and
    /// positive); the last good voltage is in use. Reported on the first of a run.
    VoltageRejected,
    /// A FourAxisCommand value was saturated (`saturate_commands`). First of a run.
    CommandSaturated,
    /// A step computed a non-finite thrust; every rotor got `min_duty`. First of a run.
    NonFiniteOutput,
    /// A step's saturation factor alpha fell below -1 and was bounded to -1
    /// (`bound_alpha`). First of a run.
    AlphaBounded,
}

/// Fixed-capacity list of events (no allocation). Events beyond the capacity are counted
/// in [`EventList::dropped`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EventList {
    items: [Option<SpinalEvent>; Self::CAPACITY],
    len: usize,
    dropped: u32,
}

impl Default for EventList {
    fn default() -> Self {
        Self {
            items: [None; Self::CAPACITY],
            len: 0,
            dropped: 0,
        }
    }
}

impl EventList {
    /// Most events kept between two steps.
    pub const CAPACITY: usize = 16;

    /// Appends an event, or counts it as dropped when full.
    pub fn push(&mut self, event: SpinalEvent) {
        match self.items.get_mut(self.len) {
            Some(slot) => {
                *slot = Some(event);
                self.len += 1;
            }
            None => self.dropped = self.dropped.saturating_add(1),
        }
    }

    /// The events in order.
    pub fn iter(&self) -> impl Iterator<Item = &SpinalEvent> {
        self.items.iter().take(self.len).flatten()
    }

    /// Number of events kept.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether no event is kept.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Events lost because the list was full.
    pub fn dropped(&self) -> u32 {
        self.dropped
    }

    /// Empties the list.
    pub fn clear(&mut self) {
        *self = Self::default();
    }
}
