"""Driving dynamics of a run's trajectories, against what real driving shows (EU RDE).

The acceleration term books the kinetic energy a vehicle gains, so a SUMO study's driving
energy is only as right as its trajectories' accelerations. SUMO's car-following models
can drive far more dynamically than people do: the Krauss model accelerates at the vType's
full ``accel`` from every stop and at any speed, and its driver imperfection (``sigma``, default 0.5) slows
a car at random and lets it accelerate back, an oscillation whose size depends on the step
length (SUMO issue #10494; the vType's ``sigmaStep`` decouples it). Measured on the
DLR-TS Bologna "acosta" scenario (docs/scenario.md): its cars' relative positive
acceleration at urban speeds falls from 0.32 to 0.24 m/s² with sigma 0 instead of 0.5.

This module measures the trajectories as the European Real Driving Emissions test judges
a real test trip's dynamics (Commission Regulation (EU) 2017/1151, Annex IIIA,
Appendix 7a, "verification of trip dynamics"): speeds at 1 Hz; accelerations by central
difference a_i = (v_i+1 − v_i−1)/2 s; the samples split by speed into urban (≤ 60 km/h),
rural (60–90) and motorway (> 90); per part

- the 95th percentile of v·a_pos over the samples with a > 0.1 m/s² [m²/s³]: a trip
  above 0.136·v̄ + 14.44 (v̄ ≤ 74.6 km/h; else 0.0742·v̄ + 18.966, v̄ the part's mean
  speed in km/h) is driven too dynamically to be a valid real-world test;
- the relative positive acceleration RPA = Σ v·a_pos·Δt / Σ v·Δt [m/s²]: below
  −0.0016·v̄ + 0.1755 (v̄ ≤ 94.05 km/h; else 0.025) a trip is too smooth.

(A part's percentile is judged from :data:`MIN_SAMPLES` samples with a > 0.1 m/s² on,
its RPA from as many samples.) The speeds are sampled at the first step of
every whole second of simulation time, so a run at 0.25 s and one at 1 s that drive the
same trajectory measure the same; a vehicle's sample needs its speeds one and two
seconds before (a vehicle off the lane in between, teleporting or parked, starts afresh; a
run whose steps are longer than 1.25 s has no such samples and gets no 1-Hz figures).
An FCD replay reads the same 1-Hz figures from rows written every second, while its
kinetic energy per km is at its rows' spacing.
Only accounted vehicles count, per vClass label as the run reports classes. Each part
keeps sums and a histogram of v·a_pos (bins of :data:`HIST_STEP` m²/s³), so the figures
of Dask buckets and of vehicles flushed from memory add up exactly.
"""

from __future__ import annotations

import math

import numpy as np

from sumo_drvpw.model.constants import G

