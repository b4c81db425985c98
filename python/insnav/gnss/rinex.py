"""RINEX 2.10/2.11 and 3.02-3.05 readers for navigation and observation files.

Navigation: GPS LNAV, GLONASS (RINEX 2 ``.g`` and RINEX 3 ``R`` records),
Galileo I/NAV and F/NAV (``E``), BeiDou D1/D2 (``C``); observations: one
signal per system (GPS, GLONASS, Galileo, BeiDou), pseudorange, phase,
Doppler and C/N0.  Which systems are read is the caller's choice
(``systems=``); the default is GPS only.

Why an own parser: the subset needed here (broadcast records, one signal per
system) is small; a dependency such as georinex pulls in xarray/pandas and
parses everything; and we want exact control over errors.  Every problem in
a file raises :class:`RinexError`, whose message names the file, the 1-based
line number and what was wrong; no IndexError or bare ValueError escapes for
a malformed file.

Times are returned as GPS seconds since 1980-01-06 (``t_gps_s``, see
:mod:`insnav.gnss.gpstime`) and as (GPS week, seconds of week).  GPS and
Galileo record epochs are GPS time (GST is steered to it), BeiDou epochs
(BDT) get +14 s, GLONASS epochs (UTC) get the leap seconds.  Observation
epochs must be GPS time (or GST / QZSST, steered to it; other time systems raise).

References
----------
W. Gurtner, L. Estey, *RINEX: The Receiver Independent Exchange Format*,
versions 2.11 (2007) and 3.05 (IGS/RTCM RINEX WG, 2020).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from typing import TYPE_CHECKING

from .ephemeris import DEFAULT_FIT_S, Ephemerides

if TYPE_CHECKING:  # annotations only (the readers import these modules where they build the tables)
    from .galbds import KeplerEphemerides
    from .glonass import GlonassEphemerides
from .gpstime import SECONDS_PER_WEEK, gps_seconds_from_calendar, week_tow

__all__ = ["RinexError", "NavData", "ObsData", "read_rinex_nav", "read_rinex_obs", "read_nav_multi", "read_obs_multi"]


class RinexError(ValueError):
    """A malformed or unsupported RINEX file.

    Attributes
    ----------
    path : str
    line : int or None
        1-based line number of the problem (None if not tied to a line).
    """

    def __init__(self, path, line, what):
        self.path = str(path)
        self.line = line
        self.what = what
        where = f"{self.path}, line {line}" if line is not None else self.path
        super().__init__(f"{where}: {what}")


class _NavOfOtherSystems(RinexError):
    """A single-system RINEX 3 navigation file of none of the systems asked for: an error when it is
    the only one, skipped by :func:`read_nav_multi` beside files of the systems asked for."""


class _Lines:
    """Line source that remembers the 1-based line number (for error messages)."""

    def __init__(self, path, lines=None):
        self.path = os.fspath(path)
        if lines is None:
            try:
                from ..data.textio import read_text

                lines = read_text(self.path, "ascii").splitlines()
            except OSError as exc:
                raise RinexError(self.path, None, f"cannot read file ({exc.strerror})") from exc
        self.lines = lines
        self.i = 0  # index of the next line

    def next(self, what="a record line"):
        if self.i >= len(self.lines):
            raise RinexError(self.path, len(self.lines) + 1 if self.lines else 1,
                             f"unexpected end of file while reading {what}")
        line = self.lines[self.i]
        self.i += 1
        return line

    def eof(self):
        return self.i >= len(self.lines)

    @property
    def lineno(self):
        """1-based number of the line last returned by :meth:`next`."""
        return self.i

    def error(self, what, lineno=None):
        return RinexError(self.path, self.lineno if lineno is None else lineno, what)


def _float(src: _Lines, text: str, what: str, blank=math.nan, lineno=None):
    try:  # the common case first: float() skips the blanks around a number itself
        return float(text)
    except ValueError:
        pass
    s = text.strip()
    if not s:
        return blank
    try:
        return float(s.replace("D", "E").replace("d", "e"))
    except ValueError:
        raise src.error(f"bad number {s!r} for {what}", lineno) from None


def _int(src: _Lines, text: str, what: str, lineno=None):
    s = text.strip()
    try:
        return int(s)
    except ValueError:
        raise src.error(f"bad integer {text!r} for {what}", lineno) from None


def _read_header(src: _Lines):
    """Read header lines up to END OF HEADER; return list of (lineno, content, label)."""
    out = []
    first = src.next("the header")
    if "RINEX VERSION / TYPE" not in first[60:]:
        raise src.error("malformed header: first line is not 'RINEX VERSION / TYPE'")
    out.append((src.lineno, first[:60], "RINEX VERSION / TYPE"))
    while True:
        line = src.next("the header (no END OF HEADER)")
        label = line[60:].strip()
        out.append((src.lineno, line[:60].ljust(60), label))
        if label == "END OF HEADER":
            return out


def _version_type(src, header):
    lineno, text, _ = header[0]
    vs = text[:9].strip()
    try:
        version = float(vs)
    except ValueError:
        raise src.error(f"malformed header: bad RINEX version {vs!r}", lineno) from None
    ftype = text[20:21].upper()
    sysc = text[40:41].upper() or " "
    if not (2.0 <= version < 4.0):
        raise src.error(f"unsupported RINEX version {version}", lineno)
    return version, ftype, sysc


# --------------------------------------------------------------------------- nav

#: Order of the broadcast orbit values after (toc, af0, af1, af2) in a GPS record.
_NAV_ORDER = (
    "iode", "crs", "delta_n", "m0",
    "cuc", "e", "cus", "sqrt_a",
    "toe_sow", "cic", "omega0", "cis",
    "i0", "crc", "omega", "omega_dot",
    "idot", "l2_codes", "week", "l2p_flag",
    "sv_accuracy", "health", "tgd", "iodc",
    "transmit_sow", "fit_h", "spare1", "spare2",
)


#: Broadcast orbit lines after the first line of a RINEX 3 record: (required, allowed).  GLONASS
#: has a 4th orbit line from RINEX 3.05 on (status flags, L1/L2 group delay, URAI, health flags).
_NAV3_LINES = {"G": (7, 7), "E": (7, 7), "C": (7, 7), "R": (3, 4), "J": (7, 7)}

#: systems whose navigation records insnav reads
_SYSTEM_NAMES = {"G": "GPS", "R": "GLONASS", "E": "Galileo", "C": "BeiDou", "J": "QZSS"}


@dataclass
class NavData:
    """Contents of a navigation file (GPS, or mixed / GLONASS / Galileo / BeiDou / QZSS).

    Attributes
    ----------
    path : str
    version : float
    eph : Ephemerides
        The GPS LNAV records, in file order.
    ion_alpha, ion_beta : ndarray (4,) or None
        Klobuchar coefficients from the header [s, s/semicircle, ...] and
        [s, s/semicircle, ...] (IS-GPS-200 20.3.3.5.1.7); None if absent.
    n_skipped : int
        Records that were skipped: systems not asked for (``systems``) and
        systems insnav does not process (SBAS, IRNSS...).
    eph_r : GlonassEphemerides
        GLONASS records (``t_b`` converted from UTC to GPS time), empty unless asked for.
    eph_e : KeplerEphemerides
        Galileo records (I/NAV and F/NAV, see ``data_source``), empty unless asked for.
    eph_c : KeplerEphemerides
        BeiDou D1/D2 records (``toc``/``toe`` converted from BDT to GPS time), empty unless asked for.
    eph_j : Ephemerides
        QZSS LNAV records (the GPS layout and algorithm, IS-QZSS-PNT 4.1.2;
        times are GPS time), empty unless asked for.  ``health`` is the SV
        health word without its L1C/B bit (bit 0, set by satellites that do
        not transmit L1C/B; RTKLIB masks it too); ``fit_s`` is 2 h for the
        fit interval flag 0 and 4 h for 1 (IS-QZSS-PNT 4.1.2.4).
    leap_seconds : float or None
        GPS - UTC from the header (``LEAP SECONDS``) [s]; None if absent
        (GLONASS epochs then use :func:`insnav.gnss.glonass.gps_utc_leap_seconds`).
    skipped_by_system : dict
        System letter -> number of records skipped.
    """

    path: str
    version: float
    eph: Ephemerides
    ion_alpha: np.ndarray | None = None
    ion_beta: np.ndarray | None = None
    n_skipped: int = 0
    eph_r: "GlonassEphemerides | None" = None
    eph_e: "KeplerEphemerides | None" = None
    eph_c: "KeplerEphemerides | None" = None
    leap_seconds: float | None = None
    skipped_by_system: dict = field(default_factory=dict)
    eph_j: "Ephemerides | None" = None

    def __post_init__(self):
        from .galbds import KeplerEphemerides
        from .glonass import GlonassEphemerides

        if self.eph_r is None:
            self.eph_r = GlonassEphemerides.empty()
        if self.eph_e is None:
            self.eph_e = KeplerEphemerides.empty()
        if self.eph_c is None:
            self.eph_c = KeplerEphemerides.empty()
        if self.eph_j is None:
            self.eph_j = _gps_like_table(None)

    @property
    def systems(self) -> str:
        """Letters of the systems with at least one record, in :data:`insnav.gnss.systems.SYSTEMS` order."""
        n = {"G": len(self.eph), "R": len(self.eph_r), "E": len(self.eph_e), "C": len(self.eph_c),
             "J": len(self.eph_j)}
        return "".join(s for s in "GRECJ" if n[s] > 0)

    def merge(self, other: "NavData") -> "NavData":
        """Records of both files (e.g. a RINEX 2 ``.n`` GPS and ``.g`` GLONASS file of the same day)."""
        return NavData(
            self.path + "+" + other.path, self.version,
            Ephemerides.from_columns({k: np.concatenate([v, getattr(other.eph, k)])
                                      for k, v in self.eph.to_columns().items()}),
            self.ion_alpha if self.ion_alpha is not None else other.ion_alpha,
            self.ion_beta if self.ion_beta is not None else other.ion_beta,
            self.n_skipped + other.n_skipped, self.eph_r.concat(other.eph_r), self.eph_e.concat(other.eph_e),
            self.eph_c.concat(other.eph_c), self.leap_seconds if self.leap_seconds is not None else other.leap_seconds,
            {k: self.skipped_by_system.get(k, 0) + other.skipped_by_system.get(k, 0)
             for k in set(self.skipped_by_system) | set(other.skipped_by_system)},
            Ephemerides.from_columns({k: np.concatenate([v, getattr(other.eph_j, k)])
                                      for k, v in self.eph_j.to_columns().items()}))

    def transmit_states(self, t_rx_gps_s, r_rx_e, sat_ids=None, *, system=None, prn=None, codes=None, **kw):
        """Multi-system satellite states at transmission; see :func:`insnav.gnss.broadcast.transmit_states_multi`."""
        from .broadcast import transmit_states_multi

        return transmit_states_multi(self, t_rx_gps_s, r_rx_e, sat_ids, system=system, prn=prn, codes=codes, **kw)

    def sat_states(self, t_gps_s, sat_ids=None, *, system=None, prn=None, codes=None, **kw):
        """Multi-system geometric states at ``t_gps_s``; see :func:`insnav.gnss.broadcast.sat_states_multi`."""
        from .broadcast import sat_states_multi

        return sat_states_multi(self, t_gps_s, sat_ids, system=system, prn=prn, codes=codes, **kw)


def _four(src, text, start, width, what, n=4):
    """``n`` numbers of ``width`` characters from column ``start`` (as :func:`_float` reads each)."""
    t = text.replace("D", "E").replace("d", "e")  # Fortran exponents once per line (same field widths)
    out = []
    for k in range(n):
        a, b = start + k * width, start + (k + 1) * width
        try:
            out.append(float(t[a:b]))
        except ValueError:  # a blank field, or the error naming the file's own text
            out.append(_float(src, text[a:b], what))
    return out


def _parse_systems(systems) -> str:
    s = "".join(dict.fromkeys(str(systems).upper().replace(",", "").replace(" ", "")))
    bad = [c for c in s if c not in _SYSTEM_NAMES]
    if bad or not s:
        raise ValueError(f"systems={systems!r}: use letters of G (GPS), R (GLONASS), E (Galileo), C (BeiDou), "
                         "J (QZSS)")
    return s


def _nav_records_core(src: _Lines, rinex3: bool, glo2: bool, want: str):
    """The record tables of :func:`read_rinex_nav` from the body after the header through the compiled
    scanner (``insnav/io/rinex_nav.hpp``): ``(rec, krec, grec, n_skipped, skipped)`` with the values the
    record loop gives, or None when the scanner is absent or leaves the file to that loop (an error to
    report, a record that fails a check, a form it does not take)."""
    from .. import _core
    from .galbds import BDT_GPST_OFFSET_S

    if not hasattr(_core, "scan_rinex_nav_body"):
        return None
    d = _core.scan_rinex_nav_body("\n".join(src.lines[src.i:]), rinex3, glo2, want)
    if d is None:
        return None
    sys_a = d["sys"]
    ymdhm = d["ymdhm"]
    t_cal = np.asarray(gps_seconds_from_calendar(ymdhm[:, 0], ymdhm[:, 1], ymdhm[:, 2], ymdhm[:, 3], ymdhm[:, 4],
                                                 d["sec"]), dtype=float).reshape(-1)
    clk = d["clk"]
    clk0 = np.where(np.isnan(clk), 0.0, clk)
    orbit = d["orbit"]
    orbit0 = np.where(np.isnan(orbit), 0.0, orbit)
    prn = d["prn"].astype(float)

    def kepler(letter, toc_offset_s, keep_nan_fit):
        m = sys_a == ord(letter)
        r = {"prn": prn[m], "toc": t_cal[m] if toc_offset_s is None else t_cal[m] + toc_offset_s}
        for j, name in enumerate(("af0", "af1", "af2")):
            r[name] = clk0[m, j]
        for j, name in enumerate(_NAV_ORDER):
            r[name] = orbit[m, j] if (keep_nan_fit and name == "fit_h") else orbit0[m, j]
        return r, bool(np.all(r["sqrt_a"] > 0.0))

    rec, ok_g = kepler("G", None, True)
    rec_e, ok_e = kepler("E", 0.0, False)
    rec_c, ok_c = kepler("C", BDT_GPST_OFFSET_S, False)
    rec_j, ok_j = kepler("J", None, True)
    m = sys_a == ord("R")
    grec = {"prn": prn[m], "toc_utc": t_cal[m]}
    for j, name in enumerate(("clock_bias", "gamma_n", "tk")):
        grec[name] = clk0[m, j]
    for j, name in enumerate(("x", "vx", "ax", "health", "y", "vy", "ay", "freq_k", "z", "vz", "az", "age")):
        grec[name] = orbit0[m, j]
    radius = np.sqrt(grec["x"] ** 2 + grec["y"] ** 2 + grec["z"] ** 2)
    ok_r = bool(np.all((1.0e3 < radius) & (radius < 1.0e5))
                and np.all((-7 <= grec["freq_k"]) & (grec["freq_k"] <= 13)))
    if not (ok_g and ok_e and ok_c and ok_r and ok_j):
        return None  # the record loop reports the record
    counts = [int(c) for c in d["skipped_count"]]
    skipped = dict(zip(d["skipped_sys"], counts))
    return rec, {"E": rec_e, "C": rec_c, "J": rec_j}, grec, sum(counts), skipped


def read_rinex_nav(path, systems="G") -> NavData:
    """Read broadcast ephemerides (and Klobuchar parameters) from a RINEX nav file.

    Supports RINEX 2.10/2.11 GPS nav (``.21n``), RINEX 2.01-2.11 GLONASS nav
    (``.16g``; always read as GLONASS, ``systems`` does not apply) and RINEX
    3.02-3.05 GPS/GLONASS/Galileo/BeiDou or mixed nav (``.rnx``/``.nav``).
    Records of systems not in ``systems`` and of systems insnav does not
    process (J, S, I...) are skipped and counted (a RINEX 3 record starts
    with a system letter in column 1, continuation lines start with blanks,
    so the skip needs no knowledge of each system's record length; a record
    start that is not a letter cannot be delimited and raises).  ``D``/``d``/``E``
    exponents are accepted; blank fields read as 0 (NaN for the GPS fit
    interval, which then defaults to 4 h).

    Parameters
    ----------
    path : str or PathLike
    systems : str
        Systems to read from a RINEX 3 file, letters of ``"GRECJ"``.  The
        default ``"G"`` reads GPS only (the behaviour before multi-GNSS).

    Returns
    -------
    NavData
        ``eph`` (GPS), ``eph_r`` (GLONASS), ``eph_e`` (Galileo), ``eph_c``
        (BeiDou), ``eph_j`` (QZSS, GPS time as GPS), all times in GPS seconds since 1980-01-06: GLONASS epochs
        (UTC) plus the leap seconds, BeiDou epochs (BDT) plus 14 s, Galileo
        (GST) as is.  Galileo: ``tgd`` = BGD(E1,E5a), ``tgd2`` = BGD(E1,E5b),
        ``data_source`` the RINEX bit field; BeiDou: ``tgd`` = T_GD1,
        ``tgd2`` = T_GD2; GLONASS: positions [m], velocities [m/s],
        accelerations [m/s^2], ``freq_k`` the FDMA channel.

    Raises
    ------
    RinexError
        Malformed header, bad or truncated record or unexpected end of file
        (message gives path and 1-based line number).
    ValueError
        ``systems`` has a letter other than G, R, E, C, J.
    """
    from .galbds import BDT_GPST_OFFSET_S, BDT_WEEK_OFFSET, KeplerEphemerides
    from .glonass import GlonassEphemerides, gps_utc_leap_seconds

    want = _parse_systems(systems)
    src = _Lines(path)
    header = _read_header(src)
    version, ftype, sysc = _version_type(src, header)
    glo2 = version < 3 and ftype == "G"  # RINEX 2 GLONASS navigation file
    if ftype != "N" and not glo2:
        raise src.error(f"malformed header: not a navigation file (type {ftype!r})", header[0][0])
    if version >= 3 and sysc != "M" and sysc not in want:
        raise _NavOfOtherSystems(src.path, header[0][0], f"a navigation file of system {sysc!r} only, and the "
                                 f"run uses the systems {want!r}: give a navigation file of one of them")
    ion_alpha = ion_beta = None
    leap = None
    for lineno, text, label in header:
        if label == "ION ALPHA" or label == "ION BETA":
            vals = [_float(src, text[2 + 12 * k:14 + 12 * k], label, lineno=lineno) for k in range(4)]
            if any(math.isnan(v) for v in vals):
                raise src.error(f"malformed header: incomplete {label}", lineno)
            if label == "ION ALPHA":
                ion_alpha = np.array(vals)
            else:
                ion_beta = np.array(vals)
        elif label == "IONOSPHERIC CORR":
            kind = text[:4].strip()
            if kind in ("GPSA", "GPSB"):
                vals = [_float(src, text[5 + 12 * k:17 + 12 * k], label, lineno=lineno) for k in range(4)]
                if any(math.isnan(v) for v in vals):
                    raise src.error(f"malformed header: incomplete {kind} {label}", lineno)
                if kind == "GPSA":
                    ion_alpha = np.array(vals)
                else:
                    ion_beta = np.array(vals)
        elif label == "LEAP SECONDS" and text[:6].strip():
            leap = float(_int(src, text[:6], "LEAP SECONDS", lineno))
            if not (0 <= leap < 100):
                raise src.error(f"malformed header: LEAP SECONDS {leap:g} out of range", lineno)

    rec = {k: [] for k in ("prn", "toc", "af0", "af1", "af2") + _NAV_ORDER}
    krec = {"E": {k: [] for k in ("prn", "toc", "af0", "af1", "af2") + _NAV_ORDER},
            "C": {k: [] for k in ("prn", "toc", "af0", "af1", "af2") + _NAV_ORDER},
            "J": {k: [] for k in ("prn", "toc", "af0", "af1", "af2") + _NAV_ORDER}}
    grec = {k: [] for k in ("prn", "toc_utc", "clock_bias", "gamma_n", "tk", "x", "vx", "ax", "health",
                            "y", "vy", "ay", "freq_k", "z", "vz", "az", "age")}
    n_skipped = 0
    skipped = {}
    rinex3 = version >= 3.0
    width0 = 23 if rinex3 else 22  # end of the epoch field on the first line
    cont_start = 4 if rinex3 else 3
    fast = _nav_records_core(src, rinex3, glo2, want)
    if fast is not None:  # the compiled scanner read every record: the loop below has nothing left to read
        rec, krec, grec, n_skipped, skipped = fast
        src.i = len(src.lines)
    while not src.eof():
        line = src.next()
        if not line.strip():
            continue
        start_line = src.lineno
        if rinex3:
            sysid = line[0]
            if sysid == " ":
                raise src.error("bad record: expected a record start (system letter in column 1)")
            if not ("A" <= sysid <= "Z"):
                raise src.error(f"bad record: cannot delimit the record: column 1 is {sysid!r}, "
                                f"not a system letter")
            if sysid not in want or sysid not in _SYSTEM_NAMES:
                n_skipped += 1
                skipped[sysid] = skipped.get(sysid, 0) + 1
                while not src.eof() and src.lines[src.i][:1] == " ":
                    src.i += 1
                continue
            prn = _int(src, line[1:3], "satellite number")
            try:
                y = int(line[4:8]); mo = int(line[9:11]); d = int(line[12:14])
                h = int(line[15:17]); mi = int(line[18:20]); sec = float(line[21:23])
            except ValueError:
                raise src.error(f"bad record: cannot parse epoch {line[:23]!r}") from None
        else:
            sysid = "R" if glo2 else "G"
            if line[:2] == "  " and line[2:3] == " ":
                raise src.error("bad record: expected a record start (PRN in columns 1-2)")
            prn = _int(src, line[0:2], "satellite number")
            try:
                y = int(line[3:5]); mo = int(line[6:8]); d = int(line[9:11])
                h = int(line[12:14]); mi = int(line[15:17]); sec = float(line[17:22])
            except ValueError:
                raise src.error(f"bad record: cannot parse epoch {line[:22]!r}") from None
            y += 2000 if y < 80 else 1900
        if not (1 <= mo <= 12 and 1 <= d <= 31 and 0 <= h <= 23 and 0 <= mi <= 59 and 0 <= sec < 61):
            raise src.error(f"bad record: impossible epoch {line[:width0]!r}")
        if not (0 <= prn <= 99):
            raise src.error(f"bad record: satellite number {prn} out of range")
        clk = _four(src, line, width0, 19, "clock parameter", n=3)
        sat = f"{sysid}{prn:02d}"
        if sysid not in "GJ":
            n_req, n_max = _NAV3_LINES[sysid] if rinex3 else (3, 3)
            vals = []
            for k in range(n_max):
                if k >= n_req and (src.eof() or src.lines[src.i][:1] != " " or not src.lines[src.i].strip()):
                    break
                cl = src.next(f"broadcast orbit line {k + 1} of {sat} (record started on line {start_line})")
                if cl[:1] != " " and rinex3:
                    raise src.error(f"bad record: broadcast orbit line {k + 1} of {sat} "
                                    f"(record started on line {start_line}) missing")
                vals.extend(_four(src, cl.ljust(cont_start + 76), cont_start, 19, "broadcast orbit value"))
            t_cal = gps_seconds_from_calendar(y, mo, d, h, mi, sec)
            if sysid == "R":
                vals = [0.0 if math.isnan(v) else v for v in vals[:12]]
                grec["prn"].append(prn)
                grec["toc_utc"].append(t_cal)
                for name, v in zip(("clock_bias", "gamma_n", "tk"), clk):
                    grec[name].append(0.0 if math.isnan(v) else v)
                for name, v in zip(("x", "vx", "ax", "health", "y", "vy", "ay", "freq_k", "z", "vz", "az", "age"),
                                   vals):
                    grec[name].append(v)
                if not (1.0e3 < math.sqrt(vals[0] ** 2 + vals[4] ** 2 + vals[8] ** 2) < 1.0e5):
                    raise src.error(f"bad record: {sat} record starting on line {start_line} has an orbit radius "
                                    "outside 1000-100000 km")
                if not (-7 <= vals[7] <= 13):
                    raise src.error(f"bad record: {sat} record starting on line {start_line} has frequency "
                                    f"channel {vals[7]:g} (not -7..13)", start_line + 2)
            else:
                r = krec[sysid]
                r["prn"].append(prn)
                r["toc"].append(t_cal + (BDT_GPST_OFFSET_S if sysid == "C" else 0.0))
                for name, v in zip(("af0", "af1", "af2"), clk):
                    r[name].append(0.0 if math.isnan(v) else v)
                for name, v in zip(_NAV_ORDER, vals):
                    r[name].append(0.0 if math.isnan(v) else v)
                if not (0.0 < r["sqrt_a"][-1]):
                    raise src.error(f"bad record: {sat} record starting on line {start_line} has sqrt(A) <= 0")
            continue
        vals = []
        for k in range(7):
            cl = src.next(f"broadcast orbit line {k + 1} of {sat} (record started on line {start_line})")
            if cl[:1] != " " and rinex3:
                raise src.error(f"bad record: broadcast orbit line {k + 1} of {sat} "
                                f"(record started on line {start_line}) missing")
            vals.extend(_four(src, cl.ljust(cont_start + 76), cont_start, 19, "broadcast orbit value"))
        toc = gps_seconds_from_calendar(y, mo, d, h, mi, sec)
        r = rec if sysid == "G" else krec["J"]
        r["prn"].append(prn)
        r["toc"].append(toc)
        for name, v in zip(("af0", "af1", "af2"), clk):
            r[name].append(0.0 if math.isnan(v) else v)
        for name, v in zip(_NAV_ORDER, vals):
            if name != "fit_h" and math.isnan(v):
                v = 0.0
            r[name].append(v)
        if not (0.0 < r["sqrt_a"][-1]):
            raise src.error(f"bad record: {sat} record starting on line {start_line} has sqrt(A) <= 0")

    eph = _gps_like_table(rec)
    eph_j = _gps_like_table(krec.pop("J"), qzss=True)

    kep = {}
    for s, r in krec.items():
        c = {k: np.asarray(v, dtype=float) for k, v in r.items()}
        # GST week = GPS week (RINEX aligns it; a 1024 offset is absorbed by the rounding below);
        # BDT week + 1356 = GPS week, BDT = GPST - 14 s
        off = (BDT_WEEK_OFFSET * SECONDS_PER_WEEK + BDT_GPST_OFFSET_S) if s == "C" else 0.0
        toe = c["week"] * SECONDS_PER_WEEK + c["toe_sow"] + off
        toe += SECONDS_PER_WEEK * np.round((c["toc"] - toe) / SECONDS_PER_WEEK)
        c["toe"] = toe
        c["week"] = np.floor(toe / SECONDS_PER_WEEK)
        # neither system broadcasts a fit interval; both are updated at least every 1-3 h
        c["fit_s"] = np.full(toe.shape, DEFAULT_FIT_S)
        c["tgd2"] = c["iodc"]  # the 4th value of broadcast orbit line 6: BGD(E1,E5b) / T_GD2
        if s == "E":
            c["data_source"] = c["l2_codes"]
            c["iodc"] = np.zeros_like(toe)
        else:
            c["data_source"] = np.zeros_like(toe)
            c["iodc"] = c["fit_h"]  # AODC
        c["prn"] = c["prn"].astype(np.int64)
        kep[s] = KeplerEphemerides.from_columns(c)

    g = {k: np.asarray(v, dtype=float) for k, v in grec.items()}
    leap_s = leap if leap is not None else (gps_utc_leap_seconds(g["toc_utc"] + 18.0) if g["prn"].size else 0.0)
    g["tb"] = g.pop("toc_utc") + leap_s
    for k in ("x", "y", "z", "vx", "vy", "vz", "ax", "ay", "az"):
        g[k] = g[k] * 1.0e3  # km -> m
    g["prn"] = g["prn"].astype(np.int64)
    g["freq_k"] = np.round(g["freq_k"]).astype(np.int64)
    eph_r = GlonassEphemerides.from_columns(g)
    return NavData(src.path, version, eph, ion_alpha, ion_beta, n_skipped, eph_r, kep["E"], kep["C"], leap, skipped,
                   eph_j)


def _gps_like_table(rec, qzss: bool = False) -> Ephemerides:
    """The :class:`Ephemerides` of GPS (or QZSS, ``qzss``) LNAV records read by :func:`read_rinex_nav`
    (``rec``: column name -> values in file order; None: an empty table)."""
    if rec is None:
        rec = {k: [] for k in ("prn", "toc", "af0", "af1", "af2") + _NAV_ORDER}
    cols = {k: np.asarray(v, dtype=float) for k, v in rec.items()}
    n = cols["prn"].size
    if n:
        # Continuous toe: the record week goes with toe; guard against a week
        # field that disagrees with toc by more than half a week.
        toe = cols["week"] * SECONDS_PER_WEEK + cols["toe_sow"]
        toe += SECONDS_PER_WEEK * np.round((cols["toc"] - toe) / SECONDS_PER_WEEK)
        cols["toe"] = toe
        fit_h = cols["fit_h"]
        if qzss:
            # QZSS: the fit interval flag, 0 -> 2 h, 1 -> more than 2 h (taken as 4 h) (IS-QZSS-PNT 4.1.2.4);
            # the health word without bit 0, the L1C/B signal's (set where it is not transmitted)
            cols["fit_s"] = np.where(np.isfinite(fit_h) & (fit_h > 0), DEFAULT_FIT_S, 2.0 * 3600.0)
            cols["health"] = (cols["health"].astype(np.int64) & ~1).astype(float)
        else:
            # RINEX 2/3: fit interval in hours; 0/blank -> 4 h (IS-GPS-200 20.3.4.4).
            cols["fit_s"] = np.where(np.isfinite(fit_h) & (fit_h > 0), fit_h * 3600.0, DEFAULT_FIT_S)
        cols["week"] = np.floor(toe / SECONDS_PER_WEEK)
    else:
        cols["toe"] = np.zeros(0)
        cols["fit_s"] = np.zeros(0)
    cols["prn"] = cols["prn"].astype(np.int64)
    return Ephemerides.from_columns(cols)


# --------------------------------------------------------------------------- obs

#: Preferred RINEX 3 codes for GPS L1 C/A (first present wins), and RINEX 2 codes.
_OBS_PREF3 = {
    "C1": ("C1C", "C1X", "C1W", "C1P"),
    "L1": ("L1C", "L1X", "L1W", "L1P"),
    "D1": ("D1C", "D1X", "D1W", "D1P"),
    "S1": ("S1C", "S1X", "S1W", "S1P"),
}
_OBS_PREF2 = {"C1": ("C1", "P1"), "L1": ("L1",), "D1": ("D1",), "S1": ("S1",)}

#: Pseudorange code preference per system for RINEX 3 (first present wins).  The carrier phase,
#: Doppler and C/N0 are then taken on the same band (same attribute first).  GPS: L1 C/A (then
#: L1C, P(Y)); GLONASS: G1 C/A, then G1 P; Galileo: E1 (C pilot, B+C, B data); BeiDou: B1I
#: (C2I; C1I in RINEX 3.02), then B1I I+Q, then B3I (C6I; broadcast clocks refer to B3I, so no
#: group delay), then B2I.  B1C/B2a (C1P/C1X/C5X) have no group delay in the D1/D2 message and
#: are not chosen.  Override with ``read_rinex_obs(..., codes={"C": ("C6I",)})``.
OBS_CODE_PREFERENCE = {
    "G": ("C1C", "C1X", "C1W", "C1P"),
    "R": ("C1C", "C1P"),
    "E": ("C1C", "C1X", "C1B"),
    "C": ("C2I", "C1I", "C2X", "C2Q", "C6I", "C6X", "C7I"),
    "J": ("C1C", "C1X", "C1L", "C1S"),
}
#: RINEX 2 code -> the RINEX 3 code it corresponds to (for group delay and wavelength)
_RINEX2_AS_3 = {("G", "C1"): "C1C", ("G", "P1"): "C1W", ("R", "C1"): "C1C", ("R", "P1"): "C1P",
                ("E", "C1"): "C1X", ("E", "P1"): "C1X"}


@dataclass
class ObsData:
    """Observations of one signal per system in long format (one row per epoch and satellite).

    Attributes
    ----------
    path : str
    version : float
    codes : dict
        Which RINEX observation code was read for each of ``C1 L1 D1 S1``
        for GPS (None if absent from the file).
    epoch_t_gps_s : (n,) float
        Epoch times, GPS seconds since 1980-01-06 [s] (receiver time tags).
    epoch_week, epoch_tow : (n,)
        The same as GPS week and seconds of week [s].
    epoch_flag : (n,) int
        RINEX epoch flag (0 OK, 1 power failure, 6 cycle slips); event
        records (flags 2-5) are skipped and not listed.
    clock_offset_s : (n,) float
        Receiver clock offset field of the epoch line [s], NaN if blank.
    epoch : (m,) int
        Row -> index into the epoch arrays.
    t_gps_s, week, tow : (m,)
        Row time in the three conventions.
    prn : (m,) int
    C1, L1, D1, S1 : (m,) float
        Pseudorange [m], carrier phase [cycles], Doppler [Hz], C/N0 [dB-Hz]
        of the system's chosen signal (``codes_by_system``); NaN where missing (a pseudorange
        written as 0.0 too).
    approx_r_e : (3,) float or None
        ``APPROX POSITION XYZ`` from the header [m].
    system : (m,) str
        One-letter system of each row (all ``'G'`` unless other systems were asked for).
    codes_by_system : dict
        System letter -> ``{"C1": code, "L1": ..., "D1": ..., "S1": ...}`` as
        read from the file (RINEX 2 codes for RINEX 2 files).
    glonass_channels : dict
        GLONASS slot -> FDMA channel from the ``GLONASS SLOT / FRQ #`` header (RINEX 3).
    lli1 : (m,) int or None
        Loss-of-lock indicator of ``L1`` (bit 0: lost lock / possible cycle slip, bit 1:
        half-cycle ambiguity); 0 where blank or no phase.
    """

    path: str
    version: float
    codes: dict
    epoch_t_gps_s: np.ndarray
    epoch_week: np.ndarray
    epoch_tow: np.ndarray
    epoch_flag: np.ndarray
    clock_offset_s: np.ndarray
    epoch: np.ndarray
    t_gps_s: np.ndarray
    week: np.ndarray
    tow: np.ndarray
    prn: np.ndarray
    C1: np.ndarray
    L1: np.ndarray
    D1: np.ndarray
    S1: np.ndarray
    approx_r_e: np.ndarray | None = field(default=None)
    system: np.ndarray | None = None
    codes_by_system: dict = field(default_factory=dict)
    glonass_channels: dict = field(default_factory=dict)
    lli1: np.ndarray | None = None

    def __post_init__(self):
        if self.system is None:
            self.system = np.full(np.shape(self.prn), "G", dtype="<U1")
        # a pseudorange written as 0.0 is a missing one (RINEX writers use 0.0 or a blank field): taken
        # as a measurement, one satellite's 0 stopped every epoch it was in from solving
        C1 = np.asarray(self.C1, dtype=float)
        if np.any(C1 == 0.0):
            self.C1 = np.where(C1 == 0.0, np.nan, C1)
        if not self.codes_by_system:
            self.codes_by_system = {"G": dict(self.codes)}

    @property
    def sat_id(self) -> np.ndarray:
        """(m,) RINEX satellite identifiers ``'G05'``..."""
        from .systems import sat_id

        return sat_id(self.system, self.prn) if self.prn.size else np.zeros(0, "<U3")

    def pseudorange_code(self) -> np.ndarray:
        """(m,) RINEX 3 code of each row's pseudorange (RINEX 2 codes mapped: C1 -> C1C, P1 -> C1W/C1P)."""
        out = np.full(self.prn.shape, "", dtype="<U3")
        for s, cd in self.codes_by_system.items():
            c = cd.get("C1")
            if c is None:
                continue
            out[self.system == s] = _RINEX2_AS_3.get((s, c), c) if len(c) == 2 else c
        return out


    def wavelength_m(self, nav=None) -> np.ndarray:
        """(m,) carrier wavelength [m] of each row's signal, for Doppler -> range rate (``-lambda D1``).

        GLONASS rows use the FDMA channel of the satellite from ``nav`` (its
        latest record) or else from the ``GLONASS SLOT / FRQ #`` header; NaN
        where the channel is unknown.
        """
        from .broadcast import signal_wavelength

        k = np.zeros(self.prn.shape)
        glo = self.system == "R"
        if glo.any():
            ch = np.array([self.glonass_channels.get(int(p), -99) for p in self.prn[glo]], dtype=float)
            if nav is not None and len(nav.eph_r):
                from_nav = nav.eph_r.channel(self.prn[glo]).astype(float)
                ch = np.where(from_nav > -99, from_nav, ch)
            k[glo] = ch
        return signal_wavelength(self.system, self.pseudorange_code(), k)


