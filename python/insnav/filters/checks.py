"""The unit and sanity checks run before every filter: :mod:`insnav.data.checks`
(they live in the data layer so that the file loaders in :mod:`insnav.io` can
run them before the initial alignment); re-exported here."""
from __future__ import annotations

from ..data.checks import (DataCheckError, check_dataset, check_gnss, check_gnss_velocity,  # noqa: F401
                           check_gyro_against_gnss, check_imu, check_latlon_radians, check_time_offset,
                           check_time_overlap, estimate_time_offset)

__all__ = ["DataCheckError", "check_dataset", "check_gnss", "check_gnss_velocity", "check_gyro_against_gnss",
           "check_imu", "check_latlon_radians", "check_time_offset", "check_time_overlap", "estimate_time_offset"]
