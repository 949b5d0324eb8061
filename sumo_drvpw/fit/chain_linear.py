"""Closing the loop on an energy chain: what a battery or fuel target adds to a declared chain.

The residual tracer (:mod:`sumo_drvpw.fit.diagnose`) is linear in its terms; an energy
chain is not (traction and recuperation go through different efficiencies, braking
beyond a limit goes to the friction brakes, the engine of a hybrid switches off). This
module linearises the chain at the declared equation and chain, so that every effect is
a column in the target's own watts (battery W, or fuel W at the lower heating value), and
runs a forward search over physically defined effects on held-out data.

Linearisation at the declared coefficients (P = the declared road load's driving power)::

    battery:  g_wheel = 1/η_t(v, P)  where P > 0
                      = η_r(v, P)    where −P_lim ≤ P ≤ 0
                      = 0            where P < −P_lim (friction brakes)
              g_aux   = 1
    fuel:     g_wheel = (on·[P > 0] + η_rt·[−P_lim < P < 0])/(η_t·η_m),   g_aux = on/η_m
              (on: engine state; η_rt: a hybrid's recuperation_round_trip, else 0)

A change δP of driving power changes the target by g_wheel·δP; an auxiliary load L by
g_aux·L. A chain with a battery state (a hybrid's window ``battery_usable_j``, a plug-in's
``[chain.depleting]``: :func:`stateful`) is evaluated with each sample's duration through each
trip, and its gains are central differences of ±1 W along the battery's path. The declared chain's own prediction is the baseline (nothing refitted: the
loop starts from what was calibrated elsewhere, e.g. on a dynamometer).

Candidate effects (each a column, or a family profiled over one parameter):

* ``grade`` — m·g·v·sin θ through the chain (the declared road load has no grade term,
  as one calibrated on a dynamometer) with coefficient 1, fixed (potential energy is exact
  at the wheels; a free coefficient would absorb attenuated grade from coarse elevation and
  under-book every climb in SUMO — what it would read is reported as ``free_coefficient``);
* ``aux_power_w`` — a constant auxiliary power [W] (g_aux);
* ``standstill_aux_w`` — battery chains: auxiliary power only while standing (v < 0.1 m/s) [W];
* ``recuperation_limit_w`` — braking power beyond P_lim goes to the friction brakes:
  column η_r·(max(P, −P_lim) − max(P, −P_lim,declared)) with coefficient 1, P_lim
  profiled over quantiles of the braking power on the training data of each fold;
* ``fuel_cut_below_w`` — fuel chains whose engine runs in overrun: an overrun fuel cut-off
  (moving with P below P_cut, no fuel), the column the prediction with the cut-off less
  the prediction without, with coefficient 1, P_cut on a grid of −5 … 0 kW;
* ``moving_idle_fuel_power_w`` — fuel chains on logs that stand and move: fuel at zero output
  while moving above the idle fuel (an engine's friction at road speed), column 1 where the
  engine runs and the vehicle moves; refused below the idle fuel;
* ``traction_efficiency`` / ``recuperation_efficiency`` — the chain's efficiency differs
  (column P/η_t for P > 0, resp. η_r·P for P < 0; coefficient c → η_t/(1 + c), η_r·(1 + c));
* ``hvac`` — heating and cooling power over the ambient temperature, max(T_set − T, 0)
  and max(T − T_set, 0) [W/K], T_set = 20 °C (the chain's default set-point, not fitted);
* ``loads.COLUMN`` — a logged load (role ``load``) the chain lacks [W/W].

Validation and the test: as the tracer — with ≥ 3 trips the folds are whole trips
(leave-one-trip-out up to 10 trips, else 5 groups), otherwise 60-s blocks interleaved
within trips; the unit of the test is the held-out block: d_b = SSE_b(model) −
SSE_b(model + candidate), one-sided paired test (:func:`sumo_drvpw.fit.diagnose.paired_test`)
Bonferroni-corrected over the candidates of the round, relative held-out RMSE gain ≥
``min_gain``; then the finding must lower the held-out error on more than half of the
trips (≥ 3 trips) and be physically plausible (efficiencies in (0, 1], powers ≥ 0, grade
total auxiliary power while standing ≥ 0). Samples are weighted by their duration; standing samples count
(the battery draws auxiliary power there).

The closed loop: each accepted finding is written into the equation (grade) or the chain
(auxiliary, standstill, limit, efficiencies, HVAC, loads); the closed equation is an
ordinary equation file with a ``[chain]`` that ``compare`` and SUMO runs take unchanged.
Before/after per trip is computed with the exact (nonlinear) chain: before = declared,
after = the closed equation of the fold that held the trip out. A target of a BMS's energy
counters sees the model as they book it (:func:`~sumo_drvpw.fit.chain_effects.through_counters`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.chain import chain_target
from sumo_drvpw.fit.compare import metrics as _metrics, trip_net_energy
from sumo_drvpw.fit.diagnose.options import check_validation
from sumo_drvpw.model.chain import EnergyChain
from sumo_drvpw.model.chain_plugin import fuel_share
from sumo_drvpw.model.chain_values import engine_demand, zero_output_fuel
from sumo_drvpw.model.constants import STANDSTILL_MPS
from sumo_drvpw.model.equations import Equation
from sumo_drvpw.model.terms import term_matrix
from sumo_drvpw.fit.chain_blocks import Blocks, full_fit, heldout
from sumo_drvpw.fit.chain_effects import (_eta as _eff, best_variant, candidates as _candidates, seen_candidates,
                                          through_counters)
from sumo_drvpw.fit.chain_search import close, fold_equations, report_doc, rms, search

METRIC_KEYS = ("rmse_w", "mae_w", "r2", "bias_w")


@dataclass
class ChainTraceOptions:
    """Settings of :func:`trace_chain` (library messages name these fields)."""

    block_s: float = 60.0
    folds: int = 5
    alpha: float = 0.05
    min_gain: float = 0.01
    max_findings: int = 6
    validation: str = "auto"   # auto | trip | blocks
    include: tuple = ()  # glob patterns: offer only these columns as loads (unknown role too)
    exclude: tuple = ()  # never these
    skip_effects: tuple = ()  # candidate effects never offered (e.g. ones that did not replicate)

    def check(self):
        check_validation(self)


@dataclass
class ChainTraceResult:
    """What :func:`trace_chain` found: the report (JSON-ready) and the closed equation."""

    report: dict
    equation: Equation
    declared: Equation
    heldout_pred_w: np.ndarray = None
    mask: np.ndarray = None


# ------------------------------------------------------------------ linearisation

def predict(equation: Equation, inputs, signals=None, dt_s=None) -> np.ndarray:
    """The equation's target power [W] (its chain applied to its driving power); ``dt_s``
    [s] given, a hybrid's battery (window, plug-in) carried through each of ``inputs.trip``."""
    x = inputs.with_mass(equation.mass_kg) if equation.mass_kg else inputs
    p = equation.power(x)
    if equation.chain is None:
        return p
    sig = inputs.signals if signals is None else signals
    if dt_s is None:
        return equation.chain.evaluate(p, inputs.v, signals=sig)["power_w"]
    return equation.chain.evaluate(p, inputs.v, dt_s, sig, inputs.trip)["power_w"]


