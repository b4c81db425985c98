"""Type stubs for the private compiled module ``insnav._core``."""
from typing import Any, Sequence

import numpy as np
import numpy.typing as npt

__version__: str

def mechanize(
    t: npt.ArrayLike,
    dtheta_b: npt.ArrayLike,
    dv_b: npt.ArrayLike,
    t0: float,
    pos_llh: npt.ArrayLike,
    v_n: npt.ArrayLike,
    rpy: npt.ArrayLike,
    coning: bool = True,
    sculling: bool = True,
) -> dict[str, Any]: ...  # lat_deg, lon_deg, h_m, v_n, roll_deg, pitch_deg, yaw_deg, bad_sample

class earth:
    @staticmethod
    def gravity(lat: npt.ArrayLike, h: npt.ArrayLike) -> Any: ...
    @staticmethod
    def radius_meridian(lat: npt.ArrayLike) -> Any: ...
    @staticmethod
    def radius_prime_vertical(lat: npt.ArrayLike) -> Any: ...
    @staticmethod
    def geodetic_to_ecef(lat: float, lon: float, h: float) -> np.ndarray: ...
    @staticmethod
    def ecef_to_geodetic(r_e: npt.ArrayLike) -> np.ndarray: ...
    @staticmethod
    def C_en(lat: float, lon: float) -> np.ndarray: ...
    @staticmethod
    def omega_ie_n(lat: float) -> np.ndarray: ...
    @staticmethod
    def omega_en_n(lat: float, h: float, v_n: npt.ArrayLike) -> np.ndarray: ...

class rotation:
    @staticmethod
    def dcm_from_euler(rpy: npt.ArrayLike) -> np.ndarray: ...
    @staticmethod
    def euler_from_dcm(C_nb: npt.ArrayLike) -> np.ndarray: ...
    @staticmethod
    def quat_from_euler(rpy: npt.ArrayLike) -> np.ndarray: ...
    @staticmethod
    def quat_from_rotvec(phi: npt.ArrayLike) -> np.ndarray: ...
    @staticmethod
    def rotvec_from_quat(wxyz: npt.ArrayLike) -> np.ndarray: ...
    @staticmethod
    def dcm_from_rotvec(phi: npt.ArrayLike) -> np.ndarray: ...

# --- closed-loop runs (the whole IMU loop in C++, GIL released) --------------
# All inputs SI (rad, m, m/s, s); results are dicts of numpy arrays plus counts.
# The public wrappers document every key: insnav.engine.run (loose),
# insnav.tight.run_tight, insnav.delay.run_delayed, insnav.particle.

