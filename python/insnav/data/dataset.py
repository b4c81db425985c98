"""Dataset containers and the on-disk dataset directory.

A dataset directory (written by :meth:`Dataset.save`, ``insnav simulate``;
read by :func:`load_dataset`, ``insnav run``) holds:

==================  ==========================================================
``imu.csv``         ``t_s``, ``dtheta_{x,y,z}_rad``, ``dv_{x,y,z}_mps``:
                    increments over ``(t - dt, t]``, body FRD
``gnss.csv``        loosely coupled fixes of the antenna: ``t_valid_s``,
                    ``t_arrival_s``, ``lat_deg``, ``lon_deg``, ``h_m``,
                    ``v{n,e,d}_mps``, ``sigma_{n,e,d}_m``, ``sigma_v{n,e,d}_mps``
``gnss_raw.csv``    (tight presets only) one row per satellite and epoch, see
                    :class:`GnssRaw`
``truth.csv``       IMU-centre truth: ``t_s``, ``lat_deg``, ``lon_deg``,
                    ``h_m``, ``v{n,e,d}_mps``, ``roll_deg``, ``pitch_deg``,
                    ``yaw_deg``, ``f_{x,y,z}_mps2``, ``omega_{x,y,z}_radps``
``imu_errors.csv``  injected biases and scale factors (see :class:`ImuErrors`)
``odometer.csv``    (car presets with an odometer) ``t_s``, ``speed_mps``:
                    mean forward speed of the rear-axle centre over
                    ``(t - dt, t]`` from the wheel ticks (see :class:`Odometer`)
``scenario.toml``   the resolved scenario (``extends`` merged, seed set)
``dataset.json``    metadata: t0, GPS time offset, lever arm, initial state,
                    the IMU model in SI (:func:`insnav.sim.imu.imu_model_dict`)
==================  ==========================================================

Every CSV has one header line naming each column with its unit.  Writing is
atomic: files go to a temporary sibling directory which is renamed into place,
so a directory that exists is always complete.
"""
from __future__ import annotations

from ..errors import close_matches

import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._median import median

from .nav import NAV_COLUMNS, NavState, NavTrajectory

FORMAT_VERSION = 1


@dataclass(frozen=True)
class RowOrigin:
    """Where the rows of a table came from, for error messages ("file:line").

    Attributes
    ----------
    source : str
        File name (or another description of the source).
    first_line : int
        1-based file line of row 0 when the rows are on consecutive lines.
    lines : ndarray (N,) of int or None
        Explicit 1-based line of each row (blank lines skipped, rows
        inserted by a repair are 0); None: ``first_line + row``.
    """

    source: str
    first_line: int = 1
    lines: np.ndarray | None = None

    def line(self, i: int) -> int:
        """1-based file line of row ``i`` (0 for a row that is not in the file)."""
        return int(self.lines[i]) if self.lines is not None else self.first_line + int(i)

    def where(self, i: int) -> str:
        """``"<source>:<line>"`` of row ``i``."""
        ln = self.line(i)
        return f"{self.source}:{ln}" if ln > 0 else f"{self.source} (inserted row {i})"

    def all_lines(self, n: int) -> np.ndarray:
        """Line of every one of ``n`` rows as an array."""
        if self.lines is not None:
            return np.asarray(self.lines, dtype=np.int64)
        return self.first_line + np.arange(n, dtype=np.int64)

    def take(self, idx, n: int) -> "RowOrigin":
        """The origin of rows ``idx`` (index array or boolean mask) of an ``n``-row table."""
        return RowOrigin(self.source, self.first_line, self.all_lines(n)[np.asarray(idx)])


@dataclass
class ImuData:
    """IMU increments.

    Attributes
    ----------
    t : ndarray (N,)
        End of each sample interval [s].
    dtheta_b : ndarray (N, 3)
        Angle increments over ``(t - dt, t]``, body FRD [rad].
    dv_b : ndarray (N, 3)
        Velocity (specific-force) increments [m/s].
    """

    t: np.ndarray
    dtheta_b: np.ndarray
    dv_b: np.ndarray
    #: file and line of each sample, set by the readers (see :class:`RowOrigin`)
    origin: RowOrigin | None = field(default=None, repr=False, compare=False)

    COLUMNS = ("t_s", "dtheta_x_rad", "dtheta_y_rad", "dtheta_z_rad", "dv_x_mps", "dv_y_mps",
               "dv_z_mps")

    def __len__(self):
        return len(self.t)

    @property
    def dt(self) -> float:
        """Median sample interval [s]."""
        return median(np.diff(self.t)) if len(self.t) > 1 else float("nan")  # np.median without numpy.ma

    def to_array(self):
        return np.column_stack([self.t, self.dtheta_b, self.dv_b])

    @classmethod
    def from_array(cls, a):
        return cls(a[:, 0].copy(), a[:, 1:4].copy(), a[:, 4:7].copy())


