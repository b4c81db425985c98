"""``insnav report``: an HTML page with plots and a summary for a saved solution."""
from __future__ import annotations

import argparse
from pathlib import Path

EXAMPLES = """examples:
  insnav run run3 --filter rbukf --out run3-rbukf.csv
  insnav report run3-rbukf.csv --truth run3 --gnss run3          # -> run3-rbukf.csv-report/report.html
  insnav report walk.csv --truth ../shared/data/rtklibexplorer_walk_0827/raw/gnss_1730_sf.pos --out walk-report
  insnav allan static.txt --out-dir imu-allan && insnav report run3-rbukf.csv --allan imu-allan
  insnav report --allan imu-allan                                  # the IMU noise alone -> imu-allan-report/

SOL: a solution written by `insnav run` (.csv, .npz or .parquet, a KF-GINS .nav, or an RTKLIB .pos;
its .innovations.csv sidecar is read when present).  TRUTH: anything `insnav evaluate` reads (a
static antenna as x,y,z ECEF [m] or lat_deg,lon_deg,h_m among them).
GNSS: gnss.csv or a dataset folder, or the RTKLIB .pos / NMEA file given to `insnav run
--format csv` (fixes on the track; the position reference when there is no truth).
ALLAN: the --out-dir of `insnav allan` (or its allan.csv): a section with the Allan deviations
and their fit, the IEEE 952 terms with 95 % intervals and the [imu] noise TOML.
Units: positions and errors in m, velocities in m/s, angles in deg, biases in mg and deg/h,
scale factors in ppm, times in s."""


def add_report_parser(sub) -> None:
    p = sub.add_parser("report", help="HTML report (track, errors with 3-sigma, biases, innovations/NIS, summary)",
                       description="Write one self-contained report.html (figures inlined, no network) plus "
                                   "its PNGs for a saved solution.",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("solution", metavar="SOL", nargs="?", default=None,
                   help="saved solution (may be left out with --allan: a page of the IMU noise only)")
    p.add_argument("--truth", default=None)
    p.add_argument("--gnss", default=None)
    p.add_argument("--allan", default=None, metavar="ALLAN",
                   help="output folder of `insnav allan` (or its allan.csv): adds the IMU-noise section")
    p.add_argument("--outages", default="", help="start:end [s], comma-separated (default: gaps in the GNSS records)")
    p.add_argument("--out", default=None, help="folder (default: SOL-report beside SOL); an earlier report there is "
                   "replaced at the end, any other existing folder only with --overwrite")
    p.add_argument("--overwrite", action="store_true",
                   help="write report.html and its figures into an existing folder that is not an insnav report "
                        "(its other files are left alone)")
    p.set_defaults(func=cmd_report)


def cmd_report(args) -> int:
    from ..analysis.evaluate import _parse_outages
    from ..analysis.report import report

    from ..errors import UserError

    if args.solution is None:
        if args.allan is None:
            raise UserError("give SOL (a saved solution), or --allan DIR for a page of the IMU noise only")
        if args.truth is not None or args.gnss is not None or args.outages:
            raise UserError("--truth, --gnss and --outages need SOL (a saved solution)")
    for name in ("solution", "truth", "gnss", "allan"):
        v = getattr(args, name)
        if v is not None and not Path(v).exists() and not (name == "truth" and "," in v):  # or a static x,y,z
            raise FileNotFoundError(f"{'SOL' if name == 'solution' else '--' + name}: not found: {v}")
    outages = _parse_outages(args.outages) if args.outages else None
    path = report(args.solution, args.out, truth=args.truth, gnss=args.gnss, outages=outages,
                  overwrite=args.overwrite, allan=args.allan)
    print(f"{path}: report written ({sum(1 for _ in path.parent.glob('*.png'))} figures beside it)")
    return 0
