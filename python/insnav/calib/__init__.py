"""IMU calibration from data: Allan-variance noise identification
(:mod:`insnav.calib.allan`, the ``insnav allan`` command)."""
