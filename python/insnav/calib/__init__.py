"""Self-calibration: IMU noise identification and filter noise tuning."""
