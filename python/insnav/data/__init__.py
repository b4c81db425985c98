"""Data containers: the navigation state and trajectories (:mod:`.nav`), a
dataset's IMU, GNSS, odometer and truth tables and its folder format
(:mod:`.dataset`), named IMU grades (:mod:`.imu_grades`).

The names below are imported on first use (PEP 562), so importing
:mod:`insnav.data.nav` (the solution layer does, on every ``insnav run``)
does not load the dataset folder format and its eight dataclasses: a GNSS-only
run (``--filter spp|rtk``) never reads one.
"""
from __future__ import annotations

_LAZY = {**{name: "dataset" for name in ("Dataset", "GnssFixes", "GnssRaw", "ImuData", "Truth", "load_dataset")},
         **{name: "nav" for name in ("NavState", "NavTrajectory", "Trajectory")}}

__all__ = ["Dataset", "GnssFixes", "GnssRaw", "ImuData", "Truth", "load_dataset", "NavState", "NavTrajectory", "Trajectory"]


def __getattr__(name: str):
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(f".{mod}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
