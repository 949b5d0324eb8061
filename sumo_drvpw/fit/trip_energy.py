"""Energy per trip, predicted against measured, and what each trip left out.

A per-trip energy sums only the samples a comparison uses. A trip that lost part of its
time (a logger dropout, an outlier run, a charger) to left-out samples then reports the
energy of what is left: :func:`left_out_by_trip` says how much of each trip's samples,
time and measured energy that was, and :func:`with_left_out` adds it to a per-trip energy
document (keys ``left_out_*``; the energies themselves stay over the used samples).
"""

from __future__ import annotations

import math

import numpy as np

from sumo_drvpw.errors import UserError, first_bad_row

#: a trip whose left-out share of time or measured energy exceeds this is flagged partial
PARTIAL_TRIP_SHARE = 0.10
#: a trip whose |measured energy| is under this share of the median trip's is too small to
#: score: left out of the mean and worst per-trip error (its own error is kept)
SMALL_TRIP_SHARE = 0.05


def _trip_energy(pred_w, meas_w, dt_s, trip, net: bool) -> dict:
    pred = np.asarray(pred_w, dtype=float).ravel()
    meas = np.asarray(meas_w, dtype=float).ravel()
    n = meas.size
    if pred.shape != meas.shape:
        raise UserError(f"trip energy: predicted power has {pred.size} samples, measured "
                        f"power {n}")
    dt = _dt_array(dt_s, n)
    tr = np.asarray(trip).ravel() if trip is not None else np.zeros(n, dtype=np.int64)
    if tr.shape != (n,):
        raise UserError(f"trip energy: trip has {tr.size} values for {n} samples")
    ok = np.isfinite(pred) & np.isfinite(meas)
    if net:
        pm, mm = np.where(ok, pred, 0.0), np.where(ok, meas, 0.0)
    else:
        pm = np.where(ok & (pred > 0.0), pred, 0.0)
        mm = np.where(ok & (meas > 0.0), meas, 0.0)
    codes, names = _codes(tr)
    k = len(names)
    e_meas = np.bincount(codes, weights=mm * dt, minlength=k)
    e_pred = np.bincount(codes, weights=pm * dt, minlength=k)
    return trip_energy_doc(names, e_meas, e_pred)


def trip_energy_doc(names, e_meas, e_pred) -> dict:
    """The per-trip energy document from per-trip sums [J]: error = predicted/measured − 1
    (NaN where nothing was measured), mean and max |error| over the finite ones, less the
    small trips: those whose |measured energy| is under :data:`SMALL_TRIP_SHARE` of the
    median trip's (a file logged while parked, a few seconds of a restart) keep their error
    but are listed in ``small_trips`` and left out of the mean and max, whose relative error
    of a near-zero energy would swamp (a LeafSpy folder's net mean 53 % where the trips that
    drove score 14 %)."""
    e_meas, e_pred = np.asarray(e_meas, float), np.asarray(e_pred, float)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        err = np.where(e_meas != 0.0, e_pred / e_meas - 1.0, np.nan)
    trips = {str(t): {"measured_j": float(em), "predicted_j": float(ep), "error": float(er)}
             for t, em, ep, er in zip(names, e_meas, e_pred, err)}
    ok = np.isfinite(err)
    small = ok & (np.abs(e_meas) < SMALL_TRIP_SHARE * (np.median(np.abs(e_meas[ok])) if ok.any() else 0.0))
    fin = np.abs(err[ok & ~small])
    doc = {"mean_abs_error": float(fin.mean()) if fin.size else math.nan,
           "max_abs_error": float(fin.max()) if fin.size else math.nan,
           "trips": trips}
    if small.any():
        doc["small_trips"] = [str(t) for t, s in zip(names, small) if s]
        doc["small_trip_share"] = SMALL_TRIP_SHARE
    return doc


def _codes(trip: np.ndarray) -> tuple[np.ndarray, list]:
    """Integer code per sample and the trip names in order of first appearance."""
    import pandas as pd

    codes, uniques = pd.factorize(pd.Series(trip), sort=False)
    return codes.astype(np.int64), list(uniques)


