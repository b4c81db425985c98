"""``insnav tune``: noise scale factors by the innovation likelihood, written as a run TOML."""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from ..errors import UserError

EXAMPLES = """examples:
  insnav tune run3 --filter ekf --out tuned.toml                        # an `insnav simulate` folder
  insnav run run3 --config tuned.toml --out sol.csv                      # ... then run with it
  insnav tune --format kfgins --config kf-gins.yaml --out tuned.toml     # then: insnav run --format kfgins
                                                                         #   --config kf-gins.yaml --run-config tuned.toml
  insnav tune --format csv --imu imu.csv --gnss fixes.pos --config base.toml --out tuned.toml
  insnav tune --format rinex --obs F.obs --nav F.nav --imu IMU.csv --config base.toml --coupling tight \\
              --reference ref.pos --out tuned.toml

The noise settings of the base configuration (--config; the dataset's IMU model without one) are
multiplied by scale factors: gyro_arw, acc_vrw, gyro_bias, acc_bias (all axes of each), gnss_pos and
gnss_vel (the data's GNSS sigmas: loose position / velocity, tight pseudorange / rate), loose
gnss_pos_v (the vertical position sigma, on top of gnss_pos), with constraints, nhc, odo, zupt,
and for a tight EKF with Gauss-Markov pseudorange states (pr_gm_sigma_m > 0 in the base
configuration) pr_gm_sigma and pr_gm_tau.  The factors that maximise the innovation log-likelihood
sum_k -(nu_k' S_k^-1 nu_k + ln det S_k)/2 over the first 1 - HOLDOUT of the data are found by
Nelder-Mead in log space (docs/algorithms.md, "Noise tuning"), one C++ run per evaluation.

The table compares the base and the tuned settings on the held-out end of the data: mean NIS per
measurement row of the applied GNSS records (1 when consistent) and, with a reference
(--reference, or the simulator's truth), the horizontal RMS error and rms(error/sigma) per axis.  A
reference epoch that was also a GNSS fix of the run is left out; a .pos reference describes the
antenna, with its own sdn/sde/sdu sigmas: rows of rms(error / sqrt(sigma^2 + sigma_ref^2)) are added.
--out gets the base TOML with the tuned [imu] noise keys, gnss_pos_sigma_scale,
gnss_vel_sigma_scale (loose: gnss_pos_v_sigma_scale), filter, coupling (and the tuned [constraints] sigmas,
pr_gm_sigma_m, pr_gm_tau_s): `insnav run --config`
(`--run-config` with --format kfgins) runs with it."""


