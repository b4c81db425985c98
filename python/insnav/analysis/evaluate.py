"""``insnav evaluate``: accuracy of a solution against a truth, per axis,
horizontal and 3-D, per outage, with reconvergence times and consistency.

The same numbers from Python: :func:`evaluate` returns a dict.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from ..units import wrap_deg
from .metrics import errors, reconvergence_time, rms, unwrapped_deg

EXAMPLES = """examples:
  insnav evaluate run3-rbukf.csv run3/truth.csv --outages 50:90
  insnav evaluate sol.csv ../shared/data/kfgins/sim/truth-sim.nav.xz --json
  insnav evaluate walk_sol.csv ../shared/data/rtklibexplorer_walk_0827/raw/gnss_1730_sf.pos --quality 1

TRUTH may be a truth.csv (insnav dataset), a dataset directory, a KF-GINS .nav(.xz), a static
antenna position "x,y,z" (ECEF m) or "lat_deg,lon_deg,h_m", or an RTKLIB .pos solution (GPST; compared at its own epochs, the solution t being GPS seconds of
week as written by `insnav run --format rinex`; the .pos is the antenna, the solution the IMU
centre: the lever arm is not applied; no attitude, so no attitude rows).
Reported: RMS and max of the N/E/D position [m], velocity [m/s] and roll/pitch/yaw [deg] errors,
horizontal and 3-D position; for each outage the max horizontal error inside it and in the
60 s after it and the reconvergence time (first time after the outage from which the
horizontal error stays within 1.5x its pre-outage RMS for 5 s); consistency rms(error/sigma)
per axis (about 1 for a consistent filter).  A carrier-phase solution (an RTKLIB .pos as SOLUTION,
or an insnav rtk solution with its <out>.rtk.csv beside it) also gets the fix rate and the 3-D
error per fix status (fixed, float, dgps).
  insnav evaluate rtk.pos 4075579.19,931853.37,4801569.19"""


class _Sol:
    pass


def has_rows(obj, path):
    """``obj`` (a solution or truth read from ``path``), or ValueError "PATH: no rows" when it has none
    (a file with its header line only: the comparison would index its first epoch)."""
    if len(np.atleast_1d(obj.t)) == 0:
        raise ValueError(f"{path}: no rows")
    return obj


def _read_solution(path):
    """A solution file; an RTKLIB ``.pos`` (insnav rtk or RTKLIB) keeps its Q as ``fix_status``, and an
    insnav rtk solution gets it from ``<path>.rtk.csv``."""
    from ..filters.solution import load_solution

    p = Path(path)
    if p.suffix == ".pos":
        sol = _pos_solution(p)
        side = p.with_suffix(p.suffix + ".rtk.csv")
        if side.exists():  # an insnav rtk .pos: the slip counts of its sidecar (Q stays the .pos's)
            a = _read_rtk_sidecar(side)
            sol.slip_counts = {k[len("slips_"):]: int(np.nansum(np.atleast_1d(a[k]))) for k in a.dtype.names
                               if k.startswith("slips_")}
        return sol
    return attach_fix_status(has_rows(load_solution(path), p), p)


def attach_fix_status(sol, path):
    """Give ``sol`` a ``fix_status`` per row from the ``<path>.rtk.csv`` sidecar of an rtk run (if any)."""
    p = Path(path)
    side = p.with_suffix(p.suffix + ".rtk.csv")
    if side.exists():
        from ..gnss.gpstime import SECONDS_PER_WEEK

        a = _read_rtk_sidecar(side)
        status = np.atleast_1d(a["status"]).astype(int)
        sol.slip_counts = {k[len("slips_"):]: int(np.nansum(np.atleast_1d(a[k]))) for k in a.dtype.names
                           if k.startswith("slips_")}
        if "t_s" in a.dtype.names:  # RTK/INS: rows at the IMU rate carry the status of the last epoch
            t = np.atleast_1d(a["t_s"])
            i = np.searchsorted(t, np.asarray(sol.t) + 1e-6, side="right") - 1
            dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
            ok = (i >= 0) & (np.asarray(sol.t) - t[np.maximum(i, 0)] <= 1.5 * dt)
            # continuous AR: the rows after a fixed epoch hold its fixed solution (the engine's output
            # shadow, engine/rtk_ins_engine.hpp) until the next epoch, as fix-and-hold's rows hold theirs
            sol.fix_status = np.where(ok, status[np.maximum(i, 0)], 0).astype(int)
            sol.epoch_fix_status = status  # fix rate over the rover epochs, not the rows
            return sol
        t = np.atleast_1d(a["t_gps_s"])
        t = t - SECONDS_PER_WEEK * np.floor(t[0] / SECONDS_PER_WEEK)
        i = np.clip(np.searchsorted(t, np.asarray(sol.t) - 1e-6), 0, len(t) - 1)
        sol.fix_status = np.where(np.abs(t[i] - sol.t) < 1e-3, status[i], 0).astype(int)
    return sol


def _read_rtk_sidecar(side: Path) -> np.ndarray:
    """``<sol>.rtk.csv`` (status, slips and times per rover epoch) as a structured array; a one-line
    ValueError naming the file when it is empty, has no rows or is not such a table."""
    import warnings

    from ..data.dataset import parse_numeric_origin
    from ..data.textio import read_bytes

    data = read_bytes(side)
    nl = data.find(b"\n")
    header = (data if nl < 0 else data[:nl]).decode("ascii", "replace").strip()
    names = [h.strip() for h in header.split(",")]
    need = {"status", "t_gps_s"}
    if not header or not need <= set(names):
        raise ValueError(f"{side}:1: not an insnav rtk table (its header needs {', '.join(sorted(need))}; "
                         f"got {header[:80]!r})")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a, _ = parse_numeric_origin(b"" if nl < 0 else memoryview(data)[nl + 1:], len(names), str(side),
                                    first_line=2, names=tuple(names))
    if a.shape[0] == 0:
        raise ValueError(f"{side}: no rows (the header only)")
    out = np.empty(a.shape[0], dtype=[(n, float) for n in names])
    for j, n in enumerate(names):
        out[n] = a[:, j]
    return out


def _pos_solution(path):
    """An RTKLIB .pos file as a solution (antenna position, GPS seconds of the first epoch's week)."""
    from .. import earth
    from ..gnss.gpstime import SECONDS_PER_WEEK
    from ..io.gnss_files import read_rtklib_pos

    ref = read_rtklib_pos(path)
    if len(ref.t_gps_s) == 0:
        raise ValueError(f"{path}: no solution records")
    out = _Sol()
    out.t = ref.t_gps_s - SECONDS_PER_WEEK * np.floor(ref.t_gps_s[0] / SECONDS_PER_WEEK)
    lat, lon, h = earth.ecef_to_geodetic(ref.r_e)
    out.lat_deg, out.lon_deg, out.h_m = np.degrees(lat), np.degrees(lon), h
    n = len(out.t)
    out.v_n = np.full((n, 3), np.nan)
    out.roll_deg = out.pitch_deg = out.yaw_deg = np.full(n, np.nan)
    # no covariance read from the .pos: no consistency figure (NaN sigmas)
    out.sigma_pos_n_m, out.sigma_vel_n_mps, out.sigma_att_deg = (np.full((n, 3), np.nan) for _ in range(3))
    # no IMU states and no GNSS records of a filter (insnav report draws what is there)
    out.acc_bias_mps2, out.gyro_bias_rps, out.acc_scale, out.gyro_scale = (np.full((n, 3), np.nan) for _ in range(4))
    out.gnss_t, out.nis, out.gnss_status = np.zeros(0), np.zeros(0), np.zeros(0, np.int8)
    out.innovation = np.zeros((0, 6))
    out.summary = dict(filter="RTKLIB .pos", coupling="gnss")
    out.fix_status = np.asarray(ref.q, int)
    return out


def static_truth(text: str, t):
    """A constant truth (a static antenna) from ``"x,y,z"`` ECEF [m] or ``"lat_deg,lon_deg,h_m"``, at times ``t``."""
    from .. import earth
    from ..data.dataset import Truth

    from ..filters.rtk import parse_base_position

    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        v = []
    if len(v) != 3:
        raise ValueError(f"truth {text!r}: not a file, nor x,y,z [m] / lat_deg,lon_deg,h_m")
    r_e = parse_base_position(v, f"truth {text!r}")  # finite, and lat,lon,h or ECEF near the Earth's surface
    if abs(v[0]) <= 90.0 and abs(v[1]) <= 360.0 and abs(v[2]) < 1e5:
        lat, lon, h = v[0], float(wrap_deg(v[1])), v[2]  # 242.5 -> -117.5
    else:
        la, lo, h = earth.ecef_to_geodetic(r_e)
        lat, lon = float(np.degrees(la)), float(np.degrees(lo))
    t = np.asarray(t, float)
    n = t.size
    z = np.zeros(n)
    return Truth(t=t.copy(), lat_deg=np.full(n, lat), lon_deg=np.full(n, lon), h_m=np.full(n, float(h)),
                 v_n=np.full((n, 3), np.nan), roll_deg=z + np.nan, pitch_deg=z + np.nan, yaw_deg=z + np.nan)


#: solution status by RTKLIB's Q (insnav writes 0, 1, 2, 4; a .pos from RTKLIB may hold the others)
POS_STATUS_NAMES = {0: "none", 1: "fixed", 2: "float", 3: "sbas", 4: "dgps", 5: "single", 6: "ppp"}

#: the header of a simulated carrier-phase dataset's antenna truth (``rtk_truth.csv``, GPS time)
RTK_TRUTH_HEADER = "t_gps_s,x_e_m,y_e_m,z_e_m"


_QUALITY_POS_ONLY = "--quality applies to an RTKLIB .pos truth only"


def _read_truth(path, quality=None, solution=None):
    """The reference of ``insnav evaluate`` / ``report``: an RTKLIB ``.pos``, a dataset folder (its
    ``truth.csv``; for an RTKLIB-layout ``solution`` (``.pos``: the antenna in GPS time) its
    ``rtk_truth.csv``, the antenna in GPS time), a simulated ``rtk_truth.csv``, a KF-GINS ``.nav`` or
    a truth CSV."""
    p = Path(path)
    if p.is_dir() and solution is not None and _antenna_in_gps_time(Path(solution)):
        if not (p / "rtk_truth.csv").is_file():
            raise ValueError(f"{solution} is an antenna in GPS time and {p} has no rtk_truth.csv (the antenna "
                             "truth); its truth.csv is the IMU centre in dataset time: give an antenna reference "
                             "(.pos, rtk_truth.csv or x,y,z)")
        p = p / "rtk_truth.csv"
    if quality is not None and p.suffix != ".pos":  # before any return: never accepted and ignored
        raise ValueError(_QUALITY_POS_ONLY)
    if p.is_file() and p.suffix == ".csv":
        with open(p, encoding="utf-8", errors="replace") as f:
            head = f.readline()
        if head.startswith(RTK_TRUTH_HEADER):
            return _rtk_truth(p)
    if p.suffix == ".pos":
        from ..gnss.gpstime import SECONDS_PER_WEEK
        from ..io.gnss_files import read_rtklib_pos
        from ..io.rinex_dataset import rtklib_truth

        from ..data.dataset import RowOrigin

        ref = read_rtklib_pos(p)
        if len(ref.t_gps_s) == 0:
            raise ValueError(f"{p}: no solution records")
        week0 = SECONDS_PER_WEEK * np.floor(ref.t_gps_s[0] / SECONDS_PER_WEEK)
        _check_truth_rows(np.column_stack([ref.t_gps_s - week0, ref.r_e]), RowOrigin(str(p), 1, ref.lines))
        t = rtklib_truth(ref, week0, quality)
        if len(t.t) == 0:
            raise ValueError(f"{p}: no records with Q <= {quality}")
        return t
    if p.is_dir():
        if not (p / "truth.csv").is_file():
            raise ValueError(f"{p}: the dataset has no truth.csv")
        p = p / "truth.csv"
    if ".nav" in p.name:
        from ..io.kfgins import read_kfgins_nav

        tr = read_kfgins_nav(p)
        _check_truth_rows(np.column_stack([tr.t, tr.lat_deg, tr.lon_deg, tr.h_m]), tr.origin)
        return has_rows(tr, p)
    from ..data.dataset import Truth, read_csv

    a, origin = read_csv(p, Truth.COLUMNS, return_origin=True)
    _check_truth_rows(a, origin)
    return has_rows(Truth.from_array(a), p)


def _check_truth_rows(a: np.ndarray, origin) -> None:
    """A truth table's rows (columns: time, then three of position): time and position finite, time
    strictly increasing (the comparison interpolates the truth in time); a ValueError naming the file
    and line of the first bad row.  Every kind of truth (CSV, .pos, .nav, rtk_truth.csv) goes through it."""
    a = np.asarray(a, float)
    if a.ndim != 2 or a.shape[0] == 0:
        return
    bad = ~np.all(np.isfinite(a[:, :4]), axis=1)  # t_s, lat_deg, lon_deg, h_m
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{origin.where(i)}: a truth row without a finite time and position "
                         f"({int(bad.sum())} such rows): remove them")
    back = np.flatnonzero(np.diff(a[:, 0]) <= 0.0)
    if back.size:
        i = int(back[0]) + 1
        fix = ("a GPS week rollover? give the time as seconds continuing across the week"
               if a[i - 1, 0] - a[i, 0] > 302400.0 else "sort the rows by time and remove repeated ones")
        raise ValueError(f"{origin.where(i)}: the truth's time does not increase ({a[i, 0]:.6f} s after "
                         f"{a[i - 1, 0]:.6f} s): {fix}")


