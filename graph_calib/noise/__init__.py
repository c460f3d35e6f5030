"""The noise of an IMU identified from its own record (docs/model.md, "Noise from the record").

``rests`` finds every rest of a record, ``allan`` the overlapping Allan deviation over them,
``identify`` the IEEE Std 952 / 1293 terms and the white-noise density that governs a keyframe.
"""

from graph_calib.noise.allan import AllanDeviation, overlapping_allan
from graph_calib.noise.identify import (NoiseIdentification, SensorNoise, identify_noise, table_noise)
from graph_calib.noise.rests import find_rests

__all__ = ["AllanDeviation", "overlapping_allan", "NoiseIdentification", "SensorNoise", "identify_noise",
           "table_noise", "find_rests"]
