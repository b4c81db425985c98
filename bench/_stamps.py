"""Freshness stamps of the results documents in docs/results/.

Every document ends with a stamp that names the commit it was generated at
and the files its numbers depend on: the generator script, the scenario
presets it runs, and the specific core headers and Python modules on its path
(not all of ``cpp/``: an unrelated change must not make every document
stale).  ``tests/test_results_stamps.py`` fails when one of those files
differs from its version at the stamped commit, i.e. when the document was
not regenerated after the change.

Generators append :func:`stamp` to the text they write::

    text += stamp("seed001.md")

and shell generators print it with ``python3 bench/_stamps.py stamp flops.md``.
The dependency lists are :data:`DEPENDS` (one per document); the check uses
the union of this list and the one written into the document, so adding a
dependency here also flags documents generated before.

    python3 bench/_stamps.py check            # the test's verdict for every document
    python3 bench/_stamps.py stamp DOC        # print the stamp block for DOC
"""
from __future__ import annotations

import functools
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results"

_CPP = "cpp/include/insnav/"
_PY = "python/insnav/"

#: the strapdown, Earth model and loose GNSS measurement every loose run uses
INS = (f"{_CPP}ins/mechanization.hpp", f"{_CPP}ins/nav_state.hpp", f"{_CPP}earth/wgs84.hpp",
       f"{_CPP}math/rotation.hpp")
#: closed-loop loose EKF engine and its Python runner (the default settings live in config.py)
LOOSE_EKF = INS + (f"{_CPP}engine/closed_loop.hpp", f"{_CPP}engine/loose_engine.hpp", f"{_CPP}filter/ekf.hpp",
                   f"{_CPP}filter/error_model_linear.hpp", f"{_CPP}filter/kalman_update.hpp",
                   f"{_CPP}filter/layout.hpp", f"{_CPP}filter/nis_gate.hpp", f"{_CPP}meas/gnss_loose.hpp",
                   f"{_CPP}filter/adaptive_noise.hpp", f"{_PY}filters/loose.py", f"{_PY}filters/_setup.py", f"{_PY}filters/sanitize.py",
                   f"{_PY}config.py")
#: the seed 000 sigma-point filters
SIGMA = (f"{_CPP}filter/rbukf.hpp", f"{_CPP}filter/ukf.hpp", f"{_CPP}filter/augmented_ut.hpp",
         f"{_CPP}filter/sigma_points.hpp", f"{_CPP}filter/error_model_nonlinear.hpp", f"{_CPP}filter/macro_step.hpp")
#: the tightly coupled EKF engine
TIGHT = INS + (f"{_CPP}engine/closed_loop.hpp", f"{_CPP}engine/tight_engine.hpp", f"{_CPP}filter/ekf.hpp",
               f"{_CPP}filter/error_model_linear.hpp", f"{_CPP}filter/kalman_update.hpp",
               f"{_CPP}filter/nis_gate.hpp", f"{_CPP}meas/pseudorange.hpp", f"{_CPP}meas/robust.hpp",
               f"{_CPP}filter/adaptive_noise.hpp", f"{_PY}filters/tight.py", f"{_PY}filters/_setup.py", f"{_PY}config.py",
               f"{_PY}gnss/clock.py")
#: the simulator (trajectory, IMU errors, loose fixes)
SIM = (f"{_PY}sim/scenario.py", f"{_PY}sim/trajectory.py", f"{_PY}sim/imu.py", f"{_PY}sim/gnss_loose.py")
#: simulated raw GNSS (pseudorange, range rate, constellation)
SIM_RAW = SIM + (f"{_PY}sim/gnss_raw.py", f"{_PY}gnss/walker.py", f"{_PY}gnss/constellation.py",
                 f"{_PY}gnss/tight_inputs.py")
#: Monte Carlo campaigns, error metrics and the paired statistics of the verdicts
MC = (f"{_PY}analysis/montecarlo.py", f"{_PY}analysis/metrics.py", f"{_PY}analysis/paired.py")
#: the seed 004 particle filters
PARTICLE = (f"{_CPP}filter/particle_filter.hpp", f"{_CPP}filter/upf.hpp", f"{_CPP}filter/fading.hpp",
            f"{_CPP}filter/ukf.hpp", f"{_CPP}filter/sigma_points.hpp", f"{_CPP}filter/resampling.hpp",
            f"{_CPP}filter/layout20.hpp", f"{_CPP}filter/random.hpp", f"{_PY}filters/particle.py")
