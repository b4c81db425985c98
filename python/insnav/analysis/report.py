"""``insnav report``: one self-contained HTML page for any saved run.

:func:`report` reads a solution (``.csv`` / ``.npz`` / ``.parquet``, with its
``.innovations.csv`` sidecar and, for a tight run, ``.residuals.csv`` when
present), optionally a truth and the GNSS
fixes, and writes ``report.html`` (every figure inlined as a PNG data URI:
no network, no script) plus the PNGs beside it:

* ground track: solution, truth, GNSS fixes, the solution inside GNSS
  outages in red;
* position, velocity and attitude errors with their +-3 sigma bounds, against
  the truth, or (position, and velocity where the fixes have it) against the
  GNSS fixes when there is no truth;
* estimated IMU biases and scale factors;
* innovations and NIS against the chi-square bounds of their row count,
  applied and rejected updates marked; for a tight run the per-satellite
  pseudorange and rate residuals;
* a summary table: RMS and max errors, the maxima inside and after each
  outage, reconvergence times, consistency rms(error / sigma), NIS statistics;
* with ``allan``, the IMU noise of a static log analysed by ``insnav allan``:
  the Allan deviations with their intervals and the IEEE 952 fit, the fitted
  terms with 95 % intervals, and the ``[imu]`` noise TOML (alone when there
  is no solution).

Outages are the gaps in the GNSS record times (sidecar or fixes) longer than
2.5 GNSS periods, unless given.
"""
from __future__ import annotations

import base64
import html
import io
import math
from pathlib import Path

import numpy as np

from ..earth import radii
from ..units import DEG, DEG_PER_H, MG
from .evaluate import evaluate
from .metrics import errors, rms

__all__ = ["report", "detect_outages", "chi2_interval", "consistency_verdict", "steady_limit", "nis_limits"]

#: every figure file a report may write
FIGURES = ("track.png", "pos_error.png", "vel_error.png", "att_error.png", "imu_errors.png", "innovations.png",
           "residuals.png", "allan.png")

_Z975 = 1.959963984540054  # standard normal 97.5 % quantile


def chi2_interval(dof, z: float = _Z975) -> tuple[np.ndarray, np.ndarray]:
    """Two-sided 95 % interval of a chi-square variable with ``dof`` degrees of
    freedom (Wilson-Hilferty: within 3 % of the exact quantiles for dof >= 6)."""
    k = np.maximum(np.asarray(dof, float), 1.0)
    a = 2.0 / (9.0 * k)
    lo = k * np.maximum(1.0 - a - z * np.sqrt(a), 0.0) ** 3
    hi = k * (1.0 - a + z * np.sqrt(a)) ** 3
    return lo, hi


def detect_outages(t_records, factor: float = 2.5) -> list[tuple[float, float]]:
    """Gaps longer than ``factor`` x the median spacing of the record times."""
    t = np.unique(np.asarray(t_records, float))
    if t.size < 3:
        return []
    d = np.diff(t)
    period = float(np.median(d))
    return [(float(t[i]), float(t[i + 1])) for i in np.flatnonzero(d > factor * period)]


class _Fixes:
    """GNSS fixes as errors need them: t, lat/lon/h, sigmas."""

    def __init__(self, g):
        self.t = np.asarray(getattr(g, "t_valid", getattr(g, "t", None)), float)
        self.lat_deg, self.lon_deg, self.h_m = (np.asarray(getattr(g, k), float) for k in ("lat_deg", "lon_deg", "h_m"))
        nan3 = np.full((len(self.t), 3), np.nan)
        self.sigma_pos_n = np.asarray(getattr(g, "sigma_pos_n", nan3), float)
        self.v_n = np.asarray(getattr(g, "v_n", nan3), float)
        self.sigma_vel_n = np.asarray(getattr(g, "sigma_vel_n", nan3), float)


def _read_fixes(path) -> _Fixes:
    """GNSS fixes of ``--gnss``: a dataset folder or its gnss.csv, or the fixes
    ``insnav run --format csv`` reads (an RTKLIB ``.pos``, NMEA
    ``.nmea``/``.nma``/``.gga``/``.log``), with times in GPS seconds of week
    (of the first fix) as that run's solution has them."""
    from ..data.dataset import GnssFixes, load_dataset, read_csv

    p = Path(path)
    if p.is_dir():
        return _Fixes(load_dataset(p).gnss)
    from ..io.gnss_files import GnssFileFormat, read_gnss

    fmt = GnssFileFormat()
    if fmt.resolved_format(p) in ("pos", "nmea"):
        from ..gnss.gpstime import SECONDS_PER_WEEK

        rec = read_gnss(p, fmt)
        week0 = math.floor((rec.t_ref_s + float(rec.t_s[0])) / SECONDS_PER_WEEK) if rec.time_base == "gps" else 0
        t = (rec.t_ref_s - week0 * SECONDS_PER_WEEK) + rec.t_s
        return _Fixes(GnssFixes(t, t, rec.lat_deg, rec.lon_deg, rec.h_m, rec.v_n, rec.sigma_pos_n, rec.sigma_vel_n))
    return _Fixes(GnssFixes.from_array(read_csv(p, GnssFixes.COLUMNS)))


def _local_en(lat_deg, lon_deg, lat0, lon0, h0=0.0):
    R_M, R_N = radii(lat0 * DEG)
    return ((np.asarray(lon_deg) - lon0) * DEG * (R_N + h0) * math.cos(lat0 * DEG),
            (np.asarray(lat_deg) - lat0) * DEG * (R_M + h0))


