"""Vehicle physics separated from the measurement (issue #11 §3).

An equation that goes into SUMO must describe the vehicle, not the logger. This module
reads each coefficient physically, flags implausible values, and fits under physical
constraints when the unconstrained fit is implausible.

Physical readings (term basis of :mod:`sumo_drvpw.model.terms`; P in W):

========  ==========================  ===========================================
term      coefficient reads as        plausible
========  ==========================  ===========================================
acc       mass factor (1 + J/(m·r²))/η 0.95 … 1.4 (rotating masses; well below 1 is a lag
                                      or a smoothed speed, not physics)
grade     1/η (1 at the wheels)        0.9 … 1.3 (η: drivetrain efficiency between the wheels
                                      and the measured power; far below 1: attenuated grade)
aero      ½·ρ·C_d·A → C_d·A = 2c/ρ     C_d·A ≥ 0 (cars 0.5 … 1.1 m² at the wheels; more at
                                      a powertrain output with losses)
aero_rho  C_d·A                        as aero
roll      c_r (rolling coefficient)    0 … 0.03
========  ==========================  ===========================================

The constrained fit minimises the same least-squares objective as OLS, ‖Xβ − y‖², under
bounds and fixed coefficients, exactly from the sufficient statistics: with XᵀX = L·Lᵀ
(Cholesky), ‖Xβ − y‖² = ‖Lᵀβ − L⁻¹Xᵀy‖² + const, solved by
:func:`scipy.optimize.lsq_linear`. Fixed coefficients are moved to the target first.

Every coefficient of a target measured behind a drivetrain (motor shaft, powertrain output,
battery) carries the factor 1/η; the grade coefficient reads it directly (potential energy
is exact physics) and, where the fit shows η otherwise, c_grade·η is the grade at the wheels
(:mod:`sumo_drvpw.fit.drivetrain`).

Constraints are declared in a candidate TOML file beside ``terms``::

    terms = ["acc", "grade", "aero", "roll"]
    [constraints]
    grade = { fixed = 1.0 }
    aero = { min = 0.0 }
    acc = { min = 1.0, max = 1.3 }

:data:`DEFAULT_CONSTRAINTS` apply when none are declared.

Physical candidates (:data:`PHYSICAL_CANDIDATES`, :func:`select_physical`): effects whose
form SUMO can evaluate — air density from temperature and altitude in the aero term
(``aero`` → ``aero_rho``), c_r(T) (``roll*cold``), cold drivetrain drag (``cold*v^2``),
a cornering drag (``radial*v1``, where the logs carry a yaw rate) and recuperation on its
own coefficient (:func:`regime_fit`) — are chosen forward on whole trips by trip-grouped
cross-validation of the per-trip traction energy, each kept only when its gain is
material, replicates over most trips and its coefficient reads plausibly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.linalg import cholesky, solve_triangular
from scipy.optimize import lsq_linear
from scipy.stats import wilcoxon

from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.drivetrain import ETA_INERTIA_MIN, drivetrain_eta, wheel_grade
from sumo_drvpw.fit.ols import Gram, gram
from sumo_drvpw.model.constants import FT, KMH, MPH, RHO_DEFAULT

#: term → (low, high) of the plausible coefficient (see the module table)
PLAUSIBLE = {"acc": (0.95, 1.4), "grade": (0.9, 1.3), "roll": (0.0, 0.03),
             # a tyre's cornering drag over its centripetal force ≈ its slip angle [rad]:
             # a few degrees at the lateral accelerations of road driving
             "radial*v1": (0.0, 0.1)}
#: plausible C_d·A [m²]: ≥ 0 (a powertrain-output target includes losses: no upper bound)
CDA_MIN = 0.0
#: constraints used when the unconstrained fit is implausible and none are declared
#: (grade: 1/η ≥ 1 behind a drivetrain; = 1 at the wheels, declare ``grade = { fixed = 1.0 }``)
DEFAULT_CONSTRAINTS = {"grade": {"min": 1.0, "max": 1.3}, "aero": {"min": 0.0},
                       "aero_rho": {"min": 0.0}, "roll": {"min": 0.0}, "acc": {"min": 1.0}}


def physical_reading(terms: dict[str, float], rho_kgm3: float = RHO_DEFAULT) -> dict[str, dict]:
    """Physical reading of each coefficient and whether it is plausible.

    Parameters
    ----------
    terms : term → coefficient
    rho_kgm3 : mean air density of the data [kg/m³] (reads the aero coefficient as C_d·A)

    Returns term → ``{"coefficient", "reads_as", "value", "unit", "plausible", "note"}``
    (``plausible`` None for a term without a physical reading).
    """
    out = {}
    for t, c in terms.items():
        c = float(c)
        if t == "acc":
            ok = PLAUSIBLE["acc"][0] <= c <= PLAUSIBLE["acc"][1]
            out[t] = {"coefficient": c, "reads_as": "mass factor", "value": c, "unit": "-",
                      "plausible": ok, "note": "" if ok else (
                          "below 1: a lag between power and speed or a smoothed speed absorbed"
                          if c < PLAUSIBLE["acc"][0] else "above 1.4: more rotating mass than a car has"
                          + _mph_hint(c))}
        elif t == "acc_pos" and "acc" in terms:
            eta = (drivetrain_eta(terms) or (math.nan,))[0]
            ok = ETA_INERTIA_MIN <= eta <= 1.0
            out[t] = {"coefficient": c, "reads_as": "η of the inertial power, (c_acc + c_acc_pos)/c_acc = 1/η²",
                      "value": eta, "unit": "-", "plausible": ok, "note": "" if ok else (
                          "above 1: the car would return more kinetic energy than it takes" if not eta <= 1.0
                          else f"below {ETA_INERTIA_MIN:g}: more loss than a drivetrain's")}
        elif t == "grade":
            ok = PLAUSIBLE["grade"][0] <= c <= PLAUSIBLE["grade"][1]
            out[t] = {"coefficient": c, "reads_as": "1/η: share of m·g·v·sin θ (1 at the wheels)", "value": c,
                      "unit": "-", "plausible": ok, "note": "" if ok else (
                          "below 1: the logged grade is attenuated (coarse or smoothed elevation)"
                          if c < PLAUSIBLE["grade"][0] else "above 1.3: the logged grade is too small")
                      + _foot_hint(c)}
            if (w := wheel_grade(terms)) is not None:   # c·η, η from the inertia by direction
                out[t]["at_wheels"] = w
        elif t in ("aero", "aero_rho"):
            cda = 2.0 * c / rho_kgm3 if t == "aero" else c
            ok = cda >= CDA_MIN
            out[t] = {"coefficient": c, "reads_as": f"C_d·A at ρ = {rho_kgm3:.4g} kg/m³", "value": cda, "unit": "m²",
                      "plausible": ok, "note": "" if ok else "negative drag: another term or an artefact took its place"}
        elif t == "roll":
            ok = PLAUSIBLE["roll"][0] <= c <= PLAUSIBLE["roll"][1]
            out[t] = {"coefficient": c, "reads_as": "rolling coefficient c_r", "value": c, "unit": "-",
                      "plausible": ok, "note": "" if ok else (
                          "negative rolling resistance" if c < 0 else "above 0.03: more than tyres")}
        elif t == "radial*v1":
            lo, hi = PLAUSIBLE[t]
            ok = lo <= c <= hi
            out[t] = {"coefficient": c, "reads_as": "cornering drag over the centripetal force (≈ the tyres' "
                      "slip angle in rad)", "value": c, "unit": "-", "plausible": ok, "note": "" if ok else (
                          "negative cornering drag" if c < lo else "above 0.1: more than tyres' slip")}
        else:
            out[t] = {"coefficient": c, "reads_as": "no physical reading", "value": None, "unit": "",
                      "plausible": None, "note": ""}
    return out


#: grade coefficients that read as an elevation in the wrong length unit: ft read as m gives a
#: grade 1/0.3048 = 3.28 × too steep, so a coefficient near 0.30 (smoothing alone attenuates a
#: grade to 0.7–0.95); m read as ft, near 3.28
FOOT_AS_METRE = (0.2, 0.45)
METRE_AS_FOOT = (2.2, 4.5)


#: acc coefficients that read as a speed in mph read as km/h: m·v·a then falls by 1/1.609²,
#: so a mass factor of 1.0–1.2 reads 2.6–3.1
MPH_AS_KMH = (2.2, 3.4)


def _mph_hint(c: float) -> str:
    """The acc note's addition when ``c`` reads as a speed logged in mph and read as km/h."""
    if MPH_AS_KMH[0] <= c <= MPH_AS_KMH[1]:
        k = MPH / KMH
        return (f"; near {k * k:.2f} (× the mass factor), the square of {k:.4g} km per mile: a speed "
                "logged in mph and read as km/h — check the speed's unit")
    return ""


