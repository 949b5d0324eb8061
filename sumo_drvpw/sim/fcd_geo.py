"""An FCD written in geographic or UTM coordinates (SUMO's ``--fcd-output.geo``,
``--fcd-output.utm``) brought back into the network's x, y, so that an FCD replay
(:mod:`sumo_drvpw.sim.fcd`) tells parked vehicles beside their lane
(:class:`~sumo_drvpw.sim.fcd_conn.ParkedTest`) as from an FCD in the network's own
coordinates.

SUMO writes such a row's x, y as the network's position less the network's
``netOffset`` (utm), projected back by the network's ``projParameter`` (geo: longitude,
latitude; GeoConvHelper::cartesian2geo). The inverse: x_net = E(λ, φ) + offset_x,
y_net = N(λ, φ) + offset_y. UTM projections (``+proj=utm +zone=Z [+south]`` on WGS84 —
netconvert's for OSM imports) are computed here (Krüger's series to n³, mm within a zone:
Karney 2011, "Transverse Mercator with an accuracy of a few nanometers", eq. 35); another
projection with pyproj installed through sumolib; else the rows are read as without
x, y (then the route files' parking stops tell parked vehicles,
:mod:`sumo_drvpw.sim.fcd_stops`), and the replay says so.

Before 2026-11-29 the replay compared longitude, latitude with the network's metres: a
standing car whose lane's line passed within 50 m of the point (10°, 53.5°) across its
heading was taken for one parked beside it (the Hamburg scenario: 15 vehicles, 339 rows
in 600 s, booked parked or "untold" instead of standing at a light)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from sumo_drvpw.fileio import open_maybe_gzip

_TRUE = ("true", "1", "yes", "on", "x", "t")

#: WGS84's semi-major axis [m] and flattening; UTM's scale on the central meridian, false
#: easting and the southern hemisphere's false northing [m]
WGS84_A, WGS84_F = 6378137.0, 1.0 / 298.257223563
UTM_K0, UTM_E0, UTM_N0_SOUTH = 0.9996, 500000.0, 10000000.0
#: a header-less FCD's coordinates (:meth:`NetCoordinates.convert`) are the ones that put its
#: rows nearest their lanes only when that median distance is at most this [m] (a parked
#: vehicle stands nearer its lane: network.PARKED_MAX_OFFSET_M); else its x, y are unknown
AUTO_MAX_M = 50.0


def recorded_coordinates(head: dict | None) -> str:
    """"geo", "utm" or "net": the coordinates an XML FCD's header (``head``, its
    options) says its x, y are in; "auto" without a header (SUMO's Parquet or CSV FCD: told
    from the rows, :meth:`NetCoordinates.convert`)."""
    if head is None:
        return "auto"
    for mode in ("geo", "utm"):
        if head.get(f"fcd-output.{mode}", "false").strip().lower() in _TRUE:
            return mode
    return "net"


def net_location(net_file) -> dict[str, str]:
    """The attributes of a SUMO network's ``<location>`` element ({} where it has none)."""
    with open_maybe_gzip(Path(net_file)) as fh:
        head = fh.read(1 << 16).decode("utf-8", "replace")
    m = re.search(r"<location\b([^>]*)/?>", head)
    return dict(re.findall(r'([\w:]+)="([^"]*)"', m.group(1))) if m else {}