def _choose_codes(s, stypes, rinex3, prefer=None):
    """{key: code or None} of system ``s`` given its list of observation types."""
    if not rinex3:
        return {k: next((c for c in cands if c in stypes), None) for k, cands in _OBS_PREF2.items()}
    if s == "G" and prefer is None:
        return {k: next((c for c in cands if c in stypes), None) for k, cands in _OBS_PREF3.items()}
    cands = prefer if prefer is not None else OBS_CODE_PREFERENCE.get(s, ())
    c1 = next((c for c in cands if c in stypes), None)
    out = {"C1": c1}
    for key in ("L1", "D1", "S1"):
        if c1 is None:
            out[key] = None
            continue
        same = key[0] + c1[1:]
        band = [c for c in stypes if c[0] == key[0] and c[1] == c1[1]]
        out[key] = same if same in stypes else (band[0] if band else None)
    return out


#: The time system of a blank ``TIME OF FIRST OBS`` field by the file's satellite system (RINEX 3.05
#: Table A2, RINEX 2.11 Table A1: compulsory in mixed files; the default of a single-system file is that
#: system's time; GLO is UTC).
DEFAULT_TIME_SYSTEM = {"G": "GPS", " ": "GPS", "M": "GPS", "R": "GLO", "E": "GAL", "C": "BDT", "J": "QZS",
                       "I": "IRN", "S": "GPS"}
