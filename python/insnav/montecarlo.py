"""Monte Carlo comparison of filters on a simulated scenario.

:func:`montecarlo` simulates ``runs`` independent realisations of a scenario
(IMU and GNSS noise, GNSS delays, initial error) and runs every requested
filter on the same data; ``insnav compare SCENARIO --filters kf,rdkf,exact
--runs 100`` is the command line.

Seeds: ``numpy.random.SeedSequence(seed).spawn(runs)`` gives run ``i`` its own
child; the simulation seed and the initial-error seed are drawn from it, so
every run's numbers are the same whatever the number of workers or the
backend.

Backends: a backend maps ``run_one`` over the task list and yields
``(index, result)`` pairs; ``"local"`` uses a ``ProcessPoolExecutor``
(everything sent to workers is a picklable top-level object, so it also works
with the ``spawn`` start method).  Another backend (e.g. Dask) is added with
:func:`register_backend` without touching the rest.

Metrics per run and filter (from the IMU-rate real-time output, after the
first ``skip_s`` seconds): RMSE over time of the north/east position
[m] and velocity [m/s] errors, and their maxima.  The summary gives, per
filter and metric, the mean over runs (the paper's "average RMSE"), the
standard deviation over runs and the pooled RMSE
sqrt(mean over runs of RMSE^2).
"""
from __future__ import annotations

import dataclasses
import json
import os
import sys
import time
from dataclasses import dataclass, field

import numpy as np

METRICS = ("pos_n_rmse_m", "pos_e_rmse_m", "vel_n_rmse_mps", "vel_e_rmse_mps",
           "pos_n_max_m", "pos_e_max_m", "vel_n_max_mps", "vel_e_max_mps")
TABLE_METRICS = METRICS[:4]


@dataclass(frozen=True)
class Task:
    """One Monte Carlo run (picklable)."""

    index: int
    scenario: object          # preset name, path or dict (anything insnav.simulate takes)
    filters: tuple
    sim_seed: int
    init_seed: int
    skip_s: float
    run_kwargs: tuple = ()    # ((key, value), ...) passed to insnav.run for every filter


def run_seeds(seed: int, runs: int) -> list[tuple[int, int]]:
    """(simulation seed, initial-error seed) of each run: deterministic in (seed, i)."""
    out = []
    for child in np.random.SeedSequence(seed).spawn(runs):
        s = child.generate_state(2, dtype=np.uint32)
        out.append((int(s[0]), int(s[1])))
    return out


def _metrics(sol, truth, skip_s: float) -> dict:
    from .analysis import errors

    e = errors(sol, truth)
    keep = e["t"] >= e["t"][0] + skip_s
    pos, vel = e["pos_n_m"][keep], e["vel_n_mps"][keep]
    rms = lambda x: float(np.sqrt(np.mean(np.square(x))))  # noqa: E731
    return dict(pos_n_rmse_m=rms(pos[:, 0]), pos_e_rmse_m=rms(pos[:, 1]), vel_n_rmse_mps=rms(vel[:, 0]),
                vel_e_rmse_mps=rms(vel[:, 1]), pos_n_max_m=float(np.max(np.abs(pos[:, 0]))),
                pos_e_max_m=float(np.max(np.abs(pos[:, 1]))), vel_n_max_mps=float(np.max(np.abs(vel[:, 0]))),
                vel_e_max_mps=float(np.max(np.abs(vel[:, 1]))))


def run_one(task: Task) -> dict:
    """Simulate one realisation and run every filter on it (top level: picklable)."""
    import warnings

    from .engine import run
    from .sim import simulate

    t0 = time.perf_counter()
    ds = simulate(task.scenario, seed=task.sim_seed)
    kw = dict(task.run_kwargs)
    res = {}
    for f in task.filters:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # refusals are in the summary
            sol = run(ds, f, init_seed=task.init_seed, **kw)
        m = _metrics(sol, ds.truth, task.skip_s)
        m["updates"] = int(sol.summary.get("updates", 0))
        m["refused_too_old"] = int(sol.summary.get("refused_too_old", 0))
        res[f] = m
    return dict(index=task.index, sim_seed=task.sim_seed, init_seed=task.init_seed, metrics=res,
                seconds=time.perf_counter() - t0)


