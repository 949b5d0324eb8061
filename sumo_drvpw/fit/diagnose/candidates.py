"""Candidate effects of the residual tracer: column screening and candidate generation.

See :mod:`sumo_drvpw.fit.diagnose` for the forms and the screening rules.
"""

from __future__ import annotations

import fnmatch
import math
from dataclasses import dataclass

import numpy as np

from sumo_drvpw.fit.diagnose.options import CUMULATIVE_SOURCE_COLUMNS, POWER_SOURCE_COLUMNS, DiagnoseOptions
from sumo_drvpw.model.terms import Inputs, parse_term


@dataclass
class Candidate:
    """One candidate effect: a column (or a per-trip family of columns) to add."""

    term: str                 # term as added ("[c]*v^1", "v^2", "trip=*", "trip=*·mass")
    effect: str               # plain-language name
    signals: tuple[str, ...]
    kind: str                 # signal | signal_x_term | signal_sq | speed | trip_offset | trip_mass
    scatter: bool = False     # one coefficient per trip


#: Candidate kinds built on a logged column: a signal times a basis (v^k or a declared term).
SIGNAL_KINDS = ("signal", "signal_x_term", "signal_sq")


def signal_split(cand: Candidate, role: str | None) -> tuple[str, list[str]] | None:
    """(signal factor, basis factors) of a candidate whose energy share is reported about
    the data's mean of its signal, or None.

    A condition's zero is a convention of its unit (°C or K, °F): the share of "[T]*v"
    measured from T = 0 would hold a share of the rolling term as large as the mean T.
    The effect a condition adds is its departure from the conditions of the data, so its
    share is taken with the signal centred at its mean over the analysis samples. A load
    (W) has a physical zero and keeps its share as it is.
    """
    if cand.kind not in SIGNAL_KINDS or role == "load":
        return None
    parts = cand.term.split("*", 1)
    return parts[0], parts[1:]


#: Column-name patterns of a position or a direction: where the car drove (map coordinates)
#: or which way (a heading in degrees, circular: 359° sits next to 1°). As candidates they
#: are proxies of the road, its grade or the day's wind, not effects a SUMO vehicle carries;
#: a wind is found from the heading by sumo_drvpw.fit.wind and given to the logs.
POSITION_PATTERNS = ("*latitude*", "*longitude*", "lat_deg", "lon_deg", "*bearing*", "*heading*")


def _vname(k: int) -> str:
    return {0: "", 1: " × v (a force proportional to it)", 2: " × v²",
            3: " × v³ (drag-like)"}[k]


def _glob_any(name: str, patterns) -> bool:
    return any(fnmatch.fnmatchcase(name, p) for p in patterns)


def check_include(columns, opt: DiagnoseOptions) -> None:
    """UserError when an ``include`` or ``exclude`` pattern matches none of the logs' extra
    ``columns`` (a misspelt name would leave nothing to find, and the trace would say 0
    findings; or leave in the column it meant to keep out)."""
    for key in ("include", "exclude"):
        for pat in getattr(opt, key) or ():
            if not any(fnmatch.fnmatchcase(n, pat) for n in columns):
                from sumo_drvpw.errors import UserError

                cols = sorted(columns)
                raise UserError(f"diagnose option {key}: {pat!r} matches no column of the logs (their "
                                f"extra columns: {', '.join(cols[:12]) or 'none'}"
                                f"{', …' if len(cols) > 12 else ''})")


