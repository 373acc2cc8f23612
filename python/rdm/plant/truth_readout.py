"""The plant's true state now (:meth:`PlantTruthReadout.ground_truth`): the whole record in
one Rust call, with the foot contact tracker's measurement when the plate touches something
or a contact anchor is held.

:class:`PlantTruthReadout` is a part of :class:`rdm.plant.plant.Plant`.
"""

from __future__ import annotations

import mujoco

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
        """The record in one Rust call (``RotorPlantCore.truth_record``: bit copies of the
        MjData arrays and the applied thrusts). Without plate contact and contact anchor (the
        flying robot, or one resting on other links) the core writes the numbers of an empty
        contact list itself (contacts without the plate are not summed); otherwise it takes
        the tracker's measurement."""
        d = self._fresh()
        tracker = self._tracker
        free = tracker.idle() and (d.ncon == 0 or not tracker.plate_contact(d))
        truth = self._rotors.truth_record(
            float(d.time),
            self._v_xpos,
            self._v_xquat,
            self._v_xmat,
            self._v_qpos,
            self._v_qvel,
            self._v_subtree_com,
            None if free else tracker.measure(d),
        )
        mujoco.mju_mat2Quat(truth.end_effector_quaternion, self._v_ee_xmat)  # MuJoCo's bits
        return truth
