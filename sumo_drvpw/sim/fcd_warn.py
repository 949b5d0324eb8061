"""What an FCD replay warns of about the file itself: vehicle rows on lanes the network
lacks, no angles for an equation with radial drag, a recording of part of the run (a share
of the vehicles, part of the network), person rows that cannot be matched to vehicles,
vehicle rows without x, y (parking told only by the route files' stops), route or
additional files the recording names that are gone (their vTypes unknown)."""

from __future__ import annotations

from pathlib import Path

from sumo_drvpw.errors import UserError


def missing_input_warnings(fcd_file, scenario=None, vtype_files=None) -> tuple[list[str], list[str]]:
    """Where a replay takes its vTypes from the files of the run that recorded ``fcd_file``
    (no ``scenario``, no ``vtype_files``: :func:`sumo_drvpw.sim.fcd_read.run_inputs`, its
    header's, else those of the SUMO config that writes it): a warning for the route and
    additional files named there and found nowhere — the vTypes defined there are unknown,
    their vehicles booked as passenger cars, SUMO's default vClass, at a car's mass — and
    those files as written ([], [] when none is missing or the files are given)."""
    if scenario is not None or vtype_files is not None:
        return [], []
    from sumo_drvpw.sim.fcd_read import run_inputs

    rec = run_inputs(fcd_file) or {"missing": []}
    gone = [v for k, v in rec["missing"] if k != "net-file"]  # (no network: refused before)
    if not gone:
        return [], []
    src = f"the SUMO config {rec['config'].name} that writes the FCD" if "config" in rec else "the FCD's header"
    return ([f"{src} names {', '.join(gone)}, not found beside the FCD {fcd_file} (looked in "
             f"{', '.join(str(p) for p in rec['looked_in'])}): the vTypes defined there are unknown, their "
             "vehicles booked as passenger cars (SUMO's default vClass) at a car's mass; give the run's route and "
             "additional files for its vTypes"], gone)


def unplaced_person_warning(fcd_file, rows: int) -> str:
    """What a replay whose person rows carry no x, y (or whose vehicle rows do not) says:
    riders are matched by place and speed (sim/fcd_conn)."""
    return (f"FCD file {fcd_file}: {rows} person rows without x, y (fcd-output.attributes without them): "
            "riding persons cannot be matched to their vehicles, whose riders' mass is not booked")


def unplaced_vehicle_warning(fcd_file, rows: int, told: int, stops_read: bool) -> str:
    """What a replay whose vehicle rows carry no x, y (``rows`` of them) says: SUMO's FCD
    shows a parked vehicle beside its lane, and without x, y only the route files' parking
    stops tell it (``told`` rows; ``stops_read``: the files declare any stop)."""
    how = (f"only where one stands at a parking stop the route files declare (parking=\"true\", a parkingArea, a "
           f"stop waiting for a person or container; {told} rows told so)" if stops_read
           else "nowhere: no route file declares a stop")
    return (f"FCD file {fcd_file}: {rows} vehicle rows without x, y (fcd-output.attributes without them): a "
            f"parked vehicle is told {how}; one parked elsewhere (at a stop added while the run ran) is booked "
            "standing there, with its auxiliary power and idle fuel, where the live run books it parked")


def partial_warnings(fcd_file, head: dict | None) -> list[str]:
    """What an FCD that records only part of the run says (its header's options): a share of
    the vehicles (``device.fcd.probability`` < 1), or of the network (``fcd-output.filter-edges
    .input-file``, ``fcd-output.filter-shapes``): the totals are that part's."""
    head = head or {}
    out = []
    try:
        share = float(head.get("device.fcd.probability", 1.0))
    except ValueError:
        share = 1.0
    if share < 1.0:
        out.append(f"FCD file {fcd_file} records a share of the vehicles (device.fcd.probability {share:g}): "
                   "the totals are those vehicles', not the run's")
    where = [k for k in ("fcd-output.filter-edges.input-file", "fcd-output.filter-shapes") if head.get(k)]
    if where:
        out.append(f"FCD file {fcd_file} records part of the network ({', '.join(f'{k} {head[k]}' for k in where)}): "
                   "the vehicles are booked there only")
    return out


def no_angle_warning(fcd_file) -> str:
    """What a replay of an FCD without angles, for an equation with the factor ``radial``, says."""
    return (f"FCD file {fcd_file} has no angle column (fcd-output.attributes without angle): the radial "
            "drag in curves (the factor radial, SUMO's radialDragCoefficient) is booked as 0")


def lane_warnings(fcd_file, net_file, unknown: int, known: int, first) -> list[str]:
    """What a replay's vehicle rows on lanes the network lacks (``unknown`` of them;
    ``known`` on its lanes; ``first``: the first one's (lane, time)) call for: a UserError
    when none is on one of its lanes (the FCD of another network), else a warning (the
    rows are not booked, as the live loop books no vehicle without a lane)."""
    if not unknown:
        return []
    lane, t = first
    if not known:
        raise UserError(f"FCD {fcd_file}: none of its vehicles' lanes is in the network "
                        f"{net_file} (the first: lane {lane!r} at t = {t:g} s): recorded on "
                        "another network?")
    return [f"{unknown} FCD row{'s' if unknown > 1 else ''} of vehicles on lanes the network {Path(net_file).name} lacks "
            f"{'were' if unknown > 1 else 'was'} not booked (the first: lane {lane!r} at t = {t:g} s); recorded on another "
            "version of the network?"]