def _foot_hint(c: float) -> str:
    """The note's addition when a grade coefficient ``c`` reads as an elevation (or grade)
    logged in feet and read as metres, or the reverse; '' otherwise."""
    if FOOT_AS_METRE[0] <= c <= FOOT_AS_METRE[1]:
        return (f"; near {FT:g}, the metres per foot: an elevation logged in feet and read as metres "
                f"makes every grade {1 / FT:.2f} × too steep — check the elevation's unit")
    if METRE_AS_FOOT[0] <= c <= METRE_AS_FOOT[1]:
        return (f"; near {1 / FT:.2f}, the feet per metre: an elevation logged in metres and read as feet "
                f"makes every grade {FT:g} × too flat — check the elevation's unit")
    return ""


#: a free acc coefficient outside this range is no mass factor: the power, the mass or the
#: speed is in another unit (a power in kW reads 0.001)
ACC_SCALE_SANE = (0.2, 5.0)


def check_scale(terms: dict[str, float]) -> None:
    """UserError when the free fit's ``acc`` coefficient is no mass factor (outside
    ``ACC_SCALE_SANE``): the measured power is that many times m·v·a, where a vehicle's is
    1–1.4 times it. No constraint makes such a fit physical (a power logged in kW was
    written with acc = 1 beside aero and roll in kW: R² −593,406, found by a sweep)."""
    c = terms.get("acc")
    if c is None or ACC_SCALE_SANE[0] <= float(c) <= ACC_SCALE_SANE[1]:
        return
    raise UserError(f"the free fit's acc coefficient is {float(c):.4g}: the measured power reads {float(c):.3g} × "
                    "m·v·a, where a vehicle's is 1–1.4 × (its rotating mass): is the power in another unit "
                    "(in kW it reads 0.001), the vehicle's mass wrong by that factor, or the speed in "
                    "another unit?")


