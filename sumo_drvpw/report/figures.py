"""Figures of the comparison report (paper Fig. 4, 5, 8, 9, 10), PNG via matplotlib Agg.

Power is SI (W) inside; axes show kW for readability, converted here at the edge. Scatter
plots draw at most ``MAX_POINTS`` samples (a fixed random subset), so million-sample logs
plot in seconds; histograms, bin statistics and lines use every sample.

Each function takes a :class:`sumo_drvpw.fit.compare.Comparison` and a path, writes the PNG
atomically (``fileio.write_figure``) and returns the path.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display: reports are written by CLI runs and tests
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from sumo_drvpw.fit.compare import Comparison  # noqa: E402
from sumo_drvpw.model.constants import HEAVY_LOAD_W, HIGH_SPEED_MPS, KMH  # noqa: E402
from sumo_drvpw.fileio import write_figure  # noqa: E402
from sumo_drvpw.report.format import KW as _KW, kw, num  # noqa: E402

#: Most points drawn in one scatter panel.
MAX_POINTS = 50_000
_CAT_COLOURS = {"acc": "tab:blue", "grade": "tab:green", "aero": "tab:orange",
                "roll": "tab:red", "other": "tab:gray"}


def subsample_index(n: int, max_points: int = MAX_POINTS, seed: int = 0) -> np.ndarray:
    """Sorted indices of at most ``max_points`` of ``n`` samples (all when n is small);
    a fixed random subset (``seed``), so figures are reproducible."""
    if n <= max_points:
        return np.arange(n)
    rng = np.random.default_rng(seed)
    return np.sort(rng.choice(n, size=max_points, replace=False))


def _grid(n: int, max_cols: int = 3, size=(4.2, 3.6)):
    cols = min(n, max_cols)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(size[0] * cols, size[1] * rows),
                             squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    return fig, axes.ravel()


def parity(comp: Comparison, path) -> Path:
    """Measured against predicted power, one panel per equation (paper Fig. 4).

    The 1:1 line and the 50 kW light/heavy boundary on both axes are drawn; the panel
    title carries R² below and above 50 kW.

    Parameters
    ----------
    comp : the comparison (:func:`sumo_drvpw.fit.compare.compare`): powers [W], drawn in kW
    path : the PNG file to write (atomically); returned
    """
    idx = subsample_index(comp.n_samples)
    meas = comp.meas_w[idx] * _KW
    fig, axes = _grid(len(comp.results))
    for ax, (name, r) in zip(axes, comp.results.items()):
        pred = r.pred_w[idx] * _KW
        ax.scatter(meas, pred, s=2, alpha=0.3, lw=0, color="tab:blue", rasterized=True)
        fin = np.concatenate([meas, pred[np.isfinite(pred)]])
        lo, hi = (float(fin.min()), float(fin.max())) if fin.size else (0.0, 1.0)
        ax.plot([lo, hi], [lo, hi], color="k", lw=1, label="1:1")
        ax.axvline(HEAVY_LOAD_W * _KW, color="tab:red", lw=0.8, ls="--", label="50 kW")
        ax.axhline(HEAVY_LOAD_W * _KW, color="tab:red", lw=0.8, ls="--")
        m = r.metrics
        ax.set_title(f"{name}\nR² <50 kW {num(m['r2_light'], 3)}, ≥50 kW {num(m['r2_heavy'], 3)}",
                     fontsize=9)
        ax.set_xlabel("measured power [kW]")
        ax.set_ylabel("predicted power [kW]")
        ax.legend(fontsize=7, loc="upper left")
        ax.grid(alpha=0.3)
    return _finish(fig, path, "Predicted against measured driving power (cf. paper Fig. 4)")


def _finish(fig, path, title: str) -> Path:
    """Title, tight layout, atomic PNG write; returns the path."""
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    write_figure(path, fig)
    return Path(path)


def error_histograms(comp: Comparison, path) -> Path:
    """Histograms of the error pred − meas at light and heavy load (paper Fig. 5).

    One row per equation; left light load (measured < 50 kW), right heavy load.

    Parameters
    ----------
    comp : the comparison (:func:`sumo_drvpw.fit.compare.compare`): powers [W], drawn in kW
    path : the PNG file to write (atomically); returned
    """
    names = list(comp.results)
    heavy = comp.meas_w >= HEAVY_LOAD_W
    fig, axes = plt.subplots(len(names), 2, figsize=(9, 2.6 * len(names)), squeeze=False)
    errs = {nm: comp.error_w(nm) * _KW for nm in names}
    allf = np.concatenate([e[np.isfinite(e)] for e in errs.values()])
    if allf.size:
        lo, hi = np.percentile(allf, [0.5, 99.5])
        lim = max(abs(lo), abs(hi), 1.0)
    else:
        lim = 1.0
    bins = np.linspace(-lim, lim, 81)
    for row, nm in enumerate(names):
        e = errs[nm]
        for col, (mask, label) in enumerate(((~heavy, "< 50 kW"), (heavy, "≥ 50 kW"))):
            ax = axes[row, col]
            sub = e[mask & np.isfinite(e)]
            if sub.size:
                ax.hist(np.clip(sub, -lim, lim), bins=bins, color="tab:blue", alpha=0.8)
                ax.axvline(float(sub.mean()), color="tab:red", lw=1,
                           label=f"mean {sub.mean():.2f} kW")
                ax.legend(fontsize=7)
            ax.axvline(0.0, color="k", lw=0.6)
            ax.set_title(f"{nm}, {label} (n = {sub.size})", fontsize=9)
            ax.set_xlabel("error, predicted − measured [kW]")
            ax.set_ylabel("samples")
    return _finish(fig, path, "Error distribution by load (cf. paper Fig. 5); errors beyond "
                   f"±{lim:.0f} kW are counted in the outermost bins")


def error_vs_speed(comp: Comparison, path) -> Path:
    """Error against speed with 10 km/h bin statistics, ≥ 80 km/h shaded (paper Fig. 8).

    Points: a subsample of samples. Line: bin mean; band: 5th–95th percentile per bin.

    Parameters
    ----------
    comp : the comparison (:func:`sumo_drvpw.fit.compare.compare`): powers [W], drawn in kW
    path : the PNG file to write (atomically); returned
    """
    idx = subsample_index(comp.n_samples)
    v_kmh = comp.speed_mps[idx] / KMH
    fig, axes = _grid(len(comp.results), max_cols=2, size=(5.5, 3.6))
    for ax, (name, r) in zip(axes, comp.results.items()):
        e = comp.error_w(name)[idx] * _KW
        ax.scatter(v_kmh, e, s=2, alpha=0.2, lw=0, color="tab:gray", rasterized=True)
        bins = [b for b in r.speed_bins if b["n"] > 0]
        if bins:
            mid = np.array([(b["lo_kmh"] + b["hi_kmh"]) / 2 for b in bins])
            ax.fill_between(mid, [b["p5_w"] * _KW for b in bins],
                            [b["p95_w"] * _KW for b in bins], color="tab:blue", alpha=0.25,
                            label="5–95 %")
            ax.plot(mid, [b["mean_w"] * _KW for b in bins], "o-", color="tab:blue", ms=3,
                    label="bin mean")
        xmax = max(float(np.nanmax(comp.speed_mps)) / KMH if comp.n_samples else 0.0,
                   HIGH_SPEED_MPS / KMH + 10.0)
        ax.axvspan(HIGH_SPEED_MPS / KMH, xmax, color="tab:orange", alpha=0.12,
                   label="≥ 80 km/h")
        ax.axhline(0.0, color="k", lw=0.6)
        hs = r.high_speed
        ax.set_title(f"{name}\n≥ 80 km/h: mean error {kw(hs['mean_w'])} kW, "
                     f"RMSE {kw(hs['rmse_w'])} kW", fontsize=9)
        ax.set_xlim(0.0, xmax)
        ax.set_xlabel("speed [km/h]")
        ax.set_ylabel("error, predicted − measured [kW]")
        ax.legend(fontsize=7, loc="lower left")
        ax.grid(alpha=0.3)
    return _finish(fig, path, "Error against speed (cf. paper Fig. 8)")


def error_vs_term_power(comp: Comparison, path) -> Path:
    """Error against each category's power of the same equation (paper Fig. 9).

    One row per equation, one column per category (acc, grade, aero, roll, other if
    used); each panel shows the least-squares line and Pearson r. A category the
    equation lacks shows an empty panel.

    Parameters
    ----------
    comp : the comparison (:func:`sumo_drvpw.fit.compare.compare`): powers [W], drawn in kW
    path : the PNG file to write (atomically); returned
    """
    names = list(comp.results)
    cats: list[str] = []
    for r in comp.results.values():
        cats += [c for c in r.category_w if c not in cats]
    idx = subsample_index(comp.n_samples)
    fig, axes = plt.subplots(len(names), len(cats), figsize=(3.2 * len(cats),
                             2.8 * len(names)), squeeze=False)
    for row, nm in enumerate(names):
        r = comp.results[nm]
        e_all = comp.error_w(nm)
        e = e_all[idx] * _KW
        for col, c in enumerate(cats):
            ax = axes[row, col]
            ax.axhline(0.0, color="k", lw=0.6)
            corr = r.error_term_correlation.get(c)
            if c in r.category_w and corr is not None and np.isfinite(corr["slope"]):
                p = r.category_w[c][idx] * _KW
                ax.scatter(p, e, s=2, alpha=0.25, lw=0, color=_CAT_COLOURS.get(c, "k"),
                           rasterized=True)
                pa = r.category_w[c]
                ok = np.isfinite(e_all)
                x0, x1 = float(pa.min()), float(pa.max())
                b = corr["slope"]
                a0 = float(np.mean(e_all[ok]) - b * np.mean(pa[ok]))
                ax.plot([x0 * _KW, x1 * _KW], [(a0 + b * x0) * _KW, (a0 + b * x1) * _KW],
                        color="k", lw=1)
                ax.set_title(f"{nm}: {c}\nr = {num(corr['r'], 2)}, slope {num(b, 3)}",
                             fontsize=8)
            else:
                ax.set_title(f"{nm}: {c}", fontsize=8)
                ax.text(0.5, 0.5, "no such term", ha="center", va="center",
                        transform=ax.transAxes, fontsize=8, color="gray")
                ax.set_xticks([])
                ax.set_yticks([])
            ax.set_xlabel(f"{c} power [kW]", fontsize=8)
            if col == 0:
                ax.set_ylabel("error [kW]", fontsize=8)
            ax.tick_params(labelsize=7)
    return _finish(fig, path, "Error against the power of each term (cf. paper Fig. 9)")


def energy_share_bars(comp: Comparison, path) -> Path:
    """Stacked bars of each category's share of traction energy (paper Fig. 10).

    One bar per equation; negative shares (e.g. downhill grade during traction) are
    stacked below zero. The measured traction energy over the predicted one is noted.

    Parameters
    ----------
    comp : the comparison (:func:`sumo_drvpw.fit.compare.compare`): powers [W], drawn in kW
    path : the PNG file to write (atomically); returned
    """
    names = list(comp.results)
    cats: list[str] = []
    for r in comp.results.values():
        cats += [c for c in r.energy_share if c not in cats]
    fig, ax = plt.subplots(figsize=(max(4.5, 1.3 * len(names) + 2.5), 4.2))
    x = np.arange(len(names))
    pos = np.zeros(len(names))
    neg = np.zeros(len(names))
    for c in cats:
        vals = np.array([100.0 * comp.results[nm].energy_share.get(c, 0.0) for nm in names])
        vals = np.nan_to_num(vals)
        bottom = np.where(vals >= 0, pos, neg)
        ax.bar(x, vals, bottom=bottom, color=_CAT_COLOURS.get(c, None), label=c, width=0.6)
        for xi, v, b in zip(x, vals, bottom):
            if abs(v) >= 4.0:
                ax.text(xi, b + v / 2, f"{v:.0f}", ha="center", va="center", fontsize=7)
        pos = pos + np.where(vals >= 0, vals, 0.0)
        neg = neg + np.where(vals < 0, vals, 0.0)
    ax.set_xticks(x)
    ax.set_xticklabels([f"{nm}\npred./meas. {num(comp.results[nm].traction_energy_ratio, 3)}"
                        for nm in names], fontsize=8)
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_ylabel("share of predicted traction energy [%]")
    ax.legend(fontsize=8, bbox_to_anchor=(1.01, 1.0), loc="upper left")
    ax.set_title("Energy share of each term (cf. paper Fig. 10)", fontsize=10)
    write_figure(path, fig)
    return Path(path)


# ------------------------------------------------------------- validation figures

def band_means(panels: list[tuple[str, list[dict]]], measured_label: str, predicted_label: str,
               path, title_prefix: str = "") -> Path:
    """Mean measured and predicted power per band, one panel per banding.

    Parameters
    ----------
    panels : (title, rows) per panel; a row has ``band`` (label), ``n``,
        ``mean_measured_w`` and ``mean_predicted_w`` [W]; empty bands are skipped
    measured_label, predicted_label : legend labels of the two bars
    path : PNG to write
    """
    fig, axes = plt.subplots(1, len(panels), figsize=(13, 3.6), squeeze=False)
    axes = axes.ravel()
    for ax, (title, bands) in zip(axes, panels):
        rows = [r for r in bands if r["n"]]
        xs = np.arange(len(rows))
        ax.bar(xs - 0.2, [r["mean_measured_w"] * _KW for r in rows], 0.4, label=measured_label)
        ax.bar(xs + 0.2, [r["mean_predicted_w"] * _KW for r in rows], 0.4, label=predicted_label)
        ax.set_xticks(xs)
        ax.set_xticklabels([r["band"] for r in rows], fontsize=7, rotation=20)
        ax.axhline(0, color="k", lw=0.6)
        ax.set_title(f"{title_prefix}mean power by {title}", fontsize=9)
        ax.set_ylabel("mean power [kW]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    write_figure(path, fig)
    return Path(path)


def road_load_and_cycle_errors(published: dict, recovered: dict, eta: float,
                               points: list[dict], per_cycle: list[dict], path,
                               max_kmh: float = 135.0) -> Path:
    """Published against recovered road-load force, and error per cycle (JLU dyno).

    Parameters
    ----------
    published, recovered : ``A_n`` [N], ``B_n_per_mps`` [N/(m/s)], ``C_n_per_mps2``
        [N/(m/s)²]: F(v) = A + B·v + C·v²
    eta : recovered drivetrain efficiency [-] (legend)
    points : constant-speed tests, ``speed_kmh`` and ``force_n`` [N] each (may be empty)
    per_cycle : ``cycle``, ``bias_w``, ``rmse_w`` [W] per cycle
    path : PNG to write
    """
    vv = np.linspace(0, max_kmh, 100) * KMH

    def force(c):
        return c["A_n"] + c["B_n_per_mps"] * vv + c["C_n_per_mps2"] * vv ** 2

    fig, ax = plt.subplots(1, 2, figsize=(11, 3.8))
    ax[0].plot(vv / KMH, force(published), "k-", label="published dyno road load")
    ax[0].plot(vv / KMH, force(recovered), "tab:blue", ls="--", label=f"recovered (η = {eta:.3f})")
    if points:
        ax[0].plot([p["speed_kmh"] for p in points], [p["force_n"] for p in points], "o",
                   color="tab:orange", ms=4, label="constant-speed tests: η·(P_batt − P_aux)/v")
    ax[0].set_xlabel("speed [km/h]")
    ax[0].set_ylabel("road-load force [N]")
    ax[0].set_title("JLU dyno: published vs recovered road load", fontsize=9)
    ax[0].legend(fontsize=7)
    ax[0].grid(alpha=0.3)
    xs = np.arange(len(per_cycle))
    ax[1].bar(xs - 0.2, [r["bias_w"] * _KW for r in per_cycle], 0.4, label="bias")
    ax[1].bar(xs + 0.2, [r["rmse_w"] * _KW for r in per_cycle], 0.4, label="RMSE")
    ax[1].set_xticks(xs)
    ax[1].set_xticklabels([r["cycle"] for r in per_cycle], rotation=60, fontsize=7, ha="right")
    ax[1].set_ylabel("battery power error [kW]")
    ax[1].set_title("JLU: two-regime model, error per cycle", fontsize=9)
    ax[1].axhline(0, color="k", lw=0.6)
    ax[1].legend(fontsize=7)
    ax[1].grid(alpha=0.3)
    write_figure(path, fig)
    return Path(path)