#: Time systems read as GPS time: GST and QZSST are steered to GPS time (offsets of nanoseconds).
GPS_ALIGNED_TIME_SYSTEMS = ("GPS", "GAL", "QZS")


def _time_system_error(ts: str, written: bool, sysc: str) -> str:
    """The message refusing time system ``ts`` (``written``: in the header; else the file type's default)."""
    why = "" if written else (f" (the default of a RINEX file of system {sysc!r} whose TIME OF FIRST OBS leaves "
                              "the time system blank)")
    return (f"unsupported time system {ts!r}{why}: the epochs are read as GPS time (GPS, GAL or QZS); "
            "convert the file to GPS time")


def _obs_header_fields(src, header, sysc=" "):
    """The station fields of an observation header: (approx, hen, glo_k).

    approx: ``APPROX POSITION XYZ`` [m, ECEF] or None; hen: ``ANTENNA: DELTA H/E/N``
    [m] (zeros when absent); glo_k: GLONASS slot -> FDMA frequency number from
    ``GLONASS SLOT / FRQ #``.  Raises on a ``TIME OF FIRST OBS`` time system not in
    :data:`GPS_ALIGNED_TIME_SYSTEMS`, a blank one standing for the default of the file's
    system ``sysc`` (:data:`DEFAULT_TIME_SYSTEM`; RINEX 3.04 section 5.2, table A2).
    """
    approx, hen, glo_k = None, np.zeros(3), {}
    for lineno, text, label in header:
        if label == "APPROX POSITION XYZ":
            approx = np.array([_float(src, text[14 * k:14 * (k + 1)], label, lineno=lineno) for k in range(3)])
        elif label == "ANTENNA: DELTA H/E/N":
            hen = np.array([_float(src, text[14 * k:14 * (k + 1)], label, 0.0, lineno=lineno) for k in range(3)])
        elif label == "TIME OF FIRST OBS":
            ts = text[48:51].strip()
            eff = ts or DEFAULT_TIME_SYSTEM.get(sysc, "GPS")
            if eff not in GPS_ALIGNED_TIME_SYSTEMS:
                raise src.error(_time_system_error(eff, bool(ts), sysc), lineno)
        elif label == "GLONASS SLOT / FRQ #":
            for k in range(8):
                sl, fr = text[4 + 7 * k:7 + 7 * k], text[8 + 7 * k:10 + 7 * k]
                if sl[:1] == "R" and sl[1:].strip():
                    glo_k[_int(src, sl[1:], "GLONASS slot", lineno)] = _int(src, fr, "GLONASS frequency number",
                                                                              lineno)
    return approx, hen, glo_k