def _antenna_in_gps_time(sol_path: Path) -> bool:
    """A solution of the antenna in GPS seconds of week: an RTKLIB-layout ``.pos``, or a GNSS-only
    ``--filter rtk`` run's table (its ``<sol>.rtk.csv`` has no IMU-time column ``t_s``)."""
    if sol_path.suffix == ".pos":
        return True
    side = sol_path.with_suffix(sol_path.suffix + ".rtk.csv")
    if not side.is_file():
        return False
    with open(side, encoding="utf-8", errors="replace") as f:
        head = f.readline().strip().split(",")
    return "t_gps_s" in head and "t_s" not in head


def _rtk_truth(p: Path):
    """A simulated ``rtk_truth.csv`` (the rover antenna, ECEF, GPS time) as a Truth in GPS seconds of
    the week of its first epoch (an RTKLIB ``.pos``'s time base); position only, compared at its epochs."""
    from .. import earth
    from ..data.dataset import Truth
    from ..gnss.gpstime import SECONDS_PER_WEEK

    from ..data.dataset import parse_numeric_origin
    from ..data.textio import read_bytes

    data = read_bytes(p)
    nl = data.find(b"\n")
    names = tuple(h.strip() for h in (data if nl < 0 else data[:nl]).decode("ascii", "replace").split(","))
    a, origin = parse_numeric_origin(b"" if nl < 0 else memoryview(data)[nl + 1:], len(names), str(p),
                                     first_line=2, names=names)
    if a.shape[0] == 0:
        raise ValueError(f"{p}: no rows")
    a = a[:, :4]  # t_gps_s, x_e_m, y_e_m, z_e_m (RTK_TRUTH_HEADER)
    t = a[:, 0] - SECONDS_PER_WEEK * np.floor(a[0, 0] / SECONDS_PER_WEEK) if np.isfinite(a[0, 0]) else a[:, 0]
    _check_truth_rows(np.column_stack([t, a[:, 1:4]]), origin)
    r_e = a[:, 1:4]
    lat, lon, h = earth.ecef_to_geodetic(r_e)
    nan = np.full(t.size, np.nan)
    tr = Truth(t, np.degrees(lat), np.degrees(lon), h, np.full((t.size, 3), np.nan), nan, nan.copy(), nan.copy())
    tr.quality = np.ones(t.size, int)  # exact: compared at its epochs
    return tr