#: the RDE parts: name, upper speed bound [km/h] (inclusive; the last has none)
PARTS = (("urban", 60.0), ("rural", 90.0), ("motorway", math.inf))
#: the upper speed of each part but the last [km/h] (part_of)
_PART_UPPER = np.array([p[1] for p in PARTS[:-1]])
#: an acceleration counts as positive above this [m/s²]
A_POS_MIN = 0.1
#: samples a part needs before its RPA (all samples) or its percentile (those with a >
#: A_POS_MIN) is judged against the bounds
MIN_SAMPLES = 100
#: histogram of v·a_pos: bin width [m²/s³] and number of bins (the last holds the rest:
#: 400 m²/s³ is 10 m/s² at 40 m/s, beyond any road vehicle)
HIST_STEP = 0.1
HIST_BINS = 4000
#: sums kept per part: time [s], distance [m], samples with a > A_POS_MIN, Σ v·a_pos·Δt [m²/s²]
SUMS = ("time_s", "distance_m", "apos_samples", "va_pos_sum")
#: the longest gap [s] between a vehicle's two earlier samples and this one still read as 1-Hz
MAX_SPAN_S = 2.5
#: the acceleration profile: speed bins of PROFILE_BIN_MPS [m/s] (the last holds the rest),
#: in each a histogram of the 1-Hz accelerations above A_POS_MIN in bins of ACC_STEP [m/s²]
#: (the last holds the rest), and the samples a bin needs to be reported
PROFILE_BIN_MPS = 5.0
PROFILE_BINS = 10
ACC_STEP = 0.02
ACC_BINS = 300
PROFILE_MIN_SAMPLES = 50
#: the class label of a drive log's figures (a SUMO run's are its vClasses)
LOG_LABEL = "measured"
#: vClass labels of heavy vehicles: the RDE's bounds are a light-duty vehicle's
HEAVY = frozenset({"bus", "coach", "truck", "trailer"})
#: specific power for accelerating and climbing alone, v̄·a + g·v·sin θ [W/kg], beyond which a
#: heavy vehicle's step asks more than any production engine gives at its mass (the strongest
#: trucks' 560 kW are 14 W/kg at 40 t, 23 at 24 t; a 300-kW coach at 12 t: 25): SUMO's
#: car-following models neither see the grade nor limit the power (a rehearsal on MoST: a
#: 24-t trailer climbing 5.7 % at 100 km/h, 10.5 % of its steps above 400 kW)
HEAVY_POWER_W_PER_KG = 25.0
#: share of a heavy class's vehicle-steps beyond :data:`HEAVY_POWER_W_PER_KG` that is said
HEAVY_POWER_WARN_SHARE = 0.01
#: and of two-wheelers, whose real driving (a motorcycle's power per kg) may exceed them
TWO_WHEELERS = frozenset({"motorcycle", "moped"})
#: SUMO 1.28's car-following defaults of a vType that sets none, per vClass: accel, decel
#: [m/s²] and the Krauss driver imperfection sigma (vehicletype.getAccel, getDecel,
#: getImperfection; tests/test_sim_dynamics.py asks SUMO); any other vClass: the passenger's
SUMO_CF_DEFAULTS = {
    "passenger": (2.6, 4.5, 0.5), "bicycle": (1.2, 3.0, 0.5), "pedestrian": (1.5, 2.0, 0.5),
    "moped": (1.1, 7.0, 0.5), "motorcycle": (6.0, 10.0, 0.5), "bus": (1.2, 4.0, 0.5),
    "coach": (2.0, 4.0, 0.5), "truck": (1.3, 4.0, 0.5), "trailer": (1.1, 4.0, 0.5),
    "tram": (1.0, 3.0, 0.0), "rail_urban": (1.0, 3.0, 0.0), "rail": (0.25, 1.3, 0.0),
    "rail_electric": (0.5, 1.3, 0.0), "rail_fast": (0.5, 1.3, 0.0), "ship": (0.1, 0.15, 0.0),
}
#: SUMO's default car-following model, and the models that read sigma (the Krauss family;
#: SUMO answers getImperfection −1 for the others)
CF_DEFAULT_MODEL = "Krauss"
SIGMA_MODELS = frozenset({"Krauss", "KraussOrig1", "KraussPS", "KraussX"})
SOURCE = ("EU RDE trip dynamics: Commission Regulation (EU) 2017/1151, Annex IIIA, Appendix 7a "
          "(95th percentile of v·a_pos and relative positive acceleration per urban/rural/motorway part)")


def va_pos_95_max(v_kmh: float) -> float:
    """The RDE's largest 95th percentile of v·a_pos [m²/s³] at a part's mean speed [km/h]."""
    return 0.136 * v_kmh + 14.44 if v_kmh <= 74.6 else 0.0742 * v_kmh + 18.966


def rpa_min(v_kmh: float) -> float:
    """The RDE's smallest relative positive acceleration [m/s²] at a part's mean speed [km/h]."""
    return -0.0016 * v_kmh + 0.1755 if v_kmh <= 94.05 else 0.025


def _bins(x: np.ndarray, n: int) -> np.ndarray:
    """Integer bin numbers ``x`` (int64) held to 0 … n − 1: np.clip's result without its
    per-call cost on integers (a few vehicles' samples each step)."""
    return np.minimum(np.maximum(x, 0), n - 1)


#: up to this many samples a histogram is counted one by one (np.add.at's per-call cost is
#: most of a few vehicles' step); more take np.add.at
FEW = 16


def _count(hist: np.ndarray, *idx: np.ndarray) -> None:
    """Add 1 to ``hist`` at each index (1-D: ``idx`` one array; 2-D: two), repeats counted."""
    if len(idx[0]) > FEW:
        np.add.at(hist, idx if len(idx) > 1 else idx[0], 1)
        return
    for i in zip(*(x.tolist() for x in idx)) if len(idx) > 1 else idx[0].tolist():
        hist[i] += 1


def part_of(v_mps: np.ndarray) -> np.ndarray:
    """The RDE part (index into :data:`PARTS`) of each speed [m/s]."""
    kmh = np.asarray(v_mps, float) * 3.6
    return np.searchsorted(_PART_UPPER, kmh, side="left")


def whole_second(t: float, dt: float) -> bool:
    """Whether a state at time ``t`` [s], a step of ``dt`` [s] after the one before, is the
    first of a whole second."""
    return math.floor(t + 1e-9) != math.floor(t - dt + 1e-9)