def _errors_vs_fixes(sol, fx: _Fixes) -> dict:
    """Solution (IMU centre, interpolated) minus GNSS fix (antenna) at the fix
    times: NED position [m] and, where the fixes have one, velocity [m/s], each
    with the root-sum-square of the solution's and the fix's 1-sigma."""
    t = fx.t[(fx.t >= sol.t[0]) & (fx.t <= sol.t[-1])]
    if t.size == 0:
        raise ValueError("no GNSS fix inside the solution's time span")
    keep = np.isin(fx.t, t)
    lat = np.interp(t, sol.t, sol.lat_deg) * DEG
    lon = np.interp(t, sol.t, sol.lon_deg) * DEG
    h = np.interp(t, sol.t, sol.h_m)
    lat_f, lon_f, h_f = fx.lat_deg[keep] * DEG, fx.lon_deg[keep] * DEG, fx.h_m[keep]
    R_M, R_N = radii(lat_f)
    pos = np.column_stack([(lat - lat_f) * (R_M + h_f), (lon - lon_f) * (R_N + h_f) * np.cos(lat_f), -(h - h_f)])
    sig_sol = np.column_stack([np.interp(t, sol.t, sol.sigma_pos_n_m[:, i]) for i in range(3)])
    sig_fix = fx.sigma_pos_n[keep]
    sig = np.sqrt(sig_sol ** 2 + np.where(np.isfinite(sig_fix), sig_fix, 0.0) ** 2)
    out = dict(t=t, pos_n_m=pos, sigma_pos_n_m=sig)
    v_f = fx.v_n[keep]
    if np.isfinite(v_f).any():
        v = np.column_stack([np.interp(t, sol.t, np.asarray(sol.v_n)[:, i]) for i in range(3)])
        sv_sol = np.column_stack([np.interp(t, sol.t, sol.sigma_vel_n_mps[:, i]) for i in range(3)])
        sv_fix = fx.sigma_vel_n[keep]
        out["vel_n_mps"] = v - v_f
        out["sigma_vel_n_mps"] = np.sqrt(sv_sol ** 2 + np.where(np.isfinite(sv_fix), sv_fix, 0.0) ** 2)
    return out


def consistency_verdict(values, axes=("north", "east", "down")) -> str:
    """The verdict on rms(error / sigma) per axis with the bounds ``insnav
    evaluate`` warns outside (:data:`insnav.analysis.evaluate.CONSISTENCY_BOUNDS`):
    ``"consistent: ..."``, or the overconfident / pessimistic axes named."""
    from .evaluate import CONSISTENCY_BOUNDS, consistency_flags

    lo, hi = CONSISTENCY_BOUNDS
    vals = [float(v) for v in values]
    finite = {i: v for i, v in enumerate(vals) if math.isfinite(v)}
    if not finite:
        return "no verdict (no finite value)"
    flags = consistency_flags({"q": list(finite.values())}).get("q", [])
    keys = list(finite)
    over = [f"{axes[keys[i]]} {v:.2f} > {hi:g}" for i, v, kind in flags if kind == "overconfident"]
    pess = [f"{axes[keys[i]]} {v:.2f} < {lo:g}" for i, v, kind in flags if kind == "pessimistic"]
    if not over and not pess:
        return f"consistent: every axis within {lo:g}-{hi:g}"
    parts = ([f"overconfident (sigmas too small): {', '.join(over)}"] if over else []) + \
        ([f"pessimistic (sigmas too large): {', '.join(pess)}"] if pess else [])
    return "; ".join(parts)


def steady_limit(t, err, sigma=None, *, transient_share: float = 0.05, min_transient_s: float = 10.0):
    """The y half-range of an error plot that the first epochs' large sigmas do
    not flatten: the largest ``|error|`` and ``3 sigma`` after the first
    ``max(transient_share x run, min_transient_s)`` (outages later in the run
    stay in), times 1.1; None when that is not below half the whole run's (no
    transient to cut) or nothing is finite."""
    t = np.asarray(t, float)
    if t.size < 3:
        return None
    a = np.abs(np.asarray(err, float))
    if sigma is not None:
        a = np.fmax(a, 3.0 * np.abs(np.asarray(sigma, float)))
    cut = t[0] + max(transient_share * (t[-1] - t[0]), min_transient_s)
    steady = a[(t >= cut) & np.isfinite(a)]
    whole = a[np.isfinite(a)]
    if steady.size == 0 or whole.size == 0:
        return None
    lim = 1.1 * float(steady.max())
    return lim if 0.0 < lim < 0.5 * float(whole.max()) else None


def nis_limits(nis, rows=None):
    """Log-axis limits of a NIS plot that one near-zero value (the alignment
    epoch's 1e-12) does not squash: from 0.3 x the 1st percentile (and the
    chi-square interval's lower end) to 3 x the largest; None without values."""
    x = np.asarray(nis, float)
    x = x[np.isfinite(x) & (x > 0)]
    if x.size == 0:
        return None
    lo = 0.3 * float(np.percentile(x, 1.0))
    if rows is not None and np.size(rows):
        lo = min(lo, 0.3 * float(np.min(chi2_interval(np.asarray(rows, float))[0][np.asarray(rows) > 0]))
                 if np.any(np.asarray(rows) > 0) else lo)
    hi = 3.0 * float(x.max())
    if rows is not None and np.any(np.asarray(rows) > 0):
        hi = max(hi, 1.5 * float(np.max(chi2_interval(np.asarray(rows, float))[1])))
    return max(lo, 1e-6 * hi), hi


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")  # no label cut off at the edge
    return buf.getvalue()