def column(x):
    """A column of fixes as a float64 array, or as it is when it is read on demand from its file
    (:class:`insnav.io.text_blocks.FileColumn`: the consumer indexes the rows it needs, never the whole)."""
    return x if getattr(x, "on_demand", False) else np.asarray(x, float)


@dataclass
class GnssFixes:
    """Loosely coupled GNSS fixes of the antenna.

    Attributes
    ----------
    t_valid : ndarray (N,)
        Time of validity [s].
    t_arrival : ndarray (N,)
        Time at which the fix reaches the filter [s] (``t_valid`` plus a
        whole number of GNSS epochs of delay).
    lat_deg, lon_deg, h_m : ndarray (N,)
        Antenna position [deg, deg, m].
    v_n : ndarray (N, 3)
        Antenna velocity NED [m/s] (NaN when not available, e.g. RTK files).
    sigma_pos_n : ndarray (N, 3)
        1-sigma of the position noise, North, East, Down [m].
    sigma_vel_n : ndarray (N, 3)
        1-sigma of the velocity noise [m/s] (NaN when no velocity).
    """

    t_valid: np.ndarray
    t_arrival: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    h_m: np.ndarray
    v_n: np.ndarray
    sigma_pos_n: np.ndarray
    sigma_vel_n: np.ndarray
    #: file and line of each record, set by the readers (see :class:`RowOrigin`)
    origin: RowOrigin | None = field(default=None, repr=False, compare=False)

    COLUMNS = ("t_valid_s", "t_arrival_s", "lat_deg", "lon_deg", "h_m", "vn_mps", "ve_mps",
               "vd_mps", "sigma_n_m", "sigma_e_m", "sigma_d_m", "sigma_vn_mps", "sigma_ve_mps",
               "sigma_vd_mps")

    def __len__(self):
        return len(self.t_valid)

    @property
    def delay_epochs(self) -> np.ndarray:
        """Delay in seconds ``t_arrival - t_valid`` [s]."""
        return self.t_arrival - self.t_valid

    def to_array(self):
        return np.column_stack([self.t_valid, self.t_arrival, self.lat_deg, self.lon_deg,
                                self.h_m, self.v_n, self.sigma_pos_n, self.sigma_vel_n])

    @classmethod
    def from_array(cls, a):
        a = a.reshape(-1, 14)
        return cls(a[:, 0].copy(), a[:, 1].copy(), a[:, 2].copy(), a[:, 3].copy(), a[:, 4].copy(),
                   a[:, 5:8].copy(), a[:, 8:11].copy(), a[:, 11:14].copy())


@dataclass
class Truth(NavTrajectory):
    """Truth of the IMU centre (the :class:`~insnav.data.nav.NavTrajectory` fields
    and the true specific force and angular rate).

    Attributes
    ----------
    t : ndarray (N,)  [s]
    lat_deg, lon_deg, h_m : ndarray (N,)  [deg, deg, m]
    v_n : ndarray (N, 3)  NED velocity [m/s]
    roll_deg, pitch_deg, yaw_deg : ndarray (N,)
        3-2-1 Euler angles [deg], yaw in (-180, 180].
    f_ib_b : ndarray (N, 3) or None
        True specific force, body FRD [m/s^2].
    omega_ib_b : ndarray (N, 3) or None
        True angular rate relative to inertial space, body FRD [rad/s].
    """

    f_ib_b: np.ndarray | None = None
    omega_ib_b: np.ndarray | None = None

    COLUMNS = NAV_COLUMNS + ("f_x_mps2", "f_y_mps2", "f_z_mps2", "omega_x_radps", "omega_y_radps",
                             "omega_z_radps")

    def to_array(self):
        n = len(self.t)
        f = self.f_ib_b if self.f_ib_b is not None else np.full((n, 3), np.nan)
        w = self.omega_ib_b if self.omega_ib_b is not None else np.full((n, 3), np.nan)
        return np.column_stack([self.nav_array(), f, w])

    @classmethod
    def from_array(cls, a):
        a = a.reshape(-1, 16)
        return cls(a[:, 0].copy(), a[:, 1].copy(), a[:, 2].copy(), a[:, 3].copy(),
                   a[:, 4:7].copy(), a[:, 7].copy(), a[:, 8].copy(), a[:, 9].copy(),
                   a[:, 10:13].copy(), a[:, 13:16].copy())


#: system letters in the order of their index, the same as insnav.gnss.systems.SYSTEMS
#: (the data layer does not import gnss; tests/test_tight_multi.py checks they agree)
SYSTEM_LETTERS = ("G", "R", "E", "C")


