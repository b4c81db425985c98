"""Self-calibration from data: Allan-variance noise identification
(:mod:`insnav.calib.allan`, ``insnav allan``) and filter noise tuning by the
innovation likelihood (:mod:`insnav.calib.tune`, ``insnav tune``)."""
