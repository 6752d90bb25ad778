"""Checkpoints: a documented, versioned, tensors-only file format, and the deployable policy.

Format ``tissue-retract-checkpoint``, version 1: one `safetensors <https://github.com/huggingface/safetensors>`_
file. Tensors are named ``<group>.<name>``:

* ``actor.*`` (always), and in training checkpoints ``critic.*``, ``actor_target.*``, ``critic_target.*``,
  ``extra.*`` (SAC's temperature), ``optim.<optimiser>.<param index>.<step|exp_avg|exp_avg_sq>``,
  ``replay.*`` and ``demos.*`` (the buffers), ``rng.torch``;

and the header's ``__metadata__`` holds one key, ``tissue_retract``, a JSON object with ``format``,
``format_version``, ``kind`` (``"policy"``: actor only; ``"training"``: everything needed to resume),
``algo``, ``task_id``, ``spaces`` (shapes of ``observation``, ``achieved_goal``, ``desired_goal``; shape and
bounds of ``action``), ``normalizer`` (``obs`` and ``goal``: running ``sum``, ``sumsq``, ``count``, and
``mean``, ``std`` for reading), ``config`` (:class:`policies.config.TrainConfig` fields),
``package_version``, ``command`` (the exact train command), ``progress`` (episodes, env steps, updates)
and, for training checkpoints, ``rng`` (NumPy generator states).

Loading parses the header as JSON and reads raw tensor bytes: nothing in a file is ever executed, and
a file that is not safetensors (a pickle, a ``torch.save`` archive) is refused before it is read.
"""

from __future__ import annotations

import itertools
import json
import struct
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from safetensors import safe_open
from safetensors.torch import save_file

from policies.algos import AGENTS, Agent, Dims, make_agent
from policies.config import TrainConfig
from policies.errors import CheckpointError, SpaceMismatchError
from psm_control import __version__
from psm_control.errors import ConfigurationError, InputFileError
from psm_control.inputs import check_regular_file
from psm_control.outputs import atomic_path

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "Checkpoint",
    "Policy",
    "check_spaces",
    "env_spaces",
    "load_agent",
    "load_checkpoint",
    "load_policy",
    "save_checkpoint",
]

FORMAT = "tissue-retract-checkpoint"
FORMAT_VERSION = 1
_META_KEY = "tissue_retract"
#: Largest safetensors header read [bytes]: names, shapes and metadata, never tensor data.
_MAX_HEADER_BYTES = 16_000_000
#: Deepest nesting of a header's JSON (this format nests 4 levels).
_MAX_HEADER_DEPTH = 32
#: Largest checkpoint file [bytes]: a training checkpoint with a full default replay buffer is ~100 MB.
_MAX_FILE_BYTES = 4_000_000_000
#: Tensor groups holding network weights, which must be finite.
_WEIGHT_GROUPS = ("actor.", "critic.", "actor_target.", "critic_target.", "extra.")


def env_spaces(env: gym.Env[Any, Any]) -> dict[str, Any]:
    """The spaces of a goal env as JSON-ready shapes and bounds."""
    obs_space = env.observation_space
    act_space = env.action_space
    if not isinstance(obs_space, gym.spaces.Dict) or not isinstance(act_space, gym.spaces.Box):
        raise CheckpointError("<env>", "the environment is not a goal env (Dict observation, Box action)")
    out: dict[str, Any] = {}
    for key in ("observation", "achieved_goal", "desired_goal"):
        space = obs_space.spaces.get(key)
        if space is None or space.shape is None:
            raise CheckpointError("<env>", f"the environment's observation has no {key!r} entry")
        out[key] = list(space.shape)
    out["action"] = {
        "shape": list(act_space.shape),
        "low": [float(v) for v in np.asarray(act_space.low).reshape(-1)],
        "high": [float(v) for v in np.asarray(act_space.high).reshape(-1)],
    }
    return out


def check_spaces(path: object, saved: Mapping[str, Any], env: gym.Env[Any, Any]) -> None:
    """Refuse an environment whose spaces differ from those a checkpoint was trained on.

    Raises:
        SpaceMismatchError: Naming the first space that differs.
    """
    found = env_spaces(env)
    for key in ("observation", "achieved_goal", "desired_goal"):
        if list(saved.get(key, [])) != found[key]:
            raise SpaceMismatchError(path, key, tuple(saved.get(key, [])), tuple(found[key]))
    want, have = saved.get("action", {}), found["action"]
    if list(want.get("shape", [])) != have["shape"]:
        raise SpaceMismatchError(path, "action", tuple(want.get("shape", [])), tuple(have["shape"]))
    for bound in ("low", "high"):
        if not np.allclose(want.get(bound, []), have[bound]):
            raise SpaceMismatchError(path, f"action {bound}", want.get(bound), have[bound])


