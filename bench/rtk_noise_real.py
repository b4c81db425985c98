"""GNSS-only RTK with the configured noise (the default) against ``noise = "estimate"`` (the phase and
code sigmas estimated from the fixed epochs of a first pass by least-squares variance component
estimation, ``insnav.gnss.rtk_noise``) on the real base/rover pairs of ``bench/rtk_compare.py``, setting
by setting (the options of ``bench/rtk/<setting>.toml``): fix rate, wrong fixes and the 3-D RMS of the
fixed epochs against the truth, and the estimate itself.  Evidence for the default, not a results
document: the table goes to stdout (or ``--out``).

    INSNAV_SHARED_DATA=/path/to/shared/data python3 bench/rtk_noise_real.py [--out table.md]
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from rtk_compare import WRONG_FIX_M, datasets, n_rover_epochs  # noqa: E402

REAL = ("euref_wettzell_wtzr_wtzz", "matrtklib_static_septentrio")


def _options(st, noise: str) -> dict:
    """The ``[rtk]`` table of ``bench/rtk/<setting>.toml`` (insnav_toml of rtk_compare) with ``noise``."""
    return dict(mode="kinematic", ar_mode=st["armode"], systems=st["systems"], frequencies=st["freq"],
                elevation_mask_deg=st["mask"], ratio_threshold=3.0, glonass_ar=False, noise=noise,
                **st.get("insnav", {}))


def run(ds, st, noise: str) -> dict:
    from insnav.gnss.rtk import solve_rtk

    c0 = time.process_time()
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        sol = solve_rtk(ds["rover"], ds["base"], ds["nav"], r_base_e=ds["base_e"], options=_options(st, noise))
    cpu = time.process_time() - c0
    n = n_rover_epochs(ds["rover"])
    fx = sol.status == 1
    err = np.linalg.norm(sol.r_e - ds["truth"](sol.t_gps_s), axis=1)
    e = err[fx]
    e = e[np.isfinite(e)]
    est = sol.info.get("noise_estimate")
    return dict(fix_rate=fx.sum() / n, fixed=int(fx.sum()), n=n, wrong=int(np.sum(e > WRONG_FIX_M)),
                rms_mm=1e3 * float(np.sqrt(np.mean(e ** 2))) if e.size else float("nan"), cpu_s=cpu,
                est=est.text() if est is not None else ("; ".join(str(x.message) for x in w) or "-"),
                a_mm=1e3 * sol.info["options"].sigma_phase_a_m, ratio=sol.info["options"].code_phase_ratio)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", help="also write the table here")
    a = ap.parse_args(argv)
    lines = ["| setting | fix rate default / estimate | wrong fixes | RMS fixed [mm] default / estimate | "
             "phase a [mm] / code ratio used (estimate) | CPU [s] default / estimate | estimate |",
             "|---|---|---|---|---|---|---|"]
    for name, ds in datasets().items():
        if name not in REAL:
            continue
        for st in ds["settings"]:
            d, e = run(ds, st, "configured"), run(ds, st, "estimate")
            lines.append(f"| {st['name']} | {100 * d['fix_rate']:.1f} % / {100 * e['fix_rate']:.1f} % "
                         f"({d['fixed']} / {e['fixed']} of {d['n']}) | {d['wrong']} / {e['wrong']} | "
                         f"{d['rms_mm']:.2f} / {e['rms_mm']:.2f} | {e['a_mm']:.3f} / {e['ratio']:.0f} | "
                         f"{d['cpu_s']:.2f} / {e['cpu_s']:.2f} | {e['est']} |")
            print(lines[-1], flush=True)
    text = "\n".join(lines) + "\n"
    if a.out:
        Path(a.out).write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
