//! A Dynamixel servo as a Neuron sees it (reference: `rdm.nodes.servo_model`): configuration,
//! the goal-sync handshake and a first-order motion model. Positions and currents are raw
//! Dynamixel units, as carried on CAN.

/// Dynamixel X "Profile Velocity" unit (0.229 rpm) in ticks/s (4096 ticks per revolution).
pub const TICKS_PER_S_PER_PROFILE_UNIT: f64 = 0.229 * 4096.0 / 60.0;
/// Dynamixel X default "Moving Threshold" (10 x 0.229 rpm) in ticks/s.
pub const MOVING_THRESHOLD_TICKS_PER_S: f64 = 10.0 * TICKS_PER_S_PER_PROFILE_UNIT;

/// Why a servo configuration is refused at setup.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServoConfigError {
    /// `initial_position` outside `[min_position, max_position]`.
    InitialPosition,
    /// `time_constant` not finite and > 0.
    TimeConstant,
    /// `current_per_tick` not finite.
    CurrentPerTick,
    /// `dynamixel_id` above 252.
    DynamixelId,
}

/// One servo behind a Neuron (what INITIAL_CONFIG_1/2/3 report) plus model parameters;
/// the defaults are those of the reference `ServoConfig`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoConfig {
    /// Dynamixel bus id 0..252.
    pub dynamixel_id: u8,
    /// False: a "gimbal" servo that reports no state on CAN.
    pub send_data_flag: bool,
    /// External encoder in use.
    pub external_encoder_flag: bool,
    /// Position P gain.
    pub p_gain: u16,
    /// Position I gain.
    pub i_gain: u16,
    /// Position D gain.
    pub d_gain: u16,
    /// 0 = no velocity limit, else 0.229 rpm units.
    pub profile_velocity: u16,
    /// Current limit (current units).
    pub current_limit: u16,
    /// Initial goal current.
    pub goal_current: i64,
    /// Joint resolution (ticks per joint revolution).
    pub joint_resolution: i16,
    /// Servo resolution (ticks per servo revolution).
    pub servo_resolution: i16,
    /// Lowest goal position (ticks).
    pub min_position: i64,
    /// Highest goal position (ticks).
    pub max_position: i64,
    /// Position at power-on (ticks).
    pub initial_position: i64,
    /// Reported temperature (deg C).
    pub temperature: i64,
    /// First-order lag of the position toward the goal (s), model assumption.
    pub time_constant: f64,
    /// Reported current per tick of position error while torque is on, model assumption.
    pub current_per_tick: f64,
}

impl Default for ServoConfig {
    fn default() -> Self {
        ServoConfig {
            dynamixel_id: 1,
            send_data_flag: true,
            external_encoder_flag: false,
            p_gain: 800,
            i_gain: 0,
            d_gain: 0,
            profile_velocity: 0,
            current_limit: 1193,
            goal_current: 0,
            joint_resolution: 4096,
            servo_resolution: 4096,
            min_position: 0,
            max_position: 4095,
            initial_position: 2048,
            temperature: 35,
            time_constant: 0.05,
            current_per_tick: 2.0,
        }
    }
}

impl ServoConfig {
    /// The reference's checks on a configuration.
    pub fn validate(&self) -> Result<(), ServoConfigError> {
        if !(self.min_position <= self.initial_position
            && self.initial_position <= self.max_position)
        {
            return Err(ServoConfigError::InitialPosition);
        }
        if !(self.time_constant.is_finite() && self.time_constant > 0.0) {
            return Err(ServoConfigError::TimeConstant);
        }
        if !self.current_per_tick.is_finite() {
            return Err(ServoConfigError::CurrentPerTick);
        }
        if self.dynamixel_id > 252 {
            return Err(ServoConfigError::DynamixelId);
        }
        Ok(())
    }
}

/// `int(min(max(round(value), low), high))` with Python's round-half-to-even.
pub fn clip_round(value: f64, low: i64, high: i64) -> i64 {
    let r = value.round_ties_even();
    if r.is_nan() {
        return 0; // unreachable for checked inputs; a defined value instead of a panic
    }
    r.max(low as f64).min(high as f64) as i64
}

/// Saturate an integer to int16.
pub fn sat_i16(value: i64) -> i16 {
    value.clamp(i16::MIN as i64, i16::MAX as i64) as i16
}

