"""RINEX 3.04 writers: observation files and GPS/Galileo navigation files.

Written so that simulated data (:mod:`insnav.sim.gnss_rtk`) can be processed
by RTKLIB, GICI-LIB or any other RINEX reader, and read back by
:func:`insnav.gnss.rinex.read_rinex_obs` / :func:`~insnav.gnss.rinex.read_rinex_nav`.

Precision (what a round trip can reproduce)
-------------------------------------------
* observations: ``F14.3`` (RINEX 3.04, 5.7): pseudorange to 1 mm, carrier
  phase to 1e-3 cycle (0.19 mm on L1), Doppler to 1e-3 Hz, C/N0 to 1e-3 dB-Hz;
  loss-of-lock indicator (LLI) and signal strength indicator (SSI) one digit each;
* navigation: every orbit and clock parameter as ``D19.12`` (12 significant
  digits, written with an ``E`` exponent, which RINEX readers accept);
  epochs (``toc``) to the whole second.

:func:`rinex_representable` turns a table of broadcast elements into one a
navigation file holds *exactly* (``toc``/``toe`` on whole seconds, ``t_oe``
the seconds of week of ``toe``, every value rounded to 12 digits) describing
the same orbit, so a simulator can use the very ephemeris it writes.

Reference: IGS/RTCM RINEX WG, *RINEX: The Receiver Independent Exchange
Format*, version 3.04 (2018), sections 5 (observation files), 6 and Tables
A6-A8 (GPS) / A10 (Galileo) (navigation files).
"""
from __future__ import annotations

import datetime as _dt
import math
import os
from pathlib import Path

import numpy as np

from .ephemeris import GM_GPS, OMEGA_E_DOT
from .gpstime import SECONDS_PER_WEEK

__all__ = ["gps_calendar", "rereference", "rinex_representable", "elements_for_system", "write_rinex_nav", "write_rinex_obs",
           "RINEX_VERSION"]

RINEX_VERSION = 3.04
_GPS_EPOCH = _dt.datetime(1980, 1, 6)
_PGM = "insnav"


def gps_calendar(t_gps_s: float):
    """GPS time [s since 1980-01-06] -> (year, month, day, hour, minute, second [s, float])."""
    whole = math.floor(t_gps_s)
    frac = t_gps_s - whole
    d = _GPS_EPOCH + _dt.timedelta(seconds=int(whole))
    return d.year, d.month, d.day, d.hour, d.minute, d.second + frac


def _d19(v: float) -> str:
    """One ``D19.12`` field (``E`` exponent)."""
    s = f"{float(v): .12E}"
    if len(s) > 19:  # three-digit exponents never occur for navigation values; guard anyway
        raise ValueError(f"navigation value {v!r} does not fit D19.12")
    return s.rjust(19)


def _q12(a) -> np.ndarray:
    """Round to what ``D19.12`` holds (12 significant digits)."""
    a = np.asarray(a, dtype=float)
    return np.array([float(f"{x:.12E}") for x in a.ravel()]).reshape(a.shape)


def elements_for_system(cols: dict, gm: float, omega_e: float) -> dict:
    """Re-express elements evaluated with the GPS constants for a system with ``gm``, ``omega_e``.

    The IS-GPS-200 Table 20-IV orbit depends on the constants only through
    the mean motion ``n = sqrt(GM / A^3) + delta_n`` and the node
    ``Omega_k = Omega_0 + (Omega_dot - Omega_e) t_k - Omega_e t_oe``; with
    ``delta_n' = delta_n + sqrt(GM_GPS/A^3) - sqrt(GM/A^3)``,
    ``Omega_dot' = Omega_dot - OMEGA_GPS + Omega_e`` and
    ``Omega_0' = Omega_0 + (Omega_e - OMEGA_GPS) t_oe`` a reader using the
    system's constants computes the same positions and velocities (the
    relativistic clock term ``F e sqrt(A) sin E`` changes with ``F`` only
    where ``e > 0``; the nominal Walker sets are circular).
    """
    out = {k: np.array(v, copy=True) for k, v in cols.items()}
    a3 = np.asarray(cols["sqrt_a"], float) ** 6
    out["delta_n"] = cols["delta_n"] + np.sqrt(GM_GPS / a3) - np.sqrt(gm / a3)
    out["omega_dot"] = cols["omega_dot"] - OMEGA_E_DOT + omega_e
    out["omega0"] = cols["omega0"] + (omega_e - OMEGA_E_DOT) * cols["toe_sow"]
    return out