def add_tune_parser(sub) -> None:
    from ..calib.tune import PARAMETERS

    p = sub.add_parser("tune", help="tune the filter's noise scale factors by the innovation likelihood",
                       description="Estimate noise scale factors by maximising the innovation log-likelihood "
                       "(loose / tight EKF and RB-UKF) and write the tuned run TOML.", epilog=EXAMPLES,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dataset", nargs="?", help="dataset directory written by `insnav simulate` (insnav format)")
    p.add_argument("--format", choices=("insnav", "kfgins", "rinex", "csv"), default="insnav")
    p.add_argument("--filter", choices=("ekf", "rbukf"), default=None, help="default: the config's, else ekf")
    p.add_argument("--coupling", choices=("loose", "tight"), default=None, help="default: the config's, else loose")
    p.add_argument("--config", help="base insnav TOML (with --format kfgins: the KF-GINS YAML)")
    p.add_argument("--run-config", metavar="TOML", help="--format kfgins: base insnav TOML overriding the YAML's keys")
    p.add_argument("--imu", help="IMU file (--format kfgins, rinex, csv)")
    p.add_argument("--gnss", help="GNSS file (--format kfgins; --format csv: .csv, .pos or NMEA)")
    p.add_argument("--obs", help="RINEX observation file (--format rinex)")
    p.add_argument("--nav", help="RINEX navigation file (--format rinex)")
    p.add_argument("--imu-tag", help="RTKLIB str2str time tag of the IMU log")
    p.add_argument("--constraints", default=None, metavar="LIST", help="vehicle constraints nhc,odo,zupt (loose)")
    p.add_argument("--params", default=None, metavar="LIST",
                   help="factors to tune, comma-separated from " + ", ".join(PARAMETERS)
                   + " (default: the IMU four, gnss_pos, gnss_vel when the data have velocity, the constraints in use)")
    p.add_argument("--holdout", type=float, default=0.3,
                   help="share of the data at its end left out of the tuning and used for the report, in [0, 0.9) "
                        "(default %(default)s; 0: tune and report on all of it)")
    p.add_argument("--split", choices=("tail", "blocks"), default="tail",
                   help="tail: hold out the end of the data; blocks: interleaved blocks of --block-s seconds, the last "
                        "--holdout of each held out (the tuning runs go over all the data, the likelihood sums the "
                        "tuning blocks' records; for data whose segment kinds, e.g. walking and standing, are not "
                        "spread over the time span; default %(default)s)")
    p.add_argument("--block-s", type=float, default=None, help="block length of --split blocks [s] (default 20)")
    p.add_argument("--max-runs", type=int, default=80, help="filter runs the search may use (default %(default)s)")
    p.add_argument("--reference", metavar="FILE",
                   help="reference trajectory for the report: insnav truth.csv or folder, KF-GINS .nav, RTKLIB .pos "
                        "(default: the dataset's truth, if any)")
    p.add_argument("--out", required=True, help="the tuned run TOML to write")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out that insnav did not write")
    p.add_argument("--quiet", "-q", action="store_true", help="no line per filter run")
    p.set_defaults(func=cmd_tune)


def _load(args):
    """(dataset, RunConfig, base TOML dict) from the input options, as ``insnav run`` reads them."""
    import insnav
    from ..config import RunConfig, load_config

    def toml(path):
        from ..config import ConfigError, read_toml

        try:
            return read_toml(path) if path else {}
        except ConfigError as exc:
            raise UserError(str(exc)) from None

    if args.format != "insnav" and args.dataset:
        raise UserError(f"--format {args.format} reads the files given by options; do not give a dataset directory")
    if args.run_config and args.format != "kfgins":
        raise UserError("--run-config goes with --format kfgins (otherwise the insnav TOML is --config)")
    if args.format == "rinex":
        missing = [n for n in ("obs", "nav", "imu") if not getattr(args, n)]
        if missing:
            raise UserError("--format rinex needs " + ", ".join(f"--{n}" for n in missing))
        from ..io.rinex_dataset import load_rinex_run

        ds, cfg = load_rinex_run(args.obs, args.nav, args.imu, args.config, imu_tag=args.imu_tag)
        return ds, cfg, toml(args.config)
    if args.format == "csv":
        missing = [n for n in ("imu", "gnss", "config") if not getattr(args, n)]
        if missing:
            raise UserError("--format csv needs " + ", ".join(f"--{n}" for n in missing))
        from ..io.csv_dataset import load_csv_run

        ds, cfg = load_csv_run(args.imu, args.gnss, args.config, imu_tag=args.imu_tag)
        return ds, cfg, toml(args.config)
    if args.format == "kfgins":
        if not args.config:
            raise UserError("--format kfgins needs --config KF-GINS.yaml")
        from ..io.kfgins_dataset import load_kfgins

        ds, cfg = load_kfgins(args.config, args.imu, args.gnss)
        if args.run_config:
            from .run import _overlay_run_config

            cfg = _overlay_run_config(cfg, args.run_config)
        return ds, cfg, toml(args.run_config)
    if not args.dataset:
        raise UserError("give a dataset directory (or --format kfgins|rinex|csv with its files)")
    if not Path(args.dataset).is_dir():
        raise UserError(f"dataset directory not found: {args.dataset}")
    ds = insnav.load_dataset(args.dataset)
    cfg = load_config(args.config, dict(filter=args.filter, coupling=args.coupling)) if args.config else RunConfig()
    return ds, cfg, toml(args.config)


def _fmt(x, nd=3):
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{nd}f}"


