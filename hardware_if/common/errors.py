"""Errors of the ROS 2 interface, under the project's root :class:`~psm_control.errors.TissueRetractError`."""

from __future__ import annotations

from psm_control.errors import TissueRetractError

__all__ = ["DvrkError", "DvrkTimeoutError", "HoldError", "RosNotAvailableError"]


class DvrkError(TissueRetractError):
    """The dVRK (or the simulated one) did not do what was asked."""


class DvrkTimeoutError(DvrkError, TimeoutError):
    """A blocking request (enable, home, first measurement) did not complete in time.

    Attributes:
        what: What was waited for.
        timeout_s: How long [s].
        last_state: The last operating state seen (may be "").
    """

    def __init__(self, what: str, timeout_s: float, last_state: str = "") -> None:
        self.what = what
        self.timeout_s = timeout_s
        self.last_state = last_state
        seen = f"; last operating state {last_state!r}" if last_state else "; no operating state received"
        super().__init__(f"{what} did not complete within {timeout_s:.3g} s{seen}")


class RosNotAvailableError(TissueRetractError):
    """rclpy or the crtk_msgs interfaces are not installed (``pip install -e .[ros]``, then ``make install``)."""


class HoldError(TissueRetractError):
    """A fault during a deploy: the arm is held (nothing new is commanded) and the deploy stops (exit 4).

    Attributes:
        kind: What failed, e.g. ``"policy error"``, ``"invalid action"``, ``"policy overrun"``,
            ``"not ready"``, ``"invalid data"``, ``"fault"``.
        detail: What was wrong and what is allowed.
        data: The offending values (JSON-ready), recorded with the hold.
        recorded: The hold is in the recording already (it is recorded once).
    """

    def __init__(self, kind: str, detail: str, data: dict[str, object] | None = None) -> None:
        self.kind = kind
        self.detail = detail
        self.data = dict(data or {})
        self.recorded = False
        super().__init__(f"{kind}: {detail}")
