"""insnav: GNSS/INS integrated navigation.

A header-only C++17/Eigen core (strapdown mechanization, EKF, RB-UKF, UKF,
random-delay and particle filters) under a pure-Python API.

Conventions: navigation frame NED, body frame forward-right-down (FRD),
3-2-1 Euler angles (roll, pitch, yaw), IMU samples as increments over
``(t - dt, t]``.  SI units inside; the public API and files carry the unit
in the name (``lat_deg``, ``h_m``).  See ``docs/conventions.md``.

Compiled parts are loaded lazily so that the pure-Python modules
(``insnav.earth``, ``insnav.gnss``) import without the extension.
"""
from __future__ import annotations

import importlib

# The one place the version is written: pyproject.toml (scikit-build-core regex
# provider) and CMakeLists.txt read this line.
__version__ = "0.1.0"

# public name -> module that defines it (PEP 562 lazy loading).  No public
# name is the name of a submodule (insnav.evaluate is the function of
# insnav.analysis.evaluate), so importing any submodule never rebinds one.
_LAZY = {
    "NavState": "insnav.data.nav",
    "Trajectory": "insnav.data.nav",
    "NavTrajectory": "insnav.data.nav",
    "mechanize": "insnav.ins.mechanize",
    "simulate": "insnav.sim",
    "simulate_rtk": "insnav.sim",
    "load_dataset": "insnav.data.dataset",
    "load_csv_dataset": "insnav.io.csv_dataset",
    "Dataset": "insnav.data.dataset",
    "run": "insnav.filters",
    "Navigator": "insnav.filters.navigator",
    "TightNavigator": "insnav.filters.navigator",
    "DelayNavigator": "insnav.filters.navigator",
    "Solution": "insnav.filters.solution",
    "load_solution": "insnav.filters.solution",
    "RunConfig": "insnav.config",
    "evaluate": "insnav.analysis.evaluate",
    "montecarlo": "insnav.analysis.montecarlo",
}

__all__ = sorted(_LAZY) + ["__version__"]


def __getattr__(name: str):
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module 'insnav' has no attribute {name!r}")
    value = getattr(importlib.import_module(mod), name)
    globals()[name] = value
    return value


def __dir__():
    return __all__