def trip_energy(pred_w, meas_w, dt_s, trip) -> dict:
    """Traction energy per trip, predicted against measured (issue #11 §5).

    Parameters
    ----------
    pred_w : predicted driving power per sample [W]
    meas_w : measured driving power per sample [W]
    dt_s : duration of each sample [s] (array or scalar; None: 1 s each)
    trip : trip id per sample (None: one trip)

    Returns
    -------
    ``{"mean_abs_error", "max_abs_error", "trips": {TRIP: {"measured_j", "predicted_j",
    "error"}}}`` with E = Σ max(P, 0)·Δt over the trip's samples [J], computed separately
    for measured and predicted power, and error = E_pred/E_meas − 1 (NaN when the trip has
    no measured traction; left out of the mean and max). Samples with a non-finite value
    count as zero power.
    """
    return _trip_energy(pred_w, meas_w, dt_s, trip, net=False)


def trip_net_energy(pred_w, meas_w, dt_s, trip) -> dict:
    """Net energy per trip, E = Σ P·Δt (traction minus recuperation) [J]; else as
    :func:`trip_energy` (error = E_pred/E_meas − 1, NaN when E_meas = 0)."""
    return _trip_energy(pred_w, meas_w, dt_s, trip, net=True)


#: below this share of its measured traction energy, a trip's measured net energy (a long
#: descent: recuperation nearly as large as traction, or larger) is too small a denominator
#: for a relative error (:func:`net_energy_errors`)
NET_SHARE_MIN = 0.2


def net_energy_errors(pred_w, meas_w, dt_s, trip) -> dict:
    """Per trip, the net-energy error a structure is chosen on: E_pred/E_meas − 1 of the net
    energy (:func:`trip_net_energy`) where the measured net energy is at least
    :data:`NET_SHARE_MIN` of the trip's measured traction energy; elsewhere the net-energy miss
    as a share of that traction energy, (E_pred − E_meas)/E_traction, which stays bounded when
    a descent brings the net energy near 0 or below. NaN for a trip without traction."""
    net = trip_net_energy(pred_w, meas_w, dt_s, trip)["trips"]
    trac = trip_energy(pred_w, meas_w, dt_s, trip)["trips"]
    out = {}
    for t, v in net.items():
        e_t = trac[t]["measured_j"]
        if not e_t > 0:
            out[t] = math.nan
        elif v["measured_j"] >= NET_SHARE_MIN * e_t:
            out[t] = v["error"]
        else:
            out[t] = (v["predicted_j"] - v["measured_j"]) / e_t
    return out


def _dt_array(dt_s, n: int) -> np.ndarray:
    if dt_s is None:
        return np.ones(n)
    dt = np.asarray(dt_s, dtype=float)
    if dt.ndim == 0:
        dt = np.full(n, float(dt))
    if dt.shape != (n,):
        raise UserError(f"compare: dt_s has {dt.size} values for {n} samples")
    bad = ~np.isfinite(dt) | (dt < 0.0)
    if bad.any():
        raise UserError(f"compare: dt_s must be finite and ≥ 0 s; {first_bad_row(bad)} "
                        f"has {dt[bad][0]!r}")
    return dt