def implausible(reading: dict[str, dict]) -> list[str]:
    """Terms whose reading is implausible, in term order."""
    return [t for t, r in reading.items() if r["plausible"] is False]


def parse_constraints(doc: dict, where: str) -> dict[str, dict]:
    """Check a ``[constraints]`` table: term → {"fixed": x} or {"min": lo, "max": hi}."""
    out = {}
    if doc is not None and not isinstance(doc, dict):
        raise UserError(f"{where}: [constraints] must be a table (term → {{fixed = x}} or {{min, max}}), "
                        f"got {doc!r}")
    for t, spec in (doc or {}).items():
        if not isinstance(spec, dict) or not spec or set(spec) - {"fixed", "min", "max"}:
            raise UserError(f"{where}: constraints.{t} must be a table with 'fixed' or 'min'/'max', "
                            f"got {spec!r}")
        if "fixed" in spec and len(spec) > 1:
            raise UserError(f"{where}: constraints.{t}: 'fixed' excludes 'min'/'max'")
        for k, v in spec.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise UserError(f"{where}: constraints.{t}.{k} must be a finite number, got {v!r}")
        if spec.get("min", -math.inf) > spec.get("max", math.inf):
            raise UserError(f"{where}: constraints.{t}: min {spec['min']} > max {spec['max']}")
        out[str(t)] = {k: float(v) for k, v in spec.items()}
    return out


def read_constraints(path) -> dict[str, dict]:
    """The ``[constraints]`` table of a candidate TOML file (empty when it has none)."""
    from sumo_drvpw.fileio import read_toml

    p = Path(path)
    return parse_constraints(read_toml(p, "candidate file").get("constraints", {}), str(p))