# --- backends ----------------------------------------------------------------
def _map_serial(fn, tasks, workers):
    for t in tasks:
        yield t.index, fn(t)


def _map_local(fn, tasks, workers):
    """Local processes (ProcessPoolExecutor); results as they complete."""
    if workers == 1 or len(tasks) <= 1:
        yield from _map_serial(fn, tasks, workers)
        return
    from concurrent.futures import ProcessPoolExecutor, as_completed

    with ProcessPoolExecutor(max_workers=workers) as ex:
        futs = {ex.submit(fn, t): t.index for t in tasks}
        for f in as_completed(futs):
            yield futs[f], f.result()


_BACKENDS = {"local": _map_local, "serial": _map_serial}


def register_backend(name: str, mapper) -> None:
    """Add a backend: ``mapper(run_one, tasks, workers)`` yields ``(task.index, result)``
    for every task (any order).  For example a Dask backend submits
    ``run_one`` for each task to a ``distributed.Client`` and yields from
    ``as_completed``."""
    _BACKENDS[name] = mapper


def default_workers() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover
        return max(1, os.cpu_count() or 1)


class _Progress:
    """tqdm when installed, else a one-line bar; only on a terminal."""

    def __init__(self, total: int, enabled: bool | None, desc: str):
        self.enabled = sys.stderr.isatty() if enabled is None else enabled
        self.total, self.n, self.desc, self.bar = total, 0, desc, None
        if self.enabled:
            try:
                from tqdm import tqdm

                self.bar = tqdm(total=total, desc=desc, file=sys.stderr, leave=False)
            except ImportError:
                self.bar = None

    def update(self):
        self.n += 1
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.update(1)
        else:
            w = 30
            k = int(w * self.n / max(self.total, 1))
            sys.stderr.write(f"\r{self.desc} [{'#' * k}{'.' * (w - k)}] {self.n}/{self.total}")
            sys.stderr.flush()

    def close(self):
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.close()
        else:
            sys.stderr.write("\n")


# --- results -----------------------------------------------------------------
@dataclass
class MonteCarloResult:
    """Per-run metrics and their summary.

    Attributes
    ----------
    per_run : list of dict
        ``{"index", "sim_seed", "init_seed", "metrics": {filter: {metric: value}}}`` in run order.
    summary : dict
        ``{filter: {metric: {"mean", "std", "rms"}}}``.
    """

    scenario: str
    filters: tuple
    runs: int
    seed: int
    per_run: list
    summary: dict = field(default_factory=dict)
    elapsed_s: float = 0.0
    workers: int = 1
    backend: str = "local"

    def values(self, filt: str, metric: str) -> np.ndarray:
        """The metric over runs for one filter."""
        return np.array([r["metrics"][filt][metric] for r in self.per_run])

    def table(self, metrics=TABLE_METRICS) -> str:
        """A Markdown table: mean over runs (std) per filter."""
        head = "| filter | " + " | ".join(metrics) + " |"
        lines = [head, "|" + "---|" * (len(metrics) + 1)]
        for f in self.filters:
            cells = [f"{self.summary[f][m]['mean']:.4g} ({self.summary[f][m]['std']:.2g})" for m in metrics]
            lines.append(f"| {f} | " + " | ".join(cells) + " |")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def to_json(self, **kw) -> str:
        return json.dumps(self.to_dict(), **kw)


def _summarise(per_run, filters) -> dict:
    out = {}
    for f in filters:
        out[f] = {}
        for m in METRICS:
            v = np.array([r["metrics"][f][m] for r in per_run])
            out[f][m] = dict(mean=float(v.mean()), std=float(v.std(ddof=1)) if v.size > 1 else 0.0,
                             rms=float(np.sqrt(np.mean(v ** 2))))
        out[f]["refused_too_old"] = int(sum(r["metrics"][f]["refused_too_old"] for r in per_run))
    return out


