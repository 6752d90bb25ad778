"""The simulated arm's velocities: smooth when set-points arrive between the console's ticks."""

from __future__ import annotations

import numpy as np

from hardware_if.console.arm_model import VELOCITY_WINDOW_S, KinematicArm


def test_a_ramp_arriving_between_ticks_reads_its_own_velocity() -> None:
    """Set-points of a 0.5 rad/s ramp every 10 ms, console ticks alternating 4 and 16 ms apart: a one-tick
    difference would read 0 and twice the speed in turn; the arm reads the ramp's speed within 10 %."""
    arm = KinematicArm()
    arm.reset(np.zeros(6), 0.6)
    speed, command_s, now_s, readings = 0.5, 0.0, 0.0, []
    for tick in range(200):
        dt_s = 0.004 if tick % 2 else 0.016
        now_s += dt_s
        while command_s + 0.01 <= now_s:
            command_s += 0.01
            arm.command(np.full(6, speed * command_s), 0.6)
        sample = arm.step(dt_s)
        if now_s > 2 * VELOCITY_WINDOW_S:
            readings.append(sample.qd[0])
    assert np.all(np.abs(np.asarray(readings) - speed) <= 0.1 * speed), (min(readings), max(readings))
    assert arm.step(0.0).qd[0] == readings[-1]  # no time passed: the velocity stands