def _shade(ax, outages):
    for a, b in outages:
        ax.axvspan(a, b, color="0.88", lw=0, zorder=0)


def _figures(sol, err, err_kind, truth, fx, inn, res, outages, plt) -> list[tuple[str, str, bytes]]:
    """(file name, caption, PNG bytes) of every figure; times since the first solution row."""
    out = []
    lat0, lon0 = float(sol.lat_deg[0]), float(sol.lon_deg[0])
    t_ref = float(sol.t[0])
    t_label = f"time since start [s] (start at t = {t_ref:.3f} s)"
    outages_rel = [(a - t_ref, b - t_ref) for a, b in outages]
    # --- ground track
    fig, ax = plt.subplots(figsize=(7.5, 6.5))
    e, n = _local_en(sol.lat_deg, sol.lon_deg, lat0, lon0)
    if truth is not None:
        te, tn = _local_en(truth.lat_deg, truth.lon_deg, lat0, lon0)
        ax.plot(te, tn, color="0.55", lw=2.5, label="truth")
    if fx is not None:
        fe, fn = _local_en(fx.lat_deg, fx.lon_deg, lat0, lon0)
        ax.plot(fe, fn, ".", color="tab:green", ms=3, label="GNSS fixes")
    ax.plot(e, n, color="tab:blue", lw=1.0, label="solution")
    for i, (a, b) in enumerate(outages):
        m = (sol.t >= a) & (sol.t <= b)
        ax.plot(e[m], n[m], color="tab:red", lw=1.6, label="solution in GNSS outages" if i == 0 else None)
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="best", fontsize=8)
    ax.set_title("ground track (from the first solution point)")
    out.append(("track.png", "Ground track", _png(fig)))
    plt.close(fig)
    # --- errors with +-3 sigma
    panels = [("pos_n_m", "position error [m]", ("north", "east", "down")),
              ("vel_n_mps", "velocity error [m/s]", ("north", "east", "down")),
              ("att_deg", "attitude error [deg]", ("roll", "pitch", "yaw"))]
    for key, label, axes in panels:
        if err is None or key not in err or not np.isfinite(err[key]).any():
            continue
        fig, axs = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
        t = err["t"] - t_ref
        sk = "sigma_" + key
        cut = False
        for i in range(3):
            ax = axs[i]
            _shade(ax, outages_rel)
            sig = err[sk][:, i] if sk in err and np.isfinite(err[sk][:, i]).any() else None
            if sig is not None:
                ax.fill_between(t, -3 * sig, 3 * sig, color="tab:orange", alpha=0.25, lw=0, label="+-3 sigma")
            ax.plot(t, err[key][:, i], color="tab:blue", lw=0.8, label="error")
            lim = steady_limit(t, err[key][:, i], sig)
            if lim is not None:  # the first epochs' large sigmas would flatten the rest
                ax.set_ylim(-lim, lim)
                cut = True
            ax.set_ylabel(axes[i])
        axs[0].legend(loc="upper right", fontsize=8)
        axs[0].set_title(f"{label} against the {err_kind} (GNSS outages shaded"
                         + ("; y axis: after the start-up transient" if cut else "") + ")", fontsize=10)
        axs[-1].set_xlabel(t_label)
        out.append((f"{key.split('_')[0]}_error.png", label.capitalize() + f" against the {err_kind}", _png(fig)))
        plt.close(fig)
    # --- IMU errors: a panel per estimated state (a layout without scale factors gets none for them)
    series = [(sol.acc_bias_mps2 / MG, "accelerometer bias [mg]"), (sol.gyro_bias_rps / DEG_PER_H, "gyro bias [deg/h]"),
              (sol.acc_scale * 1e6, "accelerometer scale factor [ppm]"), (sol.gyro_scale * 1e6, "gyro scale factor [ppm]")]
    shown = [(y, label) for y, label in series if np.any(np.nan_to_num(np.asarray(y, float)))]
    if shown:
        ncol = 2 if len(shown) > 1 else 1
        nrow = -(-len(shown) // ncol)
        fig, axs = plt.subplots(nrow, ncol, figsize=(10, 3 * nrow + 0.5), sharex=True, squeeze=False)
        for ax in axs.ravel()[len(shown):]:
            ax.set_visible(False)
        for ax, (y, label) in zip(axs.ravel(), shown):
            _shade(ax, outages_rel)
            for i, c in enumerate("xyz"):
                ax.plot(sol.t - t_ref, y[:, i], lw=0.9, label=c)
            ax.set_title(label, fontsize=10)
            ax.legend(fontsize=7, loc="best")
        for ax in axs.ravel()[max(0, len(shown) - ncol):len(shown)]:
            ax.set_xlabel(t_label, fontsize=8)
        fig.tight_layout()
        names = {label for _, label in shown}
        missing = [label.split(" [")[0] for _, label in series if label not in names]
        cap = "Estimated IMU " + ("biases and scale factors" if not missing else
                                  "errors (not estimated: " + ", ".join(missing) + ")")
        out.append(("imu_errors.png", cap, _png(fig)))
        plt.close(fig)
    # --- innovations and NIS
    if inn is not None and len(inn["t_s"]) and (np.isfinite(inn["nis"]).any()
                                                 or np.isfinite(inn["innovation"]).any()):
        t, st, nis, rows = inn["t_s"] - t_ref, inn["status"], inn["nis"], inn["rows"]
        applied = st == 1
        rejected = st == 2
        has_inn = np.isfinite(inn["innovation"]).any()
        fig, axs = plt.subplots(3 if has_inn else 1, 1, figsize=(9, 7.5 if has_inn else 3.5), sharex=True,
                                squeeze=False)
        axs = axs[:, 0]
        k = 0
        if has_inn:
            for j, (cols, label) in enumerate((((0, 1, 2), "position innovation [m]"),
                                                ((3, 4, 5), "velocity innovation [m/s]"))):
                ax = axs[k]
                for c, name in zip(cols, ("N", "E", "D")):
                    ax.plot(t, inn["innovation"][:, c], ".", ms=2.5, label=name)
                if rejected.any():
                    ax.plot(t[rejected], np.zeros(rejected.sum()), "x", color="k", ms=6, label="rejected")
                ax.set_ylabel(label, fontsize=8)
                ax.legend(fontsize=7, loc="upper right", ncol=4)
                k += 1
        ax = axs[k]
        lo, hi = chi2_interval(rows)
        ok = np.isfinite(nis) & (rows > 0)
        order = np.argsort(t)
        ax.fill_between(t[order], lo[order], hi[order], color="tab:orange", alpha=0.25, lw=0,
                        label="chi-square 95 % interval")
        ax.semilogy(t[applied & ok], nis[applied & ok], ".", ms=3, color="tab:blue", label="applied")
        if (rejected & ok).any():
            ax.semilogy(t[rejected & ok], nis[rejected & ok], "x", ms=5, color="tab:red", label="rejected by the gate")
        lims = nis_limits(nis[ok], rows[ok])
        if lims is not None:  # a near-zero NIS (the alignment epoch) would squash the axis
            ax.set_ylim(*lims)
            below = int(np.count_nonzero(nis[ok] < lims[0]))
            if below:
                ax.text(0.01, 0.03, f"{below} NIS below the axis", transform=ax.transAxes, fontsize=7)
        ax.set_ylabel("NIS")
        ax.set_xlabel(t_label)
        ax.legend(fontsize=7, loc="upper right")
        axs[0].set_title("innovations (INS minus GNSS, before the update) and NIS" if has_inn else
                         "NIS (INS runs: before the update; single point: the post-fit RAIM chi-square)")
        out.append(("innovations.png", "Innovations and NIS", _png(fig)))
        plt.close(fig)
    # --- tight: per-satellite residuals
    if res is not None and len(res["t_s"]):
        rejected_t = set(np.round(inn["t_s"][inn["status"] == 2], 6)) if inn is not None else set()
        rej = np.isin(np.round(res["t_s"], 6), list(rejected_t))
        tr_s = res["t_s"] - t_ref
        fig, axs = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
        system = np.asarray(res.get("system", np.zeros(len(res["prn"]), int)), int)  # 0 G, 1 R, 2 E, 3 C
        sats = sorted(set(zip(system.tolist(), np.asarray(res["prn"], int).tolist())))
        cmap = plt.get_cmap("tab20")
        for ax, key, label in ((axs[0], "pseudorange_residual_m", "pseudorange residual [m]"),
                               (axs[1], "rate_residual_mps", "pseudorange-rate residual [m/s]")):
            _shade(ax, outages_rel)
            flag = res.get("pseudorange_flag" if key.startswith("pseudo") else "rate_flag")
            dropped = np.zeros(len(rej), bool) if flag is None else np.asarray(flag) == 2  # the robust step's
            for j, (sy, prn) in enumerate(sats):
                m = (system == sy) & (res["prn"] == prn) & ~rej & ~dropped
                ax.plot(tr_s[m], res[key][m], ".", ms=2.5, color=cmap(j % 20), label=f"{'GREC'[sy]}{prn:02d}")
            if rej.any():
                ax.plot(tr_s[rej], res[key][rej], "x", ms=5, color="k", label="epoch rejected")
            if (dropped & ~rej).any():
                ax.plot(tr_s[dropped & ~rej], res[key][dropped & ~rej], "+", ms=5, color="tab:red",
                        label="row rejected (robust)")
            ax.set_ylabel(label, fontsize=8)
        axs[0].legend(fontsize=6, loc="upper right", ncol=min(8, len(sats) + 1))
        axs[0].set_title("per-satellite residuals (INS-predicted minus measured, before the update)")
        axs[-1].set_xlabel(t_label)
        out.append(("residuals.png", "Per-satellite pseudorange and rate residuals", _png(fig)))
        plt.close(fig)
    return out


def _fmt(x, nd=3):
    """``nd`` decimals, more below 0.1 for 3 significant digits (0.000530, not 0.001: mm-level RTK)."""
    if x is None or not math.isfinite(float(x)):  # numpy float32 NaN / inf too
        return "n/a"
    if x != 0:
        nd = max(nd, 2 - math.floor(math.log10(abs(x))))
    return f"{x:.{nd}f}"


_AXES = {"pos_n_m": ("north", "east", "down"), "vel_n_mps": ("north", "east", "down"),
         "att_deg": ("roll", "pitch", "yaw")}


def _summary_rows(sol, err_kind, ev, inn, res, outages, fix_err) -> list[tuple[str, str]]:
    rows = [("solution rows", f"{len(sol.t)} ({sol.t[0]:.3f} to {sol.t[-1]:.3f} s)")]
    if inn is not None and len(inn["t_s"]):
        st = inn["status"]
        rows.append(("GNSS records", f"{len(st)}: {int((st == 1).sum())} applied, {int((st == 2).sum())} rejected by "
                                     f"the gate, {int(np.isin(st, (0, 3, 4, 5)).sum())} not used"))
        ok = (st == 1) & np.isfinite(inn["nis"]) & (inn["rows"] > 0)
        if ok.any():
            lo, hi = chi2_interval(inn["rows"][ok])
            inside = np.mean((inn["nis"][ok] >= lo) & (inn["nis"][ok] <= hi))
            rows.append(("NIS of applied updates: mean / mean rows",
                         f"{np.mean(inn['nis'][ok]):.2f} / {np.mean(inn['rows'][ok]):.2f} (about equal when "
                         f"consistent); {100 * inside:.1f} % inside the 95 % chi-square interval"))
    if res is not None and len(res["t_s"]):
        ok = np.ones(len(res["t_s"]), bool)
        if inn is not None:
            applied_t = np.round(inn["t_s"][inn["status"] == 1], 6)
            ok = np.isin(np.round(res["t_s"], 6), applied_t)
        ok_pr, ok_rr = ok.copy(), ok.copy()
        if "pseudorange_flag" in res:  # rows the robust step rejected (flag 2) were not applied
            ok_pr &= np.asarray(res["pseudorange_flag"]) != 2
            ok_rr &= np.asarray(res["rate_flag"]) != 2
        pr, rr = res["pseudorange_residual_m"][ok_pr], res["rate_residual_mps"][ok_rr]
        pr, rr = pr[np.isfinite(pr)], rr[np.isfinite(rr)]
        rows.append(("residual RMS of applied epochs: pseudorange [m] / rate [m/s]",
                     f"{_fmt(float(rms(pr)) if pr.size else None)} / {_fmt(float(rms(rr)) if rr.size else None)} "
                     f"({pr.size} / {rr.size} satellite rows)"))
    fs = getattr(sol, "fix_status", None)
    if getattr(sol, "epoch_fix_status", None) is not None:  # RTK/INS: per rover epoch, not per IMU row
        fs = np.asarray(sol.epoch_fix_status)
    if fs is not None and len(fs):
        from .evaluate import POS_STATUS_NAMES

        counts = ", ".join(f"{int(np.sum(fs == q))} {n}" for q, n in POS_STATUS_NAMES.items() if np.any(fs == q))
        rows.append(("carrier-phase fix rate", f"{100.0 * np.mean(fs == 1):.1f} % ({counts})"))
        sc = getattr(sol, "slip_counts", None)
        if sc:
            rows.append(("cycle slips detected", ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in sc.items())))
        if ev is not None and "by_status" in ev:
            for name, d in ev["by_status"].items():
                rows.append((f"3-D error while {name}, RMS / max [m]",
                             f"{_fmt(d['rms_3d_m'])} / {_fmt(d['max_3d_m'])} ({d['samples']} samples compared)"))
    if outages:
        rows.append(("GNSS outages [s]", ", ".join(f"{a:.1f}-{b:.1f}" for a, b in outages)))
    if ev is not None:
        names = {"pos_n_m": ("position", "m", "N/E/D"), "vel_n_mps": ("velocity", "m/s", "N/E/D"),
                 "att_deg": ("attitude", "deg", "roll/pitch/yaw")}
        for k, (n, u, ax) in names.items():
            if k in ev["rms"]:
                rows.append((f"{n} RMS [{u}] {ax}", " / ".join(_fmt(x) for x in ev["rms"][k])))
                rows.append((f"{n} max [{u}] {ax}", " / ".join(_fmt(x) for x in ev["max"][k])))
        rows.append(("horizontal RMS / max [m]", f"{_fmt(ev['horizontal_rms_m'])} / {_fmt(ev['horizontal_max_m'])}"))
        rows.append(("3-D position RMS [m]", _fmt(ev["rms_3d_m"])))
        for k, (n, _, ax) in names.items():
            if k in ev["consistency"]:
                rows.append((f"consistency rms(error / sigma), {n} {ax}",
                             " / ".join(_fmt(x, 2) for x in ev["consistency"][k])
                             + f" ({consistency_verdict(ev['consistency'][k], _AXES[k])})"))
        for o in ev["outages"]:
            rows.append((f"outage {o['start_s']:.1f}-{o['end_s']:.1f} s: max horizontal inside / in the 60 s after [m]",
                         f"{_fmt(o['max_horizontal_inside_m'])} / {_fmt(o['max_horizontal_after_60s_m'])}"))
            rows.append((f"outage {o['start_s']:.1f}-{o['end_s']:.1f} s: reconvergence [s]",
                         f"{_fmt(o['reconvergence_s'], 1)} (horizontal error back within 1.5x its pre-outage RMS "
                         "for 5 s)"))
    if fix_err is not None:
        p = fix_err["pos_n_m"]
        rows.append(("position minus GNSS fixes, RMS [m] N/E/D", " / ".join(_fmt(x) for x in rms(p))))
        c = rms(p / fix_err["sigma_pos_n_m"])
        rows.append(("position minus GNSS fixes, rms(difference / sigma) N/E/D",
                     " / ".join(_fmt(x, 2) for x in c) + f" ({consistency_verdict(c)})"))
        v = fix_err.get("vel_n_mps")
        ok = np.zeros(0, bool) if v is None else np.isfinite(v).all(axis=1)
        if ok.any():  # a solution without velocity (an RTKLIB .pos): no velocity rows
            rows.append(("velocity minus GNSS fixes, RMS [m/s] N/E/D", " / ".join(_fmt(x) for x in rms(v[ok]))))
            c = rms(v[ok] / fix_err["sigma_vel_n_mps"][ok])
            rows.append(("velocity minus GNSS fixes, rms(difference / sigma) N/E/D",
                         " / ".join(_fmt(x, 2) for x in c) + f" ({consistency_verdict(c)})"))
    rows.append(("errors against", err_kind))
    return rows


