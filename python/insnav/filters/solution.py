"""What a run returns: :class:`Solution` (per output row: navigation state,
sigmas, IMU error estimates; per GNSS record: innovation, NIS, status) and
the record status codes, the same as ``RecordStatus`` in
``cpp/include/insnav/engine/closed_loop.hpp``."""
from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

from ..units import RAD2DEG

__all__ = ["RecordStatus", "GNSS_STATUS", "Solution"]


class RecordStatus(enum.IntEnum):
    """What became of one GNSS record (``Solution.gnss_status``)."""

    NOT_USED = 0              #: nothing to use (masked out, or no satellite: prediction only)
    APPLIED = 1               #: the update was applied and fed back
    REJECTED_BY_GATE = 2      #: NIS above the gate
    NOT_POSITIVE_DEFINITE = 3  #: innovation covariance not positive definite
    OUTSIDE_IMU_SPAN = 4      #: valid before the first or after the last IMU sample
    TOO_OLD = 5               #: exact delay filter: older than the history it keeps


#: GNSS record status codes of :attr:`Solution.gnss_status`
GNSS_STATUS = {RecordStatus.NOT_USED: "not used", RecordStatus.APPLIED: "applied",
               RecordStatus.REJECTED_BY_GATE: "rejected by gate", RecordStatus.NOT_POSITIVE_DEFINITE: "S not positive definite",
               RecordStatus.OUTSIDE_IMU_SPAN: "outside the IMU time span",
               RecordStatus.TOO_OLD: "refused: older than the history"}


@dataclass
class Solution:
    """A navigation solution with its uncertainty and filter diagnostics.

    Attributes
    ----------
    t : (N,) s
    lat_deg, lon_deg, h_m : (N,) position of the IMU centre
    v_n : (N, 3) m/s NED velocity
    roll_deg, pitch_deg, yaw_deg : (N,)
    sigma_pos_n_m : (N, 3) 1-sigma N, E, D position [m]
    sigma_vel_n_mps : (N, 3)
    sigma_att_deg : (N, 3) 1-sigma of the attitude error angles [deg]
    acc_bias_mps2, gyro_bias_rps : (N, 3) estimated IMU biases (SI)
    acc_scale, gyro_scale : (N, 3) estimated scale-factor errors [-]
    gnss_t : (M,) s, time of validity of each GNSS record
    innovation : (M, 6) INS minus GNSS (N, E, D position [m], velocity [m/s]) before the update
    nis : (M,) normalised innovation squared
    gnss_status : (M,) int8, see :data:`GNSS_STATUS`
    summary : dict
        filter, coupling, counts of updates / rejections / covariance repairs.
    """

    t: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    h_m: np.ndarray
    v_n: np.ndarray
    roll_deg: np.ndarray
    pitch_deg: np.ndarray
    yaw_deg: np.ndarray
    sigma_pos_n_m: np.ndarray
    sigma_vel_n_mps: np.ndarray
    sigma_att_deg: np.ndarray
    acc_bias_mps2: np.ndarray
    gyro_bias_rps: np.ndarray
    acc_scale: np.ndarray
    gyro_scale: np.ndarray
    gnss_t: np.ndarray
    innovation: np.ndarray
    nis: np.ndarray
    gnss_status: np.ndarray
    summary: dict = field(default_factory=dict)

    COLUMNS = ("t", "lat_deg", "lon_deg", "h_m", "vn", "ve", "vd", "roll_deg", "pitch_deg", "yaw_deg",
               "sigma_n_m", "sigma_e_m", "sigma_d_m", "sigma_vn_mps", "sigma_ve_mps", "sigma_vd_mps",
               "sigma_roll_deg", "sigma_pitch_deg", "sigma_yaw_deg",
               "acc_bias_x_mps2", "acc_bias_y_mps2", "acc_bias_z_mps2",
               "gyro_bias_x_dph", "gyro_bias_y_dph", "gyro_bias_z_dph",
               "acc_scale_x_ppm", "acc_scale_y_ppm", "acc_scale_z_ppm",
               "gyro_scale_x_ppm", "gyro_scale_y_ppm", "gyro_scale_z_ppm")

    def __len__(self) -> int:
        return len(self.t)

    def to_array(self) -> np.ndarray:
        """(N, 31) array in :attr:`COLUMNS` order (user units as named)."""
        return np.column_stack([self.t, self.lat_deg, self.lon_deg, self.h_m, self.v_n,
                                self.roll_deg, self.pitch_deg, self.yaw_deg,
                                self.sigma_pos_n_m, self.sigma_vel_n_mps, self.sigma_att_deg,
                                self.acc_bias_mps2, self.gyro_bias_rps * RAD2DEG * 3600.0,
                                self.acc_scale * 1e6, self.gyro_scale * 1e6])

    def to_dataframe(self):
        """A pandas DataFrame with the fixed :attr:`COLUMNS` (pandas is optional)."""
        import pandas as pd

        return pd.DataFrame(self.to_array(), columns=list(self.COLUMNS))

    def save_csv(self, path) -> None:
        """Write the solution CSV atomically (a temp file renamed into place)."""
        from .._atomic import atomic_write_text

        header = ",".join(self.COLUMNS)
        import io

        buf = io.StringIO()
        np.savetxt(buf, self.to_array(), delimiter=",", header=header, comments="",
                   fmt=["%.6f"] + ["%.10f"] * 2 + ["%.5f"] * 28)
        atomic_write_text(path, buf.getvalue())