def utm_forward(lon_deg, lat_deg, zone: int, south: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """UTM easting, northing [m] of WGS84 longitudes, latitudes [°] in ``zone`` (Krüger's
    series, Karney 2011 eq. 35 to n³)."""
    n = WGS84_F / (2.0 - WGS84_F)
    big_a = WGS84_A / (1.0 + n) * (1.0 + n ** 2 / 4.0 + n ** 4 / 64.0)
    alpha = (n / 2.0 - 2.0 * n ** 2 / 3.0 + 5.0 * n ** 3 / 16.0,
             13.0 * n ** 2 / 48.0 - 3.0 * n ** 3 / 5.0, 61.0 * n ** 3 / 240.0)
    phi = np.radians(np.asarray(lat_deg, float))
    lam = np.radians(np.asarray(lon_deg, float) - (6.0 * zone - 183.0))
    c = 2.0 * np.sqrt(n) / (1.0 + n)
    t = np.sinh(np.arctanh(np.sin(phi)) - c * np.arctanh(c * np.sin(phi)))
    xi = np.arctan2(t, np.cos(lam))
    eta = np.arctanh(np.sin(lam) / np.sqrt(1.0 + t * t))
    e, nn = eta.copy(), xi.copy()
    for j, a in enumerate(alpha, start=1):
        e += a * np.cos(2 * j * xi) * np.sinh(2 * j * eta)
        nn += a * np.sin(2 * j * xi) * np.cosh(2 * j * eta)
    return UTM_E0 + UTM_K0 * big_a * e, (UTM_N0_SOUTH if south else 0.0) + UTM_K0 * big_a * nn


class NetCoordinates:
    """x, y of an FCD's rows → the network's (:meth:`__call__`), for an FCD written in
    ``mode`` ("geo", "utm", "net") on the network ``net_file``. ``lost``: the reason x, y
    cannot be brought back (then the rows are read as without x, y; None: they can)."""

    def __init__(self, mode: str, net_file):
        self.mode, self.lost, self._proj, self._net_file = mode, None, None, net_file
        self._checked = mode not in ("geo", "utm")  # a header's geo/utm: checked on the first rows on lanes
        self._setup(net_file)

    def _setup(self, net_file) -> None:
        mode, self.lost = self.mode, None
        if mode in ("net", "auto"):
            return
        loc = net_location(net_file)
        try:
            self.offset = tuple(float(v) for v in loc.get("netOffset", "0,0").split(","))[:2]
        except ValueError:
            self.offset = (0.0, 0.0)
        proj = loc.get("projParameter", "!").strip()
        if mode == "utm" or proj == "!":  # (no projection: SUMO writes the offset's shift alone)
            self._proj = "shift"
            return
        tok = dict((k.lstrip("+"), v) for k, _, v in (t.partition("=") for t in proj.split()))
        if (tok.get("proj") == "utm" and tok.get("zone", "").isdigit() and tok.get("ellps", "WGS84") == "WGS84"
                and tok.get("datum", "WGS84") == "WGS84"):
            zone, south = int(tok["zone"]), "south" in tok
            self._proj = lambda lon, lat: utm_forward(lon, lat, zone, south)
            return
        try:
            import pyproj

            p = pyproj.Proj(proj)
            self._proj = lambda lon, lat: p(np.asarray(lon, float), np.asarray(lat, float))
        except Exception:  # pyproj absent, or a projection it does not read
            self.lost = (f"its x, y are longitude, latitude (fcd-output.geo) and the network's projection "
                         f"{proj!r} needs pyproj (pip install pyproj) to bring them back")

    def __call__(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """The rows' x, y in the network's coordinates [m] (NaN where they cannot be)."""
        x, y = np.asarray(x, float), np.asarray(y, float)
        if self.lost is not None:
            return np.full(len(x), np.nan), np.full(len(y), np.nan)
        if self.mode == "net":
            return x, y
        if self._proj != "shift":
            off = (np.abs(x) > 180.0) | (np.abs(y) > 90.0)  # no longitude, latitude
            with np.errstate(divide="ignore", invalid="ignore"):  # (a pole: ±90°)
                x, y = self._proj(np.where(off, np.nan, x), np.where(off, np.nan, y))
        return x + self.offset[0], y + self.offset[1]

    def _sample(self, cols: dict, net):
        """(x, y, the bins of their lanes' positions) of at most 500 rows on lanes of ``net``
        with finite x, y, pos; None when there are none."""
        if net is None or net.centre_x is None or "lane" not in cols or "pos" not in cols:
            return None
        x, y = np.asarray(cols["x"], float), np.asarray(cols["y"], float)
        lane = np.array([net.lane_index.get(v, -1) for v in np.asarray(cols["lane"], object)[:5000]], np.int64)
        pos = np.asarray(cols["pos"], float)[:len(lane)]
        k = np.flatnonzero((lane >= 0) & np.isfinite(x[:len(lane)]) & np.isfinite(y[:len(lane)])
                           & np.isfinite(pos))[:500]
        return (x[k], y[k], net.bin_index(lane[k], pos[k])) if len(k) else None

    def _median_m(self, sample, net) -> float:
        """The median distance [m] of ``sample``'s rows from their lanes in this mode."""
        cx, cy = self(sample[0], sample[1])
        with np.errstate(invalid="ignore"):
            d = np.hypot(cx - net.centre_x[sample[2]], cy - net.centre_y[sample[2]])
        d = d[np.isfinite(d)]  # (a row out of range: NaN)
        return float(np.median(d)) if len(d) else np.inf

    def convert(self, cols: dict, net=None) -> None:
        """A block's columns (``x``, ``y``) converted in place. Without a header (mode
        "auto") the first block with x, y on lanes of the network ``net``
        (:class:`~sumo_drvpw.sim.network.Network`) tells the mode: the one that puts its
        rows nearest their lanes' centre lines at their positions (median distance over at
        most 500 rows)."""
        if (self.mode == "net" and self.lost is None) or "x" not in cols or "y" not in cols:
            return
        if not self._checked and self.lost is None and (sample := self._sample(cols, net)) is not None:
            self._checked = True  # a header's geo/utm whose rows lie far from their lanes: another network's
            far = self._median_m(sample, net)
            if not far <= AUTO_MAX_M:
                self.lost = (f"its x, y (fcd-output.{self.mode}) "
                             + (f"lie {far:.3g} m from their lanes (median) once brought into the network's"
                                if far < np.inf else "are no longitude, latitude (out of range)")
                             + ": recorded on another network (or another zone's), or its coordinates edited")
        if self.mode == "auto":
            sample = self._sample(cols, net)
            if sample is None:
                return
            best, lost = (np.inf, "net"), []
            for mode in ("net", "geo", "utm"):
                self.mode = mode
                self._setup(self._net_file)
                if self.lost is None:
                    best = min(best, (self._median_m(sample, net), mode))
                else:
                    lost.append(self.lost)
            self.mode, self.lost = best[1], None
            self._setup(self._net_file)
            if not best[0] <= AUTO_MAX_M:  # none puts the rows on their lanes: x, y unknown, said
                self.mode = "geo" if lost else "net"
                self.lost = ((f"{lost[0]} (a file without a header: its x, y lie {best[0]:.3g} m from their "
                              "lanes in the coordinates that could be computed)") if lost else
                             (f"its x, y lie {best[0]:.3g} m from their lanes (median) in the network's, "
                              "geo and UTM coordinates alike"))
                cols["x"], cols["y"] = self(cols["x"], cols["y"])
                return
        if self.mode != "net" or self.lost is not None:
            cols["x"], cols["y"] = self(cols["x"], cols["y"])