class Dynamics:
    """Per class label: per RDE part the sums :data:`SUMS` and the v·a_pos histogram.

    Per-vehicle state (the speeds and times of its last two 1-Hz samples) lives in the
    ledger's ``veh_rde`` array, (vehicles, 4): [v_k−1, t_k−1, v_k−2, t_k−2].
    """

    def __init__(self):
        self.sums: dict[str, np.ndarray] = {}  # label → (parts, len(SUMS))
        self.hist: dict[str, np.ndarray] = {}  # label → (parts, HIST_BINS)
        #: label → [Σ max(v̄·a, 0)·Δt [J/kg], Σ distance [m]] over every step (the run's own step)
        self.kinetic: dict[str, np.ndarray] = {}
        self.acc_hist: dict[str, np.ndarray] = {}  # label → (PROFILE_BINS, ACC_BINS)
        #: heavy class label → [vehicle-steps beyond HEAVY_POWER_W_PER_KG, vehicle-steps]
        self.beyond: dict[str, np.ndarray] = {}

    def step(self, ledger, vidx: np.ndarray, v_mean: np.ndarray, a: np.ndarray, v_dist: np.ndarray,
             dt: float, theta: np.ndarray | None = None) -> None:
        """Add a step's positive kinetic energy per kg, ½(v_t² − v_t−1²)⁺ = (v̄·a)⁺·Δt, and
        distance (``v_dist``·Δt) per class of the accounted vehicles ``vidx``; with the
        grades ``theta`` [rad], count the heavy classes' steps beyond
        :data:`HEAVY_POWER_W_PER_KG`."""
        keep = ledger.veh_keep[vidx]
        if not keep.all():  # (mostly every vehicle is accounted: no copies)
            vidx, v_mean, a, v_dist = vidx[keep], v_mean[keep], a[keep], v_dist[keep]
            theta = None if theta is None else theta[keep]
        code = ledger.veh_cls[vidx]
        n = len(ledger.class_list)
        kin = np.bincount(code, np.maximum(v_mean * a, 0.0) * dt, minlength=n)
        dist = np.bincount(code, v_dist * dt, minlength=n)
        for c in np.flatnonzero(dist > 0).tolist():
            acc = self.kinetic.get(ledger.class_list[c])
            if acc is None:  # (not setdefault: its default array was made every step)
                acc = self.kinetic[ledger.class_list[c]] = np.zeros(2)
            acc[0] += kin[c]
            acc[1] += dist[c]
        if theta is None or not HEAVY.intersection(ledger.class_list):
            return
        heavy = [c for c in range(n) if ledger.class_list[c] in HEAVY]
        sp = v_mean * a + G * v_dist * np.sin(theta)
        over = np.bincount(code, sp > HEAVY_POWER_W_PER_KG, minlength=n).astype(np.int64)
        steps = np.bincount(code, minlength=n)
        for c in heavy:
            if steps[c]:
                self.beyond.setdefault(ledger.class_list[c], np.zeros(2, np.int64))[:] += (over[c], steps[c])

    def _acc(self, label: str) -> tuple[np.ndarray, np.ndarray]:
        if label not in self.sums:
            self.sums[label] = np.zeros((len(PARTS), len(SUMS)))
            self.hist[label] = np.zeros((len(PARTS), HIST_BINS), np.int64)
            self.acc_hist[label] = np.zeros((PROFILE_BINS, ACC_BINS), np.int64)
        return self.sums[label], self.hist[label]

    def sample(self, ledger, vidx: np.ndarray, v: np.ndarray, t_now: float) -> None:
        """Take this whole second's speeds ``v`` [m/s] of vehicles ``vidx`` (on a lane)."""
        keep = ledger.veh_keep[vidx]
        if not keep.all():  # (mostly every vehicle is accounted: no copies)
            vidx, v = vidx[keep], v[keep]
        if len(vidx) == 0:
            return
        st = ledger.veh_rde[vidx]
        v1, t1, v2, t2 = st[:, 0], st[:, 1], st[:, 2], st[:, 3]
        ok = np.isfinite(t2) & (t_now - t2 <= MAX_SPAN_S) & (t1 > t2)
        if ok.all():  # (mostly every vehicle has its two earlier samples: no copies)
            span = t_now - t2
            self.add(self._labels(ledger.class_list)[ledger.veh_cls[vidx]], v1, (v - v2) / span, 0.5 * span)
        elif ok.any():
            j = np.flatnonzero(ok)
            labels = self._labels(ledger.class_list)[ledger.veh_cls[vidx[j]]]
            self.add(labels, v1[j], (v[j] - v2[j]) / (t_now - t2[j]), 0.5 * (t_now - t2[j]))
        # shift the history: this sample becomes k−1, the old k−1 becomes k−2
        st[:, 2:] = st[:, :2]
        st[:, 0], st[:, 1] = v, t_now
        ledger.veh_rde[vidx] = st

    def add(self, labels: np.ndarray, v: np.ndarray, a: np.ndarray, dt: np.ndarray) -> None:
        """Add 1-Hz samples: class labels, speeds [m/s], central-difference accelerations
        [m/s²] and the time each sample stands for [s]."""
        part, pos, va = part_of(v), a > A_POS_MIN, v * a
        labels = np.asarray(labels, dtype=object)
        sbin = _bins((v / PROFILE_BIN_MPS).astype(np.int64), PROFILE_BINS)
        abin = _bins((np.where(pos, a, 0.0) / ACC_STEP).astype(np.int64), ACC_BINS)
        labs = labels.tolist()
        one = len(set(labs)) == 1  # (a step's vehicles mostly of one class: no masks)
        for lab in dict.fromkeys(labs):
            m = None if one else labels == lab
            sums, hist = self._acc(lab)
            mp = pos if m is None else m & pos
            _count(self.acc_hist[lab], sbin[mp], abin[mp])
            ks = sorted(set((part if m is None else part[m]).tolist()))  # the parts it has samples in
            for k in ks:
                if m is None and len(ks) == 1:  # every sample in this part: the arrays as they are
                    dk, vk, pk = dt, v, pos
                else:
                    mk = part == k if m is None else m & (part == k)
                    pk = mk & pos
                    dk, vk = dt[mk], v[mk]
                s = sums[k]  # (each sum added as before: the same values, bit for bit)
                s[0] += dk.sum()
                s[1] += (vk * dk).sum()
                s[2] += np.count_nonzero(pk)
                s[3] += (va[pk] * dt[pk]).sum()
                _count(hist[k], _bins((va[pk] / HIST_STEP).astype(np.int64), HIST_BINS))

    def _labels(self, class_list: list[str]) -> np.ndarray:
        """``class_list`` (a ledger's, which only grows) as an object array, made again only
        when a class was added or the list is another's."""
        src, got = getattr(self, "_labels_of", (None, None))
        if src is not class_list or len(got) != len(class_list):
            got = np.asarray(class_list, dtype=object)
            self._labels_of = (class_list, got)
        return got

    def add_trajectory(self, t_s, v_mps, label: str, dt: float | None = None) -> None:
        """Add one vehicle's trajectory (times [s], speeds [m/s], in time order, at a step
        of ``dt`` [s]; None: the median spacing of its times) as a run reads it: the states
        at the first step of every whole second (:func:`whole_second`), central differences
        over the samples one second either side (none across a gap longer than
        :data:`MAX_SPAN_S`)."""
        t, v = np.asarray(t_s, float), np.asarray(v_mps, float)
        if dt is None:
            dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
        if len(t) > 1:  # every step: positive kinetic energy per kg, distance at v_t (Euler)
            acc = self.kinetic.setdefault(label, np.zeros(2))
            acc += (np.maximum(0.5 * np.diff(v ** 2), 0.0).sum(), (v[1:] * np.diff(t)).sum())
        first = np.floor(t + 1e-9) != np.floor(t - dt + 1e-9)
        t, v = t[first], v[first]
        if len(t) < 3:
            return
        span = t[2:] - t[:-2]
        ok = span <= MAX_SPAN_S
        self.add(np.full(int(ok.sum()), label), v[1:-1][ok], ((v[2:] - v[:-2]) / span)[ok], 0.5 * span[ok])

    def merge(self, other: "Dynamics") -> None:
        """Add the sums of ``other`` (another bucket's vehicles of the same run)."""
        for lab, x in other.kinetic.items():
            acc = self.kinetic.setdefault(lab, np.zeros(2))
            acc += x
        for lab, x in other.beyond.items():
            self.beyond.setdefault(lab, np.zeros(2, np.int64))[:] += x
        for lab in other.sums:
            sums, hist = self._acc(lab)
            sums += other.sums[lab]
            hist += other.hist[lab]
            self.acc_hist[lab] += other.acc_hist[lab]

    def summary(self) -> dict:
        """Per class: ``parts`` — per RDE part its mean speed [km/h], the 95th percentile of
        v·a_pos [m²/s³], RPA [m/s²], the RDE bounds at that mean speed, time [s], distance
        [km], samples with a > 0.1 m/s², and whether each figure is judged (enough samples:
        :data:`MIN_SAMPLES`) — and ``kinetic_j_per_kg_km``, the positive kinetic energy per kg
        and km at the run's own step (what the acceleration term books as traction, per kg,
        where the rest of the road load does not turn the step's power negative; against
        1000 × RPA it shows what oscillations shorter than the 1-Hz differences add)."""
        out = {}
        for lab in dict.fromkeys([*self.sums, *self.kinetic]):
            parts = {}
            for k, (name, _) in enumerate(PARTS):
                t, d, n, va = self.sums[lab][k] if lab in self.sums else (0.0, 0.0, 0, 0.0)
                if t <= 0:
                    continue
                vbar = 3.6 * d / t
                h = self.hist[lab][k]
                p95 = float("nan")
                if h.sum() > 0:  # the upper edge of the bin holding the 95th percentile
                    p95 = _quantile(h, 0.95, HIST_STEP)
                parts[name] = {"mean_speed_kmh": vbar, "va_pos_95_m2ps3": p95,
                               "rpa_mps2": va / d if d > 0 else float("nan"),
                               "rde_va_pos_95_max": va_pos_95_max(vbar), "rde_rpa_min": rpa_min(vbar),
                               "time_s": float(t), "distance_km": float(d) / 1000.0,
                               "apos_samples": int(n), "va_pos_95_judged": bool(n >= MIN_SAMPLES),
                               "rpa_judged": bool(t >= MIN_SAMPLES)}
            kin, dist = self.kinetic.get(lab, (0.0, 0.0))
            out[lab] = {"parts": parts, "kinetic_j_per_kg_km": 1000.0 * kin / dist if dist > 0 else float("nan"),
                        "accel_profile": accel_profile(self.acc_hist[lab]) if lab in self.acc_hist else []}
            if lab in self.beyond:  # a heavy class: its steps beyond an engine's specific power
                k, m = (int(x) for x in self.beyond[lab])
                out[lab]["beyond_engine_power"] = {"w_per_kg": HEAVY_POWER_W_PER_KG, "steps": k,
                                                   "of_steps": m, "share": k / m if m else 0.0}
        return out