def _obs_types_header(src, header, version, check=""):
    """Return {system letter: [codes]} from the header.

    For RINEX 3, the systems in ``check`` must list as many types as they announce.
    """
    types = {}
    if version >= 3:
        cur_sys, cur_n = None, 0
        announced = {}
        for lineno, text, label in header:
            if label != "SYS / # / OBS TYPES":
                continue
            if text[0] != " ":
                cur_sys = text[0]
                cur_n = _int(src, text[3:6], "number of observation types", lineno) if text[3:6].strip() else None
                if cur_n is None:
                    raise src.error("malformed header: SYS / # / OBS TYPES without a count", lineno)
                types[cur_sys] = []
                announced[cur_sys] = (cur_n, lineno)
            elif cur_sys is None:
                raise src.error("malformed header: SYS / # / OBS TYPES continuation without a system", lineno)
            for k in range(13):
                c = text[7 + 4 * k:10 + 4 * k].strip()
                if c and len(types[cur_sys]) < cur_n:
                    types[cur_sys].append(c)
        for sy in check:
            if sy in announced and len(types[sy]) != announced[sy][0]:
                raise src.error(f"malformed header: SYS / # / OBS TYPES of {sy} announces {announced[sy][0]} "
                                f"types, lists {len(types[sy])}", announced[sy][1])
    else:
        n, codes = None, []
        for lineno, text, label in header:
            if label != "# / TYPES OF OBSERV":
                continue
            if text[:6].strip():
                n = _int(src, text[:6], "number of observation types", lineno)
                codes = []
            elif n is None:
                raise src.error("malformed header: # / TYPES OF OBSERV continuation before the count", lineno)
            for k in range(9):
                c = text[10 + 6 * k:12 + 6 * k].strip()
                if c and len(codes) < n:
                    codes.append(c)
        if n is None:
            raise src.error("malformed header: no # / TYPES OF OBSERV")
        if len(codes) != n:
            raise src.error(f"malformed header: # / TYPES OF OBSERV announces {n} types, lists {len(codes)}")
        types = {"G": codes}
    return types