@dataclass
class ConstrainedFit:
    """Least squares under bounds and fixed coefficients, from sufficient statistics."""

    params: dict[str, float]
    rss: float
    active: list[str] = field(default_factory=list)   # terms at a bound or fixed
    constraints: dict = field(default_factory=dict)


def constrained_fit(g: Gram, constraints: dict[str, dict]) -> ConstrainedFit:
    """Minimise ‖Xβ − y‖² subject to ``constraints`` (see the module docstring).

    Parameters
    ----------
    g : sufficient statistics of the terms (:func:`sumo_drvpw.fit.ols.gram`)
    constraints : term → {"fixed": x} or {"min": lo, "max": hi}; terms not in ``g`` ignored
    """
    names = list(g.names)
    k = len(names)
    beta = np.zeros(k)
    fixed = [j for j, t in enumerate(names) if "fixed" in constraints.get(t, {})]
    free = [j for j in range(k) if j not in fixed]
    for j in fixed:
        beta[j] = constraints[names[j]]["fixed"]
    if free:
        a = g.xtx[np.ix_(free, free)]
        b = g.xty[free] - g.xtx[np.ix_(free, fixed)] @ beta[fixed] if fixed else g.xty[free]
        s = np.sqrt(np.maximum(np.diag(a), 1e-300))       # unit-diagonal scaling for precision
        a_s = a / np.outer(s, s)
        try:
            low = cholesky(a_s + 1e-13 * np.eye(len(free)), lower=True)
        except np.linalg.LinAlgError:
            raise UserError(f"constrained fit: the terms {[names[j] for j in free]} are collinear "
                            "on these data") from None
        rhs = solve_triangular(low, b / s, lower=True)
        lo = np.array([constraints.get(names[j], {}).get("min", -np.inf) for j in free], float)
        hi = np.array([constraints.get(names[j], {}).get("max", np.inf) for j in free], float)
        res = lsq_linear(low.T, rhs, bounds=(lo * s, hi * s), method="bvls", tol=1e-12)
        # bounds hold on the scaled problem up to rounding; unscaled, keep them exactly
        beta[free] = np.clip(res.x / s, lo, hi)
    rss = float(g.yty - 2.0 * beta @ g.xty + beta @ g.xtx @ beta)
    active = [names[j] for j in fixed]
    for j in free:
        c = constraints.get(names[j], {})
        if any(abs(beta[j] - c[key]) <= 1e-9 * max(1.0, abs(c[key])) for key in ("min", "max") if key in c):
            active.append(names[j])
    return ConstrainedFit(dict(zip(names, map(float, beta))), max(rss, 0.0), active,
                          {t: constraints[t] for t in names if t in constraints})


def _refit_metrics(eq, g: Gram, free: dict[str, float], rss: float) -> None:
    """``eq.metrics`` of the constrained coefficients now in ``eq.terms``: R² (centred, its
    total sum of squares from the free fit's R² and residual on the same samples ``g``) and
    the uncentred one; the free fit's R² kept as ``r2_unconstrained``."""
    r2 = eq.metrics.get("r2")
    b = np.array([free[t] for t in g.names])
    rss_free = float(g.yty - 2.0 * b @ g.xty + b @ g.xtx @ b)
    if r2 is None or not np.isfinite(r2) or r2 >= 1.0:
        return
    sst = rss_free / (1.0 - r2)
    eq.metrics["r2_unconstrained"] = r2
    eq.metrics["r2"] = 1.0 - rss / sst if sst > 0 else math.nan
    if g.yty > 0:
        eq.metrics["r2_uncentered"] = 1.0 - rss / float(g.yty)