def screen_signals(signals: dict, y: np.ndarray, x: Inputs, trip_codes: np.ndarray,
                   usable: np.ndarray, opt: DiagnoseOptions,
                   roles: dict | None = None) -> tuple[dict, list[dict]]:
    """Pick the extra columns to offer as candidate signals (see the package docstring).

    ``roles``: column → ``{"role", "source"}`` (:func:`sumo_drvpw.data.roles.resolve`);
    a ``response`` column is left out unless ``opt.responses``; conditions, loads and
    columns of unknown role go through the screens below. Returns (name → float array
    over all samples, list of {column, reason} skipped). The callers check the ``include``
    and ``exclude`` patterns first (:func:`check_include`, before any work).
    """
    kept, skipped = {}, []
    u = usable
    v, a, th, w = x.v[u], x.a[u], x.theta[u], x.wind[u]
    kin = np.column_stack([np.ones(u.sum()), v, a, np.sin(th), w])
    kin_q, _ = np.linalg.qr(kin)
    yu = y[u]
    yc = yu - yu.mean()
    tc = trip_codes[u]
    same_trip = tc[1:] == tc[:-1]
    src = {}
    for c in POWER_SOURCE_COLUMNS:
        if c in signals and c not in CUMULATIVE_SOURCE_COLUMNS:
            a = np.asarray(signals[c], float)[u]
            a = np.where(np.isfinite(a), a, np.nanmean(a) if np.isfinite(a).any() else 0.0)
            if a.std() > 0:
                proj = kin_q.T @ a
                r2 = 1.0 - max(float(a @ a) - float(proj @ proj), 0.0) / float(((a - a.mean()) ** 2).sum())
                if r2 < opt.derived_r2:  # a motor speed ∝ vehicle speed is no power component to match
                    src[c] = (a - a.mean()) / a.std()
    for name in signals:
        arr = np.asarray(signals[name], dtype=float)
        if name in POWER_SOURCE_COLUMNS:
            skipped.append({"column": name, "reason": "measured-power source column (target or a component of it)"})
            continue
        role = (roles or {}).get(name, {})
        if role.get("role") == "response" and not opt.responses:
            skipped.append({"column": name, "role": "response",
                            "reason": f"role response ({role.get('source', 'declared')}): a consequence "
                                      "of the power demand, not a cause (offered only with responses)"})
            continue
        if opt.include and not _glob_any(name, opt.include):
            skipped.append({"column": name, "reason": "not among the included columns (include)"})
            continue
        if opt.exclude and _glob_any(name, opt.exclude):
            skipped.append({"column": name, "reason": "excluded (exclude)"})
            continue
        if _glob_any(name, POSITION_PATTERNS) and not (opt.include and _glob_any(name, opt.include)):
            skipped.append({"column": name, "reason": "a position or direction (map coordinate or heading): "
                                                      "a proxy of where and which way the car drove (road, "
                                                      "grade, wind), not an effect a vehicle carries "
                                                      "(offered only when included by name)"})
            continue
        s = arr[u]
        fin = np.isfinite(s)
        nan_frac = 1.0 - fin.mean() if len(s) else 1.0
        if nan_frac > opt.max_nan:
            skipped.append({"column": name, "reason": f"{100 * nan_frac:.1f} % NaN among usable samples (> {100 * opt.max_nan:g} %)"})
            continue
        sf = s[fin]
        if len(sf) == 0 or np.nanmax(sf) == np.nanmin(sf):
            skipped.append({"column": name, "reason": "constant"})
            continue
        ds = np.diff(s)
        ok = same_trip & np.isfinite(ds)
        if ok.any() and (np.all(ds[ok] >= 0) or np.all(ds[ok] <= 0)) and len(np.unique(sf)) > 0.5 * len(sf):
            skipped.append({"column": name, "reason": "id-like (monotone within every trip: clock, counter or odometer)"})
            continue
        sz = np.where(fin, s, np.nanmean(sf))
        sc = sz - sz.mean()
        ss = float(sc @ sc)
        if ss > 0:
            proj = kin_q.T @ sz
            r2 = 1.0 - max(float(sz @ sz) - float(proj @ proj), 0.0) / ss
            if r2 >= opt.derived_r2:
                skipped.append({"column": name, "reason": f"derived from the model inputs (R² = {r2:.4f} on 1, v, a, sin θ, wind)"})
                continue
        dup = None
        if sz.std() > 0:
            zs = (sz - sz.mean()) / sz.std()
            for c, a in src.items():
                r = abs(float(zs @ a)) / len(zs)
                if r >= opt.proxy_corr:
                    dup = (c, r)
                    break
        if dup:
            skipped.append({"column": name, "reason": f"same quantity as the measured-power source column "
                                                      f"'{dup[0]}' (|corr| = {dup[1]:.3f})"})
            continue
        best = 0.0
        for k in range(4):
            f = sz * v ** k
            fc = f - f.mean()
            den = math.sqrt(float(fc @ fc) * float(yc @ yc))
            if den > 0:
                best = max(best, abs(float(fc @ yc)) / den)
        if best >= opt.proxy_corr:
            skipped.append({"column": name, "reason": f"proxy of the target (|corr(c·vᵏ, P)| = {best:.3f} ≥ {opt.proxy_corr:g})"})
            continue
        kept[name] = arr
    return kept, skipped


def generate_candidates(signals: dict, declared_terms, n_trips: int, opt: DiagnoseOptions,
                        binary: set) -> list[Candidate]:
    """All candidate effects for the screened signals and the declared terms."""
    out = []
    for c in signals:
        for k in range(4):
            term = f"[{c}]" if k == 0 else f"[{c}]*v^{k}"
            what = "an additive load proportional to" if k == 0 else "a load"
            out.append(Candidate(term, f"{what} '{c}'{_vname(k)}", (c,), "signal"))
        for t in declared_terms:
            if parse_term(t).signals:
                continue
            cat = parse_term(t).category
            label = {"acc": "inertia", "grade": "grade", "aero": "aerodynamic drag",
                     "roll": "rolling-resistance"}.get(cat, cat)
            out.append(Candidate(f"[{c}]*{t}", f"'{c}' changes the {label} term '{t}'", (c,),
                                 "signal_x_term"))
        if c not in binary:
            for k in range(4):
                term = f"[{c}]^2" if k == 0 else f"[{c}]^2*v^{k}"
                out.append(Candidate(term, f"a load with the square of '{c}'{_vname(k)}", (c,), "signal_sq"))
    for k in range(5):
        out.append(Candidate(f"v^{k}", f"a function of speed alone: v^{k} (the declared terms lack it)",
                             (), "speed"))
    if opt.per_trip and 2 <= n_trips <= opt.max_trips_per_trip_effects:
        out.append(Candidate("trip=*", "a per-trip constant load (one offset per trip)", (), "trip_offset", True))
        out.append(Candidate("trip=*·mass", "a per-trip mass change (one factor per trip on the "
                             "mass-bearing terms)", (), "trip_mass", True))
    return out
