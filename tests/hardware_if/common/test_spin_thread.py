"""Closing a ROS node waits for its spin thread, and leaves the node alone while the thread still runs."""

from __future__ import annotations

import threading

import pytest

from hardware_if.common import session


class _Log:
    def __init__(self) -> None:
        self.warnings: list[str] = []

    def warning(self, text: str) -> None:
        self.warnings.append(text)


def test_a_thread_that_ended_lets_the_node_be_destroyed() -> None:
    thread = threading.Thread(target=lambda: None, name="PSM1-client")
    thread.start()
    log = _Log()
    assert session.stop_spin_thread(thread, log) and session.stop_spin_thread(None, log)
    assert log.warnings == []


def test_a_thread_still_spinning_keeps_the_node_and_is_reported(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(session, "SPIN_JOIN_TIMEOUT_S", 0.05)
    release = threading.Event()
    thread = threading.Thread(target=release.wait, name="PSM1-task", daemon=True)
    thread.start()
    log = _Log()
    try:
        assert not session.stop_spin_thread(thread, log)
    finally:
        release.set()
        thread.join()
    assert len(log.warnings) == 1 and log.warnings[0].startswith("PSM1-task: still spinning")


class _Node:
    def __init__(self) -> None:
        self.log = _Log()
        self.destroyed = 0

    def get_logger(self) -> _Log:
        return self.log

    def destroy_node(self) -> None:
        self.destroyed += 1


class _Executor:
    def __init__(self, finishes: bool) -> None:
        self.finishes = finishes

    def shutdown(self, timeout_sec: float) -> bool:
        return self.finishes


def test_a_node_is_destroyed_once_its_thread_and_executor_have_stopped() -> None:
    node = _Node()
    assert session.close_spun_node(node, None, _Executor(finishes=True))
    assert node.destroyed == 1 and node.log.warnings == []


def test_an_executor_that_does_not_shut_down_in_time_keeps_the_node_and_is_reported() -> None:
    node = _Node()
    assert not session.close_spun_node(node, None, _Executor(finishes=False))
    assert node.destroyed == 0
    assert len(node.log.warnings) == 1 and "executor still busy" in node.log.warnings[0]
