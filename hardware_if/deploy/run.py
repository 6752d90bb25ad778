"""Deploying a policy through the control chain, to the simulation or to a dVRK over ROS 2.

The data flow is the simulation's: each policy step turns the 5-D action into a
:class:`~psm_control.commands.CartesianDelta`, gives it to :class:`safety.chain.ControlChain` once, then
ticks the chain at the control rate and sends each verified joint command to the backend. For
``target="sim"`` the backend is the task environment's (:func:`sim.evaluation.run_episode`); for
``target="dvrk"`` it is :class:`~hardware_if.client.psm_client.PsmClient` (the same chain, unchanged) and the
observation comes from :class:`~hardware_if.client.remote_task.RemoteTask`.

A dry run (``dry_run=True``, dVRK only) listens to the live arm and computes, logs and records every
command, but the client has no command publishers at all: nothing goes out on a motion topic. Its
report counts the commands it would have sent, the chain's safety interventions and the predicted
force (measured force plus the chain's conservative stiffness prior times how far the command would
pull the grasped tool from where it is).

One fault path, the same for the simulation, the dVRK and a dry run: a policy that raises (anything,
``SystemExit`` included) or returns something other than 5 finite numbers, a policy step slower than its
budget (default one policy period), malformed or non-finite data on any subscribed topic, an arm not
ENABLED, homed and idle when an episode starts (waited for up to ``wait_s``), a stale or vanished arm (a
``measured_js`` whose stamp stopped advancing, went back or jumped included), a tracking error (the
deadman, :mod:`hardware_if.client.deadman`), the chain's own deadman, another commander or console of the arm
(:mod:`hardware_if.common.commander_watch`, checked before anything reaches a console and while it runs), an arm
not at the episode's start in a dry run or after the move back, a tracking divergence
(:mod:`hardware_if.client.arm_pose`), a recording that cannot be written (:mod:`hardware_if.recording.checked_file`), or
any other error while the arm is commanded all end the same way: nothing new is commanded (the arm keeps
the last verified command), the fault is recorded as a ``hold`` event with its reason and data, the report
says ``HOLD: <reason>`` and the exit status is :data:`EXIT_HOLD`. SIGINT, SIGTERM and SIGHUP stop between
two control ticks, close the recording and exit with 128 + the signal number (130, 143, 129). A run in
which the force certainly exceeded the limit (the true force in the simulation; on a dVRK, the measured
force beyond the limit plus the sensing's error bound) and that neither held nor was stopped exits with
:data:`EXIT_FORCE_LIMIT`. Every run is recorded (:mod:`hardware_if.recording.recorder`).
"""

import contextlib
import signal
from typing import Any

from hardware_if.common.errors import HoldError
from hardware_if.deploy.dvrk_target import deploy_dvrk
from hardware_if.deploy.meta import recording_meta
from hardware_if.deploy.options import DeployOptions
from hardware_if.deploy.report import DeployReport, record_hold
from hardware_if.deploy.sim_target import deploy_sim
from hardware_if.deploy.stopping import Interrupted, Stopper
from hardware_if.recording.checked_file import RecordingError
from hardware_if.recording.recorder import Recorder
from psm_control.errors import ConfigurationError
from safety.config import SafetyConfig
from sim.evaluation import PolicyError
from sim.scene_stream import LiveScene

__all__ = ["deploy"]


def deploy(options: DeployOptions, *, echo: Any = print) -> DeployReport:
    """Run the deploy and record it; ``echo`` shows progress lines (default ``print``).

    A recording that cannot be written (at its start, during the run or at its end) is a hold like any other
    fault: ``recording failed: <path>: <os error>``, exit 4, recorded if the file still takes it.

    Raises:
        ConfigurationError: The policy or task cannot be set up (before the arm is commanded).
    """
    report = DeployReport(options.target, options.dry_run, options.record)
    report.force_limit_n = (options.safety_config or SafetyConfig()).effective_force_limit_n
    try:
        _deploy_recorded(options, report, echo)
    except RecordingError as e:  # at the recording's start or end; in between it is held where it happens
        if not report.fault:
            report.fault = str(e)
            report.holds += 1
    return report


def _deploy_recorded(options: DeployOptions, report: DeployReport, echo: Any) -> None:
    stopper = Stopper()
    live_view = contextlib.nullcontext() if options.live is None else LiveScene(port=options.live)
    with live_view as live, stopper.installed(), Recorder(options.record, mirror=live) as recorder:
        if live is not None:
            echo(f"live: ws://127.0.0.1:{live.port} (open it in the Foxglove app)")
        recorder.write("/deploy/meta", recording_meta(options))
        try:
            try:
                if options.target == "sim":
                    deploy_sim(options, report, recorder, echo, stopper)
                else:
                    deploy_dvrk(options, report, recorder, echo, stopper)
            except HoldError as e:
                record_hold(report, recorder, e)
            except PolicyError as e:
                # The episode runner wraps whatever the policy call raised; the checked policy's own
                # verdict (policy error, invalid action, overrun) is the hold, with its data.
                cause = e.__cause__
                record_hold(
                    report, recorder, cause if isinstance(cause, HoldError) else HoldError("policy error", str(e))
                )
            except (KeyboardInterrupt, ConfigurationError):
                raise
            except Exception as e:  # anything else while commanding is a hold too, never a traceback
                record_hold(report, recorder, HoldError("fault", f"{type(e).__name__}: {e}"))
        except KeyboardInterrupt as e:
            report.interrupted = True
            report.signal = signal.Signals(e.signum).name if isinstance(e, Interrupted) else "SIGINT"
            text = "Ctrl-C" if report.signal == "SIGINT" else report.signal
            recorder.write("/deploy/event", {"kind": "interrupted", "text": text, "signal": report.signal})
        except ConfigurationError as e:
            recorder.write("/deploy/event", {"kind": "error", "text": str(e)})
            recorder.write("/deploy/report", report.to_dict())
            raise
        recorder.write("/deploy/report", report.to_dict())