def left_out_by_trip(meas_w, used, dt_s, trip) -> dict:
    """What each trip lost to samples left out of a comparison.

    Parameters
    ----------
    meas_w : measured power of *all* the log's samples [W] (NaN where not measured)
    used : bool per sample, True where the comparison uses it
    dt_s : duration of each sample [s]
    trip : trip id per sample (None: one trip)

    Returns
    -------
    ``{TRIP: {"samples", "left_out_samples", "left_out_sample_share",
    "left_out_time_share", "left_out_energy_share", "left_out_net_energy_share",
    "left_out_power_unknown_samples", "left_out_power_unknown_time_share"}}``: shares of the trip's samples, of its time
    Σ Δt, of its measured traction energy Σ max(P, 0)·Δt and of its measured net energy
    Σ P·Δt that fall on left-out samples. The energy shares count the samples whose
    measured power is known (finite); left-out samples without it are counted in
    ``left_out_power_unknown_samples``; a share is NaN when its denominator is 0 (and
    the net share when the trip's net energy is not positive: a share of a net return
    says nothing).
    """
    p = np.asarray(meas_w, dtype=float).ravel()
    n = p.size
    u = np.asarray(used, dtype=bool).ravel()
    dt = _dt_array(dt_s, n)
    tr = np.asarray(trip).ravel() if trip is not None else np.zeros(n, dtype=np.int64)
    if u.shape != (n,) or tr.shape != (n,):
        raise UserError(f"left-out samples: {u.size} usable flags and {tr.size} trip ids for {n} samples")
    codes, names = _codes(tr)
    k = len(names)
    out = ~u
    fin = np.isfinite(p)
    pos = np.where(fin, np.maximum(p, 0.0), 0.0) * dt
    net = np.where(fin, p, 0.0) * dt

    def s(w, m=None):
        return np.bincount(codes, weights=w if m is None else np.where(m, w, 0.0), minlength=k)

    n_all, n_out = s(np.ones(n)), s(np.ones(n), out)
    t_all, t_out = s(dt), s(dt, out)
    e_all, e_out = s(pos), s(pos, out)
    q_all, q_out = s(net), s(net, out)
    unknown = s(np.ones(n), out & ~fin)
    t_unknown = s(dt, out & ~fin)
    with np.errstate(divide="ignore", invalid="ignore"):
        docs = {}
        for i, t in enumerate(names):
            docs[str(t)] = {
                "samples": int(n_all[i]), "left_out_samples": int(n_out[i]),
                "left_out_sample_share": float(n_out[i] / n_all[i]) if n_all[i] else math.nan,
                "left_out_time_share": float(t_out[i] / t_all[i]) if t_all[i] > 0 else math.nan,
                "left_out_energy_share": float(e_out[i] / e_all[i]) if e_all[i] > 0 else math.nan,
                "left_out_net_energy_share": float(q_out[i] / q_all[i]) if q_all[i] > 0 else math.nan,
                "left_out_power_unknown_samples": int(unknown[i]),
                "left_out_power_unknown_time_share": float(t_unknown[i] / t_all[i]) if t_all[i] > 0 else math.nan}
    return docs


def partial_share(left: dict | None, net: bool = False) -> float:
    """How partial a trip's energy is: the largest of its left-out traction-energy share
    (``net``: and net-energy share) and the time share of left-out samples whose power is
    not measured (their energy unknown); 0 when none is known. Left-out time with a
    measured power counts through its energy only: a tracer's standstill samples are
    left out but carry no driving energy."""
    if not left:
        return 0.0
    keys = ("left_out_power_unknown_time_share", "left_out_energy_share") + (
        ("left_out_net_energy_share",) if net else ())
    xs = [left.get(k) for k in keys]
    xs = [x for x in xs if x is not None and math.isfinite(x)]
    return max(xs, default=0.0)


def with_left_out(doc: dict, left_out: dict | None, net: bool = False) -> dict:
    """A per-trip energy document (:func:`trip_energy`; ``net``: :func:`trip_net_energy`)
    with each trip's left-out samples (:func:`left_out_by_trip`) added to its entry, plus
    ``partial``: True where :func:`partial_share` exceeds :data:`PARTIAL_TRIP_SHARE`; and
    the document's ``partial_trips`` list. Unchanged when ``left_out`` is None."""
    if not left_out or not doc:
        return doc
    partial = []
    for t, v in doc.get("trips", {}).items():
        left = left_out.get(str(t))
        if left is None:
            continue
        v.update(left)
        v["partial"] = partial_share(left, net) > PARTIAL_TRIP_SHARE
        if v["partial"]:
            partial.append(str(t))
    doc["partial_trips"] = partial
    doc["partial_trip_share"] = PARTIAL_TRIP_SHARE
    return doc


def with_trace_left_out(res, m) -> dict:
    """A chain trace's per-trip net energies (``baseline`` and ``final`` of
    :class:`~sumo_drvpw.fit.chain_linear.ChainTraceResult`'s report) with what each trip lost
    to the samples the trace left out (:func:`with_left_out`, ``net``): its mask
    (``res.mask``) against every sample of the :class:`~sumo_drvpw.data.measured.Measured`
    ``m`` it traced, the target as the trace measures it (``chain_target``). Returns the
    report, changed in place."""
    from sumo_drvpw.fit.chain import chain_target

    df = m.log.df
    left = left_out_by_trip(chain_target(m, res.declared.chain), res.mask, df["dt_s"].to_numpy(float),
                            df["trip_id"].astype(str).to_numpy())
    for k in ("baseline", "final"):
        with_left_out(res.report[k]["trip_net_energy"], left, net=True)
    return res.report