def run_loose(
    filter: str,  # "ekf" | "rbukf" | "ukf"
    layout: int,  # 15, 21, or 16 (15 + the odometer scale factor: result "odo_scale" (N, 2))
    t: npt.ArrayLike,  # (N,) s
    dtheta_b: npt.ArrayLike,  # (N, 3) rad
    dv_b: npt.ArrayLike,  # (N, 3) m/s
    gnss: npt.ArrayLike,  # (M, 13): t, lat, lon, h, vN, vE, vD, sigma N/E/D [m], sigma vN/vE/vD [m/s]
    init: npt.ArrayLike,  # (10,): t0, lat, lon, h, vN, vE, vD, roll, pitch, yaw
    P0: npt.ArrayLike,  # (layout, layout)
    imu_correction: npt.ArrayLike,  # (12,): acc bias, gyro bias, acc scale, gyro scale
    imu_model: dict[str, Any],
    config: dict[str, Any],
    constraints: npt.ArrayLike | None = None,  # (K, 3): t [s], kinds (flags nhc 1, odo 2, zupt 4, zaru 8), speed [m/s]
) -> dict[str, Any]: ...
def smooth_rows(
    t: npt.NDArray[np.float64],  # (n,) row times [s]
    lat_deg: npt.NDArray[np.float64],  # (n,) rows corrected in place (contiguous float64)
    lon_deg: npt.NDArray[np.float64],
    h_m: npt.NDArray[np.float64],
    v_n: npt.NDArray[np.float64],  # (n, 3)
    roll_deg: npt.NDArray[np.float64],
    pitch_deg: npt.NDArray[np.float64],
    yaw_deg: npt.NDArray[np.float64],
    te: npt.NDArray[np.float64],  # (E,) smoother epochs [s]
    s: npt.NDArray[np.float64],  # (E, c) smoothed errors after feedback, c >= 9
    s_end: npt.NDArray[np.float64],  # (E, c) before feedback
    sigma_e: npt.NDArray[np.float64],  # (E, c)
    sigma_out: npt.NDArray[np.float64],  # (n, c) written in place (writeable float64, any strides), units of sigma_e
    extra: npt.NDArray[np.float64] | None = None,  # (n, c - 9) additive rows (clock, ISBs), in place
) -> None: ...
def run_tight(
    filter: str,  # "ekf" | "rbukf" | "ukf" (Layout17)
    t: npt.ArrayLike,
    dtheta_b: npt.ArrayLike,
    dv_b: npt.ArrayLike,
    epoch_t: npt.ArrayLike,  # (E,) s
    epoch_start: npt.ArrayLike,  # (E + 1,) first satellite row of each epoch
    sats: npt.ArrayLike,  # (S, k) per-satellite rows, see insnav.tight.TightInputs
    init: npt.ArrayLike,
    P0: npt.ArrayLike,
    imu_correction: npt.ArrayLike,
    clock0: npt.ArrayLike,  # (2,) clock bias [m], drift [m/s]
    imu_model: dict[str, Any],
    config: dict[str, Any],
    layout: int = 17,  # 17, or 20 with inter-system biases
    system: npt.ArrayLike | None = None,  # (S,) system index per row (0 G, 1 R, 2 E, 3 C)
    isb0: npt.ArrayLike | None = None,  # (3,) initial ISBs of R, E, C [m]
    prn: npt.ArrayLike | None = None,  # (S,) satellite number per row (the robust CUSUM keys on it)
    phase: npt.ArrayLike | None = None,  # (S, 4) carrier phase [m], wavelength [m], sigma [m], LLI (TDCP)
    epoch_still: npt.ArrayLike | None = None,  # (E,) standstill detector state per epoch (standstill_q_scale)
) -> dict[str, Any]: ...
def tdcp_row(
    prev: npt.ArrayLike,  # (10,) t, lat, lon [rad], h [m], v_n [m/s], roll, pitch, yaw [rad]
    cur: npt.ArrayLike,
    lever_arm_b: npt.ArrayLike,  # (3,) IMU -> antenna, FRD [m]
    sat_prev: npt.ArrayLike,  # (4,) satellite ECEF position [m], c dt_sv [m]
    sat_cur: npt.ArrayLike,
    clock_bias_prev_m: float,
    clock_bias_cur_m: float,
    omega_ib_b_prev: npt.ArrayLike | None = None,  # (3,) corrected angular rate [rad/s] (lever-arm velocity)
    omega_ib_b_cur: npt.ArrayLike | None = None,
    shift_prev_s: float = 0.0,  # how far the state is past its epoch's applied time [s]
    shift_cur_s: float = 0.0,
    layout: int = 17,  # 17, or 21 (LayoutTightTdLever: lever arm 17-19, time offset 20)
) -> dict[str, Any]: ...
def pseudorange_gm_fold_check(
    Pxx: npt.ArrayLike,  # (17, 17) navigation error covariance
    Pxb: npt.ArrayLike,  # (17, nb) cross-covariance with nb Gauss-Markov pseudorange states [m]
    Pbb: npt.ArrayLike,  # (nb, nb) [m^2]
    Hx: npt.ArrayLike,  # (m, 17)
    R: npt.ArrayLike,  # (m, m)
    y: npt.ArrayLike,  # (m,) residual (INS-predicted minus measured)
    row_slot: npt.ArrayLike,  # (m,) int32: the state of each pseudorange row, -1 for a Doppler row
) -> dict[str, Any]: ...
def run_delay(
    method: str,  # "rdkf" | "exact"
    layout: int,
    t: npt.ArrayLike,
    dtheta_b: npt.ArrayLike,
    dv_b: npt.ArrayLike,
    gnss: npt.ArrayLike,
    epochs: npt.ArrayLike,
    init: npt.ArrayLike,
    P0: npt.ArrayLike,
    imu_correction: npt.ArrayLike,
    imu_model: dict[str, Any],
    config: dict[str, Any],
    delay_p: npt.ArrayLike,  # (s + 1,) delay probabilities p_0..p_s
) -> dict[str, Any]: ...
def run_tight_particle(
    filter: str,  # "upf" | "pf" | "fukf" (Layout20)
    t: npt.ArrayLike,
    dtheta_b: npt.ArrayLike,
    dv_b: npt.ArrayLike,
    epoch_t: npt.ArrayLike,
    epoch_start: npt.ArrayLike,
    sats: npt.ArrayLike,
    init: npt.ArrayLike,
    P0: npt.ArrayLike,
    imu_correction: npt.ArrayLike,
    clock0: npt.ArrayLike,
    imu_model: dict[str, Any],
    config: dict[str, Any],
    particle: dict[str, Any],
) -> dict[str, Any]: ...