#: RINEX reading, broadcast orbits and the real-data tight inputs
RINEX = (f"{_PY}gnss/rinex.py", f"{_PY}gnss/broadcast.py", f"{_PY}gnss/ephemeris.py", f"{_PY}gnss/corrections.py",
         f"{_PY}gnss/tight_inputs.py", f"{_PY}io/rinex_dataset.py", f"{_PY}gnss/glonass.py", f"{_PY}gnss/geometry.py",
         f"{_PY}_median.py", f"{_CPP}io/rinex_nav.hpp", f"{_CPP}gnss/ephemeris_selection.hpp",
         f"{_CPP}gnss/gdop_selection.hpp")
#: carrier-phase RTK: the C++ engine (double differences, float EKF, MLAMBDA) and its Python run
RTK = (f"{_CPP}gnss/rtk.hpp", f"{_CPP}gnss/lambda.hpp", f"{_CPP}gnss/ambiguity_resolution.hpp",
       f"{_CPP}gnss/double_difference.hpp", f"{_CPP}gnss/noise_vce.hpp",
       "cpp/bindings/bind_rtk.cpp", f"{_PY}gnss/rtk.py", f"{_PY}gnss/rtk_noise.py", f"{_PY}gnss/_rtk_keys.py",
       f"{_PY}filters/rtk.py", f"{_CPP}gnss/rtk_rinex.hpp", f"{_PY}cli/rtk_fast.py",
       f"{_PY}gnss/rinex.py", f"{_PY}gnss/broadcast.py", f"{_PY}gnss/ephemeris.py")
#: KF-GINS data reading
KFGINS = (f"{_PY}io/kfgins.py", f"{_PY}io/kfgins_dataset.py")

