"""``insnav demo``: the main job on a built-in default.

Simulates ``seed000-sim`` (150 s of pitching and rolling, MEMS IMU, GPS lost
50-90 s), runs EKF, RB-UKF and UKF on the same data, prints a comparison
table and writes a report folder with error plots (3-sigma bounds, outage
shaded) and a Markdown summary.  Without ``--quick`` it also runs a delayed-
GNSS scenario (``seed001-high``: plain KF, random-delay KF, exact time-tagged)
and a tight-coupling scenario (``seed003-1sat``: loose vs tight EKF).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from ..analysis.metrics import errors, recovery_metrics, rms

QUANTITIES = (("pos_n_m", "position", "m", ("N", "E", "D")),
              ("vel_n_mps", "velocity", "m/s", ("N", "E", "D")),
              ("att_deg", "attitude", "deg", ("roll", "pitch", "yaw")))


def _plot(errs: dict, outages, path_stem: Path, title: str) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    colors = {"ekf": "tab:red", "rbukf": "tab:blue", "ukf": "tab:green", "kf": "tab:red",
              "rdkf": "tab:blue", "exact": "tab:green", "loose-ekf": "tab:red", "tight-ekf": "tab:blue"}
    for key, name, unit, axes in QUANTITIES:
        fig, ax = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
        for f, e in errs.items():
            c = colors.get(f, None)
            for i in range(3):
                ax[i].plot(e["t"], e[key][:, i], color=c, lw=0.9, label=f"{f} error")
                sk = "sigma_" + key
                if sk in e:
                    ax[i].plot(e["t"], 3 * e[sk][:, i], color=c, lw=0.6, ls="--", label=f"{f} 3-sigma")
                    ax[i].plot(e["t"], -3 * e[sk][:, i], color=c, lw=0.6, ls="--")
        for i in range(3):
            for (a, b) in outages:
                ax[i].axvspan(a, b, color="0.85", zorder=0, label="GNSS outage" if i == 0 else None)
            ax[i].set_ylabel(f"{axes[i]} [{unit}]")
            ax[i].grid(alpha=0.3)
            lo, hi = np.percentile(np.concatenate([np.abs(e[key][:, i]) for e in errs.values()]), [0, 99.5])
            ax[i].set_ylim(-2.5 * hi, 2.5 * hi)
        ax[0].set_title(f"{title}: {name} error (solution - truth)")
        ax[0].legend(fontsize=7, ncol=4, loc="upper left")
        ax[-1].set_xlabel("time [s]")
        fig.tight_layout()
        p = path_stem.with_name(f"{path_stem.name}_{name}.png")
        fig.savefig(p, dpi=110)
        plt.close(fig)
        paths.append(p)
    return paths


def _fmt_row(cells):
    return "| " + " | ".join(cells) + " |"


def _seed000_section(args, out: Path, lines: list) -> None:
    import insnav

    ds = insnav.simulate("seed000-sim", seed=args.seed)
    outages = [tuple(o) for o in ds.scenario.get("gnss", {}).get("outages", [[50.0, 90.0]])]
    t_rec = outages[0][1]
    errs, times, sols = {}, {}, {}
    for f in ("ekf", "rbukf", "ukf"):
        t0 = time.perf_counter()
        sols[f] = sol = insnav.run(ds, filter=f, init_seed=args.seed)
        times[f] = time.perf_counter() - t0
        errs[f] = errors(sol, ds.truth)
    # reconvergence band: 1.5 x the EKF's pre-outage (20 s .. outage) RMS, the same for every filter
    pre = (errs["ekf"]["t"] > 20) & (errs["ekf"]["t"] < outages[0][0])
    thr = {k: 1.5 * rms(errs["ekf"][k][pre]) for k, *_ in QUANTITIES}
    rec = {f: recovery_metrics(e, t_rec, thr) for f, e in errs.items()}
    head = ["filter", "time [s]", "pos RMS N/E/D [m]", "att RMS r/p/y [deg]",
            f"max att after {t_rec:.0f} s r/p/y [deg]", "reconv att r/p/y [s]", "max pos after N/E/D [m]",
            "reconv pos N/E/D [s]"]
    table = [_fmt_row(head), _fmt_row(["---"] * len(head))]
    for f, e in errs.items():
        r = rec[f]
        table.append(_fmt_row([
            f, f"{times[f]:.3f}", "/".join(f"{x:.2f}" for x in rms(e["pos_n_m"])),
            "/".join(f"{x:.3f}" for x in rms(e["att_deg"])),
            "/".join(f"{x:.3f}" for x in r["att_deg"]["max"]),
            "/".join(f"{x:.0f}" for x in r["att_deg"]["reconv_s"]),
            "/".join(f"{x:.2f}" for x in r["pos_n_m"]["max"]),
            "/".join(f"{x:.0f}" for x in r["pos_n_m"]["reconv_s"])]))
    pngs = _plot(errs, outages, out / "seed000", "seed000-sim")
    print("\nseed000-sim (150 s pitch/roll, MEMS IMU, GPS lost "
          f"{outages[0][0]:.0f}-{outages[0][1]:.0f} s), seed {args.seed}:")
    print("\n".join(table))
    lines += ["## seed000-sim: EKF vs RB-UKF vs UKF (seed 000, Table 1 setting)", "",
              f"One run, seed {args.seed}. GPS lost {outages[0][0]:.0f}-{outages[0][1]:.0f} s. Reconvergence: the "
              "first time after recovery from which the error stays for 5 s within 1.5x the EKF's pre-outage RMS "
              "(the same band for every filter).", "", *table, ""]
    lines += [f"![{p.stem}]({p.name})" for p in pngs] + [""]
    # the full report of the RB-UKF run: track, errors with 3 sigma, biases, innovations/NIS, summary
    from ..analysis.report import report
    from ..filters.solution import write_innovations

    sol_path = sols["rbukf"].save(out / "seed000-rbukf.npz")
    write_innovations(sols["rbukf"], sol_path)
    page = report(sol_path, out / "seed000-rbukf-report", truth=ds.truth, gnss=ds.gnss, outages=outages,
                  title=f"insnav demo: seed000-sim, RB-UKF, seed {args.seed}")
    lines += [f"Full report of the RB-UKF run: [{page.parent.name}/{page.name}]({page.parent.name}/{page.name})", ""]


def _delay_section(args, out: Path, lines: list) -> None:
    import insnav

    ds = insnav.simulate("seed001-high", seed=args.seed)
    errs = {}
    for f in ("kf", "rdkf", "exact"):
        errs[f] = errors(insnav.run(ds, filter=f, init_seed=args.seed), ds.truth)
    head = ["filter", "N pos RMS [m]", "E pos RMS [m]", "N vel RMS [m/s]", "E vel RMS [m/s]"]
    table = [_fmt_row(head), _fmt_row(["---"] * 5)]
    for f, e in errs.items():
        sel = e["t"] > 5
        p, v = rms(e["pos_n_m"][sel]), rms(e["vel_n_mps"][sel])
        table.append(_fmt_row([f, f"{p[0]:.4f}", f"{p[1]:.4f}", f"{v[0]:.5f}", f"{v[1]:.5f}"]))
    pngs = _plot(errs, [], out / "seed001", "seed001-high")
    print("\nseed001-high (GNSS late by 0-3 epochs, p = [0.2, 0.4, 0.2, 0.2]):")
    print("\n".join(table))
    lines += ["## seed001-high: delayed GNSS (seed 001)", "",
              "kf: fixes used as if current; rdkf: the random-delay KF of seed 001; exact: time-tagged "
              "re-processing from a checkpoint.", "", *table, ""]
    lines += [f"![{p.stem}]({p.name})" for p in pngs] + [""]


def _tight_section(args, out: Path, lines: list, n_seeds: int = 5) -> None:
    """seed003-1sat over several seeds: loose, tight and an INS-only baseline
    (mean +- sd at the end of the one-satellite window; a single run decides nothing)."""
    import insnav

    win = [(600.0, 900.0)]
    ends = {"loose-ekf": [], "tight-ekf": [], "INS only from 600 s": []}
    errs_first = None
    for k in range(n_seeds):
        seed = args.seed + k
        ds = insnav.simulate("seed003-1sat", seed=seed)
        errs = {"loose-ekf": errors(insnav.run(ds, filter="ekf", init_seed=seed), ds.truth),
                "tight-ekf": errors(insnav.run(ds, filter="ekf", coupling="tight", init_seed=seed), ds.truth)}
        i0 = int(np.argmin(np.abs(ds.truth.t - win[0][0])))
        sel = ds.imu.t > ds.truth.t[i0] + 1e-9
        errs["INS only from 600 s"] = errors(insnav.mechanize(ds.imu.t[sel], ds.imu.dtheta_b[sel], ds.imu.dv_b[sel],
                                                              ds.truth.state_at(i0), float(ds.truth.t[i0])), ds.truth)
        for f, e in errs.items():
            i = int(np.argmin(np.abs(e["t"] - 899.0)))
            ends[f].append(float(np.linalg.norm(e["pos_n_m"][i])))
        if errs_first is None:
            errs_first = errs
    head = ["solution", f"pos error at 899 s [m], mean +- sd over {n_seeds} seeds", "per seed"]
    table = [_fmt_row(head), _fmt_row(["---"] * 3)]
    for f, v in ends.items():
        v = np.array(v)
        table.append(_fmt_row([f, f"{v.mean():.2f} +- {v.std(ddof=1):.2f}", " ".join(f"{x:.1f}" for x in v)]))
    wins = int(np.sum(np.array(ends["tight-ekf"]) < np.array(ends["loose-ekf"])))
    pngs = _plot({k: v for k, v in errs_first.items() if k != "INS only from 600 s"}, win, out / "seed003",
                 "seed003-1sat")
    print(f"\nseed003-1sat (one satellite from 600 to 900 s; loose has no fixes there), seeds "
          f"{args.seed}..{args.seed + n_seeds - 1}:")
    print("\n".join(table))
    print(f"tight better than loose at 899 s in {wins} of {n_seeds} seeds")
    lines += ["## seed003-1sat: loose vs tight (seed 003)", "",
              "One satellite from 600 to 900 s (loose gets no fixes there, so it runs on its calibrated INS); "
              "INS only: an unaided INS started from the true state at 600 s.  Figure: the first seed.", "",
              *table, "", f"Tight better than loose at 899 s in {wins} of {n_seeds} seeds "
              "(docs/results/seed003.md has 20 runs and the clock sweep).", ""]
    lines += [f"![{p.stem}]({p.name})" for p in pngs] + [""]


#: the first line of report.md: how a folder the demo wrote is told from a user's
REPORT_TITLE = "# insnav demo report"


def _check_demo_folder(out: Path) -> None:
    """``--out`` must be new, empty, or a folder an earlier demo wrote (its report.md
    starts with :data:`REPORT_TITLE`): the demo replaces report.md and its figures there,
    and must not replace a user's files of the same names."""
    from ..errors import UserError

    if not out.exists():
        return
    if not out.is_dir():
        raise UserError(f"--out {out}: exists and is not a folder")
    report = out / "report.md"
    try:
        with open(report, encoding="utf-8", errors="replace") as f:
            ours = f.readline().rstrip("\n") == REPORT_TITLE
    except OSError:
        ours = False
    if not ours and any(out.iterdir()):
        raise UserError(f"--out {out}: a folder that is not empty and holds no report.md of an earlier "
                        "insnav demo: the demo would replace its files; give a new or empty folder")


def main(args) -> int:
    from .._atomic import atomic_write_text

    try:
        import matplotlib  # noqa: F401
    except ImportError:
        from ..errors import UserError

        raise UserError("insnav demo draws its figures with matplotlib: pip install 'insnav[plot]'") from None
    out = Path(args.out)
    _check_demo_folder(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    lines = [REPORT_TITLE, "",
             "Frames: NED navigation, FRD body, 3-2-1 Euler angles; errors are solution minus truth.", ""]
    _seed000_section(args, out, lines)
    if not args.quick:
        for section in (_delay_section, _tight_section):
            try:
                section(args, out, lines)
            except Exception as exc:  # a failing optional section must not hide the main result
                print(f"\n[{section.__name__[1:-8]} section failed: {exc}]", file=sys.stderr)
                lines += [f"_{section.__name__[1:-8]} section failed: {exc}_", ""]
    lines += [f"Total demo time {time.perf_counter() - t0:.1f} s. Reproduce: `insnav demo --seed {args.seed}"
              f"{' --quick' if args.quick else ''}`.", ""]
    report = atomic_write_text(out / "report.md", "\n".join(lines))
    print(f"\nreport: {report}  ({time.perf_counter() - t0:.1f} s)")
    return 0