def montecarlo(scenario, filters=("kf", "rdkf", "exact"), runs: int = 100, seed: int = 0, workers: int | None = None,
               backend: str = "local", *, skip_s: float = 5.0, progress: bool | None = None,
               **run_kwargs) -> MonteCarloResult:
    """Run ``runs`` Monte Carlo realisations of ``scenario`` through ``filters``.

    Parameters
    ----------
    scenario : str, Path or dict
        Anything :func:`insnav.simulate` accepts (a preset such as ``"seed001-high"``).
    filters : sequence of str
        Names accepted by :func:`insnav.run` (``kf``, ``rdkf``, ``exact``, ``ekf``, ...).
    runs : int
    seed : int
        Master seed; run i uses ``SeedSequence(seed).spawn(runs)[i]``.
    workers : int, optional
        Local processes (default: the CPUs available); the results do not
        depend on it.
    backend : {'local', 'serial'} or a registered name
    skip_s : float
        Seconds at the start excluded from the metrics (initial convergence).
    progress : bool, optional
        Progress bar on stderr; default only when stderr is a terminal.
    **run_kwargs
        Passed to :func:`insnav.run` for every filter (e.g. ``delay_p=[...]``).

    Returns
    -------
    MonteCarloResult
    """
    if isinstance(filters, str):
        filters = tuple(f.strip() for f in filters.split(",") if f.strip())
    filters = tuple(filters)
    if not filters:
        raise ValueError("montecarlo: no filters given")
    if runs < 1:
        raise ValueError(f"montecarlo: runs must be >= 1, got {runs}")
    if backend not in _BACKENDS:
        raise ValueError(f"montecarlo: unknown backend {backend!r}; available: {', '.join(sorted(_BACKENDS))}")
    workers = default_workers() if workers is None else int(workers)
    tasks = [Task(i, scenario, filters, s, q, float(skip_s), tuple(sorted(run_kwargs.items())))
             for i, (s, q) in enumerate(run_seeds(seed, runs))]
    results = [None] * runs
    bar = _Progress(runs, progress, f"{scenario} x {','.join(filters)}")
    t0 = time.perf_counter()
    try:
        for i, r in _BACKENDS[backend](run_one, tasks, workers):
            results[i] = r
            bar.update()
    finally:
        bar.close()
    name = scenario if isinstance(scenario, str) else str(getattr(scenario, "name", scenario))
    return MonteCarloResult(scenario=str(name), filters=filters, runs=runs, seed=seed, per_run=results,
                            summary=_summarise(results, filters), elapsed_s=time.perf_counter() - t0,
                            workers=workers, backend=backend)


# --- command line --------------------------------------------------------------
def _compare_main(args) -> int:
    kw = {}
    if args.delay_p:
        kw["delay_p"] = [float(x) for x in args.delay_p.split(",")]
    res = montecarlo(args.scenario, args.filters, runs=args.runs, seed=args.seed, workers=args.workers,
                     backend=args.backend, skip_s=args.skip_s, **kw)
    if args.json:
        print(res.to_json(indent=None if args.compact else 2))
    else:
        print(f"{res.scenario}: {res.runs} Monte Carlo runs, seed {res.seed}, {res.workers} worker(s), "
              f"{res.elapsed_s:.1f} s; mean over runs (std) after the first {args.skip_s:g} s")
        print(res.table())
    return 0


def add_compare_parser(sub) -> None:
    """``insnav compare``: registered by :mod:`insnav.cli`."""
    import argparse

    p = sub.add_parser(
        "compare",
        help="Monte Carlo comparison of filters on a scenario",
        description="Simulate a scenario many times and compare filters (RMSE of N/E position and velocity).\n"
        "Example: insnav compare seed001-high --filters kf,rdkf,exact --runs 100",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("scenario", help="preset name or scenario TOML file")
    p.add_argument("--filters", default="kf,rdkf,exact", help="comma-separated (default: %(default)s)")
    p.add_argument("--runs", type=int, default=100, help="Monte Carlo runs (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="master seed (default: %(default)s)")
    p.add_argument("--workers", type=int, default=None, help="local processes (default: all CPUs)")
    p.add_argument("--backend", default="local", help="local (default) or a registered backend")
    p.add_argument("--skip-s", dest="skip_s", type=float, default=5.0,
                   help="seconds excluded at the start (default: %(default)s)")
    p.add_argument("--delay-p", dest="delay_p", default=None,
                   help="rdkf delay probabilities, e.g. 0.7,0.3 (default: the scenario's)")
    p.add_argument("--json", action="store_true", help="print JSON (per-run metrics and summary)")
    p.add_argument("--compact", action="store_true", help="with --json: one line")
    p.set_defaults(func=_compare_main)
