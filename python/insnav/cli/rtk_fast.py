"""``insnav run --filter rtk --format rinex ... --out X.pos`` without numpy.

The command's usual path (:func:`insnav.cli.run.cmd_run_gnss_only`) reads the files, computes the
satellite orbits and writes the outputs with numpy; importing numpy alone is most of the CPU time
of a short run.  For the common form of the command this module instead

* reads the few options from ``argv`` itself (no argparse),
* reads the TOML's ``[rtk]`` table with ``tomllib`` and checks it with the checks of
  :class:`insnav.gnss.rtk.RtkOptions` (:mod:`insnav.gnss._rtk_keys`, shared),
* calls one C++ function, ``insnav._core.rtk_rinex_files`` (``insnav/gnss/rtk_rinex.hpp``), that
  reads the RINEX files, runs the engine and returns the text of the ``.pos`` and ``.rtk.csv``
  files (the same arithmetic and formatting as the Python path),
* writes them and ``<out>.config.toml`` all or none (:func:`insnav._atomic.output_set`) and prints
  the same summary line.

Whatever it does not cover -- other options, ``--timings``, another output format, RINEX 2,
systems other than GPS and QZSS, a base position given (on the command line or in the TOML) further than
500 m from the base header's APPROX POSITION XYZ (the usual path checks it against the base's own
pseudoranges), a receiver whose pseudoranges do not fit one position and clock
(``rtk_rinex.hpp`` code_fit_rms, as :func:`insnav.gnss.rtk.check_code_fit`: time tags shifted against
the observations), and every input the usual path would report as an error -- returns None before anything is written, and the
command takes the usual path, which gives the same files or the same one-line message.  Set
``INSNAV_RTK_FASTPATH=0`` to always take the usual path.
"""
from __future__ import annotations

import math
import os

__all__ = ["run_fast"]

#: the options this path reads (each with a value) besides --quiet / -q
_VALUED = {"--filter": "filter", "--format": "format", "--obs": "obs", "--base": "base", "--nav": "nav",
           "--config": "config", "--out": "out", "--base-pos": "base_pos"}
_BASE_KEYS = ("base_position_ecef_m", "base_position_llh")
#: the systems the C++ function computes orbits of (the Kepler LNAV orbits of GPS and QZSS)
_FAST_SYSTEMS = "GJ"


def _parse_argv(argv) -> dict | None:
    """The options of ``run ...`` (tokens after the command), or None for anything else."""
    argv = list(argv)
    if not argv or argv[0] != "run":
        return None
    opts = {"quiet": False}
    i = 1
    while i < len(argv):
        tok = argv[i]
        if tok in ("--quiet", "-q"):
            opts["quiet"] = True
            i += 1
            continue
        key, eq, val = tok.partition("=")
        if key not in _VALUED:
            return None
        if not eq:
            if i + 1 >= len(argv):
                return None
            val = argv[i + 1]
            i += 1
        if val.startswith("-"):
            return None  # argparse decides what such a value means
        opts[_VALUED[key]] = val
        i += 1
    return opts


def _base_position(value) -> list | None:
    """ECEF [m] of a base position given as x,y,z (as :func:`insnav.filters.rtk.parse_base_position`
    reads it), or None when it is latitude/longitude or not valid (the usual path converts or
    reports it)."""
    try:
        v = [float(x) for x in (value.split(",") if isinstance(value, str) else value)]
    except (TypeError, ValueError):
        return None
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        return None
    if abs(v[0]) <= 90.0 and abs(v[1]) <= 360.0 and abs(v[2]) < 1.0e5:  # geodetic
        return None
    if not (6.0e6 < math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) < 7.0e6):
        return None
    return v


def _near_header_position(path, base_e) -> bool:
    """Whether the RINEX header of ``path`` has an ``APPROX POSITION XYZ`` within
    :data:`insnav.gnss._rtk_keys.BASE_POSITION_TOLERANCE_M` of ``base_e`` (ECEF [m])."""
    from ..gnss._rtk_keys import BASE_POSITION_TOLERANCE_M

    try:
        with open(path, encoding="ascii", errors="replace") as f:
            for _, line in zip(range(1000), f):
                label = line[60:].strip()
                if label == "END OF HEADER":
                    return False
                if label == "APPROX POSITION XYZ":
                    xyz = [float(v) for v in line[:60].split()[:3]]
                    return len(xyz) == 3 and math.dist(xyz, base_e) <= BASE_POSITION_TOLERANCE_M
    except (OSError, ValueError):
        pass
    return False


