"""The effects a road (or any new data) can add to an energy chain, as target-watt columns.

Physical candidates of :func:`sumo_drvpw.fit.chain_linear.trace_chain` (its docstring
lists them with their columns) and :func:`apply`, which writes a found effect into the
equation or its chain and gives its physical reading, or refuses an implausible value.
"""

from __future__ import annotations

import copy
import fnmatch
import math
from dataclasses import dataclass, field

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.chain import Table
from sumo_drvpw.model.constants import STANDSTILL_MPS
from sumo_drvpw.model.equations import Equation
from sumo_drvpw.model.terms import term_matrix

#: quantiles of the braking power at which a recuperation limit is profiled
LIMIT_QUANTILES = (0.5, 0.7, 0.8, 0.9, 0.95, 0.98)
#: HVAC set-point of the ``hvac`` candidate [°C] (the chain's default)
HVAC_SETPOINT_C = 20.0
#: driving powers [W] at which an overrun fuel cut-off is profiled (``fuel_cut_below_w``)
FUEL_CUT_GRID_W = (-5000.0, -3000.0, -2000.0, -1500.0, -1000.0, -500.0, 0.0)
#: moving samples below a cut-off power it needs to be offered at that power
FUEL_CUT_MIN_SAMPLES = 20


@dataclass
class Cand:
    """A candidate effect: variants (free columns n×k, fixed column or None, parameter)."""

    name: str
    effect: str
    role: str
    unit: str
    variants: list = field(default_factory=list)
    #: for a fixed column profiled over its parameter: parameter → column, refined between
    #: the grid's points by :func:`best_variant` (the grid is the first ``grid`` variants)
    profile: object = None
    grid: int = 0

    def __post_init__(self):
        self.grid = self.grid or len(self.variants)


def _load_columns(m, ch, opt) -> list:
    """Logged loads the chain may lack: columns of role load, or named by ``opt.include``,
    not among the chain's loads, in the order of the log's signals."""
    from sumo_drvpw.data.roles import of_log

    roles = of_log(m.log)
    inc = tuple(getattr(opt, "include", ()) or ())
    return [col for col in (m.inputs.signals or {}) if col not in ch.loads and (
        any(fnmatch.fnmatchcase(col, g) for g in inc) or roles.get(col, {}).get("role") == "load")]


def offer_stats(m, equation: Equation, p, idx, opt=None, braking: bool = True) -> dict:
    """What decides which candidates :func:`candidates` offers, as counts, extremes and
    flags over the samples ``idx`` (of ``m``, driving power ``p`` [W]); of several batches
    of whole trips merged by :func:`merge_offer` (``braking``: keep the braking powers the
    recuperation limits are quantiles of; the streamed tracer, which does not, finds those
    quantiles exactly from binned counts and gives them to :func:`decide` as
    ``brake_quantiles``)."""
    from sumo_drvpw.fit.chain_linear import gains

    ch = equation.chain
    x = m.inputs.with_mass(equation.mass_kg) if equation.mass_kg else m.inputs
    v, pp = x.v[idx], p[idx]
    sig = m.inputs.signals or {}
    th = np.asarray(x.theta, float)[idx]
    th = th[np.isfinite(th)]
    brake = -pp[pp < 0]
    st = {"n": int(idx.size), "theta": [float(th.min()), float(th.max())] if th.size else [np.inf, -np.inf],
          "standing": int(np.sum(v < STANDSTILL_MPS)), "brake_n": int(brake.size),
          "brake_max": float(brake.max()) if brake.size else -np.inf, "brake": [brake] if braking else [],
          "fuel_cut": {}, "ambient": None, "loads": {}}
    if ch.predicts == "fuel" and ch.fuel_cut_below_w is None and ch.idle_fuel_power_w > 0:
        s = {k: np.asarray(a)[idx] for k, a in sig.items()}
        st["fuel_cut"] = {c: [n, bool(np.any(col != 0))] for c, n, col in _fuel_cut_counts(ch, pp, v, s,
                                                                                           state=_state(m, ch, idx))}
    if "ambient_c" in sig:
        col = ch.temperature_column
        _, ga = gains(ch, pp, v, {col: np.asarray(sig[col])[idx]} if col in sig else None, *_state(m, ch, idx))
        t = np.asarray(sig["ambient_c"], float)[idx]
        fin = t[np.isfinite(t)]
        st["ambient"] = {"bad": int(t.size - fin.size), "lo": float(fin.min()) if fin.size else np.inf,
                         "hi": float(fin.max()) if fin.size else -np.inf,
                         "heat": bool(np.any(ga * np.maximum(HVAC_SETPOINT_C - t, 0.0) > 0)),
                         "cool": bool(np.any(ga * np.maximum(t - HVAC_SETPOINT_C, 0.0) > 0))}
    for col in _load_columns(m, ch, opt):
        L = np.asarray(sig[col], float)[idx]
        fin = L[np.isfinite(L)]
        st["loads"][col] = [int(L.size - fin.size), float(fin.min()) if fin.size else np.inf,
                            float(fin.max()) if fin.size else -np.inf]
    return st