def report_table(rep_base: dict, rep_tuned: dict, reference_model: bool = False) -> list[str]:
    """The before/after table (plain text) of two :func:`insnav.calib.tune.holdout_report` dicts;
    ``reference_model``: they were made with one (a ``.pos`` reference: the antenna, its own sigmas),
    whose rms(error / sqrt(sigma^2 + sigma_ref^2)) rows are added."""
    rows = [("held-out GNSS records applied", "records", 0), ("mean NIS per row (expect 1)", "nis_per_row", 3),
            ("ln L per record", "log_likelihood_per_record", 3), ("reference epochs", "epochs", 0),
            ("horizontal RMS error [m]", "hor_rms_m", 4), ("3-D RMS error [m]", "rms_3d_m", 4)]
    out = [f"{'':52s} {'base':>22s} {'tuned':>22s}"]
    for label, key, nd in rows:
        if key not in rep_base and key not in rep_tuned:
            continue
        out.append(f"{label:52s} {_fmt(rep_base.get(key), nd):>22s} {_fmt(rep_tuned.get(key), nd):>22s}")
    f = (lambda v: "-" if v is None else ", ".join(f"{x:.2f}" for x in v))
    a, b = rep_base.get("innovation_lag1"), rep_tuned.get("innovation_lag1")
    if a is not None or b is not None:
        out.append(f"{'innovation lag-1 autocorr. (0: white)':52s} {f(a):>22s} {f(b):>22s}")
    names = {"pos_n_m": "position N,E,D", "vel_n_mps": "velocity N,E,D", "att_deg": "attitude r,p,y"}
    for key, suffix in (("nees", ""), ("nees_demeaned", ", mean out"), ("nees_total", ", antenna, sigma_ref")):
        if key == "nees_total" and not reference_model:
            continue  # an exact reference of the IMU centre: the same figures as the first rows
        for k, label in names.items():
            a, b = rep_base.get(key, {}).get(k), rep_tuned.get(key, {}).get(k)
            if a is None and b is None:
                continue
            out.append(f"{'rms(err/sigma) ' + label + suffix:52s} {f(a):>22s} {f(b):>22s}")
    lag = rep_tuned.get("innovation_lag1")
    if lag is not None and math.isfinite(lag[0]) and lag[0] > 0.3:
        out.append(f"note: the tuned run's innovations are correlated from record to record (lag-1 {lag[0]:.2f}): "
                   "slowly varying measurement errors, which the tuned white-noise sigmas fit only record to "
                   "record; expect the filter to be overconfident on slower errors (docs/algorithms.md section 20)")
    return out


