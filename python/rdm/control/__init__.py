"""Control: Python faces of the core's attitude, LQI, position and perching controllers."""
