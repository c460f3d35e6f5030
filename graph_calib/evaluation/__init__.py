"""How good a calibration is: validation on a record, IMU-TK's figures of merit."""
