"""Data containers: the navigation state and trajectories (:mod:`.nav`), a
dataset's IMU, GNSS, odometer and truth tables and its folder format
(:mod:`.dataset`), named IMU grades (:mod:`.imu_grades`)."""
from __future__ import annotations

from .dataset import Dataset, GnssFixes, GnssRaw, ImuData, Truth, load_dataset
from .nav import NavState, NavTrajectory, Trajectory

__all__ = ["Dataset", "GnssFixes", "GnssRaw", "ImuData", "Truth", "load_dataset", "NavState", "NavTrajectory", "Trajectory"]
