"""`calibrate --target battery --fix NAME=VALUE`: a chain's parameters held at known values
(fit/chain_fixed.py), in memory and streamed alike."""

from __future__ import annotations

from sumo_drvpw.errors import UserError

HELP = ("battery chain: hold a parameter at a known value, the rest fitted (repeat): traction_efficiency, "
        "recuperation_efficiency (in (0, 1]), aux_power_w (W), recuperation_limit_w (W, not profiled), "
        "loads.COLUMN (the gain of a --load), hvac.heating_w_per_k, hvac.cooling_w_per_k (with --hvac); "
        "e.g. a dynamometer's efficiencies under a road calibration, or a logger's known auxiliary draw")


def add_fix_argument(g) -> None:
    g.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE", help=HELP)


def fix_option(args, hvac) -> dict:
    """``--fix`` as name → value, refused in one line naming the option and the value: not
    NAME=VALUE, a name the chain fitted here has not (what it has listed), a value out of its
    bounds, a name given twice, or with a target whose fit holds nothing."""
    given = list(getattr(args, "fix", None) or [])
    if not given:
        return {}
    if args.target != "battery":
        raise UserError(f"--fix {given[0]}: " + (
            "the fuel chain's fit holds no parameter at a given value (its engine-off threshold: --engine-off W; "
            "its rated output: the --equation file's [chain] engine_max_w)" if args.target == "fuel" else
            "goes with --target battery (a battery chain's parameters)"))
    from sumo_drvpw.fit.chain_fixed import check_fixed

    names = [] if getattr(args, "efficiency", "constant") != "constant" else [
        "traction_efficiency", "recuperation_efficiency"]
    names += ["aux_power_w", *(f"loads.{c}" for c in args.load)]
    names += ["hvac.heating_w_per_k", "hvac.cooling_w_per_k"] if hvac else []
    out = {}
    for raw in given:
        name, eq, val = str(raw).partition("=")
        name = name.strip()
        if not eq or not name or not val.strip():
            raise UserError(f"--fix {raw}: give NAME=VALUE, e.g. aux_power_w=300")
        if name in out:
            raise UserError(f"--fix {raw}: {name} is already fixed (--fix {name}={out[name]:g})")
        if name in ("traction_efficiency", "recuperation_efficiency") and "traction_efficiency" not in names:
            raise UserError(f"--fix {raw}: --efficiency {args.efficiency} fits the efficiencies as tables; "
                            "a constant one is held with --efficiency constant")
        out.update(check_fixed({name: val.strip()}, names, where=f"--fix {raw}"))
    return out