def rereference(cols: dict, toe_new, toc_new=None, omega_e: float = OMEGA_E_DOT, gm: float = GM_GPS) -> dict:
    """The same orbit and clock written about new reference times (exact, no rounding).

    ``d = toe' - toe``: ``M_0' = M_0 + n d``, ``i_0' = i_0 + IDOT d``,
    ``Omega_0' = Omega_0 + (Omega_dot - Omega_e) d + Omega_e (t_oe' - t_oe)``
    with ``t_oe'`` the seconds of week of ``toe'`` (IS-GPS-200 Table 20-IV: the
    harmonic corrections depend on the argument of latitude only, so they
    stay); the clock polynomial is re-expanded about ``toc'`` (default: ``toe'``
    moved by the same amount as ``toe``).  Every time of the model is then the
    same function of ``t``, so several records of one satellite at different
    ``toe'`` describe one continuous orbit (a navigation file longer than the
    4 h fit interval).

    Parameters
    ----------
    cols : dict
        Columns of :class:`insnav.gnss.ephemeris.Ephemerides` (or its Galileo
        subclass); ``toe``/``toc`` continuous GPS seconds.
    toe_new, toc_new : float or (n,) array [GPS s]
    omega_e, gm : float
        The constants the orbit is evaluated with (GPS by default).
    """
    c = {k: np.array(v, dtype=float if k != "prn" else np.int64, copy=True) for k, v in cols.items()}
    toe_new = np.broadcast_to(np.asarray(toe_new, float), c["toe"].shape).copy()
    d = toe_new - c["toe"]
    toc_new = c["toc"] + d if toc_new is None else np.broadcast_to(np.asarray(toc_new, float), c["toc"].shape).copy()
    n = np.sqrt(gm / c["sqrt_a"] ** 6) + c["delta_n"]
    toe_sow_new = np.mod(toe_new, SECONDS_PER_WEEK)
    c["m0"] = np.mod(c["m0"] + n * d + np.pi, 2 * np.pi) - np.pi
    c["i0"] = c["i0"] + c["idot"] * d
    c["omega0"] = c["omega0"] + (c["omega_dot"] - omega_e) * d + omega_e * (toe_sow_new - c["toe_sow"])
    c["omega0"] = np.mod(c["omega0"] + np.pi, 2 * np.pi) - np.pi
    c["toe"], c["toe_sow"] = toe_new, toe_sow_new
    c["week"] = np.floor(toe_new / SECONDS_PER_WEEK)
    dc = toc_new - c["toc"]
    c["af0"] = c["af0"] + c["af1"] * dc + c["af2"] * dc ** 2
    c["af1"] = c["af1"] + 2.0 * c["af2"] * dc
    c["toc"] = toc_new
    return c