def stateful(chain: EnergyChain) -> bool:
    """Whether a chain carries a battery from sample to sample (``battery_usable_j``,
    ``[chain.depleting]``): its evaluation needs durations and trips."""
    return chain.battery_usable_j is not None or chain.depleting is not None


def gains(chain: EnergyChain, p_w, v_mps, signals=None, dt_s=None, trip=None) -> tuple[np.ndarray, np.ndarray]:
    """(g_wheel, g_aux): the target's change per W of driving power and per W of
    auxiliary load at driving power ``p_w`` [W] and speed ``v_mps`` [m/s] (module docstring);
    a fuel chain's warm-running factor at the air temperature of ``signals`` included. A
    chain with a battery state (:func:`stateful`; ``dt_s`` [s] and ``trip`` carry it): central
    differences of ±1 W on every sample, the battery's path followed (a full window credits no
    more braking; a plug-in on its battery burns no fuel: gain 0 there)."""
    p = np.asarray(p_w, float)
    v = np.broadcast_to(np.asarray(v_mps, float), p.shape)
    if stateful(chain):
        import dataclasses

        f = lambda ch, dp: ch.evaluate(p + dp, v, dt_s, signals, trip)["power_w"]  # noqa: E731
        aux = lambda da: dataclasses.replace(chain, aux_power_w=chain.aux_power_w + da)  # noqa: E731
        return (f(chain, 1.0) - f(chain, -1.0)) / 2.0, (f(aux(1.0), 0.0) - f(aux(-1.0), 0.0)) / 2.0
    if chain.motor is not None:  # SUMO's MMPEVEM motor: its slopes by central differences of ±1 W
        f = lambda dp, da: chain.evaluate(p + dp, v, signals=signals)["power_w"] if da == 0 else (  # noqa: E731
            chain.motor.battery(p, v, signals, chain.auxiliary(p.size, signals) + da)["power_w"])
        return (f(1.0, 0) - f(-1.0, 0)) / 2.0, (f(0.0, 1.0) - f(0.0, -1.0)) / 2.0
    if chain.predicts == "fuel":
        rf = chain.running_factor(p.size, signals)
        paid = chain.paid(p, v).astype(float) * rf
        # a hybrid's braking energy given back (recuperation_round_trip): η_rt up to P_lim
        lim = np.inf if chain.recuperation_limit_w is None else chain.recuperation_limit_w
        back = chain.recuperation_round_trip * rf * ((p < 0) & (p > -lim))
        gw = (paid * (p > 0) + back) / (_eff(chain.traction_efficiency, v, p) * chain.marginal_efficiency)
        within = ~over_rated(chain, p, v, signals)  # beyond its rated output more demand books nothing
        return gw * np.where(p > 0, within, 1.0), paid * within / chain.marginal_efficiency
    lim = np.inf if chain.recuperation_limit_w is None else chain.recuperation_limit_w
    gw = np.where(p > 0, 1.0 / _eff(chain.traction_efficiency, v, p),
                  np.where(p >= -lim, _eff(chain.recuperation_efficiency, v, p), 0.0))
    return gw, np.ones_like(p)


