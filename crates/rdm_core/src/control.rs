//! Flight and perching control of Sec. IV: LQI attitude/altitude, position, perching QP.
