"""``tissue-retract demo``: the PSM's kinematics at named configurations, cross-checked three ways.

For each configuration it prints the tool-tip position about the RCM from the Pinocchio model, and the
largest disagreement with an independent closed-form DH product and with PyBullet's link poses of
the same URDF: numbers a user can check against the dVRK's own ``local/measured_cp``.
"""

from __future__ import annotations

import argparse

import numpy as np

from psm_control.spec import ARMS, TOOLS

__all__ = ["add_parser", "run"]


def add_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the subcommand."""
    parser = subparsers.add_parser(
        "demo",
        help="show the PSM's forward kinematics, cross-checked against DH and PyBullet",
        description=__doc__,
    )
    parser.add_argument("--arm", choices=ARMS, default="classic", help="PSM generation (default: classic)")
    parser.add_argument("--tool", choices=TOOLS, default=None, help="instrument (default: the arm's LND)")
    parser.set_defaults(func=run)


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
    """Print the kinematics table."""
    import pybullet as p
    from rich.console import Console
    from rich.table import Table

    from psm_control.dh import dh_tool_pose
    from psm_control.robot import PsmModel
    from psm_control.urdf import TOOL_TIP_FRAME
    from sim.psm_body import PsmBody

    model = PsmModel.from_variant(args.arm, args.tool)
    configuration = model.configuration()
    client = p.connect(p.DIRECT)
    try:
        body = PsmBody(client, model)
        table = Table(title=f"{model.spec.name}: tool tip about the RCM (dVRK local/measured_cp)")
        for column in ("configuration", "x [mm]", "y [mm]", "z [mm]", "DH err [m]", "PyBullet err [m]", "cond(J)"):
            table.add_column(column, justify="right" if column != "configuration" else "left")
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
