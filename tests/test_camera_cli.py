"""The camera's commands as a user runs them: train-perception, --perception camera and --texture.

What needs no process of its own runs the real command line in a child forked from this process
(:mod:`tests.forked_cli`); train-perception's budget is the process's wall time, and its stop signals are sent
to a ``python -m tissue_retract`` started as a shell starts a background job.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import run_cli
from tests.forked_cli import run_one

TEXTURES = Path(__file__).resolve().parent / "data" / "textures"


def test_train_perception_writes_its_model_report_and_picture(tmp_path: Path) -> None:
    """A short budget prints the held-out error and the floor, and writes the model, report.json and frames.png;
    --vary's ranges, parsed as robustness parses them, are in its report."""
    done = run_cli(
        "train-perception", "--budget-s", "20", "--heldout", "10", "--any-colour", "--vary", "size=0.8:1.2x",
        "--out", str(tmp_path),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "held-out site error (10 frames x 3 sites): median" in done.stdout
    assert "floor of the sites' offset (not visible on an unmarked flap)" in done.stdout
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["report"]["heldout_frames"] == 10 and report["mark_sites"] is False
    assert report["any_colour"] is True and report["vary"] == {
        "tissue_size_m": [pytest.approx(0.064), pytest.approx(0.096)]
    }
    assert (tmp_path / "site-estimator.safetensors").stat().st_size > 0
    assert (tmp_path / "frames.png").stat().st_size > 1000


def test_train_perception_refuses_a_disturbance_in_vary_before_rendering(tmp_path: Path) -> None:
    """A disturbance acts on observations and actions, never on a frame: named, nothing written."""
    out = tmp_path / "model"
    done = run_one("train-perception", "--vary", "obs_white_m=0:0.001", "--out", str(out))
    assert done.returncode == 1 and not out.exists(), done.stdout + done.stderr
    assert "--vary='obs_white_m=0:0.001' is not allowed: expected the flap's parameters" in done.stderr


def test_evaluate_with_the_camera_on_an_unseen_texture_reports_the_site_error(tmp_path: Path) -> None:
    """evaluate --perception camera --texture FILE: the summary carries site_error_mm, the texture and which
    shipped estimator the default took per episode; no warning (it takes the any-colour one off the pink)."""
    out = tmp_path / "camera.json"
    texture = str(TEXTURES / "stripes-green.png")
    done = run_one(
        "evaluate", "--policy", "pretrained", "--task", "lift", "--episodes", "2", "--seeds", "0",
        "--perception", "camera", "--texture", texture, "--json", str(out),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    report = json.loads(out.read_text())
    summary = report["summary"]
    assert summary["perception"] == "camera" and summary["texture"].endswith("stripes-green.png")
    assert set(summary["site_error_mm"]) == {"median", "p95", "max"}
    assert all(e["site_error_mm"] is not None and e["site_estimator"] for e in report["episodes"])
    assert sum(summary["site_estimator"].values()) == 2 and "site estimator taken" in done.stdout
    assert "WARNING" not in done.stderr and summary["warnings"] == []


def test_the_pink_estimator_alone_warns_on_an_unseen_texture(tmp_path: Path) -> None:
    """--perception camera:pink on a texture: the run-start warning that it may miss the site by centimetres."""
    out = tmp_path / "camera.json"
    done = run_one(
        "evaluate", "--policy", "pretrained", "--task", "lift", "--episodes", "1", "--seeds", "0",
        "--perception", "camera:pink", "--texture", str(TEXTURES / "stripes-green.png"), "--json", str(out),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    summary = json.loads(out.read_text())["summary"]
    warning = "WARNING: the flap shows stripes-green.png, but the site estimator was trained on the tasks' pink flaps"
    assert warning in done.stderr and any(w.startswith(warning) for w in summary["warnings"])


def test_the_any_colour_estimator_takes_an_unseen_texture_without_a_warning(tmp_path: Path) -> None:
    """--perception camera:any-colour loads the second shipped model, trained on flaps of any colour."""
    out = tmp_path / "camera.json"
    done = run_one(
        "evaluate", "--policy", "pretrained", "--task", "lift", "--episodes", "1", "--seeds", "0",
        "--perception", "camera:any-colour", "--texture", str(TEXTURES / "checker-blue.png"), "--json", str(out),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "WARNING" not in done.stderr
    summary = json.loads(out.read_text())["summary"]
    assert summary["perception"] == "camera:any-colour" and summary["warnings"] == []


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--perception", "lidar"], "camera or camera:MODEL"),
        (["--perception", "camera", "--blind"], "either --blind or --perception"),
        (["--perception", "camera", "--task", "expose"], "a task whose goal is a place"),
    ],
)
def test_bad_camera_options_are_refused_in_one_line(arguments: list[str], message: str) -> None:
    """Bad perception values and combinations exit 1 with one line naming the option, no traceback (bad texture and
    estimator files are rows of tests/test_hostile_inputs.py)."""
    done = run_one("evaluate", "--policy", "pretrained", "--task", "lift", "--episodes", "1", *arguments)
    assert done.returncode == 1, done.stdout + done.stderr
    assert message in done.stderr and "Traceback" not in done.stderr, done.stderr


def test_deploy_to_the_simulation_with_the_camera_prints_how_far_off_the_site_was_seen(tmp_path: Path) -> None:
    """deploy --target sim --perception camera runs an episode and says how far from the true site it saw it."""
    done = run_one(
        "deploy", "--policy", "pretrained", "--target", "sim", "--task", "lift", "--perception", "camera",
        "--record", str(tmp_path / "run.mcap"), "--policy-budget", "600",  # a loaded machine: no overrun hold
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "site seen" in done.stdout and "mm off" in done.stdout, done.stdout


def test_a_texture_too_wide_is_refused_once(tmp_path: Path) -> None:
    """A texture over 8192 px a side: one line that says the limit and the image's size once, no repetition."""
    from PIL import Image

    wide = tmp_path / "wide.png"
    Image.new("RGB", (8200, 2)).save(wide)
    done = run_one("evaluate", "--policy", "scripted", "--task", "lift", "--episodes", "1", "--texture", str(wide))
    assert done.returncode == 1, done.stdout + done.stderr
    assert "(this is 8200 x 2)" in done.stderr, done.stderr
    assert done.stderr.count("is not allowed") == 1, done.stderr


def _ignore_sigint() -> None:
    """A child as a shell starts a background job (``&``): SIGINT ignored."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@pytest.mark.parametrize(
    ("sig", "after", "kept"),
    [
        (signal.SIGINT, "held-out: 10 frames rendered", "(stopped before training began: no model)"),
        (signal.SIGTERM, "training: epoch 1 done", "and the unfinished model"),
    ],
)
def test_train_perception_in_the_background_stops_on_a_signal_and_keeps_its_work(
    tmp_path: Path, sig: signal.Signals, after: str, kept: str
) -> None:
    """Started with SIGINT ignored, SIGINT or SIGTERM stops it: 128 + the signal, what it kept said and on disk."""
    # After the held-out frames, 35 % of the budget left (less 10 s) renders training frames and the rest trains;
    # the first epoch spends seconds in torch's first steps however few the frames. With 60 s it ended at 12-13 s of
    # a 25 s share with three such trainings at once on the two cores; with 30 s at 5 s of a 6 s share, or not at all.
    command = [sys.executable, "-m", "tissue_retract", "train-perception", "--budget-s", "60", "--heldout", "10"]
    process = subprocess.Popen(
        [*command, "--out", str(tmp_path)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_ignore_sigint,
    )
    assert process.stdout is not None
    lines = []
    for line in process.stdout:
        lines.append(line)
        if line.startswith(after):
            break
    assert lines and lines[-1].startswith(after), "".join(lines)
    process.send_signal(sig)
    output, errors = process.communicate(timeout=120)
    assert process.returncode == 128 + sig, "".join(lines) + output + errors
    assert f"train-perception: stopped by {sig.name}: kept 10 held-out frames in" in output, output + errors
    assert kept in output, output
    assert "Traceback" not in errors, errors
    frames = np.load(tmp_path / "heldout-frames.npz")
    assert frames["images"].shape == (10, 6, 96, 128) and frames["sites_camera_m"].shape == (10, 3, 3)
    if sig == signal.SIGTERM:
        from policies.perception import load_estimator

        estimator = load_estimator(tmp_path / "site-estimator-partial.safetensors")
        assert estimator.info["unfinished"] is True and estimator.info["epochs_begun"] >= 1
    assert not (tmp_path / "site-estimator.safetensors").exists()
