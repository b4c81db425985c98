"""Carrier-phase relative positioning (RTK) of a rover against a base station.

The engine is C++ (``cpp/include/insnav/gnss/rtk.hpp``, MLAMBDA in
``cpp/include/insnav/gnss/lambda.hpp``, called through ``insnav._core.rtk_run``
with the GIL released); this module reads the observations, computes the
satellite states each receiver saw, matches base and rover epochs and wraps
the result.  Equations: docs/algorithms.md, "Carrier-phase RTK".

* Observations: :func:`read_phase_obs` reads RINEX 3 files with the fast C++
  reader (``insnav._core.read_rinex3_obs``): pseudorange [m], carrier phase
  [cycles], Doppler [Hz], C/N0 [dB-Hz] and the loss-of-lock indicator (bit 0
  slip, bit 1 half-cycle ambiguity) on up to three frequency slots per system
  (:data:`SIGNALS`: slot 0 L1/E1/G1/B1I, slot 1 L2/E5b/G2/B2I, slot 2
  L5/E5a/G3/B3I -- RTKLIB 2.4.3's numbering, so ``frequencies = 2`` means
  the same signals as its "L1+L2").  RINEX 2.10/2.11 files are read by the compiled RINEX 2
  record reader on the same slots (GPS and GLONASS C1/P1 L1, P2/C2 L2, GPS C5 L5; Galileo C1 L1,
  C7 L7, C5 L5), phase with its LLI.
  Wavelengths per system and, for GLONASS, per FDMA channel (navigation data
  first, then the ``GLONASS SLOT / FRQ #`` header).
* Satellite states: per receiver and row at the transmission time
  ``t_tx = t_rx - P / c - dt^s`` from the row's own pseudorange (so no
  approximate position is needed), in the ECEF frame of that instant; the
  engine adds the Sagnac term to the range.
* Base epochs: a rover epoch uses the base epoch with the same time tag
  (within 1 ms); without one (a base at a lower rate, or a gap) the latest
  earlier base epoch not older than ``max_age_s`` is held: its zero-difference
  residuals (observation minus computed range and satellite clock at the
  base's own epoch) enter the double differences, so only the change of the
  atmosphere and of the base receiver clock over the age (the latter cancels
  between satellites) is not modelled -- RTKLIB's "age of differential".
  Epochs with no base epoch within ``max_age_s`` get no solution.
* Base position (the antenna reference point): ``r_base_e`` given, else the
  RINEX header's ``APPROX POSITION XYZ`` plus ``ANTENNA: DELTA H/E/N``.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from .._median import median, unique  # np.unique would import numpy.ma (numpy 2.4: ~30 ms per command)
from ..config import ConfigError, TomlTable

__all__ = ["RtkOptions", "PhaseObs", "RtkSolution", "SIGNALS", "STATUS_NAMES", "read_phase_obs", "receiver_rows",
           "match_base", "solve_rtk", "prepare_rtk_rows", "base_position_from_header", "write_rtklib_pos", "write_rtk_table",
           "RTK_COLUMNS", "RtkInputError", "estimate_noise", "estimate_noise_prepass"]

from ._rtk_keys import AR_MODES as _AR_MODES  # noqa: E402 - the table's keys and checks, shared without numpy
from ._rtk_keys import IONO_MODES as _IONO_MODES  # noqa: E402,F401
from ._rtk_keys import IONO_SIGMA_DEFAULT as _IONO_SIGMA_DEFAULT  # noqa: E402,F401
from ._rtk_keys import MODES as _MODES  # noqa: E402,F401
from ._rtk_keys import SIGNALS, SYSTEM_INDEX, rtk_core_dict, rtk_value_error  # noqa: E402
from ._rtk_keys import BASE_POSITION_TOLERANCE_M, CODE_FIT_TOLERANCE_M  # noqa: E402,F401

#: RTKLIB's Q values
STATUS_NAMES = {0: "none", 1: "fixed", 2: "float", 4: "dgps"}
C_LIGHT = 299792458.0


class RtkInputError(ValueError):
    """Unusable RTK input (no common epochs / satellites / frequency, base without phase, no base position)."""


@dataclass
class RtkOptions(TomlTable):
    """The ``[rtk]`` table of a run TOML.

    Attributes
    ----------
    mode : str
        ``"kinematic"`` (position and velocity, white-acceleration dynamics) or ``"static"``.
    ar_mode : str
        ``"continuous"`` (ambiguities kept while tracked), ``"instantaneous"`` (single-epoch:
        ambiguities and position re-initialised every epoch), ``"fix-and-hold"`` (the fixed
        double differences fed back as tight pseudo-measurements), ``"off"`` (float only).
    systems : str
        Letters of ``GRECJ`` (GPS, GLONASS, Galileo, BeiDou, QZSS).  Each system has its own
        reference satellite in the double differences, QZSS included (docs/algorithms.md).
    frequencies : int
        1 (L1/E1/G1/B1I), 2 (+ L2/E5b/G2/B2I), 3 (+ L5/E5a/G3/B3I).
    elevation_mask_deg, ar_elevation_mask_deg : float
        Satellites below are not used / not fixed [deg].
    ratio_threshold : float
        Ratio test s2/s1 of MLAMBDA's two best candidates (3).
    min_fix_ambiguities : int
        Fewest double-differenced ambiguities a new integer set may have (5): partial AR drops one
        ambiguity at a time until the ratio test passes (at most ``max_partial_drops`` times, 4), and a
        set with fewer is fixed only when it is all the epoch's fixable ambiguities and repeats a
        validated set (docs/algorithms.md, "Integer ambiguity resolution").
    min_success_rate : float
        Bootstrapped success rate (Teunissen 1998) a set must have from the float covariance of the
        configured sigmas, scaled by the code variance factor k below where k > 1 (the data say the
        float is noisier than configured; with ``min_success_rate_estimated`` on) (0.95; 0 off: no
        success-rate test; the tight RTK/INS filter's default is 0.4,
        :data:`insnav.filters.rtk_ins.RTK_INS_DEFAULTS`).
    min_success_rate_estimated : float
        ... or, failing that, from the float covariance scaled by the code variance factor k
        estimated from the data (0.98; 0 off): the least-squares code double differences of every
        epoch give k (the upper bound at ``success_rate_noise_confidence`` of its estimate over the
        last ``success_rate_noise_window_s``), so a receiver quieter than configured is not held
        to the configured sigmas' pessimistic success rate (docs/algorithms.md).
    success_rate_noise_window_s, success_rate_noise_confidence : float
        Forgetting time [s] (300) and confidence (0.5: the median) of that estimate.
    confirm_epochs, confirm_max_ambiguities : int
        A new set of at most ``confirm_max_ambiguities`` (6) ambiguities is reported fixed once
        its integers have passed in ``confirm_epochs`` (5) consecutive epochs.
    partial_ar_order : str
        Which one partial AR drops first: ``"variance"`` (the largest float variance) or
        ``"elevation"`` (the lowest satellite).
    glonass_ar : bool
        Fix GLONASS ambiguities (off: FDMA inter-frequency biases make them float only).
    sigma_phase_a_m, sigma_phase_b_m : float
        Zero-difference phase sigma sqrt(a^2 + b^2 / sin^2 el) [m]; code = ``code_phase_ratio`` x.
    code_correlation_time_s : float
        Correlation time of the code errors (multipath) [s]: the code of a tracked satellite enters
        with its variance x (1 + rho) / (1 - rho), rho = exp(-dt / tau) (0: white).
    phase_correlation_time_s, phase_error_ratio : float
        Time-correlated phase errors (carrier multipath, what the atmosphere models leave): their
        correlation time [s] (0: white phase) and their sigma as a multiple of the white phase sigma
        above.  Both > 0: one first-order Gauss-Markov state per ambiguity (docs/algorithms.md, "Correlated
        phase errors").  Ratio 0 with a correlation time: a tracked ambiguity's phase variance
        x (1 + rho) / (1 - rho), rho = exp(-dt / tau), instead.
    adaptive_code_gain : float
        Gain of the adaptive code variance factor estimated from post-fit code residuals (0: off).
    amb_psd_cycles2ps : float
        Random walk of the single-differenced ambiguities [cycles^2/s].
    iono : str
        Between-receiver ionosphere (docs/algorithms.md, "Ionosphere of medium baselines"):
        ``"variance"`` (default) adds ``(iono_sigma_per_10km_m bl / 10 km)^2`` to the variance of
        every double difference (with the default sigma 0: nothing, right for short baselines);
        ``"estimate"`` estimates one single-differenced slant ionosphere per satellite (L1 delay
        [m], x (f_L1 / f_k)^2, minus on phase, plus on code; RTKLIB's ``pos1-ionoopt=est-stec``),
        ionosphere-weighted: prior and stationary sigma ``iono_sigma_per_10km_m bl / 10 km M(el)``,
        first-order Gauss-Markov with ``iono_tau_s``; ``"off"``: no ionosphere term.
    iono_sigma_per_10km_m : float or None
        Ionosphere sigma per 10 km of baseline [m]: of a double difference (``iono = "variance"``,
        default 0) or of the zenith single difference (``iono = "estimate"``, default 0.03: RTKLIB's
        ``stats-stdiono``, 3 ppm).
    iono_tau_s : float
        Correlation time of the estimated ionosphere [s] (1800: with 0.03 m per 10 km, the PSD
        2 sigma^2 / tau = 1e-6 m^2/s per (10 km)^2 of RTKLIB's ``stats-prniono`` 1e-3 m/sqrt(s)).
    accel_psd_h_m2ps3, accel_psd_v_m2ps3 : float
        White acceleration PSD, kinematic mode [m^2/s^3].
    max_age_s : float
        Oldest base epoch held for a rover epoch [s].
    gf_threshold_m, mw_threshold_cycles, doppler_threshold_cycles : float
        Cycle-slip thresholds (geometry-free jump, Melbourne-Wuebbena wide-lane departure from
        its mean, Doppler-predicted phase; <= 0 switches the Doppler test off).
    noise : str
        ``"configured"`` (default): the sigmas above.  ``"estimate"``: a first GNSS-only pass estimates
        the phase sigma (a and b scaled together) and the code ratio from its fixed epochs
        (least-squares variance component estimation, :func:`insnav.gnss.rtk_noise.estimate_noise`,
        docs/algorithms.md), and the run then uses them (RTK/INS: the GNSS-only pre-pass feeds the
        RTK/INS filter); the phase sigma is floored at 0.1 mm, and with fewer than 10 fixed epochs a
        warning says so and the configured sigmas stay.
    """

    mode: str = "kinematic"
    ar_mode: str = "continuous"
    systems: str = "GREC"
    frequencies: int = 2
    elevation_mask_deg: float = 15.0
    ar_elevation_mask_deg: float = 0.0
    ratio_threshold: float = 3.0
    min_fix_ambiguities: int = 5
    max_partial_drops: int = 4
    partial_ar_order: str = "variance"
    min_lock_epochs: int = 0
    glonass_ar: bool = False
    sigma_phase_a_m: float = 0.003
    sigma_phase_b_m: float = 0.003
    code_phase_ratio: float = 100.0
    code_correlation_time_s: float = 0.0
    phase_correlation_time_s: float = 0.0
    phase_error_ratio: float = 0.0
    adaptive_code_gain: float = 0.0
    min_success_rate: float = 0.95
    min_success_rate_estimated: float = 0.98
    success_rate_noise_window_s: float = 300.0
    success_rate_noise_confidence: float = 0.5
    confirm_epochs: int = 5
    confirm_max_ambiguities: int = 6
    iono: str = "variance"
    iono_sigma_per_10km_m: float | None = None
    iono_tau_s: float = 1800.0
    tropo_model: bool = True
    accel_psd_h_m2ps3: float = 9.0
    accel_psd_v_m2ps3: float = 1.0
    amb_init_sigma_cycles: float = 30.0
    amb_psd_cycles2ps: float = 1e-8
    gf_threshold_m: float = 0.05
    mw_threshold_cycles: float = 2.0
    doppler_threshold_cycles: float = 1.0
    max_outage_epochs: int = 5
    outlier_sigma: float = 5.0
    hold_sigma_cycles: float = 0.0316
    max_age_s: float = 30.0
    noise: str = "configured"

    TABLE = "rtk"

    def validate(self, source: str = "rtk options") -> "RtkOptions":
        import dataclasses

        values = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        msg = rtk_value_error(values, source, self.TABLE)  # insnav.gnss._rtk_keys: the checks, in order
        self.iono_sigma_per_10km_m = values["iono_sigma_per_10km_m"]
        if msg is not None:
            raise ConfigError(msg)
        return self

    def core_dict(self) -> dict:
        """Options of the C++ engine (``RtkOptions`` in rtk.hpp; SI units)."""
        import dataclasses

        return rtk_core_dict({f.name: getattr(self, f.name) for f in dataclasses.fields(self)})


@dataclass
class PhaseObs:
    """Multi-frequency observations of one receiver (long format, one row per epoch and satellite).

    Attributes
    ----------
    path : str
    epoch_t_gps_s : (n,) float
        Epoch time tags, GPS seconds since 1980-01-06 [s].
    epoch : (m,) int
        Row -> epoch index.
    system : (m,) str
        One-letter system.
    prn : (m,) int
    code_m, phase_cycles, doppler_hz, cn0_dbhz : (m, 3) float
        Per frequency slot (:data:`SIGNALS`); NaN where not observed.
    lli : (m, 3) int
        Loss-of-lock indicator of the phase (bit 0: slip, bit 1: half-cycle ambiguity).
    signals : dict
        System -> the three signal codes read (``""`` where the file has none).
    approx_r_e : (3,) float or None
        ``APPROX POSITION XYZ`` [m].
    antenna_hen_m : (3,) float
        ``ANTENNA: DELTA H/E/N`` [m].
    glonass_channels : dict
        GLONASS slot -> FDMA channel from the header.
    """

    path: str
    epoch_t_gps_s: np.ndarray
    epoch: np.ndarray
    system: np.ndarray
    prn: np.ndarray
    code_m: np.ndarray
    phase_cycles: np.ndarray
    doppler_hz: np.ndarray
    cn0_dbhz: np.ndarray
    lli: np.ndarray
    signals: dict = field(default_factory=dict)
    approx_r_e: np.ndarray | None = None
    antenna_hen_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    glonass_channels: dict = field(default_factory=dict)

    def __len__(self):
        return int(self.prn.size)


def _rinex_version(path) -> float:
    from .rinex import RinexError

    try:
        with open(path, "r", encoding="ascii", errors="replace") as f:
            first = f.readline()
    except OSError as exc:
        raise RinexError(os.fspath(path), None, f"cannot read file ({exc.strerror})") from None
    try:
        return float(first[:9])
    except ValueError:
        raise RinexError(os.fspath(path), 1, "malformed header: bad RINEX version") from None


def read_phase_obs(path, systems: str = "GREC") -> PhaseObs:
    """Read code, phase, Doppler, C/N0 and LLI on the frequency slots of :data:`SIGNALS`.

    RINEX 3 through the fast C++ reader; RINEX 2 through
    the compiled RINEX 2 record reader (every slot, :data:`_V2_TYPES`).  Raises
    :class:`insnav.gnss.rinex.RinexError` naming the file and line.
    """
    from .. import _core
    from .rinex import RinexError

    path = os.fspath(path)
    systems = "".join(s for s in systems if s in SIGNALS)
    if _rinex_version(path) < 3.0:
        return _read_phase_obs_v2(path, systems)
    prefs = {s: [list(x) for x in SIGNALS[s]] for s in systems}
    try:
        d = _core.read_rinex3_obs(path, prefs)
    except RuntimeError as exc:
        msg = str(exc)
        line = None
        if ", line " in msg:
            try:
                line = int(msg.split(", line ", 1)[1].split(":", 1)[0])
            except ValueError:
                line = None
        what = msg.split(": ", 1)[1] if ": " in msg else msg
        raise RinexError(path, line, what) from None
    from .rinex import warn_repeated_epochs

    warn_repeated_epochs(path, d["n_repeated_epochs"], d["first_repeated_line"])
    obs = np.asarray(d["obs"]).reshape(-1, 3, 5)
    sys_a = np.asarray(d["row_sys"], dtype=np.uint8).view("S1").astype("<U1") if len(d["row_sys"]) else \
        np.zeros(0, "<U1")
    lli = obs[:, :, 4]
    return PhaseObs(path=path, epoch_t_gps_s=np.asarray(d["epoch_t_gps_s"]), epoch=np.asarray(d["row_epoch"], np.int64),
                    system=sys_a, prn=np.asarray(d["row_prn"], np.int64), code_m=obs[:, :, 0].copy(),
                    phase_cycles=obs[:, :, 1].copy(), doppler_hz=obs[:, :, 2].copy(), cn0_dbhz=obs[:, :, 3].copy(),
                    lli=np.where(np.isfinite(lli), lli, 0).astype(np.int64),
                    signals={s: list(v) for s, v in d["chosen"].items()},
                    approx_r_e=None if d["approx_r_e"] is None else np.asarray(d["approx_r_e"], float),
                    antenna_hen_m=np.asarray(d["antenna_hen_m"], float),
                    glonass_channels={int(k): int(v) for k, v in d["glonass_channels"].items()})


#: RINEX 2.11 observation types of each system's frequency slots (Gurtner & Estey 2007, RINEX 2.11 sec. 5.1
#: and 10.1; the slots of :data:`SIGNALS`): pseudorange types in order of preference, then the phase,
#: Doppler and C/N0 types of the band.  RINEX 2 has one type per band, so the signal is the receiver's.
_V2_TYPES = {
    "G": ((("C1", "P1"), "L1", "D1", "S1"), (("P2", "C2"), "L2", "D2", "S2"), (("C5",), "L5", "D5", "S5")),
    "R": ((("C1", "P1"), "L1", "D1", "S1"), (("P2", "C2"), "L2", "D2", "S2"), ((), "", "", "")),
    "E": ((("C1",), "L1", "D1", "S1"), (("C7",), "L7", "D7", "S7"), (("C5",), "L5", "D5", "S5")),
}
#: the RINEX 3 signal each RINEX 2 pseudorange type stands for (its band gives the wavelength); a slot
#: with phase but no pseudorange is labelled by its band
_V2_AS_3 = {("G", "C1"): "1C", ("G", "P1"): "1W", ("G", "P2"): "2W", ("G", "C2"): "2X", ("G", "C5"): "5X",
            ("R", "C1"): "1C", ("R", "P1"): "1P", ("R", "P2"): "2P", ("R", "C2"): "2C",
            ("E", "C1"): "1X", ("E", "C7"): "7X", ("E", "C5"): "5X"}


def _read_phase_obs_v2(path, systems) -> PhaseObs:
    """RINEX 2.10/2.11 through the compiled RINEX 2 record reader, every slot of :data:`_V2_TYPES`
    (L1 and L2 phase with their LLI, L5/E5a/E5b where the file has them)."""
    from .. import _core
    from ..data.textio import read_bytes
    from .rinex import (RinexError, _core_rinex_error, _header_end, _Lines, _obs_header_fields,
                        _obs_types_header, _read_header, _version_type)

    try:
        raw = read_bytes(path)
    except OSError as exc:
        raise RinexError(path, None, f"cannot read file ({exc.strerror})") from None
    head = _header_end(raw)
    if head is None:
        raise RinexError(path, None, "malformed header: no END OF HEADER")
    src = _Lines(path, raw[:head[0]].decode("ascii", "replace").splitlines())
    header = _read_header(src)
    version, ftype, sysc = _version_type(src, header)
    if ftype != "O":
        raise src.error(f"malformed header: not an observation file (type {ftype!r})", header[0][0])
    approx, hen, glo_k = _obs_header_fields(src, header, sysc)
    types = _obs_types_header(src, header, version)
    have = types.get("G", [])
    select, signals = {}, {}
    for s in systems:
        if s not in _V2_TYPES:
            continue
        codes, sig = [], []
        for code_types, lt, dt, st in _V2_TYPES[s]:
            c = next((c for c in code_types if c in have), "")
            ph = lt if lt and lt in have else ""
            if not (c or ph):
                codes += ["", "", "", ""]
                sig.append("")
                continue
            codes += [c, ph, dt if dt in have else "", st if st in have else ""]
            sig.append(_V2_AS_3.get((s, c), (c or ph)[1:] + "X"))
        select[s] = codes
        signals[s] = sig
    try:
        d = _core.read_rinex3_obs_body(raw, path, head[0], head[1], types, select, True, True)
    except RuntimeError as exc:
        raise _core_rinex_error(path, exc) from None
    from .rinex import warn_repeated_epochs

    warn_repeated_epochs(path, d["n_repeated_epochs"], d["first_repeated_line"])
    obs = np.asarray(d["obs"]).reshape(-1, 3, 5)
    row_sys = np.asarray(d["row_sys"])
    sys_a = row_sys.astype(np.uint8).view("S1").astype("<U1") if row_sys.size else np.zeros(0, "<U1")
    lli = obs[:, :, 4]
    return PhaseObs(path=path, epoch_t_gps_s=np.asarray(d["epoch_t_gps_s"], float),
                    epoch=np.asarray(d["row_epoch"], np.int64), system=sys_a,
                    prn=np.asarray(d["row_prn"], np.int64), code_m=obs[:, :, 0].copy(),
                    phase_cycles=obs[:, :, 1].copy(), doppler_hz=obs[:, :, 2].copy(), cn0_dbhz=obs[:, :, 3].copy(),
                    lli=np.where(np.isfinite(lli), lli, 0).astype(np.int64), signals=signals, approx_r_e=approx,
                    antenna_hen_m=hen, glonass_channels=glo_k)


def wavelengths(obs: PhaseObs, nav=None) -> np.ndarray:
    """(m, 3) carrier wavelength [m] per row and slot (GLONASS: FDMA channel from nav, else the header)."""
    from .broadcast import _band
    from .galbds import FREQ_HZ

    m = len(obs)
    out = np.full((m, 3), np.nan)
    glo = obs.system == "R"
    k = np.full(m, np.nan)
    if glo.any():
        glo_prns = unique(obs.prn[glo])
        ch = np.array([obs.glonass_channels.get(int(p), -99) for p in glo_prns], dtype=float)
        table = dict(zip(glo_prns.tolist(), ch.tolist()))
        if nav is not None and getattr(nav, "eph_r", None) is not None and len(nav.eph_r):
            prns = np.array(sorted(table), dtype=np.int64)
            from_nav = nav.eph_r.channel(prns).astype(float)
            for p, c in zip(prns.tolist(), from_nav.tolist()):
                if c > -99:
                    table[p] = c
        k[glo] = [table[int(p)] for p in obs.prn[glo]]
        k[k <= -99] = np.nan
    for s, sig in obs.signals.items():
        rows = obs.system == s
        for f in range(3):
            if f >= len(sig) or not sig[f]:
                continue
            b = _band(s, "C" + sig[f])
            if s == "R":
                if b == "1":
                    out[rows, f] = C_LIGHT / (1602.0e6 + k[rows] * 0.5625e6)
                elif b == "2":
                    out[rows, f] = C_LIGHT / (1246.0e6 + k[rows] * 0.4375e6)
                elif b == "3":
                    out[rows, f] = C_LIGHT / 1202.025e6
            elif (s, b) in FREQ_HZ:
                out[rows, f] = C_LIGHT / FREQ_HZ[(s, b)]
    return out


def _orbit_states(nav, system, prn, t_gps_s):
    """(valid, r_e, v_e, clock bias [s], drift [s/s]) at GPS time ``t`` (ECEF of that instant), broadcast
    ephemerides, no group delay (it cancels between the receivers)."""
    from .broadcast import _state_at, select_multi

    k = prn.size
    valid = np.zeros(k, bool)
    r = np.full((k, 3), np.nan)
    v = np.full((k, 3), np.nan)
    b = np.full(k, np.nan)
    d = np.full(k, np.nan)
    for s in unique(system):
        rows = np.flatnonzero(system == s)
        idx = select_multi(nav, np.full(rows.size, s), prn[rows], t_gps_s[rows],
                           np.full(rows.size, "C2I" if s == "C" else "C1C"))
        ok = idx >= 0
        if not ok.any():
            continue
        rr = rows[ok]
        r[rr], v[rr], b[rr], d[rr] = _state_at(nav, s, idx[ok], t_gps_s[rr])
        valid[rr] = True
    return valid & np.all(np.isfinite(r), axis=1), r, v, b, d


def transmit_states(nav, t_tag_gps_s, system, prn, code_m):
    """Satellite position (ECEF of the transmission instant) and clock ``c dt^s`` [m] of each row.

    ``t_tx = t_tag - P / c - dt^s`` from the row's own pseudorange.  The broadcast orbit is evaluated
    once per (epoch tag, satellite), at ``t_tag - P / c`` of the first such row, and carried to each
    row's ``t_tx`` by a second-order Taylor step with the ECEF acceleration (gravity, Coriolis,
    centrifugal; the step is the satellite clock plus the receivers' clock and range differences,
    a few ms: the J2 and third-body terms left out give < 1e-7 m), so rover and base rows of one
    epoch share one orbit evaluation.
    """
    m = prn.size
    rs = np.full((m, 3), np.nan)
    clk = np.full(m, np.nan)
    ok = np.isfinite(code_m) & (code_m > 1.0e6) & (code_m < 1.0e8)
    if not ok.any():
        return rs, clk
    key = np.zeros(m, np.int64)
    for sname, i in SYSTEM_INDEX.items():
        key[system == sname] = i * 64
    key += np.clip(prn, 0, 63)
    t_ms = np.round(np.asarray(t_tag_gps_s, float) * 1000.0).astype(np.int64)
    pair = t_ms * 1000 + key
    uniq, first, inv = np.unique(pair[ok], return_index=True, return_inverse=True)
    rows_ok = np.flatnonzero(ok)
    u_rows = rows_ok[first]
    t_ref = t_tag_gps_s[u_rows] - code_m[u_rows] / C_LIGHT  # the first row's own signal time
    valid, r0, v0, b0, d0 = _orbit_states(nav, system[u_rows], prn[u_rows], t_ref)
    gm = 3.986004418e14
    w = np.array([0.0, 0.0, 7.2921151467e-5])
    rn = np.linalg.norm(r0, axis=1, keepdims=True)
    a0 = -gm * r0 / rn ** 3 - 2.0 * np.cross(w, v0) - np.cross(w, np.cross(w, r0))
    # per row: t_tx = t_tag - P/c - dt^s (the clock at t_ref; its drift over 20 ms is < 1e-12 s)
    j = inv.ravel()
    dt = (t_tag_gps_s[rows_ok] - code_m[rows_ok] / C_LIGHT - b0[j]) - t_ref[j]
    good = valid[j] & (np.abs(dt) < 0.05)
    rr = rows_ok[good]
    jj = j[good]
    dtg = dt[good][:, None]
    rs[rr] = r0[jj] + v0[jj] * dtg + 0.5 * a0[jj] * dtg ** 2
    clk[rr] = C_LIGHT * (b0[jj] + d0[jj] * dt[good])
    return rs, clk


def receiver_rows(obs: PhaseObs, nav, n_freq: int = 3, states=None):
    """Engine rows of one receiver: (epoch offsets (n+1,), rows (m, RTK_ROW_COLS)).

    ``states``: (satellite positions, clocks) of the rows from :func:`transmit_states` (computed
    here when not given).  Rows without code or ephemeris keep NaN satellite states (the engine
    skips them).
    """
    from .. import _core

    m = len(obs)
    cols = int(_core.RTK_ROW_COLS)
    rows = np.full((m, cols), np.nan)
    si = np.zeros(m, np.int64)
    for s, i in SYSTEM_INDEX.items():
        si[obs.system == s] = i
    rows[:, 0] = si * 64 + np.clip(obs.prn, 0, 63)
    rows[:, 1] = si
    lam = wavelengths(obs, nav)
    for f in range(min(n_freq, 3)):
        rows[:, 2 + 5 * f] = obs.code_m[:, f]
        rows[:, 3 + 5 * f] = np.where(np.isfinite(lam[:, f]), obs.phase_cycles[:, f], np.nan)
        rows[:, 4 + 5 * f] = obs.doppler_hz[:, f]
        rows[:, 5 + 5 * f] = obs.lli[:, f]
        rows[:, 6 + 5 * f] = lam[:, f]
    if states is None:
        states = transmit_states(nav, obs.epoch_t_gps_s[obs.epoch], obs.system, obs.prn, _first_code(obs))
    rows[:, 17:20], rows[:, 20] = states
    off = np.searchsorted(obs.epoch, np.arange(obs.epoch_t_gps_s.size + 1)).astype(np.int64)
    return off, rows


def _first_code(obs: PhaseObs) -> np.ndarray:
    P = obs.code_m[:, 0].copy()
    for f in (1, 2):
        P = np.where(np.isfinite(P), P, obs.code_m[:, f])
    return P


def match_base(t_rover, t_base, max_age_s: float) -> np.ndarray:
    """(n,) index of the base epoch for each rover epoch: same tag within 1 ms, else the latest
    earlier one not older than ``max_age_s`` (held); -1 where none."""
    t_rover = np.asarray(t_rover, float)
    t_base = np.asarray(t_base, float)
    if t_base.size == 0:
        return np.full(t_rover.size, -1, np.int64)
    j = np.searchsorted(t_base, t_rover + 1e-3, side="right") - 1
    out = np.where(j >= 0, j, -1).astype(np.int64)
    age = np.where(out >= 0, t_rover - t_base[np.maximum(out, 0)], np.inf)
    out[age > max_age_s + 1e-3] = -1
    return out


def base_position_from_header(obs: PhaseObs) -> np.ndarray | None:
    """Antenna reference point [m]: ``APPROX POSITION XYZ`` + ``ANTENNA: DELTA H/E/N`` (None if absent)."""
    from .. import earth

    if obs.approx_r_e is None or not np.all(np.isfinite(obs.approx_r_e)) or not np.any(obs.approx_r_e):
        return None
    lat, lon, _ = earth.ecef_to_geodetic(np.asarray(obs.approx_r_e, float))
    h, e, n = obs.antenna_hen_m
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    up = np.array([cl * co, cl * so, sl])
    east = np.array([-so, co, 0.0])
    north = np.array([-sl * co, -sl * so, cl])
    return np.asarray(obs.approx_r_e, float) + h * up + e * east + n * north


@dataclass
class RtkSolution:
    """Per rover epoch: ``t_gps_s``, ``status`` (:data:`STATUS_NAMES`), ``ratio``, ``success_rate``
    (bootstrapped, Teunissen 1998, of the ambiguities fixed; of all the candidates when float; of
    Q_a the float covariance of the configured sigmas), ``success_rate_estimated`` (the same of k Q_a,
    k = ``success_variance_factor`` the code variance factor estimated from the data; see
    ``RtkOptions.min_success_rate_estimated``), ``n_fix``
    (double-differenced ambiguities fixed), ``n_dd`` (phase double differences used),
    ``n_sat``, ``r_e`` (fixed where fixed, else float) [m], ``v_e`` [m/s], ``r_float_e``,
    ``P_r`` (3, 3) covariance of ``r_e`` [m^2], ``slips`` (n, 6) detections per epoch
    (LLI, geometry-free, Melbourne-Wuebbena, Doppler, data gap, innovation outlier),
    ``base_age_s``; ``info`` the options and files."""

    t_gps_s: np.ndarray
    status: np.ndarray
    ratio: np.ndarray
    success_rate: np.ndarray
    n_fix: np.ndarray
    n_dd: np.ndarray
    n_sat: np.ndarray
    r_e: np.ndarray
    v_e: np.ndarray
    r_float_e: np.ndarray
    P_r: np.ndarray
    slips: np.ndarray
    base_age_s: np.ndarray
    r_base_e: np.ndarray
    info: dict = field(default_factory=dict)
    success_variance_factor: np.ndarray | None = None
    success_rate_estimated: np.ndarray | None = None
    fixed_rows: dict | None = None

    SLIP_KINDS = ("lli", "geometry_free", "melbourne_wuebbena", "doppler", "gap", "outlier")

    def __len__(self):
        return int(self.t_gps_s.size)

    def noise_estimate(self, **kwargs):
        """Phase and code noise estimated from this run's fixed epochs
        (:func:`insnav.gnss.rtk_noise.estimate_noise`; the run needs ``record_fixed_rows=True``)."""
        from .rtk_noise import estimate_noise

        if self.fixed_rows is None:
            raise ValueError("RtkSolution.noise_estimate: the fixed epochs' rows were not recorded; "
                             "run solve_rtk(..., record_fixed_rows=True)")
        return estimate_noise(self.fixed_rows, self.info.get("options"), **kwargs)

    def counts(self) -> dict:
        """Epochs per status and slip detections per kind."""
        d = {f"n_{name}": int(np.sum(self.status == q)) for q, name in STATUS_NAMES.items()}
        d["epochs"] = len(self)
        d["fix_rate"] = float(np.mean(self.status == 1)) if len(self) else 0.0
        for k, name in enumerate(self.SLIP_KINDS):
            d[f"slips_{name}"] = int(self.slips[:, k].sum())
        return d


def _check_inputs(rover: PhaseObs, base: PhaseObs, opt: RtkOptions, bidx: np.ndarray):
    if base.epoch_t_gps_s.size == 0:
        raise RtkInputError(f"{base.path}: no base observation epochs")
    if rover.epoch_t_gps_s.size == 0:
        raise RtkInputError(f"{rover.path}: no rover observation epochs")
    if np.all(bidx < 0):
        raise RtkInputError(f"{rover.path}: no epoch in common with the base {base.path} (rover "
                            f"{rover.epoch_t_gps_s[0]:.1f}-{rover.epoch_t_gps_s[-1]:.1f} s, base "
                            f"{base.epoch_t_gps_s[0]:.1f}-{base.epoch_t_gps_s[-1]:.1f} s GPS, max_age_s {opt.max_age_s})")
    nf = opt.frequencies
    if not np.any(np.isfinite(base.phase_cycles[:, :nf])):
        raise RtkInputError(f"{base.path}: the base has no carrier phase on the frequencies used "
                            f"({_sig_text(base, nf)})")
    if not np.any(np.isfinite(rover.phase_cycles[:, :nf])):
        raise RtkInputError(f"{rover.path}: the rover has no carrier phase on the frequencies used "
                            f"({_sig_text(rover, nf)})")
    rs = {(s, f) for s, sig in rover.signals.items() for f in range(nf) if f < len(sig) and sig[f]}
    bs = {(s, f) for s, sig in base.signals.items() for f in range(nf) if f < len(sig) and sig[f]}
    if not rs & bs:
        raise RtkInputError(f"{base.path}: no frequency in common with the rover {rover.path} "
                            f"(rover {_sig_text(rover, nf)}; base {_sig_text(base, nf)})")
    key_r = set(zip(rover.system.tolist(), rover.prn.tolist()))
    key_b = set(zip(base.system.tolist(), base.prn.tolist()))
    if not key_r & key_b:
        raise RtkInputError(f"{base.path}: no satellite in common with the rover {rover.path}")


def _sig_text(obs, nf):
    return ", ".join(f"{s}:{'/'.join(x or '-' for x in sig[:nf])}" for s, sig in obs.signals.items()) or "none"


def solve_rtk(rover, base, nav, r_base_e=None, options: RtkOptions | dict | None = None, *,
              record_iono: bool = False, record_fixed_rows: bool = False, record_float: bool = False,
              base_source: str | None = None) -> RtkSolution:
    """RTK of ``rover`` against ``base``.

    Parameters
    ----------
    rover, base : path or PhaseObs
    nav : path, list of paths or NavData (broadcast ephemerides of the systems used)
    r_base_e : (3,), optional
        Base antenna reference point, ECEF [m]; default the base header's (see
        :func:`base_position_from_header`).  Raises :class:`RtkInputError` when neither exists.
    options : RtkOptions or dict
    record_iono : bool
        Also return, in ``info["iono_m"]`` and ``info["iono_sigma_m"]`` (n, 320), the float
        single-differenced (rover - base) slant ionosphere at 1575.42 MHz and its sigma [m] per
        epoch and satellite key ``system * 64 + prn`` (NaN where no state; ``iono = "estimate"``);
        ``info["iono_dd_m"]``, ``info["iono_dd_sigma_m"]`` the double differences against the highest
        satellite of each system with a state (NaN for it): only these are observable, the common
        part of a system's single differences is the prior's.
    record_fixed_rows : bool
        Also return, in ``fixed_rows``, the double differences of every fixed epoch for
        :meth:`RtkSolution.noise_estimate`.  With ``options.noise = "estimate"`` a first pass records
        them, and the run uses the sigmas estimated (``info["noise_estimate"]``, None when too few
        fixed epochs; ``info["options"]`` the options used).
    record_float : bool
        Also return, in ``info["float_ar"]``, the float ambiguity problem of every epoch with AR in the
        engine's partial-AR order (partial AR drops from the end): ``epoch`` and ``n`` per such epoch,
        and concatenated over them ``a_hat`` [cycles], ``Q_a`` (each epoch's n x n, row-major)
        [cycles^2], ``Q_ab`` (n, 3) [cycles m], ``sat_j``, ``sat_i`` (satellite keys
        ``system * 64 + prn`` of each double difference's satellite and reference), ``freq``;
        ``Q_bb`` (k, 3, 3) the float position's covariance [m^2] (:mod:`insnav.gnss.ar_success`).
    base_source : str, optional
        Where a given ``r_base_e`` came from (``--base-pos``, a TOML key), named in the message of a
        base position far from the base's own code fix (:func:`check_base_position`).

    Returns
    -------
    RtkSolution
    """
    from .. import _core

    opt = options if isinstance(options, RtkOptions) else RtkOptions.from_dict(options or {}, "rtk options")
    rover, base, r_base_e, bidx, roff, rrows, boff, brows = prepare_rtk_rows(rover, base, nav, r_base_e, opt,
                                                                             base_source=base_source)
    noise_est = None
    if opt.noise == "estimate":  # a first pass estimates the noise from its fixed epochs
        opt, noise_est = estimate_noise_prepass(rover.epoch_t_gps_s, roff, rrows, boff, brows, bidx, r_base_e, opt)
    out = _core.rtk_run(rover.epoch_t_gps_s, roff, rrows, boff, brows, bidx, r_base_e, opt.core_dict(),
                        record_iono=bool(record_iono), record_fixed_rows=bool(record_fixed_rows),
                        record_float=bool(record_float))
    age = np.where(bidx >= 0, rover.epoch_t_gps_s - base.epoch_t_gps_s[np.maximum(bidx, 0)], np.nan)
    return RtkSolution(t_gps_s=rover.epoch_t_gps_s.copy(), status=np.asarray(out["status"]),
                       ratio=np.asarray(out["ratio"]), success_rate=np.asarray(out["success_rate"]),
                       n_fix=np.asarray(out["n_fix"]), n_dd=np.asarray(out["n_dd"]),
                       n_sat=np.asarray(out["n_sat"]), r_e=np.asarray(out["r_e"]), v_e=np.asarray(out["v_e"]),
                       r_float_e=np.asarray(out["r_float_e"]), P_r=np.asarray(out["P_r"]).reshape(-1, 3, 3),
                       slips=np.asarray(out["slips"]), base_age_s=age, r_base_e=r_base_e,
                       success_variance_factor=np.asarray(out["success_variance_factor"]),
                       success_rate_estimated=np.asarray(out["success_rate_estimated"]),
                       fixed_rows=({k: np.asarray(v) for k, v in out["fixed_rows"].items()}
                                   if record_fixed_rows else None),
                       info=dict(rover=rover.path, base=base.path, options=opt, noise_estimate=noise_est,
                                 rover_signals=rover.signals,
                                 base_signals=base.signals,
                                 **({k: np.asarray(out[k]) for k in ("iono_m", "iono_sigma_m", "iono_dd_m",
                                                                     "iono_dd_sigma_m")} if record_iono else {}),
                                 **({"float_ar": {k: np.asarray(v) for k, v in out["float_ar"].items()}}
                                    if record_float else {})))


def estimate_noise(rows: dict, options: RtkOptions | dict | None = None, **kwargs):
    """Phase and code noise from the fixed epochs' double differences (least-squares variance component
    estimation): :func:`insnav.gnss.rtk_noise.estimate_noise`."""
    from .rtk_noise import estimate_noise as _estimate

    if not isinstance(options, RtkOptions):
        options = RtkOptions.from_dict(options or {}, "rtk options")
    return _estimate(rows, options, **kwargs)


def estimate_noise_prepass(t_gps_s, roff, rrows, boff, brows, bidx, r_base_e, opt: RtkOptions, *,
                           validation: RtkOptions | None = None):
    """The GNSS-only first pass of ``noise = "estimate"``: the engine over the prepared rows (with the
    options ``validation``, default ``opt``) records its fixed epochs, and the noise estimated from them
    (:func:`insnav.gnss.rtk_noise.noise_options`) replaces ``opt``'s sigmas.

    Returns
    -------
    (RtkOptions, NoiseEstimate or None)
        The options to run with (``noise = "configured"``) and the estimate (None: too few fixed
        epochs, a warning said so and ``opt``'s sigmas stay).
    """
    from .. import _core
    from .rtk_noise import noise_options

    pre = validation if validation is not None else opt
    out = _core.rtk_run(t_gps_s, roff, rrows, boff, brows, bidx, r_base_e, pre.core_dict(), record_fixed_rows=True)
    return noise_options(opt, out["fixed_rows"])


def prepare_rtk_rows(rover, base, nav, r_base_e, opt: RtkOptions, *, base_source: str | None = None):
    """The engine inputs of an RTK run (shared by :func:`solve_rtk` and the tight RTK/INS filter):
    ``(rover, base, r_base_e, base_index, rover_off, rover_rows, base_off, base_rows)`` with the
    observations read (paths -> :class:`PhaseObs`), the base position (header default), the base
    epoch of each rover epoch (:func:`match_base`) and the satellite states of each receiver.

    The base position is checked against the base's own pseudoranges (:func:`check_base_position`;
    ``base_source`` names where a given one came from in the message)."""
    from .rinex import read_nav_multi

    if not isinstance(rover, PhaseObs):
        rover = read_phase_obs(rover, opt.systems)
    if not isinstance(base, PhaseObs):
        base = read_phase_obs(base, opt.systems)
    if not hasattr(nav, "eph"):
        nav = read_nav_multi(nav, "".join(s for s in opt.systems if s in "GRECJ"))
    if r_base_e is None:
        base_source = "the header's APPROX POSITION XYZ"
        r_base_e = base_position_from_header(base)
        if r_base_e is None:
            raise RtkInputError(f"{base.path}: base position missing: the header has no APPROX POSITION XYZ; "
                                f"give --base-pos, or [rtk] base_position_ecef_m or base_position_llh in the TOML")
    r_base_e = np.asarray(r_base_e, float)
    bidx = match_base(rover.epoch_t_gps_s, base.epoch_t_gps_s, opt.max_age_s)
    _check_inputs(rover, base, opt, bidx)
    nr = len(rover)
    rs, clk = transmit_states(nav, np.concatenate([rover.epoch_t_gps_s[rover.epoch], base.epoch_t_gps_s[base.epoch]]),
                              np.concatenate([rover.system, base.system]), np.concatenate([rover.prn, base.prn]),
                              np.concatenate([_first_code(rover), _first_code(base)]))
    check_base_position(base, r_base_e, rs[nr:], clk[nr:], base_source or "given")
    check_code_fit(rover, rs[:nr], clk[:nr], r_base_e, "rover")
    roff, rrows = receiver_rows(rover, nav, opt.frequencies, (rs[:nr], clk[:nr]))
    boff, brows = receiver_rows(base, nav, opt.frequencies, (rs[nr:], clk[nr:]))
    return rover, base, r_base_e, bidx, roff, rrows, boff, brows


def receiver_code_fix(obs: PhaseObs, rs, clk, r0_e, n_epochs: int = 10):
    """Code-only position of a receiver [m] (ECEF), the median over up to ``n_epochs``
    epochs spread over the file of the per-epoch least-squares fixes of the SPP solver
    (:func:`insnav.gnss.code_fix._position_fit`: position and one receiver clock per system, unit
    weights, no atmosphere models), started from ``r0_e``; the satellite positions rotated by the
    Earth's rate over the signal's travel time from ``r0_e`` (Sagnac; a start 1000 km off moves it
    by a few metres).  Returns ``(r_e, epochs used, median residual RMS of those fits [m])``, or
    ``(None, 0, None)`` when no epoch has enough satellites.

    ``rs``, ``clk``: the satellite positions [m] and clocks [m] of the receiver's rows
    (:func:`transmit_states`)."""
    from ..earth import OMEGA_IE
    from .code_check import spread_epochs, unit_weight_fit

    code = _first_code(obs)
    r0_e = np.asarray(r0_e, float)
    good = np.isfinite(code) & np.all(np.isfinite(rs), axis=1) & np.isfinite(clk)
    fixes, rms = [], []
    for e in spread_epochs(obs.epoch_t_gps_s.size, n_epochs):
        m = good & (obs.epoch == e)
        theta = OMEGA_IE * np.linalg.norm(rs[m] - r0_e, axis=1) / C_LIGHT  # Earth rotation during the travel
        sats = np.zeros((int(m.sum()), 9))
        sats[:, 0] = code[m]
        sats[:, 2] = np.cos(theta) * rs[m, 0] + np.sin(theta) * rs[m, 1]
        sats[:, 3] = -np.sin(theta) * rs[m, 0] + np.cos(theta) * rs[m, 1]
        sats[:, 4] = rs[m, 2]
        sats[:, 8] = clk[m]
        fit = unit_weight_fit(sats, obs.system[m], r0_e)
        if fit is None:
            continue  # too few rows, singular or not converged: no evidence either way
        fixes.append(fit[0])
        rms.append(fit[1])
    if not fixes:
        return None, 0, None
    fixes = np.asarray(fixes)
    return np.array([median(fixes[:, k]) for k in range(3)]), len(fixes), median(rms)


def check_code_fit(obs: PhaseObs, rs, clk, r0_e, role: str):
    """:class:`RtkInputError` (one line naming the file) when the receiver's pseudoranges do not fit
    one position and clock per epoch: the median residual RMS of its one-epoch code fits
    (:func:`receiver_code_fix`) above :data:`CODE_FIT_TOLERANCE_M`.  Epoch time tags moved against the
    observations (the satellites are then computed where they were not when the pseudoranges were
    measured) or a navigation file of other satellites give hundreds of metres, and an RTK run on
    them a float solution as far off with exit status 0.  Returns ``(code fix [m] or None, epochs)``.

    ``role``: "rover" or "base", for the message; ``rs``, ``clk``: the satellite states of the
    receiver's rows (:func:`transmit_states`); ``r0_e``: where the fits start [m] (ECEF)."""
    fix_e, n, rms = receiver_code_fix(obs, rs, clk, r0_e)
    if fix_e is not None and rms > CODE_FIT_TOLERANCE_M:
        raise RtkInputError(f"{obs.path}: the {role}'s pseudoranges do not fit one receiver position and clock "
                            f"(median residual RMS {rms:.0f} m over {n} epochs; at most "
                            f"{CODE_FIT_TOLERANCE_M:.0f} m accepted, a few metres usual): epoch time tags shifted "
                            "against the observations, or a navigation file of other satellites")
    return fix_e, n


def check_base_position(base: PhaseObs, r_base_e, rs, clk, source: str) -> None:
    """:class:`RtkInputError` (one line naming the file and where the position came from) when
    ``r_base_e`` is more than :data:`BASE_POSITION_TOLERANCE_M` from the base's own code fix
    (:func:`receiver_code_fix`): every rover position would be off by as much, and an engine given a
    base some hundred km off searches ambiguities of float solutions that cannot fix."""
    from .. import earth

    fix_e, n = check_code_fit(base, rs, clk, r_base_e, "base")
    if fix_e is None:
        return
    dist = float(np.linalg.norm(fix_e - np.asarray(r_base_e, float)))
    if dist <= BASE_POSITION_TOLERANCE_M:
        return

    def llh(r):
        lat, lon, h = (float(np.ravel(v)[0]) for v in earth.ecef_to_geodetic(np.asarray(r, float)))
        return f"{math.degrees(lat):.6f}, {math.degrees(lon):.6f} deg, {h:.1f} m"

    far = f"{dist / 1e3:.1f} km" if dist >= 1e4 else f"{dist:.0f} m"
    raise RtkInputError(f"{base.path}: the base position ({source}: {llh(r_base_e)}) is {far} from where the "
                        f"base's own pseudoranges put the receiver ({llh(fix_e)}, median of {n} epochs; more than "
                        f"{BASE_POSITION_TOLERANCE_M:.0f} m): a wrong base position or another station's file")


def _gpst_texts(t_gps_s) -> list:
    """``YYYY/MM/DD HH:MM:SS.SSS`` (RTKLIB's default time form) of each GPS time ``t_gps_s`` [s since
    1980-01-06]: the milliseconds rounded half to even (as ``round``), split into days and the time
    of day by integer arithmetic, so a file of epochs costs one calendar conversion per day, not a
    ``datetime`` per epoch."""
    import datetime

    ms = np.rint(np.asarray(t_gps_s, float) * 1000.0).astype(np.int64)
    day, ms_of_day = np.divmod(ms, 86_400_000)
    hh, rem = np.divmod(ms_of_day, 3_600_000)
    mi, rem = np.divmod(rem, 60_000)
    ss, mss = np.divmod(rem, 1000)
    ord0 = datetime.date(1980, 1, 6).toordinal()
    dates = {d: datetime.date.fromordinal(ord0 + d).strftime("%Y/%m/%d") for d in set(day.tolist())}
    return [f"{dates[d]} {h:02d}:{m:02d}:{s:02d}.{f:03d}"
            for d, h, m, s, f in zip(day.tolist(), hh.tolist(), mi.tolist(), ss.tolist(), mss.tolist())]


def write_rtklib_pos(sol: RtkSolution, path, *, program: str = "insnav") -> "os.PathLike":
    """Write ``path`` in RTKLIB's ``.pos`` layout (GPST date and time, latitude/longitude/height
    [deg, deg, m], Q, ns, sdn/sde/sdu/sdne/sdeu/sdun [m], age [s], ratio), so RTKLIB users'
    scripts read it unchanged.

    The covariance is rotated to ENU, ``Q = C P C^T`` with ``C`` the ENU <- ECEF rotation at the
    solution's latitude and longitude, for all epochs at once (numpy's stacked product gives each
    epoch the bits of its own 3 x 3 product); the off-diagonal terms are written as RTKLIB does,
    ``sign(q) sqrt(|q|)``."""
    from .. import earth
    from .._atomic import atomic_write_text

    ok = sol.status > 0
    lines = [f"% program   : {program} rtk",
             f"% inp file  : {sol.info.get('rover', '')}",
             f"% inp file  : {sol.info.get('base', '')}",
             f"% ref pos   :{sol.r_base_e[0]:15.4f}{sol.r_base_e[1]:15.4f}{sol.r_base_e[2]:15.4f}",
             "% (lat/lon/height=WGS84/ellipsoidal,Q=1:fix,2:float,3:sbas,4:dgps,5:single,6:ppp,ns=# of satellites)",
             "%  GPST                   latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)  "
             "sdne(m)  sdeu(m)  sdun(m) age(s)  ratio"]
    if ok.any():
        k = np.flatnonzero(ok)
        lat, lon, h = earth.ecef_to_geodetic(sol.r_e[ok])
        lat, lon, h = (np.asarray(a, float).reshape(-1) for a in (lat, lon, h))
        sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
        C = np.stack([np.stack([-so, co, np.zeros_like(so)], -1), np.stack([-sl * co, -sl * so, cl], -1),
                      np.stack([cl * co, cl * so, sl], -1)], 1)  # (n, 3, 3): ENU <- ECEF
        Q = C @ sol.P_r[k] @ C.transpose(0, 2, 1)
        sd = np.sqrt(np.maximum(np.diagonal(Q, axis1=1, axis2=2), 0.0))

        def ss(v):
            return np.copysign(np.sqrt(np.abs(v)), v)

        age = sol.base_age_s[k]
        age = np.where(np.isfinite(age), age, 0.0)
        cols = (np.degrees(lat), np.degrees(lon), h, sol.status[k].astype(np.int64), sol.n_sat[k].astype(np.int64),
                sd[:, 1], sd[:, 0], sd[:, 2], ss(Q[:, 1, 0]), ss(Q[:, 0, 2]), ss(Q[:, 2, 1]), age, sol.ratio[k])
        for t, (la, lo, hh, q, ns, sn, se, su, sne, seu, sun, ag, ra) in zip(
                _gpst_texts(sol.t_gps_s[k]), zip(*(np.asarray(c).tolist() for c in cols))):
            lines.append(f"{t} {la:14.9f} {lo:14.9f} {hh:10.4f} {q:3d} {ns:3d} {sn:8.4f} {se:8.4f} {su:8.4f} "
                         f"{sne:8.4f} {seu:8.4f} {sun:8.4f} {ag:6.2f} {ra:6.1f}")
    return atomic_write_text(path, "\n".join(lines) + "\n")


#: columns of ``<out>.rtk.csv``: one line per rover epoch
RTK_COLUMNS = ("t_gps_s", "status", "ratio", "n_fix", "n_dd", "n_sat", "base_age_s", "x_m", "y_m", "z_m",
               *(f"slips_{k}" for k in RtkSolution.SLIP_KINDS))


def write_rtk_table(sol: RtkSolution, path, *, t_solution_s=None) -> "os.PathLike":
    """Write ``path`` (``<out>.rtk.csv``): :data:`RTK_COLUMNS` per rover epoch (ECEF position [m]); the
    slip columns of ``type(sol).SLIP_KINDS``; with ``t_solution_s`` (the epochs on the time axis of a
    solution whose rows are not GPS seconds, e.g. RTK/INS) a last column ``t_s``."""
    from .._atomic import atomic_write_text

    cols = RTK_COLUMNS[:-len(RtkSolution.SLIP_KINDS)] + tuple(f"slips_{k}" for k in type(sol).SLIP_KINDS)
    if t_solution_s is not None:
        cols += ("t_s",)
    lines = [",".join(cols)]
    # Python numbers (tolist) format as the numpy scalars did, without a numpy call per field
    age = [f"{a:.3f}" if math.isfinite(a) else "nan" for a in sol.base_age_s.tolist()]
    xyz = [f"{x:.4f},{y:.4f},{z:.4f}" if q > 0 else "nan,nan,nan"
           for (x, y, z), q in zip(sol.r_e.tolist(), sol.status.tolist())]
    slips = [",".join(map(str, row)) for row in np.asarray(sol.slips).astype(np.int64).tolist()]  # str(int(v))
    t_sol = [""] * len(sol) if t_solution_s is None else [f",{t:.6f}" for t in np.asarray(t_solution_s).tolist()]
    for t, q, ra, nf, nd, ns, ag, r, sl, ts in zip(sol.t_gps_s.tolist(), sol.status.tolist(), sol.ratio.tolist(),
                                                    sol.n_fix.tolist(), sol.n_dd.tolist(), sol.n_sat.tolist(), age,
                                                    xyz, slips, t_sol):
        lines.append(f"{t:.3f},{int(q)},{ra:.2f},{int(nf)},{int(nd)},{int(ns)},{ag},{r},{sl}{ts}")
    return atomic_write_text(path, "\n".join(lines) + "\n")
