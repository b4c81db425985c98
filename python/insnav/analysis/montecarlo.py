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
with the ``spawn`` start method), ``"serial"`` runs in this process and
``"dask"`` submits every run to a Dask distributed cluster.  Another backend
is added with :func:`register_backend` without touching the rest.

Why Dask distributed (and not Ray) for the distributed backend: it is pure
Python and pip-installable (``pip install insnav[dask]``) with no daemon or
compiled runtime to match across machines; ``LocalCluster`` gives real
scheduler and worker processes on one machine, so the test suite runs the
same code path as a cluster; the same futures API (``Client.map``,
``as_completed``) drives a laptop, an existing ``dask-scheduler`` or an HPC
batch system through dask-jobqueue (``SLURMCluster``, ``PBSCluster``, ...),
and it is already present in most scientific Python stacks.  Ray would work
too, but it ships a compiled runtime (raylet, GCS server) as platform-specific
wheels, needs hand-written launch scripts under SLURM/PBS, and its actors and
object store bring nothing to what a Monte Carlo campaign is: independent,
coarse tasks (a few hundred ms to minutes each) with small results, exactly
the case Dask futures handle without extra machinery.

``backend="dask"``: ``scheduler`` is the scheduler address
(``"tcp://host:8786"``), a ``distributed.Client`` or a cluster object with a
``scheduler_address`` (e.g. a dask-jobqueue cluster).  Without it, Dask's own
``scheduler-address`` setting (environment ``DASK_SCHEDULER_ADDRESS``) is
used when set; otherwise a ``LocalCluster`` of ``workers`` single-threaded
processes is started for the campaign and closed afterwards, so
``backend="dask"`` alone behaves like ``"local"`` (same numbers).  The
workers need the same insnav version installed (checked before submitting);
a scenario TOML file is read here and sent as a dictionary, so it need not
exist on the workers.  Dask is imported only when this backend is used.

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

from ..errors import seed_arg

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
    from .metrics import errors

    e = errors(sol, truth)
    keep = e["t"] >= e["t"][0] + skip_s
    if not keep.any():
        raise ValueError(f"montecarlo: skip_s (--skip-s) {skip_s:g} s leaves no solution row to compare (the "
                         f"rows span {e['t'][-1] - e['t'][0]:g} s)")
    pos, vel = e["pos_n_m"][keep], e["vel_n_mps"][keep]
    rms = lambda x: float(np.sqrt(np.mean(np.square(x))))  # noqa: E731
    return dict(pos_n_rmse_m=rms(pos[:, 0]), pos_e_rmse_m=rms(pos[:, 1]), vel_n_rmse_mps=rms(vel[:, 0]),
                vel_e_rmse_mps=rms(vel[:, 1]), pos_n_max_m=float(np.max(np.abs(pos[:, 0]))),
                pos_e_max_m=float(np.max(np.abs(pos[:, 1]))), vel_n_max_mps=float(np.max(np.abs(vel[:, 0]))),
                vel_e_max_mps=float(np.max(np.abs(vel[:, 1]))))


def run_one(task: Task) -> dict:
    """Simulate one realisation and run every filter on it (top level: picklable)."""
    import warnings

    from ..filters import run
    from ..sim import simulate

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
        if m["updates"] == 0:  # insnav run refuses a free-inertial run; a comparison of them compares nothing
            raise ValueError(f"montecarlo: filter {f!r} used no GNSS update in run {task.index} (seed "
                             f"{task.sim_seed}): the scenario gives it no usable GNSS ([gnss] / [gnss_raw] "
                             "enabled, the coupling's measurements)")
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

    ex = ProcessPoolExecutor(max_workers=workers)
    try:
        futs = {ex.submit(fn, t): t.index for t in tasks}
        for f in as_completed(futs):
            yield futs[f], f.result()
    finally:  # a failed run (or a closed generator) cancels the queued ones instead of waiting for them
        ex.shutdown(wait=True, cancel_futures=True)


class BackendError(RuntimeError):
    """A backend cannot run the campaign (scheduler unreachable, workers without insnav, ...)."""


class MissingExtraError(ImportError):
    """An optional dependency of the requested backend is not installed."""


def _import_distributed():
    try:
        import distributed
    except ImportError as exc:
        raise MissingExtraError("backend 'dask' needs Dask distributed, which is not installed: "
                                "pip install 'insnav[dask]'") from exc
    return distributed