@dataclass
class GnssRaw:
    """Raw GPS observations, one row per (epoch, satellite).

    Pseudorange model (what :mod:`insnav.sim.gnss_raw` simulates and the
    tight filter inverts)::

        rho  = |r_sat - r_rx| + b_rx - sat_clock_bias + e_rho
        rhod = u . (v_sat - v_rx) + d_rx - sat_clock_drift + e_rhod,  u = (r_sat - r_rx)/|r_sat - r_rx|

    where ``r_sat``/``v_sat`` are the satellite position and velocity at
    transmission rotated into the ECEF frame at reception (Sagnac), as stored
    in ``sat_r_e``/``sat_v_e``; ``r_rx``/``v_rx`` are the antenna ECEF position
    and velocity at ``t``; ``b_rx`` [m], ``d_rx`` [m/s] the receiver clock.

    Attributes
    ----------
    t : ndarray (M,)
        Reception time (true time) [s].
    prn : ndarray (M,) int
    pseudorange_m, pseudorange_rate_mps : ndarray (M,)
    sat_r_e, sat_v_e : ndarray (M, 3)
        Satellite ECEF position [m] and velocity [m/s] at transmission, in
        the ECEF frame at reception.
    sat_clock_bias_m, sat_clock_drift_mps : ndarray (M,)
        ``c dt_sv`` [m] (relativistic term included, no T_GD) and its rate [m/s].
    elevation_deg, azimuth_deg : ndarray (M,)
        Seen from the true antenna position [deg].
    travel_time_s : ndarray (M,)
        Signal travel time [s].
    sigma_pr_m, sigma_prr_mps : ndarray (M,)
        Noise 1-sigma [m], [m/s].
    rx_clock_bias_m, rx_clock_drift_mps : ndarray (M,)
        TRUE receiver clock bias ``b_rx`` [m] and drift ``d_rx`` [m/s] (for
        evaluation; a filter must not read them).
    """

    t: np.ndarray
    prn: np.ndarray
    pseudorange_m: np.ndarray
    pseudorange_rate_mps: np.ndarray
    sat_r_e: np.ndarray
    sat_v_e: np.ndarray
    sat_clock_bias_m: np.ndarray
    sat_clock_drift_mps: np.ndarray
    elevation_deg: np.ndarray
    azimuth_deg: np.ndarray
    travel_time_s: np.ndarray
    sigma_pr_m: np.ndarray
    sigma_prr_mps: np.ndarray
    rx_clock_bias_m: np.ndarray
    rx_clock_drift_mps: np.ndarray
    #: (M,) one-letter system of each row (insnav.gnss.systems.SYSTEMS); None: every row GPS
    system: np.ndarray | None = None

    def __post_init__(self):
        if self.system is not None:
            self.system = np.asarray(self.system, dtype="<U1")

    def is_multi(self) -> bool:
        """True when any row is not GPS."""
        return self.system is not None and bool(np.any(self.system != "G"))

    COLUMNS = ("t_s", "prn", "pseudorange_m", "pseudorange_rate_mps", "sat_x_m", "sat_y_m",
               "sat_z_m", "sat_vx_mps", "sat_vy_mps", "sat_vz_mps", "sat_clock_bias_m",
               "sat_clock_drift_mps", "elevation_deg", "azimuth_deg", "travel_time_s",
               "sigma_pr_m", "sigma_prr_mps", "true_rx_clock_bias_m", "true_rx_clock_drift_mps")
    #: gnss_raw.csv of a multi-system dataset: COLUMNS + the system index (0 G, 1 R, 2 E, 3 C)
    COLUMNS_MULTI = COLUMNS + ("system",)

    def __len__(self):
        return len(self.t)

    def epochs(self):
        """Unique epoch times [s]."""
        return np.unique(self.t)

    def to_array(self):
        """(M, 19) float, columns COLUMNS; (M, 20) with the system index when :meth:`is_multi`."""
        cols = [self.t, self.prn, self.pseudorange_m, self.pseudorange_rate_mps,
                self.sat_r_e, self.sat_v_e, self.sat_clock_bias_m,
                self.sat_clock_drift_mps, self.elevation_deg, self.azimuth_deg,
                self.travel_time_s, self.sigma_pr_m, self.sigma_prr_mps,
                self.rx_clock_bias_m, self.rx_clock_drift_mps]
        if self.is_multi():
            idx = {c: k for k, c in enumerate(SYSTEM_LETTERS)}
            cols.append(np.array([idx[c] for c in self.system], np.int64))
        return np.column_stack(cols)

    @classmethod
    def from_array(cls, a):
        w = 20 if (a.ndim == 2 and a.shape[1] == 20) else 19
        a = a.reshape(-1, w)
        c = [a[:, i].copy() for i in range(19)]
        system = None
        if w == 20:
            k = a[:, 19].astype(np.int64)
            if np.any((k < 0) | (k >= len(SYSTEM_LETTERS))):
                raise ValueError(f"gnss_raw: system index outside 0..{len(SYSTEM_LETTERS) - 1}")
            system = np.asarray(SYSTEM_LETTERS)[k]
        return cls(c[0], c[1].astype(np.int64), c[2], c[3], a[:, 4:7].copy(), a[:, 7:10].copy(),
                   c[10], c[11], c[12], c[13], c[14], c[15], c[16], c[17], c[18], system)