class Checkpoint:
    """A loaded checkpoint: its JSON metadata and its tensors (CPU)."""

    def __init__(self, path: Path, meta: dict[str, Any], tensors: dict[str, torch.Tensor]) -> None:
        self.path = path
        self.meta = meta
        self.tensors = tensors

    def group(self, prefix: str) -> dict[str, torch.Tensor]:
        """Tensors named ``<prefix>.<name>``, keyed by ``name``."""
        head = prefix + "."
        return {k[len(head) :]: v for k, v in self.tensors.items() if k.startswith(head)}

    @property
    def config(self) -> TrainConfig:
        """The training configuration."""
        try:
            return TrainConfig.from_dict(self.meta["config"])
        except (KeyError, TypeError, ValueError, ConfigurationError) as e:
            raise CheckpointError(self.path, f"invalid training configuration: {e}") from e


def _normalizer_meta(agent: Agent) -> dict[str, Any]:
    out = {}
    for name, norm in (("obs", agent.obs_norm), ("goal", agent.goal_norm)):
        out[name] = {
            "sum": norm.sum.tolist(),
            "sumsq": norm.sumsq.tolist(),
            "count": norm.count,
            "mean": norm.mean.tolist(),
            "std": norm.std.tolist(),
        }
    return out


def save_checkpoint(
    path: str | Path,
    agent: Agent,
    *,
    task_id: str,
    spaces: dict[str, Any],
    command: str,
    progress: dict[str, int],
    training: bool = False,
    arrays: Mapping[str, np.ndarray] | None = None,
    rng: Mapping[str, Any] | None = None,
    observation: str = "task",
) -> Path:
    """Write a checkpoint atomically (a crash mid-write leaves the previous file intact).

    Args:
        path: Destination ``.safetensors`` file.
        agent: The agent.
        task_id: Gymnasium id of the task it was trained on.
        spaces: :func:`env_spaces` of the task.
        command: The exact command that trained it.
        progress: Episodes, env steps and updates done.
        training: Also write critics, targets, optimiser state, ``arrays`` and ``rng`` (to resume).
        arrays: Extra arrays by tensor name (replay buffers), training checkpoints only.
        rng: JSON-ready random generator states, training checkpoints only.
        observation: What the policy observed in training: ``task`` (the task's own observation) or
            the name of what replaced it (``train --blind``).
    """

    tensors: dict[str, torch.Tensor] = {}
    modules = agent.modules() if training else {"actor": agent.actor}
    for name, module in modules.items():
        for key, value in module.state_dict().items():
            tensors[f"{name}.{key}"] = value.detach().clone().contiguous()
    if training:
        for key, value in agent.extra_tensors().items():
            tensors[f"extra.{key}"] = value.detach().clone().reshape(-1)
        for opt_name, opt in agent.optimizers().items():
            for index, state in opt.state_dict()["state"].items():
                for key, value in state.items():
                    tensors[f"optim.{opt_name}.{index}.{key}"] = torch.as_tensor(value).detach().clone().reshape(-1)
        for key, array in (arrays or {}).items():
            tensors[key] = torch.from_numpy(np.ascontiguousarray(array))
        tensors["rng.torch"] = torch.get_rng_state()
    meta = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "kind": "training" if training else "policy",
        "algo": agent.name,
        "task_id": task_id,
        "spaces": spaces,
        "normalizer": _normalizer_meta(agent),
        "config": agent.config.to_dict(),
        "package_version": __version__,
        "command": command,
        "observation": observation,
        "progress": dict(progress),
        "updates": agent.updates,
    }
    if training:
        meta["rng"] = dict(rng or {})
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path, "checkpoint") as temporary:
        save_file(tensors, str(temporary), metadata={_META_KEY: json.dumps(meta)})
    return path


def _read_header(path: Path) -> dict[str, Any]:
    """The safetensors JSON header, refusing anything that is not a safetensors file."""
    try:
        with path.open("rb") as f:
            head = f.read(8)
            if len(head) < 8:
                raise CheckpointError(path, "the file is too short to be a safetensors checkpoint")
            (length,) = struct.unpack("<Q", head)
            if not 2 <= length <= _MAX_HEADER_BYTES:
                raise CheckpointError(
                    path, "not a safetensors file (a pickle or torch.save archive?); only tensors-only files are loaded"
                )
            raw = f.read(length)
    except OSError as e:
        raise CheckpointError(path, f"cannot read: {e}") from e
    header = _bounded_json(path, raw, "header")
    if not isinstance(header, dict):
        raise CheckpointError(path, "not a safetensors file: its header is not a JSON object")
    return header


