"""Shortened soak (the 24 h run is bench/soak.py; the scenario is tests/_soak.py): 20 min at 200 Hz
with two GNSS outages through the Python API -- every output finite, sigmas
positive, memory flat during the run.  The per-step P check (symmetric,
positive definite after every propagate/update) is cpp/tests/test_soak.cpp,
run by tests/test_cpp.py in Release and under ASan + UBSan."""
from __future__ import annotations

from _soak import python_soak


def test_short_soak_python_api():
    for r in python_soak(0.34, filters=("ekf", "rbukf")):
        assert r["finite"] and r["sigma_positive"], r
        assert r["summary"]["updates"] > 1000 and r["summary"]["cholesky_repairs"] == 0
        assert r["max_err_m"] < 25.0 and r["rms_err_m"] < 3.0
        assert r["rss_max_run_kb"] - r["rss_min_run_kb"] < 8 * 1024