/// Run-time state of one servo.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoModel {
    /// Current configuration (board-config sub-commands change it).
    pub config: ServoConfig,
    /// Present position (ticks, float).
    pub position: f64,
    /// Velocity of the motion model (ticks/s).
    pub velocity: f64,
    goal: i64,
    /// Goal current (from servo-current frames).
    pub goal_current: i64,
    torque_enable: bool,
    /// Goal-sync handshake pending: reports carry the goal, goals need the ack bit.
    pub send_goal_position: bool,
    /// Reported temperature.
    pub temperature: i64,
    /// Dynamixel hardware error byte (non-zero keeps torque off).
    pub hardware_error: i64,
    /// Homing offset last set.
    pub homing_offset: i64,
    /// Round offset last set.
    pub round_offset: i64,
    /// When set, the reported current (else the position-error model).
    pub external_current: Option<i64>,
}

impl ServoModel {
    /// A servo at its configured initial position, torque off.
    pub fn new(config: ServoConfig) -> ServoModel {
        ServoModel {
            config,
            position: config.initial_position as f64,
            velocity: 0.0,
            goal: config.initial_position,
            goal_current: config.goal_current,
            torque_enable: false,
            send_goal_position: false,
            temperature: config.temperature,
            hardware_error: 0,
            homing_offset: 0,
            round_offset: 0,
            external_current: None,
        }
    }

    /// Goal position (ticks).
    pub fn goal(&self) -> i64 {
        self.goal
    }

    /// Torque on.
    pub fn torque_enable(&self) -> bool {
        self.torque_enable
    }

    /// Set the goal; bumps `changes` when it differs.
    pub fn set_goal(&mut self, value: i64, changes: &mut u64) {
        if value != self.goal {
            self.goal = value;
            *changes = changes.wrapping_add(1);
        }
    }

    fn set_torque_flag(&mut self, value: bool, changes: &mut u64) {
        if value != self.torque_enable {
            self.torque_enable = value;
            *changes = changes.wrapping_add(1);
        }
    }

    /// `setTorque`: a hardware error keeps torque off; torque-on latches the goal to the
    /// present position and starts the goal-sync handshake.
    pub fn set_torque(&mut self, enable: bool, changes: &mut u64) {
        let enable = enable && self.hardware_error == 0;
        if enable && !self.torque_enable {
            self.set_goal(self.present_position(), changes);
            self.send_goal_position = true;
        }
        self.set_torque_flag(enable, changes);
    }

    /// One goal word of a servo-angle frame; true when applied.
    pub fn command_goal(&mut self, value: i64, ack: bool, changes: &mut u64) -> bool {
        if !self.torque_enable {
            return false;
        }
        if self.send_goal_position {
            if !ack {
                return false;
            }
            self.send_goal_position = false;
        }
        // Python's min(max(v, low), high): `high` wins if the limits cross (never after setup).
        let goal = value
            .max(self.config.min_position)
            .min(self.config.max_position);
        self.set_goal(goal, changes);
        true
    }

    /// The reading frame shifts by the offset change: position and goal move together.
    pub fn set_homing_offset(&mut self, offset: i64, changes: &mut u64) {
        let delta = offset - self.homing_offset;
        self.homing_offset = offset;
        self.position += delta as f64;
        self.set_goal(self.goal + delta, changes);
    }

    /// First-order approach to the goal over `dt` seconds, rate-limited by the profile
    /// velocity when set.
    pub fn advance(&mut self, dt: f64) {
        if dt.is_nan() || dt <= 0.0 {
            return;
        }
        let before = self.position;
        if self.torque_enable {
            let goal = self.goal as f64;
            let mut step = (goal - self.position) * (1.0 - (-dt / self.config.time_constant).exp());
            if self.config.profile_velocity > 0 {
                let vmax = self.config.profile_velocity as f64 * TICKS_PER_S_PER_PROFILE_UNIT * dt;
                step = (-vmax).max(vmax.min(step));
            }
            self.position += step;
            if (goal - self.position).abs() < 0.5 {
                self.position = goal;
            }
        }
        self.velocity = (self.position - before) / dt;
    }

    /// Present position rounded and saturated to int16.
    pub fn present_position(&self) -> i64 {
        clip_round(self.position, i16::MIN as i64, i16::MAX as i64)
    }

    /// Moving flag (Dynamixel moving threshold).
    pub fn moving(&self) -> bool {
        self.velocity.abs() > MOVING_THRESHOLD_TICKS_PER_S
    }

    /// Reported current: external, 0 with torque off, else the clipped position-error model.
    pub fn current(&self) -> i64 {
        if let Some(c) = self.external_current {
            return c;
        }
        if !self.torque_enable {
            return 0;
        }
        let limit = self.config.current_limit as i64;
        clip_round(
            (self.goal as f64 - self.position) * self.config.current_per_tick,
            -limit,
            limit,
        )
    }

    /// Angle field of the state frame: the goal while the handshake is pending.
    pub fn reported_angle(&self) -> i64 {
        if self.send_goal_position {
            self.goal.clamp(i16::MIN as i64, i16::MAX as i64)
        } else {
            self.present_position()
        }
    }
}
