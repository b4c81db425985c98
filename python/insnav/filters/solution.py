"""What a run returns: :class:`Solution` (per output row: navigation state,
sigmas, IMU error estimates; per GNSS record: innovation, NIS, status) and
the record status codes, the same as ``RecordStatus`` in
``cpp/include/insnav/engine/closed_loop.hpp``."""
from __future__ import annotations

import enum
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..data.nav import NAV_COLUMNS, NavTrajectory

__all__ = ["RecordStatus", "GNSS_STATUS", "Solution", "load_solution", "save_solution", "write_innovations",
           "read_innovations", "innovations_path", "INNOVATION_COLUMNS", "RESIDUAL_COLUMNS", "read_residuals",
           "residuals_path", "status_name"]


class RecordStatus(enum.IntEnum):
    """What became of one GNSS record (``Solution.gnss_status``)."""

    NOT_USED = 0              #: nothing to use (masked out, or no satellite: prediction only)
    APPLIED = 1               #: the update was applied and fed back
    REJECTED_BY_GATE = 2      #: NIS above the gate
    NOT_POSITIVE_DEFINITE = 3  #: innovation covariance not positive definite
    OUTSIDE_IMU_SPAN = 4      #: valid before the first or after the last IMU sample
    TOO_OLD = 5               #: exact delay filter: older than the history it keeps
    QUEUE_FULL = 6            #: push API: no room in the pending-record queue


#: GNSS record status codes of :attr:`Solution.gnss_status`
GNSS_STATUS = {RecordStatus.NOT_USED: "not used", RecordStatus.APPLIED: "applied",
               RecordStatus.REJECTED_BY_GATE: "rejected by gate", RecordStatus.NOT_POSITIVE_DEFINITE: "S not positive definite",
               RecordStatus.OUTSIDE_IMU_SPAN: "outside the IMU time span",
               RecordStatus.TOO_OLD: "refused: older than the history",
               RecordStatus.QUEUE_FULL: "refused: the pending queue is full"}