def _quantile(h: np.ndarray, q: float, step: float) -> float:
    """The upper edge of the histogram bin (width ``step``) that holds the ``q`` quantile."""
    return round((np.searchsorted(np.cumsum(h), q * h.sum(), side="left") + 1) * step, 9)


def accel_profile(acc_hist: np.ndarray) -> list[dict]:
    """Per speed bin with :data:`PROFILE_MIN_SAMPLES` 1-Hz accelerations above
    :data:`A_POS_MIN` or more: its speeds [m/s] (``speed_to_mps`` None: and above), samples,
    and the median, 85th and 95th percentile of those accelerations [m/s²] (each the upper
    edge of its :data:`ACC_STEP` bin)."""
    out = []
    for k, h in enumerate(acc_hist):
        n = int(h.sum())
        if n < PROFILE_MIN_SAMPLES:
            continue
        out.append({"speed_from_mps": k * PROFILE_BIN_MPS,
                    "speed_to_mps": (k + 1) * PROFILE_BIN_MPS if k < PROFILE_BINS - 1 else None,
                    "samples": n, **{f"a_pos_{q}_mps2": _quantile(h, q / 100, ACC_STEP) for q in (50, 85, 95)}})
    return out


def sumo_profile(profile: list[dict], q: int = 95) -> dict | None:
    """SUMO 1.28's speed-dependent desired acceleration of a vType from an
    :func:`accel_profile`: ``speedTable`` (each bin's middle [m/s]; the last open bin at its
    lower edge) and ``desAccelProfile`` (its ``q``-th percentile [m/s²]), as the attribute
    strings; None with fewer than two bins. SUMO holds the first and last value beyond the
    table's ends (tests/test_sim_dynamics.py drives it)."""
    if len(profile) < 2:
        return None
    speeds = [b["speed_from_mps"] + (PROFILE_BIN_MPS / 2 if b["speed_to_mps"] is not None else 0.0)
              for b in profile]
    return {"speedTable": " ".join(f"{x:g}" for x in speeds),
            "desAccelProfile": " ".join(f"{b[f'a_pos_{q}_mps2']:g}" for b in profile)}


