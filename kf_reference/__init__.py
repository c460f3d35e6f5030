r"""The reference square-root Kalman filter of graph-calib.

An iterated, linearised square-root filter over keyframes that consumes the
shared model's factors (:mod:`graph_calib.model`) and must agree with the factor
graph (:mod:`graph_calib.factor_graph`) on every parameter.  See
``docs/kf_reference.md``.

>>> from kf_reference import calibrate, to_result          # doctest: +SKIP
>>> fr = calibrate(model, q_nb0=q_nb0)                       # doctest: +SKIP
>>> result = to_result(fr, model)                            # doctest: +SKIP
"""

from kf_reference.calibrate import (  # noqa: F401  (public)
    ENCODER,
    GRAVITY,
    KIND_NAMES,
    FilterResult,
    PassInfo,
    calibrate,
    filter_pass,
    initial_attitudes,
    to_result,
)

__all__ = ["calibrate", "to_result", "filter_pass", "initial_attitudes", "FilterResult", "PassInfo", "GRAVITY", "ENCODER", "KIND_NAMES"]