@dataclass
class ImuErrors:
    """The IMU errors injected by the simulator (SI).

    Attributes
    ----------
    t : ndarray (K,)
        Times [s] (the IMU samples, decimated to ``imu.errors_rate_hz``).
    gyro_bias : ndarray (K, 3)
        Total gyro bias (constant + turn-on + Gauss-Markov + random walk) [rad/s].
    accel_bias : ndarray (K, 3)
        Total accelerometer bias [m/s^2].
    gyro_scale, accel_scale : ndarray (3,)
        Scale-factor errors [-].
    gyro_misalignment, accel_misalignment : ndarray (3, 3)
        Misalignment matrices (zero diagonal) [rad].
    """

    t: np.ndarray
    gyro_bias: np.ndarray
    accel_bias: np.ndarray
    gyro_scale: np.ndarray = field(default_factory=lambda: np.zeros(3))
    accel_scale: np.ndarray = field(default_factory=lambda: np.zeros(3))
    gyro_misalignment: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    accel_misalignment: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))

    COLUMNS = ("t_s", "gyro_bias_x_radps", "gyro_bias_y_radps", "gyro_bias_z_radps",
               "accel_bias_x_mps2", "accel_bias_y_mps2", "accel_bias_z_mps2", "gyro_scale_x",
               "gyro_scale_y", "gyro_scale_z", "accel_scale_x", "accel_scale_y", "accel_scale_z")

    def to_array(self):
        n = len(self.t)
        return np.column_stack([self.t, self.gyro_bias, self.accel_bias,
                                np.broadcast_to(self.gyro_scale, (n, 3)),
                                np.broadcast_to(self.accel_scale, (n, 3))])


@dataclass
class Odometer:
    """Wheel odometer: forward speed of the rear-axle centre, vehicle axes.

    Attributes
    ----------
    t : ndarray (K,)
        End of each counting interval [s].
    speed_mps : ndarray (K,)
        Ticks counted over ``(t[k-1], t[k]]`` divided by ticks per metre and
        the interval (includes the odometer's scale-factor error and its
        quantisation) [m/s].
    scale_error : float or None
        The simulator's true scale-factor error ``k`` [-] (reading = (1 + k)
        true speed); None for recorded or loaded data (not saved).
    """

    t: np.ndarray
    speed_mps: np.ndarray
    scale_error: float | None = None

    COLUMNS = ("t_s", "speed_mps")

    def __len__(self):
        return len(self.t)

    def to_array(self):
        return np.column_stack([self.t, self.speed_mps])

    @classmethod
    def from_array(cls, a):
        a = np.asarray(a, float).reshape(-1, 2)
        return cls(a[:, 0].copy(), a[:, 1].copy())