def of_trajectory(t_s, v_mps, label: str = "trajectory", dt: float | None = None) -> dict:
    """:meth:`Dynamics.summary` of one trajectory (:meth:`Dynamics.add_trajectory`)."""
    d = Dynamics()
    d.add_trajectory(t_s, v_mps, label, dt)
    return d.summary().get(label, {"parts": {}, "kinetic_j_per_kg_km": float("nan")})


def markdown_rows(doc: dict, lead: list[str], min_apos: int = 0, kinetic: bool = False) -> list[str]:
    """Markdown table rows of one class's :meth:`Dynamics.summary` (``doc``), one per part
    with at least ``min_apos`` accelerating samples, each after the cells ``lead``; the
    columns of :func:`markdown_head`."""
    rows = []
    for part, p in doc["parts"].items():
        if p["apos_samples"] >= min_apos:
            # (a figure on fewer than MIN_SAMPLES samples is not judged: marked *, see the note)
            va = "" if p.get("va_pos_95_judged", True) else "*"
            rpa = "" if p.get("rpa_judged", True) else "*"
            rows.append(f"| {' | '.join(lead)} | {part} | {p['mean_speed_kmh']:.1f} | {p['va_pos_95_m2ps3']:.1f}{va} "
                        f"({p['rde_va_pos_95_max']:.1f}) | {p['rpa_mps2']:.3f}{rpa} ({p['rde_rpa_min']:.3f}) | "
                        f"{p['time_s']:.0f} |" + (f" {doc['kinetic_j_per_kg_km']:.0f} |" if kinetic else ""))
    return rows