#: rms(error/sigma) per axis outside these bounds flags the solution's sigmas as
#: overconfident (above) or pessimistic (below); a consistent filter gives about 1
CONSISTENCY_BOUNDS = (0.5, 2.0)


def consistency_flags(consistency: dict, bounds=CONSISTENCY_BOUNDS) -> dict:
    """Per quantity, the axes whose rms(error/sigma) is outside ``bounds``.

    Returns ``{quantity: [(axis index, value, "overconfident" | "pessimistic"), ...]}``
    holding only the quantities with at least one such axis.
    """
    lo, hi = bounds
    out = {}
    for k, vals in consistency.items():
        bad = [(i, float(v), "overconfident" if v > hi else "pessimistic")
               for i, v in enumerate(vals) if not lo <= v <= hi]
        if bad:
            out[k] = bad
    return out


def evaluate(solution, truth, outages=()) -> dict:
    """Accuracy figures of ``solution`` against ``truth``.

    Parameters
    ----------
    solution : Solution-like (attributes t, lat_deg, ..., optional sigma_*)
    truth : Truth-like
    outages : sequence of (start_s, end_s)

    Returns
    -------
    dict
        ``rms`` / ``max`` per quantity (lists N,E,D or roll,pitch,yaw),
        ``horizontal_rms_m``, ``horizontal_max_m``, ``rms_3d_m``,
        ``consistency`` (rms(error/sigma) per quantity), ``consistency_flags``
        (:func:`consistency_flags`: axes outside :data:`CONSISTENCY_BOUNDS`),
        ``outages`` (list of dicts).
    """
    e = errors(solution, truth)
    hz = np.hypot(e["pos_n_m"][:, 0], e["pos_n_m"][:, 1])
    out = {"samples": int(len(e["t"])), "rms": {}, "max": {}, "consistency": {}}
    for k in ("pos_n_m", "vel_n_mps", "att_deg"):
        fin = np.isfinite(e[k]).all(axis=1)  # rows where both have it (no velocity at an RTK start epoch)
        if not fin.any():
            continue  # the truth lacks it (e.g. no attitude in an RTKLIB reference)
        out["rms"][k] = rms(e[k][fin]).tolist()
        out["max"][k] = np.abs(e[k][fin]).max(axis=0).tolist()
        sk = "sigma_" + k
        if sk in e and np.all(e[sk][fin] > 0):
            out["consistency"][k] = rms(e[k][fin] / e[sk][fin]).tolist()
    out["consistency_flags"] = consistency_flags(out["consistency"])
    pos_ok = np.isfinite(e["pos_n_m"]).all(axis=1)  # the rows the per-axis figures use
    out["horizontal_rms_m"] = float(rms(hz[pos_ok]))
    out["horizontal_max_m"] = float(hz[pos_ok].max()) if pos_ok.any() else float("nan")
    out["rms_3d_m"] = float(np.sqrt(np.mean(np.sum(e["pos_n_m"][pos_ok] ** 2, axis=1))))
    fs = getattr(solution, "fix_status", None)
    if fs is not None:  # carrier-phase solutions: fix rate and the error per status
        st = np.asarray(fs)
        i = np.clip(np.searchsorted(np.asarray(solution.t), e["t"] - 1e-9), 0, len(st) - 1)
        st_e = st[i]
        err3 = np.linalg.norm(e["pos_n_m"], axis=1)
        err3[~pos_ok] = np.nan
        ep = getattr(solution, "epoch_fix_status", None)  # RTK/INS: over the rover epochs
        ep = st if ep is None else np.asarray(ep)
        out["fix_rate"] = float(np.mean(ep == 1)) if ep.size else 0.0
        out["by_status"] = {}
        for q, name in POS_STATUS_NAMES.items():
            m = (st_e == q) & pos_ok
            if m.any():
                out["by_status"][name] = dict(samples=int(m.sum()), rms_3d_m=float(np.sqrt(np.mean(err3[m] ** 2))),
                                              max_3d_m=float(err3[m].max()))
    out["outages"] = []
    t, hz = e["t"][pos_ok], hz[pos_ok]
    for (a, b) in outages:
        inside = (t >= a) & (t <= b)
        after = (t > b) & (t <= b + 60.0)
        pre = (t < a) & (t >= a - 60.0)
        thr = 1.5 * rms(hz[pre]) if pre.any() else np.nan
        out["outages"].append(dict(
            start_s=a, end_s=b,
            max_horizontal_inside_m=float(hz[inside].max()) if inside.any() else float("nan"),
            max_horizontal_after_60s_m=float(hz[after].max()) if after.any() else float("nan"),
            reconvergence_s=reconvergence_time(t, hz, b, thr) if np.isfinite(thr) else float("nan")))
    return out


