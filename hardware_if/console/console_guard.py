"""One console per arm, and the console's view of who commands it (the simulated dVRK's side).

A second ``sim-dvrk --arm PSM1`` on a domain where PSM1 is already served would answer the same enable,
home and servo commands as the first, and a client would see two arms in one. :func:`other_consoles`
looks for a console that already serves the arm before this one serves anything: it waits up to
:data:`CONSOLE_DISCOVERY_S` for discovery to show one (a newcomer hears the participants already there
within one of their announcement periods, :data:`~hardware_if.common.commander_watch.DISCOVERY_S`).

:class:`CommandSources` is the console reporting, as a dVRK console reports its faults, that commands
reach it from more than one program: on each :data:`SOURCES_PERIOD_S` in which commands arrived, it reads
the ROS graph for the nodes publishing the topics they arrived on, and when there are several it says so
once (per set of nodes) on the arm's ``warning`` topic, naming them. The console still obeys the last
command, as the dVRK does: the warning is for the operator, the refusal is the deploy's.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from hardware_if.common.commander_watch import DISCOVERY_S, NAME_WAIT_S, UNNAMED, node_name, served_by
from hardware_if.common.crtk import COMMAND_TOPICS, CONSOLE_INPUT_TOPICS

__all__ = ["CONSOLE_DISCOVERY_S", "SOURCES_PERIOD_S", "CommandSources", "other_consoles"]

#: Longest a starting console waits for discovery to show another console of its arm [s]: the time in
#: which a newcomer has heard every participant already on the domain.
CONSOLE_DISCOVERY_S = DISCOVERY_S
#: How often the console looks at who sent the commands of the last period [s].
SOURCES_PERIOD_S = 0.5


def other_consoles(node: Any, arm: str, timeout_s: float = CONSOLE_DISCOVERY_S) -> list[str]:
    """The nodes already serving ``arm`` (publishing its ``measured_js``) on ``node``'s domain, or [].

    Call it before ``node`` publishes ``measured_js`` itself. Returns as soon as one is seen (and named, or
    :data:`~hardware_if.common.commander_watch.NAME_WAIT_S` later), else after ``timeout_s``.
    """
    deadline = time.monotonic() + timeout_s
    named_by = float("inf")
    while True:
        found = served_by(node, arm)  # this node has no publisher yet; another console may share its name
        if found and named_by == float("inf"):
            named_by = time.monotonic() + NAME_WAIT_S
        if (found and (UNNAMED not in found or time.monotonic() >= named_by)) or (
            not found and time.monotonic() >= deadline
        ):
            return found
        time.sleep(0.02)  # graph updates arrive on the middleware's thread; nothing to spin


class CommandSources:
    """Warns on the console's ``warning`` topic when the arm's commands come from more than one node.

    Args:
        node: The console's node (its graph and its timer).
        arm: Arm name / namespace.
        warn: Publishes a warning (the console's ``warning`` event).
    """

    #: Topics whose commands are traced to their publishers.
    TOPICS = (*COMMAND_TOPICS, *CONSOLE_INPUT_TOPICS)

    def __init__(self, node: Any, arm: str, warn: Callable[[str], None]) -> None:
        self.node, self.arm, self.warn = node, arm, warn
        self._arrived: set[str] = set()
        self._warned: frozenset[str] = frozenset()
        node.create_timer(SOURCES_PERIOD_S, self._check)

    def noting(self, topic: str, callback: Callable[[Any], None]) -> Callable[[Any], None]:
        """``callback``, noting that a command arrived on ``topic`` first."""

        def noted(message: Any) -> None:
            self._arrived.add(topic)
            callback(message)

        return noted

    def publishers(self, topics: set[str]) -> dict[str, list[str]]:
        """Nodes publishing any of ``topics`` (names relative to the arm): node name -> its topics."""
        own = self.node.get_fully_qualified_name()
        found: dict[str, list[str]] = {}
        for topic in sorted(topics):
            for info in self.node.get_publishers_info_by_topic(f"/{self.arm}/{topic}"):
                name = node_name(info)
                if name != own and topic not in found.setdefault(name, []):
                    found[name].append(topic)
        return found

    def _check(self) -> None:
        arrived, self._arrived = self._arrived, set()
        if not arrived:
            return
        try:
            sources = self.publishers(arrived)
        except Exception:  # the graph is unavailable while the node shuts down
            return
        if len(sources) < 2 or frozenset(sources) == self._warned:
            return
        self._warned = frozenset(sources)
        named = "; ".join(f"{name} ({', '.join(topics)})" for name, topics in sorted(sources.items()))
        self.warn(
            f"{self.arm}: commands from {len(sources)} publishers: {named}; one commander per arm "
            "(the arm follows whichever command came last)"
        )