#: document -> the files its numbers depend on (repository-relative)
DEPENDS: dict[str, tuple[str, ...]] = {
    "seed000.md": ("bench/seed000_tables.py", f"{_PY}scenarios/seed000-sim.toml", f"{_PY}scenarios/seed000-car.toml",
                   f"{_PY}scenarios/seed000-heading.toml", f"{_PY}ins/align.py") + LOOSE_EKF + SIGMA + SIM + MC,
    "flops.md": ("bench/update_cost.sh", "bench/cpp/update_cost.cpp", f"{_CPP}filter/flops.hpp",
                 f"{_CPP}filter/rbukf.hpp", f"{_CPP}filter/ukf.hpp", f"{_CPP}filter/augmented_ut.hpp",
                 f"{_CPP}filter/kalman_update.hpp", f"{_CPP}filter/sigma_points.hpp"),
    "seed001.md": ("bench/seed001_tables.py", f"{_PY}scenarios/seed001-low.toml", f"{_PY}scenarios/seed001-high.toml",
                   f"{_CPP}engine/delay_engine.hpp", f"{_CPP}filter/random_delay_kf.hpp", f"{_PY}filters/delay.py",
                   "cpp/bindings/bind_delay.cpp") + LOOSE_EKF + SIM + MC,
    "seed003.md": ("bench/seed003_tables.py", f"{_PY}scenarios/seed003-4sat.toml", f"{_PY}scenarios/seed003-3sat.toml",
                   f"{_PY}scenarios/seed003-1sat.toml", f"{_PY}io/rinex_dataset.py", f"{_PY}gnss/spp.py")
                  + TIGHT + LOOSE_EKF + SIM_RAW + MC,
    "seed004.md": ("bench/seed004_tables.py", f"{_PY}scenarios/seed004-uav.toml") + PARTICLE + TIGHT + SIM_RAW + MC,
    "seed004_bench.md": ("bench/bench_upf.py", f"{_PY}scenarios/seed004-uav.toml") + PARTICLE + SIM_RAW,
    "kfgins.md": ("bench/kfgins_track.py",) + KFGINS + LOOSE_EKF + SIGMA + (f"{_PY}analysis/evaluate.py",),
    "vehicle_constraints.md": ("bench/vehicle_constraints.py", f"{_PY}filters/constraints.py",
                               f"{_PY}filters/smoothing.py", f"{_CPP}meas/vehicle.hpp",
                               f"{_CPP}filter/rts_smoother.hpp", f"{_PY}sim/odometer.py",
                               f"{_PY}scenarios/car-mems.toml", f"{_PY}scenarios/car-mems-outage30.toml",
                               f"{_PY}scenarios/car-mems-outage60.toml", f"{_PY}scenarios/car-mems-outage120.toml",
                               f"{_PY}analysis/report.py") + KFGINS + LOOSE_EKF + SIM,
    "cli_end_to_end.md": ("bench/cli_end_to_end.py", "bench/_kfgins.py", f"{_PY}cli/run.py", f"{_PY}data/textio.py",
                          f"{_PY}io/imu_csv.py", f"{_PY}io/gnss_files.py", f"{_PY}filters/health.py",
                          f"{_CPP}engine/solution_scan.hpp", "cpp/bindings/bind_checks.cpp",
                          f"{_PY}filters/stream.py", f"{_CPP}engine/loose_stream.hpp",
                          "cpp/bindings/bind_loose_stream.cpp", "cpp/bindings/bind_textio.cpp", f"{_CPP}io/text_table.hpp",
                          f"{_PY}_npz.py")
                         + KFGINS + LOOSE_EKF + SIGMA,
    "gnss_geometry.md": ("bench/gnss_residuals.py", f"{_PY}gnss/measurements.py", f"{_PY}gnss/glonass.py",
                         f"{_PY}gnss/gpstime.py", f"{_PY}gnss/sp3.py", f"{_PY}gnss/galbds.py") + RINEX,
    "spp_smartloc.md": ("bench/spp_smartloc.py", f"{_PY}filters/spp.py", f"{_PY}gnss/spp.py",
                        f"{_PY}gnss/weighting.py", f"{_PY}gnss/systems.py") + RINEX,
    "tight_realdata.md": ("bench/tight_realdata.py", "tests/data/walk_0827.toml", f"{_PY}gnss/measurements.py",
                          f"{_PY}io/imu_csv.py") + RINEX + TIGHT,
    "tight_multignss.md": ("bench/tight_multignss.py", f"{_PY}scenarios/urban-multignss.toml",
                           f"{_PY}gnss/measurements.py", f"{_PY}gnss/systems.py") + RINEX + TIGHT + SIM_RAW,
    "tdcp_walk.md": ("bench/tdcp_walk.py", "tests/data/walk_0827.toml", f"{_CPP}meas/tdcp.hpp", f"{_PY}gnss/tdcp.py",
                     f"{_PY}gnss/measurements.py", f"{_PY}io/imu_csv.py", f"{_PY}analysis/paired.py",
                     f"{_PY}io/gnss_files.py", f"{_PY}sim/gnss_rtk.py", f"{_PY}gnss/rinex_write.py",
                     f"{_PY}scenarios/rtk-open-sky-car.toml") + RINEX + TIGHT + SIM_RAW,
    "selfcal_states.md": ("bench/selfcal_states.py", "bench/walk_loose.py", "tests/data/walk_0827_loose.toml",
                          f"{_PY}io/csv_dataset.py", f"{_PY}io/imu_csv.py", f"{_PY}scenarios/car-mems.toml",
                          f"{_PY}scenarios/seed000-car.toml", f"{_PY}filters/solution.py",
                          "cpp/bindings/bind_loose_selfcal.cpp", "cpp/bindings/bind_tight_selfcal.cpp",
                          f"{_CPP}meas/vehicle.hpp", f"{_PY}filters/constraints.py", f"{_PY}filters/__init__.py",
                          "bench/walk_reference_check.py", f"{_PY}gnss/spp.py", "tests/data/walk_0827.toml")
                         + RINEX + LOOSE_EKF + TIGHT + SIM_RAW,
    "walk_loose.md": ("bench/walk_loose.py", "tests/data/walk_0827_loose.toml", f"{_PY}io/csv_dataset.py",
                      f"{_PY}io/imu_csv.py") + RINEX + LOOSE_EKF,
    "gate_outages.md": ("bench/gate_outages.py", f"{_PY}filters/health.py", f"{_PY}filters/smoothing.py",
                        f"{_PY}filters/constraints.py", f"{_CPP}filter/rts_smoother.hpp", f"{_CPP}meas/vehicle.hpp",
                        "tests/data/walk_0827.toml", "tests/data/walk_0827_loose.toml", f"{_PY}io/csv_dataset.py",
                        f"{_PY}io/imu_csv.py", f"{_PY}scenarios/car-mems.toml")
                       + KFGINS + LOOSE_EKF + TIGHT + RINEX + SIM + SIM_RAW,
    "gnss_speed.md": ("bench/gnss_speed.py", f"{_PY}filters/spp.py", f"{_PY}gnss/spp.py", f"{_PY}gnss/weighting.py",
                      f"{_CPP}gnss/spp_solver.hpp", f"{_CPP}gnss/broadcast_orbit.hpp", "cpp/bindings/bind_spp.cpp",
                      "tests/data/walk_0827.toml", "tests/data/walk_0827_loose.toml", f"{_PY}io/csv_dataset.py",
                      f"{_PY}io/imu_csv.py") + RINEX + TIGHT + LOOSE_EKF,
    "navigator.md": ("bench/navigator_latency.py", "cpp/examples/loose_realtime.cpp", f"{_CPP}engine/navigator.hpp",
                     f"{_PY}filters/navigator.py", "cpp/bindings/bind_navigator.cpp") + LOOSE_EKF,
    "rtk_sim.md": ("bench/rtk_sim_rtklib.py", f"{_PY}sim/gnss_rtk.py", f"{_PY}gnss/rinex_write.py",
                   f"{_PY}scenarios/rtk-open-sky-car.toml", f"{_PY}scenarios/rtk-urban-car.toml") + RTK + SIM_RAW,
    "rtk_euref_wettzell_wtzr_wtzz.md": ("bench/rtk_compare.py",) + RTK,
    "rtk_matrtklib_static_septentrio.md": ("bench/rtk_compare.py",) + RTK,
    "rtk_instinct_spirent_rtk_dynamic_SIMULATED.md": ("bench/rtk_compare.py",) + RTK,
    "rtk_ins.md": ("bench/rtk_ins.py", "bench/rtk_compare.py", "bench/rtk/spirent_dynamic_l1l2_ge_cont.conf",
                   f"{_CPP}engine/rtk_ins_engine.hpp", f"{_CPP}meas/dd_phase.hpp",
                   f"{_CPP}gnss/ambiguity_resolution.hpp", f"{_CPP}engine/closed_loop.hpp", f"{_CPP}filter/ekf.hpp",
                   "cpp/bindings/bind_rtk_ins.cpp", f"{_PY}filters/rtk_ins.py", f"{_PY}sim/from_truth.py",
                   f"{_PY}sim/gnss_rtk.py", f"{_PY}scenarios/rtk-urban-car.toml") + RTK + TIGHT + SIM + SIM_RAW,
    "rtk_urban_feasibility.md": ("bench/rtk_urban_feasibility.py", f"{_PY}gnss/ar_success.py", f"{_PY}sim/gnss_rtk.py",
                                 f"{_PY}gnss/rinex_write.py", f"{_PY}scenarios/rtk-urban-car.toml",
                                 f"{_PY}scenarios/urban-multignss.toml") + RTK + SIM_RAW,
    "rtk_ins_screening.md": ("bench/rtk_ins_screening.py", "bench/rtk_ins.py", "bench/rtk_compare.py",
                             f"{_CPP}engine/rtk_ins_engine.hpp", f"{_CPP}meas/dd_phase.hpp", f"{_CPP}meas/robust.hpp",
                             f"{_CPP}gnss/ambiguity_resolution.hpp", f"{_CPP}gnss/double_difference.hpp",
                             "cpp/bindings/bind_rtk_ins.cpp", f"{_PY}filters/rtk_ins.py", f"{_PY}sim/from_truth.py",
                             f"{_PY}sim/gnss_rtk.py", f"{_PY}scenarios/rtk-urban-car.toml") + RTK + TIGHT + SIM + SIM_RAW,
    "allan.md": ("bench/allan_check.py", f"{_CPP}calib/allan.hpp", "cpp/bindings/bind_calib.cpp",
                 f"{_PY}calib/allan.py", f"{_PY}data/imu_grades.py"),
    "run_all.md": ("bench/run_all.py",),
    "simulate_day.md": ("bench/simulate_day.py", f"{_PY}sim/__init__.py", f"{_PY}sim/cli.py",
                        f"{_PY}data/dataset.py", "cpp/bindings/bind_textio.cpp") + SIM,
    "tune.md": ("bench/tune_check.py", "bench/walk_reference_check.py", f"{_PY}gnss/spp.py",
                f"{_PY}calib/tune.py", f"{_PY}filters/tight.py", f"{_PY}filters/solution.py",
                f"{_PY}scenarios/seed000-car.toml", "tests/data/walk_0827.toml", "tests/data/walk_0827_loose.toml",
                f"{_PY}io/csv_dataset.py", f"{_PY}io/imu_csv.py", f"{_PY}analysis/evaluate.py")
               + KFGINS + LOOSE_EKF + TIGHT + RINEX + SIM,
}