def unjudged_note(doc: dict) -> list[str]:
    """The note under :func:`markdown_rows`' table when a figure in it is not judged."""
    if all(p.get("va_pos_95_judged", True) and p.get("rpa_judged", True) for p in doc["parts"].values()):
        return []
    return [f"\\* not judged against the RDE bound: fewer than {MIN_SAMPLES} samples (accelerating "
            "samples for v·a_pos, seconds for RPA) in that part", ""]


def markdown_head(lead: list[str], kinetic: bool = False) -> list[str]:
    """The header of :func:`markdown_rows`' table after the columns ``lead`` (``kinetic``: with
    the whole trajectory's kinetic energy in every row, as a table of one row per trajectory
    and part shows it)."""
    cols = [*lead, "part", "mean speed km/h", "v·a_pos 95th pct. m²/s³ (RDE max)", "RPA m/s² (RDE min)",
            "part's time s", *(["kinetic energy J/(kg·km), whole trajectory"] if kinetic else [])]
    return ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]


def _number(val: str | None, default: float | None) -> float | str | None:
    """A car-following attribute as written (a number, else its text), else ``default``."""
    if val is None:
        return default
    try:
        return float(val)
    except ValueError:
        return val


def vtype_driving(driving: dict | None, vclass: str | None) -> dict:
    """What drives a vType's accelerations (:attr:`~sumo_drvpw.sim.vtypes.VTypeInfo.driving`
    as written, else SUMO's defaults for its vClass): ``car_follow_model``, ``accel_mps2``,
    ``decel_mps2``, ``sigma`` (None: its model reads none) and ``des_accel_profile`` (a
    speed-dependent desired acceleration, SUMO's ``speedTable``/``desAccelProfile``)."""
    d = driving or {}
    accel, decel, sigma = SUMO_CF_DEFAULTS.get(vclass or "passenger", SUMO_CF_DEFAULTS["passenger"])
    model = d.get("carFollowModel") or CF_DEFAULT_MODEL
    return {"car_follow_model": model, "accel_mps2": _number(d.get("accel"), accel),
            "decel_mps2": _number(d.get("decel"), decel),
            "sigma": _number(d.get("sigma"), sigma) if model in SIGMA_MODELS else None,
            "des_accel_profile": d.get("desAccelProfile") is not None}


#: car-following models whose speed SUMO raises by at most the vType's ``accel``·Δt in a step
#: (MSCFModel::maxNextSpeed in finalizeSpeed; KraussPS lower still uphill)
ACCEL_CAPPED_MODELS = frozenset({*SIGMA_MODELS, "IDM", "IDMM"})


def accel_bounds(file_vtypes) -> dict[str, float]:
    """vType id → the most [m/s²] SUMO let its vehicles gain speed by driving (its ``accel`` as
    written, else its vClass's default: :func:`vtype_driving`), for the vTypes of the route
    files ``file_vtypes`` (:class:`~sumo_drvpw.sim.vtypes.FileVTypes`) whose car-following
    model caps it there (:data:`ACCEL_CAPPED_MODELS`) and that write no ``maxAccelProfile``;
    the others are not in it (their bound unknown)."""
    out = {}
    for vt, info in file_vtypes.items():
        d = vtype_driving(info.driving, info.vclass)
        acc = d["accel_mps2"]
        if (d["car_follow_model"] in ACCEL_CAPPED_MODELS and isinstance(acc, float) and acc > 0
                and "maxAccelProfile" not in (info.driving or {})):
            out[vt] = acc
    return out


def _text(x) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