def _insnav_version() -> str:
    """Run on each Dask worker: the insnav version it imports."""
    from .. import __version__

    return __version__


def _check_reachable(address: str) -> None:
    """Fail fast, with the address in the message, on a malformed address or
    when nothing listens there (a ``Client`` would wait, then warn at exit)."""
    import socket

    import dask
    from dask.utils import parse_timedelta
    from distributed.comm import get_address_host_port, parse_address

    try:
        scheme, _ = parse_address(address)
    except ValueError as exc:
        raise BackendError(f"bad Dask scheduler address {address!r}: {exc}") from None
    if scheme not in ("tcp", "tls"):
        return  # other transports (ucx, inproc, ws) are left to distributed
    try:
        host, port = get_address_host_port(address)
    except ValueError as exc:
        raise BackendError(f"bad Dask scheduler address {address!r}: {exc}; expected tcp://HOST:PORT") from None
    timeout = parse_timedelta(dask.config.get("distributed.comm.timeouts.connect"), default="seconds")
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except OSError as exc:
        raise BackendError(f"no Dask scheduler answers at {address} ({exc}); start one with "
                           "'dask scheduler' or give the right --scheduler") from None


def _map_dask(fn, tasks, workers, scheduler=None, *, info=None):
    """Dask distributed: one future per run, results as they complete.

    ``scheduler``: address, ``distributed.Client``, an object with a
    ``scheduler_address`` (a cluster), or None (``DASK_SCHEDULER_ADDRESS``,
    else a ``LocalCluster`` of ``workers`` processes, closed at the end).
    ``info`` (a dict) receives the scheduler address and the worker count.
    """
    distributed = _import_distributed()
    import uuid

    import dask

    from .. import __version__

    cluster = client = None
    own_client = True
    if scheduler is None:
        scheduler = dask.config.get("scheduler-address", None)
    try:
        if isinstance(scheduler, distributed.Client):
            client, own_client = scheduler, False
        else:
            if scheduler is None:
                cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                                   dashboard_address="127.0.0.1:0")
                address = cluster.scheduler_address
            else:
                address = str(getattr(scheduler, "scheduler_address", scheduler))
                _check_reachable(address)
            try:
                client = distributed.Client(address, set_as_default=False)
            except (OSError, ValueError) as exc:
                raise BackendError(f"cannot connect to the Dask scheduler at {address}: {exc}") from None
        try:
            versions = client.run(_insnav_version)
        except Exception as exc:  # the workers cannot even import insnav
            raise BackendError(f"the Dask workers at {client.scheduler.address} cannot run insnav "
                               f"({type(exc).__name__}: {exc}); install insnav {__version__} on them") from None
        wrong = {w: v for w, v in versions.items() if v != __version__}
        if wrong:
            raise BackendError(f"Dask workers run another insnav version than this one ({__version__}): "
                               + ", ".join(f"{w}: {v}" for w, v in sorted(wrong.items())))
        if info is not None:
            info.update(scheduler=str(client.scheduler.address), workers=len(client.nthreads()))
        token = uuid.uuid4().hex[:8]
        keys = [f"insnav-run-{token}-{t.index}" for t in tasks]
        futures = client.map(fn, tasks, key=keys, pure=False)
        index = {k: t.index for k, t in zip(keys, tasks)}
        try:
            for fut, res in distributed.as_completed(futures, with_results=True, loop=client.loop):
                yield index[fut.key], res
        finally:
            client.cancel(futures)  # no-op once all are done; stops the rest on an error or Ctrl-C
    finally:
        if client is not None and own_client:
            client.close()
        if cluster is not None:
            cluster.close()


_BACKENDS = {"local": _map_local, "serial": _map_serial, "dask": _map_dask}


def register_backend(name: str, mapper) -> None:
    """Add a backend: ``mapper(run_one, tasks, workers)`` yields ``(task.index, result)``
    for every task (any order).  A mapper that also takes a ``scheduler``
    keyword receives :func:`montecarlo`'s ``scheduler`` argument when one is
    given (see the built-in ``"dask"`` backend, :func:`_map_dask`)."""
    _BACKENDS[name] = mapper


