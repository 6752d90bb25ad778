"""What a deploy waits for before its first command, said in words a user can act on.

A deploy commands only an arm that is ENABLED and homed. A real deploy enables and homes it itself; a dry
run never does (it publishes nothing that moves the arm), so against a freshly started console it would
wait for a state that nothing brings about. These lines say, at once, the operating state the deploy
really sees and how to reach the state it waits for.
"""

from __future__ import annotations

__all__ = ["describe_operating_state", "dry_run_wait_hint", "is_ready_state"]


def is_ready_state(state: str, homed: bool) -> bool:
    """True when an arm in ``state`` (homed or not) may be commanded."""
    return state == "ENABLED" and homed


def describe_operating_state(state: str, homed: bool, busy: bool, waited_s: float) -> str:
    """The operating state as a deploy saw it, e.g. ``"ENABLED, homed"``.

    Args:
        state: The console's state, "" when no ``operating_state`` arrived.
        homed: Whether the arm is homed.
        busy: Whether a move or homing runs.
        waited_s: How long the deploy waited for an ``operating_state`` [s].
    """
    if not state:
        return f"unknown (no operating_state received in {waited_s:g} s)"
    return f"{state}, {'homed' if homed else 'not homed'}" + (", busy" if busy else "")


def dry_run_wait_hint(arm: str, state: str, homed: bool, wait_s: float) -> str:
    """What a dry run on an arm that is not ENABLED and homed waits for, and how to get there."""
    missing = "enabled and homed" if state != "ENABLED" else "homed"
    return (
        f"dry run: waiting up to {wait_s:g} s for {arm} to be ENABLED and homed; a dry run never enables or "
        f"homes the arm. Get it {missing} and at the episodes' start from another terminal: "
        f"tissue-retract ready-arm --arm {arm} (or the console's GUI: Power On, Home)."
    )