def scan_imu(
    t: npt.ArrayLike,
    dtheta_b: npt.ArrayLike,
    dv_b: npt.ArrayLike,
    t0: float = ...,
    max_rate_rps: float = ...,
    max_accel_mps2: float = ...,
    gap_factor: float = ...,
) -> dict[str, Any]: ...
def scan_solution(
    lat_deg: npt.NDArray[np.float64],  # (N,) any strides
    lon_deg: npt.NDArray[np.float64],
    h_m: npt.NDArray[np.float64],
    v_n: npt.NDArray[np.float64],  # (N, 3)
    sigmas: list[npt.NDArray[np.float64]],  # up to 3 blocks (N, 3)
    h_lo_m: float,
    h_hi_m: float,
    r_m: float,
) -> dict[str, Any]: ...
def rotation_about_at(
    t: npt.ArrayLike,
    dtheta_b: npt.ArrayLike,
    axis_b: npt.ArrayLike,
    query: npt.ArrayLike,
) -> np.ndarray: ...
def nav_rows_to_degrees(
    llh: npt.NDArray[np.float64],  # (N, 3) lat, lon [rad] -> [deg] in place
    rpy: npt.NDArray[np.float64],  # (N, 3) [rad] -> [deg] in place
    sigma: npt.NDArray[np.float64],  # (N, k): columns att_col..att_col+2 [rad] -> [deg] in place
    att_col: int,
    v_n: npt.NDArray[np.float64],
) -> tuple[int, bool]: ...  # (first row with a non-finite latitude or velocity or -1, any non-finite)
def parse_csv(
    data: bytes | memoryview,
    begin: int,  # the byte the parse starts at (a line start)
    delim: str,  # one character
    nfields: int,
    want: Sequence[int],  # the fields read, in this order
    time_want: int,  # index into want of the time field, < 0: none
) -> tuple[Any, Any, Any, int, int | None]: ...  # (values (rows, len(want)), line index of each row, None or (t_hi, t_lo, t_frac, t_kind), lines taken, None or the byte of the line not taken)
def parse_text(
    data: bytes | memoryview,
    ncols: int,
    keep: int,
    allow_extra: bool = False,
    comma: bool = False,
    first_line: int = 1,
    threads: int = 2,
    groups: list[int] | None = None,
) -> tuple[Any, Any, Any]: ...  # (array or tuple of arrays, line of each row or None, None or the first error)
def set_progress(callback: Any) -> None: ...  # callback(k, n) from every run's C++ loop, at most every 20 ms
def standstill_statistic(
    t: npt.ArrayLike,
    dtheta_b: npt.ArrayLike,
    dv_b: npt.ArrayLike,
    t0: float,
    window: int,
    sigma_f_mps2: float,
    sigma_w_radps: float,
    gravity_mps2: float = 9.80665,
) -> np.ndarray: ...  # (N,) test statistic T (ins/standstill.hpp), +inf until the window is full
def overlapping_avar(
    rates: Sequence[npt.ArrayLike],  # (n,) or (n, k) float64 arrays, same n, any strides (not copied)
    m: npt.ArrayLike,  # (n_m,) cluster sizes, 1 <= m <= n / 2
    threads: int = 0,  # <= 0: the hardware's
) -> tuple[np.ndarray, np.ndarray, int, int]: ...  # (avar (n_m, axes), terms (n_m,), first non-finite row or -1, its axis group or -1)
def allan_cluster_sizes(n: int, per_octave: int = 1, max_m: int = -1) -> np.ndarray: ...  # round(2^(k/per_octave)) <= n/2
def write_table(
    path: str,
    header: str,
    columns: list[npt.NDArray[np.float64]],
    scales: list[float],
    decimals: list[int],  # >= 0 fixed, < 0 shortest round trip
    sep: str = ",",
    width: int = 0,
    trim_zeros: bool = True,
    trailing_sep: bool = False,
    threads: int = 2,
    append: bool = False,  # after the file's end (no header rewrite, no truncation)
) -> int: ...  # bytes written