def merge_offer(a: dict | None, b: dict) -> dict:
    """Two :func:`offer_stats` of disjoint samples as one (a column a batch lacks: unknown there)."""
    if a is None:
        return b
    lo_hi = lambda x, y: [min(x[0], y[0]), max(x[1], y[1])]  # noqa: E731
    out = {"n": a["n"] + b["n"], "theta": lo_hi(a["theta"], b["theta"]), "standing": a["standing"] + b["standing"],
           "brake_n": a["brake_n"] + b["brake_n"], "brake_max": max(a["brake_max"], b["brake_max"]),
           "brake": a["brake"] + b["brake"],
           "fuel_cut": {c: [a["fuel_cut"].get(c, [0, False])[0] + b["fuel_cut"].get(c, [0, False])[0],
                            a["fuel_cut"].get(c, [0, False])[1] or b["fuel_cut"].get(c, [0, False])[1]]
                        for c in dict.fromkeys([*a["fuel_cut"], *b["fuel_cut"]])}}
    amb = [x["ambient"] or {"bad": x["n"], "lo": np.inf, "hi": -np.inf, "heat": False, "cool": False}
           for x in (a, b)]
    out["ambient"] = None if a["ambient"] is None and b["ambient"] is None else {
        "bad": amb[0]["bad"] + amb[1]["bad"], "lo": min(amb[0]["lo"], amb[1]["lo"]),
        "hi": max(amb[0]["hi"], amb[1]["hi"]), "heat": amb[0]["heat"] or amb[1]["heat"],
        "cool": amb[0]["cool"] or amb[1]["cool"]}
    out["loads"] = {}
    for col in dict.fromkeys([*a["loads"], *b["loads"]]):
        x, y = (s["loads"].get(col, [s["n"], np.inf, -np.inf]) for s in (a, b))
        out["loads"][col] = [x[0] + y[0], min(x[1], y[1]), max(x[2], y[2])]
    return out


def decide(st: dict, equation: Equation, opt=None, left_out: dict | None = None) -> dict:
    """Which candidates are offered (and at which grid values) from :func:`offer_stats`;
    those left out, and why, go into ``left_out``."""
    ch = equation.chain
    left_out = {} if left_out is None else left_out
    n = max(st["n"], 1)
    d = {"grade": "grade" not in equation.terms and st["theta"][1] > st["theta"][0],
         "fuel_cut": [c for c in FUEL_CUT_GRID_W if c in st["fuel_cut"]
                      and st["fuel_cut"][c][0] >= FUEL_CUT_MIN_SAMPLES and st["fuel_cut"][c][1]],
         "standstill": 0.01 < st["standing"] / n < 0.99, "limits": [], "hvac": None, "loads": []}
    lim0 = np.inf if ch.recuperation_limit_w is None else ch.recuperation_limit_w
    if ch.predicts == "battery" and st["brake_n"] > 50 and ch.motor is None:
        qv = st.get("brake_quantiles")  # (exact, from binned counts: the streamed trace's)
        if qv is None:
            brake = np.concatenate(st["brake"]) if st["brake"] else np.zeros(0)
            qv = [np.quantile(brake, q) for q in LIMIT_QUANTILES] if brake.size else []
        qs = sorted({float(x) for x in qv if x < lim0})
        d["limits"] = [L for L in qs if L > 0]
        d["limit_top"] = float(min(st["brake_max"], lim0))
    amb = st["ambient"]
    if ch.hvac is None and amb is None:  # said, so a log's own temperature is mapped to it
        left_out["ambient_c"] = ("no such column: the hvac candidate reads the air temperature as ambient_c "
                                 "(map the log's to it)")
    if ch.hvac is None and amb is not None:
        if not (amb["bad"] == 0 and amb["hi"] > amb["lo"]):
            left_out["ambient_c"] = ("the hvac candidate needs the air temperature on every sample, varying: "
                                     + ("constant" if amb["bad"] == 0 else
                                        f"no number on {amb['bad'] / n:.1%} of the samples"))
        else:
            d["hvac"] = tuple(k for k, on in enumerate((amb["heat"], amb["cool"])) if on)
    inc, exc = tuple(getattr(opt, "include", ()) or ()), tuple(getattr(opt, "exclude", ()) or ())
    for col, (bad, lo, hi) in st["loads"].items():
        named = any(fnmatch.fnmatchcase(col, g) for g in inc)
        if any(fnmatch.fnmatchcase(col, g) for g in exc):
            left_out[col] = "excluded (exclude option)"
        elif inc and not named:
            left_out[col] = "not among the offered columns (signals option)"
        elif bad:
            left_out[col] = (f"no number on {bad / n:.1%} of the samples: a load of the chain "
                             "needs one on every sample")
        elif not hi > lo:
            left_out[col] = "constant (the auxiliary power carries a constant load)"
        else:
            d["loads"].append(col)
    return d


