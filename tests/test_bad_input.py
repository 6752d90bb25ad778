"""Bad values and bad content through the real command line: a named error, no traceback, nothing written.

Every case runs the real command line as a careless or hostile user would type it, in a child forked from this
process (:mod:`tests.forked_cli`: what ``python -m tissue_retract ...`` would do, without importing torch and the
simulation again for each). Each must exit non-zero, print a message naming the option, field or value and what
is allowed, print no Python traceback, and leave no output file behind. The cases run in groups (:data:`GROUPS`,
one test each) and two at a time within a group; each group's summary line prints the counts. A file that is
missing, not a regular file, empty, garbage or over its size limit, and an output path that is a folder, a device,
a FIFO or an input, are rows of the one table of hostile files, ``tests/test_hostile_inputs.py``; here are the
files whose content is wrong.
"""

from __future__ import annotations

import json
import signal
import struct
import subprocess
import sys
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors.torch import load_file, save_file

from policies.toy_env import TOY_TASK_ID
from tests.forked_cli import run_forked

PRETRAINED = Path(__file__).resolve().parents[1] / "policies" / "pretrained"
MULTISITE = PRETRAINED / "TissueRetract-MultiSite-v0.safetensors"
TOY_TRAIN = ("train", "--task", TOY_TASK_ID, "--algo", "ddpgbc", "--demos", "2", "--episodes", "1")
TOY_TRAIN_TAIL = ("--eval-episodes", "1", "--no-progress", "--no-tensorboard", "--set", "hidden_sizes=[8]")
EVALUATE = ("evaluate", "--task", "lift", "--episodes", "1", "--seeds", "1")
SWEEP = ("--task", "lift", "--jobs", "1", "--no-progress")
REPRODUCE = ("reproduce", "--budget", "1", "--tasks", "I", "--algos", "ddpg", "--seeds", "1", "--out")


@dataclass
class Case:
    """One bad input: the command, words its error must contain, and paths it must not create."""

    name: str
    argv: tuple[str, ...]
    expect: tuple[str, ...]
    absent: tuple[Path, ...] = ()
    outcome: dict[str, object] = field(default_factory=dict)


def _write(path: Path, text: str | bytes) -> Path:
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    return path


def _alias_bomb() -> str:
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for i in range(1, 10):
        lines.append(f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]")
    return "\n".join(lines) + "\n"


def _toy_demos(n: int = 2, t: int = 50, obs: int = 4, goal: int = 3, act: int = 5) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    return {
        "obs": rng.uniform(-1, 1, (n, t + 1, obs)).astype(np.float32),
        "achieved_goal": rng.uniform(-1, 1, (n, t + 1, goal)).astype(np.float32),
        "desired_goal": rng.uniform(-1, 1, (n, t, goal)).astype(np.float32),
        "actions": rng.uniform(-1, 1, (n, t, act)).astype(np.float32),
    }


def _huge_npz(path: Path) -> Path:
    """A small .npz whose actions header claims (100000, 100000, 5) float32: 200 GB once read."""
    with (
        zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as archive,
        archive.open("actions.npy", "w") as member,
    ):
        np.lib.format.write_array_header_1_0(
            member, {"descr": "<f4", "fortran_order": False, "shape": (100_000, 100_000, 5)}
        )
        member.write(b"\x00" * 4096)
    return path


def _checkpoint_with(tmp: Path, name: str, edit: Callable[[dict[str, object], dict[str, torch.Tensor]], None]) -> Path:
    """A copy of the shipped MultiSite policy with its metadata or tensors edited."""
    tensors = load_file(str(MULTISITE))
    raw = MULTISITE.read_bytes()
    (length,) = struct.unpack("<Q", raw[:8])
    meta = json.loads(json.loads(raw[8 : 8 + length])["__metadata__"]["tissue_retract"])
    edit(meta, tensors)
    path = tmp / name
    save_file(tensors, str(path), metadata={"tissue_retract": json.dumps(meta)})
    return path


def _nested_header(path: Path) -> Path:
    header = ("[" * 100_000 + "]" * 100_000).encode()
    return _write(path, struct.pack("<Q", len(header)) + header)