class TextSink:
    """One text file written by several write() calls, through an aligned buffer with O_DIRECT where allowed."""

    def __init__(self, path: str, direct: bool = True) -> None: ...
    def write(
        self,
        header: str,
        columns: list[npt.NDArray[np.float64]],
        scales: list[float],
        decimals: list[int],
        sep: str = ",",
        width: int = 0,
        trim_zeros: bool = True,
        trailing_sep: bool = False,
        threads: int = 2,
    ) -> int: ...
    def close(self) -> int: ...
    @property
    def direct(self) -> bool: ...

class LooseStream:
    """The loose run fed block by block (engine/loose_stream.hpp); used by insnav.filters.stream."""
    def __init__(
        self,
        filter: str,  # "ekf" | "rbukf" | "ukf"
        layout: int,  # 15 | 21
        gnss: npt.ArrayLike,  # (m, 13) run_loose's gnss rows, sorted by time (the first fixes; more: push_gnss)
        init: npt.ArrayLike,  # (10,): t0, lat, lon, h, vN, vE, vD, roll, pitch, yaw (SI)
        P0: npt.ArrayLike,  # (layout, layout)
        imu_correction: npt.ArrayLike,  # (12,)
        imu_model: dict[str, Any],
        config: dict[str, Any],  # run_loose's engine config (no smooth, no self-calibration)
        block_samples: int,  # the most samples one run_block takes
    ) -> None: ...
    def push_gnss(self, gnss: npt.ArrayLike) -> None: ...  # (n, 13) the next fixes in time order
    def run_block(self, t: npt.ArrayLike, dtheta_b: npt.ArrayLike, dv_b: npt.ArrayLike) -> int: ...  # rows written
    def finish(self) -> int: ...  # 0 or 1 rows: the last sample's
    def rows(self) -> dict[str, np.ndarray]: ...  # t, llh, v_n, rpy, sigma, imu_err of the last call (views; two buffers in turn)
    # first (the run's index of the first record); innovation, nis, log_det_s, meas_sigma, status of the fixes
    # consumed since the last take
    def take_records(self) -> dict[str, Any]: ...
    def records(self) -> dict[str, Any]: ...  # take_records() and the counters
    @property
    def max_window(self) -> int: ...  # the most fixes held at once
    @property
    def samples(self) -> int: ...
    @property
    def t_last(self) -> float: ...

class LooseNavigator:
    """Real-time loose navigator (engine/navigator.hpp); use insnav.Navigator."""
    def __init__(
        self,
        filter: str,  # "ekf" (layout 15, 16, 21) | "rbukf" | "ukf" (15)
        layout: int,
        init: npt.ArrayLike,  # (10,): t0, lat, lon, h, vN, vE, vD, roll, pitch, yaw (SI)
        P0: npt.ArrayLike,  # (layout, layout)
        imu_correction: npt.ArrayLike,  # (12,)
        imu_model: dict[str, Any],
        config: dict[str, Any],  # run_loose's engine config
        imu_hold: int = 0,  # IMU samples held back for late records, 0..256
    ) -> None: ...
    def push_imu(self, t: float, dtheta_b: npt.ArrayLike, dv_b: npt.ArrayLike) -> bool: ...
    def push_imu_array(self, t: npt.ArrayLike, dtheta_b: npt.ArrayLike, dv_b: npt.ArrayLike) -> int: ...
    def push_gnss_fix(self, row: npt.ArrayLike) -> int: ...  # run_loose's 13-value gnss row; RecordStatus code
    def push_constraint(self, t: float, kinds: int, speed_mps: float = ...) -> int: ...
    def flush(self) -> None: ...
    def solution(self) -> dict[str, Any]: ...  # t, lat, lon [rad], h, v_n, rpy [rad], sigma, imu_err (, odo_scale)
    def covariance(self) -> np.ndarray: ...
    def counters(self) -> dict[str, Any]: ...
    def last_fix(self) -> dict[str, Any]: ...  # status, nis, innovation (6)