def _allan_section(path) -> tuple[list[tuple[str, str, bytes]], list[str]]:
    """The Allan section of a report from the output of ``insnav allan`` (its
    ``--out-dir`` or ``allan.csv``): the curve refitted exactly as ``insnav
    allan`` fits it (:func:`insnav.calib.allan.fit_allan`), so the figure, the
    terms and the TOML are the ones that command printed (to the 6 digits of
    allan.csv).  Returns (figures, HTML parts)."""
    from ..calib.allan import TERMS, fit_allan, imu_noise_toml
    from .allan_plot import allan_figure, read_curve_csv, term_cells
    from .allan_plot import units as _units

    curve, source = read_curve_csv(path)
    fits = [fit_allan(curve, a) for a in range(6)]
    fits_g, fits_a = fits[:3], fits[3:]
    head = (f"{source or path}: {curve.n} samples at {1 / curve.tau0_s:.6g} Hz, {curve.n * curve.tau0_s / 3600:.3g} h; "
            f"overlapping Allan deviation at {curve.tau_s.size} averaging times "
            f"{curve.tau_s[0]:.3g}..{curve.tau_s[-1]:.4g} s")
    figs = [("allan.png", "Allan deviation of the static IMU log (95 % intervals, dashed: IEEE 952 fit)",
             allan_figure(curve, fits_g, fits_a, head, dpi=90))]
    u = _units()
    parts = ["<h2 id=\"allan-noise\">IMU noise (Allan variance, IEEE Std 952)</h2>",
             f"<p>{html.escape(head)} (<code>{html.escape(str(path))}</code>).</p>",
             "<table id=\"allan\"><tr><th>axis</th>"
             + "".join(f"<th>{k} [{html.escape(u[k][0][0])} | {html.escape(u[k][1][0])}]</th>" for k in TERMS)
             + "</tr>"]
    for axis, cells in term_cells(fits_g, fits_a, lt="&lt;"):
        parts.append(f"<tr><td>{html.escape(axis)}</td>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    parts.append("</table>")
    parts.append("<p>Value (95 % interval); '&lt; x': not resolved by this log, x its upper bound; '-': zero in the "
                 "fit; Q quantisation, N angle / velocity random walk, B bias instability, K rate random walk, R rate "
                 "ramp.  The filter's <code>[imu]</code> noise keys (docs/algorithms.md section 24 maps the terms "
                 "to the process noise):</p>")
    parts.append(f"<pre id=\"imu_noise_toml\">{html.escape(imu_noise_toml(fits_g, fits_a, source=source))}</pre>")
    return figs, parts


def report(solution, out_dir=None, *, truth=None, gnss=None, outages=None, title: str | None = None,
           overwrite: bool = False, allan=None) -> Path:
    """Write ``report.html`` and its PNGs for a solution; returns the HTML path.

    The files are written into a temporary folder beside ``out_dir`` that
    replaces it at the end (an earlier report there goes then; a failed or
    interrupted report leaves no file and the earlier report as it was).

    Parameters
    ----------
    solution : path or Solution or None
        A saved solution (its ``.innovations.csv`` sidecar is read when present);
        None for a page with only the Allan section (``allan`` then needed).
    out_dir : path, optional
        Default: ``<solution>-report`` beside a saved solution (``<allan>-report``
        beside the Allan folder without a solution).
    truth : path or Truth-like, optional
        Anything ``insnav evaluate`` reads (truth.csv, dataset folder, KF-GINS .nav, RTKLIB .pos).
    gnss : path or GnssFixes, optional
        gnss.csv or a dataset folder: fixes on the track, and the position
        reference when there is no truth.
    outages : sequence of (start_s, end_s), optional
        Default: the gaps in the GNSS record times.
    overwrite : bool
        Write into an existing folder that is not an insnav report (its
        report.html and figures replaced, its other files left alone);
        without it such a folder is refused before any work.
    allan : path, optional
        The ``--out-dir`` of ``insnav allan`` (or its ``allan.csv``): adds the
        section "IMU noise (Allan variance)" (figure allan.png, the IEEE 952
        terms with 95 % intervals, the ``[imu]`` noise TOML).
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise ImportError("insnav report needs matplotlib: pip install 'insnav[plot]'") from None
    from ..filters.solution import innovations_path, read_innovations, read_residuals, residuals_path
    from .evaluate import _read_solution, _read_truth, _solution_at, static_truth

    if solution is None:
        if allan is None:
            raise ValueError("report: give a solution, or allan (an `insnav allan` output) for a noise-only page")
        if truth is not None or gnss is not None:
            raise ValueError("report: truth and gnss need a solution")
        return _allan_report(Path(allan), out_dir, title, overwrite, plt)
    src, res = None, None
    if isinstance(solution, (str, Path)):
        src = Path(solution)
        sol = _read_solution(src)
        side = innovations_path(src)
        inn = read_innovations(side) if side.is_file() else None
        if residuals_path(src).is_file():
            res = read_residuals(residuals_path(src))
    else:
        sol = solution
        inn = None
        inputs = getattr(sol, "inputs", None)
        i2 = np.asarray(getattr(sol, "innovation", np.zeros((0, 6))), float)
        if inputs is not None and i2.ndim == 2 and i2.shape == (len(inputs.prn), 2):
            ep = np.repeat(np.asarray(inputs.epoch_t, float), np.diff(inputs.epoch_start))
            res = dict(t_s=ep, prn=np.asarray(inputs.prn, int), pseudorange_residual_m=i2[:, 0],
                       rate_residual_mps=i2[:, 1])
            sys_ = getattr(inputs, "system", None)
            if sys_ is not None:  # letters G R E C -> the residuals file's system index
                res["system"] = np.array(["GREC".index(str(x)) for x in np.asarray(sys_)], int)
        if len(getattr(sol, "gnss_t", ())) and np.asarray(sol.innovation).ndim == 2:
            m = len(sol.gnss_t)
            i6 = np.asarray(sol.innovation, float)
            inn = dict(t_s=np.asarray(sol.gnss_t, float), status=np.asarray(sol.gnss_status, int),
                       nis=np.asarray(sol.nis, float),
                       rows=np.asarray(getattr(sol, "rows", None) if getattr(sol, "rows", None) is not None
                                       else np.isfinite(i6).sum(axis=1), int),
                       innovation=i6 if i6.shape == (m, 6) else np.full((m, 6), np.nan))
    if out_dir is None:
        if src is None:
            raise ValueError("report: out_dir is needed for a Solution object")
        out_dir = src.with_name(src.name + "-report")
    out_dir = Path(out_dir)
    _check_report_out(out_dir, [src, truth, gnss, allan], overwrite)
    if isinstance(truth, str) and "," in truth and not Path(truth).exists():  # a static antenna: x,y,z or lat,lon,h
        tr = static_truth(truth, sol.t)
    else:
        tr = _read_truth(truth, solution=src) if isinstance(truth, (str, Path)) else truth
    fx = None
    if gnss is not None:
        fx = _read_fixes(gnss) if isinstance(gnss, (str, Path)) else _Fixes(gnss)
    if outages is None:
        rec_t = inn["t_s"] if inn is not None and len(inn["t_s"]) else (fx.t if fx is not None else [])
        outages = [(a, b) for a, b in detect_outages(rec_t) if b > sol.t[0] and a < sol.t[-1]]
    outages = [(float(a), float(b)) for a, b in outages]

    err, ev, err_kind, fix_err = None, None, "nothing (no truth, no GNSS fixes given)", None
    if tr is not None:
        s_cmp = _solution_at(sol, tr.t) if hasattr(tr, "quality") else sol
        err = errors(s_cmp, tr)
        if len(err["t"]) == 0:
            raise ValueError("the truth does not overlap the solution in time")
        ev = evaluate(s_cmp, tr, outages)
        err_kind = "truth"
    elif fx is not None:
        fix_err = _errors_vs_fixes(sol, fx)
        err = fix_err
        gnss_only = not np.isfinite(np.asarray(getattr(sol, "roll_deg", [np.nan]), float)).any()
        err_kind = ("GNSS fixes (antenna; the solution, GNSS only, is an antenna position too)" if gnss_only else
                    "GNSS fixes (antenna; the solution is the IMU centre, no lever arm applied)")

    allan_figs, allan_parts = _allan_section(allan) if allan is not None else ([], [])
    figs = _figures(sol, err, "truth" if tr is not None else "GNSS fixes", tr, fx, inn, res, outages, plt)
    rows = _summary_rows(sol, err_kind, ev, inn, res, outages, fix_err)
    heading = title or f"insnav report: {src.name if src else 'solution'}"
    parts = _page_head(heading)
    if src is not None:
        parts.append(f"<p>Solution: <code>{html.escape(str(src))}</code>"
                     + (f"; truth: <code>{html.escape(str(truth))}</code>" if isinstance(truth, (str, Path)) else "")
                     + (f"; GNSS: <code>{html.escape(str(gnss))}</code>" if isinstance(gnss, (str, Path)) else "")
                     + "</p>")
    parts.append("<h2>Summary</h2><table id=\"summary\"><tr><th>quantity</th><th>value</th></tr>")
    for k, v in rows:
        parts.append(f"<tr><td>{html.escape(k)}</td><td>{html.escape(v)}</td></tr>")
    parts.append("</table>")
    parts += [_figure_html(*f) for f in figs]
    if allan_figs:
        parts += allan_parts[:2] + [_figure_html(*f) for f in allan_figs] + allan_parts[2:]
    parts.append("</body></html>")
    files = [(name, data) for name, _, data in figs + allan_figs] + \
        [("report.html", ("\n".join(parts) + "\n").encode())]
    return _write_report(out_dir, files)


def _page_head(heading: str) -> list[str]:
    return ["<!DOCTYPE html>", "<html lang=\"en\"><head><meta charset=\"utf-8\">",
            f"<title>{html.escape(heading)}</title>",
            "<style>body{font-family:sans-serif;max-width:1000px;margin:1em auto;color:#222}"
            "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #bbb;padding:3px 8px;"
            "text-align:left;font-size:14px}th{background:#eee}figure{margin:1.5em 0}"
            "img{max-width:100%;border:1px solid #ddd}figcaption{font-size:13px;color:#555}"
            "pre{background:#f6f6f6;padding:6px;font-size:12px;overflow-x:auto}</style>",
            "</head><body>", f"<h1>{html.escape(heading)}</h1>"]


def _figure_html(name: str, caption: str, data: bytes) -> str:
    b64 = base64.b64encode(data).decode("ascii")
    return (f"<figure id=\"{name[:-4]}\"><img alt=\"{html.escape(caption)}\" "
            f"src=\"data:image/png;base64,{b64}\"><figcaption>{html.escape(caption)} "
            f"({html.escape(name)})</figcaption></figure>")


def _allan_report(allan: Path, out_dir, title, overwrite: bool, plt) -> Path:
    """A report with only the Allan section (no solution)."""
    if out_dir is None:
        base = (allan.parent if allan.is_file() else allan).resolve()  # "." or "allan.csv" inside the folder
        out_dir = base.with_name(base.name + "-report")
    out_dir = Path(out_dir)
    _check_report_out(out_dir, [None, allan], overwrite)
    figs, sec = _allan_section(allan)
    heading = title or f"insnav report: IMU noise of {allan.resolve().name}"
    parts = _page_head(heading) + sec[:2] + [_figure_html(*f) for f in figs] + sec[2:] + ["</body></html>"]
    files = [(name, data) for name, _, data in figs] + [("report.html", ("\n".join(parts) + "\n").encode())]
    return _write_report(out_dir, files)


def _report_inputs(paths) -> dict:
    """:func:`insnav._outputs.input_files` of a report's inputs: the solution,
    its sidecars, and the truth and GNSS files or folders."""
    from .._outputs import input_files
    from ..filters.solution import innovations_path, residuals_path

    files = []
    for p in paths:
        if isinstance(p, (str, Path)):
            files.append(Path(p))
    if paths and isinstance(paths[0], Path):
        files += [innovations_path(paths[0]), residuals_path(paths[0])]
    return input_files(*files)


def is_report_folder(path) -> bool:
    """True for a folder written by :func:`report`: report.html (an insnav
    page) and its figures, nothing else."""
    from .._outputs import head

    p = Path(path)
    if not p.is_dir() or not (p / "report.html").is_file():
        return False
    h = head(p / "report.html", 65536)
    if not (h.startswith(b"<!DOCTYPE html>") and (b"insnav report" in h or b'id="summary"' in h)):
        return False
    allowed = set(FIGURES) | {"report.html"}
    return all(c.name in allowed and c.is_file() for c in p.iterdir())


def _check_report_out(out_dir: Path, inputs, overwrite: bool) -> None:
    """Before any work: ``out_dir`` is new, empty or an earlier report (then
    replaced), or with ``overwrite`` any folder (its report files replaced);
    never an input, never holding an input under a report file's name; writable."""
    from .._outputs import check_writable, file_id
    from ..errors import UserError

    ins = _report_inputs(inputs)
    if out_dir.exists() and not out_dir.is_dir():
        raise UserError(f"--out {out_dir} exists and is not a folder: not replaced")
    if file_id(out_dir) in ins:
        raise UserError(f"--out {out_dir} is an input of this report: choose another folder")
    if out_dir.is_dir() and any(out_dir.iterdir()) and not is_report_folder(out_dir):
        if not overwrite:
            raise UserError(f"--out {out_dir} exists and is not an insnav report folder (report.html and its "
                            "figures only): not replaced (choose another --out, or --overwrite to write the "
                            "report files into it)")
        for name in ("report.html", *FIGURES):
            if file_id(out_dir / name) in ins:
                raise UserError(f"{out_dir / name} is an input of this report: choose another --out")
    check_writable(out_dir)


def _write_report(out_dir: Path, files) -> Path:
    """Write ``files`` ((name, bytes), report.html last) as the report folder
    ``out_dir``: into a temporary folder beside it, renamed into place at the
    end (an earlier report there removed then; a folder that is not a report,
    accepted by ``overwrite``, gets the files each renamed in at the end)."""
    import os
    import shutil
    import tempfile

    from .._atomic import atomic_write_with, chmod_like_new, output_set, signals_held

    if out_dir.is_dir() and any(out_dir.iterdir()) and not is_report_folder(out_dir):
        with output_set():
            for name, data in files:
                atomic_write_with(out_dir / name, lambda tmp, d=data: Path(tmp).write_bytes(d))
        return out_dir / "report.html"
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", suffix=".part", dir=out_dir.parent))
    old = None
    try:
        for name, data in files:
            (tmp / name).write_bytes(data)
        chmod_like_new(tmp, directory=True)
        with signals_held():
            if out_dir.exists():  # an earlier report, or an empty folder: swapped out, then removed
                old = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", suffix=".old", dir=out_dir.parent))
                os.replace(out_dir, old)
                try:
                    os.replace(tmp, out_dir)
                except BaseException:
                    os.replace(old, out_dir)
                    old = None
                    raise
            else:
                os.replace(tmp, out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        if old is not None and old.exists() and not out_dir.exists():
            os.replace(old, out_dir)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
    return out_dir / "report.html"
