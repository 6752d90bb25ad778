"""The path to the robot as docs/rehearsal-and-reports.md shows it, run as written against a fresh sim-dvrk.

The page and the test are one: the test runs the page's marked ``sh`` block command by command, in order, in a
folder of its own (the page's relative paths land there), on a ROS domain of its own (the page's
``export ROS_DOMAIN_ID=...`` takes this test's domain; discovery on localhost). A command ending in ``&`` is
the console: it runs beside the rest, from its start-up line and the ``next:`` line after it on. Each command
must succeed and end with a ``next:`` line naming the page's next command, and the page's ``text`` block after
it shows those lines as they are printed. Waits are on lines and exits; the guards only bound a failure.
"""

from __future__ import annotations

import queue
import re
import shlex
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from domains import page_domain_id

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "rehearsal-and-reports.md"
DVRK_PAGE = ROOT / "docs" / "dvrk.md"
MARKER = "<!-- the path to the robot: tests/ros/test_rehearsal_page.py runs this block -->"
#: Bounds a step that never ends (a failure), not how long one takes.
GUARD_S = 600.0
#: The console's start-up line: it serves every topic and service from then on.
STARTED = re.compile(r"simulated \S+ at [\d.]+ Hz on ROS_DOMAIN_ID=")
#: Bounds the wait for a console's next: line after its start-up line (it prints it at once; a failure).
AFTER_START_S = 60.0


def page_block(text: str, marker: str, language: str = "sh") -> str:
    """The first fenced block of ``language`` after ``marker``."""
    block = re.search(rf"```{language}\n(.*?)```", text[text.index(marker) :], re.DOTALL)
    assert block is not None, f"no ```{language} block after {marker!r}"
    return block.group(1)


def block_commands(block: str) -> list[str]:
    """The block's commands: continuation lines joined, blank lines dropped; a ``tissue-retract`` command as its
    words (`` &`` kept, the comment dropped), any other line as written, for a shell."""
    commands = []
    for line in block.replace("\\\n", " ").splitlines():
        words = shlex.split(line, comments=True)
        if words[:1] == ["tissue-retract"]:
            background = words[-1] == "&"
            commands.append(shlex.join(words[: len(words) - background]) + " &" * background)
        elif words:
            commands.append(line.strip())
    return commands


def command_words(command: str) -> list[str]:
    """A ``tissue-retract`` command's words (without `` &``); a shell line's first word only."""
    if command.startswith("tissue-retract "):
        return shlex.split(command.removesuffix(" &"))
    return command.split()[:1]


def options(words: list[str]) -> set[tuple[str, ...]]:
    """A command's words as (option, value) pairs, (flag,) and (positional,) entries."""
    out: set[tuple[str, ...]] = set()
    i = 0
    while i < len(words):
        word = words[i]
        if word.startswith("--") and i + 1 < len(words) and not words[i + 1].startswith("--"):
            out.add((word, words[i + 1]))
            i += 2
        else:
            out.add((word,))
            i += 1
    return out


def named_commands(next_line: str) -> list[list[str]]:
    """The ``tissue-retract ...`` commands a ``next:`` line names, each up to its first "(", ";" or ","."""
    return [shlex.split(m) for m in re.findall(r"tissue-retract ([^(;,]*)", next_line)]


def names(next_line: str, command: str) -> bool:
    """Whether ``next_line`` names ``command``: the same subcommand, every option it gives as ``command`` gives it."""
    words = command_words(command)[1:]
    return any(
        named[:1] == words[:1] and options(named[1:]) <= options(words[1:]) for named in named_commands(next_line)
    )


class Lines:
    """A child's merged output, read on a thread so that a wait for a line can be bounded."""

    def __init__(self, process: subprocess.Popen[str]) -> None:
        self.seen: list[str] = []
        self._queue: queue.Queue[str | None] = queue.Queue()
        assert process.stdout is not None
        stream = process.stdout
        threading.Thread(target=lambda: [*map(self._queue.put, stream), self._queue.put(None)], daemon=True).start()

    def until(self, pattern: re.Pattern[str], guard_s: float = GUARD_S) -> str:
        """The first line ``pattern`` matches (every line before it kept in ``seen``)."""
        while True:
            try:
                line = self._queue.get(timeout=guard_s)
            except queue.Empty:
                line = None
            assert line is not None, f"no line matching {pattern.pattern!r}:\n" + "".join(self.seen)
            self.seen.append(line)
            if pattern.search(line):
                return line.strip()