#: hand-written measurement logs live in docs/logs/ (not checked here): docs/results/ holds
#: only documents written by their generators
HAND_WRITTEN = frozenset()

STAMP_HEADER = "## Stamp"
_STAMP_RE = re.compile(r"^Generated at commit `(?P<commit>[0-9a-f]{7,40})`(?P<dirty>[^\n]*)\.\s*$", re.M)
_FILES_RE = re.compile(r"^Its numbers depend on: (?P<files>.*)$", re.M)


def _git(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True)


def depends(doc: str) -> tuple[str, ...]:
    """The dependency list of a document (a KeyError names the known ones)."""
    try:
        return tuple(dict.fromkeys(DEPENDS[doc]))
    except KeyError:
        raise KeyError(f"no dependency list for {doc!r} in bench/_stamps.py; known: {', '.join(sorted(DEPENDS))}") \
            from None


def stamp(doc: str) -> str:
    """The stamp block appended to ``doc``: HEAD's full hash and the dependency
    list; the files among them with uncommitted changes are named (the test
    then fails: regenerate after committing)."""
    files = depends(doc)
    head = _git("rev-parse", "HEAD").stdout.strip() or "unknown"
    dirty = sorted(line[3:] for line in _git("status", "--porcelain", "--", *files).stdout.splitlines())
    note = f" with uncommitted changes to {', '.join(f'`{f}`' for f in dirty)}" if dirty else ""
    return (f"\n\n{STAMP_HEADER}\n\n"
            f"Generated at commit `{head}`{note}.\n"
            f"Its numbers depend on: {', '.join(f'`{f}`' for f in files)}\n\n"
            "(written by the generator; `tests/test_results_stamps.py` fails when one of these files changed "
            "after that commit and the document was not regenerated)\n")