def warn_repeated_epochs(path, n: int, first_line: int) -> None:
    """One :class:`insnav.errors.InsnavWarning` when ``n`` epochs of ``path`` repeated the time of the epoch
    before them (a merge of overlapping files, a logger writing an epoch twice): the readers keep the first
    and skip the repeats whole, as RTKLIB's ``sortobs`` keeps one observation per satellite and time."""
    if n:
        import warnings

        from ..errors import InsnavWarning

        warnings.warn(f"{path}, line {first_line}: this epoch repeats the time of the one before it"
                      f"{f' (and {n - 1} more epochs do)' if n > 1 else ''}; the first is kept, the repeats skipped",
                      InsnavWarning, stacklevel=3)


def _check_event_types(src, records, version, types, ep_line):
    """Refuse an event whose special records re-declare different observation types.

    Epoch flag 4 is followed by header lines (RINEX 3.05 Sec. 5.2.1, RINEX 2.11 Sec. 7.7). The
    records after it are read with the header's columns, so a changed list would misread every
    field; a repeat of the header's own list is accepted.
    """
    label = "SYS / # / OBS TYPES" if version >= 3 else "# / TYPES OF OBSERV"
    declared = [r for r in records if r[2] == label]
    if not declared:
        return
    try:
        new = _obs_types_header(src, declared, version)
    except RinexError:
        new = None
    if not new:
        raise src.error(f"the event on line {ep_line} re-declares the observation types without a system or count",
                        declared[0][0])
    for s, v in new.items():
        if types.get(s) != v:
            raise src.error(f"the event on line {ep_line} re-declares the observation types of {s} (not supported: "
                            f"the records after it would be misread); split the file before line {ep_line}",
                            declared[0][0])


