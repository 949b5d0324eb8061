"""Measurement corrections as data: how a log was corrected before an equation was fitted.

An equation that goes into SUMO describes the vehicle, not the logger (issue #11 §3): a lag
between the power and the speed signal, a grade attenuated by coarse or smoothed
elevation, air density at sea-level pressure where the car drove at altitude, a speedometer
that reads a few per cent high — these are
corrected in the data, not absorbed by coefficients. The corrections a calibration used
are part of the equation, as its ``[measurement]`` table, so that every later comparison
on new logs reads them the same way (in SUMO, inputs are clean: the table is not used
there)::

    [measurement]
    power_lag_s = -1.4     # the power signal's lag behind the speed signal [s]; the power
                           # is read that much later (diagnose's "timing" finding)
    grade = "fused"        # "logged" (elevation), "fused" (accelerometer above the
                           # crossover, logged grade below it) or "accelerometer" (alone,
                           # its per-trip offset fixed by the elevation)
    fusion_tau_s = 60      # crossover of the fusion in time [s] (default 60); its slow part
                           # weights standing samples too, so the grade's integral can drift
                           # from the elevation by tens of metres on long trips
    # fusion_distance_m = 1000  # or a crossover over driven distance [m]: the fused grade
                           # keeps each trip's logged elevation change
    # accelerometer_offset_mps2 = 0.004  (only with grade = "accelerometer"): the logger's
                           # own offset (its mounting pitch) [m/s²], one constant for every
                           # trip, instead of a per-trip offset fixed by each trip's elevation
    air_density = "altitude"  # "logged" or "altitude": pressure of the standard
                           # atmosphere at the logged elevation when pressure is not logged
    exclude_dropouts = true  # leave out logger dropouts: speed and a longitudinal
                           # accelerometer held or linearly filled for seconds
                           # (sumo_drvpw.data.dropouts; inputs only)
    speed_scale = "gps"    # the logged speed times a scale before anything is derived from
                           # it (acceleration, distance, grade from elevation): "gps", each
                           # trip's Σ GPS speed / Σ speed over its steady samples above
                           # 8 m/s, or a number (0.984: a speedometer 1.6 % high); a log
                           # with two GPS speeds that disagree names one: "gps:gps_speed_mps"

The correction itself (signal processing on a log) is :mod:`sumo_drvpw.data.corrections`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from sumo_drvpw.errors import UserError

#: where the grade comes from
GRADE_SOURCES = ("logged", "fused", "accelerometer")
#: where the air density comes from
AIR_DENSITY_SOURCES = ("logged", "altitude")
#: default crossover of the grade fusion [s] (in time): well above the ~10 s that 100 m of elevation
#: smoothing spans at town speeds, well below a trip (an accelerometer's mounting pitch
#: biases its slow part)
FUSION_TAU_S = 60.0
#: a crossover of the grade fusion over driven distance [m] (``fused:1000m``; not the
#: default): well above the ~100 m over which logged elevation is smoothed (a whole-metre
#: step in 1000 m is 0.06° of grade), well below a trip. On the shared i3 logs it keeps every
#: trip's elevation change, but raises the free grade coefficient to 1.12–1.26
#: (docs/closing-the-loop.md), so the fusion in time stays the default
FUSION_DISTANCE_M = 1000.0
#: longest lag a correction may declare [s] (a lag of minutes is no signal timing)
MAX_LAG_S = 60.0
#: largest accelerometer offset a correction may declare [m/s²]: g·sin 10°, a logger
#: mounted 10° off level (more is a wrong axis or unit, not a mounting pitch)
MAX_ACC_OFFSET_MPS2 = 1.7
#: a speed scale measured against the GPS speed logged beside the speed (``speed_scale = "gps"``)
SPEED_SCALE_GPS = "gps"
#: the farthest a declared speed scale may be from 1: a speedometer or wheel-speed signal is off
#: by a few per cent (tyre wear and pressure, a manufacturer's margin); 20 % is a unit or a wrong
#: column, not a reading error
MAX_SPEED_SCALE_OFF = 0.2


@dataclass(frozen=True)
class Measurement:
    """Corrections applied to a log before a model sees it (see the module docstring).

    The default is no correction: the log as read.
    """

    power_lag_s: float = 0.0
    grade: str = "logged"
    #: with grade "fused": the crossover in time [s] (None: FUSION_TAU_S, unless
    #: fusion_distance_m is given)
    fusion_tau_s: float | None = None
    air_density: str = "logged"
    exclude_dropouts: bool = False
    #: with grade "accelerometer": the logger's fixed offset [m/s²] (None: one offset per
    #: trip, fixed by the trip's elevation change)
    accelerometer_offset_mps2: float | None = None
    #: with grade "fused": the crossover over driven distance [m] instead (None: in time)
    fusion_distance_m: float | None = None
    #: the logged speed's scale: a number k (v' = k·v), "gps" (k per trip against the GPS
    #: speed logged beside it; "gps:COLUMN" against that one of several), None (as read).
    #: Never used in SUMO, whose speeds are exact
    speed_scale: float | str | None = None

    def __post_init__(self):
        if self.fusion_tau_s is not None and self.fusion_distance_m is not None:
            raise UserError("[measurement]: give fusion_tau_s or fusion_distance_m, not both")

    @property
    def fusion_seconds(self) -> float:
        """The fusion's crossover in time [s] (when it is not over distance)."""
        return FUSION_TAU_S if self.fusion_tau_s is None else float(self.fusion_tau_s)

    @property
    def fusion_text(self) -> str:
        """The crossover as a reader says it: "60 s" or "1000 m"."""
        return f"{self.fusion_distance_m:g} m" if self.fusion_distance_m is not None else f"{self.fusion_seconds:g} s"

    @property
    def identity(self) -> bool:
        """True when nothing is corrected."""
        return (self.power_lag_s == 0.0 and self.grade == "logged" and self.air_density == "logged"
                and not self.exclude_dropouts and self.speed_scale in (None, 1.0))

    def to_dict(self) -> dict:
        """The ``[measurement]`` table (every key that has a value, so the file says what was
        done; TOML has no null, so an unset accelerometer offset is left out; a fused grade
        names its crossover, in time or over distance)."""
        doc = {k: v for k, v in asdict(self).items() if v is not None}
        if self.grade == "fused" and self.fusion_distance_m is None:
            doc["fusion_tau_s"] = self.fusion_seconds
        return doc

    def describe(self) -> str:
        """One line for reports."""
        if self.identity:
            return "none (the log as read)"
        parts = []
        if self.power_lag_s:
            parts.append(f"power re-timed by {self.power_lag_s:+g} s (the power signal's lag behind speed)")
        if self.grade == "fused":
            parts.append(f"grade fused: accelerometer above {self.fusion_text}, logged grade below"
                         + ("" if self.fusion_distance_m is None else " (over driven distance: the grade keeps "
                            "each trip's logged elevation change)"))
        elif self.grade == "accelerometer" and self.accelerometer_offset_mps2 is not None:
            parts.append(f"grade from the accelerometer, less the logger's fixed offset of "
                         f"{self.accelerometer_offset_mps2:+.4g} m/s² (no logged elevation used)")
        elif self.grade == "accelerometer":
            parts.append("grade from the accelerometer, its per-trip offset fixed by the elevation")
        if self.air_density == "altitude":
            parts.append("air density at the logged altitude (standard atmosphere)")
        if self.exclude_dropouts:
            parts.append("logger dropouts (speed and accelerometer held or linearly filled) left out")
        if isinstance(self.speed_scale, str):
            col = gps_scale_column(self.speed_scale)
            parts.append("speed scaled per trip to the GPS speed logged beside it (" + (f"{col}; " if col else "")
                         + "Σ GPS speed / Σ speed over steady samples above 8 m/s)")
        elif self.speed_scale not in (None, 1.0):
            parts.append(f"speed × {self.speed_scale:.4g} (declared: a speed reading "
                         f"{abs(1 / self.speed_scale - 1):.1%} {'high' if self.speed_scale < 1 else 'low'})")
        return "; ".join(parts)