def over_rated(chain: EnergyChain, p, v, signals=None) -> np.ndarray:
    """Where a fuel chain's engine output demand reaches its rated output (``engine_max_w``):
    fuel booked at the rating, the target's change per W of demand 0; False everywhere without one."""
    if chain.engine_max_w is None:  # (nothing to evaluate)
        return np.zeros(np.shape(p), bool)
    return engine_demand(chain, p, v, signals).at_rating  # (the model's one engine formula)


def linearised_columns(equation: Equation, inputs, dt_s=None) -> tuple[dict, np.ndarray]:
    """Columns [W of target] whose sum is the chain's prediction at the declared coefficients.

    Returns ({name: column}, offset): each road-load term's power × g_wheel, the chain's
    auxiliary power (constant, loads, HVAC, standstill) × g_aux (× the fuel chain's idle
    fuel power where on), and the offset that is no column's (the braking power beyond
    the limit, booked at −η_r·P_lim). Σ columns + offset equals :func:`predict` exactly
    where the chain is linear in P between regime changes (the test checks it).
    """
    ch = equation.chain
    x = inputs.with_mass(equation.mass_kg) if equation.mass_kg else inputs
    p = equation.power(x)
    gw, ga = gains(ch, p, inputs.v, inputs.signals, dt_s, inputs.trip)
    names = equation.term_names
    tm = term_matrix(names, x)
    cols = {t: gw * tm[:, j] * equation.terms[t] for j, t in enumerate(names)}
    n = p.size
    if ch.predicts == "fuel":
        aux = ch.auxiliary(n, inputs.signals)
        cols["aux"] = ga * aux
        rf = ch.running_factor(n, inputs.signals)
        cols["idle_fuel_power_w"] = ch.engine_on(p, inputs.v) * rf * zero_output_fuel(
            ch.idle_fuel_power_w, ch.moving_idle_fuel_power_w, inputs.v, STANDSTILL_MPS)
        if stateful(ch):  # (a plug-in's engine idles only on its share on fuel: the idle fuel's own part)
            import dataclasses

            f = lambda c: c.evaluate(p, inputs.v, dt_s, inputs.signals, inputs.trip)["power_w"]  # noqa: E731
            cols["idle_fuel_power_w"] = f(ch) - f(dataclasses.replace(
                ch, idle_fuel_power_w=0.0, moving_idle_fuel_power_w=None if ch.moving_idle_fuel_power_w is None else 0.0))
        # at the rated output the booking is the rated output's, no column's (a plug-in's: on its share on fuel)
        over = over_rated(ch, p, inputs.v, inputs.signals)
        off = np.where(over, ch.paid(p, inputs.v) * rf * (ch.engine_max_w or 0.0) / ch.marginal_efficiency
                       * fuel_share(ch, p, inputs.v, dt_s, inputs.signals, inputs.trip), 0.0)
        if ch.recuperation_round_trip and ch.recuperation_limit_w is not None and not stateful(ch):
            # a hybrid's braking beyond its limit gives back the limit's energy, no column's
            off = off - np.where(p < -ch.recuperation_limit_w, ch.recuperation_round_trip * rf * ch.recuperation_limit_w
                                 / (_eff(ch.traction_efficiency, inputs.v, p) * ch.marginal_efficiency), 0.0)
        return cols, off
    aux = ch.auxiliary(n, inputs.signals) + ch.standstill_aux_w * (inputs.v < STANDSTILL_MPS)
    cols["aux"] = ga * aux
    off = np.zeros(n)
    if ch.recuperation_limit_w is not None:
        beyond = p < -ch.recuperation_limit_w
        off = np.where(beyond, -_eff(ch.recuperation_efficiency, inputs.v, p) * ch.recuperation_limit_w, 0.0)
    return cols, off


