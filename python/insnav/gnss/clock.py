"""Receiver clock noise models.

Two-state clock (bias b [m], drift d [m/s]): ``b' = d + w_b``, ``d' = w_d``
with PSDs ``clock_bias_psd`` [m^2/s] and ``clock_drift_psd`` [m^2/s^3]
(Brown & Hwang, *Introduction to Random Signals and Applied Kalman
Filtering*, 4th ed., sec. 9.3, eqs. (9.3.8)-(9.3.9): ``S_b = c^2 h0 / 2``,
``S_d = 2 pi^2 c^2 h_-2``).  Clock classes from their Table 9.1 Allan-variance
coefficients (``h0``, ``h_-2``); the flicker term ``h_-1`` is left out of the two-state
model.  TCXO defaults with margin for flicker noise:
``clock_bias_psd = 0.1`` m^2/s, ``clock_drift_psd = 0.04`` m^2/s^3.
"""
from __future__ import annotations

import numpy as np

__all__ = ["C_LIGHT_MPS", "CLOCK_ALLAN", "CLOCK_CLASSES", "TCXO_CLOCK_BIAS_PSD", "TCXO_CLOCK_DRIFT_PSD",
           "clock_model", "clock_psd_of_class"]

C_LIGHT_MPS = 299_792_458.0
#: Brown & Hwang (2012) Table 9.1: ``(h0, h_-2)`` of the fractional frequency PSD
CLOCK_ALLAN = {"tcxo": (2e-19, 2e-20), "ocxo": (8e-20, 4e-23), "rubidium": (2e-20, 4e-29)}
#: clock class -> (clock_bias_rw [m/sqrt(s)], clock_drift_rw [(m/s)/sqrt(s)])
CLOCK_CLASSES = {k: (C_LIGHT_MPS * np.sqrt(h0 / 2.0), C_LIGHT_MPS * np.sqrt(2.0 * np.pi ** 2 * hm2))
                 for k, (h0, hm2) in CLOCK_ALLAN.items()}

#: TCXO receiver clock noise (Brown & Hwang Table 9.1, see the module docstring)
TCXO_CLOCK_BIAS_PSD = 0.1     # m^2/s
TCXO_CLOCK_DRIFT_PSD = 0.04   # m^2/s^3


def clock_model(dataset) -> tuple[float, float]:
    """(clock_bias_psd [m^2/s], clock_drift_psd [m^2/s^3]) for a dataset.

    A simulator dataset's ``gnss_raw`` random-walk densities (squared, with a
    small floor), else the TCXO defaults.
    """
    gr = (getattr(dataset, "scenario", None) or {}).get("gnss_raw") or {}
    if "clock_bias_rw_m_per_sqrts" in gr or "clock_drift_rw_mps_per_sqrts" in gr or "clock" in gr:
        cb, cd = CLOCK_CLASSES.get(gr.get("clock", ""), (0.0, 0.0))
        qb = float(gr.get("clock_bias_rw_m_per_sqrts", cb)) ** 2
        qd = float(gr.get("clock_drift_rw_mps_per_sqrts", cd)) ** 2
        return max(qb, 1e-6), max(qd, 1e-12)
    return TCXO_CLOCK_BIAS_PSD, TCXO_CLOCK_DRIFT_PSD


def clock_psd_of_class(name: str) -> tuple[float, float]:
    """(clock_bias_psd [m^2/s], clock_drift_psd [m^2/s^3]) of a named clock class
    (``"tcxo"``, ``"ocxo"``, ``"rubidium"``; Brown & Hwang Table 9.1, see
    :data:`CLOCK_CLASSES`)."""
    if name not in CLOCK_CLASSES:
        raise ValueError(f"clock class {name!r} unknown; known: {', '.join(CLOCK_CLASSES)}")
    qb, qd = CLOCK_CLASSES[name]
    return qb * qb, qd * qd
