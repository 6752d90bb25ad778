"""What the simulated console and the client share: the CRTK interface, message conversions, ROS sessions.

Both sides of the interface speak through these: :mod:`~hardware_if.common.crtk` (topic names, QoS, frames,
tolerances), :mod:`~hardware_if.common.task_topics` (the simulated scene's task topics and the endoscope's),
:mod:`~hardware_if.common.convert` (ROS messages to arrays and poses), and
:mod:`~hardware_if.common.commander_watch` (the ROS graph's view of who commands or serves an arm: a client
refuses a second commander, a console warns of one and refuses to be a second console). Beside them: the
errors, the loopback-only network settings, the executor and session every node spins in, and the short
garbage-collector pauses of the real-time processes.

Imports: no other room of :mod:`hardware_if`. A piece the console and the client both need belongs here, so
that neither imports the other.
"""
