"""SP3-c/d precise orbit reader with Lagrange interpolation, and RINEX clock (AS) reader.

SP3 positions are centre-of-mass positions in the ITRF/IGS realisation of
the file (close to WGS-84 at the cm level); SP3 and CLK clocks *exclude* the
periodic relativistic term that the broadcast clock of IS-GPS-200
20.3.3.3.3.1 adds, so compare them with the broadcast polynomial only.
Only files whose time system is GPS are supported (the usual case).

References
----------
S. Hilla, *The Extended Standard Product 3 Orbit Format (SP3-d)*, IGS, 2016.
*RINEX Extensions to Handle Clock Information*, version 3.04, IGS, 2017.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .gpstime import gps_seconds_from_calendar
from .rinex import _Lines

__all__ = ["Sp3Data", "ClkData", "read_sp3", "read_rinex_clk", "lagrange_interpolate"]

#: SP3 "bad or absent" clock value [microseconds].
_SP3_BAD_CLOCK = 999999.0


@dataclass
class Sp3Data:
    """Precise orbits.

    Attributes
    ----------
    path : str
    t_gps_s : (n,) epochs, GPS seconds since 1980-01-06 [s]
    sats : list of str, e.g. ``'G01'``
    r_e : (n, s, 3) ECEF positions [m], NaN where absent (0 0 0 in the file)
    clock_s : (n, s) clock offsets [s], NaN where absent (999999)
    """

    path: str
    t_gps_s: np.ndarray
    sats: list
    r_e: np.ndarray
    clock_s: np.ndarray

    def index(self, sat: str) -> int:
        """Column of satellite ``sat`` (e.g. ``'G05'``); KeyError if absent."""
        try:
            return self.sats.index(sat)
        except ValueError:
            raise KeyError(f"{sat} not in {self.path}") from None

    def position(self, sat: str, t_gps_s, order: int = 10) -> np.ndarray:
        """Lagrange-interpolated ECEF position [m] of ``sat`` at times ``t_gps_s`` [s], shape (k, 3).

        Uses ``order + 1`` consecutive epochs centred on each time (shifted
        inwards at the ends of the file); NaN outside the file span or where
        any node is absent.
        """
        j = self.index(sat)
        return lagrange_interpolate(self.t_gps_s, self.r_e[:, j, :], t_gps_s, order)


def lagrange_interpolate(t_nodes, y_nodes, t, order=10):
    """Piecewise Lagrange interpolation on (roughly) equally spaced nodes, vectorised.

    Parameters
    ----------
    t_nodes : (n,) increasing node times [s]
    y_nodes : (n, ...) node values
    t : (k,) or scalar query times [s]
    order : int
        Polynomial degree; ``order + 1`` nodes around each query are used
        (10 -> 11 nodes, the customary choice for 5/15-min SP3 orbits, mm-level).

    Returns
    -------
    (k, ...) ndarray, NaN for queries outside ``[t_nodes[0], t_nodes[-1]]``.
    """
    t_nodes = np.asarray(t_nodes, dtype=float)
    y_nodes = np.asarray(y_nodes, dtype=float)
    t = np.atleast_1d(np.asarray(t, dtype=float))
    n = t_nodes.size
    m = min(order + 1, n)
    i = np.searchsorted(t_nodes, t) - (m // 2)
    i0 = np.clip(i, 0, n - m)
    idx = i0[:, None] + np.arange(m)[None, :]  # (k, m)
    tn = t_nodes[idx]  # (k, m)
    dt = t[:, None] - tn  # (k, m)
    # weights w_j = prod_{l != j} (t - t_l) / (t_j - t_l)
    diff = tn[:, :, None] - tn[:, None, :]  # (k, m, m)
    eye = np.eye(m, dtype=bool)
    diff[:, eye] = 1.0
    num = np.repeat(dt[:, None, :], m, axis=1)  # (k, m, m): [j, l] -> t - t_l
    num[:, eye] = 1.0
    w = np.prod(num / diff, axis=2)  # (k, m)
    y = np.einsum("km,km...->k...", w, y_nodes[idx])
    out = (t < t_nodes[0]) | (t > t_nodes[-1])
    y[out] = np.nan
    return y


def read_sp3(path) -> Sp3Data:
    """Read an SP3-c or SP3-d file (position records ``P``; velocity records ignored).

    Raises
    ------
    RinexError
        (shared error type of :mod:`insnav.gnss`) on a malformed header or
        record, with the file path and the 1-based line number.
    """
    src = _Lines(path)
    first = src.next("the SP3 header")
    if not first.startswith("#") or first[1:2] not in ("c", "d", "a", "b"):
        raise src.error("malformed header: first line is not an SP3 '#c'/'#d' line")
    epochs, rows = [], []  # rows: (epoch index, sat, x, y, z, clk)
    sats_seen = {}
    while not src.eof():
        line = src.next()
        if line.startswith("%c") and line[9:12].strip() not in ("", "ccc", "GPS"):
            raise src.error(f"unsupported SP3 time system {line[9:12]!r} (only GPS)")
        if line.startswith("*  "):
            try:
                y = int(line[3:7]); mo = int(line[8:10]); d = int(line[11:13])
                h = int(line[14:16]); mi = int(line[17:19]); s = float(line[20:31])
            except ValueError:
                raise src.error(f"bad record: cannot parse SP3 epoch {line.rstrip()!r}") from None
            epochs.append(gps_seconds_from_calendar(y, mo, d, h, mi, s))
        elif line.startswith("P") and epochs:
            sat = line[1:4].replace(" ", "0")
            try:
                x, yy, z = (float(line[4 + 14 * k:18 + 14 * k]) for k in range(3))
                cs = line[46:60].strip()
                c = float(cs) if cs else _SP3_BAD_CLOCK
            except ValueError:
                raise src.error(f"bad record: cannot parse SP3 position record for {sat}") from None
            sats_seen.setdefault(sat, len(sats_seen))
            rows.append((len(epochs) - 1, sats_seen[sat], x, yy, z, c))
        elif line.startswith("EOF"):
            break
    if not epochs:
        raise src.error("unexpected end of file: no SP3 epochs")
    sats = sorted(sats_seen)
    col = np.array([sats.index(s) for s in sorted(sats_seen, key=sats_seen.get)])
    arr = np.array(rows, dtype=float).reshape(-1, 6)
    n, ns = len(epochs), len(sats)
    r_e = np.full((n, ns, 3), np.nan)
    clk = np.full((n, ns), np.nan)
    ei = arr[:, 0].astype(int)
    si = col[arr[:, 1].astype(int)]
    xyz = arr[:, 2:5] * 1e3
    bad_pos = np.all(arr[:, 2:5] == 0.0, axis=1)
    xyz[bad_pos] = np.nan
    r_e[ei, si] = xyz
    c = arr[:, 5]
    clk[ei, si] = np.where(np.abs(c) >= _SP3_BAD_CLOCK - 1.0, np.nan, c * 1e-6)
    return Sp3Data(src.path, np.asarray(epochs), sats, r_e, clk)


@dataclass
class ClkData:
    """Satellite clocks from a RINEX clock file (``AS`` records).

    Attributes
    ----------
    path : str
    t_gps_s : (n,) epochs [s]
    sats : list of str
    clock_s : (n, s) clock bias [s], NaN where absent
    """

    path: str
    t_gps_s: np.ndarray
    sats: list
    clock_s: np.ndarray

    def clock(self, sat: str, t_gps_s) -> np.ndarray:
        """Linearly interpolated clock bias [s] of ``sat`` at ``t_gps_s`` (NaN outside / across gaps)."""
        j = self.sats.index(sat)
        t = np.atleast_1d(np.asarray(t_gps_s, dtype=float))
        c = self.clock_s[:, j]
        if self.t_gps_s.size == 1:  # a single epoch: its value at that epoch only
            return np.where(t == self.t_gps_s[0], c[0], np.nan)
        i = np.clip(np.searchsorted(self.t_gps_s, t) - 1, 0, self.t_gps_s.size - 2)
        t0, t1 = self.t_gps_s[i], self.t_gps_s[i + 1]
        w = (t - t0) / (t1 - t0)
        out = c[i] * (1.0 - w) + c[i + 1] * w
        out[(t < self.t_gps_s[0]) | (t > self.t_gps_s[-1])] = np.nan
        return out


def read_rinex_clk(path) -> ClkData:
    """Read satellite clock (``AS``) records of a RINEX 2/3 clock file.

    Raises
    ------
    RinexError
        Malformed header or ``AS`` record (path and 1-based line number).
    """
    src = _Lines(path)
    first = src.next("the clock header")
    if "RINEX VERSION / TYPE" not in first[60:] or "C" not in first[20:22]:
        raise src.error("malformed header: not a RINEX clock file")
    while True:
        line = src.next("the clock header (no END OF HEADER)")
        if "END OF HEADER" in line[60:]:
            break
        if "TIME SYSTEM ID" in line[60:] and line[:10].strip() not in ("", "GPS"):  # 3.04: label at col 66
            raise src.error(f"unsupported clock time system {line[:10].strip()!r} (only GPS)")
    times, recs, sats = {}, [], {}
    while not src.eof():
        line = src.next()
        if not line.startswith("AS "):
            continue
        parts = line[3:].split()
        try:
            sat = parts[0]
            if len(sat) == 2:  # RINEX 2 style 'G 1'
                raise ValueError
            y, mo, d, h, mi = (int(p) for p in parts[1:6])
            s = float(parts[6])
            nval = int(parts[7])
            bias = float(parts[8].replace("D", "E"))
        except (ValueError, IndexError):
            raise src.error(f"bad record: cannot parse AS record {line.rstrip()!r}") from None
        if nval < 1:
            raise src.error("bad record: AS record with no values")
        t = gps_seconds_from_calendar(y, mo, d, h, mi, s)
        ti = times.setdefault(t, len(times))
        si = sats.setdefault(sat, len(sats))
        recs.append((ti, si, bias))
    if not recs:
        raise src.error("unexpected end of file: no AS records")
    tarr = np.array(sorted(times))
    torder = np.argsort(np.array(list(times.keys())))
    trank = np.empty_like(torder)
    trank[torder] = np.arange(torder.size)
    sat_names = sorted(sats)
    scol = np.array([sat_names.index(s) for s in sats])
    a = np.array(recs)
    clk = np.full((tarr.size, len(sat_names)), np.nan)
    clk[trank[a[:, 0].astype(int)], scol[a[:, 1].astype(int)]] = a[:, 2]
    return ClkData(src.path, tarr, sat_names, clk)