def _bounded_json(path: Path, raw: bytes | str, what: str) -> Any:
    """JSON nested at most :data:`_MAX_HEADER_DEPTH` levels, checked before it is parsed."""
    text = raw.decode("utf-8") if isinstance(raw, bytes) else raw
    depth = deepest = 0
    in_string = escaped = False
    for char in text:
        if in_string:
            if escaped:
                escaped = False
            elif char == "\\":
                escaped = True
            elif char == '"':
                in_string = False
        elif char == '"':
            in_string = True
        elif char in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif char in "]}":
            depth -= 1
    if deepest > _MAX_HEADER_DEPTH:
        raise CheckpointError(path, f"its {what} is nested {deepest} levels deep; at most {_MAX_HEADER_DEPTH} allowed")
    try:
        return json.loads(text)
    except (json.JSONDecodeError, RecursionError) as e:
        raise CheckpointError(
            path, f"not a safetensors checkpoint: its {what} is not valid JSON (a pickle or torch.save archive?)"
        ) from e


def load_checkpoint(path: str | Path) -> Checkpoint:
    """Read and validate a checkpoint without executing anything from it.

    Raises:
        CheckpointError: The file is missing, is not a tensors-only safetensors file, or lacks this
            format's metadata, or is of a newer format version.
    """
    path = Path(path)
    if not path.exists():
        raise CheckpointError(path, "no such file")
    try:
        check_regular_file(path, "--policy", _MAX_FILE_BYTES)
    except InputFileError as e:
        raise CheckpointError(path, f"not a usable file: expected {e.allowed}") from e
    try:
        header = _read_header(path)
    except UnicodeDecodeError as e:
        raise CheckpointError(path, "not a safetensors file: its header is not UTF-8 JSON") from e
    meta_raw = (header.get("__metadata__") or {}).get(_META_KEY)
    if not isinstance(meta_raw, str):
        raise CheckpointError(path, f"no {_META_KEY!r} metadata: not a tissue-retract checkpoint")
    meta = _bounded_json(path, meta_raw, "metadata")
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise CheckpointError(path, f"metadata format is not {FORMAT!r}")
    version = meta.get("format_version")
    if not isinstance(version, int) or not 1 <= version <= FORMAT_VERSION:
        raise CheckpointError(path, f"format version {version!r} is not supported (1 to {FORMAT_VERSION})")
    if meta.get("algo") not in AGENTS:
        raise CheckpointError(path, f"unknown algorithm {meta.get('algo')!r}")
    try:
        tensors: dict[str, torch.Tensor] = {}
        with safe_open(str(path), framework="pt", device="cpu") as f:
            for key in f.keys():  # noqa: SIM118 (a safe_open handle is not a mapping)
                tensors[key] = f.get_tensor(key)
    except Exception as e:
        raise CheckpointError(path, f"malformed tensor data: {e}") from e
    for key, tensor in tensors.items():
        if key.startswith(_WEIGHT_GROUPS) and tensor.is_floating_point() and not bool(torch.isfinite(tensor).all()):
            raise CheckpointError(
                path, f"tensor {key!r} holds non-finite values (NaN or inf); only finite weights load"
            )
    return Checkpoint(path, meta, tensors)


def _dims(ckpt: Checkpoint) -> Dims:
    spaces = ckpt.meta.get("spaces", {})
    try:
        return Dims(
            int(np.prod(spaces["observation"])),
            int(np.prod(spaces["desired_goal"])),
            int(np.prod(spaces["action"]["shape"])),
        )
    except (KeyError, TypeError, ValueError, OverflowError) as e:
        raise CheckpointError(ckpt.path, f"its spaces are incomplete: {e}") from e


def _restore_normalizers(ckpt: Checkpoint, agent: Agent) -> None:
    try:
        for name, norm in (("obs", agent.obs_norm), ("goal", agent.goal_norm)):
            stats = ckpt.meta["normalizer"][name]
            norm.load_state(
                {
                    "sum": np.asarray(stats["sum"]),
                    "sumsq": np.asarray(stats["sumsq"]),
                    "count": np.asarray([stats["count"]]),
                }
            )
    except (KeyError, TypeError, ValueError) as e:
        raise CheckpointError(ckpt.path, f"its normaliser statistics are invalid: {e}") from e


