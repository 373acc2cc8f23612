//! Robot description and the quasi-steady model of Sec. III (kinematics, allocation, ZMP).
