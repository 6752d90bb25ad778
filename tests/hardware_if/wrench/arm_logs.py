"""Free-space logs of an arm that moves under its own dynamics, made in the test: the shipped identified arm's
efforts (the effort model's regressor times its parameters) along a smooth motion, plus a measurement noise."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from bags import write_bag

from hardware_if.wrench.joint_logs import LND_COUPLING
from sim.identified_arm import identified_arm

RATE_HZ = 100.0
#: Joint amplitudes about the centre [rad, m]: yaw, pitch, insertion 8-16 cm, and the wrist.
AMPLITUDE = np.array([0.5, 0.4, 0.04, 0.8, 0.6, 0.6])
CENTRE = np.array([0.0, 0.0, 0.12, 0.0, 0.0, 0.0])


def motion(samples: int, phase: float, rate_hz: float = RATE_HZ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A slow Lissajous motion of every joint (q, qd, qdd), each (samples, 6)."""
    t = np.arange(samples) / rate_hz
    w = 2 * np.pi * np.array([0.13, 0.17, 0.11, 0.19, 0.23, 0.29])
    q = CENTRE + AMPLITUDE * np.sin(np.outer(t, w) + phase)
    qd = AMPLITUDE * w * np.cos(np.outer(t, w) + phase)
    qdd = -AMPLITUDE * w**2 * np.sin(np.outer(t, w) + phase)
    return q, qd, qdd


def arm_efforts(
    q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, *, noise: float = 0.01, scale: float = 1.0, seed: int = 0
) -> np.ndarray:
    """The identified WPI arm's efforts along a motion, times ``scale``, plus white noise of ``noise`` (N m, N)."""
    arm = identified_arm("wpi-psm")
    efforts = np.array([arm.efforts(q[k], qd[k], qdd[k]) for k in range(len(q))])
    return scale * efforts + np.random.default_rng(seed).normal(scale=noise, size=efforts.shape)


def arm_bag(path: Path, samples: int, phase: float, *, noise: float = 0.01, scale: float = 1.0, edit=None) -> Path:
    """A bag of the arm's free-space log; ``edit(q, qd, effort)`` may change the arrays in place first."""
    q, qd, qdd = motion(samples, phase)
    effort = arm_efforts(q, qd, qdd, noise=noise, scale=scale)
    if edit is not None:
        edit(q, qd, effort)
    return write_bag(path, q, qd, effort, rate_hz=RATE_HZ)


def arm_csv(path: Path, samples: int, phase: float) -> Path:
    """The arm's free-space log as a WPI-layout CSV (21 columns, the wrist and the jaw in motor space, 200 Hz)."""
    q, qd, qdd = motion(samples, phase, rate_hz=200.0)
    effort = arm_efforts(q, qd, qdd)
    jaw = np.zeros((samples, 1))
    inverse = np.linalg.inv(LND_COUPLING)
    columns = []
    for values, to_motor in ((q, inverse.T), (qd, inverse.T), (effort, LND_COUPLING)):
        full = np.hstack([values, jaw])
        full[:, 4:7] = full[:, 4:7] @ to_motor  # q_motor = C^-1 q_joint; tau_motor = C^T tau_joint
        columns.append(full)
    np.savetxt(path, np.hstack(columns), delimiter=",")
    return path
