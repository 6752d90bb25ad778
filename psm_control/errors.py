"""The project's exception hierarchy.

Every error raised on purpose by tissue-retract derives from :class:`TissueRetractError`, so a caller
can catch the project's failures without catching programming errors. Subclasses carry the offending
data as attributes (joint, value, bound) so that callers and logs can act on them, not only print them.
"""

from __future__ import annotations

from collections.abc import Iterable

__all__ = [
    "ConfigurationError",
    "InfeasibleProblemError",
    "InputFileError",
    "JointLimitError",
    "JointVectorError",
    "NotBuiltError",
    "OutputFileError",
    "OutputWriteError",
    "SafetyStopError",
    "TissueRetractError",
    "UnknownVariantError",
]


class TissueRetractError(Exception):
    """Root of every error the project raises on purpose."""


class ConfigurationError(TissueRetractError, ValueError):
    """A setting is missing, of the wrong type, or outside its allowed range.

    Attributes:
        field: Name of the offending setting.
        value: The value that was given.
        allowed: Human-readable description of what is allowed.
    """

    def __init__(self, field: str, value: object, allowed: str) -> None:
        self.field = field
        self.value = value
        self.allowed = allowed
        super().__init__(f"{field}={value!r} is not allowed: expected {allowed}")

    def for_field(self, field: str) -> ConfigurationError:
        """The same refusal of the same value, given as ``field`` (a reader that serves several options names
        the one it serves by default)."""
        # Not copy.copy: it calls the class with the exception's args, which subclasses' signatures do not take.
        other = type(self).__new__(type(self))
        other.__dict__.update(self.__dict__)
        other.field = field
        other.args = (f"{field}={self.value!r} is not allowed: expected {self.allowed}",)
        return other


class InputFileError(ConfigurationError):
    """A file the user named cannot be used: missing, not a regular file, too large, not UTF-8, malformed.

    Attributes:
        path: The file, as given.
    """

    def __init__(self, field: str, path: object, allowed: str) -> None:
        self.path = str(path)
        super().__init__(field, self.path, allowed)


class OutputFileError(ConfigurationError):
    """A path the user named for an output cannot be used: a device, a FIFO, a folder, one of the inputs,
    an existing recording without the user's word, a folder that cannot be made or written.

    Raised before any work starts, so nothing is lost and nothing at the path is touched.

    Attributes:
        path: The path, as given.
    """

    def __init__(self, field: str, path: object, allowed: str) -> None:
        self.path = str(path)
        super().__init__(field, self.path, allowed)


class OutputWriteError(TissueRetractError):
    """An output file could not be written (a full disk, a file-size limit, a quota, a write error).

    The path is left as it was: the old file, or none; never an empty or partial one.

    Attributes:
        field: The option that named the file (``--json``), or a description of the file.
        path: The file.
        reason: What the system said (``No space left on device (ENOSPC)``).
    """

    def __init__(self, field: str, path: object, reason: str) -> None:
        self.field = field
        self.path = str(path)
        self.reason = reason
        super().__init__(f"could not write {field} {self.path!r}: {reason}; nothing was written there")


class UnknownVariantError(ConfigurationError):
    """A named variant (arm, tool, task, ...) is not one the project knows.

    Attributes:
        valid: The names that are known.
    """

    def __init__(self, field: str, value: object, valid: Iterable[str]) -> None:
        self.valid = tuple(valid)
        super().__init__(field, value, "one of " + ", ".join(repr(v) for v in self.valid))


class JointVectorError(TissueRetractError, ValueError):
    """A joint vector has the wrong shape or holds non-finite values.

    Attributes:
        joint: Name of the offending joint, or None when the whole vector is wrong (its length).
        value: The offending value (the joint value, or the vector's length).
    """

    def __init__(self, message: str, joint: str | None = None, value: object = None) -> None:
        self.joint = joint
        self.value = value
        super().__init__(message)


class JointLimitError(JointVectorError):
    """A joint value lies outside its limits where strict checking was asked for.

    Attributes:
        bound: The limit that was crossed.
    """

    def __init__(self, joint: str, value: float, bound: float, kind: str = "position") -> None:
        self.bound = bound
        self.kind = kind
        side = "above the upper" if value > bound else "below the lower"
        super().__init__(f"joint {joint!r} {kind} {value:.6g} is {side} limit {bound:.6g}", joint=joint, value=value)


class NotBuiltError(TissueRetractError):
    """A command exists in the interface but is not implemented in this version."""


class InfeasibleProblemError(TissueRetractError):
    """A quadratic program of the control chain has no acceptable solution.

    Attributes:
        stage: Which stage built the problem (``"ik"``, ``"safety_filter"``).
        status: The solver's status text.
        problem: The ``qpsolvers.Problem`` that failed, so it can be inspected or re-solved offline.
    """

    def __init__(self, stage: str, status: str, problem: object = None) -> None:
        self.stage = stage
        self.status = status
        self.problem = problem
        super().__init__(f"{stage} QP has no acceptable solution (solver status: {status})")


class SafetyStopError(TissueRetractError):
    """A safety stage refused a command; the reason names the rule and the offending value.

    Attributes:
        reason: Human-readable cause, as recorded in the safety log.
    """

    def __init__(self, reason: str) -> None:
        self.reason = reason
        super().__init__(reason)
