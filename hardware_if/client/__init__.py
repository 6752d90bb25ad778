"""What drives a dVRK over ROS 2, real or simulated, and what it knows of the task.

:mod:`~hardware_if.client.psm_client` commands one arm, every motion command guarded by the deadman
(:mod:`~hardware_if.client.deadman`); :mod:`~hardware_if.client.readiness` says what a deploy waits for and
:mod:`~hardware_if.client.arm_pose` checks that the arm is at the episode's start and follows its commands.
The task, as a robot without the simulation's truth knows it: a site registered by touch and the jaw
(:mod:`~hardware_if.client.registration`, :mod:`~hardware_if.client.registration_checks`,
:mod:`~hardware_if.client.task_estimate`), the endoscope's images (:mod:`~hardware_if.client.camera_site`) or
the simulated console's task topics (:mod:`~hardware_if.client.remote_task`); and the same estimators around a
simulated task (:mod:`~hardware_if.client.registered_env`, :mod:`~hardware_if.client.perceived_env`).

Imports: :mod:`hardware_if.common` and :mod:`hardware_if.wrench` (the force calibration the client applies).
Never the console: a client meets a console only on ROS topics, so it drives a real dVRK as it drives the
simulated one. Nor the recording, which is read without an arm, nor the deploy, which is built on the client.
"""