def candidates(m, equation: Equation, p, idx, opt=None, left_out: dict | None = None,
               decided: dict | None = None) -> list[Cand]:
    """Physical candidates for the chain of ``equation`` on the samples ``idx``; logged loads:
    columns of role load, or named by ``opt.include`` (a column of unknown role too), less
    those ``opt.exclude`` names; those left out, and why, go into ``left_out``. Which are
    offered is :func:`decide`'s, on these samples' :func:`offer_stats` or ``decided`` (of
    all batches: the same candidates on each)."""
    from sumo_drvpw.fit.chain_linear import gains

    left_out = {} if left_out is None else left_out
    if decided is None:
        decided = decide(offer_stats(m, equation, p, idx, opt), equation, opt, left_out)
    ch = equation.chain
    x = m.inputs.with_mass(equation.mass_kg) if equation.mass_kg else m.inputs
    v = x.v[idx]
    pp = p[idx]
    col, sig = ch.temperature_column, m.inputs.signals or {}
    gw, ga = gains(ch, pp, v, {col: np.asarray(sig[col])[idx]} if col in sig else None, *_state(m, ch, idx))
    out = []
    if decided["grade"]:
        g = term_matrix(["grade"], x.take(idx))[:, 0]
        out.append(Cand("grade", "road grade m·g·v·sin θ through the chain (the declared road load has no grade "
                        "term: calibrated where the road is flat, e.g. on a dynamometer); coefficient 1 (potential "
                        "energy is exact at the wheels, the chain carries the efficiencies)", "structural", "-",
                        [(None, gw * g, 1.0)]))
    out.append(Cand("aux_power_w", "constant auxiliary power at the battery/engine the declared chain lacks",
                    "structural", "W", [(np.column_stack([ga]), None, None)]))
    if decided["fuel_cut"]:
        s = {k: np.asarray(a)[idx] for k, a in sig.items()}
        cut = [(None, col, c) for c, _, col in _fuel_cut_counts(ch, pp, v, s, decided["fuel_cut"], _state(m, ch, idx))]
        out.append(Cand("fuel_cut_below_w", "overrun fuel cut-off: moving with a driving power below the "
                        "cut-off, the wheels turn the engine and its injection is cut (profiled over "
                        f"{', '.join(f'{c / 1000:g}' for c in FUEL_CUT_GRID_W)} kW)", "structural", "W", cut))
    if ch.predicts == "fuel" and decided["standstill"]:
        out.append(moving_idle_candidate(ch, pp, v, {k: np.asarray(a)[idx] for k, a in sig.items()}, _state(m, ch, idx)))
    if ch.predicts == "battery":  # (SUMO's MMPEVEM motor has no η_t, η_r or limit of that kind: not offered)
        if decided["standstill"]:
            st = (v < STANDSTILL_MPS).astype(float)
            out.append(Cand("standstill_aux_w", "auxiliary power while standing (v < 0.1 m/s): HVAC, 12 V, "
                            "pumps of a waiting car", "structural", "W", [(np.column_stack([st]), None, None)]))
        eta_r = _eta(ch.recuperation_efficiency, v, pp)
        lim0 = np.inf if ch.recuperation_limit_w is None else ch.recuperation_limit_w
        if decided["limits"]:
            col = lambda L: eta_r * (np.maximum(pp, -L) - np.maximum(pp, -lim0))  # noqa: E731
            out.append(Cand("recuperation_limit_w", "a recuperation limit: braking power beyond it goes to the "
                            "friction brakes (profiled over quantiles of the braking power, refined between "
                            "them)", "structural", "W", [(None, col(L), L) for L in decided["limits"]],
                            profile=(col, decided["limit_top"])))
        if not isinstance(ch.recuperation_efficiency, Table) and ch.motor is None:
            rec = eta_r * np.maximum(np.minimum(pp, 0.0), -lim0)
            out.append(Cand("recuperation_efficiency", "recuperation efficiency differs from the declared chain's",
                            "structural", "-", [(np.column_stack([rec]), None, None)]))
    if not isinstance(ch.traction_efficiency, Table) and ch.motor is None:
        tra = gw * np.maximum(pp, 0.0)
        out.append(Cand("traction_efficiency", "traction efficiency differs from the declared chain's",
                        "structural", "-", [(np.column_stack([tra]), None, None)]))
    sig = x.signals
    if decided["hvac"] is not None:
        t = np.asarray(sig["ambient_c"], float)[idx]
        keep = decided["hvac"]
        c = [ga * np.maximum(HVAC_SETPOINT_C - t, 0.0), ga * np.maximum(t - HVAC_SETPOINT_C, 0.0)]
        out.append(Cand("hvac", f"heating/cooling power over the ambient temperature (set-point "
                        f"{HVAC_SETPOINT_C:g} °C)", "condition", "W/K",
                        [(np.column_stack([c[k] for k in keep]), None, tuple(keep))]))
    for col in decided["loads"]:
        L = np.asarray(sig[col], float)[idx]
        out.append(Cand(f"loads.{col}", f"logged load '{col}' the declared chain lacks", "load", "W/W",
                        [(np.column_stack([ga * L]), None, None)]))
    skip = set(getattr(opt, "skip_effects", ()) or ())
    for c in out:
        if c.name in skip:
            left_out[c.name] = "not offered (skip_effects option)"
    return [c for c in out if c.name not in skip]


