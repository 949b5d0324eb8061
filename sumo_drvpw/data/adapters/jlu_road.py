"""Adapter for the JLU on-road trips of the same BEV as ``jlu-dyno`` (``jlu-road``).

Source: ``../shared/data/jlu_bev_road/`` (same repository and licence as the dynamometer
tests): one Parquet file per trip, 20 Hz; the dynamometer columns plus ``tempAmb`` [°C],
``elevation`` [m, GPS, whole metres], ``lat``/``long`` [°], ``gear`` (drive state) and the
cumulative counters ``tot_disc``/``tot_char``. ``Time`` is a wall-clock text timestamp
(→ ``clock_s``); ``PhaseTime`` is the time base.

Mapping (beyond :mod:`jlu_dyno`'s): tempAmb → ``ambient_c`` (so the reader derives ρ from
it at standard pressure), elevation → ``elevation_m`` (grade from elevation smoothed over
distance), lat/long → ``latitude_deg``/``longitude_deg``, gear kept; the BMS's cumulative
energy counters tot_disc, tot_char [kWh] → ``battery_discharge_energy_j``,
``battery_charge_energy_j`` (roles: response — they identify the trip, they are no physical
effect; the battery target of a trip without V·I, :mod:`sumo_drvpw.data.counters`). The
all-zero DAScheduleSpeed, REESSCurrent2 and REESSVoltage2 are left out. ``mass_kg`` = the
test mass of jlu_bev.toml (1919 kg, as on the dynamometer; the driver is not added).
"""

from __future__ import annotations

from sumo_drvpw.data.adapters.jlu_dyno import ROLES, SUFFIXES, VEHICLE, read_file  # noqa: F401

FORMAT = "jlu-road"


def read(paths):
    """Read JLU road trips (files or folders of .parquet)."""
    from sumo_drvpw.model.vehicles import load_vehicle
    from sumo_drvpw.data.adapters._common import expand_paths, read_each

    vehicle = load_vehicle(VEHICLE)
    frames, reports = read_each(expand_paths(paths, SUFFIXES, "JLU road Parquet"),
                                lambda f: read_file(f, vehicle, road=True))
    return frames, reports, [f"vehicle file {vehicle.path}",
                             "grade from elevation_m (whole metres, GPS) smoothed over distance by the reader"]