def read_rinex_obs(path, systems="G", codes=None) -> ObsData:
    """Read one signal's observations (pseudorange, phase, Doppler, C/N0) per system from RINEX 2.x / 3.x.

    Parameters
    ----------
    path : str or PathLike
        RINEX 2.10/2.11 or 3.02-3.05 observation file (GPS or mixed).
    systems : str
        Systems to read, letters of ``"GRECJ"``; the default ``"G"`` reads GPS
        only (the behaviour before multi-GNSS).  RINEX 2.11 mixed files carry
        G, R (and E) satellites with one list of types for all.
    codes : dict, optional
        System letter -> tuple of pseudorange codes in order of preference,
        overriding :data:`OBS_CODE_PREFERENCE` (RINEX 3 only).

    Returns
    -------
    ObsData
        Long-format arrays; see :class:`ObsData`.  For RINEX 3 GPS the code
        read is the first present of C1C, C1X, C1W, C1P (likewise L/D/S); the
        other systems follow :data:`OBS_CODE_PREFERENCE` (phase, Doppler and
        C/N0 then on the same band); for RINEX 2 ``C1`` (else ``P1``), ``L1``,
        ``D1``, ``S1``.  ``system`` names each row's system,
        ``codes_by_system`` the codes read.  Doppler stays in Hz: GLONASS rows
        need their FDMA wavelength (:func:`insnav.gnss.broadcast.signal_wavelength`).

    Raises
    ------
    RinexError
        Malformed header (e.g. fewer observation types than announced for a
        requested system), bad epoch or observation record, unexpected end of
        file; the message names the file and the 1-based line number.
    ValueError
        ``systems`` has a letter other than G, R, E, C, J.

    Notes
    -----
    The header is parsed here, the records by the compiled reader
    (``insnav/io/rinex3_obs.hpp``), which gives the same numbers as the
    Python records parser kept as the reference of the tests, to the last
    bit: the same fields, the same decimal-to-binary conversion (correctly
    rounded in both) and the same time arithmetic.
    """
    return _read_obs(path, systems, codes, compiled=True)


