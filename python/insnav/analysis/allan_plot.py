"""The Allan-variance curve file and figure shared by ``insnav allan`` and the
HTML report (``insnav report --allan``): the table units, the ``allan.csv``
reader and the Allan-deviation figure (IEEE Std 952 terms).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import UserError

_MARK = "# insnav allan"  # first line of an allan.csv
PNG_SOFTWARE = "insnav allan"  # the allan.png's Software text chunk

def units():
    """term -> ((gyro unit, factor to SI), (accel unit, factor to SI)) of the table."""
    from ..units import DEG, DEG_PER_H, DEG_PER_SQRT_H, HOUR, MG, MPS_PER_SQRT_H

    return {
        "Q": (("arcsec", DEG / 3600.0), ("m/s", 1.0)),
        "N": (("deg/sqrt(h)", DEG_PER_SQRT_H), ("m/s/sqrt(h)", MPS_PER_SQRT_H)),
        "B": (("deg/h", DEG_PER_H), ("mg", MG)),
        "K": (("deg/h/sqrt(h)", DEG_PER_H / 60.0), ("mg/sqrt(h)", MG / 60.0)),
        "R": (("deg/h/h", DEG_PER_H / HOUR), ("mg/h", MG / HOUR)),
    }


def term_cells(fits_g, fits_a, lt: str = "<") -> list[tuple[str, list[str]]]:
    """The fitted IEEE 952 terms as table cells in the units of :func:`units`:
    one (axis, cells) per gyro then accelerometer axis, a cell per term of
    :data:`insnav.calib.allan.TERMS`: "value (low..high)" with the fit's
    interval, "{lt} x" for a term the log does not resolve (x its upper bound),
    "-" for a term that is zero in the fit.  ``lt`` is "&lt;" for HTML."""
    from ..calib.allan import TERMS

    u = units()
    rows = []
    for kind, fits in ((0, fits_g), (1, fits_a)):
        for f in fits:
            cells = []
            for k in TERMS:
                fac = u[k][kind][1]
                v = f.coef[k] / fac
                lo, hi = (c / fac for c in f.ci[k])
                if v == 0.0:
                    up = f.upper.get(k, math.nan) / fac
                    cells.append(f"{lt} {up:.3g}" if math.isfinite(up) else "-")
                elif math.isfinite(lo):
                    cells.append(f"{v:.4g} ({lo:.3g}..{hi:.3g})")
                else:
                    cells.append(f"{v:.4g}")
            rows.append((f.axis, cells))
    return rows


def read_curve_csv(path):
    """The Allan curve of an ``allan.csv`` written by ``insnav allan``: (AllanCurve
    in SI rates (gyro rad/s, accelerometer m/s^2), the analysed input's name).

    The number of samples is the ``clusters`` column at ``m = 1`` (``floor(n / m)``;
    the largest ``clusters x m`` if the curve starts above ``m = 1``), the sample
    interval ``tau_s / m``.  A file that is not an ``insnav allan`` curve is a
    one-line :class:`~insnav.errors.UserError` naming it.
    """
    from ..calib.allan import AllanCurve
    from ..units import DEG_PER_H, MG

    p = Path(path)
    if p.is_dir():
        p = p / "allan.csv"
    if not p.is_file():
        raise UserError(f"{p}: no such file (give the --out-dir of `insnav allan` or its allan.csv)")
    with open(p, encoding="utf-8", errors="replace") as f:
        first = f.readline().rstrip("\n")
        header = f.readline().strip()
        body = f.read()
    cols = ["tau_s", "m", "clusters"] + [f"adev_{a}_dph" for a in "xyz"] + [f"adev_{a}_mg" for a in "xyz"]
    if not first.startswith(_MARK) or header != ",".join(cols):
        raise UserError(f"{p}: not an Allan curve written by `insnav allan` (first line '{_MARK} ...', then the "
                        f"columns {','.join(cols)})")
    rows = []
    for k, line in enumerate(body.splitlines(), start=3):
        if not line.strip():
            continue
        try:
            v = [float(x) for x in line.split(",")]
        except ValueError:
            v = []
        if len(v) != len(cols) or not all(math.isfinite(x) for x in v[:3]) or v[0] <= 0 or v[1] < 1:
            raise UserError(f"{p}, line {k}: expected {len(cols)} numbers (tau_s > 0, m >= 1, clusters, 6 deviations)")
        rows.append(v)
    if len(rows) < 2:
        raise UserError(f"{p}: fewer than 2 averaging times")
    a = np.array(rows)
    m = a[:, 1].astype(np.int64)
    n = int(a[m == 1, 2][0]) if np.any(m == 1) else int(np.max(a[:, 2] * a[:, 1]))
    scale = np.array([DEG_PER_H] * 3 + [MG] * 3)
    curve = AllanCurve(a[:, 0], a[:, 3:] * scale, m, n + 1 - 2 * m, float(a[0, 0] / a[0, 1]), n,
                       ("gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z"))
    return curve, first[len(_MARK):].strip()


def allan_figure(curve, fits_g, fits_a, title: str, dpi: int = 110) -> bytes:
    """PNG bytes of the gyro [deg/h] and accelerometer [mg] Allan deviations with
    95 % chi-square intervals (white-rate edf) and the fitted curves."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..calib.allan import chi2_ppf
    from ..units import DEG_PER_H, MG

    edf = curve.edf(0)
    lo = np.sqrt(edf / np.array([chi2_ppf(0.975, e) for e in edf]))
    hi = np.sqrt(edf / np.array([chi2_ppf(0.025, e) for e in edf]))
    fig, axs = plt.subplots(1, 2, figsize=(12, 4.8))
    colors = ("tab:blue", "tab:orange", "tab:green")
    fine = np.geomspace(curve.tau_s[0], curve.tau_s[-1], 200)
    for k, (ax, fits, scale, unit) in enumerate(((axs[0], fits_g, 1 / DEG_PER_H, "deg/h"),
                                                 (axs[1], fits_a, 1 / MG, "mg"))):
        for a in range(3):
            y = curve.adev[:, 3 * k + a] * scale
            ax.errorbar(curve.tau_s, y, yerr=[y - y * lo, y * hi - y], fmt="o", ms=3, color=colors[a],
                        capsize=2, lw=0.8, label=f"{'xyz'[a]}")
            ax.plot(fine, fits[a].adev_model(fine) * scale, "--", color=colors[a], lw=1)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
        ax.set_xlabel("averaging time tau [s]")
        ax.set_ylabel(f"Allan deviation [{unit}]")
        ax.set_title(("gyro" if k == 0 else "accelerometer") + " (dashed: IEEE 952 fit)")
        ax.legend()
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, metadata={"Software": PNG_SOFTWARE})  # marks it as ours
    plt.close(fig)
    return buf.getvalue()
