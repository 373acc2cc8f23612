"""The plant's true state now (:meth:`PlantTruthReadout.ground_truth`): the flying robot's
record in one Rust call, any contact state through the foot contact tracker's measurement.

:class:`PlantTruthReadout` is a part of :class:`rdm.plant.plant.Plant`.
"""

from __future__ import annotations

import mujoco
import numpy as np

from rdm.plant.truth import GroundTruth


class PlantTruthReadout:
    """The ground truth of :class:`rdm.plant.plant.Plant` (a part of it)."""

    def ground_truth(self) -> GroundTruth:
        """The true state now (see :class:`GroundTruth`). Asked twice for the same state
        (e.g. a logger and a mocap node in one tick), it returns the same object: treat
        its arrays as read-only."""
        cached = self._truth_cache
        if cached is not None and cached[0] == self._state.version:
            return cached[1]
        truth = self._ground_truth()
        self._truth_cache = (self._state.version, truth)
        return truth

    def _ground_truth(self) -> GroundTruth:
        d = self._fresh()
        tracker = self._tracker
        if tracker.idle() and (d.ncon == 0 or not tracker.plate_contact(d)):
            # No plate contact and no contact anchor (the flying robot, or one resting on
            # other links): the whole record in one Rust call, the numbers
            # :meth:`_ground_truth_arrays` gives (contacts without the plate are not summed;
            # tests/test_truthlog_truth.py); None when the plate frame is not finite.
            truth = self._rotors.truth_free(
                float(d.time),
                self._v_xpos,
                self._v_xquat,
                self._v_xmat,
                self._v_qpos,
                self._v_qvel,
                self._v_subtree_com,
            )
            if truth is not None:
                mujoco.mju_mat2Quat(truth.end_effector_quaternion, self._v_ee_xmat)
                return truth
        return self._ground_truth_arrays()

    def _ground_truth_arrays(self) -> GroundTruth:
        """:meth:`_ground_truth` for any contact state: the tracker's measurement, the
        MjData copies in one Rust call, the record built without the frozen ``__init__``."""
        d = self._fresh()
        points, force, torque, zmp, slip, yaw = self._tracker.measure(d)
        # Every MjData copy (and the applied thrusts) in one Rust call over the cached views
        # (stable for the data's lifetime): bit copies of MjData's arrays.
        pos, quat, lin, ang, qj, vj, cog, ee_pos, thrusts = self._rotors.truth_arrays(
            self._v_xpos, self._v_xquat, self._v_qpos, self._v_qvel, self._v_subtree_com
        )
        ee_quat = np.zeros(4)
        mujoco.mju_mat2Quat(ee_quat, self._v_xmat[self._ee_body])  # MuJoCo's own bits
        return GroundTruth.from_values(
            float(d.time),
            pos,
            quat,
            lin,
            ang,
            qj,
            vj,
            cog,
            ee_pos,
            ee_quat,
            thrusts,
            points > 0,
            points,
            force,
            torque,
            zmp,
            slip,
            yaw,
        )