def measurement_from_dict(doc, where: str) -> Measurement:
    """A :class:`Measurement` from a ``[measurement]`` table; errors name ``where`` and the key."""
    if not isinstance(doc, dict):
        raise UserError(f"{where} [measurement]: must be a table")
    known = ("power_lag_s", "grade", "fusion_tau_s", "fusion_distance_m", "air_density", "exclude_dropouts",
             "accelerometer_offset_mps2", "speed_scale")
    bad = sorted(set(doc) - set(known))
    if bad:
        raise UserError(f"{where} [measurement]: unknown key {bad[0]!r} (known: {', '.join(known)})")
    kw = {}
    for key in ("power_lag_s", "fusion_tau_s", "fusion_distance_m", "accelerometer_offset_mps2"):
        if key in doc:
            v = doc[key]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise UserError(f"{where} [measurement] {key}: must be a finite number, got {v!r}")
            kw[key] = float(v)
    if abs(kw.get("power_lag_s", 0.0)) > MAX_LAG_S:
        raise UserError(f"{where} [measurement] power_lag_s: {kw['power_lag_s']:g} s is beyond "
                        f"±{MAX_LAG_S:g} s (a lag of minutes is no signal timing)")
    for key, most in (("fusion_tau_s", 86400.0), ("fusion_distance_m", 1e6)):  # a day, 1000 km
        if key in kw and not 0 < kw[key] <= most:
            raise UserError(f"{where} [measurement] {key}: must be > 0 and at most {most:g}, got {kw[key]:g}")
    if "fusion_tau_s" in kw and "fusion_distance_m" in kw:
        raise UserError(f"{where} [measurement] fusion_distance_m: give it or fusion_tau_s, not both "
                        "(a crossover over distance or in time)")
    for key, allowed in (("grade", GRADE_SOURCES), ("air_density", AIR_DENSITY_SOURCES)):
        if key in doc:
            if doc[key] not in allowed:
                raise UserError(f"{where} [measurement] {key}: must be one of {', '.join(allowed)}, "
                                f"got {doc[key]!r}")
            kw[key] = str(doc[key])
    if "exclude_dropouts" in doc:
        if not isinstance(doc["exclude_dropouts"], bool):
            raise UserError(f"{where} [measurement] exclude_dropouts: must be true or false, "
                            f"got {doc['exclude_dropouts']!r}")
        kw["exclude_dropouts"] = doc["exclude_dropouts"]
    if "accelerometer_offset_mps2" in kw:
        if kw.get("grade") != "accelerometer":
            raise UserError(f"{where} [measurement] accelerometer_offset_mps2: only with grade = "
                            f"\"accelerometer\" (got grade {kw.get('grade', 'logged')!r})")
        if abs(kw["accelerometer_offset_mps2"]) > MAX_ACC_OFFSET_MPS2:
            raise UserError(f"{where} [measurement] accelerometer_offset_mps2: "
                            f"{kw['accelerometer_offset_mps2']:g} m/s² is beyond ±{MAX_ACC_OFFSET_MPS2:g} "
                            "(a mounting pitch of more than 10°)")
    if "speed_scale" in doc:
        kw["speed_scale"] = speed_scale_value(doc["speed_scale"], f"{where} [measurement] speed_scale")
    return Measurement(**kw)