@dataclass
class Dataset:
    """Everything one simulation (or a converted real run) produced.

    Attributes
    ----------
    imu : ImuData
    gnss : GnssFixes
        Loosely coupled fixes (possibly empty).
    truth : Truth or None
    gnss_raw : GnssRaw or None
        Raw observations (tight presets only).
    imu_errors : ImuErrors or None
    scenario : dict
        The resolved scenario TOML as a dictionary.
    lever_arm_b : ndarray (3,)
        Antenna position relative to the IMU centre, body FRD [m].
    initial : NavState
        True state of the IMU centre at ``t0``.
    t0 : float
        Start time [s]; the first IMU interval is ``(t0, t0 + dt]``.
    gps_time_offset_s : float
        GPS time of ``t = 0`` [s since 1980-01-06]: ``t_gps = t + offset``.
    imu_model : dict
        IMU noise/bias model in SI, keys documented in
        :func:`insnav.sim.imu.imu_model_dict`.
    name : str
    seed : int or None
    odometer : Odometer or None
        Wheel odometer (car presets with ``[odometer]``).
    initial_is_truth : bool
        ``initial`` is the simulator's exact truth (``insnav.simulate``): a run
        with ``init_error = "auto"`` (the default) then starts from a random
        draw around it, as a real alignment would; a state given by the user
        (hand-written ``dataset.json``, KF-GINS, RINEX, CSV) is taken as given.
    rtk : insnav.sim.gnss_rtk.RtkSimulation or None
        Simulated rover/base carrier phase (scenarios with ``[gnss_rtk]``);
        :meth:`save` writes it as RINEX 3 (``rover.obs``, ``base.obs``,
        ``nav.rnx``) with ``rtk_truth.csv``; :meth:`load` does not read it back.
    """

    imu: ImuData
    gnss: GnssFixes
    truth: Truth | None
    gnss_raw: GnssRaw | None
    imu_errors: ImuErrors | None
    scenario: dict
    lever_arm_b: np.ndarray
    initial: NavState
    t0: float
    gps_time_offset_s: float
    imu_model: dict
    name: str = ""
    seed: int | None = None
    odometer: Odometer | None = None
    initial_is_truth: bool = False
    rtk: object | None = None

    def save(self, directory, overwrite: bool = False, *, write_tables=None) -> Path:
        """Write the dataset directory atomically (see module docstring).

        Parameters
        ----------
        directory : str or Path
        overwrite : bool
            Replace an existing directory; otherwise raise ``FileExistsError``.
        write_tables : callable, optional
            ``write_tables(folder)`` writes ``imu.csv``, ``truth.csv``,
            ``imu_errors.csv`` and ``gnss.csv`` into the new folder itself
            (block by block, :func:`insnav.sim.simulate_to`); this dataset's
            ``imu``, ``truth``, ``imu_errors`` and ``gnss`` rows are then not
            written (the constants of ``imu_errors`` still go to
            ``dataset.json``).

        Returns
        -------
        Path
        """
        from .._toml import dumps_toml

        import json

        from .._atomic import chmod_like_new, json_safe

        out = Path(directory)
        check_replaceable(out, overwrite)
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
        chmod_like_new(tmp, directory=True)
        try:
            if write_tables is not None:
                write_tables(tmp)
            else:
                write_csv(tmp / "imu.csv", ImuData.COLUMNS, self.imu.to_array(), "%.17g")
            if write_tables is None:
                write_csv(tmp / "gnss.csv", GnssFixes.COLUMNS, self.gnss.to_array(), "%.17g")
            if self.truth is not None and write_tables is None:
                write_csv(tmp / "truth.csv", Truth.COLUMNS, self.truth.to_array(), "%.17g")
            if self.gnss_raw is not None:
                write_csv(tmp / "gnss_raw.csv", GnssRaw.COLUMNS_MULTI if self.gnss_raw.is_multi() else GnssRaw.COLUMNS,
                          self.gnss_raw.to_array(), "%.17g")
            if self.imu_errors is not None and write_tables is None:
                write_csv(tmp / "imu_errors.csv", ImuErrors.COLUMNS, self.imu_errors.to_array(),
                          "%.17g")
            if self.odometer is not None:
                write_csv(tmp / "odometer.csv", Odometer.COLUMNS, self.odometer.to_array(), "%.17g")
            if self.rtk is not None:
                self.rtk.write(tmp)
            (tmp / "scenario.toml").write_text(dumps_toml(self.scenario), encoding="utf-8")
            meta = {
                "format": "insnav-dataset", "version": FORMAT_VERSION, "name": self.name,
                "seed": self.seed, "t0_s": float(self.t0),
                "gps_time_offset_s": float(self.gps_time_offset_s),
                "lever_arm_b_m": np.asarray(self.lever_arm_b, float).tolist(),
                "initial": {"lat_deg": self.initial.lat_deg, "lon_deg": self.initial.lon_deg,
                            "h_m": self.initial.h_m, "v_n_mps": self.initial.v_n.tolist(),
                            "roll_deg": self.initial.roll_deg, "pitch_deg": self.initial.pitch_deg,
                            "yaw_deg": self.initial.yaw_deg},
                "imu_model": self.imu_model,
                "initial_is_truth": bool(self.initial_is_truth),
            }
            if self.imu_errors is not None:
                meta["imu_errors_const"] = {
                    "gyro_scale": self.imu_errors.gyro_scale.tolist(),
                    "accel_scale": self.imu_errors.accel_scale.tolist(),
                    "gyro_misalignment_rad": self.imu_errors.gyro_misalignment.tolist(),
                    "accel_misalignment_rad": self.imu_errors.accel_misalignment.tolist()}
            # JSON has no Infinity: an infinite correlation time (no Gauss-Markov part) is null
            (tmp / "dataset.json").write_text(json.dumps(json_safe(meta), indent=1, allow_nan=False) + "\n",
                                              encoding="utf-8")
            from .._atomic import interrupts_deferred

            with interrupts_deferred():  # a Ctrl-C between the renames would leave no dataset at `out`
                old = None
                if out.exists():
                    old = out.parent / f".{out.name}.old-{os.getpid()}"
                    os.rename(out, old)
                os.rename(tmp, out)
                if old is not None:  # a symlink to a dataset (--out link): the link goes, its target stays
                    old.unlink() if old.is_symlink() else shutil.rmtree(old, ignore_errors=True)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        return out


#: the files Dataset.save writes (an --overwrite may replace a folder holding only these)
DATASET_FILES = frozenset({"imu.csv", "gnss.csv", "truth.csv", "gnss_raw.csv", "imu_errors.csv", "odometer.csv",
                           "scenario.toml", "dataset.json", "rover.obs", "base.obs", "nav.rnx", "rtk_truth.csv"})


