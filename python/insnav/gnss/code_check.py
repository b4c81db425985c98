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

from .._median import median
from ..errors import UserError
from ._rtk_keys import CODE_FIT_TOLERANCE_M
from .code_fix import _position_fit

__all__ = ["check_inputs_code_fit"]


def check_inputs_code_fit(inp, r0_e, path, n_epochs: int = 10) -> float | None:
    """:class:`UserError` (one line naming ``path``) when the pseudoranges do not fit one receiver
    position and clock per epoch: the median, over up to ``n_epochs`` epochs spread over the run, of the
    residual RMS of a unit-weight one-epoch fit (:func:`insnav.gnss.code_fix._position_fit`, started
    from ``r0_e``) above :data:`insnav.gnss._rtk_keys.CODE_FIT_TOLERANCE_M`, the RTK inputs' bound
    (:func:`insnav.gnss.rtk.check_code_fit`).  Epoch time tags moved by 0.5 s against the observations
    gave a solution 264 m off with exit status 0 (RAIM excluded rows in every epoch); the urban smartLoc
    file fits within 15 m.  Returns the median residual RMS [m] (None: no epoch with a redundant
    fit)."""
    ne = inp.epoch_t.size
    rms = []
    for e in np.unique(np.linspace(0, ne - 1, min(n_epochs, ne)).astype(np.int64)) if ne else ():
        a, b = int(inp.epoch_start[e]), int(inp.epoch_start[e + 1])
        sats, system = inp.sats[a:b], inp.system[a:b]
        m = np.isfinite(sats[:, 0]) & np.all(np.isfinite(sats[:, 2:5]), axis=1) & np.isfinite(sats[:, 8])
        if m.sum() < 4 + len(np.unique(system[m])):  # one redundant row at least
            continue
        fit = _position_fit(sats[m], system[m], np.ones(int(m.sum())), np.append(np.asarray(r0_e, float), 0.0), 10)
        if fit is None or not fit[4]:
            continue
        rms.append(float(np.sqrt(np.mean(fit[3] ** 2))))
    if not rms:
        return None
    value = median(rms)
    if value > CODE_FIT_TOLERANCE_M:
        raise UserError(f"{path}: the pseudoranges do not fit one receiver position and clock (median residual "
                        f"RMS {value:.0f} m over {len(rms)} epochs; at most {CODE_FIT_TOLERANCE_M:.0f} m accepted, "
                        "a few metres usual): epoch time tags shifted against the observations, or a navigation "
                        "file of other satellites")
    return value
