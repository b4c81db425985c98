"""GNSS fault detection by the NIS gate: detection and false-alarm rates.

Injects position jumps (10-100 m) and velocity spikes (1-10 m/s) into the
loose GNSS fixes of ``seed000-car`` (GNSS sigma 5 m horizontal, 10 m
vertical, 0.15 m/s; 10 Hz; four outages) and a pseudorange ramp on one
satellite of ``seed004-uav`` (tight coupling), runs the filters with and
without the gate, and prints a markdown table (docs/logs/robustness.md).

Gate thresholds (chi-square 0.999 quantiles, :data:`insnav.analysis.faults.CHI2_999`):
loose 22.46 (6 rows: position + velocity); tight 45.31 (20 rows: the largest
epoch, 10 satellites x pseudorange + rate; the tight gate is one number for
the whole epoch, see the note in the results).

    python bench/faults.py [--seeds 5] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

import insnav
from insnav.analysis import faults as F
from insnav.analysis import errors

LOOSE_GATE = F.CHI2_999[6]
TIGHT_GATE = F.CHI2_999[20]


def horiz_err(sol, truth) -> float:
    e = errors(sol, truth)["pos_n_m"]
    return float(np.max(np.hypot(e[:, 0], e[:, 1])))


def bins(sol, faults, edges):
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = [f for f in faults if lo <= f["magnitude"] < hi]
        s = F.score(sol, sel)
        out.append((lo, hi, s["detected"], s["injected"]))
    return out


def loose_cases(seeds, filters):
    rows = []
    for flt in filters:
        acc = {}
        for seed in seeds:
            ds = insnav.simulate("seed000-car", seed=seed)
            cases = {"clean": (ds, [], None),
                     "position jump": (*F.inject_position_jumps(ds, n=40, seed=seed), [10, 25, 50, 100.1]),
                     "velocity spike": (*F.inject_velocity_spikes(ds, n=40, seed=100 + seed), [1, 2, 5, 10.1])}
            for name, (d2, fl, edges) in cases.items():
                for gate in (0.0, LOOSE_GATE):
                    sol = insnav.run(d2, filter=flt, gate_chi2=gate, gate_reopen_after=0, output_decimation=10)
                    s = F.score(sol, fl, settle_records=0)
                    a = acc.setdefault((name, gate), dict(injected=0, detected=0, missed=0, false_alarms=0,
                                                          clean=0, max_herr=0.0, bins={}))
                    for k in ("injected", "detected", "missed", "false_alarms"):
                        a[k] += s[k]
                    a["clean"] += s["clean_records"]
                    a["max_herr"] = max(a["max_herr"], horiz_err(sol, ds.truth))
                    if edges is not None and gate > 0:
                        for lo, hi, d, n in bins(sol, fl, edges):
                            b = a["bins"].setdefault(f"{lo:g}-{min(hi, 100):g}", [0, 0])
                            b[0] += d
                            b[1] += n
        for (name, gate), a in acc.items():
            rows.append(dict(coupling="loose", filter=flt, fault=name, gate=gate, **a))
    return rows


def tight_cases(seeds, rates=(0.5, 1.0, 2.0)):
    rows = []
    for seed in seeds:
        # every visible satellite: the redundancy the gate needs (the preset keeps the paper's 4)
        ds = insnav.simulate({"extends": "seed004-uav", "gnss_raw": {"max_sats": 0}}, seed=seed)
        for rate in (None, *rates):
            if rate is None:
                d2, fl, name = ds, [], "clean"
            else:
                d2, fl = F.inject_pseudorange_ramp(ds, rate_mps=rate, duration_s=120.0, seed=seed)
                name = f"pseudorange ramp {rate:g} m/s"
            for gate in (0.0, TIGHT_GATE):
                sol = insnav.run(d2, coupling="tight", gate_chi2=gate, gate_reopen_after=0, output_decimation=10)
                s = F.score(sol, fl)
                b = bins(sol, fl, [0, 20, 50, 100, 1e9]) if fl else []
                first = next((f["magnitude"] for f in fl
                              if sol.gnss_status[np.searchsorted(sol.gnss_t, f["t"])] == 2), None)
                rows.append(dict(coupling="tight", filter="ekf", fault=name, gate=gate, seed=seed,
                                 injected=s["injected"], detected=s["detected"], missed=s["missed"],
                                 false_alarms=s["false_alarms"], clean=s["clean_records"],
                                 max_herr=horiz_err(sol, ds.truth), first_detect_m=first,
                                 bins={f"{lo:g}-{hi:g}": [d, n] for lo, hi, d, n in b}))
    return rows


def table(rows):
    lines = ["| coupling / filter | fault | gate | injected | detected | missed | false alarms (clean records) "
             "| max horiz. error [m] | detected by size |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        b = ", ".join(f"{k}: {d}/{n}" for k, (d, n) in r["bins"].items() if n)
        extra = f"; first rejected at {r['first_detect_m']:.0f} m" if r.get("first_detect_m") else ""
        lines.append(f"| {r['coupling']} {r['filter']} | {r['fault']} | {r['gate'] or 'off'} | {r['injected']} | "
                     f"{r['detected']} | {r['missed']} | {r['false_alarms']} ({r['clean']}) | "
                     f"{r['max_herr']:.1f} | {b}{extra} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--filters", default="ekf,rbukf")
    ap.add_argument("--json")
    a = ap.parse_args(argv)
    t0 = time.time()
    rows = loose_cases(range(1, a.seeds + 1), a.filters.split(","))
    rows += tight_cases(range(1, min(a.seeds, 3) + 1))
    print(table(rows))
    print(f"\n{time.time() - t0:.0f} s")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