@dataclass
class Solution(NavTrajectory):
    """A navigation solution with its uncertainty and filter diagnostics (the
    :class:`~insnav.data.nav.NavTrajectory` fields, then the rest).

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
    sigma_imu_err : (N, 12) or None
        1-sigma of accelerometer bias [m/s^2], gyro bias [rad/s], accelerometer
        and gyro scale factor [-] (the order of the IMU-error columns; 0 for the
        scale factors of a 15-state layout, which does not estimate them); only
        when the run asked for it (``imu_error_sigmas``), else None
    odo_scale, sigma_odo_scale : (N,) or None
        Estimated odometer scale-factor error [-] (reading = (1 + s) true
        forward speed) and its 1-sigma [-]: runs with the scale-factor state
        (``[constraints] odo_scale``), else None
    time_offset_s, sigma_time_offset_s : (N,) or None
        Estimated IMU-GNSS time offset t_d [s] (a GNSS record tagged t holds
        the antenna at IMU time t - t_d) and its 1-sigma: runs with ``[time]
        estimate_offset``, else None
    lever_arm_b_m, sigma_lever_arm_b_m : (N, 3) or None
        Estimated GNSS lever arm (IMU -> antenna, FRD) [m] and its 1-sigma:
        runs with ``[lever_arm] estimate``, else None
    odo_lever_arm_b_m, sigma_odo_lever_arm_b_m : (N, 3) or None
        Estimated lever arm of the vehicle constraints' point (IMU -> rear-axle
        centre, FRD) [m] and its 1-sigma: runs with ``[lever_arm]
        estimate_odometer`` (not written to the solution file), else None
    gnss_t : (M,) s, time of validity of each GNSS record
    innovation : (M, 6) INS minus GNSS (N, E, D position [m], velocity [m/s]) before the update
    nis : (M,) normalised innovation squared
    gnss_status : (M,) int8, see :data:`GNSS_STATUS`
    log_det_s : (M,) or None
        log det S of each record's innovation covariance (NaN where no S was
        formed): with ``nis`` the innovation log-likelihood
        ``-(nis + log_det_s + rows log 2 pi) / 2`` (:mod:`insnav.calib.tune`);
        EKF and RB-UKF runs (NaN from the other filters)
    constraint_log_det_s : (K,) or None
        The same per vehicle-constraint event (runs with ``[constraints]``)
    gnss_sigma : (M, 6) or None
        Loose runs: the 1-sigma of each GNSS record's rows as its update used
        them (N, E, D position [m], velocity [m/s]; sqrt of R's diagonal, after
        the adaptive scaling of ``adaptive_r_window``; NaN where the record has
        no such row or was not used)
    summary : dict
        filter, coupling, counts of updates / rejections / covariance repairs.
    """

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
    sigma_imu_err: np.ndarray | None = None
    odo_scale: np.ndarray | None = None
    sigma_odo_scale: np.ndarray | None = None
    log_det_s: np.ndarray | None = None
    constraint_log_det_s: np.ndarray | None = None
    gnss_sigma: np.ndarray | None = None
    time_offset_s: np.ndarray | None = None
    sigma_time_offset_s: np.ndarray | None = None
    lever_arm_b_m: np.ndarray | None = None
    sigma_lever_arm_b_m: np.ndarray | None = None
    odo_lever_arm_b_m: np.ndarray | None = None
    sigma_odo_lever_arm_b_m: np.ndarray | None = None

    COLUMNS = NAV_COLUMNS + (
               "sigma_n_m", "sigma_e_m", "sigma_d_m", "sigma_vn_mps", "sigma_ve_mps", "sigma_vd_mps",
               "sigma_roll_deg", "sigma_pitch_deg", "sigma_yaw_deg",
               "acc_bias_x_mps2", "acc_bias_y_mps2", "acc_bias_z_mps2",
               "gyro_bias_x_dph", "gyro_bias_y_dph", "gyro_bias_z_dph",
               "acc_scale_x_ppm", "acc_scale_y_ppm", "acc_scale_z_ppm",
               "gyro_scale_x_ppm", "gyro_scale_y_ppm", "gyro_scale_z_ppm")

    #: the odometer scale factor and its 1-sigma [ppm] (runs that estimate it: ``[constraints] odo_scale``),
    #: after :attr:`COLUMNS` in the ``bias`` group
    ODO_SCALE_COLUMNS = ("odo_scale_ppm", "sigma_odo_scale_ppm")
    #: the IMU-GNSS time offset and its 1-sigma [ms] (runs with ``[time] estimate_offset``), then
    TIME_OFFSET_COLUMNS = ("time_offset_ms", "sigma_time_offset_ms")
    #: the GNSS lever arm and its 1-sigma [m] (runs with ``[lever_arm] estimate``), in the ``bias`` group
    LEVER_ARM_COLUMNS = ("lever_x_m", "lever_y_m", "lever_z_m", "sigma_lever_x_m", "sigma_lever_y_m",
                         "sigma_lever_z_m")

    #: --columns groups: the navigation state (t_s always), its 1-sigma, the IMU (and odometer) error estimates
    COLUMN_GROUPS = {"nav": COLUMNS[:10], "sigma": COLUMNS[10:19],
                     "bias": COLUMNS[19:31] + ODO_SCALE_COLUMNS + TIME_OFFSET_COLUMNS + LEVER_ARM_COLUMNS}

    def columns(self) -> list[tuple[str, np.ndarray, float]]:
        """(name, SI or degree array, factor to the column's unit) of every
        :attr:`COLUMNS` entry, then :attr:`ODO_SCALE_COLUMNS` when the run
        estimated the odometer scale factor; the arrays are views, nothing is
        copied."""
        from ..units import RAD2DEG

        out = [("t_s", self.t, 1.0), ("lat_deg", self.lat_deg, 1.0), ("lon_deg", self.lon_deg, 1.0),
               ("h_m", self.h_m, 1.0)]
        tables = ((self.v_n, 1.0), (None, None), (self.sigma_pos_n_m, 1.0), (self.sigma_vel_n_mps, 1.0),
                  (self.sigma_att_deg, 1.0), (self.acc_bias_mps2, 1.0), (self.gyro_bias_rps, RAD2DEG * 3600.0),
                  (self.acc_scale, 1e6), (self.gyro_scale, 1e6))
        names = iter(self.COLUMNS[4:])
        for a, f in tables:
            if a is None:
                out += [(next(names), x, 1.0) for x in (self.roll_deg, self.pitch_deg, self.yaw_deg)]
                continue
            a = np.asarray(a, float)
            out += [(next(names), a[:, j], f) for j in range(3)]
        if self.odo_scale is not None:
            out += [(n, np.asarray(x, float), 1e6) for n, x in zip(self.ODO_SCALE_COLUMNS,
                                                                    (self.odo_scale, self.sigma_odo_scale))]
        if self.time_offset_s is not None:
            out += [(n, np.asarray(x, float), 1e3) for n, x in zip(self.TIME_OFFSET_COLUMNS,
                                                                    (self.time_offset_s, self.sigma_time_offset_s))]
        if self.lever_arm_b_m is not None:
            la, sl = np.asarray(self.lever_arm_b_m, float), np.asarray(self.sigma_lever_arm_b_m, float)
            out += [(n, x[:, j], 1.0) for n, (x, j) in zip(self.LEVER_ARM_COLUMNS,
                                                          [(la, 0), (la, 1), (la, 2), (sl, 0), (sl, 1), (sl, 2)])]
        return out

    def to_array(self) -> np.ndarray:
        """(N, 31) array in :attr:`COLUMNS` order (user units as named; (N, 33) with the odometer scale)."""
        cols = self.columns()
        a = np.empty((len(self.t), len(cols)))
        for j, (_, x, f) in enumerate(cols):
            np.multiply(x, f, out=a[:, j])
        return a

    def to_dataframe(self):
        """A pandas DataFrame with the :attr:`COLUMNS` (pandas is optional: ``pip install insnav[pandas]``)."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError("Solution.to_dataframe needs pandas: pip install 'insnav[pandas]'") from None
        return pd.DataFrame(self.to_array(), columns=[n for n, _, _ in self.columns()])

    def save(self, path, *, columns=None, precision: str = "resolution") -> Path:
        """Write the solution atomically (a temp file renamed into place); the
        suffix chooses the format: ``.csv`` (text, :attr:`COLUMNS`), ``.npz``
        (numpy, one array per column, exact) or ``.parquet`` (pyarrow, exact).
        :func:`load_solution` reads all three.

        Parameters
        ----------
        columns : iterable of str, optional
            Column groups of :attr:`COLUMN_GROUPS` (``nav``, ``sigma``, ``bias``); default all.
        precision : {'resolution', 'exact'}
            CSV only: each value rounded to its column's resolution
            (:data:`CSV_DECIMALS`: 1 ns, 1e-11 deg, 1 um, ...; the shortest text
            of the rounded value), or the shortest text that reads back as the
            very same double (``std::to_chars`` round trip; about twice the size).
        """
        return save_solution(self, path, columns=columns, precision=precision)

    def save_csv(self, path, **kw) -> Path:
        """Write the solution CSV atomically (see :meth:`save`)."""
        return _save_csv(self, Path(path), **kw)


#: old (unit-less) column names still accepted on reading
LEGACY_COLUMNS = {"t": "t_s", "vn": "vn_mps", "ve": "ve_mps", "vd": "vd_mps"}
#: decimals of each CSV column (precision='resolution'): time 1 ns, lat/lon 1e-11 deg (~1 um),
#: h, velocities and their sigmas 1 um(/s), angles and their sigmas 1e-8 deg, acc bias 1e-9 m/s^2,
#: gyro bias 1e-6 deg/h, scale factors 1e-4 ppm
CSV_DECIMALS = dict(zip(Solution.COLUMNS, [9, 11, 11] + [6] * 4 + [8] * 3 + [6] * 6 + [8] * 3 + [9] * 3 + [6] * 3
                        + [4] * 6))
CSV_DECIMALS.update(odo_scale_ppm=4, sigma_odo_scale_ppm=4, time_offset_ms=6, sigma_time_offset_ms=6)
CSV_DECIMALS.update({n: 6 for n in Solution.LEVER_ARM_COLUMNS})
FORMATS = (".csv", ".npz", ".parquet")
#: rows per Parquet row group (about 20 MB of float64 with every column): the whole-file writer and the
#: block-by-block one (``insnav.filters.stream``, which buffers one row group) cut the same groups, so their
#: files are the same byte for byte
PARQUET_ROW_GROUP_ROWS = 1 << 16
#: bytes of a Parquet column chunk's dictionary before the writer gives it up for plain values: the float
#: columns go plain at once (a full dictionary of 2^16 distinct doubles is larger than the values), the
#: constant ones (a 15-state run's scale factors) stay dictionary-encoded; the files are smaller than with
#: pyarrow's defaults (1 MiB, row groups of 2^20 rows) at 200 Hz and at 10 Hz
PARQUET_DICTIONARY_PAGE_BYTES = 1 << 14
PRECISIONS = ("resolution", "exact")


def _selected(sol: Solution, columns) -> list[tuple[str, np.ndarray, float]]:
    cols = sol.columns()
    if columns is None:
        return cols
    groups = [columns] if isinstance(columns, str) else list(columns)
    bad = [g for g in groups if g not in Solution.COLUMN_GROUPS]
    if bad or not groups:
        raise ValueError(f"unknown column group {', '.join(map(repr, bad)) or '(none)'}; "
                         f"use any of {','.join(Solution.COLUMN_GROUPS)}")
    keep = {"t_s"}.union(*(Solution.COLUMN_GROUPS[g] for g in groups))
    return [c for c in cols if c[0] in keep]


def _save_csv(sol: Solution, path: Path, columns=None, precision: str = "resolution") -> Path:
    if precision not in PRECISIONS:
        raise ValueError(f"precision {precision!r}: use one of {', '.join(PRECISIONS)}")
    cols = _selected(sol, columns)
    dec = [CSV_DECIMALS[n] if precision == "resolution" else -1 for n, _, _ in cols]
    from ..data.textio import write_text_columns

    return write_text_columns(path, ",".join(n for n, _, _ in cols) + "\n", cols, dec)


def _atomic_binary(path: Path, write) -> Path:
    """Write through ``write(tmp_path)`` to a temp file beside ``path``, then rename."""
    from .._atomic import atomic_write_with

    return atomic_write_with(path, write)


def _parquet():
    try:
        import pyarrow
        import pyarrow.parquet
    except ImportError:
        raise ImportError("Parquet needs pyarrow: pip install 'insnav[parquet]' (or write .csv / .npz)") from None
    return pyarrow


def save_solution(sol: Solution, path, *, columns=None, precision: str = "resolution") -> Path:
    """:meth:`Solution.save`."""
    path = Path(path)
    fmt = path.suffix.lower()
    if fmt == ".csv":
        return _save_csv(sol, path, columns, precision)
    if fmt not in FORMATS:
        raise ValueError(f"{path}: unknown solution format {path.suffix!r}; use one of {', '.join(FORMATS)}")

    if fmt == ".npz":
        from .._npz import write_npz

        cols = _selected(sol, columns)  # views: each column is gathered (and scaled) as it is written
        return _atomic_binary(path, lambda tmp: write_npz(tmp, cols))

    pa = _parquet()

    def write(tmp):
        cols = [(name, np.ascontiguousarray(x, float) if f == 1.0 else np.multiply(x, f))
                for name, x, f in _selected(sol, columns)]
        pa.parquet.write_table(parquet_table(pa, [n for n, _ in cols], [x for _, x in cols]), tmp,
                               row_group_size=PARQUET_ROW_GROUP_ROWS,
                               dictionary_pagesize_limit=PARQUET_DICTIONARY_PAGE_BYTES)

    return _atomic_binary(path, write)


def parquet_table(pa, names, arrays):
    """A ``pyarrow.Table`` of float64 columns ``names`` on the memory of the 1-D
    contiguous float64 ``arrays`` (no copy; no nulls, a NaN stays a value).
    Made with ``pa.Array.from_buffers``, not ``pa.array``, whose numpy path
    imports pandas (about 50 MB of memory).  The schema: the names, float64,
    no metadata.  Shared by ``Solution.save`` and the block-by-block writer."""
    cols = [pa.Array.from_buffers(pa.float64(), len(x), [None, pa.py_buffer(x)]) for x in arrays]
    return pa.Table.from_arrays(cols, schema=pa.schema([pa.field(n, pa.float64()) for n in names]))


def is_kfgins_nav(path) -> bool:
    """True for a KF-GINS ``.nav`` result name (``.nav``, ``.nav.xz``/``.gz``/``.bz2``)."""
    name = Path(path).name.lower()
    return name.endswith(".nav") or any(name.endswith(".nav" + z) for z in (".xz", ".gz", ".bz2"))


def _kfgins_columns(path: Path) -> dict:
    """The columns of a KF-GINS ``.nav`` result (KF-GINS's own or ``insnav run
    --out-format kfgins``), with the sigmas of ``KF_GINS_STD.txt`` and the IMU
    errors of ``KF_GINS_IMU_ERR.txt`` when they lie beside it, row for row."""
    from ..io.kfgins import KFGINS_IMU_ERR_FILE, KFGINS_STD_FILE, MGAL, _read_table, read_kfgins_nav

    nav = read_kfgins_nav(path)
    cols = dict(t_s=nav.t, lat_deg=nav.lat_deg, lon_deg=nav.lon_deg, h_m=nav.h_m, vn_mps=nav.v_n[:, 0],
                ve_mps=nav.v_n[:, 1], vd_mps=nav.v_n[:, 2], roll_deg=nav.roll_deg, pitch_deg=nav.pitch_deg,
                yaw_deg=nav.yaw_deg)

    def beside(name, ncols):
        f = path.with_name(name)
        if not f.is_file():
            return None
        a = _read_table(f, ncols)
        return a if a.shape[0] == len(nav.t) and np.array_equal(a[:, 0], nav.t) else None

    std = beside(KFGINS_STD_FILE, 22)
    if std is not None:
        names = ["sigma_n_m", "sigma_e_m", "sigma_d_m", "sigma_vn_mps", "sigma_ve_mps", "sigma_vd_mps",
                 "sigma_roll_deg", "sigma_pitch_deg", "sigma_yaw_deg"]
        cols.update({n: std[:, 1 + j] for j, n in enumerate(names)})
    err = beside(KFGINS_IMU_ERR_FILE, 13)
    if err is not None:
        for j, ax in enumerate("xyz"):
            cols[f"gyro_bias_{ax}_dph"] = err[:, 1 + j]
            cols[f"acc_bias_{ax}_mps2"] = err[:, 4 + j] * MGAL
            cols[f"gyro_scale_{ax}_ppm"] = err[:, 7 + j]
            cols[f"acc_scale_{ax}_ppm"] = err[:, 10 + j]
    return cols


def _columns_from(path: Path) -> dict:
    """column name -> array of a saved solution (legacy names mapped)."""
    fmt = path.suffix.lower()
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such solution file")
    if is_kfgins_nav(path):
        cols = _kfgins_columns(path)
    elif fmt == ".npz":
        with np.load(path, allow_pickle=False) as z:
            cols = {k: np.asarray(z[k], float) for k in z.files}
    elif fmt == ".parquet":
        pa = _parquet()
        t = pa.parquet.read_table(path)
        cols = {k: t.column(k).to_numpy().astype(float) for k in t.column_names}
    else:
        from ..data.textio import parse_numeric, read_bytes

        data = read_bytes(path)
        nl = data.find(b"\n")
        header = [h.strip() for h in (data if nl < 0 else data[:nl]).decode("ascii", "replace").strip().split(",")]
        a, _ = parse_numeric(b"" if nl < 0 else memoryview(data)[nl + 1:], len(header), str(path), first_line=2,
                             names=header)
        cols = dict(zip(header, a.T))
    cols = {LEGACY_COLUMNS.get(k, k): v for k, v in cols.items()}
    need = ("t_s", "lat_deg", "lon_deg", "h_m", "vn_mps", "ve_mps", "vd_mps", "roll_deg", "pitch_deg", "yaw_deg")
    missing = [c for c in need if c not in cols]
    if missing:
        raise ValueError(f"{path}:1: not an insnav solution: columns {', '.join(missing)} missing "
                         f"(expected {','.join(Solution.COLUMNS)})")
    return cols


def load_solution(path) -> Solution:
    """Read a solution written by ``insnav run`` or :meth:`Solution.save`
    (``.csv``, ``.npz``, ``.parquet``; old unit-less CSV names accepted), or a
    KF-GINS result ``.nav`` (``week sow lat lon h vN vE vD roll pitch yaw``;
    KF-GINS's own or ``insnav run --out-format kfgins``: ``t`` = seconds of
    week; the sigmas of ``KF_GINS_STD.txt`` and the IMU errors of
    ``KF_GINS_IMU_ERR.txt`` beside it are read when they have the same epochs).

    Columns absent from the file (sigmas, biases, scale factors) come back as
    NaN.  The innovations sidecar ``<path>.innovations.csv``, when present,
    fills ``gnss_t``, ``innovation``, ``nis`` and ``gnss_status``.
    """
    path = Path(path)
    c = _columns_from(path)
    n = len(c["t_s"])

    def col(*names, scale=1.0):
        return np.column_stack([c[k] * scale if k in c else np.full(n, np.nan) for k in names]) if len(names) > 1 \
            else (c[names[0]] * scale if names[0] in c else np.full(n, np.nan))

    from ..units import DEG_PER_H

    sol = Solution(
        t=col("t_s"), lat_deg=col("lat_deg"), lon_deg=col("lon_deg"), h_m=col("h_m"),
        v_n=col("vn_mps", "ve_mps", "vd_mps"), roll_deg=col("roll_deg"), pitch_deg=col("pitch_deg"),
        yaw_deg=col("yaw_deg"), sigma_pos_n_m=col("sigma_n_m", "sigma_e_m", "sigma_d_m"),
        sigma_vel_n_mps=col("sigma_vn_mps", "sigma_ve_mps", "sigma_vd_mps"),
        sigma_att_deg=col("sigma_roll_deg", "sigma_pitch_deg", "sigma_yaw_deg"),
        acc_bias_mps2=col("acc_bias_x_mps2", "acc_bias_y_mps2", "acc_bias_z_mps2"),
        gyro_bias_rps=col("gyro_bias_x_dph", "gyro_bias_y_dph", "gyro_bias_z_dph", scale=DEG_PER_H),
        acc_scale=col("acc_scale_x_ppm", "acc_scale_y_ppm", "acc_scale_z_ppm", scale=1e-6),
        gyro_scale=col("gyro_scale_x_ppm", "gyro_scale_y_ppm", "gyro_scale_z_ppm", scale=1e-6),
        gnss_t=np.zeros(0), innovation=np.zeros((0, 6)), nis=np.zeros(0), gnss_status=np.zeros(0, np.int8),
        summary={"source": str(path)})
    if "odo_scale_ppm" in c:
        sol.odo_scale = c["odo_scale_ppm"] * 1e-6
        sol.sigma_odo_scale = col("sigma_odo_scale_ppm", scale=1e-6)
    if "time_offset_ms" in c:
        sol.time_offset_s = c["time_offset_ms"] * 1e-3
        sol.sigma_time_offset_s = col("sigma_time_offset_ms", scale=1e-3)
    if "lever_x_m" in c:
        sol.lever_arm_b_m = col("lever_x_m", "lever_y_m", "lever_z_m")
        sol.sigma_lever_arm_b_m = col("sigma_lever_x_m", "sigma_lever_y_m", "sigma_lever_z_m")
    side = innovations_path(path)
    if side.is_file():
        inn = read_innovations(side)
        sol.gnss_t, sol.nis, sol.gnss_status = inn["t_s"], inn["nis"], inn["status"].astype(np.int8)
        sol.innovation = inn["innovation"]
    return sol


# --- innovations sidecar --------------------------------------------------------

#: the sidecar's columns: per GNSS record (loose: fix; tight: epoch)
INNOVATION_COLUMNS = ("t_s", "status", "applied", "nis", "rows", "dn_m", "de_m", "dd_m", "dvn_mps", "dve_mps",
                      "dvd_mps", "status_name")
#: the columns of a tight run's per-satellite residuals ``<solution>.residuals.csv``
RESIDUAL_COLUMNS = ("t_s", "prn", "elevation_deg", "pseudorange_residual_m", "rate_residual_mps")
#: ... and of a run that has the robust step's flags: + the system index (0 G, 1 R, 2 E, 3 C,
#: insnav.gnss.systems) and the flags of the pseudorange and the rate (-1 absent, 0 used,
#: 1 down-weighted, 2 rejected)
RESIDUAL_COLUMNS_FLAGS = RESIDUAL_COLUMNS + ("system", "pseudorange_flag", "rate_flag")


def status_name(code: int) -> str:
    """The sidecar's name of a :class:`RecordStatus` code (``applied``,
    ``rejected_by_gate``, ...; ``unknown_<code>`` for a code it does not know)."""
    try:
        return RecordStatus(int(code)).name.lower()
    except ValueError:
        return f"unknown_{int(code)}"


def _status_names(codes: np.ndarray) -> list[str]:
    """:func:`status_name` of every code (looked up once per distinct code)."""
    codes = np.asarray(codes).tolist()
    names = {c: status_name(c) for c in set(codes)}
    return [names[c] for c in codes]


def innovations_path(solution_path) -> Path:
    p = Path(solution_path)
    return p.with_name(p.name + ".innovations.csv")


def residuals_path(solution_path) -> Path:
    p = Path(solution_path)
    return p.with_name(p.name + ".residuals.csv")


def _csv_text(body: np.ndarray, columns, fmt, names=None) -> str:
    """CSV text of a numeric table (NaN written as an empty cell), with an
    optional last text column."""
    row = ",".join(fmt)  # what np.savetxt formats each row with, ~3x faster without its per-row overhead
    lines = [row % tuple(r) for r in np.asarray(body, float).tolist()]
    if names is not None:
        lines = [f"{ln},{n}" for ln, n in zip(lines, names)]
    text = "\n".join([",".join(columns)] + lines) + "\n"
    # NaN -> an empty cell ("nan" is only ever a whole cell); two passes for ",nan,nan,"
    # (a replace goes on after the comma its match consumed)
    return text.replace("\nnan,", "\n,").replace(",nan,", ",,").replace(",nan,", ",,").replace(",nan\n", ",\n")


def write_innovations(sol: Solution, solution_path) -> Path:
    """Write ``<solution>.innovations.csv`` (columns :data:`INNOVATION_COLUMNS`).

    Per GNSS record: its time of validity [s], status code
    (:class:`RecordStatus`), applied (1/0), NIS (innovation squared in the
    metric of its predicted covariance), measurement rows, the loose
    innovation INS minus GNSS (N, E, D position [m], velocity [m/s]; empty for
    a tight solution) and the status name.  A tight solution's per-satellite
    residuals (the rows the core returns, in the order of ``sol.inputs``) go
    to ``<solution>.residuals.csv`` (:data:`RESIDUAL_COLUMNS`).
    """
    from .._atomic import output_set

    with output_set():  # both sidecars or neither
        return _write_innovations(sol, solution_path)


def _write_innovations(sol: Solution, solution_path) -> Path:
    from .._atomic import atomic_write_text

    m = len(sol.gnss_t)
    st = np.asarray(sol.gnss_status, int)
    inn = np.asarray(sol.innovation, float)
    loose = inn.ndim == 2 and inn.shape == (m, 6)
    rows = getattr(sol, "rows", None)
    if rows is None:
        rows = np.isfinite(inn).sum(axis=1) if loose else np.zeros(m, int)
    body = np.column_stack([sol.gnss_t, st, st == RecordStatus.APPLIED, sol.nis, rows,
                            inn if loose else np.full((m, 6), np.nan)])
    out = atomic_write_text(innovations_path(solution_path),
                            _csv_text(body, INNOVATION_COLUMNS, ["%.6f", "%d", "%d", "%.6g", "%d"] + ["%.6g"] * 6,
                                      _status_names(st)))
    inputs = getattr(sol, "inputs", None)
    if inputs is not None and not loose and inn.ndim == 2 and inn.shape[1] == 2:
        ep = np.repeat(np.arange(len(inputs.epoch_t)), np.diff(inputs.epoch_start))
        res = np.column_stack([inputs.epoch_t[ep], inputs.prn, inputs.elevation_deg, inn])
        cols, fmt = RESIDUAL_COLUMNS, ["%.6f", "%d", "%.3f", "%.6g", "%.6g"]
        flags = getattr(sol, "sat_flag", None)
        if flags is not None and np.shape(flags) == (len(inputs.prn), 2):
            from ..gnss.systems import system_index

            res = np.column_stack([res, system_index(inputs.system) if len(inputs.prn) else np.zeros(0), flags])
            cols, fmt = RESIDUAL_COLUMNS_FLAGS, fmt + ["%d", "%d", "%d"]
        atomic_write_text(residuals_path(solution_path), _csv_text(res, cols, fmt))
    return out


def _read_table(path: Path, columns, text_last: bool) -> tuple[np.ndarray, list[str] | None]:
    from ..data.textio import read_text

    text = read_text(path, "ascii")
    nl = text.find("\n")
    header = tuple(h.strip() for h in (text[:nl] if nl >= 0 else text).split(","))
    ncol = len(columns) - (1 if text_last else 0)
    names = None
    lines = [ln for ln in text[nl + 1:].splitlines() if ln.strip()] if nl >= 0 else []
    if header == tuple(columns):
        if text_last:
            cut = [ln.rsplit(",", 1) for ln in lines]
            for i, c in enumerate(cut):
                if len(c) != 2:
                    raise ValueError(f"{path}:{i + 2}: expected {len(columns)} columns")
            lines, names = [c[0] for c in cut], [c[1].strip() for c in cut]
    elif not (text_last and header == tuple(columns[:-1])):  # (a sidecar written before status_name existed)
        raise ValueError(f"{path}:1: unexpected header; expected {','.join(columns)}")
    body = "\n".join(",".join(x if x.strip() else "nan" for x in ln.split(",")) for ln in lines)
    from ..data.dataset import parse_numeric_text

    return parse_numeric_text(body, ncol, str(path), first_line=2), names


def read_innovations(path) -> dict:
    """The arrays of an innovations sidecar (empty cells: NaN): ``t_s``,
    ``status`` (codes), ``applied`` (bool), ``nis``, ``rows``, ``innovation``
    (M, 6) and ``status_name`` (the names; derived from the codes in a file
    without that column)."""
    path = Path(path)
    a, names = _read_table(path, INNOVATION_COLUMNS, text_last=True)
    status = a[:, 1].astype(int)
    if names is None:
        names = [status_name(c) for c in status]
    else:
        for i, (c, n) in enumerate(zip(status, names)):
            if n != status_name(c):
                raise ValueError(f"{path}:{i + 2}: status {c} is {status_name(c)!r}, but the row says {n!r}")
    return dict(t_s=a[:, 0], status=status, applied=a[:, 2] > 0, nis=a[:, 3], rows=a[:, 4].astype(int),
                innovation=a[:, 5:11], status_name=np.array(names, dtype=object))


def read_residuals(path) -> dict:
    """The arrays of a tight run's ``<solution>.residuals.csv``: ``t_s``,
    ``prn``, ``elevation_deg``, ``pseudorange_residual_m``,
    ``rate_residual_mps`` (INS-predicted minus measured, before the update);
    and when the file has them (:data:`RESIDUAL_COLUMNS_FLAGS`) ``system``
    (index), ``pseudorange_flag``, ``rate_flag``."""
    path = Path(path)
    with open(path, "rb") as f:
        header = tuple(h.strip() for h in f.readline().decode("ascii", "replace").strip().split(","))
    cols = RESIDUAL_COLUMNS_FLAGS if header == RESIDUAL_COLUMNS_FLAGS else RESIDUAL_COLUMNS
    a, _ = _read_table(path, cols, text_last=False)
    out = dict(t_s=a[:, 0], prn=a[:, 1].astype(int), elevation_deg=a[:, 2], pseudorange_residual_m=a[:, 3],
               rate_residual_mps=a[:, 4])
    if cols is RESIDUAL_COLUMNS_FLAGS:
        out.update(system=a[:, 5].astype(int), pseudorange_flag=a[:, 6].astype(int), rate_flag=a[:, 7].astype(int))
    return out