def run_block(commands: list[str], folder: Path, env: dict[str, str]) -> list[tuple[str, str, str]]:
    """Run the commands in order in ``folder``; each one's (command, output, next line). A console (``&``) is
    stopped with SIGINT at the end and must exit 0."""
    consoles: list[tuple[subprocess.Popen[str], Lines]] = []
    runs: list[tuple[str, str, str]] = []
    try:
        for line in commands:
            words = command_words(line)
            if words[0] == "export":
                for assignment in shlex.split(line, comments=True)[1:]:
                    name, value = assignment.split("=", 1)
                    env[name] = env["ROS_DOMAIN_ID"] if name == "ROS_DOMAIN_ID" else value
                continue
            if words[0] != "tissue-retract":  # a shell line of the page's (writing a file)
                subprocess.run(["bash", "-c", line], cwd=folder, env=env, check=True, timeout=GUARD_S)
                continue
            argv = [sys.executable, "-m", "tissue_retract", *words[1:]]
            if line.endswith(" &"):
                process = subprocess.Popen(
                    argv, cwd=folder, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
                )
                lines = Lines(process)
                consoles.append((process, lines))
                lines.until(STARTED)
                next_line = lines.until(re.compile("^next: "), AFTER_START_S)
                runs.append((line, "".join(lines.seen), next_line))
                continue
            done = subprocess.run(argv, cwd=folder, env=env, capture_output=True, text=True, timeout=GUARD_S)
            output = done.stdout + done.stderr
            assert done.returncode == 0, f"{line}\n{output}"
            assert "Traceback" not in output, f"{line}\n{output}"
            last = done.stdout.strip().splitlines()[-1] if done.stdout.strip() else ""
            runs.append((line, output, last if last.startswith("next: ") else ""))
    finally:
        for process, _ in consoles:
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
            try:
                process.wait(timeout=60)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
    for process, lines in consoles:
        assert process.returncode == 0, "".join(lines.seen)
    return runs


#: The page's live calibration needs the machine to itself: sim-dvrk computes the arm's efforts in its simulated
#: time and stamps them with the wall clock's, which drift apart when the console's ticks come late, and the fit's
#: held-out error rises with the drift. Measured on the 2-core machine: 2.7-3.2 x lower RMS than the console's
#: idle, 2.1 x with three busy processes beside it, once 1.48 x among make test's parallel workers, where
#: calibrate-wrench refuses anything under 1.5 x (and the page's next step then has no file).
@pytest.mark.idle_machine
@pytest.mark.slow
def test_the_rehearsal_page_runs_as_written_and_each_step_names_the_next(
    ros_env: dict[str, str], tmp_path: Path
) -> None:
    """The page's path to the robot, run in order against a fresh sim-dvrk: every command succeeds, each one's
    last line is ``next:`` naming the page's next command, the page shows those lines, and the replay reads the
    deploy's recording."""
    text = PAGE.read_text()
    commands = block_commands(page_block(text, MARKER))
    domain = str(page_domain_id())
    env = {**ros_env, "ROS_DOMAIN_ID": domain, "PYTHONPATH": str(ROOT)}  # the children run this checkout's code
    env.pop("TISSUE_RETRACT_LIVE_PORT", None)
    runs = run_block(commands, tmp_path, env)
    steps = [c for c in commands if c.startswith("tissue-retract ")]
    assert [line for line, _, _ in runs] == steps
    for (line, output, next_line), following in zip(runs, steps[1:], strict=False):
        assert next_line, f"{line}: its last line names no next step\n{output}"
        assert names(next_line, following), f"{line}\n  printed: {next_line}\n  the page's next: {following}"
    shown = [row.strip() for row in page_block(text, MARKER, "text").splitlines() if row.strip()]
    printed = [next_line for _, _, next_line in runs if next_line]
    assert sorted(set(printed)) == sorted(shown), (printed, shown)
    assert (tmp_path / "run.png").is_file() and (tmp_path / "wrench.json").is_file()


def test_no_dry_run_on_the_pages_follows_a_move_without_ready_arm() -> None:
    """A dry run moves nothing and holds ``not at start`` where the arm is elsewhere: on the dVRK and rehearsal
    pages, every ``deploy --dry-run`` against a dVRK in a block comes after ``ready-arm``, never right after a
    fresh console (disabled, not homed) or a command that moved the arm (a deploy, a calibration)."""
    for page in (DVRK_PAGE, PAGE):
        for block in re.findall(r"```sh\n(.*?)```", page.read_text(), re.DOTALL):
            placed = False  # whether the arm is known to be at the episodes' start
            for line in block_commands(block):
                words = command_words(line)
                if words[:1] != ["tissue-retract"] or len(words) < 2:
                    continue
                sub = words[1]
                if sub == "ready-arm":
                    placed = True
                elif sub == "deploy" and "dvrk" in words and "--dry-run" in words:
                    assert placed, f"{page.name}: {line}: a dry run where the arm may not be at the start"
                elif sub in ("deploy", "calibrate-wrench", "sim-dvrk") and "--from" not in words:
                    placed = False  # a deploy or an excitation moved it; a fresh console is disabled, not homed
