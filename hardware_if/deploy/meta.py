"""What a deploy's recording says about the run (``/deploy/meta``): its settings and the force sensing it used.

The settings are :class:`~hardware_if.deploy.options.DeployOptions`'s, except the sensing's, which are gathered
in one ``sensing`` object that names what the chain's force really came from:

- ``force_sensing``: the simulation's ``--force-sensing`` preset (``ideal``, ``dvrk``, ``dvrk-calibrated``);
  on a dVRK ``dvrk`` (the console's ``measured_cf``) or ``dvrk-calibrated`` (the joint efforts through a
  calibration file);
- ``force_sensing_error_n``: the error bound the safety filter was given [N] (0: exact);
- ``source``: the same in words, as the run-start warning says it;
- ``wrench_calibration``: with a calibration, the file's resolved ``path`` and ``sha256`` as it was read, its
  bounds ``error_bound_n`` and ``error_bound_with_acceleration_n`` [N] and the rest of the fit; else null.

A recording from before this object has none: ``replay`` says the sensing was not recorded.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from hardware_if.deploy.options import DeployOptions
from safety.config import SafetyConfig
from sim.force_sensing import error_bound_n, sensing_params

__all__ = ["SENSING_KEY", "recording_meta", "sensing_meta"]

#: The meta's key of the sensing object.
SENSING_KEY = "sensing"
#: Options the sensing object holds instead.
_SENSING_OPTIONS = (
    "force_sensing",
    "force_sensing_error_n",
    "force_sensing_source",
    "wrench_calibration",
    "wrench_calibration_path",
    "wrench_calibration_sha256",
)


def sensing_meta(options: DeployOptions) -> dict[str, Any]:
    """The force sensing a deploy with these options uses, and the error bound its safety filter is given."""
    if options.target == "sim":
        # What the task environment gives its chain (sim.envs.base.use_force_sensing).
        config = options.safety_config or SafetyConfig()
        name = options.force_sensing
        error_n = error_bound_n(sensing_params(name), config)
        source = f"{name} force sensing (simulated)"
    else:
        name = (
            "force-sensor"
            if options.force_sensor
            else "dvrk"
            if options.wrench_calibration is None
            else "dvrk-calibrated"
        )
        given = options.force_sensing_error_n  # what deploy_dvrk gives the chain
        error_n = error_bound_n(sensing_params("dvrk")) if given is None else given
        source = options.force_sensing_source
    calibration = None
    if options.wrench_calibration is not None:
        calibration = {
            "path": None if options.wrench_calibration_path is None else str(options.wrench_calibration_path),
            "sha256": options.wrench_calibration_sha256,
            **dataclasses.asdict(options.wrench_calibration),
        }
    return {
        "force_sensing": name,
        "force_sensing_error_n": float(error_n),
        "source": source,
        "wrench_calibration": calibration,
    }


def recording_meta(options: DeployOptions) -> dict[str, Any]:
    """The ``/deploy/meta`` message: the options (paths as text) but the sensing's, and the sensing."""
    meta = {
        k: (str(v) if isinstance(v, Path) else v)
        for k, v in dataclasses.asdict(options).items()
        if k not in _SENSING_OPTIONS
    }
    meta[SENSING_KEY] = sensing_meta(options)
    return meta
