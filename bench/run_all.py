"""Regenerate every results document in docs/results/ at the current commit.

    python3 bench/run_all.py [--only NAME[,NAME...]] [--quick] [--list] [--jobs N]

Each generator writes its whole document (with the commit and the exact
command inside it).  They run one after the other (each may use both cores);
the wall time of each and of the whole run is printed and written to
``docs/results/run_all.md`` (``--only`` replaces the rows of the generators it ran).  ``--quick`` passes each generator's reduced-run
arguments (for checking the pipeline, not for publishing: the documents then
say so through their own command line).  Needs the installed package
(``scripts/install.sh``) and ``../shared/data`` for the real-data documents.
"""
from __future__ import annotations

import argparse
import shlex
import subprocess
import sys
import time
from pathlib import Path
from _stamps import with_stamp  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable

#: name -> (document(s), full command, quick command)
GENERATORS: dict[str, tuple[tuple[str, ...], list[str], list[str]]] = {
    "seed000": (("seed000.md",), ["bench/seed000_tables.py"],
                ["bench/seed000_tables.py", "--runs", "4", "--car-runs", "2"]),
    "seed001": (("seed001.md",), ["bench/seed001_tables.py"], ["bench/seed001_tables.py", "--runs", "4"]),
    "seed003": (("seed003.md",), ["bench/seed003_tables.py"], ["bench/seed003_tables.py", "--runs", "3"]),
    "seed004": (("seed004.md",), ["bench/seed004_tables.py"],
                ["bench/seed004_tables.py", "--runs", "2", "--heading-runs", "2", "--pf-particles", "200"]),
    "seed004_bench": (("seed004_bench.md",), ["bench/bench_upf.py", "--out", "docs/results/seed004_bench.md"],
                      ["bench/bench_upf.py", "--repeat", "1", "--out", "docs/results/seed004_bench.md"]),
    "kfgins": (("kfgins.md",), ["bench/kfgins_track.py"], ["bench/kfgins_track.py", "--repeat", "1"]),
    "flops": (("flops.md",), ["bench/update_cost.sh", "200"], ["bench/update_cost.sh", "20"]),
    "gnss_geometry": (("gnss_geometry.md",), ["bench/gnss_residuals.py", "--out", "docs/results/gnss_geometry.md"],
                      ["bench/gnss_residuals.py", "--out", "docs/results/gnss_geometry.md"]),
    "vehicle_constraints": (("vehicle_constraints.md",), ["bench/vehicle_constraints.py"],
                            ["bench/vehicle_constraints.py", "--runs", "2"]),
    "cli_end_to_end": (("cli_end_to_end.md",), ["bench/cli_end_to_end.py", "--repeat", "3"],
                       ["bench/cli_end_to_end.py", "--repeat", "1"]),
    "spp_smartloc": (("spp_smartloc.md",), ["bench/spp_smartloc.py", "--out", "docs/results/spp_smartloc.md"],
                     ["bench/spp_smartloc.py", "--out", "docs/results/spp_smartloc.md"]),
    "tight_realdata": (("tight_realdata.md",),
                       ["bench/tight_realdata.py", "--out", "docs/results/tight_realdata.md"],
                       ["bench/tight_realdata.py", "--out", "docs/results/tight_realdata.md"]),
    "tight_multignss": (("tight_multignss.md",),
                        ["bench/tight_multignss.py", "--runs", "20", "--fault-runs", "20", "--walk", "--out",
                         "docs/results/tight_multignss.md"],
                        ["bench/tight_multignss.py", "--runs", "2", "--fault-runs", "2", "--walk", "--out",
                         "docs/results/tight_multignss.md"]),
    "gnss_speed": (("gnss_speed.md",), ["bench/gnss_speed.py", "--out", "docs/results/gnss_speed.md"],
                   ["bench/gnss_speed.py", "--repeats", "3", "--out", "docs/results/gnss_speed.md"]),
    "walk_loose": (("walk_loose.md",), ["bench/walk_loose.py", "--out", "docs/results/walk_loose.md"],
                   ["bench/walk_loose.py", "--out", "docs/results/walk_loose.md"]),
    "tdcp_walk": (("tdcp_walk.md",), ["bench/tdcp_walk.py", "--out", "docs/results/tdcp_walk.md"],
                  ["bench/tdcp_walk.py", "--out", "docs/results/tdcp_walk.md"]),
    "rtk_sim": (("rtk_sim.md",), ["bench/rtk_sim_rtklib.py", "--runs", "20", "--out", "docs/results/rtk_sim.md"],
                ["bench/rtk_sim_rtklib.py", "--runs", "2", "--out", "docs/results/rtk_sim.md"]),
    "rtk_compare": (("rtk_euref_wettzell_wtzr_wtzz.md", "rtk_matrtklib_static_septentrio.md",
                     "rtk_instinct_spirent_rtk_dynamic_SIMULATED.md"), ["bench/rtk_compare.py"],
                    ["bench/rtk_compare.py", "--repeat", "1"]),
    "rtk_ins": (("rtk_ins.md",), ["bench/rtk_ins.py", "--runs", "20", "--out", "docs/results/rtk_ins.md"],
                ["bench/rtk_ins.py", "--runs", "2", "--out", "docs/results/rtk_ins.md"]),
    "rtk_urban_feasibility": (("rtk_urban_feasibility.md",),
                              ["bench/rtk_urban_feasibility.py", "--runs", "20", "--out",
                               "docs/results/rtk_urban_feasibility.md"],
                              ["bench/rtk_urban_feasibility.py", "--runs", "2", "--out",
                               "docs/results/rtk_urban_feasibility.md"]),
    "rtk_ins_screening": (("rtk_ins_screening.md",),
                          ["bench/rtk_ins_screening.py", "--runs", "20", "--out", "docs/results/rtk_ins_screening.md"],
                          ["bench/rtk_ins_screening.py", "--runs", "2", "--out", "docs/results/rtk_ins_screening.md"]),
    "gate_outages": (("gate_outages.md",), ["bench/gate_outages.py", "--out", "docs/results/gate_outages.md"],
                     ["bench/gate_outages.py", "--seeds", "2", "--out", "docs/results/gate_outages.md"]),
    "navigator": (("navigator.md",), ["bench/navigator_latency.py"], ["bench/navigator_latency.py", "--runs", "1"]),
    "tune": (("tune.md",), ["bench/tune_check.py", "--out", "docs/results/tune.md"],
             ["bench/tune_check.py", "--seeds", "1", "--max-runs", "40", "--real-max-runs", "24", "--out",
              "docs/results/tune.md"]),
    "selfcal_states": (("selfcal_states.md",), ["bench/selfcal_states.py", "--out", "docs/results/selfcal_states.md"],
                       ["bench/selfcal_states.py", "--runs", "4", "--zero-runs", "2", "--lever-runs", "1",
                        "--out", "docs/results/selfcal_states.md"]),
    "allan": (("allan.md",), ["bench/allan_check.py", "--out", "docs/results/allan.md"],
              ["bench/allan_check.py", "--hours", "3", "--repeat", "1", "--skip-24h", "--out", "docs/results/allan.md"]),
    "simulate_day": (("simulate_day.md",), ["bench/simulate_day.py", "--out", "docs/results/simulate_day.md"],
                     ["bench/simulate_day.py", "--repeat", "1", "--hours", "3", "--out",
                      "docs/results/simulate_day.md"]),
}


