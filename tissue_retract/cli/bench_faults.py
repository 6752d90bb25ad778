"""``tissue-retract bench faults``: the deploy's fault matrix, fault -> exit status, hold reason, recording.

Each fault (:data:`tissue_retract.faults.FAULTS`) runs a real ``deploy`` as a child process, against a
real ``sim-dvrk --task lift`` on a loopback-only ROS domain of its own for the dVRK target, and injects
one fault mid-episode: a policy that raises, exits, returns garbage or overruns; a NaN on each
subscribed topic; a tracking error; an arm disabled mid-episode or never enabled (dry run); a console
that dies; SIGINT, SIGTERM, SIGHUP; a SIGKILL of the deploy in its third episode. The table gives each
fault's exit status, the hold (or stop) line deploy printed, and what ``replay`` reads in the
recording. Exit status 0 when every fault ended as expected, 1 otherwise.

The faults that leave their console as they found it run one after another on one console
(:class:`~tissue_retract.faults.SharedConsole`, on the first domain), as the tests run them: its start-up and the
arm's enable and home are paid once, not once per fault. The others run on a console of their own.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from psm_control.outputs import write_atomic
from sim.strict_json import write_strict_json
from tissue_retract.cli._checks import check_out_folder
from tissue_retract.cli._ros import add_bench_domain_argument, bench_domain_id

if TYPE_CHECKING:  # imported where it runs: after the ROS environment is set
    from tissue_retract.faults import Fault, FaultResult

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the faults target."""
    parser.add_argument(
        "--only", metavar="TEXT", default=None, help="run only the faults whose name contains TEXT (default: all)"
    )
    parser.add_argument("--keep", metavar="DIR", default=None, help="keep each fault's recording and output in DIR")
    add_bench_domain_argument(parser)  # the first fault's; each next fault takes the next domain


def run(args: argparse.Namespace) -> int:
    """Run the matrix, print the table, return 0 when every fault ended as expected."""
    base = bench_domain_id(args)  # before rclpy starts (the injector runs in this process)
    from tissue_retract.faults import FAULTS, SharedConsole, run_fault, scratch_dir

    faults = [f for f in FAULTS if args.only is None or args.only in f.name]
    if args.keep:
        check_out_folder(Path(args.keep), (), (), "--keep")
    root = Path(args.keep) if args.keep else scratch_dir()
    rows: list[dict[str, Any]] = []
    width = max(len(f.name) for f in faults) if faults else 5
    print(f"{'fault':<{width}}  exit  ok   hold / stop line | recording (replay)", flush=True)
    shared = SharedConsole(base)
    try:
        for index, fault in enumerate(faults):
            # The shared console has the first domain; each fault on a console of its own the next one.
            console = shared if fault.shares_console else None
            domain = base if console is not None else 1 + (base + index) % 100
            started = time.monotonic()
            result = run_fault(fault, root / f"{index:02d}", domain, console=console)
            elapsed = time.monotonic() - started
            hold = result.hold.removeprefix("HOLD: ") or "-"
            ok = "yes" if result.ok else "NO"
            print(f"{fault.name:<{width}}  {result.status:>4}  {ok:<3}  {hold} | {result.recording}", flush=True)
            write_atomic(root / f"{index:02d}" / "output.txt", result.output, "--keep")
            rows.append(_row(fault, result, elapsed))
    finally:
        shared.close()
    passed = sum(r["ok"] for r in rows)
    print(f"{passed}/{len(rows)} faults ended as expected; files in {root}")
    if args.json:
        write_strict_json(Path(args.json), {"faults": rows}, field="--json")
    return 0 if passed == len(rows) else 1


def _row(fault: Fault, result: FaultResult, elapsed_s: float) -> dict[str, Any]:
    """One fault's row of ``--json``."""
    return {
        "fault": fault.name,
        "target": fault.target,
        "exit": result.status,
        "expected_exit": fault.status,
        "hold": result.hold,
        "recording": result.recording,
        "episodes_kept": result.episodes_kept,
        "truncated": result.truncated,
        "traceback": result.traceback,
        "ok": result.ok,
        "seconds": elapsed_s,
    }