def _vtypes(doc: dict, show: int = 4) -> str:
    """'; vTypes a (Krauss, accel 2.6, sigma 0.5), b … and N more' of a class's summary
    (``vtypes``, ``vtype_driving``), or ''."""
    names = doc.get("vtypes") or []
    if not names:
        return ""
    more = f" and {len(names) - show} more" if len(names) > show else ""

    def say(name):
        p = (doc.get("vtype_driving") or {}).get(name)
        if p is None:
            return name
        what = [p["car_follow_model"], f"accel {_text(p['accel_mps2'])}"]
        if p["sigma"] is not None:
            what.append(f"sigma {_text(p['sigma'])}")
        if p["des_accel_profile"]:
            what.append("desAccelProfile")
        return f"{name} ({', '.join(what)})"
    return f"; vType{'s' if len(names) > 1 else ''} {', '.join(say(n) for n in names[:show])}{more}"


def _apart(value: float, bound: float, op: str) -> str:
    """``value op bound`` with as many decimals (1 to 3) as show them apart (18.4 > 18.4 said
    nothing)."""
    for d in (1, 2, 3):
        if f"{value:.{d}f}" != f"{bound:.{d}f}":
            break
    return f"{value:.{d}f} {op} {bound:.{d}f}"


def warnings(summary: dict) -> list[str]:
    """At most two lines: the classes whose trajectories an RDE test would reject as too
    dynamic in some part, and those it would reject as too smooth (judged parts only)."""
    hard, smooth = [], []
    for lab, doc in summary.items():
        parts = doc["parts"]
        heavy = ("; a car's bound: a heavy vehicle's real driving stays well below it" if lab in HEAVY else
                 "; a car's bound: a two-wheeler's real driving may exceed it" if lab in TWO_WHEELERS else "")
        over = [f"{name} {_apart(p['va_pos_95_m2ps3'], p['rde_va_pos_95_max'], '>')} m²/s³ at "
                f"{p['mean_speed_kmh']:.0f} km/h" for name, p in parts.items()
                if p["va_pos_95_judged"] and p["va_pos_95_m2ps3"] > p["rde_va_pos_95_max"]]
        under = [f"{name} {p['rpa_mps2']:.3f} < {p['rde_rpa_min']:.3f} m/s² at {p['mean_speed_kmh']:.0f} km/h"
                 for name, p in parts.items() if p["rpa_judged"] and p["rpa_mps2"] < p["rde_rpa_min"]]
        if over:
            hard.append(f"{lab} ({', '.join(over)}{heavy}{_vtypes(doc)})")
        if under:  # a bus or truck, with a fraction of a car's power per kg, may drive smoother
            low = "; a car's bound: a heavy vehicle's real driving may stay below it" if lab in HEAVY else ""
            smooth.append(f"{lab} ({', '.join(under)}{low})")
    out = []
    strong = {lab: doc["beyond_engine_power"] for lab, doc in summary.items()
              if doc.get("beyond_engine_power", {}).get("share", 0.0) > HEAVY_POWER_WARN_SHARE}
    if strong:
        out.append("driving dynamics: heavy vehicles accelerate and climb beyond any engine's power: "
                   + "; ".join(f"{lab} {b['share']:.1%} of its vehicle-steps above {b['w_per_kg']:g} W/kg for "
                               "accelerating and climbing alone" for lab, b in strong.items())
                   + " (the strongest trucks' 560 kW are 14 W/kg at 40 t): SUMO's car-following models "
                   "neither see the grade nor limit the power, and the energy and fuel booked follow those "
                   "trajectories — lower the vTypes' accel, their maxSpeed on climbs, or use a power-"
                   "limited model (summary.json driving_dynamics beyond_engine_power)")
    if hard:
        out.append("driving dynamics: trajectories accelerate harder than a valid real-world test trip "
                   f"(EU RDE, 95th percentile of v·a_pos above its bound): {'; '.join(hard)}; the acceleration "
                   "term books more kinetic energy than such driving would: check the vTypes' accel and sigma "
                   "(the Krauss model accelerates at the full accel at any speed, where a real vehicle's power "
                   "limits it, and its driver imperfection sigma adds speed "
                   "oscillations whose size depends on the step length, SUMO issue #10494; the vType "
                   "attributes speedTable and desAccelProfile lower its desired acceleration with speed) "
                   "(summary.json driving_dynamics)")
    if smooth:
        out.append("driving dynamics: trajectories smoother than a valid real-world test trip (EU RDE, "
                   f"relative positive acceleration below its bound): {'; '.join(smooth)}; the acceleration term "
                   "books less kinetic energy than real driving, whose speed varies more (summary.json "
                   "driving_dynamics)")
    return out


