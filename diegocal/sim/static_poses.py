"""Static-pose calibration sessions with ground truth (issue #15): the robot held still in tens of
poses, as labs calibrate (encoders, a rigid marker cluster on the end effector, the mocap frame
unknown), some poses possibly filed with another pose's mocap frame. The observation models and
the truth draw are :mod:`diegocal.sim.kinematics`'s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diegocal.errors import RobotConfigError
from diegocal.io import Log, Truth, make_stream
from diegocal.robot import Robot, pot_transmission
from diegocal.sim.effects import SimOptionError
from diegocal.sim.kinematics import KinematicsOptions, draw_truth, joint_ranges, marker_positions, offset_robot


@dataclass(frozen=True)
class StaticPoseOptions:
    """Options of :func:`simulate_static_poses`: a lab's static-pose calibration session.

    Attributes
    ----------
    n_poses : int, poses the robot is driven to and held still in
    samples : int, samples recorded per pose (only the noise differs between them)
    wrong : int, poses whose mocap frame is another pose's (a labelling or clock mix-up: the
        reading does not belong to the pose it is filed under)
    spread : float in (0, 1], fraction of each joint's range the poses are drawn from (centred)
    gain_error, bias_error, marker_offset, pot_noise, marker_noise : as :class:`KinematicsOptions`
    """

    n_poses: int = 30
    samples: int = 1
    wrong: int = 0
    spread: float = 0.8
    gain_error: float = 0.2
    bias_error: float = 0.3
    marker_offset: float = 0.03
    pot_noise: float = 0.005
    marker_noise: float = 0.002

    def check(self) -> StaticPoseOptions:
        if self.n_poses < 2 or self.samples < 1:
            raise SimOptionError(f"need at least 2 poses and 1 sample each, got {self.n_poses} and {self.samples}")
        if not 0 <= self.wrong < self.n_poses:
            raise SimOptionError(f"wrong poses must be in [0, {self.n_poses}), got {self.wrong}")
        if not 0.0 < self.spread <= 1.0:
            raise SimOptionError(f"spread must be in (0, 1], got {self.spread}")
        KinematicsOptions(gain_error=self.gain_error, bias_error=self.bias_error, marker_offset=self.marker_offset,
                          pot_noise=self.pot_noise, marker_noise=self.marker_noise).check()
        return self


def simulate_static_poses(robot: Robot, options: StaticPoseOptions, rng: np.random.Generator) -> Log:
    """A static-pose session with ground truth: the robot held still in ``n_poses`` random poses.

    Joint angles are uniform in the central ``spread`` of each range; pots and markers follow the
    same observation models and truth draw as :func:`simulate_kinematics` (no occlusion, no
    effects). Pose k's ``samples`` samples are 10 ms apart and poses 2 s apart. The markers of
    ``wrong`` poses are replaced by those of another pose (with fresh noise). ``/truth`` holds the
    true parameters, the signals ``q`` (T, n), ``pose`` (T, 1) and ``markers_corrupted`` (T, M),
    and one effect record ``wrong_pose`` (channel ``markers``) listing the poses and their sources.
    """
    options.check()
    sensors = robot.sensors
    if not sensors.markers:
        raise RobotConfigError(f"robot {robot.name!r} has no markers: nothing to calibrate from poses")
    truth_rng, pose_rng, noise_rng = (np.random.default_rng(s) for s in rng.integers(0, 2**62, size=3))
    lo, hi = joint_ranges(robot)
    mid, half = 0.5 * (lo + hi), 0.5 * options.spread * (hi - lo)
    poses = pose_rng.uniform(mid - half, mid + half, (options.n_poses, robot.n_joints))
    label = np.repeat(np.arange(options.n_poses), options.samples)
    q = poses[label]
    T = q.shape[0]
    fast = offset_robot(robot, {})
    s = pot_transmission(fast, q) if sensors.pots else np.zeros((T, 0))
    kin_options = KinematicsOptions(gain_error=options.gain_error, bias_error=options.bias_error,
                                    marker_offset=options.marker_offset, pot_noise=options.pot_noise,
                                    marker_noise=options.marker_noise)
    truth = draw_truth(robot, kin_options, s, q, truth_rng)
    streams = {}
    if sensors.pots:
        p = truth.gain * s + truth.bias + noise_rng.normal(0.0, options.pot_noise, s.shape)
        streams["pots"] = make_stream(sensors.pot_names, p)
    wrong = np.sort(pose_rng.choice(options.n_poses, options.wrong, replace=False))
    source = np.arange(options.n_poses)
    for k in wrong:  # another pose's mocap frame, filed under pose k
        source[k] = (k + pose_rng.integers(1, options.n_poses)) % options.n_poses
    x = marker_positions(fast, poses[source][label], truth)
    x += noise_rng.normal(0.0, options.marker_noise, x.shape)
    streams["markers"] = make_stream(sensors.marker_names, x)
    corrupted = np.repeat(np.isin(label, wrong)[:, None], len(sensors.markers), axis=1)
    record = {"cause": "wrong_pose", "channel": "markers", "region": None,
              "values": {"poses": wrong.tolist(), "from": source[wrong].tolist()}}
    signals = {
        "q": make_stream(robot.joint_names, q),
        "pose": make_stream(["pose"], label[:, None].astype(float)),
        "markers_corrupted": make_stream(sensors.marker_names, corrupted.astype(float)),
    }
    time = 2.0 * label + 0.01 * (np.arange(T) - label * options.samples)
    return Log(
        time=time,
        streams=streams,
        robot=robot.reference,
        rate_hz=None,
        truth=Truth(params=truth.to_dict(), effects=[record] if options.wrong else [], signals=signals),
    )