def apply(equation: Equation, name: str, coef, param=None) -> tuple[Equation | None, str]:
    """The equation with finding ``name`` written in (a copy), and its physical reading;
    (None, reason) when the value is implausible."""
    eq = copy.deepcopy(equation)
    ch = eq.chain
    c = np.atleast_1d(np.asarray(coef, float))
    if name == "grade":
        eq.terms = dict(eq.terms, grade=float(param))
        return eq, f"grade term with coefficient {param:g} (m·g·v·sin θ at the wheels, through the chain)"
    if name == "aux_power_w":
        old, new = ch.aux_power_w, ch.aux_power_w + c[0]
        if new < 0:
            return None, f"auxiliary power would be negative ({new:.0f} W)"
        ch.aux_power_w = float(new)
        return eq, f"auxiliary power {old:.0f} W → {new:.0f} W ({c[0]:+.0f} W)"
    if name == "standstill_aux_w":
        new = ch.standstill_aux_w + c[0]
        if ch.aux_power_w + new < 0:
            return None, f"auxiliary power while standing would be negative ({ch.aux_power_w + new:.0f} W)"
        ch.standstill_aux_w = float(new)
        if new < 0:
            return eq, (f"auxiliary power while standing {ch.aux_power_w + new:.0f} W, {-new:.0f} W less than while "
                        "moving (drawn only while moving: drivetrain no-load losses, cooling, or road load the "
                        "declared equation lacks)")
        return eq, f"extra auxiliary power while standing {new:.0f} W"
    if name == "fuel_cut_below_w":
        if param is None or param > 0:
            return None, f"a fuel cut-off at a positive driving power ({param}) is no overrun"
        ch.fuel_cut_below_w = float(param)
        return eq, (f"overrun fuel cut-off below {param / 1000:g} kW of driving power while moving: the "
                    "wheels turn the engine, no fuel")
    if name == "moving_idle_fuel_power_w":
        return apply_moving_idle(eq, c[0])
    if name == "recuperation_limit_w":
        ch.recuperation_limit_w = float(param)
        return eq, f"braking power beyond {param / 1000:.1f} kW goes to the friction brakes"
    if name == "traction_efficiency":
        new = ch.traction_efficiency / (1.0 + c[0]) if c[0] > -1 else math.inf
        if not 0.5 <= new <= 1.0:
            return None, f"implausible traction efficiency {new:.3g}"
        ch.traction_efficiency = float(new)
        return eq, f"traction efficiency {new:.3f}"
    if name == "recuperation_efficiency":
        new = ch.recuperation_efficiency * (1.0 + c[0])
        if not 0.0 < new <= 1.0:
            return None, f"implausible recuperation efficiency {new:.3g}"
        ch.recuperation_efficiency = float(new)
        return eq, f"recuperation efficiency {new:.3f}"
    if name == "hvac":
        h = {"column": "ambient_c", "setpoint_c": HVAC_SETPOINT_C, "heating_w_per_k": 0.0, "cooling_w_per_k": 0.0}
        for k, val in zip(param, c):
            h[("heating_w_per_k", "cooling_w_per_k")[k]] = float(val)
        if h["heating_w_per_k"] < 0 or h["cooling_w_per_k"] < 0:
            return None, f"negative HVAC gain (heating {h['heating_w_per_k']:.0f}, cooling {h['cooling_w_per_k']:.0f} W/K)"
        ch.hvac = h
        return eq, f"heating {h['heating_w_per_k']:.0f} W/K below, cooling {h['cooling_w_per_k']:.0f} W/K above {HVAC_SETPOINT_C:g} °C"
    if name.startswith("loads."):
        if c[0] < 0:
            return None, f"negative load gain {c[0]:.3g}"
        ch.loads = dict(ch.loads, **{name[6:]: float(c[0])})
        return eq, f"{c[0]:.3f} W at the target per W logged"
    raise UserError(f"unknown chain effect '{name}'")


