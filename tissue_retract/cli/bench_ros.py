"""``tissue-retract bench ros``: the policy -> ``servo_jp`` -> simulated dVRK -> ``measured_js`` round trip.

A ``sim-dvrk`` child process serves PSM1 on a loopback-only domain of this run's own; this process
streams ``servo_jp`` through a :class:`~hardware_if.client.psm_client.PsmClient` (deadman included) at each
rate and times, for every command, its arrival back as a ``measured_js`` that carries it. Each command
is tagged by a distinct roll angle. It prints p50/p99 latency and the commands never seen back (drops).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from hardware_if.common.session import ros_session
from psm_control.commands import JointCommand
from sim.strict_json import write_strict_json
from sim.sweep.stopping import ChildProcesses
from tissue_retract.cli._checks import float_in
from tissue_retract.cli._ros import add_bench_domain_argument, bench_domain_id

__all__ = ["add_arguments", "run"]

_ROLL0 = -0.5
_ROLL_STEP = 1e-4


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the ros target."""
    parser.add_argument(
        "--rates", type=float_in(1.0, 5000.0), nargs="+", default=[100.0, 1000.0], help="rates [Hz] (default: 100 1000)"
    )
    parser.add_argument(
        "--duration", type=float_in(0.1, 3600.0), default=5.0, help="streaming time per rate [s] (default: 5)"
    )
    add_bench_domain_argument(parser)


def _stream(rate_hz: float, duration_s: float, env: dict[str, str], children: ChildProcesses) -> dict[str, Any]:
    from hardware_if.client.psm_client import PsmClient  # the ros extra: rclpy, after the ROS environment is set

    count = max(1, round(rate_hz * duration_s))
    sent = np.full(count, np.nan)
    received = np.full(count, np.nan)
    lock = threading.Lock()

    def on_measured(message: Any, rx_s: float) -> None:
        if len(message.position) != 6:
            return
        k = round((message.position[3] - _ROLL0) / _ROLL_STEP)
        with lock:
            if 0 <= k < count and np.isnan(received[k]):
                received[k] = rx_s

    command = [sys.executable, "-m", "tissue_retract", "sim-dvrk", "--rate", f"{rate_hz:g}"]
    command += ["--domain-id", env["ROS_DOMAIN_ID"]]
    sim = children.start("sim-dvrk", command, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    holds = 0
    try:
        with PsmClient("PSM1", on_measured=on_measured) as psm:
            psm.wait_for_measurement(timeout_s=60.0)
            psm.home(timeout_s=20.0)
            start_q = np.array([0.0, 0.0, 0.12, _ROLL0, 0.0, 0.0])
            psm.move_jp(start_q)
            base = _wait_until_at(psm, start_q, timeout_s=60.0)
            zeros = np.zeros(6)
            period = 1.0 / rate_hz
            start = time.perf_counter()
            for k in range(count):
                target = start + k * period
                while (now := time.perf_counter()) < target:
                    time.sleep(target - now)  # one wake-up per command: the client's thread needs the CPU
                q = base.copy()
                q[3] = _ROLL0 + _ROLL_STEP * k
                sent[k] = time.perf_counter()
                psm.servo_jp(JointCommand(q, zeros, zeros, 0.0, sent[k]))
                holds += int(psm.status.holding)
            _wait_for_last(received, lock, timeout_s=2.0)  # the last echo, or what came within the bound
            achieved_hz = (count - 1) / (sent[-1] - sent[0]) if count > 1 else rate_hz
    finally:
        children.stop(sim)
    with lock:
        latency_ms = (received - sent)[~np.isnan(received)] * 1000.0
    return {
        "rate_hz": rate_hz,
        "achieved_send_rate_hz": float(achieved_hz),
        "commands": count,
        "drops": int(count - latency_ms.size),
        "held_commands": holds,
        "p50_ms": float(np.percentile(latency_ms, 50)) if latency_ms.size else None,
        "p99_ms": float(np.percentile(latency_ms, 99)) if latency_ms.size else None,
        "max_ms": float(latency_ms.max()) if latency_ms.size else None,
    }


def _wait_until_at(psm: Any, q: np.ndarray, timeout_s: float) -> np.ndarray:
    """Measurements until the arm is within 1e-4 of ``q`` (its move_jp ended); the last measured joints."""
    measured = psm.measure()
    deadline = time.monotonic() + timeout_s
    while np.max(np.abs(measured.q - q)) > 1e-4 and time.monotonic() < deadline:
        measured = psm.next_measurement(measured.stamp_s, timeout_s)
    return np.asarray(measured.q)


def _wait_for_last(received: np.ndarray, lock: threading.Lock, timeout_s: float) -> None:
    """Until the last command's echo arrived, at most ``timeout_s`` (a dropped one never comes)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with lock:
            if not np.isnan(received[-1]):
                return
        time.sleep(0.005)


def _ms(value: float | None) -> str:
    return "none" if value is None else f"{value:.3f}"


def run(args: argparse.Namespace) -> int:
    """Measure and print the round trip at each rate."""
    bench_domain_id(args)

    env = dict(os.environ)
    results = []
    with ros_session(), ChildProcesses("bench ros") as children:
        for rate in args.rates:
            result = _stream(rate, args.duration, env, children)
            results.append(result)
            print(
                f"{rate:7.0f} Hz: {result['commands']:6d} commands, drops {result['drops']}, "
                f"p50 {_ms(result['p50_ms'])} ms, p99 {_ms(result['p99_ms'])} ms, max {_ms(result['max_ms'])} ms "
                f"(sent at {result['achieved_send_rate_hz']:.1f} Hz, {result['held_commands']} held by the deadman)"
            )
    report = {
        "benchmark": "ros round trip: servo_jp -> sim-dvrk (kinematic) -> measured_js, loopback UDPv4",
        "machine": {"cpus": os.cpu_count(), "python": sys.version.split()[0]},
        "results": results,
    }
    if args.json:
        write_strict_json(Path(args.json), report, field="--json")
    return 0