def _takes_scheduler(mapper) -> bool:
    import inspect

    try:
        params = inspect.signature(mapper).parameters
    except (TypeError, ValueError):  # pragma: no cover (builtins)
        return False
    return "scheduler" in params or any(p.kind is p.VAR_KEYWORD for p in params.values())


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
    scheduler: str = ""       # Dask scheduler address for backend "dask", else ""

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
        from .._atomic import json_safe
        return json.dumps(json_safe(self.to_dict()), **{"allow_nan": False, **kw})


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
               backend: str = "local", *, scheduler=None, skip_s: float = 5.0, progress: bool | None = None,
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
        Local processes, or the size of the ``LocalCluster`` that
        ``backend="dask"`` starts without a scheduler (default: the CPUs
        available); ignored with a scheduler.  The results do not depend on it.
    backend : {'local', 'serial', 'dask'} or a registered name
        ``'dask'`` needs ``pip install insnav[dask]``; see the module docstring.
    scheduler : str, distributed.Client or cluster, optional
        Where ``backend="dask"`` runs: ``"tcp://host:8786"``, a client, or a
        cluster with a ``scheduler_address``.  None: ``DASK_SCHEDULER_ADDRESS``
        if set, else a ``LocalCluster`` of ``workers`` processes for this call.
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
    from ..registry import FILTERS, filter_spec

    for f in filters:
        spec = filter_spec(f)  # a ValueError naming the known filters
        if "gnss" in spec.couplings and len(spec.couplings) == 1:
            raise ValueError(f"montecarlo: filter {f!r} is GNSS only (it reads RINEX files: insnav run --filter "
                             f"{f} --format rinex); the campaign runs the INS filters: "
                             f"{', '.join(n for n, s_ in FILTERS.items() if s_.couplings != ('gnss',))}")
    if isinstance(runs, bool) or not isinstance(runs, (int, np.integer)) or runs < 1:
        raise ValueError(f"montecarlo: runs must be a whole number >= 1, got {runs!r}")
    reserved = sorted(k for k in run_kwargs if k in ("init_seed", "filter"))
    if reserved:
        raise ValueError(f"montecarlo: option {reserved[0]!r} is set per run by the campaign (init_seed from the "
                         "master seed, the filters from `filters`); leave it out")
    if backend not in _BACKENDS:
        raise ValueError(f"montecarlo: unknown backend {backend!r}; available: {', '.join(sorted(_BACKENDS))}")
    mapper = _BACKENDS[backend]
    options = {}
    if scheduler is not None:
        if not _takes_scheduler(mapper):
            raise ValueError(f"montecarlo: backend {backend!r} takes no scheduler (use backend='dask')")
        options["scheduler"] = scheduler
    if mapper is _map_dask:
        options["info"] = {}  # filled with the scheduler address and worker count
    workers = default_workers() if workers is None else int(workers)
    if workers < 1:
        raise ValueError(f"montecarlo: workers must be >= 1, got {workers}")
    from ..sim.scenario import load_scenario, resolve_raw

    sc = load_scenario(scenario)  # a bad scenario fails here, once, not in every worker
    if isinstance(skip_s, bool) or not (isinstance(skip_s, (int, float)) and 0.0 <= skip_s < sc.duration):
        raise ValueError(f"montecarlo: skip_s (--skip-s) {skip_s!r}; allowed: 0 <= skip_s < the scenario's "
                         f"{sc.duration:g} s (the errors are taken after it)")
    sent = scenario
    if backend == "dask" and isinstance(scenario, (str, os.PathLike)) and (
            str(scenario).endswith(".toml") or os.path.isfile(scenario)):
        sent, _ = resolve_raw(scenario)  # the file need not exist on the workers
    tasks = [Task(i, sent, filters, s, q, float(skip_s), tuple(sorted(run_kwargs.items())))
             for i, (s, q) in enumerate(run_seeds(seed, runs))]
    results = [None] * runs
    name = scenario if isinstance(scenario, str) else str(getattr(sc, "name", None) or getattr(scenario, "name", scenario))
    bar = _Progress(runs, progress, f"{name} x {','.join(filters)}")
    t0 = time.perf_counter()
    stream = mapper(run_one, tasks, workers, **options)
    try:
        for i, r in stream:
            results[i] = r
            bar.update()
    finally:
        bar.close()
        if hasattr(stream, "close"):
            stream.close()  # a generator backend releases its pool / cluster now, even on an error
    if any(r is None for r in results):
        missing = [i for i, r in enumerate(results) if r is None]
        raise BackendError(f"montecarlo: backend {backend!r} returned no result for runs {missing[:10]}")
    info = options.get("info", {})
    return MonteCarloResult(scenario=str(name), filters=filters, runs=runs, seed=seed, per_run=results,
                            summary=_summarise(results, filters), elapsed_s=time.perf_counter() - t0,
                            workers=int(info.get("workers", workers)), backend=backend,
                            scheduler=str(info.get("scheduler", "")))


