"""``tissue-retract tissue-test``: the flap's material in a virtual materials lab.

Builds a W x W sheet of the flap's material (Young's modulus, thickness and density, or a literature
preset with ``--tissue``) as the simulation does, and runs two quasi-static tests in PyBullet:

* uniaxial tension: one edge clamped, the opposite edge pulled to ``--strain`` (default 10 %), against the
  closed form ``F = E t W eps``;
* picture-frame shear: the edges moved with a frame sheared by ``--strain``, against ``F = G t W gamma``
  with ``G = E / (2 (1 + nu))`` and the lattice's ``nu = 1/3``.

``--model fem`` runs them on PyBullet's Neo-Hookean tetrahedral plate of the same material instead of the
simulated mass-spring flap (a reference; tens of times slower). ``--lift`` adds the flap's lift test (back
and sides pinned, under gravity, the middle of the free edge raised 30 mm) on both models, side by side.
It prints measured against expected and, with ``--json FILE``, writes every test (force, strain, expected
force, the whole force-strain curve). ``--list`` prints the presets with their sources.
"""

from __future__ import annotations

import argparse

from psm_control.inputs import check_output_path
from sim.material import LATTICE_POISSON_RATIO, MODELS, PRESETS, preset
from sim.strict_json import write_strict_json
from sim.tissue_params import TissueParams
from tissue_retract.cli._checks import float_in, int_in

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the subcommand to its parser."""
    names = ", ".join(p.name for p in PRESETS)
    parser.add_argument("--tissue", metavar="PRESET", default=None, help=f"a literature preset: {names}")
    parser.add_argument(
        "--youngs-kpa", type=float_in(0.1, 10_000.0), default=None, help="Young's modulus, 0.1-10000 kPa (default 10)"
    )
    parser.add_argument(
        "--thickness-mm", type=float_in(0.1, 50.0), default=None, help="thickness, 0.1-50 mm (default 3)"
    )
    parser.add_argument(
        "--density", type=float_in(100.0, 3000.0), default=None, help="density, 100-3000 kg/m^3 (default 1050)"
    )
    parser.add_argument(
        "--size-mm", type=float_in(10.0, 500.0), default=80.0, help="sheet side, 10-500 mm (default 80)"
    )
    parser.add_argument(
        "--resolution", type=int_in(4, 21), default=TissueParams.resolution, help="nodes per side, 4-21 (default 7)"
    )
    parser.add_argument(
        "--strain", type=float_in(0.0, 0.5, open_low=True), default=0.10, help="final strain, (0, 0.5] (default 0.1)"
    )
    parser.add_argument("--model", choices=MODELS, default="spring", help="spring: the simulated flap (default); fem")
    parser.add_argument("--lift", action="store_true", help="also lift the pinned flap 30 mm, spring and FEM")
    parser.add_argument("--json", metavar="FILE", default=None, help="write the material and the tests as JSON")
    parser.add_argument("--list", action="store_true", help="list the presets with their sources and exit")


def _material(args: argparse.Namespace) -> TissueParams:
    """The sheet's settings: the preset's (or the flap's defaults), then any value given on the command line."""
    source = preset(args.tissue) if args.tissue else TissueParams()
    return TissueParams(
        size_m=args.size_mm / 1000.0,
        resolution=args.resolution,
        youngs_modulus_kpa=args.youngs_kpa or source.youngs_modulus_kpa,
        thickness_mm=args.thickness_mm or source.thickness_mm,
        density_kg_m3=args.density or source.density_kg_m3,
    )


def _list() -> int:
    for p in PRESETS:
        print(f"{p.name}: E {p.youngs_modulus_kpa:g} kPa, t {p.thickness_mm:g} mm, {p.density_kg_m3:g} kg/m^3")
        print(f"  {p.measurement}")
        print(f"  source: {p.source}")
    return 0


def run(args: argparse.Namespace) -> int:
    """Run both tests and print them; 0 (bad input is refused by the parser or with a ConfigurationError)."""
    if args.list:
        return _list()
    output = check_output_path(args.json, "--json") if args.json else None
    params = _material(args)
    # The tests run in PyBullet: loaded once the preset, the material and the output path are accepted.
    from sim.fem import FEM_POISSON_RATIO
    from sim.material_testing import lift, picture_frame_shear, uniaxial_tension

    model = next(m for m in MODELS if m == args.model)  # argparse's choices, typed
    print(
        f"material: E {params.youngs_modulus_kpa:g} kPa, t {params.thickness_mm:g} mm, "
        f"{params.density_kg_m3:g} kg/m^3; sheet {args.size_mm:g} x {args.size_mm:g} mm, "
        f"{params.resolution} x {params.resolution} nodes, spring {params.spring_stiffness_n_per_m:.4g} N/m, "
        f"{args.model} model",
        flush=True,
    )
    tests = {
        "uniaxial": uniaxial_tension(params, args.strain, model),
        "shear": picture_frame_shear(params, args.strain, model),
    }
    labels = {"uniaxial": ("uniaxial tension", "E t W eps"), "shear": ("picture-frame shear", "G t W gamma")}
    for name, test in tests.items():
        label, form = labels[name]
        print(
            f"{label} to {100 * test.strain:g} %: {test.force_n:.5g} N measured, {test.expected_force_n:.5g} N "
            f"closed form {form} ({100 * test.relative_error:+.1f} %)",
            flush=True,
        )
    lifts = {model: lift(params, model=model) for model in MODELS} if args.lift else {}
    if lifts:
        print("lift [mm]  spring [N]  fem [N]  fem/spring")
        for (height, spring), (_, fem) in zip(lifts["spring"], lifts["fem"], strict=True):
            ratio = f"{fem / spring:.2f}" if spring > 0 else "-"
            print(f"{1000 * height:9.0f}  {spring:10.4f}  {fem:7.4f}  {ratio:>10}")
    if output is not None:
        document = {
            "material": {
                "youngs_modulus_kpa": params.youngs_modulus_kpa,
                "thickness_mm": params.thickness_mm,
                "density_kg_m3": params.density_kg_m3,
                "size_mm": args.size_mm,
                "resolution": params.resolution,
                "spring_stiffness_n_per_m": params.spring_stiffness_n_per_m,
                "poisson_ratio": LATTICE_POISSON_RATIO if args.model == "spring" else FEM_POISSON_RATIO,
                "preset": args.tissue,
            },
            "model": args.model,
            **{name: test.to_dict() for name, test in tests.items()},
        }
        if lifts:
            document["lift"] = {model: [list(point) for point in curve] for model, curve in lifts.items()}
        write_strict_json(output, document, field="--json")
        print(f"written to {output}")
    return 0