def check_replaceable(out: Path, overwrite: bool) -> None:
    """Refuse to replace ``out`` unless it is an insnav dataset folder holding
    nothing but the files :meth:`Dataset.save` writes (never a user's folder)."""
    import json

    out = Path(out)
    if not out.exists():
        return
    if not overwrite:
        raise FileExistsError(f"{out} exists (use overwrite=True / --overwrite to replace an insnav dataset)")
    if not out.is_dir():
        raise FileExistsError(f"{out} exists and is not a folder: not replaced")
    meta = out / "dataset.json"
    try:
        is_dataset = json.loads(meta.read_text(encoding="utf-8")).get("format") == "insnav-dataset"
    except (OSError, ValueError, AttributeError):
        is_dataset = False
    if not is_dataset:
        raise FileExistsError(f"{out} is not an insnav dataset (no dataset.json of format insnav-dataset): "
                              "not replaced; choose another --out")
    foreign = sorted(p.name for p in out.iterdir() if p.name not in DATASET_FILES or not p.is_file())
    if foreign:
        raise FileExistsError(f"{out} holds {len(foreign)} file(s) insnav did not write ({', '.join(foreign[:3])}"
                              f"{', ...' if len(foreign) > 3 else ''}): not replaced; move them or choose another --out")
    if not out.is_symlink():
        here, there = Path.cwd().resolve(), out.resolve()
        if there == here or there in here.parents:
            raise FileExistsError(f"{out} is the current folder{'' if there == here else ' or holds it'}: not "
                                  "replaced from inside; run from outside it or choose another --out")


_INITIAL_KEYS = ("lat_deg", "lon_deg", "h_m", "v_n_mps", "roll_deg", "pitch_deg", "yaw_deg")
#: every key of dataset.json (docs/formats.md)
_META_KEYS = ("format", "version", "name", "seed", "t0_s", "gps_time_offset_s", "lever_arm_b_m", "initial",
              "imu_model", "imu_grade", "imu_errors_const", "initial_is_truth")


def _check_meta_keys(meta: dict, meta_path: Path) -> None:
    """A key dataset.json does not define is a one-line error with the closest known key."""
    for where, keys, known in (("", meta, _META_KEYS),
                               ("initial.", meta.get("initial") if isinstance(meta.get("initial"), dict) else {},
                                _INITIAL_KEYS)):
        for k in keys:
            if k not in known:
                close = close_matches(str(k), known)
                hint = f"; did you mean '{close[0]}'?" if close else f"; known keys: {', '.join(known)}"
                raise ValueError(f"{meta_path}: unknown key '{where}{k}'{hint}")


def _finite_number(meta: dict, key: str, default: float, meta_path: Path) -> float:
    """``meta[key]`` as a finite float (``default`` when absent); else a ValueError naming the key."""
    v = meta.get(key, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
        raise ValueError(f"{meta_path}: key '{key}': expected a finite number, got {v!r}")
    return float(v)


def _imu_model_from_meta(meta: dict, meta_path: Path) -> dict:
    """``imu_model`` of a dataset.json, its numbers checked: the correlation times (``*_tau``) > 0
    (null: infinite, no Gauss-Markov part), the noise densities and sigmas (``*_arw``, ``*_vrw``,
    ``*_sigma``, ``*_rw``) and ``rate_hz`` >= 0, the constant biases and scale factors finite of
    either sign; else a ValueError naming the key (a negative ``gyro_arw`` ran with exit status 0)."""
    model = meta.get("imu_model", {})
    if not isinstance(model, dict):
        raise ValueError(f"{meta_path}: key 'imu_model': expected an object of IMU noise values")
    out = {}
    for k, v in model.items():
        tau = k.endswith("_tau")
        vals = v if isinstance(v, list) else [v]
        vals = [np.inf if (x is None and tau) else x for x in vals]
        if not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in vals):
            out[k] = v  # not a numeric entry: kept as written
            continue
        if tau:
            ok, allowed = all(x > 0 for x in vals), "numbers > 0 or null (infinite)"
        elif k == "rate_hz" or k.endswith(("_arw", "_vrw", "_sigma", "_rw")):
            ok, allowed = all(0 <= x < np.inf for x in vals), "finite numbers >= 0"
        else:
            ok, allowed = all(np.isfinite(x) for x in vals), "finite numbers"
        if not ok:
            raise ValueError(f"{meta_path}: key 'imu_model.{k}': bad value {v!r}; allowed: {allowed}")
        out[k] = vals if isinstance(v, list) else vals[0]
    return out