def physical_calibration(x, y, candidates, mask=None, constraints: dict | None = None,
                         force: bool = False, **kw):
    """Calibrate stepwise; when the fit is implausible (or ``force``), refit the selected
    terms under ``constraints`` (default :data:`DEFAULT_CONSTRAINTS`), saying so.

    Parameters
    ----------
    x, y, candidates, mask, **kw : as :func:`sumo_drvpw.fit.calibrate.calibrate`
    constraints : declared constraints (e.g. from :func:`read_constraints`)
    force : use the constrained fit even when the unconstrained one is plausible

    Returns (Equation, report dict with ``unconstrained``, ``reading``, ``implausible``,
    ``constrained`` (or None) and ``used``).
    """
    from sumo_drvpw.fit.calibrate import calibrate

    res = calibrate(x, y, candidates, mask=mask, **kw)
    check_scale(dict(res.params))
    use = res.results.model.exog.shape[0] if res.results is not None else None
    m = np.isfinite(np.asarray(y, float)) if mask is None else (np.asarray(mask, bool) & np.isfinite(y))
    rho = float(np.nanmean(np.asarray(x.rho, float)[m]))
    reading = physical_reading(res.params, rho)
    bad = implausible(reading)
    rep = {"unconstrained": dict(res.params), "reading": reading, "implausible": bad,
           "rho_kgm3": rho, "constrained": None, "used": "unconstrained", "n": use}
    eq = res.to_equation("calibrated")
    if not bad and not force:
        return eq, rep
    cons = constraints or DEFAULT_CONSTRAINTS
    g = gram(x, np.asarray(y, float), tuple(res.terms), m)
    fit = constrained_fit(g, cons)
    rep["constrained"] = {"params": fit.params, "active": fit.active, "constraints": fit.constraints,
                          "reading": physical_reading(fit.params, rho), "rss": fit.rss,
                          "rss_unconstrained": float(g.yty - np.linalg.lstsq(g.xtx, g.xty, rcond=None)[0] @ g.xty)}
    rep["used"] = "constrained"
    rep["why"] = ("unconstrained fit implausible: " + ", ".join(f"{t} ({reading[t]['note']})" for t in bad)
                  if bad else "constrained fit requested")
    _refit_metrics(eq, g, dict(res.params), fit.rss)
    eq.terms = dict(fit.params)
    eq.std_err = {}
    eq.p_values = {}
    eq.provenance["physical"] = {"used": "constrained", "why": rep["why"], "constraints": fit.constraints,
                                 "active": fit.active, "unconstrained": dict(res.params)}
    return eq, rep


def apply_physics(eq, x, y, mask, constraints: dict | None = None):
    """Keep ``eq`` if its coefficients read plausibly; else refit its terms under
    ``constraints`` (default :data:`DEFAULT_CONSTRAINTS`) on the same samples.

    Returns (equation, message or None); the unconstrained coefficients and the reason stay
    in ``eq.provenance["physical"]``.
    """
    from sumo_drvpw.model.terms import term_matrix

    terms = tuple(eq.terms)
    use = np.asarray(mask, bool) & np.isfinite(np.asarray(y, float))
    rho = float(np.nanmean(np.asarray(x.rho, float)[use])) if use.any() else RHO_DEFAULT
    if not implausible(physical_reading(eq.terms, rho)):
        return apply_physics_gram(eq, None, rho, constraints)
    use &= np.all(np.isfinite(term_matrix(terms, x)), axis=1)
    return apply_physics_gram(eq, gram(x, np.where(use, y, 0.0), terms, use), rho, constraints)


def apply_physics_gram(eq, g: Gram | None, rho_kgm3: float = RHO_DEFAULT,
                       constraints: dict | None = None):
    """:func:`apply_physics` from sufficient statistics ``g`` (any superset of the
    equation's terms, e.g. a streamed calibration's); ``rho_kgm3`` reads the aero term."""
    check_scale(eq.terms)
    reading = physical_reading(eq.terms, rho_kgm3)
    bad = implausible(reading)
    if not bad:
        eq.provenance["physical"] = {"used": "unconstrained", "reading": reading}
        return eq, None
    idx = [list(g.names).index(t) for t in eq.terms]
    sub = Gram(g.xtx[np.ix_(idx, idx)], g.xty[idx], g.yty, g.n, tuple(eq.terms))
    fit = constrained_fit(sub, constraints or DEFAULT_CONSTRAINTS)
    why = ", ".join(f"{t} = {eq.terms[t]:.4g} ({reading[t]['note']})" for t in bad)
    eq.provenance["physical"] = {"used": "constrained", "why": why, "constraints": fit.constraints,
                                 "active": fit.active, "unconstrained": dict(eq.terms),
                                 "reading": physical_reading(fit.params, rho_kgm3)}
    _refit_metrics(eq, sub, dict(eq.terms), fit.rss)
    eq.terms = dict(fit.params)
    eq.std_err, eq.p_values = {}, {}
    return eq, (f"physically constrained fit used: the free fit is implausible: {why}; "
                f"constraints {fit.constraints} (active: {', '.join(fit.active) or 'none'})")