def of_log(df) -> "tuple[dict, int]":
    """(:meth:`Dynamics.summary` of a drive log's trips — a canonical log's ``time_s``,
    ``speed_mps`` and ``trip_id``; each trip one trajectory — under :data:`LOG_LABEL`, or {}
    when no trip gives a 1-Hz sample, with ``logged_s`` (the trips' time, first to last
    sample) and ``median_step_s`` (the median spacing of their samples); the number of
    trips). The parts' ``time_s`` is the time the 1-Hz figures cover: against ``logged_s``
    it shows how much of a coarsely sampled log they rest on (:func:`coverage_warning`)."""
    d = Dynamics()
    trips = df["trip_id"].astype(str).to_numpy()
    t, v = df["time_s"].to_numpy(float), df["speed_mps"].to_numpy(float)
    names = list(dict.fromkeys(trips))
    logged, steps = 0.0, []
    for trip in names:
        s = (trips == trip) & np.isfinite(v) & np.isfinite(t)  # (the reader: time increases within a trip)
        d.add_trajectory(t[s], v[s], LOG_LABEL)
        if s.sum() > 1:
            logged += float(t[s][-1] - t[s][0])
            steps.append(np.diff(t[s]))
    out = d.summary().get(LOG_LABEL, {})
    if steps:  # (also where no part has a 1-Hz sample: the refusal says how far apart they are)
        out["logged_s"] = logged
        out["median_step_s"] = float(np.median(np.concatenate(steps)))
    return out, len(names)


#: the share of a log's time its 1-Hz figures must cover before they stand for the log
MIN_COVERAGE = 0.5


def coverage_warning(dyn: dict) -> str | None:
    """A warning when the 1-Hz figures of :func:`of_log`'s result cover less than
    :data:`MIN_COVERAGE` of the logged time (samples mostly more than a second apart, or
    gaps over :data:`MAX_SPAN_S`), else None."""
    covered = sum(p["time_s"] for p in dyn.get("parts", {}).values())
    logged = dyn.get("logged_s", 0.0)
    if logged <= 0 or covered >= MIN_COVERAGE * logged:
        return None
    return (f"the 1-Hz figures rest on {covered:.0f} s of the logs' {logged:.0f} s "
            f"({100 * covered / logged:.1f} %): the samples are {dyn['median_step_s']:g} s apart "
            f"(median), and RDE differences need speeds one second apart (gaps up to {MAX_SPAN_S:g} s); "
            "the figures describe only those stretches, not the logs")


def report_md(doc: dict) -> str:
    """The report.md of ``sumo-drvpw dynamics``' document (its dynamics.json)."""
    dyn = doc["driving_dynamics"]
    lines = ["# Driving dynamics of the logs", "",
             f"{doc['trips']} trips of {len(doc['logs'])} file(s), measured as a SUMO run measures its "
             f"trajectories ({doc['source']}; speeds at 1 Hz, central differences).", "",
             *([f"**Warning:** {w}.", ""] if (w := coverage_warning(dyn)) else []),
             *markdown_head(["logs"]), *markdown_rows(dyn, [LOG_LABEL]), "", *unjudged_note(dyn),
             f"Positive kinetic energy over all parts: {dyn['kinetic_j_per_kg_km']:.0f} J/(kg·km).", "",
             "Accelerations above 0.1 m/s² by speed (1 Hz):", "",
             "| speed m/s | samples | median m/s² | 85th pct. | 95th pct. |", "|---|---|---|---|---|"]
    for b in dyn.get("accel_profile", []):
        to = "…" if b["speed_to_mps"] is None else f"{b['speed_to_mps']:g}"
        lines.append(f"| {b['speed_from_mps']:g}–{to} | {b['samples']} | {b['a_pos_50_mps2']:.2f} | "
                     f"{b['a_pos_85_mps2']:.2f} | {b['a_pos_95_mps2']:.2f} |")
    vt = doc["sumo_vtype"]
    lines.append("")
    if vt:
        lines += ["A SUMO vType that accelerates, wherever it is free to, at these drivers' 95th "
                  "percentile (SUMO 1.28 reads the two attributes on the vType; between the speeds it "
                  "interpolates, beyond them it holds the first and last value):", "", "```xml",
                  f'<vType id="..." speedTable="{vt["speedTable"]}" desAccelProfile="{vt["desAccelProfile"]}"/>',
                  "```", "",
                  "It changes the traffic as well as the dynamics: vehicles that pull away more slowly "
                  "clear fewer per green, so a scenario's flows and travel times are calibrated again "
                  "with it (docs/scenario.md, \"Driving dynamics\", measured on Bologna Acosta)."]
    else:
        lines.append("Too few accelerating samples for a vType profile (two speed bins of 50 needed).")
    return "\n".join(lines) + "\n"