def _initial_from_meta(meta: dict, meta_path: Path):
    """The initial state, its time t0 [s] and the lever arm [m] of a
    dataset.json, each checked: a missing key or a bad value is a ValueError
    naming the file and the key."""
    ini = meta.get("initial")
    if not isinstance(ini, dict):
        raise ValueError(f"{meta_path}: 'initial' missing or not an object with {', '.join(_INITIAL_KEYS)}")
    missing = [k for k in _INITIAL_KEYS if k not in ini]
    if missing:
        raise ValueError(f"{meta_path}: initial: {', '.join(missing)} missing")
    v = ini["v_n_mps"]
    if not (isinstance(v, list) and len(v) == 3):
        raise ValueError(f"{meta_path}: initial: v_n_mps must be 3 numbers (north, east, down [m/s]), got {v!r}")
    try:
        initial = NavState(*(ini[k] for k in _INITIAL_KEYS))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{meta_path}: initial: {exc}") from None
    if "t0_s" not in meta:
        raise ValueError(f"{meta_path}: t0_s (time of the initial state [s]) missing")
    try:
        t0 = float(meta["t0_s"])
    except (TypeError, ValueError):
        raise ValueError(f"{meta_path}: t0_s must be a number [s], got {meta['t0_s']!r}") from None
    lever = meta.get("lever_arm_b_m", [0.0, 0.0, 0.0])
    try:
        lever_arm_b = np.asarray(lever, dtype=float).reshape(3)
    except (TypeError, ValueError):
        raise ValueError(f"{meta_path}: lever_arm_b_m must be 3 numbers (forward, right, down [m]), "
                         f"got {lever!r}") from None
    return initial, t0, lever_arm_b