# ------------------------------------------------------------------ the samples in memory

class _Memory:
    """The search's engine on every sample's columns (:mod:`sumo_drvpw.fit.chain_search`)."""

    def __init__(self, bl: Blocks, w, r, pred0):
        self.bl, self.w, self.r = bl, w, r
        self.sw = float(w.sum())
        self.e_pred = float(np.sum(w * pred0))

    def cols(self, acc):
        """(Z, fixed) of the model ``acc``."""
        n = self.r.size
        Z, fx = np.zeros((n, 0)), np.zeros(n)
        for c, vi in acc:
            var = c.variants[vi]
            if var[0] is not None:
                Z = np.column_stack([Z, var[0]])
            if var[1] is not None:
                fx = fx + var[1]
        return Z, fx

    def score(self, acc, pool):
        Z, fx = self.cols(acc)
        out = []
        for c in pool:
            if c is None:
                t_v, Zc = [self.r - fx], Z
            elif c.variants[0][0] is None:       # a fixed column profiled over its parameter
                t_v, Zc = [self.r - fx - v[1] for v in c.variants[:c.grid]], Z
            else:
                t_v, Zc = [self.r - fx], np.column_stack([Z, c.variants[0][0]])
            out.append(heldout(self.bl, Zc, t_v)[:2])
        return out

    def _rows(self, fold):
        return slice(None) if fold is None else self.bl.sample_fold(self.r.size) != fold

    def best_variant(self, acc, c, fold):
        Z, fx = self.cols(acc)
        return best_variant(self.w, Z, self.r - fx, c, self._rows(fold))

    def fit(self, acc, fold):
        Z, fx = self.cols(acc)
        rows = self._rows(fold)
        return full_fit(self.w[rows], Z[rows], (self.r - fx)[rows])[:2]

    def free_coef(self, acc, c, vi):
        Z, fx = self.cols(acc)
        return float(full_fit(self.w, np.column_stack([Z, c.variants[vi][1]]), self.r - fx)[0][-1])

    def contrib_j(self, c, vi, coef):
        var = c.variants[vi]
        contrib = (var[0] @ coef if var[0] is not None else 0.0) + (0.0 if var[1] is None else var[1])
        return float(np.sum(self.w * contrib))


