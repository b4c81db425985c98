"""Navigation state and trajectory containers of the public API.

Angles are in degrees and carry ``_deg`` in their names; heights in metres
(``h_m``); velocities in m/s in NED.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from ..units import DEG

__all__ = ["NavState", "NavTrajectory", "Trajectory", "NAV_FIELDS", "NAV_COLUMNS"]

#: the navigation fields every trajectory container declares (time [s], position [deg, deg, m],
#: NED velocity [m/s], 3-2-1 Euler angles [deg]), and their file columns
NAV_FIELDS = ("t", "lat_deg", "lon_deg", "h_m", "v_n", "roll_deg", "pitch_deg", "yaw_deg")
NAV_COLUMNS = ("t_s", "lat_deg", "lon_deg", "h_m", "vn_mps", "ve_mps", "vd_mps", "roll_deg", "pitch_deg", "yaw_deg")


@dataclass
class NavState:
    """A navigation state of the IMU centre.

    Parameters
    ----------
    lat_deg, lon_deg : float
        Geodetic latitude and longitude (WGS-84) [deg].
    h_m : float
        Height above the ellipsoid [m].
    v_n : array_like of 3
        Velocity relative to the Earth, North-East-Down [m/s].
    roll_deg, pitch_deg, yaw_deg : float
        3-2-1 Euler angles of the body (FRD) relative to NED [deg].
    """

    lat_deg: float
    lon_deg: float
    h_m: float
    v_n: np.ndarray = field(default_factory=lambda: np.zeros(3))
    roll_deg: float = 0.0
    pitch_deg: float = 0.0
    yaw_deg: float = 0.0

    def __post_init__(self):
        self.v_n = np.asarray(self.v_n, dtype=float).reshape(3)
        for name in ("lat_deg", "lon_deg", "h_m", "roll_deg", "pitch_deg", "yaw_deg"):
            value = float(getattr(self, name))
            if not np.isfinite(value):
                raise ValueError(f"NavState.{name} must be finite, got {value!r}")
            setattr(self, name, value)
        if not np.all(np.isfinite(self.v_n)):
            raise ValueError(f"NavState.v_n must be finite, got {self.v_n!r}")
        if abs(self.lat_deg) > 90.0:
            raise ValueError(f"NavState.lat_deg must be within [-90, 90], got {self.lat_deg}")

    @property
    def pos_llh(self) -> np.ndarray:
        """``[lat, lon, h]`` in SI (rad, rad, m)."""
        return np.array([self.lat_deg * DEG, self.lon_deg * DEG, self.h_m])

    @property
    def rpy(self) -> np.ndarray:
        """``[roll, pitch, yaw]`` [rad]."""
        return np.array([self.roll_deg, self.pitch_deg, self.yaw_deg]) * DEG


@dataclass
class NavTrajectory:
    """Navigation states of the IMU centre sampled at times ``t`` (one row per sample).

    The one navigation-trajectory schema: :class:`~insnav.data.dataset.Truth` (adds the true
    specific force and rate), :class:`~insnav.Solution` (adds sigmas, IMU errors,
    innovations) and the free-inertial output of :func:`insnav.mechanize` (this
    class, also named ``insnav.Trajectory``) share these fields and the first
    :data:`NAV_COLUMNS` of their files.

    Attributes
    ----------
    t : ndarray (N,)
        Time [s].
    lat_deg, lon_deg, h_m : ndarray (N,)
        Geodetic position [deg, deg, m].
    v_n : ndarray (N, 3)
        NED velocity [m/s].
    roll_deg, pitch_deg, yaw_deg : ndarray (N,)
        3-2-1 Euler angles [deg], yaw in (-180, 180].
    """

    t: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    h_m: np.ndarray
    v_n: np.ndarray
    roll_deg: np.ndarray
    pitch_deg: np.ndarray
    yaw_deg: np.ndarray

    #: fixed column names of :meth:`to_dataframe` and CSV output
    COLUMNS = NAV_COLUMNS

    def __len__(self) -> int:
        return len(self.t)

    def state_at(self, i: int) -> NavState:
        """The state of row ``i`` as a :class:`NavState`."""
        return NavState(self.lat_deg[i], self.lon_deg[i], self.h_m[i], self.v_n[i],
                        self.roll_deg[i], self.pitch_deg[i], self.yaw_deg[i])

    def nav_array(self) -> np.ndarray:
        """(N, 10) array of the navigation fields in :data:`NAV_COLUMNS` order."""
        return np.column_stack([self.t, self.lat_deg, self.lon_deg, self.h_m, self.v_n,
                                self.roll_deg, self.pitch_deg, self.yaw_deg])

    def to_array(self) -> np.ndarray:
        """(N, 10) array in :attr:`COLUMNS` order."""
        return self.nav_array()

    def to_dataframe(self):
        """A pandas DataFrame with :attr:`COLUMNS` (pandas is optional)."""
        import pandas as pd

        return pd.DataFrame(self.to_array(), columns=list(self.COLUMNS))


#: the free-inertial output of :func:`insnav.mechanize` (the same class)
Trajectory = NavTrajectory