class TightNavigator:
    """Real-time tight navigator (engine/navigator.hpp); use insnav.TightNavigator."""
    def __init__(
        self,
        filter: str,  # "ekf" | "rbukf" | "ukf"
        layout: int,  # 17 | 20 (inter-system biases of R, E, C)
        init: npt.ArrayLike,  # (10,): t0, lat, lon, h, vN, vE, vD, roll, pitch, yaw (SI)
        P0: npt.ArrayLike,  # (layout, layout)
        imu_correction: npt.ArrayLike,  # (12,)
        clock0: npt.ArrayLike,  # (2,): receiver clock bias [m], drift [m/s]
        isb0: npt.ArrayLike | None,  # (3,) [m] (layout 20)
        imu_model: dict[str, Any],
        config: dict[str, Any],  # run_tight's engine config
        imu_hold: int = 0,  # IMU samples held back for late epochs, 0..256
    ) -> None: ...
    def push_imu(self, t: float, dtheta_b: npt.ArrayLike, dv_b: npt.ArrayLike) -> bool: ...
    def push_imu_array(self, t: npt.ArrayLike, dtheta_b: npt.ArrayLike, dv_b: npt.ArrayLike) -> int: ...
    def push_pseudoranges(self, t: float, sats: npt.ArrayLike, system: npt.ArrayLike, prn: npt.ArrayLike) -> int: ...
    def flush(self) -> None: ...
    def solution(self) -> dict[str, Any]: ...  # as LooseNavigator's, plus clock (2) (, isb (3))
    def covariance(self) -> np.ndarray: ...
    def counters(self) -> dict[str, Any]: ...
    def last_epoch(self) -> dict[str, Any]: ...  # status, nis

class DelayNavigator:
    """Real-time random-delay KF navigator (engine/navigator.hpp); use insnav.DelayNavigator."""
    def __init__(
        self,
        layout: int,  # 15
        init: npt.ArrayLike,  # (10,): t0, lat, lon, h, vN, vE, vD, roll, pitch, yaw (SI)
        P0: npt.ArrayLike,  # (15, 15)
        imu_correction: npt.ArrayLike,  # (12,)
        imu_model: dict[str, Any],
        config: dict[str, Any],  # run_delay's engine config
        delay_p: npt.ArrayLike,  # (s + 1,) P(delay = i epochs), s = 1..4 (one value: s = 1)
        imu_hold: int = 0,  # IMU samples held back for late epochs, 0..256
    ) -> None: ...
    def push_imu(self, t: float, dtheta_b: npt.ArrayLike, dv_b: npt.ArrayLike) -> bool: ...
    def push_imu_array(self, t: npt.ArrayLike, dtheta_b: npt.ArrayLike, dv_b: npt.ArrayLike) -> int: ...
    def push_epoch(self, t: float, records: npt.ArrayLike) -> int: ...  # (k <= 8, 14) run_delay's gnss rows; RecordStatus code
    def flush(self) -> None: ...
    def solution(self) -> dict[str, Any]: ...  # t, lat, lon [rad], h, v_n, rpy [rad], sigma, imu_err
    def covariance(self) -> np.ndarray: ...
    def counters(self) -> dict[str, Any]: ...
    def last_record(self) -> dict[str, Any]: ...  # status, nis, innovation (6)

# carrier-phase RTK (bind_rtk.cpp)
RTK_ROW_COLS: int
RTK_MAX_AMBIGUITIES: int

def read_rinex3_obs(path: str, prefs: dict[str, list[list[str]]]) -> dict[str, Any]: ...
def read_rinex3_obs_body(text: bytes, path: str, offset: int, lineno: int, types: dict[str, list[str]],
                         select: dict[str, list[str]], zero_is_missing: bool, rinex2: bool = False) -> dict[str, Any]: ...
