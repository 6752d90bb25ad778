"""Policies that misbehave, for the bad-input corpus (``--policy tests.bad_policies:NAME``)."""

from __future__ import annotations

from typing import Any


def exit_zero(observation: Any) -> Any:
    """A policy that ends the interpreter with status 0, as a careless ``sys.exit()`` would."""
    raise SystemExit(0)


def raises(observation: Any) -> Any:
    """A policy with a bug."""
    raise RuntimeError("policy bug")
