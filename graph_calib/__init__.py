r"""graph-calib: thermal calibration of inertial measurement units on a turntable.

One model of the sensors and of the two measurements of the method (gravity and
encoder attitude) is written once, in :mod:`graph_calib.model`, and fed to two
solvers: a GTSAM factor graph (:mod:`graph_calib.solvers.factor_graph`) and the reference
square-root Kalman filter (:mod:`kf_reference`).

Conventions (they follow ``shared/spec/model.md`` to the letter)
----------------------------------------------------------------
Frames
    ``n``  local level, East-North-Up, fixed to the Earth at the bench;
           gravity is ``g_n = [0, 0, -g]``, a body at rest feels ``[0, 0, +g]``.
    ``b``  instrument frame, defined by the accelerometer triad.
    ``f``  faceplate of the turntable; its attitude in ``n`` comes from the encoders.
    ``i``  inertial.

Names
    A vector in frame ``a`` is ``name_a`` (``f_b``, ``omega_ie_n``); an angular
    rate of frame ``b`` against ``a`` expressed in ``c`` is ``omega_ab_c``; a
    rotation matrix mapping frame-``b`` coordinates into frame ``a`` is ``C_ab``
    (``v_a = C_ab @ v_b``); its quaternion, scalar first ``[w, x, y, z]`` with the
    Hamilton product, is ``q_ab``.  ``Exp(a)`` is the rotation by the rotation
    vector ``a``, ``I + [a x]`` to first order.

Units
    SI and radians everywhere inside the code and in every file; degrees Celsius
    for temperature.  Degrees, deg/h, ppm and micro-g appear only at the edges
    (reports, plots, printing), through the named constants of
    :mod:`graph_calib.constants`.

Attitude errors
    Both solvers perturb keyframe rotations on the right,
    ``C_nb = C_nb_hat @ Exp(delta_b)`` (GTSAM's ``Rot3.retract``); the Kalman
    filter's attitude-error states are the same ``delta_b`` (the level-frame
    error is ``phi_n = C_nb_hat @ delta_b``).

Earth rate
    Never neglected: gyros measure ``omega_ib_b``; the level frame turns with
    ``omega_ie_n = OMEGA_E * [0, cos(lat), sin(lat)]``.
"""

__version__ = "0.1.0"

import os as _os
import sys as _sys

# Large arrays in ordinary pages, not transparent huge pages.  NumPy asks the kernel for huge pages (madvise) on
# every array of 4 MiB or more; where the kernel honours that (the THP policy "madvise", a common default) each
# of the solvers' large short-lived temporaries is faulted in and zeroed 2 MiB at a time, and a 3 h loop job
# spent a third of its CPU time in the kernel (docs/performance.md, "One 3 h job of the first wave").  The
# variable is read when numpy is imported: set here for this process's children (a campaign's Dask workers)
# and, numpy being loaded already, switched in this one too.  A value the user set is kept.
if "NUMPY_MADVISE_HUGEPAGE" not in _os.environ:
    _os.environ["NUMPY_MADVISE_HUGEPAGE"] = "0"
    if "numpy" in _sys.modules:
        _toggle = getattr(getattr(_sys.modules["numpy"], "_core", None), "multiarray", None)
        if hasattr(_toggle, "_set_madvise_hugepage"):
            _toggle._set_madvise_hugepage(False)

from graph_calib.errors import InputError  # noqa: F401  (public)
