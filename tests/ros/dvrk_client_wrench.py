"""Read ``body/measured_cf`` with the dVRK 2.4 Python client, unmodified, as a console user would.

Run by ``test_dvrk_client.py`` in a child process (see ``dvrk_client_checks.py``). Usage:
``dvrk_client_wrench.py ARM``. Enables and homes the arm, reads the body force at two poses and while the
arm moves between them, and prints ``WRENCH {json}`` with the three force magnitudes [N]. The read while
moving is one the console sent with joints between the two poses (same stamp as a ``measured_js`` seen
there), of a move slowed to :data:`MOVE_RATIO` so that a busy machine cannot miss it.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable

import crtk  # type: ignore[import-not-found]
import dvrk  # type: ignore[import-not-found]
import numpy as np

from tests.ros.rclpy_rate_race import close_the_race

close_the_race()

#: Trajectory ratio of the move between the two poses (about 3 s): long enough to read in its middle.
MOVE_RATIO = 0.2
#: Longest the script waits for an observable event before it fails [s]: a guard only.
GUARD_S = 30.0


def _force_n(arm: object, where: Callable[[np.ndarray], bool]) -> list[float] | None:
    """The body force of the console's first period seen whose ``measured_js`` (same stamp) is ``where``."""
    arm.body.measured_cf(wait_timeout=GUARD_S)  # type: ignore[attr-defined]
    deadline = time.monotonic() + GUARD_S
    while time.monotonic() < deadline:
        q, q_stamp = arm.measured_jp()  # type: ignore[attr-defined]
        wrench, wrench_stamp = arm.body.measured_cf()  # type: ignore[attr-defined]
        if wrench_stamp == q_stamp and where(q):
            return [float(v) for v in wrench[:3]]
        time.sleep(0.002)
    return None


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
        arm.move_jp(first).wait(timeout=GUARD_S)
        at_first = _force_n(arm, lambda q: bool(np.allclose(q, first, atol=1e-6)))
        arm.trajectory_j_set_ratio(MOVE_RATIO)
        ratio_deadline = time.monotonic() + GUARD_S
        while arm.trajectory_j_get_ratio() != MOVE_RATIO and time.monotonic() < ratio_deadline:
            time.sleep(0.005)
        handle = arm.move_jp(second)
        # Strictly between the poses in yaw, a tenth of the way from either end.
        moving = _force_n(arm, lambda q: bool(first[0] + 0.04 < q[0] < second[0] - 0.04))
        handle.wait(timeout=GUARD_S)
        arm.trajectory_j_set_ratio(1.0)
        at_second = _force_n(arm, lambda q: bool(np.allclose(q, second, atol=1e-6)))
        if at_first is None or moving is None or at_second is None:
            print(f"NO READ: first {at_first}, moving {moving}, second {at_second}", flush=True)
            return 1
        print("WRENCH " + json.dumps({"first": at_first, "moving": moving, "second": at_second}), flush=True)
        return 0
    finally:
        ral.shutdown()


if __name__ == "__main__":
    raise SystemExit(main())
