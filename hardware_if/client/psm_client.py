"""A PSM client speaking the dVRK's CRTK topics: a control-chain :class:`~psm_control.commands.Backend`.

:class:`PsmClient` subscribes to the arm's state and events, as the
:class:`~hardware_if.client.arm_listener.ArmListener` it is, and publishes its commands. It spins its own
executor on a background thread, so :meth:`PsmClient.measure` and :meth:`PsmClient.servo_jp` are plain
calls from the control loop, the same as on the simulation. A :class:`~hardware_if.client.deadman.Deadman`
guards every motion command: on a stale measurement (one whose stamp stopped advancing is stale too), a
vanished publisher, an arm not ENABLED and homed, or a tracking error beyond the dVRK's tolerances, the
client stops forwarding commands, holds by re-sending the arm's current set-point, logs the reason once,
and reports it in :attr:`PsmClient.status`.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from crtk_msgs.msg import OperatingState, StringStamped  # type: ignore[import-untyped]
from geometry_msgs.msg import PoseStamped  # type: ignore[import-untyped]
from rclpy.context import Context
from rclpy.publisher import Publisher
from sensor_msgs.msg import JointState  # type: ignore[import-untyped]

from hardware_if.client.arm_listener import CLOCK_SLACK_S, ArmListener
from hardware_if.client.deadman import ArmFacts, Deadman, DeadmanStatus
from hardware_if.common import convert
from hardware_if.common.commander_watch import (
    NAME_WAIT_S,
    NAMING_TIMEOUT_S,
    UNNAMED,
    WATCH_PERIOD_S,
    CommanderWatch,
)
from hardware_if.common.crtk import DEFAULT_ARM, JAW_JOINT_NAME, JOINT_NAMES, event_qos, periodic_qos
from hardware_if.common.errors import DvrkError, DvrkTimeoutError
from psm_control.commands import JointCommand
from safety.config import SafetyConfig

__all__ = ["PsmClient"]

#: How often the watchdog looks at the arm [s] (also how often it counts publishers in the graph).
WATCHDOG_PERIOD_S = 0.02
#: A state command is re-sent this often while waiting, in case discovery had not matched yet [s].
RESEND_PERIOD_S = 0.5
#: An arm that reports homed and idle without passing through homing is taken as homed after this [s].
HOME_GRACE_S = 1.0


class PsmClient(ArmListener):
    """Client of one dVRK arm over ROS 2.

    Args:
        arm: Arm name / namespace (``PSM1``, ``PSM2``, ...).
        deadman_timeout_s: Largest age of ``measured_js`` before holding [s]; None: the chain's
            :attr:`SafetyConfig.deadman_timeout_s <safety.config.SafetyConfig.deadman_timeout_s>` default.
        on_fault: Called (from the ROS thread) with the status when a hold starts.
        on_measured: Called (from the ROS thread) with each ``measured_js`` and its arrival time on
            ``time.perf_counter`` [s], e.g. to record or time the stream.
        node_name: ROS node name; default ``<arm>_client``.
        listen_only: Create no command publishers at all (a dry run): the client only subscribes, and
            every command method raises :class:`~hardware_if.common.errors.DvrkError`.
        context: The rclpy context (default: the global one), e.g. one per ROS domain.

    Use as a context manager (or call :meth:`start` and :meth:`close`).
    """

    def __init__(
        self,
        arm: str = DEFAULT_ARM,
        *,
        deadman_timeout_s: float | None = None,
        on_fault: Callable[[DeadmanStatus], None] | None = None,
        on_measured: Callable[[JointState, float], None] | None = None,
        node_name: str | None = None,
        listen_only: bool = False,
        context: Context | None = None,
    ) -> None:
        super().__init__(arm, node_name=node_name or f"{arm.lower()}_client", on_measured=on_measured, context=context)
        timeout_s = SafetyConfig().deadman_timeout_s if deadman_timeout_s is None else deadman_timeout_s
        self._deadman = Deadman(timeout_s=timeout_s)
        self._on_fault = on_fault
        self._graph_publishers = -1
        self._commanders: CommanderWatch | None = None
        self._conflict = ""
        self._watch_ticks = 0
        self._unnamed_since_s = float("inf")
        self._pending_unnamed = ""
        self._commanding = False
        self._hold_q: np.ndarray | None = None

        state, event = periodic_qos(), event_qos()
        t = self.topics.topic
        self.listen_only = listen_only
        publishers: dict[str, Publisher | None] = dict.fromkeys(
            ("servo_jp", "servo_cp", "move_jp", "move_cp", "jaw/servo_jp", "jaw/move_jp", "state_command")
        )
        if not listen_only:
            for name in ("servo_jp", "move_jp", "jaw/servo_jp", "jaw/move_jp"):
                publishers[name] = self.create_publisher(JointState, t(name), state)
            for name in ("servo_cp", "move_cp"):
                publishers[name] = self.create_publisher(PoseStamped, t(name), state)
            publishers["state_command"] = self.create_publisher(StringStamped, t("state_command"), event)
        self._commands = publishers
        self.create_timer(WATCHDOG_PERIOD_S, self._watch)

    def _watch(self) -> None:
        try:
            publishers = self.count_publishers(self.topics.topic("measured_js"))
        except Exception:  # the graph is unavailable while shutting down
            return
        self._watch_ticks += 1
        conflict = None
        if self._commanders is not None and self._watch_ticks % round(WATCH_PERIOD_S / WATCHDOG_PERIOD_S) == 0:
            conflict = self._unnamed_conflict(self._commanders.conflict())
        with self._lock:
            self._graph_publishers = publishers
            if conflict is not None and conflict != self._conflict:
                self._conflict = conflict
                if conflict:
                    self.get_logger().error(f"{self.topics.arm}: {conflict}")
                self._lock.notify_all()
            if self._commanding:
                self._apply_deadman()

    # -- one commander ----------------------------------------------------------------------------
    def _unnamed_conflict(self, raw: str) -> str | None:
        """The conflict to act on: one whose node has no name yet waits up to NAME_WAIT_S for it (None).

        A node that leaves before its name arrives was still another commander: its unnamed conflict stands.
        """
        now = time.monotonic()
        if UNNAMED in raw:
            if not self._pending_unnamed:
                self._unnamed_since_s = now
            self._pending_unnamed = raw
            return raw if now - self._unnamed_since_s >= NAME_WAIT_S else None
        conflict, self._pending_unnamed = raw or self._pending_unnamed, ""
        return conflict

    def watch_commanders(self, *own_nodes: str, sensed: tuple[str, ...] = ()) -> None:
        """Watch the graph for other commanders, consoles and sources of the arm
        (:mod:`hardware_if.common.commander_watch`).

        From now on the deadman holds on one, every state command is refused while there is one, and
        :meth:`exclusive` reads the graph at once. ``own_nodes`` are this program's other nodes (fully
        qualified names); this node is one of its own. ``sensed`` are other topics the run acts on (fully
        qualified, e.g. the endoscope's images), watched for a second source as the arm's state topics are.
        """
        self._commanders = CommanderWatch(
            self, self.topics.arm, {self.get_fully_qualified_name(), *own_nodes}, sensed=sensed
        )

    def pin_sources(self) -> None:
        """Take the sensed topics' publishers now as the run's only sources (before the first command)."""
        if self._commanders is not None:
            self._commanders.pin_sources()

    def settle_graph(self, timeout_s: float) -> None:
        """Wait for discovery to go quiet before the first command (see :meth:`CommanderWatch.settle`)."""
        if self._commanders is not None:
            self._commanders.settle(self._joined_s, timeout_s=timeout_s)

    def exclusive_within(self, timeout_s: float) -> str:
        """:meth:`exclusive`, read again until it names a conflict or ``timeout_s`` passed (discovery lags)."""
        deadline = time.monotonic() + timeout_s
        reason = self.exclusive()
        while not reason and time.monotonic() < deadline:
            time.sleep(WATCH_PERIOD_S)
            reason = self.exclusive()
        return reason

    def named(self, reason: str, timeout_s: float = NAMING_TIMEOUT_S) -> str:
        """A hold's ``reason`` with the names of the other nodes it is about, once discovery brings them.

        Called with the arm already held, so waiting for the names costs time only; ``reason`` as it is when
        no name arrives within ``timeout_s``, or when the conflict is gone (the other node left).
        """
        if UNNAMED not in reason or self._commanders is None:
            return reason
        named = self._commanders.named_conflict(wait_s=timeout_s)
        return named if named and UNNAMED not in named else reason

    def exclusive(self) -> str:
        """Read the graph now: "" when this program alone commands the arm and one console serves it.

        Otherwise the reason (``another commander: ...`` or ``another console: ...``), which the deadman
        then holds on. Without :meth:`watch_commanders`, always "".
        """
        if self._commanders is None:
            return ""
        reason = self._commanders.named_conflict()  # consoles by what they serve, not by who listens
        with self._lock:
            self._conflict = reason
            self._lock.notify_all()
        return reason

    # -- deadman ----------------------------------------------------------------------------------
    def _facts(self) -> ArmFacts:
        measured_q = None
        if self._measured is not None:
            try:
                measured_q = convert.joint_state_positions(self._measured)
            except ValueError:
                measured_q = None
        return ArmFacts(
            now_s=time.monotonic(),
            measured_rx_s=self._measured_rx_s,
            publishers=self._graph_publishers,
            state=self._state.state if self._state_received else "",
            is_homed=bool(self._state.is_homed),
            measured_q=measured_q,
            setpoint_q=self._setpoint_q,
            data_fault=self._data_fault,
            conflict=self._conflict,
            repeated_rx_s=self._repeated_rx_s,
        )

    def _apply_deadman(self) -> DeadmanStatus:
        """Update the deadman (lock held); on a new fault, log it, latch the hold set-point, send it."""
        was_holding = self._deadman.status.holding
        status = self._deadman.update(self._facts())
        if status.holding and not was_holding:
            facts = self._facts()
            self._hold_q = next(
                (q.copy() for q in (self._setpoint_q, facts.measured_q) if q is not None),
                None,
            )
            # A listener (a dry run, register) commands nothing, so nothing holds the arm: it says so.
            verb = "stopped, nothing commanded" if self.listen_only else "holding"
            self.get_logger().error(f"{self.topics.arm}: {verb}, {status.reason}")
            self._send_hold()
            if self._on_fault is not None:
                self._on_fault(status)
        return status

    def _send_hold(self) -> None:
        self._commanded_qdd = np.zeros(6)  # a hold is a set-point at rest
        if self._hold_q is not None:
            self._command_publisher("servo_jp").publish(
                convert.joint_state(JOINT_NAMES, self._hold_q, stamp_s=self._now_s())
            )

    @property
    def status(self) -> DeadmanStatus:
        """The deadman's verdict: ``holding`` and ``reason`` tell why commands are not forwarded."""
        with self._lock:
            if self._commanding:
                return self._deadman.status
            reason = self._deadman.check(self._facts())
            return DeadmanStatus(not reason, False, reason)

    def resume(self) -> DeadmanStatus:
        """Clear a hold if the arm is fresh, present, ENABLED, homed and tracking; return the status."""
        with self._lock:
            self._data_fault = ""
            status = self._deadman.release(self._facts())
            if not status.holding:
                self._hold_q = None
            return status

    # -- Backend ----------------------------------------------------------------------------------
    def servo_jp(self, command: JointCommand) -> None:
        """Forward a joint set-point (and the jaw) if the deadman allows; otherwise re-send the hold."""
        self._command_publisher("servo_jp")  # a listen-only client refuses before touching the deadman
        with self._lock:
            self._commanding = True
            self.pin_clock()  # the lock is re-entrant
            status = self._apply_deadman()
            if status.holding:
                self._send_hold()
                return
            stamp = self._now_s()
            self._commanded_qdd = np.asarray(command.qdd, dtype=float).copy()
            self._command_publisher("servo_jp").publish(convert.joint_state(JOINT_NAMES, command.q, stamp_s=stamp))
            self._command_publisher("jaw/servo_jp").publish(
                convert.joint_state((JAW_JOINT_NAME,), [command.jaw], stamp_s=stamp)
            )

    # -- other CRTK commands ----------------------------------------------------------------------
    def servo_cp(self, pose_base: np.ndarray) -> bool:
        """Send a tool pose goal (4x4, base frame); False (and nothing sent) when the deadman holds."""
        return self._send_pose("servo_cp", pose_base)

    def move_cp(self, pose_base: np.ndarray) -> bool:
        """Send a tool pose goal reached by the arm's own trajectory; False when the deadman holds."""
        return self._send_pose("move_cp", pose_base)

    def _send_pose(self, name: str, pose_base: np.ndarray) -> bool:
        publisher = self._command_publisher(name)
        with self._lock:
            if self._commanding and self._apply_deadman().holding:
                return False
            message = convert.pose_stamped(pose_base, self.topics.base_frame_id, self._now_s())
            publisher.publish(message)
            return True

    def move_jp(self, q: np.ndarray) -> None:
        """Send a joint goal the arm reaches with its own trajectory (not guarded: the arm plans it)."""
        self._command_publisher("move_jp").publish(convert.joint_state(JOINT_NAMES, q, stamp_s=self._now_s()))

    def jaw_move_jp(self, jaw: float) -> None:
        """Send a jaw angle goal [rad] the console reaches with its own trajectory (not guarded, as ``move_jp``)."""
        self._command_publisher("jaw/move_jp").publish(
            convert.joint_state((JAW_JOINT_NAME,), [jaw], stamp_s=self._now_s())
        )

    def jaw_servo_jp(self, jaw: float) -> None:
        """Send a jaw angle set-point [rad]."""
        self._command_publisher("jaw/servo_jp").publish(
            convert.joint_state((JAW_JOINT_NAME,), [jaw], stamp_s=self._now_s())
        )

    def _command_publisher(self, name: str) -> Publisher:
        publisher = self._commands[name]
        if publisher is None:
            raise DvrkError(f"{self.topics.arm}: {name} refused, this client listens only (dry run)")
        return publisher

    def wait_ready(self, timeout_s: float, *, after_s: float = float("-inf")) -> str:
        """Wait until the arm is fresh, present, ENABLED, homed, idle and tracking, with valid data.

        Args:
            timeout_s: How long to wait [s].
            after_s: Judge only a ``measured_js`` that arrived after this ``time.monotonic`` [s].

        Returns:
            "" when ready; otherwise the reason it was not within ``timeout_s`` (at once for invalid data,
            which does not clear by waiting).
        """
        deadline = time.monotonic() + timeout_s
        with self._lock:
            while True:
                reason = self._deadman.check(self._facts())
                if not reason and (self._measured_rx_s or float("-inf")) <= after_s:
                    reason = "no measurement: no measured_js since the episode's reset"
                if not reason and self._state.is_busy:
                    reason = "not ready: operating state busy (a move or homing is running)"
                if not reason or self._data_fault or self._conflict:
                    return reason
                remaining = deadline - time.monotonic()
                if remaining <= 0.0:
                    return f"{reason} (waited {timeout_s:.3g} s)"
                self._lock.wait(min(remaining, WATCHDOG_PERIOD_S))

    def enable(self, timeout_s: float = 5.0) -> None:
        """Send ``enable`` and wait for the state ENABLED."""
        self._request("enable", lambda s: s.state == "ENABLED", timeout_s)

    def home(self, timeout_s: float = 10.0) -> None:
        """Send ``home`` and wait until the arm is ENABLED, homed and not busy."""
        started, sent_s = time.monotonic(), self._now_s()

        def done(state: OperatingState) -> bool:
            # Homing shows as busy or not homed first. A late subscriber also gets the states of earlier
            # homings replayed (transient local), so only a homing stamped after the request counts; an arm
            # that does not re-home, or whose clock is behind, is accepted after a grace period.
            settled = state.state == "ENABLED" and state.is_homed and not state.is_busy
            homed_since = self._unsettled_stamp_s >= sent_s - CLOCK_SLACK_S
            return settled and (homed_since or time.monotonic() - started > HOME_GRACE_S)

        self._request("home", done, timeout_s)

    def disable(self, timeout_s: float = 5.0) -> None:
        """Send ``disable`` and wait for the state DISABLED."""
        self._request("disable", lambda s: s.state == "DISABLED", timeout_s)

    def _request(self, command: str, done: Callable[[OperatingState], bool], timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        with self._lock:
            # A state change (enable, home) is not a servo stream: the deadman watches again from the next
            # servo command on, instead of holding an arm that is homing on request.
            self._commanding = False
            # Only a state published after the command counts: an arm already homed re-homes first.
            seen = self._state_count
            while True:
                self._send_state_command(command)
                resend_at = time.monotonic() + RESEND_PERIOD_S
                while time.monotonic() < min(resend_at, deadline):
                    if self._state_count > seen and done(self._state):
                        self._deadman.release(self._facts())
                        self._hold_q = None
                        return
                    self._lock.wait(min(resend_at, deadline) - time.monotonic())
                if time.monotonic() >= deadline:
                    last = self._state.state if self._state_received else ""
                    raise DvrkTimeoutError(f"{self.topics.arm} {command}", timeout_s, last)

    def _send_state_command(self, command: str) -> None:
        """Publish a state command, unless another console or commander would get or contradict it."""
        reason = self.exclusive()
        if reason:
            raise DvrkError(f"{self.topics.arm} {command} not sent: {reason}")
        message = StringStamped(string=command)
        message.header.stamp = convert.seconds_to_time(self._now_s())
        self._command_publisher("state_command").publish(message)
