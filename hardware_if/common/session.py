"""A ROS 2 session for the entry points: ``with ros_session(): ...`` initialises and shuts down rclpy.

``rclpy.init()`` returns a context manager from ROS 2 Kilted on; Jazzy's returns None. This wraps both
so that every executable has the same ``with`` shape, and turns a missing ROS install into a clear error.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from hardware_if.common.errors import RosNotAvailableError
from hardware_if.common.executor import make_executor

__all__ = [
    "SPIN_JOIN_TIMEOUT_S",
    "SpinThread",
    "close_spun_node",
    "require_ros",
    "ros_session",
    "stop_spin_thread",
]

#: How long closing a node waits for its spin thread to leave ``spin_once`` (which waits 0.05 s at most).
SPIN_JOIN_TIMEOUT_S = 5.0
#: How long closing a node waits for its executor to finish what it is running.
EXECUTOR_SHUTDOWN_TIMEOUT_S = 1.0


def require_ros() -> Any:
    """Import and return rclpy, or raise :class:`RosNotAvailableError` naming the fix."""
    try:  # the ros extra: optional, and read by Fast DDS at import, after the ROS environment is set
        import rclpy
        from crtk_msgs.msg import OperatingState  # type: ignore[import-untyped]  # noqa: F401
    except ImportError as e:
        raise RosNotAvailableError(
            f"ROS 2 is not available ({e}); install the ros extra and build crtk_msgs with `make install`"
        ) from e
    return rclpy


@contextmanager
def ros_session(args: list[str] | None = None, *, signal_handlers: bool = True) -> Iterator[None]:
    """Initialise rclpy's default context for the block, and shut it down after (also on Ctrl-C).

    Args:
        args: ROS arguments.
        signal_handlers: Let rclpy handle Ctrl-C by shutting the context down (its default). False keeps
            Python's own: Ctrl-C raises KeyboardInterrupt where the program is, so a control loop can
            stop between two commands and report, instead of meeting a dead context mid-publish.
    """
    rclpy = require_ros()
    if signal_handlers:
        rclpy.init(args=args)
    else:
        from rclpy.signals import SignalHandlerOptions  # the ros extra, as above

        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    try:
        yield
    finally:
        if rclpy.ok():
            rclpy.shutdown()


def stop_spin_thread(thread: threading.Thread | None, logger: Any) -> bool:
    """Wait for a node's spin thread to end (its loop flag already cleared); False while it still runs.

    rclpy does not support destroying a node, or shutting down its executor, while another thread is inside
    ``spin_once`` on it: the spinning thread can crash the process (SIGSEGV, ros2/rclpy#663). A caller that
    gets False leaves the node alone; the thread is a daemon and ends with the process.
    """
    if thread is None:
        return True
    thread.join(timeout=SPIN_JOIN_TIMEOUT_S)
    if thread.is_alive():
        logger.warning(f"{thread.name}: still spinning after {SPIN_JOIN_TIMEOUT_S:.0f} s; node left to the exit")
        return False
    return True


def close_spun_node(node: Any, thread: threading.Thread | None, executor: Any) -> bool:
    """Destroy a node that spins on its own executor and thread, in the order rclpy supports.

    The thread leaves ``spin_once`` first, then the executor shuts down (the events executor clears the
    callbacks it gave the middleware for the node's entities), then the node is destroyed. Returns False,
    leaving the node to the process's exit, while the thread still spins or the executor has not shut down
    within :data:`EXECUTOR_SHUTDOWN_TIMEOUT_S`: destroying it then can crash the process.
    """
    if not stop_spin_thread(thread, node.get_logger()):
        return False
    if executor is not None and executor.shutdown(timeout_sec=EXECUTOR_SHUTDOWN_TIMEOUT_S) is False:
        node.get_logger().warning(
            f"executor still busy after {EXECUTOR_SHUTDOWN_TIMEOUT_S:.0f} s; node left to the exit"
        )
        return False
    node.destroy_node()
    return True


class SpinThread:
    """A node spun by an executor of its own on a daemon thread, until :meth:`close` destroys it.

    The dVRK client, the task listener and the camera's image node each spin this way, with
    ``spin_once`` in a loop (:mod:`hardware_if.common.executor` says why not ``spin()``). A callback that raises
    is logged and the loop goes on; a shut-down context ends it.

    Args:
        node: The rclpy node.
        name: The thread's name, in logs and warnings (``PSM1-client``).
    """

    def __init__(self, node: Any, name: str) -> None:
        self._node = node
        self._executor = make_executor(node.context)
        self._executor.add_node(node)
        self._running = True
        self._thread = threading.Thread(target=self._spin, name=name, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while self._running and self._node.context.ok():
            try:
                self._executor.spin_once(timeout_sec=0.05)
            except Exception as e:  # a shut-down context ends the loop; anything else is logged, not fatal
                if not self._node.context.ok():
                    break
                self._node.get_logger().error(f"callback failed: {e!r}")

    @property
    def thread(self) -> threading.Thread:
        """The spinning thread."""
        return self._thread

    def close(self) -> bool:
        """Stop spinning and destroy the node (:func:`close_spun_node`); False if it was left to the exit."""
        self._running = False
        return close_spun_node(self._node, self._thread, self._executor)