def constraints_of(candidates_spec) -> dict | None:
    """Constraints declared in a candidate TOML file, or None (a set name or a list)."""
    from sumo_drvpw.fit.calibrate import is_candidate_file

    return read_constraints(candidates_spec) if is_candidate_file(candidates_spec) else None


# ------------------------------------------------- physical candidates, chosen on whole trips

#: Physical candidates of the closed loop (issue #11 §2–§4) in forms SUMO can evaluate:
#: name → (what it means, terms replaced {old: new}, terms added). ``regime`` is a fit
#: option, not a term: recuperation on its own coefficient (1 + r scales predicted
#: recuperation), so that braking samples do not bend the traction coefficients.
PHYSICAL_CANDIDATES = {
    "rho(T)": ("air density from temperature and altitude in the aero term (coefficient C_d·A)",
               {"aero": "aero_rho"}, ()),
    "c_r(T)": ("rolling resistance rising in the cold, c_r0·(1 + k·(T_ref − T))", {}, ("roll*cold",)),
    "cold drag": ("drivetrain (gear oil, bearing grease) drag ∝ v rising in the cold", {}, ("cold*v^2",)),
    "regime": ("recuperation on its own coefficient (drivetrain efficiency differs by direction)", {}, ()),
    "inertia by direction": ("inertial power on its own coefficient while speeding up: the drivetrain "
                             "delivers kinetic energy at 1/η and returns it at η", {}, ("acc_pos",)),
    "cornering drag": ("tyre drag in curves, a share of the centripetal force (needs a yaw rate, "
                       "yaw_rate_rps)", {}, ("radial*v1",)),
}
#: plausible tyre temperature coefficient k of c_r(T) [1/K]: ISO 28580 corrects with 0.008/K;
#: up to 0.03/K leaves room for bearings and the drivetrain share of the ``roll`` term
K_CR_MAX = 0.03
#: significance of a candidate's gain over whole trips: one-sided Wilcoxon signed-rank test
#: of the per-trip absolute traction-energy errors before and after
ALPHA = 0.05
#: smallest material gain in the mean absolute trip traction-energy error (0.1 percentage
#: point; the product's trip-energy errors are read in whole percent)
MIN_GAIN = 0.001


def regime_fit(X: np.ndarray, y: np.ndarray, regime: bool, iters: int = 12) -> tuple[np.ndarray, float]:
    """Least squares of y on X; with ``regime``, P̂ = Xβ where Xβ ≥ 0 and (1 + r)·Xβ where it
    is negative (alternating least squares for β and r). Returns (β, r); r = 0 without regime."""
    s = np.sqrt(np.maximum(np.einsum("ij,ij->j", X, X), 1e-300))   # column scaling
    Xs = X / s

    def solve(w):  # weighted normal equations of the scaled columns
        return np.linalg.solve((Xs * (w * w)[:, None]).T @ Xs, Xs.T @ (w * y)) / s
    b = solve(np.ones(len(y)))
    r = 0.0
    if not regime:
        return b, r
    for _ in range(iters):
        p = X @ b
        neg = p < 0.0
        den = float(np.sum(p[neg] ** 2))
        r = float(np.sum(p[neg] * (y[neg] - p[neg])) / den) if den > 0 else 0.0
        b = solve(np.where(neg, 1.0 + r, 1.0))
    return b, r


def regime_power(X: np.ndarray, b: np.ndarray, r: float) -> np.ndarray:
    """P̂ = Xβ, its negative part scaled by (1 + r) [W]."""
    p = X @ b
    return np.where(p < 0.0, (1.0 + r) * p, p)