def moving_idle_candidate(ch, p, v, signals, state=(None, None)) -> Cand:
    """The fuel at zero output while moving above the idle fuel (``moving_idle_fuel_power_w``): its
    column is 1 W of fuel where the engine runs and the vehicle moves (times the warm-running factor);
    for a chain with a battery state (``state``: :func:`_state`), the chain's own change per W, as a
    plug-in's engine runs only on its share on fuel."""
    if state[0] is not None:
        import dataclasses

        base = ch.idle_fuel_power_w if ch.moving_idle_fuel_power_w is None else ch.moving_idle_fuel_power_w
        f = lambda c: c.evaluate(p, v, state[0], signals, state[1])["power_w"]  # noqa: E731
        col = f(dataclasses.replace(ch, moving_idle_fuel_power_w=base + 1.0)) - f(ch)
    else:
        col = (ch.engine_on(p, v) & (v >= STANDSTILL_MPS)) * ch.running_factor(p.size, signals)
    return Cand("moving_idle_fuel_power_w", "fuel at zero output while moving above the idle fuel: an engine "
                "turning at road speed has more friction than at idle (a heavy diesel's)", "structural", "W",
                [(np.column_stack([col]), None, None)])


def apply_moving_idle(eq: Equation, extra: float) -> tuple[Equation | None, str]:
    """``eq`` (a copy) with ``extra`` [W] more fuel at zero output while moving, or (None, why)."""
    ch = eq.chain
    new = (ch.idle_fuel_power_w if ch.moving_idle_fuel_power_w is None else ch.moving_idle_fuel_power_w) + extra
    if new < ch.idle_fuel_power_w:
        return None, (f"fuel at zero output while moving {new:.0f} W would be below the idle fuel "
                      f"{ch.idle_fuel_power_w:.0f} W (an engine at road speed has more friction, not less)")
    ch.moving_idle_fuel_power_w = float(new)
    return eq, (f"fuel at zero output while moving {new:.0f} W, {new - ch.idle_fuel_power_w:.0f} W above the idle "
                "fuel (friction at road engine speed)")


def _state(m, ch, idx) -> tuple:
    """(durations [s], trip ids) of the samples ``idx`` for a chain with a battery state
    (fit/chain_linear.stateful), else (None, None)."""
    from sumo_drvpw.fit.chain_linear import stateful

    if not stateful(ch):
        return None, None
    dt = m.log.df["dt_s"].to_numpy(float) if hasattr(m, "log") else m.dt  # (the streamed tracer's batch: its own)
    return np.asarray(dt, float)[idx], np.asarray(m.inputs.trip)[idx]


def _fuel_cut_counts(ch, p, v, signals, grid=None, state=(None, None)) -> list:
    """(cut-off, moving samples below it, column) of the overrun fuel cut-off at each power of
    :data:`FUEL_CUT_GRID_W` with a moving sample below it, or at each of ``grid``: the fuel
    chain's prediction with the cut-off less its prediction without (≤ 0); ``state``: the
    samples' (durations, trips) of a chain with a battery state (:func:`_state`)."""
    import dataclasses

    base = ch.evaluate(p, v, state[0], signals, state[1])["power_w"]
    moving = v > STANDSTILL_MPS
    out = []
    for c in FUEL_CUT_GRID_W if grid is None else grid:
        n = int(np.sum(moving & (p < c)))
        if n or grid is not None:
            out.append((c, n, dataclasses.replace(ch, fuel_cut_below_w=c).evaluate(p, v, state[0], signals, state[1])["power_w"]
                        - base))
    return out


