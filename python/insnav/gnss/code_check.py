"""The pseudoranges of a run against one receiver position and clock per epoch.

A receiver whose epoch time tags are moved against its observations (or a navigation file of other
satellites) has pseudoranges that no position and clock fit: the satellites are computed where they
were not when the ranges were measured.  The SPP run's inputs (:class:`TightInputs`) are checked
here; the RTK inputs by :func:`insnav.gnss.rtk.check_code_fit`, with the same bound
(:data:`insnav.gnss._rtk_keys.CODE_FIT_TOLERANCE_M`).  The check needs redundant epochs: the
rtklibexplorer walk's tight run uses 4 satellites per epoch, and its rover moved by 0.5 s gave a
solution 234 m off (horizontal) with exit 0 and "health: ok" that no code fit can see (measured).
"""
from __future__ import annotations

import numpy as np

from .._median import median, unique  # np.unique would import numpy.ma (insnav.gnss.rtk: the RTK command's start-up)
from ..errors import UserError
from ._rtk_keys import CODE_FIT_TOLERANCE_M
from .code_fix import _position_fit

__all__ = ["check_inputs_code_fit", "spread_epochs", "unit_weight_fit"]


def spread_epochs(n_total: int, n: int) -> np.ndarray:
    """Up to ``n`` epoch indices spread evenly over ``0 .. n_total - 1`` (first and last included)."""
    return unique(np.linspace(0, n_total - 1, min(n, n_total)).astype(np.int64)) if n_total else np.zeros(0, np.int64)


def unit_weight_fit(sats, system, r0_e):
    """One-epoch code-only fit with unit weights (:func:`insnav.gnss.code_fix._position_fit`: position
    and one clock per system, Gauss-Newton from ``r0_e``): ``(r_e [m], residual RMS [m])``, or None
    without a redundant row or a converged fit.  ``sats``: rows in the column layout of
    :class:`insnav.gnss.tight_inputs.TightInputs` (pseudorange, satellite position, clock)."""
    if len(system) < 4 + len(unique(system)):  # one redundant row at least
        return None
    fit = _position_fit(sats, system, np.ones(len(system)), np.append(np.asarray(r0_e, float), 0.0), 10)
    if fit is None or not fit[4]:
        return None
    return fit[0][:3], float(np.sqrt(np.mean(fit[3] ** 2)))


def check_inputs_code_fit(inp, r0_e, path, n_epochs: int = 10) -> float | None:
    """:class:`UserError` (one line naming ``path``) when the pseudoranges do not fit one receiver
    position and clock per epoch: the median, over up to ``n_epochs`` epochs spread over the run, of the
    residual RMS of a unit-weight one-epoch fit (:func:`insnav.gnss.code_fix._position_fit`, started
    from ``r0_e``) above :data:`insnav.gnss._rtk_keys.CODE_FIT_TOLERANCE_M`, the RTK inputs' bound
    (:func:`insnav.gnss.rtk.check_code_fit`).  Epoch time tags moved by 0.5 s against the observations
    gave a solution 264 m off with exit status 0 (RAIM excluded rows in every epoch); the urban smartLoc
    file fits within 15 m.  Returns the median residual RMS [m] (None: no epoch with a redundant
    fit)."""
    rms = []
    for e in spread_epochs(inp.epoch_t.size, n_epochs):
        a, b = int(inp.epoch_start[e]), int(inp.epoch_start[e + 1])
        sats, system = inp.sats[a:b], inp.system[a:b]
        m = np.isfinite(sats[:, 0]) & np.all(np.isfinite(sats[:, 2:5]), axis=1) & np.isfinite(sats[:, 8])
        fit = unit_weight_fit(sats[m], system[m], r0_e)
        if fit is not None:
            rms.append(fit[1])
    if not rms:
        return None
    value = median(rms)
    if value > CODE_FIT_TOLERANCE_M:
        raise UserError(f"{path}: the pseudoranges do not fit one receiver position and clock (median residual "
                        f"RMS {value:.0f} m over {len(rms)} epochs; at most {CODE_FIT_TOLERANCE_M:.0f} m accepted, "
                        "a few metres usual): epoch time tags shifted against the observations, or a navigation "
                        "file of other satellites")
    return value