#: generators whose documents report wall or CPU times: they run alone, after the others
#: (the rest only count, so ``--jobs 2`` may run two of them side by side)
TIMED = ("seed004_bench", "kfgins", "cli_end_to_end", "gnss_speed", "rtk_compare", "navigator", "tune", "allan",
         "simulate_day")


def git_commit() -> str:
    out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    return out.stdout.strip() or "unknown"


def _previous_rows() -> dict[str, tuple[str, ...]]:
    """The rows of the current docs/results/run_all.md (generator -> its six cells; a
    row of the older five-column table gets the document's commit)."""
    path = ROOT / "docs/results/run_all.md"
    if not path.exists():
        return {}
    text = path.read_text()
    old_commit = text.split("at commit `", 1)[1].split("`", 1)[0] if "at commit `" in text else "unknown"
    out = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) in (5, 6) and cells[0] in GENERATORS:
            cells = [c.strip("`") if i in (2, 5) else c for i, c in enumerate(cells)]
            out[cells[0]] = tuple(cells) if len(cells) == 6 else (*cells, old_commit)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", default="", help="comma-separated generator names")
    ap.add_argument("--quick", action="store_true", help="reduced runs (pipeline check)")
    ap.add_argument("--list", action="store_true")
    ap.add_argument("--jobs", type=int, default=1,
                    help="generators run side by side (not the timed ones, which run alone at the end)")
    args = ap.parse_args(argv)
    if args.list:
        for name, (docs, full, _) in GENERATORS.items():
            print(f"{name:15s} {', '.join(docs):28s} {shlex.join(full)}")
        return 0
    names = [n.strip() for n in args.only.split(",") if n.strip()] or list(GENERATORS)
    unknown = [n for n in names if n not in GENERATORS]
    if unknown:
        ap.error(f"unknown generator(s) {', '.join(unknown)}; known: {', '.join(GENERATORS)}")
    rows, failed = {}, []
    t_all = time.perf_counter()

    def one(name):
        docs, full, quick = GENERATORS[name]
        argv_ = quick if args.quick else full
        cmd = ["bash" if argv_[0].endswith(".sh") else PY, *argv_]
        print(f"[run_all] {name}: {shlex.join(cmd[1:])}", flush=True)
        t0, at = time.perf_counter(), git_commit()
        rc = subprocess.run(cmd, cwd=ROOT).returncode
        dt = time.perf_counter() - t0
        rows[name] = (name, docs, shlex.join([cmd[0] if cmd[0] == "bash" else "python3", *cmd[1:]]), dt, rc, at)
        print(f"[run_all] {name}: rc {rc}, {dt:.0f} s", flush=True)
        if rc:
            failed.append(name)

    counted = [n for n in names if n not in TIMED]
    if args.jobs > 1:
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(args.jobs) as pool:
            list(pool.map(one, counted))
    else:
        for name in counted:
            one(name)
    for name in names:
        if name in TIMED:
            one(name)
    total = time.perf_counter() - t_all
    commit = git_commit()
    table = _previous_rows() if args.only else {}  # a partial run updates its own rows only
    for n in names:
        name, docs, cmd, dt, rc, at = rows[n]
        table[name] = (name, ", ".join(docs), cmd, f"{dt:.0f}", str(rc), at)
    how = ("each generator alone, one after the other" if args.jobs <= 1 else
           f"the generators that only count {args.jobs} side by side; those that report times "
           f"({', '.join(TIMED)}) alone after them")
    lines = ["# Results documents: regeneration times", "",
             f"Written by `bench/run_all.py`; this invocation at commit `{commit}`: "
             f"`python3 bench/run_all.py {' '.join(argv if argv is not None else sys.argv[1:])}` ({how}, "
             f"on the shared 2-core machine; {total:.0f} s, {total / 60:.1f} min).  A run with `--only` "
             "replaces its generators' rows and keeps the others; each row names the commit its generator started at.", "",
             "| generator | documents | command | wall [s] | exit | commit |", "|---|---|---|---|---|---|"]
    for name in GENERATORS:
        if name in table:
            g, docs, cmd, dt, rc, c = table[name]
            lines.append(f"| {g} | {docs} | `{cmd}` | {dt} | {rc} | `{c}` |")
    (ROOT / "docs/results/run_all.md").write_text(with_stamp("\n".join(lines) + "\n", "run_all.md"))
    print("\n".join(lines))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
