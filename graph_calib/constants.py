"""Physical constants and conversions used only at the edges (reports, printing).

Inside the code everything is SI and radians; multiply by a ``X_TO_Y`` constant
to convert a value in unit X into unit Y.
"""

import numpy as np

#: Earth rotation rate, rad/s (WGS-84).
OMEGA_E = 7.292115e-5

#: Standard gravity, m/s^2 (used only to express micro-g).
G0 = 9.80665

DEG_TO_RAD = np.pi / 180.0
RAD_TO_DEG = 180.0 / np.pi
#: deg/h to rad/s.
DH_TO_RS = DEG_TO_RAD / 3600.0
#: rad/s to deg/h.
RS_TO_DH = 1.0 / DH_TO_RS
#: deg/sqrt(h) to rad/sqrt(s) (angle random walk).
DSH_TO_RSS = DEG_TO_RAD / 60.0
#: m/s^2 to micro-g.
MPS2_TO_UG = 1e6 / G0
UG_TO_MPS2 = 1.0 / MPS2_TO_UG
#: dimensionless to ppm.
TO_PPM = 1e6
ARCSEC_TO_RAD = DEG_TO_RAD / 3600.0
RAD_TO_ARCSEC = 1.0 / ARCSEC_TO_RAD


def omega_ie_n(latitude_rad):
    """Earth rate in the local level (ENU) frame, rad/s, shape (3,)."""
    return OMEGA_E * np.array([0.0, np.cos(latitude_rad), np.sin(latitude_rad)])