def with_stamp(text: str, out) -> str:
    """``text`` with the stamp of the document it is written to (by file name;
    a name without a dependency list, e.g. a scratch output, gets none)."""
    doc = Path(out).name
    return text.rstrip("\n") + stamp(doc) if doc in DEPENDS else text


def read_stamp(text: str) -> tuple[str, bool, tuple[str, ...]] | None:
    """(commit, generated with uncommitted dependencies, files) of a document's stamp, or None."""
    i = text.rfind(STAMP_HEADER)
    if i < 0:
        return None
    m, f = _STAMP_RE.search(text, i), _FILES_RE.search(text, i)
    if not m or not f:
        return None
    files = tuple(re.findall(r"`([^`]+)`", f.group("files")))
    return m.group("commit"), bool(m.group("dirty").strip()), files


@functools.lru_cache(maxsize=None)
def _changed_since(commit: str) -> frozenset:
    """Files that differ between ``commit`` and the working tree (one git call per commit)."""
    return frozenset(_git("diff", "--name-only", commit).stdout.split())


@functools.lru_cache(maxsize=1)
def history_problem() -> str | None:
    """Why the stamps cannot be checked here (no git, not a repository, a shallow clone), or None."""
    r = _git("rev-parse", "--is-shallow-repository")
    if r.returncode != 0:
        return f"no git history at {ROOT} ({(r.stderr or 'git not available').strip().splitlines()[0]})"
    if r.stdout.strip() == "true":
        return "shallow clone: the stamped commits are not in the history (clone with full history)"
    return None


def check(doc: str) -> str | None:
    """None when ``doc`` is fresh, else one line saying why it is stale."""
    path = RESULTS / doc
    st = read_stamp(path.read_text(encoding="utf-8"))
    if st is None:
        return f"{doc}: no stamp (regenerate it with its script in bench/)"
    commit, dirty, files = st
    if dirty:
        return (f"{doc}: generated at {commit[:10]} with uncommitted changes to its dependencies; "
                "commit, then regenerate")
    if _git("cat-file", "-e", f"{commit}^{{commit}}").returncode != 0:
        return f"{doc}: stamped commit {commit[:10]} is not in this repository's history; regenerate"
    want = tuple(dict.fromkeys(files + DEPENDS.get(doc, ())))
    missing = [f for f in want if not (ROOT / f).exists()
               and _git("cat-file", "-e", f"{commit}:{f}").returncode != 0]
    if missing:
        return f"{doc}: dependency file(s) {', '.join(missing)} exist neither now nor at {commit[:10]}"
    changed = [f for f in want if f in _changed_since(commit)]
    if changed:
        return (f"{doc}: stale, generated at {commit[:10]} but {', '.join(changed)} changed since; "
                f"regenerate it with its script in bench/")
    return None


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) == 2 and argv[0] == "stamp":
        sys.stdout.write(stamp(argv[1]))
        return 0
    if argv == ["check"]:
        why = history_problem()
        if why:
            print(f"skipped: {why}")
            return 0
        bad = [m for m in (check(p.name) for p in sorted(RESULTS.glob("*.md"))) if m]
        print("\n".join(bad) if bad else "all results documents are fresh")
        return 1 if bad else 0
    print(__doc__)
    return 2


if __name__ == "__main__":
    sys.exit(main())
