"""Settings of the residual tracer (:func:`sumo_drvpw.fit.diagnose.diagnose`)."""

from __future__ import annotations

from dataclasses import dataclass

from sumo_drvpw.errors import UserError

#: Columns from which the spec derives measured power: never offered as effects.
POWER_SOURCE_COLUMNS = ("power_w", "motor_torque_nm", "motor_speed_rpm", "mg1_speed_rpm",
                        "mg1_torque_nm", "mg2_speed_rpm", "mg2_torque_nm", "ice_speed_rpm",
                        "battery_voltage_v", "battery_current_a", "battery_discharge_energy_j",
                        "battery_charge_energy_j")
#: of those, cumulative counters: no power component, so no column is screened as "the same
#: quantity" as them (across trips they follow the trip, as anything constant per trip does)
CUMULATIVE_SOURCE_COLUMNS = ("battery_discharge_energy_j", "battery_charge_energy_j")
#: Metrics copied into the report (from :func:`sumo_drvpw.fit.compare.metrics`).
METRIC_KEYS = ("rmse_w", "mae_w", "r2", "r2_light", "r2_heavy", "bias_w")


@dataclass
class DiagnoseOptions:
    """Settings of the tracer (see :mod:`sumo_drvpw.fit.diagnose` for their meaning).

    Library messages name the option (``block_s``), never a command-line flag.
    """

    validation: str = "auto"      # auto | trip | blocks
    block_s: float = 60.0         # block length [s]
    folds: int = 5
    alpha: float = 0.05
    min_gain: float = 0.01        # minimum relative held-out RMSE gain
    max_findings: int = 5
    include: tuple = ()           # glob patterns of columns to offer (empty: all)
    exclude: tuple = ()           # glob patterns of columns never to offer
    max_nan: float = 0.05
    proxy_corr: float = 0.9
    derived_r2: float = 0.99
    per_trip: bool = True
    min_speed_mps: float = 0.1    # samples below this speed are left out [m/s]
    max_trips_per_trip_effects: int = 400
    batch: int = 16
    responses: bool = False       # also offer columns whose role is 'response'
    structural: bool = True       # offer structural effects (lag, regimes, air density, grade)
    max_lag_s: float = 3.0        # largest power–speed lag searched [s]

    def check(self):
        """Raise :class:`UserError` naming the first setting out of range."""
        check_validation(self)
        if not 0 <= self.min_gain < 1:
            raise UserError(f"diagnose option min_gain must be in [0, 1), got {self.min_gain}")
        if self.max_findings < 0:
            raise UserError(f"diagnose option max_findings must be ≥ 0, got {self.max_findings}")
        if not 0 <= self.max_nan <= 1:
            raise UserError(f"diagnose option max_nan must be in [0, 1], got {self.max_nan}")
        if not 0 <= self.max_lag_s <= 30:
            raise UserError(f"diagnose option max_lag_s must be in [0, 30] s, got {self.max_lag_s}")
        if not 0 <= self.min_speed_mps <= 50:
            raise UserError(f"diagnose option min_speed_mps must be in [0, 50] m/s, got {self.min_speed_mps}")


def check_validation(opt) -> None:
    """Raise :class:`UserError` naming the first held-out setting out of range (validation,
    block_s, folds, alpha), for the tracer's and the chain trace's options alike."""
    if opt.validation not in ("auto", "trip", "blocks"):
        raise UserError(f"diagnose option validation must be auto, trip or blocks, "
                        f"got '{opt.validation}'")
    if not opt.block_s > 0:
        raise UserError(f"diagnose option block_s must be > 0 s, got {opt.block_s}")
    if not 2 <= opt.folds <= 1000:
        raise UserError(f"diagnose option folds must be from 2 to 1000, got {opt.folds}")
    if not 0 < opt.alpha < 1:
        raise UserError(f"diagnose option alpha must be between 0 and 1, got {opt.alpha}")
    if not 0 < getattr(opt, "proxy_corr", 0.9) <= 1:
        raise UserError(f"diagnose option proxy_corr must be in (0, 1], got {opt.proxy_corr}")


#: trips a finding must replicate on (lower the held-out error on more than half of them)
#: before replication is tested; with fewer, the held-out block test is the only one
MIN_REPLICATION_TRIPS = 3


def stop_reason(tried: list, n_trips: int, m: int, opt) -> str:
    """Why a search round added nothing, for its stop line and trace: the candidates tried
    (``tried``: (name, test failed, value), best held-out gain first; tests ``significance``
    with the Bonferroni p over ``m`` candidates, ``gain`` with the held-out RMSE gain, or
    ``rejected`` with the replication or plausibility reason) grouped by the test they failed
    and, with fewer than :data:`MIN_REPLICATION_TRIPS` trips, that replication on held-out
    trips could not be tested."""
    parts = []
    sig = [(t, v) for t, k, v in tried if k == "significance"]
    if sig:
        parts.append(f"not significant in the held-out block test (Bonferroni over {m} candidates, "
                     f"α = {opt.alpha:g}): " + ", ".join(f"{t} p = {v:.3g}" for t, v in sig))
    parts += [f"{t} {v}" for t, k, v in tried if k == "rejected"]
    low = [(t, v) for t, k, v in tried if k == "gain"]
    if low:
        parts.append(f"below the minimum gain {100 * opt.min_gain:g} %: "
                     + ", ".join(f"{t} {100 * v:.2f} %" for t, v in low))
    why = "; ".join(parts) or "no candidate was tried"
    if n_trips < MIN_REPLICATION_TRIPS:
        why += (f"; replication on held-out trips not tested ({n_trips} trip(s), it needs "
                f"{MIN_REPLICATION_TRIPS})")
    return why
