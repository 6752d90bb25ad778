"""One commander per arm: who else could command the arm, or serve it, as the ROS graph shows it.

A dVRK console obeys whoever publishes on its command topics; it cannot tell two clients apart. A
teleoperation node left running, a second script or a colleague's terminal is the ordinary way an arm
gets two masters, and each of them would see the arm leave its commands without knowing why.
:class:`CommanderWatch` reads the ROS graph of one node (no message is exchanged) and names, for one arm:

- every other node with a publisher on the arm's command topics (:data:`COMMANDED_TOPICS`: the servo,
  move, effort and jaw commands, ``state_command``, the console's settings, and the simulated scene's
  ``task/reset``), as ``another commander: /node publishes /PSM1/servo_jp``;
- more than one console serving the arm (publishers of ``measured_js``; subscribers of ``state_command``
  that also publish ``operating_state``), as ``another console: ...``. A node that only listens, as
  ``ros2 topic echo`` or ``ros2 bag record`` does, serves nothing and is no console;
- a sensed topic (the arm's state, the endoscope's images) published by more than one node, or by another
  node than the one that published it when the sources were pinned (:meth:`CommanderWatch.pin_sources`,
  before the first command), as ``another source: ...``: the data the chain and the policy act on come from
  one source for the whole run.

Nodes of this process are told apart by their fully qualified names, so every node of a commanding
program needs a name of its own (the deploy's carry its process id). The watch answers what discovery
has shown so far: a participant is seen a few milliseconds to a second after it starts, so the deploy
checks before each command to a console and again every :data:`WATCH_PERIOD_S` while it runs.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from typing import Any

from hardware_if.common.crtk import COMMAND_TOPICS, CONSOLE_INPUT_TOPICS, ArmTopics

__all__ = [
    "COMMANDED_TOPICS",
    "DISCOVERY_QUIET_S",
    "DISCOVERY_S",
    "NAME_WAIT_S",
    "NAMING_TIMEOUT_S",
    "SENSED_TOPICS",
    "UNNAMED",
    "WATCH_PERIOD_S",
    "CommanderWatch",
    "console_kind",
    "node_name",
    "served_by",
]

#: The arm's command topics (relative to ``/<arm>/``): what only one program may publish.
COMMANDED_TOPICS = (*COMMAND_TOPICS, *CONSOLE_INPUT_TOPICS, "task/reset")
#: The arm's sensed topics (relative to ``/<arm>/``): what the client acts on, from one source each.
SENSED_TOPICS = (
    "measured_js",
    "setpoint_js",
    "jaw/measured_js",
    "jaw/setpoint_js",
    "body/measured_cf",
    "spatial/measured_cf",
    "measured_cp",
    "local/measured_cp",
    "setpoint_cp",
    "operating_state",
)
#: How often a running deploy reads the graph for other commanders [s].
WATCH_PERIOD_S = 0.1
#: An endpoint is discovered a little before its node's name (ROS sends names on a topic of its own): how
#: long a conflict waits for the names before it is said without them [s].
NAME_WAIT_S = 0.5
#: How long a hold already in force waits for the names of the nodes it is about before it is said without
#: them [s]: the arm is held meanwhile, and on a busy machine a name arrived more than NAME_WAIT_S after its
#: node's endpoints.
NAMING_TIMEOUT_S = 10.0
#: How long after joining the domain a program has heard every participant already there [s]. Fast DDS
#: announces each participant every 3 s (its default lease announcement period) and a newcomer often
#: learns of the others only from that: a new node saw a running sim-dvrk after 0.0 to 2.4 s over six
#: starts on this machine (``docs/one-commander.md``). Half a second more covers the delivery.
DISCOVERY_S = 3.5
#: How long the graph must also stay unchanged before a program's first command to the arm [s].
DISCOVERY_QUIET_S = 0.5
#: How an endpoint whose node's name has not arrived yet is named.
UNNAMED = "a node not yet named"
_UNKNOWN_NODE = "_NODE_NAME_UNKNOWN_"


def node_name(info: Any) -> str:
    """The fully qualified name of an endpoint's node, or :data:`UNNAMED` while discovery has not brought it."""
    if info.node_name == _UNKNOWN_NODE:
        return UNNAMED
    namespace = info.node_namespace.rstrip("/")
    return f"{namespace}/{info.node_name}"


def served_by(node: Any, arm: str) -> list[str]:
    """The nodes publishing ``/<arm>/measured_js`` (consoles serving the arm), one entry per publisher."""
    return sorted(node_name(i) for i in node.get_publishers_info_by_topic(ArmTopics(arm).topic("measured_js")))


def console_kind(consoles: list[str]) -> str:
    """``sim-dvrk`` when this project's simulated console serves the arm, else ``dvrk`` (``unknown``: none, or
    not yet named); ``consoles`` as :func:`served_by` lists them."""
    if not consoles or not all(name.startswith("/") for name in consoles):
        return "unknown"
    return "sim-dvrk" if all(name.endswith("_sim_dvrk") for name in consoles) else "dvrk"