def _pick(m) -> dict:
    return {k: m[k] for k in METRIC_KEYS if k in m}


def check_chain_equation(equation: Equation, target: str) -> None:
    """Raise :class:`UserError` unless ``equation`` carries a chain predicting ``target``."""
    ch = equation.chain
    if ch is None or ch.predicts != target:
        raise UserError(f"equation '{equation.name}' has {'no energy chain' if ch is None else 'a chain that predicts ' + ch.predicts}; tracing the {target} target needs an "
                        f"equation whose [chain] predicts {target} (calibrate one with that target first)")
    if target not in ("battery", "fuel"):
        raise UserError(f"chain trace: target must be battery or fuel, got '{target}'")
    ch.require_complete()


def chain_samples(m, equation: Equation):
    """(the usable samples with finite target, driving power, prediction and weight, the
    driving power [W], the target [W], the declared chain's prediction [W], the weights [s])
    of a :class:`~sumo_drvpw.data.measured.Measured` (or a batch of it)."""
    x = m.inputs.with_mass(equation.mass_kg) if equation.mass_kg else m.inputs
    p = equation.power(x)
    y_all = chain_target(m, equation.chain)
    dt_all = m.log.df["dt_s"].to_numpy(float)
    pred0_all = predict(equation, m.inputs, dt_s=dt_all if stateful(equation.chain) else None)
    ok = m.usable & np.isfinite(y_all) & np.isfinite(pred0_all) & np.isfinite(p) & np.isfinite(dt_all)
    return ok, p, y_all, pred0_all, dt_all


def trace_chain(m, equation: Equation, opt: ChainTraceOptions | None = None, progress=None,
                mask=None) -> ChainTraceResult:
    """Trace what a battery or fuel target adds to a declared equation with an energy chain.

    Parameters
    ----------
    m : :class:`sumo_drvpw.data.measured.Measured` with ``target`` battery or fuel
    equation : declared equation whose ``chain`` predicts ``m.target`` (kept as it is: the
        baseline; findings are added on top)
    opt : :class:`ChainTraceOptions`
    progress : optional callable(str)
    mask : optional boolean array: trace on these samples only (e.g. the training trips)

    Returns a :class:`ChainTraceResult`: ``report`` (baseline and final held-out metrics,
    findings with coefficient, unit and physical reading, per-trip net energy before and
    after on held-out trips) and ``equation``, the closed equation with its chain.
    """
    opt = opt or ChainTraceOptions()
    opt.check()
    say = progress or (lambda s: None)
    check_chain_equation(equation, m.target)
    ok, p, y_all, pred0_all, dt_all = chain_samples(m, equation)
    if mask is not None:
        ok &= np.asarray(mask, bool)
    idx = np.flatnonzero(ok)
    if idx.size < 50:
        raise UserError(f"{m.log.describe()}: only {idx.size} samples with finite measured {m.target} power, "
                        "driving power and chain prediction; need at least 50")
    trip_names, trip = np.unique(m.log.df["trip_id"].astype(str).to_numpy()[idx], return_inverse=True)
    t = m.log.df["time_s"].to_numpy(float)[idx]
    y, pred0, w = y_all[idx], pred0_all[idx], dt_all[idx]
    see = through_counters(m, idx, y_all.size)
    pred0 = pred0 if see is None else m.counter_view(pred0_all)[idx]  # as the counters book it
    r = y - pred0
    bl = Blocks(r, w, trip, t, opt)
    cands = _candidates(m, equation, p, idx, opt, left_out := {})  # (columns not offered, and why)
    cands = cands if see is None else seen_candidates(cands, see)
    say(f"{idx.size} samples, {len(trip_names)} trip(s), {bl.n_blocks} blocks; {len(cands)} candidate effects; "
        f"validation: {bl.how}")
    eng = _Memory(bl, w, r, pred0)
    findings, rounds, rejected, accepted, base_stats, cur_stats = search(eng, equation, cands, opt, trip_names, say)
    closed = close(eng, equation, accepted, findings, m.target, m.log.files)
    # held-out, exact: each fold's closed equation predicts the samples it held out
    sfold = bl.sample_fold(idx.size)
    held = np.full(idx.size, np.nan)
    sub_inputs = m.inputs.take(idx)
    for k, eq in enumerate(fold_equations(eng, equation, accepted)):
        # (a battery's state through every sample of each trip, as the baseline's)
        pk = predict(eq, m.inputs, dt_s=dt_all)[idx] if stateful(eq.chain) else predict(eq, sub_inputs)
        held[sfold == k] = pk[sfold == k]
    held = held if see is None else see(held)
    trips = trip_names[trip]
    report = report_doc(m.target, equation, closed, bl, idx.size, trip_names, equation.chain.unknown_inputs(
        {k: np.asarray(v)[idx] if np.ndim(v) else v for k, v in m.inputs.signals.items()}, idx.size, trips),
        _metric_doc(pred0, y, base_stats), _metric_doc(held, y, cur_stats, w.sum()),
        trip_net_energy(pred0, y, w, trips), trip_net_energy(held, y, w, trips), findings, rounds, rejected, cands)
    report["columns_left_out"] = left_out
    return ChainTraceResult(report, closed, equation, held, ok)