def cmd_tune(args) -> int:
    import dataclasses

    from .._atomic import atomic_write_text
    from .._outputs import check_outputs, input_files
    from .._toml import dumps_toml
    from ..calib.tune import holdout_report, split_time, tune, tuned_toml_dict
    from ..config import ConfigError
    from ..filters import run

    out = Path(args.out)
    if out.suffix.lower() != ".toml":
        raise UserError(f"--out {out}: the tuned configuration is a TOML file (e.g. tuned.toml)")
    if not (0.0 <= args.holdout < 0.9):
        raise UserError(f"--holdout {args.holdout:g}: expected a fraction of the data in [0, 0.9) (0: no hold-out)")
    if args.block_s is not None and args.split != "blocks":
        raise UserError(f"--block-s {args.block_s:g}: the block length of --split blocks; add --split blocks or "
                        "leave it out")
    if args.block_s is None:
        args.block_s = 20.0
    params = None if args.params is None else [p.strip() for p in args.params.split(",") if p.strip()]
    if params is not None and len(set(params)) < len(params):
        twice = next(p for p in params if params.count(p) > 1)
        raise UserError(f"--params {args.params}: {twice!r} given twice")
    ins = [args.dataset, args.config, args.run_config, args.imu, args.gnss, args.obs, args.nav, args.imu_tag,
           args.reference]
    check_outputs([out], input_files(*ins), overwrite=args.overwrite, command="tune")
    src = next((a for a in (args.dataset, args.config, args.obs, args.gnss) if a), "tune")  # named in its messages
    try:
        ds, cfg, base_d = _load(args)
        if args.constraints is not None:
            cfg.constraints.use = [c.strip() for c in args.constraints.split(",") if c.strip()]
        split_time(ds, args.holdout)  # a bad --holdout before any work
        if (args.coupling or cfg.coupling) == "tight" and getattr(ds, "tight_inputs", None) is None \
                and getattr(ds, "gnss_raw", None) is None:
            raise UserError(f"{src}: no raw GNSS data (gnss_raw.csv, or RINEX with --format rinex): tight coupling "
                            "tunes on pseudorange innovations")
        progress = None
        if not args.quiet:
            def progress(k, scales, ll):
                print(f"run {k:3d}: ln L {ll:14.3f}  " + " ".join(f"{n} {v:.3g}" for n, v in scales.items()),
                      file=sys.stderr)
        reference = None
        if args.reference:  # read before the search: a missing or bad reference is one line, not after it
            from ..analysis.evaluate import _read_truth

            if not Path(args.reference).exists():
                raise UserError(f"--reference {args.reference}: not found")
            try:
                reference = _read_truth(args.reference)
            except (OSError, ValueError) as exc:
                raise UserError(f"--reference {args.reference}: {exc}") from None
        elif getattr(ds, "truth", None) is not None:
            reference = ds.truth
        ref_kw, ref_note = {}, None
        if args.reference and reference is not None:
            # a GNSS solution (.pos) describes the antenna, with its own sigmas; its epochs that were also
            # the filter's fixes are left out (the filter saw them)
            from ..calib.tune import pos_reference_model, unseen_reference_epochs

            unseen = unseen_reference_epochs(reference, ds.gnss.t_valid) if getattr(ds, "gnss", None) else None
            if unseen is not None:
                ref_kw["keep_t"] = unseen
                ref_note = (f"reference epochs that were also GNSS fixes of the run left out ({len(reference.t) - len(unseen)} "
                            f"of {len(reference.t)})")
            if Path(args.reference).suffix.lower() == ".pos" and getattr(ds, "gps_time_offset_s", None) is not None:
                same = args.gnss is not None and Path(args.gnss).resolve() == Path(args.reference).resolve()
                lag = float(base_d.get("gnss", {}).get("velocity_lag_s", 0.0)) if same else 0.0
                try:
                    ref_kw["reference_model"] = pos_reference_model(args.reference, ds, lag)
                except (OSError, ValueError) as exc:
                    raise UserError(f"--reference {args.reference}: {exc}") from None
        res = tune(ds, cfg, filter=args.filter, coupling=args.coupling, params=params, holdout=args.holdout,
                   max_runs=args.max_runs, progress=progress, split=args.split, block_s=args.block_s)
        t_from = res.t_split if args.holdout > 0 else -math.inf
        reps = []
        for c in (res.base, res.tuned):
            sol = run(ds, config=dataclasses.replace(c))
            reps.append(holdout_report(sol, reference, t_from=t_from, **ref_kw)
                        if res.split == "tail" or args.holdout == 0
                        else holdout_report(sol, reference, intervals=res.heldout, **ref_kw))
    except ConfigError as exc:
        raise UserError(str(exc)) from None
    if args.holdout > 0 and reps[0]["records"] == 0:
        raise UserError(f"{src}: no GNSS record in the held-out segment ({args.holdout:.0%} of the data): "
                        "nothing to check the tuned settings on; give a longer recording or --holdout 0")
    d = tuned_toml_dict(base_d, res)
    span = (f"t < {res.t_split:.3f} s" if res.split == "tail"
            else f"the first {1 - args.holdout:.0%} of each {args.block_s:g} s block")
    head = (f"# insnav tune: {res.tuned.filter} {res.tuned.coupling}, {len(res.names)} factors by the innovation "
            f"likelihood over {span} ({res.records} records, {res.runs} runs)\n"
            + "".join(f"#   {n} x {v:.4g}\n" for n, v in res.scales.items()))
    atomic_write_text(out, head + dumps_toml(d))
    print(f"tuned {len(res.names)} factors in {res.runs} runs, {res.seconds:.1f} s; ln L over the tuning segment "
          f"{res.log_likelihood_base:.2f} -> {res.log_likelihood_tuned:.2f} ({res.records} records)")
    for n, v in res.scales.items():
        print(f"  {n:10s} x {v:.4g}")
    if args.holdout == 0:
        print("no hold-out: the report uses all the data")
    elif res.split == "tail":
        print(f"held out: t >= {res.t_split:.3f} s ({args.holdout:.0%} of the IMU span)")
    else:
        print(f"held out: the last {args.holdout:.0%} of each {args.block_s:g} s block ({len(res.heldout)} blocks); "
              "the tuning runs applied the held-out blocks' records too (only the likelihood leaves them out), so "
              "the held-out figures are not independent of the tuning")
    if res.time_offset_test is not None:
        z = res.time_offset_test
        print(f'[time] estimate_offset = "auto" settled before tuning: {str(z["state_kept"]).lower()} '
              f'(estimate {z["estimate_ms"]:.2f} ms, sigma {z["sigma_ms"]:.2f} ms, |z| {abs(z["z"]):.2f} against '
              f'{z["threshold_z"]:.2f}); written as that')
    if res.tuned.smooth:
        print("the held-out figures are of the smoothed solution (smooth = true); the likelihood is the forward "
              "filter's")
    if ref_note:
        print(ref_note)
    for line in report_table(*reps, reference_model="reference_model" in ref_kw):
        print(line)
    print(f"{out}: written (insnav run --config {out})" if args.format != "kfgins"
          else f"{out}: written (insnav run --format kfgins --config {args.config} --run-config {out})")
    return 0
