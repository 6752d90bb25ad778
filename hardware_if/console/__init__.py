"""The simulated dVRK console (``tissue-retract sim-dvrk``): what a dVRK 2.4 console serves for one PSM.

:mod:`~hardware_if.console.sim_dvrk` serves the arm's CRTK topics and services, one console per arm
(:mod:`~hardware_if.console.console_guard`). Behind it an arm model moves
(:mod:`~hardware_if.console.arm_model`: the kinematic arm, or a task's PyBullet scene,
:mod:`~hardware_if.console.sim_task`) along the console's own trajectories and IK
(:mod:`~hardware_if.console.motion`), and the endoscope's images are rendered in a process of their own
(:mod:`~hardware_if.console.endoscope_stream`).

Imports: :mod:`hardware_if.common` only. Never the client nor the deploy: a console answers whoever commands
it, over ROS, and a client must drive a real dVRK as it drives this one.
"""
