"""Read ``body/measured_cf`` with the dVRK 2.4 Python client, unmodified, as a console user would.

Run by ``test_dvrk_client.py`` in a child process (see ``dvrk_client_checks.py``). Usage:
``dvrk_client_wrench.py ARM``. Enables and homes the arm, reads the body force at two poses and while the
arm moves between them, and prints ``WRENCH {json}`` with the three force magnitudes [N].
"""

from __future__ import annotations

import json
import sys

import crtk  # type: ignore[import-not-found]
import dvrk  # type: ignore[import-not-found]
import numpy as np

from tests.ros.rclpy_rate_race import close_the_race

close_the_race()


def _force_n(arm: object) -> list[float]:
    wrench, _ = arm.body.measured_cf(wait_timeout=5.0)  # type: ignore[attr-defined]
    return [float(v) for v in wrench[:3]]


def main() -> int:
    arm_name = sys.argv[1]
    ral = crtk.ral("dvrk_client_wrench")
    ral.spin()
    try:
        arm = dvrk.psm(ral, arm_name)
        ral.check_connections(30.0)
        if not (arm.enable(10) and arm.home(20)):
            print("ENABLE/HOME FAILED", flush=True)
            return 1
        first, second = np.array([0.0, 0.0, 0.12, 0.0, 0.0, 0.0]), np.array([0.4, -0.3, 0.16, 0.3, 0.2, -0.2])
        arm.move_jp(first).wait(timeout=30.0)
        at_first = _force_n(arm)
        handle = arm.move_jp(second)
        moving = _force_n(arm)  # the move takes about a second: this read is mid-motion
        handle.wait(timeout=30.0)
        at_second = _force_n(arm)
        print("WRENCH " + json.dumps({"first": at_first, "moving": moving, "second": at_second}), flush=True)
        return 0
    finally:
        ral.shutdown()


if __name__ == "__main__":
    raise SystemExit(main())
