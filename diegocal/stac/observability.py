"""What a log determines of the STAC parameters (thesis §2.5.1): unobservable pots and gauges.

A pot whose joints move no marker (or that has no channel in the log) cannot be calibrated; a
joint whose zero the markers cannot fix (a leaf gauge: every marker it moves rides on its own
child link; a root gauge: it moves every marker about an axis fixed in a fixed base) keeps one
reading pot's bias at nominal. :class:`Observability` holds these checks for
:class:`~diegocal.stac.model.Observation` (its data, robot and kinematics), which mixes it in.
"""

from __future__ import annotations

import numpy as np

from diegocal.errors import FitError
from diegocal.robot.gauges import axis_fixed_in_base, spanned_by_linear_pot

#: Why a pot of sensors.yaml that the log does not have is listed under ``unobservable``.
NO_CHANNEL = "no channel in the log"


class Observability:
    """The observability checks of an :class:`~diegocal.stac.model.Observation` (mixed into it:
    they read its ``robot``, ``kin``, pot and marker specs, ``A`` and ``valid``)."""

    def check_observable(self) -> None:
        """What the data determine (thesis §2.5.1), set once before a fit.

        A pot whose joint(s) move none of the log's markers relative to the base link has an
        unobservable gain and bias: both keep their nominal values (``fixed_gain``) and the pot is
        listed in ``unobservable``; it still tracks its joint. A pot of sensors.yaml that has no
        channel in the log is listed there too (reason :data:`NO_CHANNEL`): the calibration
        writes it at its nominal values, and it must not pass for calibrated. Gauge joints (:meth:`_gauge_biases`)
        keep one reading pot's bias at nominal and are listed in ``gauges``. Raises FitError only
        when nothing can be calibrated: no markers, every marker on the base link, a marker never
        seen, fewer than 10 frames.
        """
        if self.n_markers == 0:
            raise FitError(
                "STAC needs markers: no marker of the robot's sensors.yaml has a channel in the log "
                f"(robot {self.robot.name!r}; is it the log's robot? --robot names another)"
            )
        moving = [self.kin.moves(link) for link in self.marker_links]
        if not any(moving):
            raise FitError(
                "every marker is on a link fixed to the base link "
                f"{self.robot.sensors.base_link!r}: joint angles and pot gains/biases are "
                "unobservable; put markers on moving links"
            )
        if not self.valid.any(axis=0).all():
            dead = [n for n, ok in zip(self.marker_names, self.valid.any(axis=0), strict=True) if not ok]
            raise FitError(f"markers never seen (all NaN) in the log: {', '.join(dead)}")
        if self.n_frames < 10:
            raise FitError(f"too few samples for STAC: {self.n_frames} (need at least 10)")
        joints, _, _ = self.kin.link_info(self.marker_links)
        anc = self.kin._anc
        seen = (anc[joints] != anc[self.kin.base_joint]).any(axis=0)  # (n,) moves some marker
        names = self.robot.joint_names
        self.fixed_gain = np.zeros(self.n_pots, dtype=bool)
        unobservable = []
        for j, p in enumerate(self.pot_specs):
            cols = np.flatnonzero(self.A[j]) if p.kind != "linear" else np.zeros(0, dtype=int)
            blind = [names[c] for c in cols if not seen[c]]
            if blind:
                self.fixed_gain[j] = True
                what = "joint" if len(blind) == 1 else "joints"
                reason = f"no marker moves with {what} {', '.join(blind)}"
                unobservable.append({"pot": p.name, "joints": blind, "reason": reason})
        logged = set(self.pot_names)
        for p in self.robot.sensors.pots:  # a pot of sensors.yaml the log lacks (a misspelt channel?)
            if p.name not in logged:
                unobservable.append({"pot": p.name, "joints": list(p.joints), "reason": NO_CHANNEL})
        self.unobservable = tuple(unobservable)
        self.fixed_bias = self._gauge_biases(joints)
        self.gauges = self._gauge_records(joints)

    def _gauge_kinds(self, marker_joints: np.ndarray) -> dict:
        """{joint index: 'leaf' | 'root'} of the joints whose zero the markers cannot fix (none that
        a linear pot of the log spans: :func:`diegocal.robot.gauges.gauge_joints`' rule)."""
        anc, kin = self.kin._anc, self.kin
        spanned = spanned_by_linear_pot(self.robot, self.pot_specs)
        out = {}
        for k in range(self.robot.n_joints):
            moved = anc[marker_joints, k]
            if not moved.any() or spanned[k]:
                continue
            if (marker_joints[moved] == k + 1).all():
                out[k] = "leaf"
            elif kin.base_joint == 0 and moved.all() and axis_fixed_in_base(kin, k):
                out[k] = "root"
        return out

    def _gauge_reader(self, k: int) -> int | None:
        """The pot whose bias fixes joint k's gauge: the first rotary/encoder pot (else tendon)
        reading it, among those whose gain and bias are estimated."""
        readers = [j for j in np.flatnonzero(self.A[:, k]) if self.kinds[j] != "linear" and not self.fixed_gain[j]]
        readers.sort(key=lambda j: self.kinds[j] == "tendon")
        return readers[0] if readers else None

    def _gauge_biases(self, marker_joints: np.ndarray) -> np.ndarray:
        """Pots whose bias is fixed at nominal to remove a gauge freedom: (P,) bool.

        When every marker moved by joint k sits on k's own child link, an offset δ of q_k is
        exactly absorbed by rotating those markers about k's axis (d → Rot(a, −δ) d) and shifting
        the biases of the pots that read q_k (b → b − gain · r · δ): the likelihood is flat along
        it (leaf gauge). When a joint moves every marker along or about an axis fixed in a fixed
        base (:func:`diegocal.robot.gauges.axis_fixed_in_base`), moving the mocap frame does the
        same (root gauge). The first rotary/encoder pot (else tendon) reading such a joint keeps
        its nominal bias.
        """
        fixed = np.zeros(self.n_pots, dtype=bool)
        for k in self._gauge_kinds(marker_joints):
            j = self._gauge_reader(k)
            if j is not None:
                fixed[j] = True
        return fixed

    def _gauge_records(self, marker_joints: np.ndarray) -> tuple:
        """({joint, pot, kind, reason[, markers]}, ...) for calib.yaml's ``gauges`` (pot None when no
        pot with an estimated bias reads the joint: its tracked angle's zero is then arbitrary; a
        leaf gauge's ``markers``: those placed turned about its axis with its zero's convention)."""
        out = []
        for k, kind in self._gauge_kinds(marker_joints).items():
            joint = self.robot.joint_names[k]
            j = self._gauge_reader(k)
            if kind == "leaf":
                link = self.marker_links[int(np.flatnonzero(self.kin._anc[marker_joints, k])[0])]
                why = (
                    f"every marker joint {joint} moves is on link {link}: turning them about its axis "
                    "absorbs any offset of its zero"
                )
            elif self.kin.prismatic[k]:
                why = (
                    f"joint {joint} moves every marker along an axis fixed in the base: shifting the mocap "
                    "frame absorbs any offset of its zero"
                )
            else:
                why = (
                    f"joint {joint} moves every marker about an axis fixed in the base: turning the mocap "
                    "frame absorbs any offset of its zero"
                )
            if j is None:
                why += "; no calibrated pot reads it, so its tracked angle's zero is arbitrary"
            else:
                why += f"; pot {self.pot_specs[j].name}'s bias keeps its nominal value"
            pot = None if j is None else self.pot_specs[j].name
            out.append({"joint": joint, "pot": pot, "kind": kind, "reason": why})
            if kind == "leaf":
                out[-1]["markers"] = [self.marker_names[i] for i in np.flatnonzero(self.kin._anc[marker_joints, k])]
        return tuple(out)

    def gauge_joints(self) -> set[str]:
        """Joints whose zero is a gauge, fixed by keeping a reading pot's bias at nominal."""
        return {self.pot_specs[j].joint for j in np.flatnonzero(self.fixed_bias)}

    def gauge_free_markers(self) -> np.ndarray:
        """(M,) bool, in ``robot.sensors.markers`` order: markers whose position takes up no gauge
        (not on the child link of a gauge joint, about whose axis they would rotate with its zero)."""
        fixed, robot = self.gauge_joints(), self.robot
        out = []
        for m in robot.sensors.markers:
            joint = robot.model.frames[robot.frame_id(m.link)].parentJoint
            out.append(not (joint > 0 and robot.joint_names[joint - 1] in fixed))
        return np.array(out, dtype=bool)

    def gauge_equivalent_bias(self, true_gain, true_bias, fitted_bias) -> np.ndarray:
        """True biases (P,) moved into the gauge a fit fixed (for scoring against ground truth).

        A pot j whose bias is fixed at nominal (``fixed_bias``) shifts its joint k's zero by
        δ = (b_true,j − b_fit,j) / (gain_j r_jk), and every other pot i reading q_k by
        −gain_i r_ik δ; the other biases are unchanged.
        """
        out = np.array(true_bias, float)
        for j in np.flatnonzero(self.fixed_bias):
            k = int(np.argmax(np.abs(self.A[j])))
            delta = (true_bias[j] - fitted_bias[j]) / (true_gain[j] * self.A[j, k])
            for i in np.flatnonzero(self.A[:, k]):
                if i != j:
                    out[i] -= true_gain[i] * self.A[i, k] * delta
        return out
