"""The code-only least-squares position fit of one epoch, the kernel of the SPP solver
(:mod:`insnav.gnss.spp`) and of the RTK base-position check (:func:`insnav.gnss.rtk.receiver_code_fix`).

Rows ``sats`` in the SPP input layout (:func:`insnav.gnss.spp.spp_inputs_from_rinex`): column 0 the
pseudorange [m], 2:5 the satellite position at transmission in the ECEF frame at reception [m],
8 the satellite clock [m].  The state is the position [m] and the receiver clock of the first
system present plus one inter-system bias per other system [m] (QZSS on the GPS clock,
:data:`insnav.gnss.systems.CLOCK_SYSTEM`).  Gauss-Newton on the weighted rows (RTKLIB ``pntpos``,
Takasu 2013, without its atmosphere models).  A module of its own so that the RTK command loads
it without the SPP solver.
"""
from __future__ import annotations

import numpy as np

from .systems import CLOCK_SYSTEM, SYSTEMS


def _design(r, sats, sys_col, n_clk):
    """Line of sight, ranges and the design matrix [-u, clock columns] at ``r``."""
    d = sats[:, 2:5] - r
    rng = np.linalg.norm(d, axis=1)
    u = d / rng[:, None]
    H = np.zeros((len(sats), 3 + n_clk))
    H[:, :3] = -u
    H[:, 3] = 1.0  # reference clock
    o = np.flatnonzero(sys_col > 0)
    H[o, 3 + sys_col[o]] = 1.0  # inter-system bias of the row's system
    return u, rng, H


def _clock(x, col):
    """Modelled receiver clock of each row: reference clock plus its system's ISB [m]."""
    return x[3] + np.append(0.0, x[4:])[col]


def _clock_columns(system):
    """Reference system, column of each row (0 = reference clock, k = ISB of the k-th other) and the letters
    (QZSS rows on the GPS clock, :data:`insnav.gnss.systems.CLOCK_SYSTEM`)."""
    system = np.asarray(system, dtype="<U1")
    for s, clock in CLOCK_SYSTEM.items():
        system = np.where(system == s, clock, system)
    present = [s for s in SYSTEMS if np.any(system == s)]
    others = [s for s in present if s != present[0]]
    col = np.zeros(len(system), np.int64)
    for k, s in enumerate(others):
        col[system == s] = k + 1
    return present[0], col, [present[0]] + others


def _position_fit(sats, system, w, x0, iterations):
    """Gauss-Newton from ``x0`` (3 position + clocks); returns (x, u, H, v, ok) or None on singular geometry."""
    ref, col, letters = _clock_columns(system)
    n_clk = len(letters)
    x = np.zeros(3 + n_clk)
    x[:3] = x0[:3]
    x[3] = x0[3]
    ok = False
    for _ in range(iterations):
        u, rng, H = _design(x[:3], sats, col, n_clk)
        y = sats[:, 0] - (rng - sats[:, 8] + _clock(x, col))
        Hw = H * w[:, None]
        dx = np.linalg.lstsq(Hw, y * w, rcond=None)[0]
        x = x + dx
        if not np.all(np.isfinite(x)):
            return None
        if np.linalg.norm(dx[:3]) < 1e-4:
            ok = True
            break
    u, rng, H = _design(x[:3], sats, col, n_clk)
    v = sats[:, 0] - (rng - sats[:, 8] + _clock(x, col))
    return x, u, H, v, ok, letters, col
