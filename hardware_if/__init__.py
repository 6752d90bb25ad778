"""The dVRK over ROS 2 (CRTK topics). Needs the ``ros`` extra; nothing outside this package imports rclpy.

Its modules live in rooms by role, each a sub-package that imports only itself and the rooms its docstring
names (``tests/test_layers.py`` checks it), bottom to top:

- :mod:`hardware_if.common`: what the simulated console and the client share (CRTK names, message
  conversions, ROS sessions, the graph's view of who commands an arm, errors);
- :mod:`hardware_if.console`: the simulated dVRK console (``sim-dvrk``) and the arm models behind it;
- :mod:`hardware_if.recording`: a run's MCAP recording, read back, summarised and plotted (``replay``);
- :mod:`hardware_if.wrench`: the force-sensing calibration and the joint logs it is fitted on;
- :mod:`hardware_if.client`: what drives a dVRK, real or simulated, and what it knows of the task;
- :mod:`hardware_if.deploy`: a policy deployed through the control chain, to the simulation or a dVRK.

The console and the client never import each other: they meet only on ROS topics, so the client drives a
real dVRK as it drives the simulated one. The modules at this level (``psm_client``, ``sim_dvrk``,
``wrench_calibration``) are the paths these had before the rooms, kept for user scripts; the project
imports from the rooms.
"""
