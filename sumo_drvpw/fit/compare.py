"""Compare driving-power equations with a log's measured power (paper Table 3, Fig. 4–10).

Everything here is SI: power in W, energy in J, speed in m/s. Speed bins are labelled in
km/h because the paper bins that way; the edges themselves are also given in m/s.

Conventions
-----------
* error = predicted − measured [W] per sample: a negative error is underprediction.
* R² is the ordinary, centred coefficient of determination of the prediction against
  the measurement, R² = 1 − Σ(p − m)² / Σ(m − m̄)². It is *not* the uncentred,
  no-intercept R² that statsmodels reports for a regression without constant; it is
  what a reader of the paper's Table 3 compares equations by, and it can be negative
  for a prediction worse than the mean.
* Light load: measured power < 50 kW (``constants.HEAVY_LOAD_W``); heavy load: ≥ 50 kW.
  Each subset's R² uses that subset's own mean (Table 3 reports them this way).
* A subset metric is NaN (JSON null) when the subset has fewer than 3 samples.

References
----------
Pitanuwat, S. et al., "Development of Hybrid-Vehicle Energy-Consumption Model for
Transportation Applications — Part I": Table 3 (R² by load), Fig. 4 (parity), Fig. 5
(error histograms), Fig. 8 (error against speed, ≥ 80 km/h), Fig. 9 (error against the
power of each term), Fig. 10 (energy share of each term).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sumo_drvpw.model.constants import HEAVY_LOAD_W, HIGH_SPEED_MPS, KMH
from sumo_drvpw.model.equations import Equation
from sumo_drvpw.errors import UserError, first_bad_row
from sumo_drvpw.fileio import plain
from sumo_drvpw.fit.ols import dense_gram
# energy per trip lives in fit/trip_energy.py; imported here, where other modules find it
from sumo_drvpw.fit.trip_energy import (_dt_array, fuel_mismatch_note, trip_energy, trip_net_energy,
                                         with_fuel_volumes, with_left_out)
from sumo_drvpw.model.terms import CATEGORIES, Inputs

#: Width of the speed bins of Fig. 8 [m/s] (10 km/h).
SPEED_BIN_MPS = 10.0 * KMH
#: Fewest samples for which a subset statistic (R², correlation) is reported.
MIN_SAMPLES = 3


# ----------------------------------------------------------------------------- metrics

def _r2(pred: np.ndarray, meas: np.ndarray) -> float:
    """Centred R² = 1 − SSE/SST; NaN with < MIN_SAMPLES samples or a constant measurement."""
    if len(meas) < MIN_SAMPLES:
        return math.nan
    sst = float(np.sum((meas - meas.mean()) ** 2))
    if sst <= 0.0:
        return math.nan
    return 1.0 - float(np.sum((pred - meas) ** 2)) / sst


def _r2_corr(pred: np.ndarray, meas: np.ndarray) -> float:
    """Squared Pearson correlation of pred and meas; NaN as for :func:`_r2`."""
    if len(meas) < MIN_SAMPLES:
        return math.nan
    pc, mc = pred - pred.mean(), meas - meas.mean()
    with np.errstate(over="ignore", invalid="ignore"):  # absurd predictions: NaN, not an OverflowError
        den = np.float64(pc @ pc) * np.float64(mc @ mc)
        r2 = np.float64(pc @ mc) ** 2 / den if den > 0.0 else math.nan
    return float(r2) if np.isfinite(r2) else math.nan


def _rmse(err: np.ndarray) -> float:
    return float(np.sqrt(np.mean(err * err))) if len(err) else math.nan


def metrics(pred_w, meas_w) -> dict:
    """Goodness of fit of predicted against measured driving power (paper Table 3).

    Parameters
    ----------
    pred_w : predicted driving power per sample [W]
    meas_w : measured driving power per sample [W]

    Returns
    -------
    dict with ``n`` (finite pairs used), ``r2`` (centred, 1 − SSE/SST), ``r2_light`` and
    ``r2_heavy`` (measured < / ≥ 50 kW, each on its own mean), ``rmse_w``, ``mae_w``,
    ``bias_w`` = mean(pred − meas) [W], ``rmse_light_w``, ``rmse_heavy_w``,
    ``bias_light_w``, ``bias_heavy_w`` [W], ``n_light``, ``n_heavy``, and
    ``r2_corr``/``r2_corr_light``/``r2_corr_heavy``: the squared Pearson correlation
    (the R² of regressing measured on predicted with intercept, blind to bias and
    scale), for matching published values whose R² definition is unstated. Pairs with a NaN
    or infinite value are left out. R² needs ≥ 3 samples and a non-constant
    measurement, else it is NaN; the other subset statistics are NaN for an empty subset.
    """
    pred = np.asarray(pred_w, dtype=float).ravel()
    meas = np.asarray(meas_w, dtype=float).ravel()
    if pred.shape != meas.shape:
        raise UserError(f"metrics: predicted power has {pred.size} samples, measured "
                        f"power {meas.size}")
    ok = np.isfinite(pred) & np.isfinite(meas)
    if not ok.all():
        pred, meas = pred[ok], meas[ok]
    err = pred - meas
    heavy = meas >= HEAVY_LOAD_W
    light = ~heavy
    out = {
        "n": int(meas.size),
        "r2": _r2(pred, meas),
        "r2_light": _r2(pred[light], meas[light]),
        "r2_heavy": _r2(pred[heavy], meas[heavy]),
        "rmse_w": _rmse(err),
        "mae_w": float(np.mean(np.abs(err))) if err.size else math.nan,
        "bias_w": float(np.mean(err)) if err.size else math.nan,
        "n_light": int(light.sum()),
        "n_heavy": int(heavy.sum()),
        "rmse_light_w": _rmse(err[light]),
        "rmse_heavy_w": _rmse(err[heavy]),
        "bias_light_w": float(np.mean(err[light])) if light.any() else math.nan,
        "bias_heavy_w": float(np.mean(err[heavy])) if heavy.any() else math.nan,
        "r2_corr": _r2_corr(pred, meas),
        "r2_corr_light": _r2_corr(pred[light], meas[light]),
        "r2_corr_heavy": _r2_corr(pred[heavy], meas[heavy]),
    }
    return out


# --------------------------------------------------------------- error statistics

def _error_summary(err: np.ndarray) -> dict:
    """n, mean, median, 5th/95th percentile and RMSE of an error sample [W]."""
    if err.size == 0:
        return {"n": 0, "mean_w": math.nan, "median_w": math.nan, "p5_w": math.nan,
                "p95_w": math.nan, "rmse_w": math.nan}
    p5, p50, p95 = np.percentile(err, [5.0, 50.0, 95.0])
    return {"n": int(err.size), "mean_w": float(err.mean()), "median_w": float(p50),
            "p5_w": float(p5), "p95_w": float(p95), "rmse_w": _rmse(err)}


def speed_bins(err_w, speed_mps, width_mps: float = SPEED_BIN_MPS) -> list[dict]:
    """Error statistics in speed bins of 10 km/h (paper Fig. 8).

    Parameters
    ----------
    err_w : error pred − meas per sample [W]
    speed_mps : speed per sample [m/s]; negative speeds fall into the first bin
    width_mps : bin width [m/s]

    Returns
    -------
    One dict per bin from 0 to the highest speed, contiguous (empty bins have n = 0
    and NaN statistics): ``lo_kmh``, ``hi_kmh``, ``lo_mps``, ``hi_mps``, ``n``,
    ``mean_w``, ``median_w``, ``p5_w``, ``p95_w``, ``rmse_w``. A bin is [lo, hi).
    """
    err = np.asarray(err_w, dtype=float)
    v = np.asarray(speed_mps, dtype=float)
    if err.size == 0:
        return []
    # the small tolerance keeps 20 km/h (= 5.5555… m/s) in the 20–30 bin despite rounding
    idx = np.floor(np.maximum(v, 0.0) / width_mps + 1e-9).astype(np.int64)
    order = np.argsort(idx, kind="stable")
    sorted_idx = idx[order]
    sorted_err = err[order]
    nbins = int(sorted_idx[-1]) + 1
    starts = np.searchsorted(sorted_idx, np.arange(nbins), side="left")
    ends = np.searchsorted(sorted_idx, np.arange(nbins), side="right")
    out = []
    for k in range(nbins):  # a handful of bins, not samples
        lo, hi = k * width_mps, (k + 1) * width_mps
        row = {"lo_kmh": lo / KMH, "hi_kmh": hi / KMH, "lo_mps": lo, "hi_mps": hi}
        row.update(_error_summary(sorted_err[starts[k]:ends[k]]))
        out.append(row)
    return out


def high_speed_summary(err_w, speed_mps, threshold_mps: float = HIGH_SPEED_MPS) -> dict:
    """Error at and above 80 km/h, where the paper's VSP equations underpredict (Fig. 8).

    Parameters
    ----------
    err_w : error pred − meas per sample [W]
    speed_mps : speed per sample [m/s]
    threshold_mps : lower edge of the range [m/s] (default ``constants.HIGH_SPEED_MPS``)

    Returns
    -------
    ``threshold_kmh``, ``fraction`` of samples in the range, ``n``, ``mean_w``
    (mean error), ``median_w``, ``p5_w``, ``p95_w``, ``rmse_w`` [W] in the range, and
    ``mean_below_w``/``rmse_below_w`` below it for contrast.
    """
    err = np.asarray(err_w, dtype=float)
    v = np.asarray(speed_mps, dtype=float)
    hi = v >= threshold_mps
    out = {"threshold_kmh": threshold_mps / KMH,
           "fraction": float(hi.mean()) if err.size else math.nan}
    out.update(_error_summary(err[hi]))
    below = err[~hi]
    out["mean_below_w"] = float(below.mean()) if below.size else math.nan
    out["rmse_below_w"] = _rmse(below)
    return out


def target_terms(chain, cats: dict, wheel, target, v, signals, battery_w, a, theta, dt_s=None, trip=None) -> dict:
    """Each term's power as it reaches a chain's target (battery or fuel) [W]: the term's
    wheel power times the chain's slope from zero to the sample's driving power, (f(P) −
    f(0))/P (0 where |P| < 1 W), so that "which term carries the error" reads the error of
    the target in the target's watts (a partial slope s: about (1 − s) times that term).
    Regressed on the wheel powers instead, a fuel chain's slope 1/η_m came out as the term's
    error (a rehearsal read 'roll' −9.5: "10.5 × the rolling term")."""
    base = chain.target_power(np.zeros_like(np.asarray(wheel, float)), v, signals, battery_w, a, theta, dt_s, trip)
    w = np.asarray(wheel, float)
    k = np.divide(np.asarray(target, float) - base, w, out=np.zeros_like(w), where=np.abs(w) >= 1.0)
    return {c: np.asarray(p, float) * k for c, p in cats.items()}


def error_term_correlation(err_w, category_w: dict[str, np.ndarray]) -> dict[str, dict]:
    """Which term carries the error: error against each category's power (paper Fig. 9).

    Parameters
    ----------
    err_w : error pred − meas per sample [W]
    category_w : category → power per sample [W]

    Returns
    -------
    category → ``r`` (Pearson correlation of error and category power), ``slope``
    (least-squares slope of error on that power alone, with intercept, W/W) and
    ``partial_slope`` (its coefficient when the error is regressed on all categories
    at once, with intercept). When the error is (c − c_true)/c times the equation's own
    term power, ``partial_slope`` is that relative coefficient error, e.g. −0.5 for an
    aero coefficient half the truth. NaN for a category whose power is constant
    (e.g. absent) or with fewer than 3 samples; ``partial_slope`` is NaN for all when
    the category powers are collinear. Fitted by :mod:`sumo_drvpw.fit.ols` on the
    centred columns.
    """
    err = np.asarray(err_w, dtype=float)
    n = err.size
    out: dict[str, dict] = {}
    names, cols = [], []
    ec = err - err.mean() if n else err
    see = float(ec @ ec)
    for cat, p in category_w.items():
        p = np.asarray(p, dtype=float)
        pc = p - p.mean() if n else p
        spp = float(pc @ pc)
        r = slope = math.nan
        if n >= MIN_SAMPLES and spp > 0.0 and np.ptp(p) > 1e-9 * max(1.0, np.abs(p).max()):
            sep = float(ec @ pc)
            slope = sep / spp
            r = sep / math.sqrt(spp * see) if see > 0.0 else math.nan
            names.append(cat)
            cols.append(pc)
        out[cat] = {"r": r, "slope": slope, "partial_slope": math.nan}
    if names and n > len(names) + 1:
        fit = dense_gram(np.column_stack(cols), ec, names).fit(list(range(len(names))))
        if fit is not None:  # collinear category powers: no partial slope (NaN)
            for cat, c in zip(names, fit["beta"]):
                out[cat]["partial_slope"] = float(c)
    return out


def energy_shares(category_w: dict[str, np.ndarray], dt_s) -> tuple[dict, dict]:
    """Traction energy of each category and its share of the total (paper Fig. 10).

    Parameters
    ----------
    category_w : category → power per sample [W]
    dt_s : duration of each sample [s] (array or scalar)

    Returns
    -------
    (energy_j, share): ``energy_j[cat]`` = Σ P_cat·Δt over samples whose total
    predicted power Σ_cat P_cat > 0 [J], ``energy_j["total"]`` their sum (the predicted
    traction energy); ``share[cat]`` = energy_j[cat] / energy_j["total"]. The shares sum
    to 1; a category can have a negative share (downhill grade during traction). NaN
    shares when there is no traction.
    """
    cats = list(category_w)
    if not cats:
        return {"total": 0.0}, {}
    total_p = np.sum([np.asarray(category_w[c], dtype=float) for c in cats], axis=0)
    dt = np.broadcast_to(np.asarray(dt_s, dtype=float), total_p.shape)
    w = np.where(total_p > 0.0, dt, 0.0)
    energy = {c: float(np.asarray(category_w[c], dtype=float) @ w) for c in cats}
    total = float(sum(energy.values()))
    energy["total"] = total
    share = {c: (energy[c] / total if total > 0.0 else math.nan) for c in cats}
    return energy, share


# -------------------------------------------------------------------- comparison

@dataclass
class EquationResult:
    """One equation's predictions and statistics against the measured power."""

    equation: Equation
    pred_w: np.ndarray
    category_w: dict[str, np.ndarray]
    metrics: dict
    speed_bins: list[dict]
    high_speed: dict
    error_term_correlation: dict
    energy_j: dict
    energy_share: dict
    traction_energy_ratio: float
    error_reference_correlation: dict | None = None
    #: chain inputs unknown (NaN) on some samples: column → {"samples", "read_as", "trips"}
    #: (:meth:`sumo_drvpw.model.chain.EnergyChain.unknown_inputs`)
    unknown_inputs: dict = field(default_factory=dict)
    #: Σ max(P̂, 0)·Δt of the compared target [J] (a battery or fuel target: the chain's)
    predicted_traction_j: float = math.nan

    @property
    def name(self) -> str:
        """The equation's name."""
        return self.equation.name

    def error_w(self, meas_w: np.ndarray) -> np.ndarray:
        """Error pred − meas [W] per sample against measured power ``meas_w`` [W]."""
        return self.pred_w - meas_w


