"""The ``[rtk]`` table's keys, defaults, checks and engine options, without numpy.

Shared by :class:`insnav.gnss.rtk.RtkOptions` (its ``validate`` and ``core_dict``) and the
command line's RTK path that runs without numpy (:mod:`insnav.cli.rtk_fast`), so both accept
the same values with the same one-line messages.
"""
from __future__ import annotations

import math

__all__ = ["SIGNALS", "SYSTEM_INDEX", "RTK_DEFAULTS", "BASE_POSITION_TOLERANCE_M", "CODE_FIT_TOLERANCE_M", "MAX_AMBIGUITIES", "rtk_value_error",
           "rtk_core_dict"]

#: engine index of each system (``RtkSystem`` in rtk.hpp)
SYSTEM_INDEX = {"G": 0, "R": 1, "E": 2, "C": 3, "J": 4}
#: signals per system and frequency slot, in order of preference (RINEX 3 band + attribute)
SIGNALS = {
    "G": (("1C", "1W", "1X", "1P", "1S", "1L"), ("2W", "2L", "2S", "2X", "2P", "2C", "2D"), ("5Q", "5X", "5I")),
    "R": (("1C", "1P"), ("2C", "2P"), ("3Q", "3X", "3I")),
    "E": (("1C", "1X", "1B"), ("7Q", "7X", "7I"), ("5Q", "5X", "5I")),
    "C": (("2I", "2X", "2Q", "1I"), ("7I", "7X", "7Q"), ("6I", "6X", "6Q")),
    # QZSS: the GPS frequencies L1/L2/L5 (IS-QZSS-PNT 3.1.1); L1 C/A first, then L1C
    "J": (("1C", "1X", "1L", "1S"), ("2L", "2X", "2S"), ("5Q", "5X", "5I")),
}
MODES = {"static": 0, "kinematic": 1}
AR_MODES = {"off": 0, "continuous": 1, "instantaneous": 2, "fix-and-hold": 3}
IONO_MODES = {"off": 0, "variance": 1, "estimate": 2}
#: default iono_sigma_per_10km_m per mode [m]: no DD variance; RTKLIB's stats-stdiono for the states
IONO_SIGMA_DEFAULT = {"off": 0.0, "variance": 0.0, "estimate": 0.03}

#: largest distance [m] between the base position a run is given and the code-only fix of the base's own
#: pseudoranges (no ionosphere or troposphere model; :func:`insnav.gnss.rtk.check_base_position`): that fix
#: lands 20-60 m from the known antenna on the shared data sets (matrtklib 56 m, Wettzell 21 m, Spirent
#: 24 m), so a position further off is a wrong one (a mistyped coordinate, another station's file) that
#: would shift every rover epoch by as much
BASE_POSITION_TOLERANCE_M = 500.0
#: largest median residual RMS [m] of a receiver's one-epoch code fits (unit weights, no atmosphere
#: models; insnav.gnss.rtk.check_code_fit) that an RTK run accepts.  Measured on the repository's data:
#: 5.7-10.3 m on the real EUREF and MatRTKLIB files, 1.4-2.9 m on the Spirent files, 0.2-1.4 m on the
#: simulator's presets; the MatRTKLIB rover with its epoch time tags moved by 0.5 s: 172 m (the
#: satellites computed half a second away from where the pseudoranges saw them)
CODE_FIT_TOLERANCE_M = 50.0

#: every key of the table and its default, in the order of the dataclass (tests/test_rtk_fast.py checks it)
RTK_DEFAULTS = {
    "mode": "kinematic", "ar_mode": "continuous", "systems": "GREC", "frequencies": 2, "elevation_mask_deg": 15.0,
    "ar_elevation_mask_deg": 0.0, "ratio_threshold": 3.0, "min_fix_ambiguities": 5, "max_partial_drops": 4,
    "partial_ar_order": "variance", "min_lock_epochs": 0, "glonass_ar": False, "sigma_phase_a_m": 0.003,
    "sigma_phase_b_m": 0.003, "code_phase_ratio": 100.0, "code_correlation_time_s": 0.0,
    "phase_correlation_time_s": 0.0, "phase_error_ratio": 0.0, "adaptive_code_gain": 0.0,
    "min_success_rate": 0.95, "min_success_rate_estimated": 0.98, "success_rate_noise_window_s": 300.0,
    "success_rate_noise_confidence": 0.5, "confirm_epochs": 5, "confirm_max_ambiguities": 6, "iono": "variance",
    "iono_sigma_per_10km_m": None, "iono_tau_s": 1800.0, "tropo_model": True, "accel_psd_h_m2ps3": 9.0,
    "accel_psd_v_m2ps3": 1.0, "amb_init_sigma_cycles": 30.0, "amb_psd_cycles2ps": 1e-8, "gf_threshold_m": 0.05,
    "mw_threshold_cycles": 2.0, "doppler_threshold_cycles": 1.0, "max_outage_epochs": 5, "outlier_sigma": 5.0,
    "hold_sigma_cycles": 0.0316, "max_age_s": 30.0, "noise": "configured",
}