def _cases(tmp: Path) -> list[Case]:
    out = tmp / "out"
    cfg = tmp / "cfg"
    cfg.mkdir()
    configs = {
        "bool-force": (_write(cfg / "bool.toml", "force_limit_n = true\n"), ("force_limit_n", "True", "finite number")),
        "string-insertion": (
            _write(cfg / "str.toml", 'min_insertion_m = "0.06"\n'),
            ("min_insertion_m", "'0.06'", "0.045"),
        ),
        "utf16": (_write(cfg / "u16.yaml", "force_limit_n: 2.0\n".encode("utf-16")), ("--safety-config", "UTF-8")),
        "latin1": (_write(cfg / "latin1.yaml", "tissue: f\xe9\n".encode("latin-1")), ("--safety-config", "UTF-8")),
        "duplicate-yaml": (
            _write(cfg / "dup.yaml", "force_limit_n: 2.0\nforce_limit_n: 40.0\n"),
            ("duplicate key", "force_limit_n"),
        ),
        "duplicate-toml": (
            _write(cfg / "dup.toml", "force_limit_n = 2.0\nforce_limit_n = 40.0\n"),
            ("TOML", "duplicate"),
        ),
        "tiny-force": (_write(cfg / "tiny.toml", "force_limit_n = 1e-300\n"), ("force_limit_n", "[0.01, 50]")),
        "huge-acceleration": (
            _write(cfg / "acc.toml", "acceleration_limit = [1e300, 1e300, 1e300, 1e300, 1e300, 1e300]\n"),
            ("acceleration_limit", "move_jp"),
        ),
        "short-vector": (_write(cfg / "short.yaml", "velocity_limit: [1.0, 2.0]\n"), ("velocity_limit", "6 finite")),
        "alias-bomb": (_write(cfg / "bomb.yaml", _alias_bomb()), ("alias", "not allowed")),
        "unknown-key": (_write(cfg / "unknown.toml", "force_limt_n = 2.0\n"), ("force_limt_n", "known setting")),
        "not-a-mapping": (_write(cfg / "list.yaml", "- 1\n- 2\n"), ("mapping",)),
    }
    cases = [
        Case(f"config-{name}", ("safety", "show", "--config", str(path)), expect)
        for name, (path, expect) in configs.items()
    ]
    box = _write(cfg / "box.toml", "workspace_min_m = [0.05, 0.05, -0.20]\nworkspace_max_m = [0.07, 0.07, -0.05]\n")
    cases.append(
        Case(
            "config-box-excludes-start",
            (*EVALUATE, "--policy", "scripted", "--safety-config", str(box), "--json", str(out / "box.json")),
            ("workspace", "start tool-tip"),
            (out / "box.json",),
        )
    )
    # Command values.
    cases += [
        Case("seeds-negative", (*EVALUATE[:5], "--policy", "scripted", "--seeds", "-5"), ("--seeds", "-5", "[0,")),
        Case(
            "reproduce-budget-zero",
            (*REPRODUCE, str(out / "r"), "--budget", "0"),
            ("--budget", "0", "[1,"),
            (out / "r",),
        ),
        Case("reproduce-jobs-zero", (*REPRODUCE, str(out / "r"), "--jobs", "0"), ("--jobs", "0", "[1,"), (out / "r",)),
        Case("reproduce-seed-negative", (*REPRODUCE, str(out / "r"), "--seeds", "-1"), ("--seeds", "-1", "[0,")),
        Case("reproduce-eval-every-zero", (*REPRODUCE, str(out / "r"), "--eval-every", "0"), ("--eval-every", "[1,")),
        Case(
            "reproduce-no-tasks", (*REPRODUCE, str(out / "r"), "--tasks", ","), ("--tasks", "I, II, III"), (out / "r",)
        ),
        Case(
            "bench-safety-json-unwritable",
            ("bench", "safety", "--json", str(_write(tmp / "a-file", "x") / "safety.json")),
            ("--json", "a path whose folder can be created"),
        ),
        Case("bench-chain-seed-negative", ("bench", "chain", "--seed", "-1"), ("--seed", "-1", "[0,")),
        Case("bench-chain-few-ticks", ("bench", "chain", "--ticks", "5"), ("--ticks", "5", "[100,")),
        Case("bench-chain-no-repeats", ("bench", "chain", "--repeats", "0"), ("--repeats", "0", "[1,")),
        Case("bench-env-negative-steps", ("bench", "env", "--steps", "-3"), ("--steps", "-3", "[1,")),
        Case("simdvrk-seed-negative", ("sim-dvrk", "--seed", "-1"), ("--seed", "-1", "[0,")),
        Case("simdvrk-base-nan", ("sim-dvrk", "--base-xyz", "nan", "0", "0"), ("--base-xyz", "nan", "[-5, 5]")),
        Case("bench-ros-negative-rate", ("bench", "ros", "--rates", "-5"), ("--rates", "-5", "[1, 5000]")),
        Case("bench-ros-nan-duration", ("bench", "ros", "--duration", "nan"), ("--duration", "nan", "[0.1,")),
        Case(
            "reproduce-runs-a-file",
            (*REPRODUCE, str(out / "r2"), "--runs", str(_write(tmp / "runs.txt", "x"))),
            ("--runs", "a folder (this is a file)"),
        ),
        Case("reproduce-out-a-file", (*REPRODUCE, str(_write(tmp / "r.txt", "x"))), ("--out", "a folder")),
        Case("episodes-zero", ("evaluate", "--policy", "scripted", "--episodes", "0"), ("--episodes", "0", "[1,")),
        Case(
            "seed-negative",
            (
                "robustness",
                "--policy",
                "scripted",
                *SWEEP,
                "--vary",
                "stiffness=1",
                "--seed",
                "-1",
                "--out",
                str(tmp / "o1"),
            ),
            ("--seed", "-1", "[0,"),
            (tmp / "o1",),
        ),
        *(
            Case(
                f"deploy-force-sensor-{name}",
                ("deploy", "--policy", "scripted", *argv, "--record", str(tmp / f"fs-{name}" / "r.mcap")),
                expect,
                (tmp / f"fs-{name}",),
            )
            for name, argv, expect in (
                ("zero", ("--target", "dvrk", "--force-sensor", "0"), ("--force-sensor", "error bound", "> 0")),
                ("nan", ("--target", "dvrk", "--force-sensor", "nan"), ("--force-sensor", "nan", "finite")),
                ("in-sim", ("--target", "sim", "--force-sensor", "0.2"), ("--force-sensor", "dvrk only")),
                (
                    "with-calibration",
                    ("--target", "dvrk", "--force-sensor", "0.2", "--wrench-calibration", str(tmp / "w.json")),
                    ("--force-sensor", "not both"),
                ),
            )
        ),
        Case(
            "deploy-rate-zero",
            (
                "deploy",
                "--policy",
                "scripted",
                "--target",
                "sim",
                "--rate",
                "0",
                "--record",
                str(tmp / "o2" / "r.mcap"),
            ),
            ("--rate", "0", "[20, 5000]"),
            (tmp / "o2",),
        ),
        Case(
            "trials-1e12",
            ("robustness", "--policy", "scripted", *SWEEP, "--vary", "stiffness=1", "--trials", "1000000000000"),
            ("--trials", "1000000000000"),
        ),
        Case(
            "trials-grid-product",
            (
                "robustness",
                "--policy",
                "scripted",
                *SWEEP,
                "--mode",
                "grid",
                "--trials",
                "1000",
                "--vary",
                "stiffness=0.5:2x,latency=0:3",
                "--out",
                str(tmp / "o3"),
            ),
            ("--trials", "1000000", "at most"),
            (tmp / "o3",),
        ),
        Case(
            "tune-grid-list",
            ("tune-safety", "--policy", "scripted", *SWEEP, "--out", str(tmp / "o5"), "--grid", "force_limit_n=1,2"),
            ("--grid", "'2'", "NAME=LOW:HIGH"),
            (tmp / "o5",),
        ),
        Case(
            "tune-grid-huge",
            (
                "tune-safety",
                "--policy",
                "scripted",
                *SWEEP,
                "--levels",
                "100000",
                "--grid",
                "force_limit_n=0.5:3,cbf_gamma=0.2:1,horizon_s=0.05:0.2,max_yaw_rad=0.1:0.5,max_translation_m=0.01:0.05",
            ),
            ("--levels", "100000", "[1, 1000]"),
        ),
        Case(
            "tune-grid-product",
            (
                "tune-safety",
                "--policy",
                "scripted",
                *SWEEP,
                "--levels",
                "100",
                "--episodes",
                "20",
                "--out",
                str(tmp / "o4"),
                "--grid",
                "force_limit_n=0.5:3,cbf_gamma=0.2:1,horizon_s=0.05:0.2",
            ),
            ("--grid/--levels/--episodes", "at most"),
            (tmp / "o4",),
        ),
        Case(
            "json-overwrites-policy",
            (*EVALUATE, "--policy", str(tmp / "policy.safetensors"), "--json", str(tmp / "policy.safetensors")),
            ("--json", "other than the input"),
        ),
        Case(
            "record-overwrites-policy",
            (
                "deploy",
                "--policy",
                str(tmp / "policy.safetensors"),
                "--target",
                "sim",
                "--record",
                str(tmp / "policy.safetensors"),
            ),
            ("--record", "other than the input"),
        ),
        Case(
            "jobs-zero",
            ("robustness", "--policy", "scripted", *SWEEP[:2], "--vary", "stiffness=1", "--jobs", "0"),
            ("--jobs", "0"),
        ),
        # Every --vary parameter has an allowed range (a 1e9-step latency filled memory in every episode).
        Case(
            "vary-latency-1e9",
            ("robustness", "--policy", "scripted", *SWEEP, "--vary", "latency=0:1e9", "--out", str(tmp / "v1")),
            ("vary.latency", "[0, 50] policy steps"),
            (tmp / "v1",),
        ),
        Case(
            "vary-obs-noise-1e308",
            ("robustness", "--policy", "scripted", *SWEEP, "--vary", "obs_noise=0:1e308", "--out", str(tmp / "v2")),
            ("vary.obs_noise", "[0, 0.01] m"),
            (tmp / "v2",),
        ),
        Case(
            "vary-stiffness-multiple",
            ("robustness", "--policy", "scripted", *SWEEP, "--vary", "stiffness=1:1e6x", "--out", str(tmp / "v3")),
            ("vary.stiffness", "[0.1, 1000] kPa", "multiples 0.01-100x"),
            (tmp / "v3",),
        ),
        Case(
            "vary-action-white-1e9",
            ("robustness", "--policy", "scripted", *SWEEP, "--vary", "action_white=0:1e9", "--out", str(tmp / "v4")),
            ("vary.action_white", "[0, 2] action units"),
            (tmp / "v4",),
        ),
        Case(
            "vary-train-latency",
            (*TOY_TRAIN, "--out", str(tmp / "v5"), *TOY_TRAIN_TAIL, "--vary", "latency=0:1e9"),
            ("vary.latency", "[0, 50]"),
            (tmp / "v5",),
        ),
    ]
    cases.append(
        Case(
            "train-huge-buffer",
            (*TOY_TRAIN, "--out", str(tmp / "o5"), *TOY_TRAIN_TAIL, "--set", "buffer_size=100000000000"),
            ("buffer_size", "100000000000", "<= 2000000"),
            (tmp / "o5",),
        )
    )
    # Demonstrations.
    demos = tmp / "demos"
    demos.mkdir()
    good = _toy_demos()
    nan = dict(good)
    nan["actions"] = good["actions"].copy()
    nan["actions"][0, 3, 1] = np.nan
    np.savez(demos / "nan.npz", **nan)
    np.savez(demos / "flat.npz", **{**good, "actions": np.zeros(10, np.float32)})
    np.savez(demos / "dims.npz", **_toy_demos(obs=7))
    np.savez(demos / "steps.npz", **{**good, "obs": good["obs"][:, :10]})
    np.savez(demos / "good.npz", **good)
    whole = (demos / "good.npz").read_bytes()
    _write(demos / "truncated.npz", whole[: len(whole) // 2])  # an empty or a text file fails as this one does
    _huge_npz(demos / "huge.npz")
    expected_demos = {
        "nan": ("actions", "non-finite"),
        "flat": ("actions", "(10,)", "3 dimensions"),
        "dims": ("obs", "7 values", "the task has 4"),
        "steps": ("obs and achieved_goal", "T + 1"),
        "truncated": ("--demos-file", "truncated", "not a readable .npz"),
        "huge": ("--demos-file", "200000000000 bytes", "at most"),
    }
    for name, expect in expected_demos.items():
        run = tmp / f"train-{name}"
        argv = (*TOY_TRAIN, "--demos-file", str(demos / f"{name}.npz"), "--out", str(run), *TOY_TRAIN_TAIL)
        cases.append(Case(f"demos-{name}", argv, expect, (run / "policy.safetensors", run / "eval.csv")))
    # Checkpoints.
    ck = tmp / "ckpt"
    ck.mkdir()

    def wide(meta: dict[str, object], tensors: dict[str, torch.Tensor]) -> None:
        meta["config"]["hidden_sizes"] = [30000, 30000, 30000]  # type: ignore[index]

    def wide_ok(meta: dict[str, object], tensors: dict[str, torch.Tensor]) -> None:
        meta["config"]["hidden_sizes"] = [4000, 4000, 4000]  # type: ignore[index]

    def nan_weight(meta: dict[str, object], tensors: dict[str, torch.Tensor]) -> None:
        key = next(k for k in tensors if k.startswith("actor.") and k.endswith("weight"))
        tensors[key][0, 0] = float("nan")

    checkpoints = {
        "nested": (_nested_header(ck / "nested.safetensors"), ("nested", "at most 32")),
        "hidden-too-wide": (_checkpoint_with(ck, "wide.safetensors", wide), ("hidden_sizes", "4096")),
        "hidden-vs-tensors": (
            _checkpoint_with(ck, "wide_ok.safetensors", wide_ok),
            ("layer sizes", "actor parameters"),
        ),
        "nan-weights": (_checkpoint_with(ck, "nan.safetensors", nan_weight), ("non-finite", "actor.")),
        "pickle": (_write(ck / "pickle.pt", b"\x80\x04\x95" + b"\x00" * 64), ("not a safetensors checkpoint",)),
    }
    for name, (path, expect) in checkpoints.items():
        report = out / f"ckpt-{name}.json"
        argv = ("evaluate", "--task", "multisite", "--episodes", "1", "--seeds", "1", "--policy", str(path))
        cases.append(Case(f"checkpoint-{name}", (*argv, "--json", str(report)), expect, (report,)))
    cases.append(
        Case(
            "checkpoint-other-task",
            (*EVALUATE, "--policy", str(MULTISITE), "--json", str(out / "other.json")),
            ("TissueRetract-MultiSite-v0", "TissueRetract-Lift-v0", "--allow-other-task"),
            (out / "other.json",),
        )
    )
    # Policies that raise, SystemExit(0) included.
    for name in ("exit_zero", "raises"):
        cases.append(
            Case(
                f"policy-{name}",
                (*EVALUATE, "--policy", f"tests.bad_policies:{name}"),
                ("policy error", "SystemExit: 0" if name == "exit_zero" else "RuntimeError: policy bug"),
            )
        )
    cases.append(
        Case(
            "policy-exit-zero-sweep",
            (
                "robustness",
                "--policy",
                "tests.bad_policies:exit_zero",
                *SWEEP,
                "--vary",
                "stiffness=1",
                "--trials",
                "1",
                "--out",
                str(tmp / "sweep-exit"),
            ),
            ("1 of 1 episodes failed", "SystemExit"),
        )
    )
    cases.append(Case("policy-unimportable", (*EVALUATE, "--policy", "no_such_module:act"), ("--policy", "importable")))
    cases += _blind_cases(tmp)
    return cases


def _blind_cases(tmp: Path) -> list[Case]:
    """A registered site and the blind simulation: where each belongs and what a site is."""
    record = tmp / "blind" / "r.mcap"
    deploy = ("deploy", "--policy", "scripted", "--record", str(record))
    registration = _write(tmp / "registration.json", "not json\n")
    other_arm = _write(tmp / "psm2.json", '{"arm": "PSM2", "site_m": [0, 0, 0.02]}\n')
    return [
        Case("site-in-sim", (*deploy, "--target", "sim", "--site", "0", "0", "0.02"), ("site", "--target dvrk")),
        Case("site-nan", (*deploy, "--target", "dvrk", "--site", "nan", "0", "0"), ("--site", "nan", "[-1, 1]")),
        Case("goal-without-site", (*deploy, "--target", "dvrk", "--goal", "0", "0", "0.04"), ("goal", "--site")),
        Case("goal-in-sim", (*deploy, "--target", "sim", "--goal", "0", "0", "0.04"), ("goal", "--target dvrk")),
        Case(
            "site-camera-without-camera",
            (*deploy, "--target", "dvrk", "--camera-site", "left"),
            ("camera_site", "--perception camera"),
        ),
        Case(
            "registration-garbage",
            (*deploy, "--target", "dvrk", "--registration", str(registration)),
            ("--registration", "register --out"),
        ),
        Case(
            "registration-other-arm",
            (*deploy, "--target", "dvrk", "--registration", str(other_arm)),
            ("--registration", "PSM1", "PSM2"),
        ),
        Case("blind-expose", (*EVALUATE[:1], "--policy", "scripted", "--task", "expose", "--blind"), ("task", "I-III")),
        Case("blind-without-task", ("sim-dvrk", "--blind"), ("--blind", "--task")),
        Case("register-few-samples", ("register", "--samples", "2"), ("--samples", "[5, 10000]")),
    ]


def _outcome(case: Case, result: subprocess.CompletedProcess[str]) -> Case:
    text = result.stdout + result.stderr
    case.outcome = {
        "returncode": result.returncode,
        "traceback": "Traceback" in text,
        "missing": [word for word in case.expect if word not in text],
        "written": [str(p) for p in case.absent if p.exists()],
        "text": text[-1500:],
    }
    return case


#: The matrix in groups of about a dozen commands (by the case's name), so that pytest-xdist spreads them.
GROUPS = {
    "configs": ("config-",),
    "command-values": (
        "seeds-",
        "seed-",
        "episodes-",
        "deploy-",
        "trials-",
        "tune-",
        "json-",
        "record-",
        "jobs-",
        "vary-",
    ),
    "reproduce-bench-simdvrk": ("reproduce-", "bench-", "simdvrk-"),
    "demonstrations": ("demos-", "train-"),
    "checkpoints-and-policies": ("checkpoint-", "policy-"),
    "sites": ("site-", "goal-", "registration-", "blind-", "register-"),
}


def test_every_bad_input_case_is_in_a_group(tmp_path: Path) -> None:
    """No case of the matrix falls outside the groups that the next test runs."""
    names = [case.name for case in _cases(tmp_path)]
    assert len(names) == len(set(names)) >= 51
    assert [n for n in names if sum(n.startswith(GROUPS[g]) for g in GROUPS) != 1] == []


@pytest.mark.slow
@pytest.mark.timeout(1800)  # a dozen commands: a hang guard that a loaded machine stays within
@pytest.mark.parametrize("group", GROUPS)
def test_every_bad_input_gets_a_named_error_and_loses_nothing(tmp_path: Path, group: str) -> None:
    """Every bad input exits non-zero naming the field and what is allowed, with no traceback and no output."""
    (tmp_path / "policy.safetensors").write_bytes(MULTISITE.read_bytes())
    cases = [case for case in _cases(tmp_path) if case.name.startswith(GROUPS[group])]
    done = [_outcome(c, r) for c, r in zip(cases, run_forked([c.argv for c in cases]), strict=True)]
    accepted = [c for c in done if c.outcome["returncode"] == 0]
    tracebacks = [c for c in done if c.outcome["traceback"]]
    unnamed = [c for c in done if c.outcome["missing"]]
    written = [c for c in done if c.outcome["written"]]
    print(
        f"\nbad inputs tried ({group}): {len(done)}, tracebacks: {len(tracebacks)}, accepted: {len(accepted)}, "
        f"unclear messages: {len(unnamed)}, partial outputs: {len(written)}"
    )
    failures = [
        f"{c.name}: exit {c.outcome['returncode']}, missing {c.outcome['missing']}, wrote {c.outcome['written']}\n"
        f"{c.outcome['text']}"
        for c in done
        if c in accepted or c in tracebacks or c in unnamed or c in written
    ]
    assert done and not failures, "\n\n".join(failures)


def test_an_empty_or_text_demonstrations_file_is_refused_as_a_truncated_one(tmp_path: Path) -> None:
    """An empty file and a text file named .npz get the truncated archive's refusal, word for word: the matrix
    runs the truncated one through the command line (a new check of either is a new row there)."""
    from policies.demos import load_demos
    from policies.errors import DemonstrationError

    np.savez(tmp_path / "good.npz", **_toy_demos())
    whole = (tmp_path / "good.npz").read_bytes()
    messages = {}
    for name, data in (("truncated", whole[: len(whole) // 2]), ("empty", b""), ("text", b"not an archive\n")):
        path = _write(tmp_path / f"{name}.npz", data)
        with pytest.raises(DemonstrationError) as refused:
            load_demos(path)
        messages[name] = str(refused.value).replace(str(path), "PATH")
    assert messages["empty"] == messages["text"] == messages["truncated"], messages
    assert "--demos-file PATH: not a readable .npz" in messages["truncated"]


def test_a_sweep_rerun_with_another_identity_is_refused(tmp_path: Path) -> None:
    """A robustness rerun into the same --out with another --vary or policy is refused naming the difference."""
    out = tmp_path / "sweep"
    base = ("robustness", "--policy", "scripted", *SWEEP, "--trials", "1", "--out", str(out))
    (first,) = run_forked([(*base, "--vary", "stiffness=1")])
    assert first.returncode == 0, first.stderr
    recorded = json.loads((out / "sweep.json").read_text())
    assert recorded["vary"] == ["stiffness=1:1"] and recorded["episodes"] == 1 and recorded["package_version"]
    lines = (out / "episodes.jsonl").read_text()
    for argv, words in (
        ((*base, "--vary", "stiffness=0.1:0.2x"), ("vary", "stiffness=1:1", "stiffness=0.1:0.2x", "--fresh")),
        (
            ("robustness", "--policy", "random", *SWEEP, "--trials", "1", "--out", str(out), "--vary", "stiffness=1"),
            ("policy", "'scripted'", "'random'"),
        ),
    ):
        (again,) = run_forked([argv])
        assert again.returncode != 0 and "Traceback" not in again.stderr
        for word in words:
            assert word in again.stderr, again.stderr
        assert (out / "episodes.jsonl").read_text() == lines  # the first sweep's episodes are kept
    (fresh,) = run_forked([(*base, "--vary", "stiffness=0.1:0.2x", "--fresh")])
    assert fresh.returncode == 0, fresh.stderr
    assert json.loads((out / "sweep.json").read_text())["vary"] == ["stiffness=0.1:0.2x"]


def test_json_into_a_missing_folder_is_written(tmp_path: Path) -> None:
    """--json into a folder that does not exist yet gets the folder made before the episodes run."""
    report = tmp_path / "new" / "deeper" / "eval.json"
    (result,) = run_forked([(*EVALUATE, "--policy", "scripted", "--json", str(report))])
    assert result.returncode == 0, result.stderr
    assert json.loads(report.read_text())["summary"]["episodes"] == 1


@pytest.mark.skipif(sys.platform != "linux", reason="reads /proc for the process tree")
def test_sweep_workers_end_with_a_killed_parent(tmp_path: Path) -> None:
    """SIGKILL of a robustness run leaves none of its pool workers (or their resource tracker) running."""
    out = tmp_path / "sweep"
    argv = ["robustness", "--policy", "scripted", "--task", "lift", "--jobs", "2", "--no-progress"]
    argv += ["--vary", "stiffness=0.5:2x", "--trials", "40", "--out", str(out)]
    parent = subprocess.Popen(
        [sys.executable, "-m", "tissue_retract", *argv], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    try:
        episodes = out / "episodes.jsonl"
        # Event, not a delay: the first finished episode proves the pool is up and serving.
        _wait_for(lambda: (episodes.exists() and episodes.stat().st_size > 0) or parent.poll() is not None)
        assert parent.poll() is None, "the sweep ended before it could be killed"
        children = _descendants(parent.pid)
        assert children, "no worker processes found"
    finally:
        parent.send_signal(signal.SIGKILL)
        parent.wait()
    _wait_for(lambda: not any(_alive(pid) for pid in children))
    assert not [pid for pid in children if _alive(pid)]


def _descendants(pid: int) -> list[int]:
    found: list[int] = []
    pending = [pid]
    while pending:
        current = pending.pop()
        for task in Path(f"/proc/{current}/task").glob("*"):
            try:
                kids = [int(k) for k in (task / "children").read_text().split()]
            except OSError:
                continue
            found += kids
            pending += kids
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z"


def _wait_for(condition: Callable[[], bool], limit_s: float = 240.0) -> None:
    """Block until ``condition`` holds, re-checking on a short wait (a bound for a hung run, not a timing)."""
    import threading

    event = threading.Event()
    waited = 0.0
    while not condition():
        if waited > limit_s:
            raise AssertionError("condition not reached")
        event.wait(0.05)
        waited += 0.05
