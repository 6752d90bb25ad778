"""``tissue-retract demo``: scripted-expert episodes in the retraction simulation, and the kinematics check.

With no arguments it runs one episode of Task III (multi-site retraction) with the scripted expert and
prints a summary. ``--out demos.npz`` writes the successful episodes as demonstrations, ``--video
out.gif`` records the first episode from the endoscope camera. ``--kinematics`` instead prints the
tool-tip position about the RCM at named configurations from the Pinocchio model, with the largest
disagreement with a closed-form DH product and with PyBullet's link poses of the same URDF.

Demonstration file (``numpy.savez_compressed``), E successful episodes of T steps:
``observation`` (E, T+1, 18), ``achieved_goal`` / ``desired_goal`` (E, T+1, G), ``action`` (E, T, 5),
``reward`` (E, T), ``seed`` (E,), and ``metadata``: a JSON string with the task, Gymnasium id, seeds,
each episode's randomization values, the package version and this layout.
"""

from __future__ import annotations

import argparse

import numpy as np
from rich.console import Console
from rich.table import Table
from rich.text import Text

from psm_control.dh import dh_tool_pose
from psm_control.robot import PsmModel
from psm_control.spec import ARMS, TOOLS
from psm_control.urdf import TOOL_TIP_FRAME
from tissue_retract.cli._camera import add_texture_argument
from tissue_retract.cli._checks import MAX_EPISODES, int_in
from tissue_retract.cli._demos import run_episodes

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the subcommand to its parser."""
    parser.add_argument("--kinematics", action="store_true", help="print the kinematics cross-check instead")
    parser.add_argument("--arm", choices=ARMS, default="classic", help="PSM generation (default: classic)")
    parser.add_argument("--tool", choices=TOOLS, default=None, help="instrument (default: the arm's LND)")
    parser.add_argument("--task", default="multisite", help="lift, target, multisite, expose (default: multisite)")
    parser.add_argument("--episodes", type=int_in(1, MAX_EPISODES), default=1, help="episodes to run (default: 1)")
    parser.add_argument(
        "--seed", type=int_in(0, 2**31 - 1 - MAX_EPISODES), default=0, help="first episode seed (default: 0)"
    )
    parser.add_argument("--out", metavar="FILE", default=None, help="write successful episodes as .npz demos")
    parser.add_argument("--video", metavar="FILE", default=None, help="record the first episode (.gif or .mp4)")
    add_texture_argument(parser)


def _named_configurations(insertion: float) -> dict[str, np.ndarray]:
    return {
        "home": np.array([0.0, 0.0, insertion, 0.0, 0.0, 0.0]),
        "yaw +0.5": np.array([0.5, 0.0, insertion, 0.0, 0.0, 0.0]),
        "pitch -0.4": np.array([0.0, -0.4, insertion, 0.0, 0.0, 0.0]),
        "insertion 0.20": np.array([0.0, 0.0, 0.20, 0.0, 0.0, 0.0]),
        "wrist pitch +0.8": np.array([0.0, 0.0, insertion, 0.0, 0.8, 0.0]),
        "mixed": np.array([0.3, -0.2, 0.15, 1.0, 0.4, -0.6]),
    }


def run(args: argparse.Namespace) -> int:
    """Run expert episodes, or print the kinematics table with ``--kinematics``."""
    if args.kinematics:
        return run_kinematics(args)

    return run_episodes(args)


def run_kinematics(args: argparse.Namespace) -> int:
    """Print the kinematics table."""
    from sim.psm_body import PsmBody  # PyBullet: only for the cross-check
    from sim.quiet_pybullet import pybullet as p

    model = PsmModel.from_variant(args.arm, args.tool)
    configuration = model.configuration()
    client = p.connect(p.DIRECT)
    try:
        body = PsmBody(client, model)
        table = Table(title=f"{model.spec.name}: tool tip about the RCM (dVRK local/measured_cp)")
        for column in ("configuration", "x [mm]", "y [mm]", "z [mm]", "DH err [m]", "PyBullet err [m]", "cond(J) [-]"):
            # Text, not markup: rich would take "[mm]" for a style tag and drop it.
            table.add_column(Text(column), justify="right" if column != "configuration" else "left")
        worst = 0.0
        for name, q in _named_configurations(model.spec.rcm.cartesian_start_insertion_m).items():
            configuration.update(q)
            pose = configuration.local_pose()
            body.reset_joints(q)
            dh_error = float(np.abs(dh_tool_pose(model.spec, q) - pose).max())
            bullet_error = float(np.abs(body.link_pose(TOOL_TIP_FRAME) - pose).max())
            worst = max(worst, dh_error, bullet_error)
            x, y, z = pose[:3, 3] * 1000.0
            cond = np.linalg.cond(configuration.local_jacobian())
            table.add_row(
                name, f"{x:.3f}", f"{y:.3f}", f"{z:.3f}", f"{dh_error:.1e}", f"{bullet_error:.1e}", f"{cond:.1f}"
            )
    finally:
        p.disconnect(client)
    console = Console(width=110)
    console.print(table)
    console.print(f"largest disagreement between Pinocchio, closed-form DH and PyBullet: {worst:.2e} m")
    return 0 if worst < 1e-6 else 1