def rinex_representable(cols: dict, omega_e: float = OMEGA_E_DOT, gm: float = GM_GPS) -> dict:
    """Broadcast elements a RINEX navigation file holds exactly, describing the same orbit and clock.

    :func:`rereference` to ``toe' = round(toe)``, ``toc' = round(toc)`` (the
    node term ``- Omega_e t_oe`` of IS-GPS-200 Table 20-IV uses the broadcast
    seconds of week, which a re-referenced nominal set no longer matches: it
    is made the seconds of week of ``toe'``), then every value rounded to 12
    significant digits (``D19.12``).

    Parameters
    ----------
    cols : dict
        Columns of :class:`insnav.gnss.ephemeris.Ephemerides` (or its Galileo subclass).
    omega_e, gm : float
        The constants the orbit is evaluated with (GPS by default).

    Returns
    -------
    dict
        New columns; ``week`` is the GPS week of ``toe'``.
    """
    c = rereference(cols, np.round(np.asarray(cols["toe"], float)), np.round(np.asarray(cols["toc"], float)),
                    omega_e, gm)
    for k in ("af0", "af1", "af2", "crs", "delta_n", "m0", "cuc", "e", "cus", "sqrt_a", "cic", "omega0", "cis", "i0",
              "crc", "omega", "omega_dot", "idot", "sv_accuracy", "tgd", "tgd2", "iode", "iodc", "health"):
        if k in c:
            c[k] = _q12(c[k])
    return c


def _atomic_write(path, text: str) -> Path:
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text, encoding="ascii")
    os.replace(tmp, path)
    return path


def _hline(text: str, label: str) -> str:
    return f"{text:<60.60}{label:<20}\n"


def _pgm_line() -> str:
    now = _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%d %H%M%S UTC")
    return _hline(f"{_PGM:<20}{'insnav':<20}{now:<20}", "PGM / RUN BY / DATE")


def write_rinex_nav(path, eph_g=None, eph_e=None, *, ion_alpha=None, ion_beta=None, leap_seconds: int = 18,
                    comment: str = "") -> Path:
    """Write a RINEX 3.04 navigation file with GPS LNAV and Galileo I/NAV records.

    Parameters
    ----------
    path : str or Path
    eph_g : Ephemerides, optional
        GPS records (continuous ``toc``/``toe`` in GPS seconds).  Pass them
        through :func:`rinex_representable` first for an exact round trip.
    eph_e : KeplerEphemerides, optional
        Galileo records with Galileo constants (:func:`elements_for_system`);
        ``data_source`` is written as given (513: I/NAV E1-B, clock E5b/E1).
    ion_alpha, ion_beta : (4,) array_like, optional
        Klobuchar coefficients (``IONOSPHERIC CORR`` GPSA/GPSB).
    leap_seconds : int
        GPS - UTC [s] for the header (18 since 2017).
    comment : str
        One ``COMMENT`` line.

    Returns
    -------
    Path
    """
    has_g = eph_g is not None and len(eph_g) > 0
    has_e = eph_e is not None and len(eph_e) > 0
    if not (has_g or has_e):
        raise ValueError(f"write_rinex_nav {path}: no GPS or Galileo records to write")
    sysc = "M" if (has_g and has_e) else ("G" if has_g else "E")
    out = [_hline(f"{RINEX_VERSION:9.2f}{'':11}{'N: GNSS NAV DATA':<20}{sysc:<20}", "RINEX VERSION / TYPE"),
           _pgm_line()]
    if comment:
        out.append(_hline(comment, "COMMENT"))
    if ion_alpha is not None and ion_beta is not None:
        for name, v in (("GPSA", ion_alpha), ("GPSB", ion_beta)):
            out.append(_hline(f"{name} " + "".join(f"{x:12.4E}" for x in v), "IONOSPHERIC CORR"))
    out.append(_hline(f"{int(leap_seconds):6d}", "LEAP SECONDS"))
    out.append(_hline("", "END OF HEADER"))

    def record(sysid, e, i, lines5_7):
        y, mo, d, h, mi, s = gps_calendar(float(e.toc[i]))
        if abs(s - round(s)) > 1e-6:
            raise ValueError(f"write_rinex_nav {path}: {sysid}{int(e.prn[i]):02d} toc is not on a whole second "
                             "(use rinex_representable)")
        rec = [f"{sysid}{int(e.prn[i]):02d} {y:4d} {mo:02d} {d:02d} {h:02d} {mi:02d} {int(round(s)):02d}"
               + _d19(e.af0[i]) + _d19(e.af1[i]) + _d19(e.af2[i]) + "\n"]
        rows = [(e.iode[i], e.crs[i], e.delta_n[i], e.m0[i]),
                (e.cuc[i], e.e[i], e.cus[i], e.sqrt_a[i]),
                (e.toe_sow[i], e.cic[i], e.omega0[i], e.cis[i]),
                (e.i0[i], e.crc[i], e.omega[i], e.omega_dot[i])] + lines5_7
        for r in rows:
            rec.append("    " + "".join(_d19(v) for v in r) + "\n")
        return "".join(rec)

    if has_g:
        e = eph_g
        for i in np.argsort(e.prn * 1e10 + e.toc, kind="stable"):
            week = math.floor(e.toe[i] / SECONDS_PER_WEEK)
            fit_h = float(e.fit_s[i]) / 3600.0 if np.isfinite(e.fit_s[i]) else 4.0
            out.append(record("G", e, i, [(e.idot[i], 1.0, week, 0.0),
                                          (e.sv_accuracy[i], e.health[i], e.tgd[i], e.iodc[i]),
                                          (float(np.mod(e.toc[i], SECONDS_PER_WEEK)), fit_h)]))
    if has_e:
        e = eph_e
        for i in np.argsort(e.prn * 1e10 + e.toc, kind="stable"):
            week = math.floor(e.toe[i] / SECONDS_PER_WEEK)  # GAL week in RINEX is aligned with the GPS week
            out.append(record("E", e, i, [(e.idot[i], e.data_source[i], week, 0.0),
                                          (e.sv_accuracy[i], e.health[i], e.tgd[i], e.tgd2[i]),
                                          (float(np.mod(e.toc[i], SECONDS_PER_WEEK)),)]))
    return _atomic_write(path, "".join(out))