def _check_network_size(ckpt: Checkpoint, dims: Dims, config: TrainConfig) -> None:
    """Refuse metadata describing a larger actor than the file's tensors, before anything is allocated."""
    sizes = [dims.obs + dims.goal, *config.hidden, dims.action]
    if min(sizes) < 1:
        raise CheckpointError(ckpt.path, f"its spaces give a network of layer sizes {sizes}")
    implied = sum(a * b + b for a, b in itertools.pairwise(sizes))
    stored = sum(int(t.numel()) for t in ckpt.group("actor").values())
    if implied > stored:
        raise CheckpointError(
            ckpt.path,
            f"its metadata describes an actor of layer sizes {sizes} ({implied} parameters) but the file holds "
            f"{stored} actor parameters",
        )


def load_agent(ckpt: Checkpoint, seed: int = 0) -> Agent:
    """Rebuild the agent of a checkpoint: networks, normalisers and, for training checkpoints, optimisers.

    Raises:
        CheckpointError: The tensors do not fit the networks the metadata describes.
    """
    dims, config = _dims(ckpt), ckpt.config
    _check_network_size(ckpt, dims, config)
    agent = make_agent(dims, config, seed)
    _restore_normalizers(ckpt, agent)
    modules = agent.modules() if ckpt.meta.get("kind") == "training" else {"actor": agent.actor}
    try:
        for name, module in modules.items():
            module.load_state_dict(ckpt.group(name), strict=True)
        if ckpt.meta.get("kind") == "training":
            with torch.no_grad():
                for key, value in agent.extra_tensors().items():
                    value.copy_(ckpt.tensors[f"extra.{key}"].reshape(value.shape))
            for opt_name, opt in agent.optimizers().items():
                saved = ckpt.group(f"optim.{opt_name}")
                state: dict[int, dict[str, torch.Tensor]] = {}
                params = [p for group in opt.param_groups for p in group["params"]]
                for key, value in saved.items():
                    index, field = key.split(".", 1)
                    i = int(index)
                    state.setdefault(i, {})[field] = value if field == "step" else value.reshape(params[i].shape)
                for entry in state.values():
                    entry["step"] = entry["step"].reshape(())
                opt.load_state_dict({"state": state, "param_groups": opt.state_dict()["param_groups"]})
    except (RuntimeError, KeyError, ValueError, IndexError) as e:
        raise CheckpointError(ckpt.path, f"its tensors do not fit the {ckpt.meta['algo']} networks: {e}") from e
    agent.updates = int(ckpt.meta.get("updates", 0))
    return agent


class Policy:
    """The deterministic actor of a checkpoint, as ``policy(obs_dict) -> action``.

    Actions are in the environment's action space (the actor's [-1, 1] output mapped onto its bounds).
    A single observation dict gives one action; a dict of stacked observations gives stacked actions.
    """

    def __init__(self, agent: Agent, meta: dict[str, Any]) -> None:
        self.agent = agent
        self.meta = meta
        action = meta["spaces"]["action"]
        low = np.asarray(action["low"], dtype=np.float32)
        high = np.asarray(action["high"], dtype=np.float32)
        # centre + half-range * a: exactly the actor's output for the usual Box(-1, 1).
        self.centre = 0.5 * (high + low)
        self.half_range = 0.5 * (high - low)

    def __call__(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        a = self.agent.act(np.asarray(obs["observation"]), np.asarray(obs["desired_goal"]))
        return (self.centre + self.half_range * a).astype(np.float32)


def load_policy(
    path: str | Path, env: gym.Env[Any, Any], *, allow_other_task: bool = False
) -> Callable[[Mapping[str, np.ndarray]], np.ndarray]:
    """The deterministic policy stored in a checkpoint, checked against ``env``'s spaces and task.

    Raises:
        CheckpointError: The file is not a valid tensors-only checkpoint, or was trained for another task
            (unless ``allow_other_task``).
        SpaceMismatchError: The checkpoint's spaces differ from ``env``'s.
    """
    ckpt = load_checkpoint(path)
    check_spaces(ckpt.path, ckpt.meta.get("spaces", {}), env)
    trained_for = ckpt.meta.get("task_id")
    task = env.spec.id if env.spec is not None else None
    if not allow_other_task and task is not None and trained_for != task:
        raise CheckpointError(
            ckpt.path,
            f"was trained for task {trained_for!r}, not {task!r}; pick --task to match, or pass "
            "--allow-other-task to run it anyway",
        )
    agent = load_agent(ckpt)
    agent.actor.eval()
    return Policy(agent, ckpt.meta)