def load_dataset(directory) -> Dataset:
    """Read a dataset directory written by :meth:`Dataset.save`.

    Raises
    ------
    FileNotFoundError
        When the directory or a required file is missing.
    ValueError
        Naming the file, the 1-based line and the reason for a malformed file.
    """
    import json  # here: a run from other files never reads JSON
    import tomllib

    d = Path(directory)
    if not d.is_dir():
        raise FileNotFoundError(f"dataset directory {d} does not exist")
    meta_path = d / "dataset.json"
    if not meta_path.is_file():
        raise FileNotFoundError(f"{meta_path} missing: not an insnav dataset directory")
    from .textio import read_text

    try:
        meta = json.loads(read_text(meta_path, errors="strict"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{meta_path}:{exc.lineno}: invalid JSON: {exc.msg}") from None
    a, imu_origin = read_csv(d / "imu.csv", ImuData.COLUMNS, return_origin=True)
    check_finite_rows(a, imu_origin, ImuData.COLUMNS)
    imu = ImuData.from_array(a)
    imu.origin = imu_origin
    a, gnss_origin = read_csv(d / "gnss.csv", GnssFixes.COLUMNS, return_origin=True)
    check_finite_rows(a[:, :1], gnss_origin, GnssFixes.COLUMNS[:1])
    gnss = GnssFixes.from_array(a)
    gnss.origin = gnss_origin
    truth = (Truth.from_array(read_csv(d / "truth.csv", Truth.COLUMNS))
             if (d / "truth.csv").is_file() else None)
    raw = (GnssRaw.from_array(read_csv(d / "gnss_raw.csv", GnssRaw.COLUMNS_MULTI if _csv_header(
        d / "gnss_raw.csv").endswith(",system") else GnssRaw.COLUMNS)) if (d / "gnss_raw.csv").is_file() else None)
    errs = None
    if (d / "imu_errors.csv").is_file():
        a = read_csv(d / "imu_errors.csv", ImuErrors.COLUMNS).reshape(-1, 13)
        c = meta.get("imu_errors_const", {})
        errs = ImuErrors(a[:, 0].copy(), a[:, 1:4].copy(), a[:, 4:7].copy(),
                         np.array(c.get("gyro_scale", a[0, 7:10] if len(a) else np.zeros(3))),
                         np.array(c.get("accel_scale", a[0, 10:13] if len(a) else np.zeros(3))),
                         np.array(c.get("gyro_misalignment_rad", np.zeros((3, 3)))),
                         np.array(c.get("accel_misalignment_rad", np.zeros((3, 3)))))
    odo = (Odometer.from_array(read_csv(d / "odometer.csv", Odometer.COLUMNS))
           if (d / "odometer.csv").is_file() else None)
    scen = {}
    if (d / "scenario.toml").is_file():
        scen = tomllib.loads(read_text(d / "scenario.toml", errors="strict"))
    imu_model = _imu_model_from_meta(meta, meta_path)
    if "imu_grade" in meta:
        if imu_model:
            raise ValueError(f"{d / 'dataset.json'}: give 'imu_model' or 'imu_grade', not both")
        from .imu_grades import imu_model_for_grade

        try:
            imu_model = imu_model_for_grade(meta["imu_grade"])
        except ValueError as exc:
            raise ValueError(f"{d / 'dataset.json'}: {exc}") from None
    _check_meta_keys(meta, meta_path)
    initial, t0, lever_arm_b = _initial_from_meta(meta, meta_path)
    iit = meta.get("initial_is_truth", False)
    if not isinstance(iit, bool):
        raise ValueError(f"{meta_path}: initial_is_truth must be true or false, got {iit!r}")
    return Dataset(imu=imu, gnss=gnss, truth=truth, gnss_raw=raw, imu_errors=errs, scenario=scen,
                   lever_arm_b=lever_arm_b, initial=initial, t0=t0,
                   gps_time_offset_s=_finite_number(meta, "gps_time_offset_s", 0.0, meta_path),
                   imu_model=imu_model, name=meta.get("name", ""),
                   seed=meta.get("seed"), odometer=odo, initial_is_truth=iit)


# --- fast CSV --------------------------------------------------------------
def write_csv(path, columns, data, fmt="%.17g", chunk=100_000, append: bool = False) -> None:
    """Write a numeric array with a one-line header of column names.

    ``fmt="%.17g"`` (exact doubles): the shortest text that reads back to the
    same double (``nan``, ``inf``, ``-0`` kept), formatted by the compiled
    writer (``_core.write_table``, GIL released, about 10x the Python
    formatter).  Any other ``fmt``: Python's %-formatting, ``chunk`` rows at a
    time.  ``append``: the rows go after the file's end, without the header
    (a table written block by block).
    """
    data = np.asarray(data, dtype=float).reshape(-1, len(columns))
    header = "" if append else ",".join(columns) + "\n"
    if fmt == "%.17g":
        from .. import _core
        from .textio import threads

        _core.write_table(str(path), header, [data[:, j] for j in range(data.shape[1])],
                          [1.0] * data.shape[1], [-1] * data.shape[1], threads=threads(), append=append)
        return
    row = ",".join([fmt] * len(columns)) + "\n"
    with open(path, "a" if append else "w", encoding="ascii", newline="\n") as f:
        f.write(header)
        for s in range(0, data.shape[0], chunk):
            blk = data[s:s + chunk]
            f.write((row * blk.shape[0]) % tuple(blk.ravel().tolist()))


def parse_numeric_text(text, ncols: int, source: str, first_line: int = 1,
                       sep: str | None = None, min_cols: int | None = None, names=None) -> np.ndarray:
    """Parse whitespace/comma-separated numeric text into an (N, ncols) array.

    The C++ reader (:func:`insnav.data.textio.parse_numeric`) reports the
    first bad line as ``ValueError("<source>:<line>: <reason>")`` (1-based),
    counting lines as it parses.  Blank lines are ignored.  ``sep=" "``:
    whitespace only (KF-GINS files); otherwise commas separate too.  With
    ``min_cols`` rows may have more columns than ``ncols`` (only the first
    ``ncols`` are kept).
    """
    return parse_numeric_origin(text, ncols, source, first_line, sep, min_cols, names)[0]


def parse_numeric_origin(text, ncols: int, source: str, first_line: int = 1, sep: str | None = None,
                         min_cols: int | None = None, names=None, keep: int | None = None):
    """:func:`parse_numeric_text` and the :class:`RowOrigin` of its rows."""
    from .textio import parse_numeric

    a, lines = parse_numeric(text, ncols, source, first_line=first_line, comma=sep in (None, ","), keep=keep,
                             allow_extra=min_cols is not None, names=names)
    return a, RowOrigin(source, first_line, lines)


def check_finite_rows(a, origin: RowOrigin, columns) -> None:
    """Raise ``ValueError("<file>:<line>: non-finite value ...")`` for the first NaN/inf in ``a``
    (an (N, k) array, or a tuple of (N,) / (N, k) arrays holding its columns side by side)."""
    parts = a if isinstance(a, tuple) else (a,)
    first, c0 = None, 0
    for part in parts:
        if np.isfinite(part).all():  # the usual case: no per-element mask to search
            c0 += part.shape[1] if part.ndim > 1 else 1  # (an empty file: no rows to reshape)
            continue
        part2 = part.reshape(len(part), -1)
        bad = ~np.isfinite(part2)
        if bad.any():
            r, c = np.argwhere(bad)[0]
            if first is None or r < first[0]:
                first = (int(r), c0 + int(c), float(part2[r, c]))
        c0 += part2.shape[1]
    if first is not None:
        r, c, v = first
        raise ValueError(f"{origin.where(r)}: non-finite value {v!r} in column {columns[c]!r}")


def _csv_header(path) -> str:
    """The first line of a CSV file, stripped (empty for an empty file)."""
    with open(path, "rb") as f:
        return f.readline().decode("ascii", "replace").strip().replace(" ", "")


def read_csv(path, columns, return_origin: bool = False):
    """Read a dataset CSV, checking the header names ``columns``.

    With ``return_origin`` also return the :class:`RowOrigin` (file line of each row)."""
    from .textio import read_bytes

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path} missing")
    data = read_bytes(path)
    nl = data.find(b"\n")
    header = (data if nl < 0 else data[:nl]).decode("ascii", "replace").strip()
    got = tuple(h.strip() for h in header.split(","))
    if got != tuple(columns):
        raise ValueError(f"{path}:1: unexpected header {header!r}; expected {','.join(columns)}")
    body = b"" if nl < 0 else memoryview(data)[nl + 1:]
    a, origin = parse_numeric_origin(body, len(columns), str(path), first_line=2, names=columns)
    return (a, origin) if return_origin else a