def write_rinex_obs(path, *, t_gps_s, epoch, sat_id, obs_types: dict, values: dict, lli: dict | None = None,
                    ssi: dict | None = None, marker_name: str = "SIM", approx_r_e=None, interval_s: float | None = None,
                    receiver: str = "insnav simulator", antenna: str = "SIM", comment: str = "") -> Path:
    """Write a RINEX 3.04 observation file (GPS time tags).

    Parameters
    ----------
    path : str or Path
    t_gps_s : (n,) float
        Epoch time tags [GPS s since 1980-01-06], increasing.
    epoch : (m,) int
        Row -> epoch index (rows of one epoch contiguous or not; written sorted by satellite).
    sat_id : (m,) str
        RINEX satellite identifiers ``'G05'``, ``'E11'``.
    obs_types : dict
        System letter -> list of RINEX 3 observation codes (``['C1C', 'L1C', 'D1C', 'S1C']``).
    values : dict
        System letter -> (m_s, len(obs_types[s])) array of that system's rows (in
        row order of ``sat_id == s``); NaN = missing (written blank).  Units:
        pseudorange [m], phase [cycles], Doppler [Hz], C/N0 [dB-Hz].
    lli, ssi : dict, optional
        Same layout, integers 0-9 (0 written as blank for LLI).
    marker_name : str
    approx_r_e : (3,) float, optional
        ``APPROX POSITION XYZ`` [m] (a base station's known position).
    interval_s : float, optional
        ``INTERVAL`` [s].

    Returns
    -------
    Path
    """
    t = np.asarray(t_gps_s, float)
    epoch = np.asarray(epoch, np.int64)
    sat_id = np.asarray(sat_id, dtype="<U3")
    systems = [s for s in "GREC" if s in obs_types]
    for s in np.unique(np.array([x[0] for x in sat_id])) if sat_id.size else []:
        if s not in obs_types:
            raise ValueError(f"write_rinex_obs {path}: rows of system {s} but no obs_types for it")
    sysc = systems[0] if len(systems) == 1 else "M"
    out = [_hline(f"{RINEX_VERSION:9.2f}{'':11}{'OBSERVATION DATA':<20}{sysc:<20}", "RINEX VERSION / TYPE"),
           _pgm_line()]
    if comment:
        out.append(_hline(comment, "COMMENT"))
    out.append(_hline(marker_name, "MARKER NAME"))
    out.append(_hline(f"{'insnav':<20}{'insnav':<40}", "OBSERVER / AGENCY"))
    out.append(_hline(f"{'0':<20}{receiver:<20}{'1':<20}", "REC # / TYPE / VERS"))
    out.append(_hline(f"{'0':<20}{antenna:<20}", "ANT # / TYPE"))
    xyz = np.zeros(3) if approx_r_e is None else np.asarray(approx_r_e, float)
    out.append(_hline("".join(f"{v:14.4f}" for v in xyz), "APPROX POSITION XYZ"))
    out.append(_hline("".join(f"{v:14.4f}" for v in (0.0, 0.0, 0.0)), "ANTENNA: DELTA H/E/N"))
    for s in systems:
        codes = list(obs_types[s])
        for k in range(0, max(len(codes), 1), 13):
            chunk = codes[k:k + 13]
            head = f"{s}  {len(codes):3d}" if k == 0 else " " * 6
            out.append(_hline(head + "".join(f" {c:3}" for c in chunk), "SYS / # / OBS TYPES"))
    if interval_s is not None:
        out.append(_hline(f"{interval_s:10.3f}", "INTERVAL"))
    if t.size:
        y, mo, d, h, mi, sec = gps_calendar(float(t[0]))
        out.append(_hline(f"{y:6d}{mo:6d}{d:6d}{h:6d}{mi:6d}{sec:13.7f}     GPS", "TIME OF FIRST OBS"))
    for s in systems:
        for c in obs_types[s]:
            if c[0] == "L":
                out.append(_hline(f"{s} {c:3} {0.0:8.5f}", "SYS / PHASE SHIFT"))
    out.append(_hline("", "END OF HEADER"))

    # per-system row positions
    pos_in_sys = np.zeros(sat_id.size, np.int64)
    sys_of_row = np.array([x[0] for x in sat_id], dtype="<U1") if sat_id.size else np.zeros(0, "<U1")
    for s in systems:
        rows = np.flatnonzero(sys_of_row == s)
        pos_in_sys[rows] = np.arange(rows.size)
        v = np.asarray(values[s], float)
        if v.shape != (rows.size, len(obs_types[s])):
            raise ValueError(f"write_rinex_obs {path}: values[{s!r}] has shape {v.shape}, expected "
                             f"({rows.size}, {len(obs_types[s])})")
    order = np.lexsort((sat_id, epoch))
    ep_sorted = epoch[order]
    starts = np.searchsorted(ep_sorted, np.arange(t.size))
    ends = np.searchsorted(ep_sorted, np.arange(t.size), side="right")

    def field(v, li, si):
        if not np.isfinite(v):
            return " " * 16
        if abs(v) >= 1e10:
            raise ValueError(f"write_rinex_obs {path}: observation {v!r} does not fit F14.3")
        return f"{v:14.3f}{(str(int(li)) if li else ' ')}{(str(int(si)) if si else ' ')}"

    for k in range(t.size):
        rows = order[starts[k]:ends[k]]
        y, mo, d, h, mi, sec = gps_calendar(float(t[k]))
        out.append(f"> {y:4d} {mo:02d} {d:02d} {h:02d} {mi:02d}{sec:11.7f}  0{rows.size:3d}\n")
        for r in rows:
            s = sys_of_row[r]
            j = pos_in_sys[r]
            vals = np.asarray(values[s], float)[j]
            li = np.zeros(vals.size, int) if lli is None or s not in lli else np.asarray(lli[s])[j]
            si = np.zeros(vals.size, int) if ssi is None or s not in ssi else np.asarray(ssi[s])[j]
            out.append(sat_id[r] + "".join(field(v, a, b) for v, a, b in zip(vals, li, si)).rstrip() + "\n")
    return _atomic_write(path, "".join(out))
