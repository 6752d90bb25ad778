"""The dVRK's force sensing calibrated: the joint logs it is fitted on, the fit, and the calibration file.

:mod:`~hardware_if.wrench.joint_logs` reads the free-space joint logs dVRK users keep (rosbag2 bags, the
public CSV layouts, this project's recordings); :mod:`~hardware_if.wrench.fit` fits a calibration of the
arm's own efforts on them and checks it on others; :mod:`~hardware_if.wrench.calibration` is the calibration
and its file, which the client applies to the console's joint efforts.

Imports: :mod:`hardware_if.common` and :mod:`hardware_if.recording` (a deploy's recording is a joint log
too). It drives no arm: ``calibrate-wrench`` moves the arm through the client and hands the log here.
"""