def _metric_doc(pred, y, stats, sw=None) -> dict:
    """Metrics of a prediction with the block energy RMS (and, ``sw`` given, the held-out
    linear RMSE) of its per-block ``stats``."""
    doc = _pick(_metrics(pred, y))
    if sw is not None:
        doc["rmse_heldout_linear_w"] = math.sqrt(stats[0].sum() / sw)
    doc["block_energy_rms_j"] = rms(stats[1])
    return doc


def close_loop_heldout(m, equation: Equation, opt: ChainTraceOptions | None = None, progress=None) -> dict:
    """Leave-one-trip-out: trace on the other trips, predict the left-out trip with the closed
    equation (exact chain); per trip net energy before (declared) and after.

    Returns ``{"trips": {TRIP: {"measured_j", "before_j", "after_j", "before", "after",
    "findings": {effect: value}}}, "mean_abs_error_before", "mean_abs_error_after",
    "found_on": {effect: number of folds}}`` (errors = predicted/measured − 1).
    """
    say = progress or (lambda s: None)
    check_chain_equation(equation, m.target)
    trips = m.log.df["trip_id"].astype(str).to_numpy()
    dt = m.log.df["dt_s"].to_numpy(float)
    y = chain_target(m, equation.chain)
    pred0 = predict(equation, m.inputs, dt_s=dt if stateful(equation.chain) else None)
    out, found = {}, {}
    for t in dict.fromkeys(trips):
        test = trips == t
        res = trace_chain(m, equation, opt, mask=~test)
        use = test & m.usable & np.isfinite(y)
        pred1 = predict(res.equation, m.inputs, dt_s=dt if stateful(res.equation.chain) else None)
        e_m = float(np.sum((y * dt)[use]))
        e0, e1 = float(np.sum((pred0 * dt)[use])), float(np.sum((pred1 * dt)[use]))
        fnd = {f["term"]: (f["parameter"] if f["coefficient"] is None else f["coefficient"])
               for f in res.report["findings"]}
        for k in fnd:
            found[k] = found.get(k, 0) + 1
        out[t] = {"measured_j": e_m, "before_j": e0, "after_j": e1, "before": e0 / e_m - 1 if e_m else math.nan,
                  "after": e1 / e_m - 1 if e_m else math.nan, "findings": fnd,
                  "closed_chain": res.equation.chain.to_dict(), "closed_terms": dict(res.equation.terms)}
        say(f"held out {t}: before {100 * out[t]['before']:+.1f} %, after {100 * out[t]['after']:+.1f} % "
            f"({', '.join(fnd) or 'nothing found'})")
    err = lambda k: float(np.nanmean([abs(r[k]) for r in out.values()]))  # noqa: E731
    return {"trips": out, "mean_abs_error_before": err("before"), "mean_abs_error_after": err("after"),
            "found_on": found}