def _header_end(raw: bytes):
    """(byte offset after the ``END OF HEADER`` line, number of header lines), or None if absent."""
    pos, n = 0, 0
    while True:
        nl = raw.find(b"\n", pos)
        end = len(raw) if nl < 0 else nl + 1
        n += 1
        if raw[pos:end][60:].strip() == b"END OF HEADER":
            return end, n
        if nl < 0 or n > 10000:
            return None
        pos = end


def _core_rinex_error(path, exc) -> RinexError:
    """The compiled readers' ``"<file>, line <n>: <what>"`` as a :class:`RinexError`."""
    msg = str(exc)
    line = None
    if ", line " in msg:
        try:
            line = int(msg.split(", line ", 1)[1].split(":", 1)[0])
        except ValueError:
            line = None
    what = msg.split(": ", 1)[1] if ": " in msg else msg
    return RinexError(path, line, what)


def _read_obs(path, systems="G", codes=None, compiled=True) -> ObsData:
    """:func:`read_rinex_obs`; ``compiled=False`` parses the records in Python (the tests' reference)."""
    want = _parse_systems(systems)
    raw = head = None
    if compiled:
        from ..data.textio import read_bytes

        try:
            raw = read_bytes(path)
        except OSError as exc:
            raise RinexError(os.fspath(path), None, f"cannot read file ({exc.strerror})") from exc
        head = _header_end(raw)
    if head is not None:
        src = _Lines(path, raw[:head[0]].decode("ascii", "replace").splitlines())
    else:
        src = _Lines(path, None if raw is None else raw.decode("ascii", "replace").splitlines())
    header = _read_header(src)
    version, ftype, sysc = _version_type(src, header)
    if ftype != "O":
        raise src.error(f"malformed header: not an observation file (type {ftype!r})", header[0][0])
    approx, _, glo_k = _obs_header_fields(src, header, sysc)
    rinex3 = version >= 3
    types = _obs_types_header(src, header, version, check=want if rinex3 else "")
    # RINEX 2: one list of types for every system
    sys_types = {s: types.get(s if rinex3 else "G", []) for s in want}
    prefer = {} if codes is None else {k.upper(): tuple(v) if not isinstance(v, str) else (v,)
                                       for k, v in codes.items()}
    codes_by_sys, cols_by_sys = {}, {}
    for s in want:
        cs = _choose_codes(s, sys_types[s], rinex3, prefer.get(s) if rinex3 else None)
        codes_by_sys[s] = cs
        cols_by_sys[s] = {k: (sys_types[s].index(c) if c else None) for k, c in cs.items()}
    gcodes = codes_by_sys.get("G") or _choose_codes("G", types.get("G", []), rinex3)
    keys = tuple(_OBS_PREF3)
    ntypes = {s: len(v) for s, v in types.items()}
    if head is not None:
        return _obs_from_core(src.path, version, raw, (head[0], src.i), types, want, codes_by_sys, gcodes,
                              approx, glo_k)

    ep_t, ep_flag, ep_clk = [], [], []
    repeated = [0, 0]  # epochs at the time of the one kept before them, the line of the first
    r_ep, r_prn, r_sys = [], [], []
    r_val = {k: [] for k in keys}
    r_lli = []

    def lli_of(txt_line, start):
        c = txt_line[start + 14:start + 15]
        return int(c) if c.isdigit() else 0

    def parse_sat(line, s, sat_prn, ep_index):
        r_ep.append(ep_index)
        r_prn.append(sat_prn)
        r_sys.append(s)
        base = 3
        for key, col in cols_by_sys[s].items():
            if col is None:
                r_val[key].append(math.nan)
                if key == "L1":
                    r_lli.append(0)
                continue
            txt = line[base + 16 * col: base + 16 * col + 14]
            r_val[key].append(_float(src, txt, f"observation {codes_by_sys[s][key]}"))
            if key == "L1":
                r_lli.append(lli_of(line, base + 16 * col))

    while not src.eof():
        line = src.next()
        if not line.strip():
            continue
        ep_line = src.lineno
        if rinex3:
            if line[0] != ">":
                raise src.error("bad record: expected an epoch line starting with '>'")
            try:
                flag = int(line[31:32]); nsat = int(line[32:35])
                if flag in (2, 3, 4, 5):  # RINEX 3.05 Table A13: an event's date may be blank
                    y = mo = d = 1; h = mi = 0; sec = 0.0
                else:
                    y = int(line[2:6]); mo = int(line[7:9]); d = int(line[10:12])
                    h = int(line[13:15]); mi = int(line[16:18]); sec = float(line[18:29])
            except ValueError:
                raise src.error(f"bad record: cannot parse epoch line {line[:35]!r}") from None
            clk = _float(src, line[41:56], "receiver clock offset")
        else:
            try:
                flag = int(line[28:29])
                nsat = int(line[29:32])
            except ValueError:
                raise src.error(f"bad record: cannot parse epoch flag / satellite count {line[26:32]!r}") from None
            if flag in (2, 3, 4, 5):
                y = mo = d = 1; h = mi = 0; sec = 0.0
            else:
                try:
                    y = int(line[1:3]); mo = int(line[4:6]); d = int(line[7:9])
                    h = int(line[10:12]); mi = int(line[13:15]); sec = float(line[15:26])
                except ValueError:
                    raise src.error(f"bad record: cannot parse epoch line {line[:32]!r}") from None
                y += 2000 if y < 80 else 1900
            clk = _float(src, line[68:80], "receiver clock offset")
        if flag > 6 or nsat < 0:
            raise src.error(f"bad record: epoch flag {flag} / count {nsat} out of range")
        if flag in (2, 3, 4, 5):
            # Event: nsat special records (header lines) follow.
            records = []
            for _ in range(nsat):
                rec = src.next(f"the special records of the event on line {ep_line}")
                records.append((src.lineno, rec[:60].ljust(60), rec[60:].strip()))
            _check_event_types(src, records, version, types, ep_line)
            continue
        if not (1 <= mo <= 12 and 1 <= d <= 31 and 0 <= h <= 23 and 0 <= mi <= 59 and 0 <= sec < 61):
            raise src.error("bad record: impossible epoch date/time")
        t = gps_seconds_from_calendar(y, mo, d, h, mi, sec)
        keep = flag in (0, 1)
        if keep and ep_t and t == ep_t[-1]:  # the time of the epoch kept before it: skipped (warn_repeated_epochs)
            keep = False
            repeated[0] += 1
            repeated[1] = repeated[1] or ep_line
        e_idx = len(ep_t)
        if rinex3:
            for _ in range(nsat):
                sl = src.next(f"the satellites of the epoch on line {ep_line}")
                if sl[:1] == ">":
                    raise src.error(f"bad record: epoch on line {ep_line} announces {nsat} satellites, found fewer")
                sid = sl[:3]
                s = sid[0]
                if s not in ntypes:
                    raise src.error(f"bad record: satellite {sid!r} of an undeclared system")
                if s in want and keep:
                    parse_sat(sl, s, _int(src, sid[1:3], "satellite number"), e_idx)
        else:
            sats = []
            text = line[32:68]
            while True:
                for k in range(12):
                    sid = text[3 * k:3 * k + 3]
                    if sid.strip():
                        sats.append(sid)
                if len(sats) >= nsat:
                    break
                cl = src.next(f"the satellite list of the epoch on line {ep_line}")
                text = cl[32:68]
            if len(sats) != nsat:
                raise src.error(f"bad record: epoch on line {ep_line} announces {nsat} satellites, lists {len(sats)}")
            nlines = max(1, (ntypes["G"] + 4) // 5)
            for sid in sats:
                s = sid[0] if sid[0] != " " else "G"
                obs_lines = [src.next(f"the observations of the epoch on line {ep_line}") for _ in range(nlines)]
                if s in want and keep:
                    prn = _int(src, sid[1:3], "satellite number")
                    # assemble the obs of the requested columns line by line
                    r_ep.append(e_idx)
                    r_prn.append(prn)
                    r_sys.append(s)
                    for key, col in cols_by_sys[s].items():
                        if col is None:
                            r_val[key].append(math.nan)
                            if key == "L1":
                                r_lli.append(0)
                            continue
                        ol = obs_lines[col // 5]
                        txt = ol[16 * (col % 5):16 * (col % 5) + 14]
                        if key == "L1":
                            r_lli.append(lli_of(ol, 16 * (col % 5)))
                        r_val[key].append(_float(src, txt, f"observation {codes_by_sys[s][key]}",
                                                 lineno=src.lineno - nlines + 1 + col // 5))
        if keep:
            ep_t.append(t)
            ep_flag.append(flag)
            ep_clk.append(clk)

    warn_repeated_epochs(src.path, *repeated)
    ep_t = np.asarray(ep_t, dtype=float)
    e = np.asarray(r_ep, dtype=np.int64)
    wk, tw = week_tow(ep_t)
    wk, tw = np.atleast_1d(wk), np.atleast_1d(tw)
    return ObsData(
        path=src.path, version=version, codes=dict(gcodes),
        epoch_t_gps_s=ep_t, epoch_week=wk, epoch_tow=tw,
        epoch_flag=np.asarray(ep_flag, dtype=np.int64), clock_offset_s=np.asarray(ep_clk, dtype=float),
        epoch=e, t_gps_s=ep_t[e], week=wk[e], tow=tw[e], prn=np.asarray(r_prn, dtype=np.int64),
        C1=np.asarray(r_val["C1"], dtype=float), L1=np.asarray(r_val["L1"], dtype=float),
        D1=np.asarray(r_val["D1"], dtype=float), S1=np.asarray(r_val["S1"], dtype=float), approx_r_e=approx,
        system=np.asarray(r_sys, dtype="<U1"), codes_by_system=codes_by_sys, glonass_channels=glo_k,
        lli1=np.asarray(r_lli, dtype=np.int64),
    )


def _obs_from_core(path, version, raw, head, types, want, codes_by_sys, gcodes, approx, glo_k) -> ObsData:
    """The records of a RINEX 2 or 3 file (header parsed) through ``insnav._core.read_rinex3_obs_body``."""
    from .. import _core

    select = {s: [codes_by_sys[s][k] or "" for k in _OBS_PREF3] for s in want}
    try:  # a 0.0 stays 0.0, as in the Python records parser
        d = _core.read_rinex3_obs_body(raw, path, head[0], head[1], types, select, False, version < 3)
    except RuntimeError as exc:
        raise _core_rinex_error(path, exc) from None
    warn_repeated_epochs(path, d["n_repeated_epochs"], d["first_repeated_line"])
    ep_t = np.asarray(d["epoch_t_gps_s"], dtype=float)
    e = np.asarray(d["row_epoch"], dtype=np.int64)
    obs = np.asarray(d["obs"])
    wk, tw = week_tow(ep_t)
    wk, tw = np.atleast_1d(wk), np.atleast_1d(tw)
    row_sys = np.asarray(d["row_sys"])
    system = row_sys.astype(np.uint8).view("S1").astype("<U1") if row_sys.size else np.zeros(0, "<U1")
    lli = obs[:, 4]
    return ObsData(
        path=path, version=version, codes=dict(gcodes),
        epoch_t_gps_s=ep_t, epoch_week=wk, epoch_tow=tw,
        epoch_flag=np.asarray(d["epoch_flag"], dtype=np.int64),
        clock_offset_s=np.asarray(d["epoch_clock_s"], dtype=float),
        epoch=e, t_gps_s=ep_t[e], week=wk[e], tow=tw[e], prn=np.asarray(d["row_prn"], dtype=np.int64),
        C1=obs[:, 0].copy(), L1=obs[:, 1].copy(), D1=obs[:, 2].copy(), S1=obs[:, 3].copy(), approx_r_e=approx,
        system=system, codes_by_system=codes_by_sys, glonass_channels=glo_k,
        lli1=np.where(np.isfinite(lli), lli, 0).astype(np.int64),
    )


# The multi-file entry points of the GNSS-only filters (SPP, RTK) live beside the readers they call, so
# that RTK does not import the SPP module for them.

def _reads_systems() -> bool:
    import inspect

    return "systems" in inspect.signature(read_rinex_obs).parameters


def read_obs_multi(path, systems="GREC"):
    """ObsData of the ``systems`` (a GPS-only reader: GPS)."""
    return read_rinex_obs(path, systems="".join(systems)) if _reads_systems() else read_rinex_obs(path)


def read_nav_multi(paths, systems="GREC"):
    """NavData of one or more navigation files (merged; e.g. a RINEX 2 ``.n`` and ``.g`` pair).

    A single-system RINEX 3 file of none of ``systems`` is skipped (the Galileo file of a GPS +
    Galileo pair in a GPS-only run); it is an error only when no file has the systems asked for."""
    if isinstance(paths, (str, bytes)) or not hasattr(paths, "__iter__"):
        paths = [paths]
    nav, other = None, None
    for p in paths:
        try:
            n = read_rinex_nav(p, systems="".join(systems)) if _reads_systems() else read_rinex_nav(p)
        except _NavOfOtherSystems as exc:  # e.g. the Galileo file of a GPS + Galileo pair in a GPS-only run
            other = other or exc
            continue
        if nav is None:
            nav = n
        elif hasattr(nav, "merge"):
            nav = nav.merge(n)
        else:
            raise ValueError(f"{p}: this navigation reader cannot merge files; give one navigation file")
    if nav is None and other is not None:
        raise other  # no file of the systems asked for
    return nav