def _eta(e, v, p):
    return e(v, p) if isinstance(e, Table) else np.full(np.shape(p), float(e))


def through_counters(m, idx, n):
    """None; or, for a target read from the BMS's energy counters (``m.counter_view``), a
    function giving columns on the samples ``idx`` (of ``n``) as the counters would book them
    (:class:`sumo_drvpw.data.counters.CounterView`; zero on the samples not in ``idx``), so
    the tracer fits its model as its target sees the battery: not biased by the spreading of
    the power between the counters' steps."""
    view = getattr(m, "counter_view", None)
    if view is None:
        return None

    def see(col):
        if col is None:
            return None
        a = np.asarray(col, float)
        full = np.zeros((n,) + a.shape[1:])
        full[idx] = np.nan_to_num(a)
        return view(full)[idx]
    return see


def seen_candidates(cands: list, see) -> list:
    """The candidates' columns, fixed columns and profiled columns through ``see``
    (:func:`through_counters`)."""
    for c in cands:
        c.variants = [(see(z), see(f), par) for z, f, par in c.variants]
        if c.profile is not None:
            col, top = c.profile
            c.profile = (lambda L, col=col: see(col(L)), top)
    return cands


def best_variant(w, Z, t, c: Cand, rows=slice(None)) -> int:
    """The variant of a candidate with the smallest weighted RSS of t − fixed ~ Z on ``rows``
    (:func:`refine`; a refined parameter is appended as a variant of its own)."""
    from sumo_drvpw.fit.chain_blocks import full_fit

    if len(c.variants) == 1 and c.profile is None:
        return 0
    rss = lambda col: full_fit(w[rows], Z[rows], (t - col)[rows])[2]  # noqa: E731
    i, L = refine(c, [rss(v[1]) for v in c.variants[:c.grid]], lambda L: rss(c.profile[0](L)))
    if L is None:
        return i
    c.variants.append((None, c.profile[0](L), L))
    return len(c.variants) - 1


def refine(c: Cand, scores: list, rss_at) -> tuple[int, float | None]:
    """(the best grid variant of ``c`` by its RSS ``scores``, None); for a candidate with a
    ``profile``, its parameter searched between the best grid point's neighbours (bounded
    scalar search of ``rss_at(parameter)``, to 0.5 % of it; a parameter's RSS is continuous in
    it): (that variant, the better parameter) when it beats the grid."""
    from scipy.optimize import minimize_scalar

    grid = c.variants[:c.grid]
    i = int(np.argmin(scores))
    if c.profile is None:
        return i, None
    top = c.profile[1]
    lo = grid[i - 1][2] if i > 0 else 0.5 * grid[0][2]
    hi = grid[i + 1][2] if i + 1 < len(grid) else top
    if not hi > lo:
        return i, None
    res = minimize_scalar(rss_at, bounds=(lo, hi), method="bounded", options={"xatol": 0.005 * grid[i][2]})
    if not res.fun < scores[i]:
        return i, None
    return i, float(res.x)


def _flat(d: dict, pre: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict) and k not in ("std_err", "reading", "provenance", "metrics"):
            out.update(_flat(v, f"{pre}{k}."))
        elif not isinstance(v, dict):
            out[pre + k] = v
    return out


def mark_changed(declared, closed, findings: list) -> None:
    """The closed chain's fit statistics and readings of the parameters the closed loop set
    (changed or new against the declared chain, ``hvac.<key>`` and ``loads.<column>``
    included): the declared fit's standard errors dropped, each reading replaced by what the
    loop found (they described the declared values: "290 W" beside an aux_power_w of 1286)."""
    a, b = _flat(declared.to_dict()), _flat(closed.to_dict())
    changed = sorted(k for k, v in b.items() if a.get(k) != v and k != "predicts")
    closed.std_err = {k: v for k, v in closed.std_err.items() if k not in changed}
    found = "; ".join(findings) or "the closed loop"
    closed.reading = {**{k: v for k, v in closed.reading.items() if k not in changed},
                      **{k: f"set by diagnose's closed loop ({found})" for k in changed}}
    closed.metrics = {}
