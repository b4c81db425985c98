"""GPS constellation states for the simulator (and anything else that needs them).

Two kinds of :class:`Constellation`:

* :meth:`Constellation.from_rinex_nav` -- real broadcast ephemerides; at each
  time every PRN uses its nearest-``toe`` healthy record inside the fit
  interval (:func:`insnav.gnss.ephemeris.select_ephemeris`); PRNs with no
  valid record are left out.
* :meth:`Constellation.nominal` -- an embedded set of 32 real LNAV element
  sets (one per PRN, from the IGS broadcast file ``brdc1180.21n``, see
  :mod:`insnav.gnss._nominal_elements`) propagated with the IS-GPS-200 Table
  20-IV model at *any* time: no validity window, no file needed at run time,
  fully deterministic.

States are geometric states *at* the requested GPS time in the ECEF frame of
that time (no light time).  For signal modelling use
:meth:`Constellation.transmit_states` (light time + Sagnac rotation into the
ECEF frame at reception, the convention documented in
:mod:`insnav.gnss.ephemeris`).

``clock_bias_m = c * dt_sv`` includes the relativistic term ``F e sqrt(A) sin E``
(IS-GPS-200 20.3.3.3.3.1) and *excludes* ``T_GD``; the pseudorange model is
``P = rho + c dt_rx - clock_bias_m + I + T``.
"""
from __future__ import annotations

import io
from typing import NamedTuple

import numpy as np

from .ephemeris import (
    C_LIGHT,
    Ephemerides,
    sat_clock,
    sat_position_velocity,
    select_ephemeris,
    transmit_states,
)

__all__ = ["SatStates", "Constellation"]


class SatStates(NamedTuple):
    """Satellite states at one epoch (k satellites)."""

    prn: np.ndarray  #: (k,) int
    r_e: np.ndarray  #: (k, 3) m, ECEF
    v_e: np.ndarray  #: (k, 3) m/s, ECEF
    clock_bias_m: np.ndarray  #: (k,) m (c * dt_sv)
    clock_drift_mps: np.ndarray  #: (k,) m/s


def _load_nominal() -> tuple[Ephemerides, float]:
    from ._nominal_elements import ELEMENTS_CSV, T_REF_GPS_S

    data = np.genfromtxt(io.StringIO(ELEMENTS_CSV), delimiter=",", names=True, dtype=float)
    cols = {name: data[name] for name in data.dtype.names}
    cols["prn"] = cols["prn"].astype(np.int64)
    return Ephemerides.from_columns(cols), float(T_REF_GPS_S)