def lambda_search(a_hat: npt.ArrayLike, Q: npt.ArrayLike) -> tuple[np.ndarray, tuple[float, float]]: ...
def lambda_search_stats(a_hat: npt.ArrayLike, Q: npt.ArrayLike) -> dict[str, Any]: ...
def lambda_decorrelate(Q: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
def lambda_success_rate(Q: npt.ArrayLike, variance_factor: float = 1.0) -> float: ...
def rtk_run(
    t_rover: npt.ArrayLike,
    rover_off: npt.ArrayLike,
    rover_rows: npt.ArrayLike,
    base_off: npt.ArrayLike,
    base_rows: npt.ArrayLike,
    base_index: npt.ArrayLike,
    r_base_e: npt.ArrayLike,
    options: dict[str, Any],
    record_iono: bool = False,
    record_fixed_rows: bool = False,
    record_float: bool = False,
) -> dict[str, Any]: ...
def rtk_vce_sums(
    epoch: npt.ArrayLike,
    code: npt.ArrayLike,
    group: npt.ArrayLike,
    y: npt.ArrayLike,
    h: npt.ArrayLike,
    var_own: npt.ArrayLike,
    var_ref: npt.ArrayLike,
    k: npt.ArrayLike,
    redundancy: bool = False,
) -> dict[str, Any]: ...
def slip_detect(t: npt.ArrayLike, off: npt.ArrayLike, rows: npt.ArrayLike, options: dict[str, Any]) -> np.ndarray: ...
def rtk_rinex_files(rover: str, base: str, nav: list[str], systems: str, options: dict[str, Any],
                    base_position_e_m: list[float] | None,
                    signal_prefs: dict[str, list[list[str]]]) -> dict[str, Any] | str: ...
def rtk_double_differences(
    rover_rows: npt.ArrayLike,
    base_rows: npt.ArrayLike,
    r_rover_e: npt.ArrayLike,
    r_base_e: npt.ArrayLike,
    options: dict[str, Any],
) -> dict[str, np.ndarray]: ...

# tight RTK/INS (bind_rtk_ins.cpp)
RTK_INS_SLIP_KINDS: int

def rtk_ins_run(
    t: npt.ArrayLike,
    dtheta_b: npt.ArrayLike,
    dv_b: npt.ArrayLike,
    init: npt.ArrayLike,
    P0: npt.ArrayLike,
    imu_correction: npt.ArrayLike,
    imu_model: dict[str, Any],
    config: dict[str, Any],
    rtk_options: dict[str, Any],
    t_rec: npt.ArrayLike,
    rover_off: npt.ArrayLike,
    rover_rows: npt.ArrayLike,
    base_off: npt.ArrayLike,
    base_rows: npt.ArrayLike,
    base_index: npt.ArrayLike,
    r_base_e: npt.ArrayLike,
    probe_epoch: int = -1,
    filter: str = "ekf",
) -> dict[str, Any]: ...
def dd_phase_row(
    init: npt.ArrayLike,
    lever_arm_b: npt.ArrayLike,
    r_base_e: npt.ArrayLike,
    rover_s: npt.ArrayLike,
    rover_i: npt.ArrayLike,
    base_s: npt.ArrayLike,
    base_i: npt.ArrayLike,
    freq: int,
    code: bool,
    tropo: bool = True,
) -> tuple[float, np.ndarray]: ...
def ambiguity_accepts(
    a_hat: npt.ArrayLike, Q: npt.ArrayLike, a_cand: npt.ArrayLike, ratio_threshold: float, validation_prob: float
) -> tuple[bool, float, float]: ...

GDOP_MAX_SATS: int

def select_best_gdop(u: npt.ArrayLike, n_select: int, max_combinations: int) -> tuple[np.ndarray, float]: ...
def best_gdop_keep(u: npt.ArrayLike, epoch_start: npt.ArrayLike, n_select: int,
                   max_combinations: int) -> np.ndarray: ...  # (M,) bool
def select_nearest_record(rec_prn: npt.ArrayLike, rec_ok: npt.ArrayLike, rec_t: npt.ArrayLike,
                          rec_window: npt.ArrayLike, row_prn: npt.ArrayLike,
                          row_t: npt.ArrayLike) -> np.ndarray: ...  # (k,) int64, -1 if none
def scan_rinex_nav_body(body: str, rinex3: bool, glonass2: bool,
                        want: str) -> dict[str, Any] | None: ...
SPP_MAX_ROWS: int

def solve_spp_batch(
    epoch_start: npt.ArrayLike,
    sats: npt.ArrayLike,
    sigma_pr_m: npt.ArrayLike,
    sigma_prr_mps: npt.ArrayLike,
    system: npt.ArrayLike,
    r0_e: npt.ArrayLike,
    options: dict[str, Any],
    out: dict[str, np.ndarray],
) -> None: ...
def transmit_states_kepler(
    elem: npt.ArrayLike,
    idx: npt.ArrayLike,
    t_rx: npt.ArrayLike,
    r_rx: npt.ArrayLike,
    gm: float,
    omega_e: float,
    f_rel: float,
    omega_geo: float,
    tol_s: float,
    max_iter: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]: ...
def transmit_states_glonass(
    glo: npt.ArrayLike,
    idx: npt.ArrayLike,
    t_rx: npt.ArrayLike,
    r_rx: npt.ArrayLike,
    gm: float,
    j2_term: float,
    omega_e: float,
    step_s: float,
    tol_s: float,
    max_iter: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]: ...