def add_evaluate_parser(sub) -> None:
    p = sub.add_parser("evaluate", help="accuracy of a solution against a truth",
                       description="Compare a solution CSV with a truth.", epilog=EXAMPLES,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("solution")
    p.add_argument("truth")
    p.add_argument("--outages", default="", help="comma-separated start:end [s], e.g. 50:90,200:240")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.add_argument("--out", default=None, metavar="FILE",
                   help="also write the results as JSON to FILE (atomically; never over an input, nor over an "
                        "existing file that is not an insnav evaluation unless --overwrite)")
    p.add_argument("--overwrite", action="store_true",
                   help="let --out replace an existing file that is not an insnav evaluation")
    p.add_argument("--quality", type=int, default=None,
                   help="RTKLIB .pos truth: use records with Q <= this (1 fix only, 2 fix and float)")
    p.set_defaults(func=cmd_evaluate)


def _parse_outages(text: str):
    out = []
    for part in filter(None, text.split(",")):
        try:
            a, b = (float(x) for x in part.split(":"))
        except ValueError:
            raise ValueError(f"--outages: bad window {part!r}; expected start:end in seconds") from None
        if not b > a:
            raise ValueError(f"--outages: window {part!r} ends before it starts")
        out.append((a, b))
    return out


def _solution_at(sol, t):
    """The solution interpolated linearly to the times ``t`` inside its span (yaw unwrapped), leaving
    out the times inside a gap of the solution (two consecutive rows more than 1.5 of its median
    spacing apart, e.g. epochs without a solution in an RTKLIB .pos): nothing is drawn across one."""
    t = np.asarray(t, float)
    st = np.asarray(sol.t, float)
    t = t[(t >= st[0]) & (t <= st[-1])]
    if st.size > 1 and t.size:
        d = np.diff(st)
        step = float(np.median(d[d > 0])) if np.any(d > 0) else 0.0
        i = np.clip(np.searchsorted(st, t, side="right") - 1, 0, st.size - 2)
        on_row = np.isclose(t, st[i], rtol=0.0, atol=1e-6) | np.isclose(t, st[i + 1], rtol=0.0, atol=1e-6)
        t = t[on_row | (st[i + 1] - st[i] <= 1.5 * step)]
    if t.size == 0:
        raise ValueError(f"no truth epoch inside the solution's time span {sol.t[0]:.3f}..{sol.t[-1]:.3f} s "
                         "(a .pos reference needs solution times in GPS seconds of week)")
    out = _Sol()

    def at(x):
        x = np.asarray(x, float)
        return np.interp(t, sol.t, x) if x.ndim == 1 else np.column_stack(
            [np.interp(t, sol.t, x[:, i]) for i in range(x.shape[1])])

    out.t = t
    for k in ("lat_deg", "lon_deg", "h_m", "v_n", "roll_deg", "pitch_deg", "sigma_pos_n_m", "sigma_vel_n_mps",
              "sigma_att_deg"):
        setattr(out, k, at(getattr(sol, k)))
    out.yaw_deg = wrap_deg(at(unwrapped_deg(sol.yaw_deg)))
    out.lon_deg = wrap_deg(at(unwrapped_deg(sol.lon_deg)))  # across +-180 deg
    fs = getattr(sol, "fix_status", None)
    if fs is not None:  # a time on a solution epoch: its status; between two: the worse (higher Q) of the two,
        fs = np.asarray(fs)  # as the position there is interpolated from both (a float epoch makes it float)
        j = np.clip(np.searchsorted(st, t, side="right") - 1, 0, fs.size - 1)
        k = np.minimum(j + 1, fs.size - 1)
        on_j = np.isclose(t, st[j], rtol=0.0, atol=1e-6)
        on_k = np.isclose(t, st[k], rtol=0.0, atol=1e-6)
        out.fix_status = np.where(on_j, fs[j], np.where(on_k, fs[k], np.maximum(fs[j], fs[k])))
        out.epoch_fix_status = getattr(sol, "epoch_fix_status", fs)  # the fix rate stays over the solution's epochs
    if hasattr(sol, "slip_counts"):
        out.slip_counts = sol.slip_counts
    return out


def cmd_evaluate(args) -> int:
    for p in (args.solution,) + (() if "," in args.truth else (args.truth,)):
        if not Path(p).exists():
            raise FileNotFoundError(f"not found: {p}")
    out = getattr(args, "out", None)
    if out is not None:  # before the work: never over an input or a user's file
        from .._outputs import check_outputs, input_files
        from ..filters.solution import innovations_path, residuals_path

        sol_p = Path(args.solution)
        check_outputs([Path(out)], input_files(args.solution, innovations_path(args.solution),
                                               residuals_path(args.solution), args.truth,
                                               sol_p.with_suffix(sol_p.suffix + ".rtk.csv"),
                                               sol_p.with_suffix(sol_p.suffix + ".config.toml")),
                      overwrite=getattr(args, "overwrite", False), command="evaluation", replaces=("evaluation",))
    if args.quality is not None and not Path(args.truth).exists():  # a static x,y,z truth
        raise ValueError(_QUALITY_POS_ONLY)
    sol = _read_solution(args.solution)
    truth = _read_truth(args.truth, args.quality, solution=args.solution) if Path(args.truth).exists() \
        else static_truth(args.truth, sol.t)
    if hasattr(truth, "quality"):  # a 4 Hz reference, possibly with gaps: compare at its epochs
        sol = _solution_at(sol, truth.t)
    res = evaluate(sol, truth, _parse_outages(args.outages))
    if out is not None:
        from .._atomic import atomic_write_text, json_safe

        atomic_write_text(out, json.dumps(json_safe(res), indent=2, allow_nan=False) + "\n")
    if args.json:
        from .._atomic import json_safe
        print(json.dumps(json_safe(res), indent=2, allow_nan=False))
        return 0
    names = {"pos_n_m": ("position", "m", "N/E/D"), "vel_n_mps": ("velocity", "m/s", "N/E/D"),
             "att_deg": ("attitude", "deg", "roll/pitch/yaw")}
    print(f"{res['samples']} samples compared")
    for k, (n, u, ax) in names.items():
        if k not in res["rms"]:
            continue
        c = res["consistency"].get(k)
        cs = f"   rms(err/sigma) {'/'.join(f'{x:.2f}' for x in c)}" if c else ""
        print(f"{n:9s} [{u}] {ax}: RMS {'/'.join(f'{x:.4g}' for x in res['rms'][k])}"
              f"   max {'/'.join(f'{x:.4g}' for x in res['max'][k])}{cs}")
    print(f"horizontal RMS {res['horizontal_rms_m']:.4g} m, max {res['horizontal_max_m']:.4g} m; "
          f"3-D RMS {res['rms_3d_m']:.4g} m")
    if "fix_rate" in res:
        parts = [f"{name} {d['samples']} samples (3-D RMS {d['rms_3d_m']:.4g} m, max {d['max_3d_m']:.4g} m)"
                 for name, d in res["by_status"].items()]
        print(f"fix rate {100.0 * res['fix_rate']:.1f} %; " + "; ".join(parts))
    lo, hi = CONSISTENCY_BOUNDS
    for k, bad in res["consistency_flags"].items():
        n, _, ax = names[k]
        axes = ax.split("/")
        what = "; ".join(f"{axes[i]} {v:.2f} ({kind})" for i, v, kind in bad)
        print(f"WARNING: {n} rms(err/sigma) outside {lo:g}-{hi:g}: {what}: the solution's {n} sigmas "
              f"do not describe its errors")
    for o in res["outages"]:
        print(f"outage {o['start_s']:g}-{o['end_s']:g} s: max horizontal inside {o['max_horizontal_inside_m']:.4g} m, "
              f"in the 60 s after {o['max_horizontal_after_60s_m']:.4g} m, reconverged after "
              f"{o['reconvergence_s']:.1f} s")
    return 0
