"""Errors raised by the learning code.

They derive from :class:`psm_control.errors.TissueRetractError`, so the command line reports them as
clear one-line messages instead of tracebacks.
"""

from __future__ import annotations

from psm_control.errors import TissueRetractError

__all__ = ["CheckpointError", "DemonstrationError", "ReproductionError", "SpaceMismatchError", "TrainingDivergedError"]


class CheckpointError(TissueRetractError):
    """A checkpoint file is missing, malformed, of an unknown version, or holds something other than tensors.

    Attributes:
        path: The file that was refused.
    """

    def __init__(self, path: object, reason: str) -> None:
        self.path = str(path)
        self.reason = reason
        super().__init__(f"checkpoint {self.path}: {reason}")


class SpaceMismatchError(CheckpointError):
    """A checkpoint was trained on spaces that differ from the environment it is asked to drive.

    Attributes:
        key: The space that differs (``"observation"``, ``"desired_goal"``, ``"action"``, ...).
        expected: What the checkpoint was trained with.
        found: What the environment has.
    """

    def __init__(self, path: object, key: str, expected: object, found: object) -> None:
        self.key = key
        self.expected = expected
        self.found = found
        super().__init__(
            path,
            f"the policy was trained on {key} space {expected} but the environment has {found}; "
            "train a policy for this task or pick the matching --task",
        )


class DemonstrationError(TissueRetractError):
    """Demonstrations could not be obtained or do not fit the task's spaces."""


class TrainingDivergedError(TissueRetractError):
    """A loss or a network weight became non-finite; training stopped before writing it to a checkpoint.

    Attributes:
        episode: The training episode after which it was found.
        what: The loss or weight that is not finite.
    """

    def __init__(self, episode: int, what: str, kept: str) -> None:
        self.episode = episode
        self.what = what
        super().__init__(
            f"training stopped after episode {episode}: {what} is not finite (NaN or inf); {kept}. Check the "
            "demonstrations and lower the learning rates (--set actor_lr=..., critic_lr=...)"
        )


class ReproductionError(TissueRetractError):
    """Some runs of a reproduction failed; every other run was finished and kept.

    Attributes:
        failures: ``(run name, error message)`` per failed run.
    """

    def __init__(self, failures: list[tuple[str, str]]) -> None:
        self.failures = failures
        listed = "; ".join(f"{name}: {message}" for name, message in failures)
        super().__init__(
            f"{len(failures)} run(s) failed ({listed}); the other runs finished and are kept, and running "
            "the same command again retrains only the failed and unfinished ones"
        )
