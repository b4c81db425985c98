"""Carrier phase of the tight filter's satellite rows, for the time-differenced
carrier-phase (TDCP) rows of the tight EKF (``cpp/include/insnav/meas/tdcp.hpp``,
docs/algorithms.md "TDCP/INS").

:func:`phase_rows` matches each row of a :class:`~insnav.gnss.tight_inputs.TightInputs`
(epoch, system, satellite) with the RINEX observation of the same epoch and
satellite and returns the ``(M, 4)`` array ``_core.run_tight(phase=...)`` takes:
carrier phase [m] (cycles x wavelength of the row's signal), wavelength [m],
zero-difference 1-sigma [m] and the loss-of-lock indicator.
"""
from __future__ import annotations

import numpy as np

__all__ = ["phase_rows", "PHASE_COLUMNS"]

#: columns of :func:`phase_rows`
PHASE_COLUMNS = ("phase_m", "wavelength_m", "sigma_phase_m", "lli")

_SYS_INDEX = {"G": 0, "R": 1, "E": 2, "C": 3, "J": 4}


def phase_rows(inputs, obs, nav, t0_gps_s: float, *, sigma_phase_zenith_m: float = 0.01,
               floor_el_deg: float = 5.0) -> np.ndarray:
    """Carrier phase per tight-input row (NaN where the observation has none).

    Parameters
    ----------
    inputs : insnav.gnss.tight_inputs.TightInputs
        Rows from :func:`~insnav.gnss.tight_inputs.tight_inputs_from_rinex` of ``obs``.
    obs : insnav.gnss.ObsData
        The observations the rows came from (``L1`` [cycles], ``lli1``).
    nav : insnav.gnss.NavData
        For the GLONASS FDMA channels (:meth:`ObsData.wavelength_m`).
    t0_gps_s : float
        GPS time of dataset time 0 [s] (as for the inputs).
    sigma_phase_zenith_m : float
        Zero-difference phase 1-sigma at zenith [m]; / sin(elevation).
    floor_el_deg : float
        Elevation floor of the sigma model [deg].

    Returns
    -------
    (M, 4) float
        :data:`PHASE_COLUMNS`.  The LLI column is the RINEX indicator with bit 0
        also set where the half-cycle bit (bit 1) changed since the satellite's
        previous epoch (a half-cycle correction applied by the receiver is a
        phase jump of half a cycle).

    Notes
    -----
    An input epoch's time is the true reception time (tag minus the receiver
    clock estimate, :func:`~insnav.gnss.tight_inputs.tight_inputs_from_rinex`);
    it is matched with the nearest observation epoch tag within 0.4 times the
    smallest epoch interval (receiver clock offsets are below 1 ms).
    """
    m = len(inputs.prn)
    out = np.full((m, 4), np.nan)
    out[:, 3] = 0.0
    if m == 0 or getattr(obs, "L1", None) is None:
        return out
    L1 = np.asarray(obs.L1, float)
    lam = np.asarray(obs.wavelength_m(nav), float)
    lli = np.asarray(obs.lli1 if obs.lli1 is not None else np.zeros(L1.size), np.int64)
    sys_o = np.asarray(obs.system, "<U1")
    code_to_index = np.full(128, 5, np.int64)  # _SYS_INDEX by the letter's code point, 5 for any other
    for letter, k in _SYS_INDEX.items():
        code_to_index[ord(letter)] = k
    codes = np.ascontiguousarray(sys_o).view(np.int32).astype(np.int64) if sys_o.size else np.zeros(0, np.int64)
    sysi_o = np.where(codes < 128, code_to_index[np.minimum(codes, 127)], 5)
    ep_o = np.asarray(obs.epoch, np.int64)
    # half-cycle bit changed since the satellite's previous observation epoch -> slip
    key_sat = sysi_o * 1000 + np.asarray(obs.prn, np.int64)
    order = np.lexsort((ep_o, key_sat))
    ks, es, half = key_sat[order], ep_o[order], (lli[order] >> 1) & 1
    same = np.r_[False, (ks[1:] == ks[:-1]) & (es[1:] == es[:-1] + 1)]
    changed = np.zeros(L1.size, bool)
    changed[order] = same & (half != np.r_[0, half[:-1]])
    lli_eff = lli | changed.astype(np.int64)

    # input epochs -> observation epochs
    tag = np.asarray(obs.epoch_t_gps_s, float) - t0_gps_s
    t_in = np.asarray(inputs.epoch_t, float)
    if tag.size == 0 or t_in.size == 0:
        return out
    j = np.clip(np.searchsorted(tag, t_in), 1, max(tag.size - 1, 1)) if tag.size > 1 else np.zeros(t_in.size, int)
    if tag.size > 1:
        j = np.where(np.abs(tag[j - 1] - t_in) < np.abs(tag[j] - t_in), j - 1, j)
        tol = 0.4 * float(np.min(np.diff(tag))) if tag.size > 1 else 0.5
    else:
        tol = 0.5
    ok_ep = np.abs(tag[j] - t_in) <= tol
    # (obs epoch, system, prn) -> obs row
    key_o = (ep_o * 8 + sysi_o) * 1000 + np.asarray(obs.prn, np.int64)
    srt = np.argsort(key_o, kind="stable")
    row_ep = inputs.row_epoch
    sysi_i = np.array([_SYS_INDEX.get(s, 5) for s in np.asarray(inputs.system, "<U1")], np.int64)
    key_i = (j[row_ep] * 8 + sysi_i) * 1000 + np.asarray(inputs.prn, np.int64)
    pos = np.clip(np.searchsorted(key_o[srt], key_i), 0, key_o.size - 1)
    hit = (key_o[srt][pos] == key_i) & ok_ep[row_ep]
    r = srt[pos[hit]]
    phase = L1[r] * lam[r]
    good = np.isfinite(phase) & (lam[r] > 0)
    rows = np.flatnonzero(hit)[good]
    r = r[good]
    el = np.radians(np.maximum(np.asarray(inputs.elevation_deg, float)[rows], floor_el_deg))
    out[rows, 0] = L1[r] * lam[r]
    out[rows, 1] = lam[r]
    out[rows, 2] = sigma_phase_zenith_m / np.sin(el)
    out[rows, 3] = lli_eff[r]
    return out