@dataclass
class Comparison:
    """Equations against one set of measured power; build with :func:`compare`.

    Attributes
    ----------
    meas_w : measured driving power [W]
    speed_mps : speed [m/s]
    dt_s : duration of each sample [s]
    results : equation name → :class:`EquationResult`, in the order given
    measured_traction_energy_j : Σ P_meas·Δt over samples with P_meas > 0 [J]
    reference : name of the equation whose category powers the errors were also
        correlated with (``error_reference_correlation``), or None
    trip : trip id per sample, or None; when given, ``to_json`` reports energy per trip
        (``trip_energy``, ``trip_net_energy``) for each equation
    left_out : per trip, what it lost to samples left out before the comparison
        (:func:`sumo_drvpw.fit.trip_energy.left_out_by_trip`), or None; added to each
        trip's entry of the per-trip energies (``left_out_*``, ``partial``)
    target : what was compared: ``wheel``, ``battery`` or ``fuel`` (:func:`compare`);
        with ``fuel`` the per-trip energies are also given in litres of each chain's fuel
    measured_fuel : with ``fuel``, the fuel the log's flow was read as and where from
        (:func:`sumo_drvpw.data.powertrain.measured_fuel`), or None; ``to_json`` gives it
        (``settings.measured_fuel``) and a note when a chain burns another
        (``settings.fuel_note``, :func:`sumo_drvpw.fit.trip_energy.fuel_mismatch_note`)
    """

    meas_w: np.ndarray
    speed_mps: np.ndarray
    dt_s: np.ndarray
    results: dict[str, EquationResult] = field(default_factory=dict)
    measured_traction_energy_j: float = math.nan
    reference: str | None = None
    trip: np.ndarray | None = None
    left_out: dict | None = None
    target: str = "wheel"
    measured_fuel: tuple[str, str] | None = None
    #: a fuel target with the hybrid battery's V·I: each chain's prediction takes the battery's
    #: energy change off (SAE J1711), the measured fuel is the logged one (``settings.battery_correction``)
    battery_corrected: bool = False

    @property
    def n_samples(self) -> int:  # number of samples compared
        return int(self.meas_w.size)

    def error_w(self, name: str) -> np.ndarray:
        """Error pred − meas [W] of the named equation."""
        return self.results[name].pred_w - self.meas_w

    def to_json(self) -> dict:
        """JSON-ready summary (NaN → None) with the keys other tools read.

        ``{"equations": {NAME: {"n", "r2", "r2_light", "r2_heavy", "rmse_w", "bias_w",
        "mae_w", …, "speed_bins", "high_speed", "error_term_correlation",
        "energy_share", "energy_j", "trip_energy", "trip_net_energy", …}},
        "n_samples", …}``; the per-trip energies only when the trips are known.
        """
        eqs = {}
        for name, r in self.results.items():
            d = dict(r.metrics)
            d["terms"] = dict(r.equation.terms)
            if r.equation.chain is not None:
                d["predicts"] = r.equation.predicts
                d["chain"] = r.equation.chain.to_dict()
            if r.equation.std_err:
                d["std_err"] = dict(r.equation.std_err)
            if r.equation.mass_kg is not None:
                d["mass_kg"] = r.equation.mass_kg
            d.update(speed_bins=r.speed_bins, high_speed=r.high_speed, error_term_correlation=r.error_term_correlation)
            if r.error_reference_correlation is not None:
                d["error_reference_correlation"] = r.error_reference_correlation
            if r.unknown_inputs:
                d["chain_unknown_inputs"] = r.unknown_inputs
            d.update(energy_share=r.energy_share, energy_j=r.energy_j,
                     measured_traction_energy_j=self.measured_traction_energy_j,
                     predicted_traction_energy_j=r.predicted_traction_j,
                     traction_energy_ratio=r.traction_energy_ratio)
            if self.trip is not None:
                d["trip_energy"] = with_left_out(trip_energy(r.pred_w, self.meas_w, self.dt_s, self.trip),
                                                 self.left_out, net=False)
                d["trip_net_energy"] = with_left_out(trip_net_energy(r.pred_w, self.meas_w, self.dt_s,
                                                                     self.trip), self.left_out, net=True)
            eqs[name] = with_fuel_volumes(d, self.target)
        fuel = {}
        if self.target == "fuel" and self.measured_fuel:
            note = fuel_mismatch_note(eqs, self.measured_fuel)
            fuel = {"measured_fuel": self.measured_fuel[0], "measured_fuel_from": self.measured_fuel[1],
                    **({"fuel_note": note} if note else {})}
        if self.battery_corrected:
            fuel["battery_correction"] = (
                "the measured fuel is the logged flow; each chain's predicted fuel has the hybrid battery's "
                "energy change taken off (SAE J1711: k = battery_to_fuel, else 1/η_m, fuel joules per battery "
                "joule), so a state-of-charge swing over a trip is no fuel error; the measured fuel corrected "
                "the other way (logged + k·battery energy) is what the chain books on a charge-sustaining trip")
        return plain({
            "equations": eqs,
            "n_samples": self.n_samples,
            "measured": {
                "traction_energy_j": self.measured_traction_energy_j,
                "mean_w": float(self.meas_w.mean()) if self.n_samples else math.nan,
                "n_light": int((self.meas_w < HEAVY_LOAD_W).sum()),
                "n_heavy": int((self.meas_w >= HEAVY_LOAD_W).sum()),
                "n_high_speed": int((self.speed_mps >= HIGH_SPEED_MPS).sum()),
            },
            "settings": {
                "heavy_load_w": HEAVY_LOAD_W,
                "high_speed_mps": HIGH_SPEED_MPS,
                "speed_bin_mps": SPEED_BIN_MPS,
                "reference": self.reference,
                "target": self.target,
                "error": "predicted - measured",
                "r2": "centred: 1 - SSE/SST",
                **fuel,
            },
        })


