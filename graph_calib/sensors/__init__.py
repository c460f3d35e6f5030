"""Sensors: the effect registry, the calibration-vector layout and IMU grades, the sensor equations."""
