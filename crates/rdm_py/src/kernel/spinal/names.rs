//! The mirror's attribute and method names the kernel reads and writes, interned once.

use pyo3::prelude::*;

use crate::kernel::attr::Name;

pub(super) struct Names {
    pub(super) counters: Name,
    pub(super) last_output: Name,
    pub(super) duties: Name,
    pub(super) duties_to_master: Name,
    pub(super) last_pub: Name,
    pub(super) imu: Name,
    pub(super) servo_states: Name,
    pub(super) battery_sample: Name,
    pub(super) session: Name,
    pub(super) counts: Name,
    pub(super) tx_frames: Name,
    pub(super) published: Name,
    pub(super) uart: Name,
    pub(super) bytes_out: Name,
    pub(super) dropped: Name,
    pub(super) bytes_lost: Name,
    pub(super) peer: Name,
    pub(super) inbox: Name,
    pub(super) extend: Name,
    pub(super) tx_bytes: Name,
    pub(super) tx_file: Name,
    pub(super) write: Name,
    pub(super) write_marked: Name,
}

impl Names {
    pub(super) fn new(py: Python<'_>) -> Names {
        Names {
            counters: Name::new(py, "counters"),
            last_output: Name::new(py, "last_output"),
            duties: Name::new(py, "duties"),
            duties_to_master: Name::new(py, "_duties_to_master"),
            last_pub: Name::new(py, "_last_pub"),
            imu: Name::new(py, "imu"),
            servo_states: Name::new(py, "servo/states"),
            battery_sample: Name::new(py, "_battery_sample"),
            session: Name::new(py, "session"),
            counts: Name::new(py, "counts"),
            tx_frames: Name::new(py, "tx_frames"),
            published: Name::new(py, "published"),
            uart: Name::new(py, "uart"),
            bytes_out: Name::new(py, "bytes_out"),
            dropped: Name::new(py, "dropped"),
            bytes_lost: Name::new(py, "bytes_lost"),
            peer: Name::new(py, "peer"),
            inbox: Name::new(py, "_inbox"),
            extend: Name::new(py, "extend"),
            tx_bytes: Name::new(py, "tx_bytes"),
            tx_file: Name::new(py, "_tx"),
            write: Name::new(py, "write"),
            write_marked: Name::new(py, "write_marked"),
        }
    }
}
