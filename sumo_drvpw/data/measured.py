"""Glue shared by calibrate, compare, the tracer and the validation report.

``load_measured`` reads logs, picks the vehicle, computes the measured driving power
and the term-basis inputs, and the mask of samples usable for fitting; everything that
compares a model with a log goes through it, so they all see the same samples.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd

from sumo_drvpw.model.equations import SPEC_EQUATIONS, Equation, load_equation
from sumo_drvpw.errors import UserError
from sumo_drvpw.data.log import DriveLog, ReadOptions, read_log
from sumo_drvpw.data.powertrain import measured_power
from sumo_drvpw.model.constants import STANDSTILL_MPS
from sumo_drvpw.model.terms import Inputs
from sumo_drvpw.model.vehicles import Vehicle, load_vehicle


@dataclass
class Measured:
    """A log with its measured power [W], model inputs and the usable-sample mask."""

    log: DriveLog
    vehicle: Vehicle | None
    power_w: np.ndarray
    source: str
    inputs: Inputs
    usable: np.ndarray
    #: what ``power_w`` measures: wheel (driving power), battery (V·I) or fuel (ṁ·LHV)
    target: str = "wheel"
    #: for the fuel target: the hybrid battery's V·I [W] when logged (SOC correction), else None
    battery_w: np.ndarray | None = None
    #: measurement corrections applied (model.measurement.Measurement; None: the log as read)
    measurement: object | None = None
    #: battery target read with ``sign_check=False``: the sums of the sign test
    #: (:func:`sign_sums`), for the caller to merge over batches and test (:func:`check_sign_sums`)
    sign_test: tuple | None = None
    #: a battery target read from the BMS's energy counters: their view of the log
    #: (:class:`~sumo_drvpw.data.counters.CounterView`), through which a fit sees its model's
    #: power as the counters book it; None for V·I and other targets
    counter_view: object | None = None

    @property
    def counts(self) -> dict:
        c = dict(self.log.counts)
        c["power_source"] = self.source
        c["target"] = self.target
        c["excluded_nonfinite_power"] = int((~np.isfinite(self.power_w)).sum())
        c["usable"] = int(self.usable.sum())
        c.update(held_rows(self.inputs.v, self.power_w, self.inputs.trip, self.usable))
        if self.measurement is not None and not self.measurement.identity:
            c["measurement"] = self.measurement.to_dict()
        return c

    def context(self) -> dict:
        return {"logs": self.log.files, "vehicle": self.vehicle.name if self.vehicle else None,
                "power_source": self.source, "samples": len(self.log), "usable": int(self.usable.sum()),
                "counts": self.counts}


def held_rows(v, p, trip, use) -> dict:
    """``moving_rows`` (usable, moving, after a usable row of the same trip) and ``held_moving_rows``: those whose speed and
    measured power both equal the row's before in the trip — values a logger holds between
    its updates (an OBD log at 11 rows/s of values new about once a second: 90 %), which a
    fit counts as independent samples."""
    v, p, use = np.asarray(v, float), np.asarray(p, float), np.asarray(use, bool)
    if v.size < 2:
        return {"moving_rows": 0, "held_moving_rows": 0}
    same_trip = np.ones(v.size - 1, bool) if trip is None else (np.asarray(trip)[1:] == np.asarray(trip)[:-1])
    mov = use[1:] & use[:-1] & (v[1:] > STANDSTILL_MPS) & same_trip  # (pairs within a trip: a batch's too)
    held = mov & (v[1:] == v[:-1]) & (p[1:] == p[:-1])
    return {"moving_rows": int(mov.sum()), "held_moving_rows": int(held.sum())}


#: what a measured power can be (``load_measured(target=...)``)
TARGETS = ("wheel", "battery", "fuel")


def load_measured(paths, vehicle: str | None = None, options: ReadOptions | None = None,
                  target: str = "wheel") -> Measured:
    """Read logs and compute measured power and inputs (see module docstring).

    ``target``: ``wheel`` (default) the measured driving power; ``battery`` the battery's
    V·I; ``fuel`` the fuel power ṁ·LHV (with the hybrid battery's V·I in ``battery_w``).
    Measurement corrections (power lag, grade source, air density) come with ``options``
    (``ReadOptions.measurement``; :mod:`sumo_drvpw.data.corrections`).
    """
    if target not in TARGETS:
        raise UserError(f"target must be one of {', '.join(TARGETS)}, got {target!r}")
    veh = load_vehicle(vehicle) if vehicle else None
    m = measure(read_log(paths, veh, options), veh, target)
    if not m.usable.any():
        from sumo_drvpw.data.log import exclusions

        raise UserError(f"{m.log.describe()}: no usable sample among {len(m.log)} rows (excluded: "
                        f"{exclusions(m.log.counts)}; any other row lacks a finite measured power or input)")
    return m


def measure(log: DriveLog, veh: Vehicle | None, target: str = "wheel",
            sign_check: bool = True, lazy_signals: bool = False) -> Measured:
    """Measured power, inputs and usable mask of a read log (the streaming reader calls
    this per batch of whole trips, so it sees the same samples as :func:`load_measured`),
    with the measurement corrections of its reading options applied
    (``log.options.measurement``; None: the log as read).

    ``sign_check``: test a battery target's sign here (:func:`check_battery_sign`); False
    (a batch of a streamed log, whose test is on all batches): its sums are returned in
    ``Measured.sign_test`` instead. ``lazy_signals``: the inputs' extra columns are read
    from the table when asked for (:class:`ColumnSignals`), not copied: a caller keeps the
    arrays it needs with :func:`keep_arrays`."""
    from sumo_drvpw.data.counters import COUNTERS
    from sumo_drvpw.data.powertrain import battery_power_and_view, measured_battery_power, measured_fuel_power

    if target not in TARGETS:
        raise UserError(f"target must be one of {', '.join(TARGETS)}, got {target!r}")

    battery_w = view = None
    if target == "battery":
        p, source, view = battery_power_and_view(log, veh)  # its rows per source: power_rows
    elif target == "fuel":
        p, source = measured_fuel_power(log, veh)
        if all(c in log.df for c in ("battery_voltage_v", "battery_current_a")) \
                or all(c in log.df for c in COUNTERS):
            battery_w = np.nan_to_num(measured_battery_power(log, veh)[0], nan=0.0)
    else:
        p, source = measured_power(log, veh)
    x = log.inputs(veh.mass_kg if veh else None, signals=not lazy_signals)
    if lazy_signals:
        df = log.df
        x = dataclasses.replace(x, signals=ColumnSignals(df, [c for c in log.extra_columns if _numeric(df[c])]))
    usable = ~log.excluded & np.isfinite(p)
    for arr in (x.v, x.a, x.theta, x.wind, x.mass, x.rho):
        usable &= np.isfinite(arr)
    sign_test = None
    if target == "battery":  # V·I's sign (the counters name what they count: no sign to test)
        signed = usable if view is None else usable & ~view.rows
        if sign_check:
            check_battery_sign(log, x, p, signed, source)
        else:
            sign_test = sign_sums(x, p, signed)
    if target == "battery" and not _has_engine(log, veh):
        # energy into the battery while the car stands is a charger, not driving
        from sumo_drvpw.data.charging import charging_mask
        from sumo_drvpw.data.trips import trip_codes_of

        chg = charging_mask(p, x.v, log.df["time_s"].to_numpy(float), trip_codes_of(log.df["trip_id"]))
        log.counts["excluded_charging"] = int((chg & usable).sum())
        usable &= ~chg
    if target in ("battery", "wheel"):  # standing while the power drives: the speed dropped out
        from sumo_drvpw.data.charging import speed_dropout_mask
        from sumo_drvpw.data.trips import trip_codes_of

        lost = speed_dropout_mask(p, x.v, trip_codes_of(log.df["trip_id"]), log.df["time_s"].to_numpy(float))
        if lost.any():
            log.counts["excluded_speed_dropout"] = int((lost & usable).sum())
        usable &= ~lost
    measurement = log.options.measurement
    if measurement is not None and not measurement.identity:
        from sumo_drvpw.data.corrections import apply_measurement

        p, x, usable = apply_measurement(log, x, p, usable, measurement)
        if battery_w is not None and measurement.power_lag_s:
            from sumo_drvpw.data.corrections import median_dt, shift_within_trips
            from sumo_drvpw.data.trips import trip_codes_of

            codes = trip_codes_of(log.df["trip_id"])
            lag = int(round(measurement.power_lag_s / median_dt(log.df["time_s"].to_numpy(float), codes)))
            battery_w = np.nan_to_num(shift_within_trips(battery_w, codes, lag), nan=0.0)
    if target in ("battery", "wheel"):  # does the power carry braking? (cli.note_counts says)
        log.counts.update(braking_counts(x, p, usable))
    return Measured(log, veh, p, source, x, usable, target, battery_w, measurement, sign_test, view)


#: inertial and grade power m·v·(a + g·sin θ) [W] below which a sample brakes hard enough
#: that a powertrain able to recuperate shows negative power
BRAKING_PROXY_W = -10000.0
#: measured power [W] below which a braking sample recuperates
RECUPERATING_W = -1000.0
#: share of braking samples that recuperate below which a log records traction only
TRACTION_ONLY_SHARE = 0.02
#: braking samples a log needs for that verdict: a signed power recuperates in most of them
#: (a LeafSpy log's battery V·I in 17 of 25, 17-s samples; its never-negative motor power
#: in 0 of 17), so none of ten is no chance
TRACTION_ONLY_MIN_BRAKING = 10


def braking_counts(x: Inputs, p, usable) -> dict:
    """Mergeable counts (batches add): usable samples braking hard (``braking_samples``:
    m·v·(a + g·sin θ) < :data:`BRAKING_PROXY_W`) and those of them whose measured power
    ``p`` recuperates (``braking_recuperating``: < :data:`RECUPERATING_W`). Nearly none
    recuperating: the power logs traction only (a motor power or engine estimate clipped at
    0), which no linear driving-power equation fits and which leaves a battery chain no
    recuperation."""
    d, y = _sign_proxy(x), np.asarray(p, float)
    brake = np.asarray(usable, bool) & (d < BRAKING_PROXY_W) & np.isfinite(y)
    return {"braking_samples": int(brake.sum()), "braking_recuperating": int((brake & (y < RECUPERATING_W)).sum())}


def _numeric(col: pd.Series) -> bool:
    return pd.api.types.is_bool_dtype(col) or pd.api.types.is_numeric_dtype(col)


class ColumnSignals(Mapping):
    """The numeric extra columns of a log's table as float arrays (NaN where missing), as
    :meth:`~sumo_drvpw.data.log.DriveLog.inputs` gives them, each made when it is read and
    not kept (``measure(lazy_signals=True)``)."""

    def __init__(self, df: pd.DataFrame, names: list[str]):
        self._df, self._names = df, list(names)

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self._names:
            raise KeyError(name)
        return self._df[name].to_numpy(float, na_value=np.nan)

    def __iter__(self):
        return iter(self._names)

    def __len__(self) -> int:
        return len(self._names)

    def __contains__(self, name) -> bool:
        return name in self._names


def load_measured_pair(paths, vehicle: str | None, options: ReadOptions | None,
                       target: str) -> tuple[Measured, Measured | UserError]:
    """A battery or fuel target and the measured driving power of the same logs, read once.

    Returns (the ``target``'s :class:`Measured`, as :func:`load_measured` gives it, and the
    driving power's — or the UserError measuring it raised, for the caller to raise or pass
    over). Both share the one table (their counts are their own, as if each had read the
    logs) and read its extra columns lazily (:class:`ColumnSignals`): keep what a fit needs
    with :func:`keep_arrays`, and the table goes when neither refers to it.
    """
    if target not in TARGETS:
        raise UserError(f"target must be one of {', '.join(TARGETS)}, got {target!r}")
    veh = load_vehicle(vehicle) if vehicle else None
    log = read_log(paths, veh, options)
    wlog = dataclasses.replace(log, counts=dict(log.counts))
    m = _usable_or_refuse(measure(log, veh, target, lazy_signals=True))
    try:
        mw: Measured | UserError = _usable_or_refuse(measure(wlog, veh, lazy_signals=True))
    except UserError as e:
        mw = e
    return m, mw


def _usable_or_refuse(m: Measured) -> Measured:
    if not m.usable.any():
        from sumo_drvpw.data.log import exclusions

        raise UserError(f"{m.log.describe()}: no usable sample among {len(m.log)} rows (excluded: "
                        f"{exclusions(m.log.counts)}; any other row lacks a finite measured power or input)")
    return m


def _own(a):
    """``a`` holding no more memory than its own: a view into a bigger array (a column of a
    table's block of columns) is copied, so the rest can go; an array that is all of its base
    (a column that is a block of its own) and a broadcast constant (stride 0) stay as they
    are; None stays None."""
    if a is None:
        return None
    a = np.asarray(a)
    base = a
    while isinstance(base.base, np.ndarray):
        base = base.base
    if base is a or (a.ndim == 1 and a.strides[0] == 0) or base.nbytes <= a.nbytes:
        return a
    return a.copy()


def with_signals(m: Measured, signals) -> Measured:
    """``m`` whose inputs carry only the extra columns ``signals`` that it has, as arrays
    (the table kept): what a fit of terms that read those columns needs, without making
    every extra column again for each block it takes (:meth:`ColumnSignals.__getitem__`)."""
    sig = {c: np.asarray(m.inputs.signals[c], float) for c in signals if c in m.inputs.signals}
    return dataclasses.replace(m, inputs=dataclasses.replace(m.inputs, signals=sig))


def keep_arrays(m: Measured, signals=()) -> Measured:
    """The arrays of a :class:`Measured` a fit needs, without its table: the model inputs
    (with only the extra columns ``signals`` that it has, as arrays), measured power,
    hybrid battery power, usable mask, and of the table the time weights ``dt_s`` alone;
    counts, files and options stay. Values are unchanged (copies, not recomputations)."""
    x = m.inputs
    sig = {c: _own(np.asarray(x.signals[c], float)) for c in signals if c in x.signals}
    x = dataclasses.replace(x, v=_own(x.v), a=_own(x.a), theta=_own(x.theta), wind=_own(x.wind),
                            mass=_own(x.mass), rho=_own(x.rho), signals=sig, trip=_own(x.trip))
    log = dataclasses.replace(m.log, df=pd.DataFrame({"dt_s": _own(m.log.df["dt_s"].to_numpy(float))}),
                              excluded=None, deriv=None)
    return dataclasses.replace(m, log=log, power_w=_own(m.power_w), inputs=x, usable=_own(m.usable),
                               battery_w=_own(m.battery_w))


#: inertial and grade power [W] beyond which a sample tests the battery current's sign
SIGN_TEST_W = 5000.0


def check_battery_sign(log: DriveLog, x: Inputs, p_battery, usable, source: str) -> None:
    """UserError when the measured battery power falls where the car speeds up or climbs:
    the current's sign flipped (every command that reads a battery target: compare and
    diagnose booked +200…+400 % per trip with exit 0, and took driving for charging).
    Tested on the samples whose inertial and grade power m·v·(a + g·sin θ) exceeds
    ±``SIGN_TEST_W``, with ≥ 50 of them; on the shared logs r is 0.88–0.98 for the
    electric cars and 0.36 for the Prius Gen-2's small hybrid battery."""
    refuse_falling_battery(log.describe(), source, _sign_proxy(x), p_battery, usable, SIGN_TEST_W,
                           _SIGN_RISES)


_SIGN_RISES = "the inertial and grade power m·v·(a + g·sin θ)"


def _sign_proxy(x: Inputs) -> np.ndarray:
    from sumo_drvpw.model.constants import G

    return np.asarray(x.mass * x.v * (x.a + G * np.sin(x.theta)), float)


def sign_sums(x: Inputs, p_battery, usable) -> tuple:
    """The sign test of :func:`check_battery_sign` as mergeable sums over its samples:
    (n, mean of the proxy, mean of the battery power, centred Σd², Σy², Σdy)."""
    d, y = _sign_proxy(x), np.asarray(p_battery, float)
    ok = np.asarray(usable, bool) & np.isfinite(d) & np.isfinite(y) & (np.abs(d) > SIGN_TEST_W)
    d, y = d[ok], y[ok]
    if not len(d):
        return (0, 0.0, 0.0, 0.0, 0.0, 0.0)
    md, my = float(d.mean()), float(y.mean())
    d, y = d - md, y - my
    return (len(d), md, my, float(d @ d), float(y @ y), float(d @ y))


def merge_sign_sums(a: tuple | None, b: tuple | None) -> tuple | None:
    """The sums of :func:`sign_sums` of two batches (Chan et al. 1979 pairwise update)."""
    if a is None or not a[0]:
        return b
    if b is None or not b[0]:
        return a
    na, nb = a[0], b[0]
    n = na + nb
    dd, dy = b[1] - a[1], b[2] - a[2]
    f = na * nb / n
    return (n, a[1] + dd * nb / n, a[2] + dy * nb / n, a[3] + b[3] + dd * dd * f,
            a[4] + b[4] + dy * dy * f, a[5] + b[5] + dd * dy * f)


def check_sign_sums(where: str, source: str, sums: tuple | None) -> None:
    """:func:`check_battery_sign` on the merged sums of every batch (:func:`sign_sums`):
    the same rule, on all samples of a streamed log."""
    if sums is None:
        return
    n, _, _, sdd, syy, sdy = sums
    if n < 50 or sdd <= 0.0 or syy <= 0.0:
        return
    r = sdy / float(np.sqrt(sdd * syy))
    if r < 0:
        raise UserError(_falling(where, source, r, n, SIGN_TEST_W, _SIGN_RISES))


def refuse_falling_battery(where: str, source: str, drive, p_battery, mask, threshold_w: float,
                           rises: str) -> None:
    """UserError when the battery power ``p_battery`` correlates negatively with the power
    ``drive`` on the samples of ``mask`` where |drive| > ``threshold_w`` (≥ 50 of them):
    a current whose sign is flipped."""
    d, y = np.asarray(drive, float), np.asarray(p_battery, float)
    ok = np.asarray(mask, bool) & np.isfinite(d) & np.isfinite(y) & (np.abs(d) > threshold_w)
    if ok.sum() < 50 or np.std(y[ok]) == 0 or np.std(d[ok]) == 0:
        return
    r = float(np.corrcoef(d[ok], y[ok])[0, 1])
    if r < 0:
        raise UserError(_falling(where, source, r, int(ok.sum()), threshold_w, rises))


def _falling(where: str, source: str, r: float, n: int, threshold_w: float, rises: str) -> str:
    return (f"{where}: the measured battery power ({source}) falls where {rises} rises (correlation "
            f"r = {r:.2f} over {n} samples beyond ±{threshold_w / 1000:g} kW): is the "
            "current's sign flipped? The vehicle file's [battery] current_positive says which sign "
            "discharges (\"discharge\" or \"charge\"); for a log written by the column import, "
            "its mapping's scale = -1 on battery_current_a turns the sign at the import")


def _has_engine(log: DriveLog, veh: Vehicle | None) -> bool:
    """Whether an engine may charge the battery at standstill: a power-split vehicle, or a
    log with fuel flow (then energy into the battery at standstill is no charger's)."""
    from sumo_drvpw.data.powertrain import fuel_column

    return (veh is not None and veh.powertrain_type == "power_split") or fuel_column(log.df, getattr(log, "logged", None)) is not None


def resolve_equations(specs, vehicle: Vehicle | None = None, predicting: bool = True) -> list[Equation]:
    """Equations by name or file; ``vsp_spec`` means VSP from the vehicle's body specs,
    ``roadload_spec`` the vehicle's published road load A + B·v + C·v²
    (:data:`sumo_drvpw.model.equations.SPEC_EQUATIONS`). ``predicting`` false: the road load
    under a chain to calibrate, whose own ``[chain]`` may declare only what the fit keeps."""
    out = []
    for s in specs:
        if s in SPEC_EQUATIONS:
            if vehicle is None:
                raise UserError(f"equation {s} needs a vehicle: it is built from the vehicle file")
            out.append(SPEC_EQUATIONS[s](vehicle))
        else:
            out.append(load_equation(s))
            if predicting and out[-1].chain is not None:  # (a fuel chain without its engine: a declaration)
                out[-1].chain.require_complete()
    names = [e.name for e in out]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        given = [str(s) for s, n in zip(specs, names) if n == dup[0]]
        if len(set(given)) == 1:
            raise UserError(f"equations: {given[0]} given twice")
        raise UserError(f"equations: {' and '.join(given)} are both named '{dup[0]}' (the [equation] "
                        "name, else the file's stem), given twice: results are keyed by name, so give "
                        "each its own [equation] name")
    return out