# --- command line --------------------------------------------------------------
def _compare_main(args) -> int:
    from ..errors import UserError

    backend = args.backend or ("dask" if args.scheduler else "local")
    if args.scheduler and backend != "dask":
        raise UserError(f"--scheduler needs --backend dask (got --backend {backend})")
    kw = {}
    if args.delay_p:
        try:
            kw["delay_p"] = [float(x) for x in args.delay_p.split(",")]
        except ValueError:
            raise UserError(f"--delay-p: expected comma-separated probabilities, got {args.delay_p!r}") from None
    try:
        res = montecarlo(args.scenario, args.filters, runs=args.runs, seed=args.seed, workers=args.workers,
                         backend=backend, scheduler=args.scheduler, skip_s=args.skip_s,
                         progress=False if getattr(args, "quiet", False) else None, **kw)
    except (BackendError, MissingExtraError) as exc:
        raise UserError(str(exc)) from None
    if args.json:
        print(res.to_json(indent=None if args.compact else 2))
    else:
        where = f"Dask scheduler {res.scheduler}" if res.scheduler else backend
        print(f"{res.scenario}: {res.runs} Monte Carlo runs, seed {res.seed}, {res.workers} worker(s) ({where}), "
              f"{res.elapsed_s:.1f} s; mean over runs (std) after the first {args.skip_s:g} s; "
              "position RMSE [m], velocity RMSE [m/s]")
        print(res.table())
    return 0


EXAMPLES = """examples:
  insnav compare seed001-high --filters kf,rdkf,exact --runs 100
  insnav compare my_scenario.toml --filters ekf,rbukf --runs 20 --json > mc.json
  insnav compare seed001-high --runs 1000 --backend dask --scheduler tcp://head-node:8786

Reported per filter: the mean over runs (and its standard deviation) of the RMSE over time
of the north/east position error [m] and velocity error [m/s], after the first --skip-s
seconds.  Run i always uses the seeds numpy.random.SeedSequence(SEED).spawn(RUNS)[i], so
the numbers do not depend on --workers or --backend.

--backend dask (pip install 'insnav[dask]') sends each run to a Dask distributed cluster:
--scheduler ADDRESS connects to a running scheduler (its workers need the same insnav
version); without it DASK_SCHEDULER_ADDRESS is used when set, otherwise a local cluster
of --workers processes is started for the campaign."""


def add_compare_parser(sub) -> None:
    """``insnav compare``: registered by :mod:`insnav.cli`."""
    import argparse

    p = sub.add_parser(
        "compare",
        help="Monte Carlo comparison of filters on a scenario",
        description="Simulate a scenario many times and compare filters (RMSE of the N/E position [m] "
        "and velocity [m/s]).",
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("scenario", help="preset name or scenario TOML file")
    from ..registry import FILTERS

    p.add_argument("--filters", default="kf,rdkf,exact",
                   help=f"comma-separated, from {', '.join(n for n, s in FILTERS.items() if s.couplings != ('gnss',))} "
                        "(default: %(default)s)")
    p.add_argument("--runs", type=int, default=100, help="Monte Carlo runs (default: %(default)s)")
    p.add_argument("--seed", type=seed_arg, default=0, help="master seed (default: %(default)s)")
    p.add_argument("--workers", type=int, default=None,
                   help="local processes, or the size of the local Dask cluster (default: all CPUs)")
    p.add_argument("--backend", default=None,
                   help=f"one of {', '.join(sorted(_BACKENDS))} (default: local; dask with --scheduler)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="Dask scheduler address, e.g. tcp://10.0.0.5:8786 (implies --backend dask)")
    p.add_argument("--skip-s", dest="skip_s", type=float, default=5.0,
                   help="time excluded at the start [s] (default: %(default)s)")
    p.add_argument("--delay-p", dest="delay_p", default=None,
                   help="rdkf delay probabilities, e.g. 0.7,0.3 (default: the scenario's)")
    p.add_argument("--json", action="store_true", help="print JSON (per-run metrics and summary)")
    p.add_argument("--compact", action="store_true", help="with --json: one line")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar (shown on a terminal only)")
    p.set_defaults(func=_compare_main)