class Constellation:
    """A set of GPS satellites whose ECEF states can be evaluated at any GPS time.

    Use the constructors :meth:`from_rinex_nav` and :meth:`nominal`.

    Parameters
    ----------
    eph : Ephemerides
    nominal : bool
        True: one record per PRN, propagated without validity window.
    ion_alpha, ion_beta : array_like (4,), optional
        Klobuchar parameters that came with the ephemerides.
    """

    def __init__(self, eph: Ephemerides, *, nominal: bool = False, ion_alpha=None, ion_beta=None):
        self.eph = eph
        self.is_nominal = bool(nominal)
        self.ion_alpha = None if ion_alpha is None else np.asarray(ion_alpha, dtype=float)
        self.ion_beta = None if ion_beta is None else np.asarray(ion_beta, dtype=float)
        self.prns = np.unique(eph.prn)
        if self.is_nominal and self.prns.size != len(eph):
            raise ValueError("a nominal constellation needs exactly one record per PRN")

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_rinex_nav(cls, path) -> "Constellation":
        """Broadcast constellation from a RINEX 2/3 navigation file (GPS records).

        Raises
        ------
        insnav.gnss.RinexError
            On a malformed file.
        """
        from .rinex import read_rinex_nav

        nav = read_rinex_nav(path)
        return cls(nav.eph, ion_alpha=nav.ion_alpha, ion_beta=nav.ion_beta)

    @classmethod
    def nominal(cls, t0_gps_s: float | None = None) -> "Constellation":
        """Nominal 32-satellite GPS constellation from embedded real elements.

        Parameters
        ----------
        t0_gps_s : float, optional
            Re-reference epoch [GPS s since 1980-01-06].  ``None`` keeps the
            elements at their real epoch (2021-04-28 20:00 GPS): the states
            at any time are the broadcast-model propagation of that day's
            elements.  A value shifts every ``toe``/``toc`` by the common
            amount ``t0_gps_s - T_REF`` (the broadcast ``t_oe`` in the
            node-longitude term is kept), so the sky at ``t0_gps_s + x``
            equals the real 2021-04-28 20:00 sky at ``+ x`` and satellite
            clocks are near their broadcast values around ``t0_gps_s``.

        Notes
        -----
        ``IDOT`` is set to zero (it is a fit parameter of a 4-hour arc; its
        secular use over months would tilt the planes by milliradians per
        month); ``delta_n`` and ``OMEGA_DOT`` (J2 effects) are kept.  Clock
        bias then grows as ``af0 + af1 (t - toc)`` with ``|af1| < 1e-11``
        (< 1 m per day).  The Klobuchar parameters of the same file come
        with it (``ion_alpha``, ``ion_beta``).
        """
        eph, t_ref = _load_nominal()
        cols = eph.to_columns()
        cols["idot"] = np.zeros_like(cols["idot"])
        cols["af2"] = np.zeros_like(cols["af2"])
        if t0_gps_s is not None:
            shift = float(t0_gps_s) - t_ref
            cols["toe"] = cols["toe"] + shift
            cols["toc"] = cols["toc"] + shift
        # Klobuchar set of brdc1180.21n.
        alpha = np.array([0.9313e-08, 0.1490e-07, -0.5960e-07, -0.1192e-06])
        beta = np.array([0.8806e05, 0.4915e05, -0.1311e06, -0.3277e06])
        return cls(Ephemerides.from_columns(cols), nominal=True, ion_alpha=alpha, ion_beta=beta)

    # ------------------------------------------------------------------ evaluation
    def _rows(self, t_gps_s: float, prns):
        p = self.prns if prns is None else np.atleast_1d(np.asarray(prns, dtype=np.int64))
        if self.is_nominal:
            lut = {int(q): i for i, q in enumerate(self.eph.prn)}
            idx = np.array([lut.get(int(q), -1) for q in p], dtype=np.int64)
        else:
            idx = select_ephemeris(self.eph, p, np.full(p.shape, float(t_gps_s)))
        ok = idx >= 0
        return p[ok], idx[ok]

    def sat_states(self, t_gps_s: float, prns=None) -> SatStates:
        """Satellite ECEF states at GPS time ``t_gps_s`` [s since 1980-01-06].

        Parameters
        ----------
        t_gps_s : float
        prns : int array_like, optional
            PRNs wanted (default: all).  PRNs without a usable ephemeris (or not
            in the constellation) are left out of the result, so check ``prn``.

        Returns
        -------
        SatStates
            Sorted as ``prns`` (or by PRN).
        """
        p, idx = self._rows(t_gps_s, prns)
        t = np.full(idx.shape, float(t_gps_s))
        pv = sat_position_velocity(self.eph, idx, t)
        clk = sat_clock(self.eph, idx, t, relativistic=True, E=pv.E, E_dot=pv.E_dot)
        return SatStates(p, pv.r_e, pv.v_e, C_LIGHT * clk.bias_s, C_LIGHT * clk.drift_s_s)

    def transmit_states(self, t_rx_gps_s: float, r_rx_e, prns=None) -> SatStates:
        """Satellite states at signal transmission seen from ``r_rx_e`` at ``t_rx_gps_s``.

        Light-time iteration and Sagnac rotation as in
        :func:`insnav.gnss.ephemeris.transmit_states`: ``r_e``/``v_e`` are in
        the ECEF frame at reception, the clock is evaluated at transmission.
        Ephemerides are selected at ``t_rx_gps_s``.
        """
        p, idx = self._rows(t_rx_gps_s, prns)
        ts = transmit_states(self.eph, idx, float(t_rx_gps_s), r_rx_e)
        return SatStates(p, ts.r_e, ts.v_e, C_LIGHT * ts.clock_bias_s, C_LIGHT * ts.clock_drift_s_s)