#: the settings that go with the grade source: a grade given anew brings its own (or none)
GRADE_KEYS = ("grade", "fusion_tau_s", "fusion_distance_m", "accelerometer_offset_mps2")


def override_measurement(base: Measurement | None, doc: dict, where: str) -> Measurement:
    """``base`` with the settings of ``doc`` (a partial ``[measurement]`` table) put over it,
    every other setting of ``base`` kept; a grade in ``doc`` brings its own crossover and offset
    (:data:`GRADE_KEYS`: those of ``base`` go with its grade). Errors name ``where``.

    >>> override_measurement(Measurement(power_lag_s=-1.4, air_density="altitude"),
    ...                      {"speed_scale": 0.98}, "x").power_lag_s
    -1.4
    """
    kept = {} if base is None else base.to_dict()
    if "grade" in doc:
        kept = {k: v for k, v in kept.items() if k not in GRADE_KEYS}
    return measurement_from_dict({**kept, **doc}, where)


def gps_scale_column(scale) -> str | None:
    """The GPS speed column a speed scale ``"gps:COLUMN"`` names (None: any other scale)."""
    if isinstance(scale, str) and scale.startswith(SPEED_SCALE_GPS + ":"):
        return scale[len(SPEED_SCALE_GPS) + 1:]
    return None


def speed_scale_value(v, where: str) -> float | str:
    """A speed scale as declared: "gps", "gps:COLUMN" (a GPS speed column ``gps_speed…_mps``),
    or a finite number within ±:data:`MAX_SPEED_SCALE_OFF` of 1; errors name ``where`` and the value."""
    if v == SPEED_SCALE_GPS:
        return SPEED_SCALE_GPS
    col = gps_scale_column(v)
    if col is not None:
        if not (col.startswith("gps_speed") and col.endswith("_mps")):
            raise UserError(f"{where}: {v!r} names no GPS speed column after 'gps:' (gps_speed…_mps, e.g. "
                            "\"gps:gps_speed_mps\")")
        return v
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise UserError(f"{where}: must be \"gps\" or a finite number (the factor on the logged speed), or "
                        f"\"gps:COLUMN\" naming the GPS speed column, got {v!r}")
    if abs(float(v) - 1.0) > MAX_SPEED_SCALE_OFF:
        raise UserError(f"{where}: {float(v):g} is more than {MAX_SPEED_SCALE_OFF:.0%} from 1 (a speedometer is off "
                        "by a few per cent; more is a unit or a wrong column)")
    return float(v)