def _inputs(opts: dict):
    """(rtk table values, base position or None, nav paths), or None to take the usual path."""
    if opts.get("format") != "rinex" or not all(opts.get(k) for k in ("obs", "base", "nav", "out")):
        return None
    d = {}
    if opts.get("config"):
        import tomllib

        try:
            with open(opts["config"], "rb") as f:
                d = tomllib.load(f)
        except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError):
            return None
    if any(k not in ("filter", "coupling", "rtk", "smooth", "tdcp") for k in d):
        return None  # a key GNSS-only RTK does not read: the usual path names it (filters.rtk.check_rtk_toml_keys)
    tdcp = d.get("tdcp")
    if d.get("smooth", False) is not False or (tdcp is not None and not (isinstance(tdcp, dict) and
                                                                         tdcp in ({}, {"enabled": False}))):
        return None  # the usual path refuses them with one line
    if d.get("coupling", "gnss") != "gnss":
        return None  # the usual path refuses it, or reads an INS run's TOML for its [rtk] table
    name = opts.get("filter")
    if name is None:
        name = d.get("filter") if opts.get("config") else None
    if name != "rtk":
        return None
    t = d.get("rtk", {})
    if not isinstance(t, dict):
        return None
    t = dict(t)
    from ..gnss._rtk_keys import RTK_DEFAULTS, rtk_value_error

    base = None
    if "base_position_llh" in t:
        return None
    if "base_position_ecef_m" in t:
        base = _base_position(t.pop("base_position_ecef_m"))
        if base is None:
            return None
    if opts.get("base_pos") is not None:
        base = _base_position(opts["base_pos"])
        if base is None:
            return None
    if base is not None and not _near_header_position(opts["base"], base):
        # a typed base position far from the base file's own APPROX POSITION XYZ (or one without it):
        # the usual path checks it against the base's pseudoranges (insnav.gnss.rtk.check_base_position)
        return None
    if any(k not in RTK_DEFAULTS for k in t):
        return None
    if t.get("noise", "configured") != "configured":  # an estimated noise needs the Python pre-pass
        return None
    values = {**RTK_DEFAULTS, **t}
    if rtk_value_error(values, "rtk options") is not None:
        return None
    if any(s not in _FAST_SYSTEMS for s in values["systems"]):
        return None
    nav = [p for p in opts["nav"].split(",") if p]
    if not nav:
        return None
    return values, base, nav


def run_fast(argv) -> int | None:
    """Run ``insnav run`` (``argv``: the tokens after the program name) without numpy when it is
    an RTK run this path covers; its exit status, or None (nothing written) for the usual path."""
    from pathlib import Path

    opts = _parse_argv(argv)
    if opts is None:
        return None
    got = _inputs(opts)
    if got is None:
        return None
    values, base, nav = got
    out = Path(opts["out"])
    if out.suffix.lower() != ".pos" or out.is_dir():
        return None
    writes = [out, out.with_suffix(out.suffix + ".rtk.csv"), out.with_suffix(out.suffix + ".config.toml")]
    reads = [opts["obs"], opts["base"], *nav] + ([opts["config"]] if opts.get("config") else [])
    if {os.path.realpath(p) for p in writes} & {os.path.realpath(p) for p in reads}:
        return None  # an output names an input: the usual path refuses it with one line
    from .._outputs import insnav_output_kind

    if any(os.path.lexists(p) and insnav_output_kind(p) is None for p in writes):
        return None  # an existing file insnav did not write: the usual path keeps it (or --overwrite)
    from .. import _core

    if not hasattr(_core, "rtk_rinex_files"):
        return None
    from ..gnss._rtk_keys import SIGNALS, rtk_core_dict

    systems = values["systems"]
    prefs = {s: [list(x) for x in SIGNALS[s]] for s in systems if s in SIGNALS}
    res = _core.rtk_rinex_files(os.fspath(opts["obs"]), os.fspath(opts["base"]), nav, systems,
                                rtk_core_dict(values), base, prefs)
    if isinstance(res, str) or res["epochs"] == res["n_none"]:
        return None  # not covered here, or an input the usual path reports
    from .._atomic import atomic_write_text, output_set
    from .._toml import table_toml

    table = dict(values)
    if base is not None:
        table["base_position_ecef_m"] = [float(v) for v in base]
    config_text = "\n".join(["# insnav resolved run configuration", 'filter = "rtk"', 'coupling = "gnss"']) + "\n" \
        + table_toml("rtk", table)
    n = res["epochs"]
    line = (f"{out}: {n} epochs, {res['n_fixed']} fixed ({100.0 * (res['n_fixed'] / n if n else 0.0):.1f} %), "
            f"{res['n_float']} float, {res['n_dgps']} dgps, {res['n_none']} none; filter rtk ({values['mode']}, "
            f"{values['ar_mode']}, {values['systems']}, {values['frequencies']} frequencies); {res['slips']} cycle "
            "slips detected")
    with output_set():  # every file or, on an error (a full disk, Ctrl-C), none; older files untouched
        atomic_write_text(out, res["pos_text"])
        atomic_write_text(out.with_suffix(out.suffix + ".rtk.csv"), res["table_text"])
        atomic_write_text(out.with_suffix(out.suffix + ".config.toml"), config_text)
    print(line)
    return 0
