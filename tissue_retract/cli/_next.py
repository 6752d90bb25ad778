"""The line a command ends with when it succeeds: ``next: <the next step of its workflow>``.

The path to the robot (docs/rehearsal-and-reports.md): the robot's console or ``sim-dvrk`` -> ``ready-arm``
-> ``calibrate-wrench`` -> ``ready-arm`` -> ``deploy --dry-run`` -> ``deploy`` -> ``replay``; with a
registered site, ``register`` first. Offline: ``train`` -> ``evaluate`` -> ``robustness`` or ``tune-safety``
-> the rehearsal. Each step names the commands it can, with the arguments it knows (its arm, its files,
its domain), so that a user can copy it.
"""

from __future__ import annotations

import argparse
import shlex
from collections.abc import Sequence
from pathlib import Path

__all__ = ["command", "console_words", "replay_command", "say_next", "without_options"]


def command(*words: str) -> str:
    """``tissue-retract WORD ...``, quoted for a shell."""
    return shlex.join(["tissue-retract", *words])


def console_words(args: argparse.Namespace) -> list[str]:
    """``--domain-id N`` and ``--network`` when the command was given them, for the next command on the console."""
    words = shlex.split(getattr(args, "command_line", ""))
    given = any(word == "--domain-id" or word.startswith("--domain-id=") for word in words)
    out = ["--domain-id", str(args.domain_id)] if given else []
    return out + (["--network"] if getattr(args, "network", False) else [])


def without_options(args: argparse.Namespace, flags: Sequence[str], valued: Sequence[str]) -> list[str]:
    """The command's own words after ``tissue-retract`` without ``flags`` and without ``valued`` and their values."""
    words = shlex.split(args.command_line)[1:]
    out: list[str] = []
    skip = False
    for word in words:
        if skip:
            skip = False
            continue
        name = word.split("=", 1)[0]
        if name in flags:
            continue
        if name in valued:
            skip = "=" not in word
            continue
        out.append(word)
    return out


def replay_command(record: Path) -> str:
    """The replay of a recording, its figure beside it."""
    return command("replay", str(record), "--plot", str(record.with_suffix(".png")))


def say_next(text: str) -> None:
    """Print ``next: TEXT``, the command's last line."""
    print(f"next: {text}", flush=True)