class CommanderWatch:
    """Reads one node's view of the graph for other commanders and consoles of one arm.

    Args:
        node: Any rclpy node (its graph is the process's view of the domain).
        arm: Arm name / namespace.
        own_nodes: Fully qualified names of this program's nodes (their publishers are not "others").
    """

    def __init__(self, node: Any, arm: str, own_nodes: Iterable[str], sensed: Iterable[str] = ()) -> None:
        self.node = node
        self.arm = arm
        self.own_nodes = frozenset(own_nodes)
        self._topics = [f"/{arm}/{name}" for name in COMMANDED_TOPICS]
        self._sensed = [*(f"/{arm}/{name}" for name in SENSED_TOPICS), *sensed]
        self._pinned: dict[str, frozenset[str]] = {}

    def sources(self) -> dict[str, frozenset[str]]:
        """The nodes publishing each sensed topic (fully qualified topic name -> node names)."""
        return {
            topic: frozenset(node_name(i) for i in self.node.get_publishers_info_by_topic(topic))
            for topic in self._sensed
        }

    def pin_sources(self) -> None:
        """Take the sensed topics' publishers now as the run's sources (a topic with none is not pinned)."""
        self._pinned = {topic: nodes for topic, nodes in self.sources().items() if nodes and UNNAMED not in nodes}

    def _source_conflict(self) -> str:
        for topic, nodes in self.sources().items():
            if len(nodes) > 1:
                return (
                    f"another source: {topic} is published by {len(nodes)} nodes ({', '.join(sorted(nodes))}); "
                    "one source per sensor (stop the other one)"
                )
            pinned = self._pinned.get(topic)
            if pinned and nodes and UNNAMED not in nodes and nodes != pinned:
                return (
                    f"another source: {topic} is now published by {', '.join(nodes)}, not by "
                    f"{', '.join(pinned)} that published it when the run started (a sensor's source does not "
                    "change during a run)"
                )
        return ""

    def others(self) -> dict[str, list[str]]:
        """Other nodes with a publisher on a command topic: node name -> its topics, in topic order."""
        found: dict[str, list[str]] = {}
        for topic in self._topics:
            for info in self.node.get_publishers_info_by_topic(topic):
                name = node_name(info)
                if name not in self.own_nodes and topic not in found.setdefault(name, []):
                    found[name].append(topic)
        return found

    def consoles(self) -> list[str]:
        """Nodes that serve the arm: publishers of ``measured_js``, and subscribers of ``state_command`` that
        publish ``operating_state`` (a console answers the commands it takes).

        One console publishes the first and is the second; a list longer than one entry per role means a
        second console answers the same commands. A node that only subscribes (``ros2 topic echo``, a
        recorder) answers nothing and is not counted.
        """
        topics = ArmTopics(self.arm)
        publishers = served_by(self.node, self.arm)
        states = {node_name(i) for i in self.node.get_publishers_info_by_topic(topics.topic("operating_state"))}
        subscribers = sorted(
            name
            for name in (node_name(i) for i in self.node.get_subscriptions_info_by_topic(topics.topic("state_command")))
            if name not in self.own_nodes and name in states
        )
        return publishers if len(publishers) >= len(subscribers) else subscribers

    def snapshot(self) -> tuple[object, ...]:
        """What the graph shows of the domain: its nodes and the publishers of the arm's command topics."""
        nodes = tuple(sorted(self.node.get_node_names_and_namespaces()))
        publishers = tuple(len(self.node.get_publishers_info_by_topic(t)) for t in self._topics)
        return nodes, publishers, tuple(served_by(self.node, self.arm))

    def settle(self, joined_s: float, quiet_s: float = DISCOVERY_QUIET_S, timeout_s: float = 10.0) -> None:
        """Wait until :data:`DISCOVERY_S` after ``joined_s`` and ``quiet_s`` without a change in the graph.

        A program that has just joined the domain sees the console it waits for, and the other programs up
        to an announcement period later: the first check waits for them, at most ``timeout_s``.

        Args:
            joined_s: When this program's node joined the domain (``time.monotonic`` [s]).
            quiet_s: How long the graph must stay unchanged [s].
            timeout_s: Longest wait [s].
        """
        deadline = time.monotonic() + timeout_s
        last, since = self.snapshot(), time.monotonic()
        while (
            time.monotonic() - since < quiet_s or time.monotonic() < joined_s + DISCOVERY_S
        ) and time.monotonic() < deadline:
            time.sleep(0.05)  # graph updates arrive on the middleware's thread
            now = self.snapshot()
            if now != last:
                last, since = now, time.monotonic()

    def named_conflict(self, wait_s: float = NAME_WAIT_S) -> str:
        """:meth:`conflict`, waiting up to ``wait_s`` for the names of the nodes it is about."""
        deadline = time.monotonic() + wait_s
        reason = self.conflict()
        while UNNAMED in reason and time.monotonic() < deadline:
            time.sleep(0.02)  # names arrive on the middleware's thread
            reason = self.conflict()
        return reason

    def conflict(self) -> str:
        """The hold reason, or "" when this program is the arm's only commander and one console serves it."""
        try:
            consoles = self.consoles()
            others = self.others()
        except Exception:  # the graph is unavailable while the node shuts down: nothing to say
            return ""
        if len(consoles) > 1:
            return (
                f"another console: /{self.arm} is served by {len(consoles)} nodes ({', '.join(consoles)}); "
                "one console per arm (stop the other one, or give it another ROS_DOMAIN_ID)"
            )
        if others:
            named = "; ".join(f"{name} publishes {', '.join(topics)}" for name, topics in sorted(others.items()))
            return f"another commander: {named} (one commander per arm: stop it, then deploy again)"
        try:
            return self._source_conflict()
        except Exception:  # as above
            return ""