def _terms_of(base: list[str], chosen: list[str]) -> tuple[list[str], bool]:
    terms = list(base)
    for c in chosen:
        _, repl, add = PHYSICAL_CANDIDATES[c]
        terms = [repl.get(t, t) for t in terms] + [t for t in add if t not in terms]
    return terms, "regime" in chosen


def trip_cv(x, y, use, dt, trip, terms, regime=False, k: int = 5, energy: str = "traction") -> dict:
    """Trip-grouped k-fold cross-validation of ``terms``: fold j holds out every k-th trip in
    name order from the j-th; per held-out trip the traction-energy error (Σ max(P, 0)·Δt,
    predicted/measured − 1, :func:`sumo_drvpw.fit.compare.trip_energy`; ``energy="net"``: of
    Σ P·Δt, bounded on a descent, :func:`~sumo_drvpw.fit.trip_energy.net_energy_errors`) and
    the pooled RMSE.
    ``k = 1``: one fit on every trip and its in-sample errors (what no held-out protocol can
    beat)."""
    from sumo_drvpw.fit.compare import trip_energy
    from sumo_drvpw.fit.trip_energy import net_energy_errors
    from sumo_drvpw.model.terms import term_matrix

    X = term_matrix(terms, x)
    ok = np.asarray(use, bool) & np.all(np.isfinite(X), axis=1) & np.isfinite(y)
    names = sorted(set(np.asarray(trip)[ok].tolist()))
    k = 1 if k == 1 else max(2, min(k, len(names)))
    errs, sse, n = {}, 0.0, 0
    for j in range(k):
        test = np.isin(trip, names[j::k]) & ok
        train = ok & ~test if k > 1 else ok  # k = 1: fitted on every trip, errors in sample
        b, r = regime_fit(X[train], y[train], regime)
        p = regime_power(X[test], b, r)
        if energy == "net":
            errs.update(net_energy_errors(p, y[test], dt[test], trip[test]))
        else:
            errs.update({t: v["error"] for t, v in trip_energy(p, y[test], dt[test], trip[test])["trips"].items()})
        sse += float(np.sum((y[test] - p) ** 2))
        n += int(test.sum())
    a = np.abs(np.array([e for e in errs.values() if np.isfinite(e)]))
    return {"errors": errs, "mean_abs_error": float(a.mean()), "max_abs_error": float(a.max()),
            "rmse_w": math.sqrt(sse / max(n, 1)), "folds": k}


def candidate_reading(name: str, params: dict[str, float], r: float, rho_kgm3: float) -> dict:
    """Physical reading of a candidate's coefficient and whether it is plausible."""
    if name == "rho(T)":
        c = params.get("aero_rho", math.nan)
        return {"reads_as": "C_d·A", "value": c, "unit": "m²", "plausible": bool(c >= CDA_MIN)}
    if name == "c_r(T)":
        k = params["roll*cold"] / params["roll"] if params.get("roll") else math.nan
        return {"reads_as": "k of c_r(T) = c_r0·(1 + k·(T_ref − T))", "value": k, "unit": "1/K",
                "plausible": bool(0.0 <= k <= K_CR_MAX)}
    if name == "cold drag":
        c = params["cold*v^2"]
        return {"reads_as": "extra drag force per K below T_ref and per m/s", "value": c, "unit": "N·s/(m·K)",
                "plausible": bool(c >= 0.0)}
    if name == "inertia by direction":
        eta = (drivetrain_eta(params) or (math.nan,))[0]
        return {"reads_as": "η of the inertial power, (c_acc + c_acc_pos)/c_acc = 1/η²", "value": eta,
                "unit": "-", "plausible": bool(ETA_INERTIA_MIN <= eta <= 1.0)}
    if name == "cornering drag":
        c = params["radial*v1"]
        return {"reads_as": "cornering drag over the centripetal force (≈ the tyres' slip angle in rad)",
                "value": c, "unit": "-", "plausible": bool(PLAUSIBLE["radial*v1"][0] <= c <= PLAUSIBLE["radial*v1"][1])}
    if name == "regime":
        return {"reads_as": "recuperation scale 1 + r (≈ η² with friction braking)", "value": 1.0 + r,
                "unit": "-", "plausible": bool(0.0 < 1.0 + r <= 1.0)}
    raise KeyError(name)


