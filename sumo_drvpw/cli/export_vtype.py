"""``sumo-drvpw export-vtype EQ --vehicle NAME --id ID --out FILE.add.xml``: an equation as
a vType for SUMO's own Energy model (where its parameters come from: a calibration); an
equation whose chain is SUMO's MMPEVEM motor as an MMPEVEM vType (sim/export.py)."""

from __future__ import annotations

import argparse


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("equation", metavar="EQ", help="equation TOML file or built-in name")
    parser.add_argument("--vehicle", metavar="NAME_OR_FILE",
                        help="vehicle file or built-in name: mass and frontal area")
    parser.add_argument("--mass", type=float, metavar="KG",
                        help="vehicle mass [kg] (instead of the vehicle file's)")
    parser.add_argument("--id", required=True, metavar="ID", help="vType id to write")
    parser.add_argument("--vclass", metavar="VCLASS",
                        help="SUMO vClass of the vType (default: the equation's first vClass when it is "
                             "made for other vehicles than cars, else SUMO's default, passenger)")
    parser.add_argument("--air-temperature", type=float, metavar="C",
                        help="air temperature [°C] of the runs: a battery chain's HVAC power at it joins "
                             "constantPowerIntake (SUMO's Energy model has no temperature)")
    parser.add_argument("--out", required=True, metavar="FILE.add.xml",
                        help="additional file to write")


def main(args: argparse.Namespace) -> int:
    from sumo_drvpw.errors import UserError
    from sumo_drvpw.fileio import write_text
    from sumo_drvpw.model.constants import MASS_MAX_KG
    from sumo_drvpw.model.equations import load_equation
    from sumo_drvpw.sim.export import energy_vtype_xml

    from pathlib import Path

    from sumo_drvpw.fileio import check_output_path

    check_output_path(args.out, [p for p in (args.equation, args.vehicle) if p and Path(p).exists()],
                      kind="file")
    bad = [c for c in args.id if c.isspace() or c in "<>&\"|;,'\\"]
    if not args.id or bad:  # SUMO 1.28 refuses a vType id with these ("invalid characters")
        raise UserError(f"--id {args.id!r}: a vType id is a non-empty name without spaces or "
                        f"the characters < > & \" | ; , ' \\ (SUMO refuses them)"
                        + (f"; it holds {bad[0]!r}" if bad else ""))
    if args.vclass is not None:
        from sumo_drvpw.model.equations import check_vclass

        check_vclass(args.vclass, "export-vtype", "--vclass")
    eq = load_equation(args.equation)
    mass, area = args.mass, None
    if mass is not None and not 0 < mass <= MASS_MAX_KG:
        raise UserError(f"--mass {mass:g}: a vehicle's mass in kg, > 0 and at most {MASS_MAX_KG:g}")
    if args.vehicle:
        from sumo_drvpw.model.vehicles import load_vehicle

        v = load_vehicle(args.vehicle)
        mass = mass if mass is not None else v.mass_kg
        area = v.body.get("frontal_area_m2")
    if mass is not None and not 0 < mass < float("inf"):
        raise UserError(f"--mass must be a finite number > 0 [kg], got {mass}")
    if mass is None and eq.mass_kg is None:
        raise UserError(f"equation '{eq.name}' has no fixed mass: give the vehicle (--vehicle NAME_OR_FILE, "
                        "whose mass_kg it takes) or its mass (--mass KG)")
    from sumo_drvpw.cli import check_air_temperature

    check_air_temperature(args.air_temperature)
    from sumo_drvpw.model.equations import DEFAULT_VCLASSES

    vclass = args.vclass
    if vclass is None and eq.vclasses and not set(eq.vclasses) & set(DEFAULT_VCLASSES):
        vclass = eq.vclasses[0]  # a truck's equation: not a passenger car in SUMO's lanes and outputs
    xml, missing = energy_vtype_xml(eq, args.id, mass, area, vclass, args.air_temperature, out=args.out)
    write_text(args.out, xml)
    model = ("MMPEVEM", "MMPEVEM") if getattr(eq.chain, "motor", None) is not None else ("Energy/unknown", "Energy model")
    print(f"wrote vType '{args.id}' ({model[0]}) from equation '{eq.name}' to {args.out}"
          + (f" (vClass {vclass}, the equation's{'' if len(eq.vclasses) == 1 else ' first'}; --vclass "
             "chooses another)" if vclass is not None and args.vclass is None else ""))
    for m in missing:
        print(f"  not expressible in SUMO's {model[1]}: {m}")
    for w in (getattr(eq.chain, "provenance", None) or {}).get("warnings", []):  # as compare and run say
        print(f"warning: {eq.name}: its chain's calibration warned: {w}")
    return 0
