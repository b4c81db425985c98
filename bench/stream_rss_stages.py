"""Where the peak RSS of a block-by-block ``insnav run`` grows with the recording.

The synthesised recordings of ``bench/cli_end_to_end.py`` (``write_day``: a
vehicle standing at the KF-GINS track's start point, 200 Hz increments, 1 Hz
GNSS fixes) at each of ``--hours``, each run once per variant in a child
process whose stages (``insnav.filters.stream``: the GNSS file read, the
engine's set-up with the GNSS cut and sanitizer, the block loop, the end's
input checks) are wrapped to log the process's ``VmRSS`` and ``VmHWM``
(``/proc/self/status``) before and after.  The table gives the peak RSS
(``VmHWM``) reached by the end of each stage at each length and the
difference between the longest and the shortest, per hour of the
difference.  Linux only.  The recordings are written under the temporary
folder (about 81 MB of text per hour) and deleted at the end; nothing is
written to docs/results.

    python bench/stream_rss_stages.py [--hours 1 24] [--out /tmp/stages.md]
"""
from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from cli_end_to_end import SIM, write_day

#: (label, extra arguments of ``insnav run``): the growth rows of bench/cli_end_to_end.py
VARIANTS = [("EKF, CSV, 10 Hz", ["--output-rate", "10"]), ("EKF, CSV, 200 Hz, nav columns", ["--columns", "nav"])]
#: the stages, in the order they end: (label, module, attribute)
STAGES = [("GNSS file read (kfgins_stream_inputs)", "insnav.io.kfgins_dataset", "kfgins_stream_inputs"),
          ("engine set-up: GNSS cut, sanitizer, rows (_BlockRun._start)", "insnav.filters.stream", "_BlockRun._start"),
          ("block loop (to _BlockRun._result)", "insnav.filters.stream", "_BlockRun._result:enter"),
          ("input checks (check_dataset)", "insnav.data.checks", "check_dataset"),
          ("whole run (_BlockRun.run)", "insnav.filters.stream", "_BlockRun.run")]

PROBE = r"""
import functools, importlib, json, sys
def status():
    d = {}
    with open("/proc/self/status") as f:
        for ln in f:
            if ln.startswith(("VmHWM", "VmRSS")):
                k, v = ln.split(":")
                d[k] = int(v.split()[0]) / 1024
    return d
def wrap(owner, name, key):
    f = getattr(owner, name)
    @functools.wraps(f)
    def g(*a, **k):
        s0 = status()
        print("STAGE " + json.dumps(dict(key=key + ":enter", rss=s0["VmRSS"], hwm=s0["VmHWM"])), file=sys.stderr)
        try:
            return f(*a, **k)
        finally:
            s1 = status()
            print("STAGE " + json.dumps(dict(key=key, rss=s1["VmRSS"], hwm=s1["VmHWM"])), file=sys.stderr)
    setattr(owner, name, g)
for mod, attr in json.loads(sys.argv[1]):
    m = importlib.import_module(mod)
    owner, name = (getattr(m, attr.split(".")[0]), attr.split(".")[1]) if "." in attr else (m, attr)
    wrap(owner, name.split(":")[0], attr.split(":")[0])
from insnav.cli import main
rc = main(sys.argv[2:])
sys.stderr.flush()
sys.exit(rc)
"""


def probe(work: Path, extra) -> dict:
    """One ``insnav run`` of ``work/day.yaml`` with the stages logged: {stage key: (VmRSS, VmHWM) [MB]}."""
    out = work / "out" / "sol.csv"
    out.parent.mkdir(exist_ok=True)
    targets = sorted({(m, a.split(":")[0]) for _, m, a in STAGES})
    args = [sys.executable, "-c", PROBE, json.dumps(targets), "run", "--format", "kfgins", "--config",
            str(work / "day.yaml"), "--quiet", "--filter", "ekf", "--out", str(out), *extra]
    p = subprocess.run(args, cwd=work, capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(p.stderr)
    shutil.rmtree(out.parent)
    res = {}
    for ln in p.stderr.splitlines():
        if ln.startswith("STAGE "):
            e = json.loads(ln[6:])
            res[e["key"]] = (e["rss"], e["hwm"])
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--hours", type=float, nargs="+", default=[1.0, 24.0])
    ap.add_argument("--gnss-hz", type=float, default=1.0, help="GNSS fix rate of the recordings [Hz]")
    ap.add_argument("--out", help="also write the table to this file")
    a = ap.parse_args(argv)
    hours = sorted(a.hours)
    work = Path(tempfile.mkdtemp(prefix="insnav-rss-stages-"))
    got = {}
    try:
        for h in hours:
            d = work / f"h{h:g}"
            d.mkdir()
            for f in ("GNSS-RTK-sim.txt", "kf-gins-sim.yaml"):
                shutil.copy(SIM / f, d / f)
            write_day(d, h, a.gnss_hz)
            for label, extra in VARIANTS:
                got[label, h] = probe(d, extra)
                print(f"{h:g} h: {label}: peak {got[label, h]['_BlockRun.run'][1]:.1f} MB", file=sys.stderr)
            shutil.rmtree(d)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    lo, hi = hours[0], hours[-1]
    lines = [f"Peak RSS (VmHWM) [MB] reached by the end of each stage of a block-by-block `insnav run` "
             f"(bench/stream_rss_stages.py; synthesised recordings of {', '.join(f'{h:g} h' for h in hours)}, "
             f"{a.gnss_hz:g} Hz GNSS), "
             f"the peak's rise in the stage, and the difference {hi:g} h - {lo:g} h:", ""]
    for label, _ in VARIANTS:
        lines += [f"{label}:", "",
                  "| stage | " + " | ".join(f"{h:g} h: peak (rise)" for h in hours) + f" | {hi:g} h - {lo:g} h |",
                  "|---|" + "---|" * (len(hours) + 1)]
        for name, _, attr in STAGES:
            key = attr if attr.endswith(":enter") else attr.split(":")[0]
            cells, peaks = [], []
            for h in hours:
                r = got[label, h]
                # the rise: from the stage's entry (the loop: from the end of the set-up)
                before = r["_BlockRun._start" if key.endswith(":enter") else key + ":enter"][1]
                peak = r[key][1]
                peaks.append(peak)
                cells.append(f"{peak:.1f} ({peak - before:+.1f})")
            lines.append(f"| {name} | " + " | ".join(cells) + f" | {peaks[-1] - peaks[0]:+.1f} |")
        p0, p1 = got[label, lo]["_BlockRun.run"][1], got[label, hi]["_BlockRun.run"][1]
        lines += ["", f"- {label}: {p1 - p0:+.1f} MB over {hi - lo:g} h: {(p1 - p0) / (hi - lo):+.2f} MB per hour "
                      "of recording.", ""]
    text = "\n".join(lines)
    print(text)
    if a.out:
        Path(a.out).write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