#: (key, lowest, highest) of the real-valued keys
_RANGES = (("elevation_mask_deg", 0.0, 90.0), ("ar_elevation_mask_deg", 0.0, 90.0),
           ("ratio_threshold", 1.0, 1e3), ("sigma_phase_a_m", 0.0, 1.0),
           ("sigma_phase_b_m", 0.0, 1.0), ("code_phase_ratio", 1.0, 1e4),
           ("code_correlation_time_s", 0.0, 1e4), ("phase_correlation_time_s", 0.0, 1e4),
           ("phase_error_ratio", 0.0, 10.0), ("min_success_rate", 0.0, 1.0),
           ("min_success_rate_estimated", 0.0, 1.0),
           ("success_rate_noise_window_s", 1.0, 1e6), ("success_rate_noise_confidence", 0.5, 0.999),
           ("adaptive_code_gain", 0.0, 1.0),
           ("iono_sigma_per_10km_m", 0.0, 10.0), ("iono_tau_s", 1e-3, 1e7),
           ("accel_psd_h_m2ps3", 0.0, 1e4),
           ("accel_psd_v_m2ps3", 0.0, 1e4), ("amb_init_sigma_cycles", 1e-3, 1e6),
           ("amb_psd_cycles2ps", 0.0, 1.0),
           ("gf_threshold_m", 1e-4, 10.0), ("mw_threshold_cycles", 0.1, 100.0),
           ("doppler_threshold_cycles", -1.0, 1e3), ("outlier_sigma", 0.0, 1e3),
           ("hold_sigma_cycles", 1e-6, 10.0), ("max_age_s", 0.0, 86400.0))
#: tracked single-differenced ambiguities of the GNSS-only engine (``kMaxAmbStates`` in
#: cpp/include/insnav/gnss/rtk.hpp): no set to fix can hold more
MAX_AMBIGUITIES = 120
#: largest epoch count of the integer keys: above any run's length at 1 Hz (11.6 days), and far
#: inside the engine's 32-bit int (a larger TOML integer gave a raw pybind11 cast error)
MAX_EPOCHS = 1_000_000
#: (key, lowest, highest) of the integer keys
_INT_RANGES = (("min_fix_ambiguities", 1, MAX_AMBIGUITIES), ("max_partial_drops", 0, MAX_AMBIGUITIES),
               ("min_lock_epochs", 0, MAX_EPOCHS), ("confirm_epochs", 1, MAX_EPOCHS),
               ("confirm_max_ambiguities", 0, MAX_AMBIGUITIES), ("max_outage_epochs", 0, MAX_EPOCHS))