def compare(meas_w, inputs: Inputs, equations: list[Equation], dt_s=None,
            reference: str | None = None, trip=None, target: str = "wheel",
            battery_w=None) -> Comparison:
    """Evaluate equations against measured driving power (paper Table 3, Fig. 4–10).

    Parameters
    ----------
    meas_w : measured driving power per sample [W]
    inputs : the term-basis inputs of the same samples (speed, acceleration, grade …)
    equations : the equations to compare; names must be unique
    dt_s : duration of each sample [s] (array or scalar) for energies; None: 1 s each
    reference : optional name of one of ``equations`` (e.g. the calibrated DrvPw);
        every equation's error is then also correlated with the reference's category
        powers (``error_reference_correlation``), which shows a term an equation lacks
        altogether — its own power of a missing term is zero and carries no signal.
    trip : trip id per sample (default: ``inputs.trip``); when known, the report gives
        energy per trip (:func:`trip_energy`, :func:`trip_net_energy`)
    target : ``wheel`` (default): the prediction is the driving power; ``battery`` or
        ``fuel``: each equation's energy chain (``[chain]``, model/chain.py) turns its
        driving power into battery or fuel power, and ``meas_w`` is that measured power
        (the category powers stay at the wheel)
    battery_w : fuel target only: the hybrid battery's measured V·I [W]; each chain's
        prediction is then P_fuel − k·P_bat (its battery-to-fuel factor k), so a
        state-of-charge swing does not count as a fuel error

    Returns
    -------
    :class:`Comparison`. Samples where an equation's prediction is not finite are
    left out of that equation's statistics.

    Example
    -------
    >>> import numpy as np
    >>> from sumo_drvpw.model.equations import Equation, load_equation
    >>> from sumo_drvpw.model.terms import Inputs
    >>> from sumo_drvpw.fit.compare import compare
    >>> n = 600
    >>> v = np.linspace(5.0, 35.0, n); zero = np.zeros(n)
    >>> x = Inputs(v=v, a=zero, theta=zero, wind=zero, mass=np.full(n, 1500.0),
    ...            rho=np.full(n, 1.2041))
    >>> truth = Equation(name="truth", terms={"aero": 0.35, "roll": 0.009})
    >>> half_aero = Equation(name="half_aero", terms={"aero": 0.175, "roll": 0.009})
    >>> comp = compare(truth.power(x), x, [truth, half_aero, load_equation("vsp_ldv1999")],
    ...                dt_s=0.1)
    >>> round(comp.results["truth"].metrics["r2"], 6)
    1.0
    >>> comp.results["half_aero"].traction_energy_ratio < 1.0   # underpredicts
    True
    >>> report = comp.to_json()   # what `sumo-drvpw compare` writes to report.json
    """
    meas = np.asarray(meas_w, dtype=float).ravel()
    n = meas.size
    if len(inputs) != n:
        raise UserError(f"compare: measured power has {n} samples, inputs {len(inputs)}")
    bad = ~np.isfinite(meas)
    if bad.any():
        raise UserError(f"compare: measured power is not finite at {first_bad_row(bad)}")
    if not equations:
        raise UserError("compare: no equations given")
    names = [eq.name for eq in equations]
    dup = {x for x in names if names.count(x) > 1}
    if dup:
        raise UserError(f"compare: equation names must be unique; repeated: {sorted(dup)}")
    if reference is not None and reference not in names:
        raise UserError(f"compare: reference equation '{reference}' is not among "
                        f"{', '.join(names)}")
    dt = _dt_array(dt_s, n)
    v = np.asarray(inputs.v, dtype=float)
    meas_traction = float(np.where(meas > 0.0, meas, 0.0) @ dt)

    if trip is None:
        trip = inputs.trip
    if trip is not None:
        trip = np.asarray(trip).ravel()
        if trip.shape != (n,):
            raise UserError(f"compare: trip has {trip.size} values for {n} samples")
    comp = Comparison(meas_w=meas, speed_mps=v, dt_s=dt,
                      measured_traction_energy_j=meas_traction, reference=reference,
                      trip=trip, target=target, battery_corrected=target == "fuel" and battery_w is not None)
    cat_powers = {eq.name: eq.category_powers(inputs) for eq in equations}
    prepared = {}  # name → (its terms, its prediction, its terms where its error is measured)
    for eq in equations:
        cats = cat_powers[eq.name]
        # drop empty "other"; keep the four physical categories always (Fig. 10 axes)
        cats = {c: p for c, p in cats.items() if c in CATEGORIES or np.any(p != 0.0)}
        pred = np.sum(list(cats.values()), axis=0) if cats else np.zeros(n)
        cats_at = cats
        if target != "wheel":
            if eq.chain is None or eq.chain.predicts != target:
                raise UserError(f"compare: equation '{eq.name}' ({eq.path or 'built in'}) has no energy "
                                f"chain predicting '{target}' (it predicts '{eq.predicts}')")
            wheel = pred
            pred = eq.chain.target_power(pred, inputs.v, inputs.signals, battery_w, inputs.a, inputs.theta, dt, trip)
            cats_at = target_terms(eq.chain, cats, wheel, pred, inputs.v, inputs.signals, battery_w,
                                   inputs.a, inputs.theta, dt, trip)  # (in the chain's target's watts)
        prepared[eq.name] = (cats, pred, cats_at)
    for eq in equations:
        cats, pred, cats_at = prepared[eq.name]
        err = pred - meas
        ok = np.isfinite(err)
        allok = bool(ok.all())
        e, vv = (err, v) if allok else (err[ok], v[ok])
        cats_ok = cats if allok else {c: p[ok] for c, p in cats.items()}
        at_ok = cats_at if allok else {c: p[ok] for c, p in cats_at.items()}
        energy, share = energy_shares(cats_ok, dt if allok else dt[ok])
        # the traction of what is compared: the terms' at the wheel, the chain's otherwise
        p_trac = energy["total"] if target == "wheel" else float(np.maximum(pred[ok], 0.0) @ dt[ok])
        ref_corr = None
        if reference is not None:
            rc = prepared[reference][2]
            ref_corr = error_term_correlation(e, {c: (p if allok else p[ok]) for c, p in rc.items()})
        comp.results[eq.name] = EquationResult(
            equation=eq, pred_w=pred, category_w=cats,
            metrics=metrics(pred, meas),
            speed_bins=speed_bins(e, vv),
            high_speed=high_speed_summary(e, vv),
            error_term_correlation=error_term_correlation(e, at_ok),
            energy_j=energy, energy_share=share,
            traction_energy_ratio=(p_trac / meas_traction if meas_traction > 0.0 else math.nan),
            error_reference_correlation=ref_corr,
            unknown_inputs=eq.chain.unknown_inputs(inputs.signals, n, trip) if target != "wheel" else {},
            predicted_traction_j=p_trac,
        )
    return comp