def with_fuel_volume(doc: dict | None, fuel: str) -> dict | None:
    """A per-trip energy document of a fuel target (:func:`trip_energy`,
    :func:`trip_net_energy`: fuel energy at the lower heating value [J]) with each trip's
    energies also in litres of ``fuel`` (a key of :data:`sumo_drvpw.model.constants.FUELS`):
    ``measured_l``, ``predicted_l`` = ``*_j`` / (LHV · density), and the document's ``fuel``
    and ``fuel_j_per_l``. The ``*_j`` keys and the errors stay (litres are J scaled: the
    relative errors are the same). Changed in place; None stays None."""
    from sumo_drvpw.model.chain import fuel_j_per_l

    if not doc:
        return doc
    per_l = fuel_j_per_l(fuel)
    for v in doc.get("trips", {}).values():
        for k in ("measured", "predicted"):
            j = v.get(f"{k}_j")
            v[f"{k}_l"] = None if j is None else float(j) / per_l
    doc["fuel"] = fuel
    doc["fuel_j_per_l"] = per_l
    return doc


def with_fuel_volumes(eq_doc: dict, target: str) -> dict:
    """One equation's comparison document (``Comparison.to_json``'s entry) with its per-trip
    energies in litres too (:func:`with_fuel_volume`) when the compared target is fuel; the
    fuel is its chain's. Unchanged otherwise. Changed in place."""
    chain = eq_doc.get("chain") or {}
    if target == "fuel" and chain.get("predicts") == "fuel":
        for key in ("trip_energy", "trip_net_energy"):
            with_fuel_volume(eq_doc.get(key), chain.get("fuel", "gasoline"))
    return eq_doc


def with_trace_fuel_volumes(report: dict, measured: tuple[str, str] | None = None) -> dict:
    """A chain trace's report (:class:`~sumo_drvpw.fit.chain_linear.ChainTraceResult`'s)
    with its per-trip net energies (``baseline``, ``final``) in litres too when its target is
    fuel (:func:`with_fuel_volume`), of its declared chain's fuel, as trace.md shows them;
    with ``measured`` (the fuel the log's flow was read as, and where from) also
    ``measured_fuel`` and, when the chain burns another, ``fuel_note``
    (:func:`fuel_mismatch_note`). Unchanged otherwise. Changed in place."""
    if report.get("target") == "fuel":
        chain = report.get("declared_chain") or {}
        for k in ("baseline", "final"):
            with_fuel_volume(report[k].get("trip_net_energy"), chain.get("fuel") or "gasoline")
        if measured:
            report["measured_fuel"] = measured[0]
            note = fuel_mismatch_note({report.get("declared_equation", "declared"): {"chain": chain}}, measured)
            report.update({"fuel_note": note} if note else {})
    return report


def fuel_mismatch_note(eq_docs: dict, measured: tuple[str, str] | None) -> str | None:
    """One line when a fuel chain of the equations' documents (``Comparison.to_json``'s
    ``equations``) burns another fuel than the log's flow was read as (``measured``: the fuel
    and where it comes from, :func:`sumo_drvpw.data.powertrain.measured_fuel`): the measured
    energy is the flow × LHV of the one, its litres are litres of the other. None when they
    agree (or nothing is known of the measured fuel)."""
    if not measured:
        return None
    fuel, where = measured
    odd = {nm: f for nm, d in eq_docs.items() if (d.get("chain") or {}).get("predicts") == "fuel"
           and (f := (d.get("chain") or {}).get("fuel") or "gasoline") != fuel}
    if not odd:
        return None
    return (f"The log's fuel flow was read as {fuel} ({where}) while the chain of "
            + ", ".join(f"{nm} burns {f}" for nm, f in odd.items())
            + f": the measured fuel energy is the flow × LHV of {fuel}, and its litres in this report are that "
            "energy in litres of each chain's own fuel, not the litres the log metered.")


def trip_block(trip_e: dict, net: bool) -> dict:
    """:func:`sumo_drvpw.fit.compare.trip_energy` (``net``: ``trip_net_energy``) from a
    streamed comparison's sums per trip ([measured, predicted traction, measured, predicted
    net] energy [J])."""
    names = list(trip_e)
    em = [trip_e[t][2] if net else trip_e[t][0] for t in names]
    ep = [trip_e[t][3] if net else trip_e[t][1] for t in names]
    return trip_energy_doc(names, em, ep)  # as in memory (small trips, NaN where none measured)