def rtk_value_error(v: dict, source: str, table: str = "rtk") -> str | None:
    """The one-line message of the first bad value of the table ``v`` (every key present), or
    None; fills ``v["iono_sigma_per_10km_m"]`` with its mode's default when None (as
    ``RtkOptions.validate`` does, whose checks these are, in their order)."""

    def bad(key, allowed):
        return f"{source}: key '{table}.{key}': bad value {v[key]!r}; allowed: {allowed}"

    if v["mode"] not in MODES:
        return bad("mode", " or ".join(MODES))
    if v["ar_mode"] not in AR_MODES:
        return bad("ar_mode", ", ".join(AR_MODES))
    s = v["systems"]
    if not isinstance(s, str) or not s or any(c not in SIGNALS for c in s):
        return bad("systems", "letters of GRECJ")
    if isinstance(v["frequencies"], bool) or v["frequencies"] not in (1, 2, 3):
        return bad("frequencies", "1, 2 or 3")
    if v["partial_ar_order"] not in ("elevation", "variance"):
        return bad("partial_ar_order", "elevation or variance")
    if not isinstance(v["glonass_ar"], bool):
        return bad("glonass_ar", "true or false")
    if v["iono"] not in IONO_MODES:
        return bad("iono", ", ".join(IONO_MODES))
    if v["iono_sigma_per_10km_m"] is None:
        v["iono_sigma_per_10km_m"] = IONO_SIGMA_DEFAULT[v["iono"]]
    if v["iono"] == "estimate" and not (isinstance(v["iono_sigma_per_10km_m"], (int, float))
                                        and v["iono_sigma_per_10km_m"] > 0.0):
        return bad("iono_sigma_per_10km_m", "a number > 0 with iono = 'estimate'")
    if not isinstance(v["tropo_model"], bool):
        return bad("tropo_model", "true or false")
    if v["noise"] not in ("configured", "estimate"):
        return bad("noise", "configured or estimate")
    for key, lo, hi in _RANGES:
        x = v[key]
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not (lo <= x <= hi):
            return bad(key, f"a number in [{lo}, {hi}]")
    if v["sigma_phase_a_m"] == 0.0 and v["sigma_phase_b_m"] == 0.0:
        return bad("sigma_phase_a_m", "a and b not both 0")
    for key, lo, hi in _INT_RANGES:
        x = v[key]
        if isinstance(x, bool) or not isinstance(x, int) or not (lo <= x <= hi):
            return bad(key, f"an integer in [{lo}, {hi}]")
    return None


def rtk_core_dict(v: dict) -> dict:
    """Options of the C++ engine (``RtkOptions`` in rtk.hpp; SI units) from the table ``v``."""
    return dict(mode=MODES[v["mode"]], ar_mode=AR_MODES[v["ar_mode"]], n_freq=int(v["frequencies"]),
                elevation_mask_rad=math.radians(v["elevation_mask_deg"]),
                ar_elevation_mask_rad=math.radians(v["ar_elevation_mask_deg"]),
                ratio_threshold=float(v["ratio_threshold"]), min_fix_ambiguities=int(v["min_fix_ambiguities"]),
                max_partial_drops=int(v["max_partial_drops"]),
                partial_by_variance=v["partial_ar_order"] == "variance", min_lock_epochs=int(v["min_lock_epochs"]),
                glonass_ar=bool(v["glonass_ar"]), sigma_phase_a_m=float(v["sigma_phase_a_m"]),
                sigma_phase_b_m=float(v["sigma_phase_b_m"]), code_phase_ratio=float(v["code_phase_ratio"]),
                code_corr_time_s=float(v["code_correlation_time_s"]),
                phase_corr_time_s=float(v["phase_correlation_time_s"]),
                phase_error_ratio=float(v["phase_error_ratio"]),
                code_scale_gain=float(v["adaptive_code_gain"]),
                min_success_rate=float(v["min_success_rate"]),
                min_success_rate_estimated=float(v["min_success_rate_estimated"]),
                noise_window_s=float(v["success_rate_noise_window_s"]),
                noise_confidence=float(v["success_rate_noise_confidence"]),
                confirm_epochs=int(v["confirm_epochs"]),
                confirm_max_ambiguities=int(v["confirm_max_ambiguities"]),
                iono_mode=IONO_MODES[v["iono"]],
                iono_sigma_per_10km_m=float(IONO_SIGMA_DEFAULT[v["iono"]] if v["iono_sigma_per_10km_m"] is None
                                            else v["iono_sigma_per_10km_m"]),
                iono_tau_s=float(v["iono_tau_s"]), tropo_model=bool(v["tropo_model"]),
                accel_psd_h=float(v["accel_psd_h_m2ps3"]), accel_psd_v=float(v["accel_psd_v_m2ps3"]),
                amb_init_sigma_cycles=float(v["amb_init_sigma_cycles"]),
                amb_psd=float(v["amb_psd_cycles2ps"]),
                gf_threshold_m=float(v["gf_threshold_m"]), mw_threshold_cycles=float(v["mw_threshold_cycles"]),
                doppler_threshold_cycles=float(v["doppler_threshold_cycles"]),
                max_outage_epochs=int(v["max_outage_epochs"]), outlier_sigma=float(v["outlier_sigma"]),
                hold_sigma_cycles=float(v["hold_sigma_cycles"]), max_age_s=float(v["max_age_s"]))