def select_physical(x, y, use, dt, trip, base_terms, candidates=tuple(PHYSICAL_CANDIDATES),
                    k: int = 5, energy: str = "traction") -> dict:
    """Forward selection of physical candidates on whole training trips.

    A candidate is added when, with those chosen before, it lowers the trip-grouped k-fold
    cross-validated mean absolute trip traction-energy error (:func:`trip_cv`) by at least
    :data:`MIN_GAIN`, lowers the
    error on more than half of the trips, significantly (one-sided Wilcoxon signed-rank test
    of the per-trip absolute errors, p < :data:`ALPHA`), and its coefficient fitted on all
    trips reads plausibly (:func:`candidate_reading`); the best such candidate enters first.

    Parameters
    ----------
    x, y, use, dt, trip : inputs, measured power [W], usable mask, sample duration [s] and
        trip id per sample (the training trips only)
    base_terms : the declared terms (e.g. acc, aero, roll, grade)
    energy : "traction" or "net": the trip energy whose error is judged (:func:`trip_cv`)

    Returns ``{"chosen", "terms", "regime", "steps": [{candidate, cv, helped, trips, reading,
    accepted, why}], "base_cv", "energy"}``.
    """
    from sumo_drvpw.model.terms import term_matrix

    y = np.asarray(y, float)
    chosen: list[str] = []
    cur = trip_cv(x, y, use, dt, trip, base_terms, k=k, energy=energy)
    out = {"base_cv": cur, "steps": [], "chosen": chosen, "energy": energy}
    rho = float(np.nanmean(np.asarray(x.rho, float)[use]))
    # a candidate whose added terms are 0 on every sample (no yaw rate, no temperature logged)
    # has nothing to fit: not tried
    left = [c for c in candidates if all(np.any(term_matrix([t], x)[np.asarray(use, bool), 0] != 0)
                                         for t in PHYSICAL_CANDIDATES[c][2])]
    while left:
        trials = []
        for c in left:
            terms, regime = _terms_of(base_terms, chosen + [c])
            cv = trip_cv(x, y, use, dt, trip, terms, regime, k=k, energy=energy)
            common = [t for t in cv["errors"]
                      if np.isfinite(cv["errors"][t]) and np.isfinite(cur["errors"].get(t, np.nan))]
            d = np.array([abs(cur["errors"][t]) - abs(cv["errors"][t]) for t in common])
            helped = int((d > 0).sum())
            pval = float(wilcoxon(d, alternative="greater").pvalue) if np.any(d != 0) else 1.0
            trials.append((cv["mean_abs_error"], c, cv, (helped, pval), terms, regime))
        trials.sort(key=lambda z: z[0])
        step_done = False
        for mean, c, cv, (helped, pval), terms, regime in trials:
            X = term_matrix(terms, x)
            ok = np.asarray(use, bool) & np.all(np.isfinite(X), axis=1) & np.isfinite(y)
            b, r = regime_fit(X[ok], y[ok], regime)
            reading = candidate_reading(c, dict(zip(terms, b)), r, rho)
            n = len(cv["errors"])
            why = []
            if mean > cur["mean_abs_error"] - MIN_GAIN:
                why.append("does not lower the cross-validated trip-energy error by "
                           f"{100 * MIN_GAIN:g} percentage point")
            if helped * 2 <= n:
                why.append(f"helps on only {helped} of {n} trips")
            if pval >= ALPHA:
                why.append(f"gain over trips not significant (Wilcoxon p = {pval:.2g})")
            if not reading["plausible"]:
                why.append(f"implausible {reading['reads_as']} = {reading['value']:.4g}")
            step = {"candidate": c, "cv": cv, "helped": helped, "trips": n, "p_value": pval, "reading": reading,
                    "accepted": not why, "why": "; ".join(why), "after": list(chosen)}
            out["steps"].append(step)
            if not why:
                chosen.append(c)
                left.remove(c)
                cur = cv
                step_done = True
                break
        if not step_done:
            break
    out["terms"], out["regime"] = _terms_of(base_terms, chosen)
    out["cv"] = cur
    return out
