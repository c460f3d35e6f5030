r"""A Ferraris-style hand-held session: six static faces, then a full turn about each body axis.

After Ferraris et al. (Sensors and Materials, 1995): the unit rests on each of its six faces (each
body axis up, then down), then is turned by hand once round each body axis, 360 deg, the axis held
horizontal so that gravity sweeps the plane of the other two and the rest at the end shows how far
the gyros integrated.  Every move is a :class:`~graph_calib.simulation.handheld.HandheldMotion` turn
(a smooth step about one body axis); the faces are reached by the shortest turn from the previous
attitude.

>>> motion, turns = ferraris_motion(100.0, rng=np.random.default_rng(1))    # doctest: +SKIP
"""

from __future__ import annotations

import numpy as np

from graph_calib.navigation.rotations import exp_so3, log_so3
from graph_calib.simulation.handheld import HandheldMotion

#: The six faces: the body axis that points up, in order.
FACES = ((0, 0, 1), (0, 0, -1), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0))
#: For each body axis turned round, the face the unit rests on meanwhile (an axis across it is up).
ROTATION_FACES = {0: (0, 0, 1), 1: (1, 0, 0), 2: (0, 1, 0)}
#: The same with the turns guided (imucal's guide): the axis turned round is up, the unit slid flat on the surface.
GUIDED_ROTATION_FACES = {0: (1, 0, 0), 1: (0, 1, 0), 2: (0, 0, 1)}


def _rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def face_attitude(up_b, heading_rad):
    """``C_nb`` with the body axis ``up_b`` pointing up and a heading, shape (3, 3)."""
    u = np.asarray(up_b, dtype=float)
    # the rotation taking u to the level frame's up, then a turn about up
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(u, z)
    s, c = np.linalg.norm(axis), float(u @ z)
    if s < 1e-12:
        C = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    else:
        C = exp_so3(axis / s * np.arctan2(s, c))
    return _rot_z(heading_rad) @ C


def _length(rng, spec):
    """A length in s: ``spec`` itself when a number, else drawn uniformly from the range ``(lo, hi)``."""
    if np.ndim(spec) == 0:
        return float(spec)
    lo, hi = (float(v) for v in spec)
    return lo if hi == lo else float(rng.uniform(lo, hi))


def ferraris_motion(rate_hz, *, rng, initial_static_s=20.0, face_s=10.0, turn_s=(1.5, 2.5),
                    rotation_s=(3.0, 5.0), rest_s=5.0, guided=False):
    """The Ferraris-style programme as a hand-held motion.

    Parameters
    ----------
    rate_hz : float
    rng : numpy.random.Generator
        Headings and the lengths of the turns.
    initial_static_s : float
        Rest on the first face before anything moves, s; 0: the record starts in motion (the hand
        turning the unit onto its first face from a random attitude, then ``face_s`` on it).
    face_s : float or (float, float)
        Rest on each face, s (a range: drawn per face, as a hand holds it 0.5-1.5 s).
    turn_s : (float, float)
        Range of a turn's length between faces, s.
    rotation_s : (float, float)
        Range of a full turn's length, s.
    rest_s : float or (float, float)
        Rest before and after each full turn, s (a range: drawn per rest).
    guided : bool
        Each full turn about the body axis that is up, the unit slid flat on a level surface and back to its
        start (imucal's guide: pressed against a box before and after), instead of about a horizontal axis.
        The same draws either way.

    Returns
    -------
    motion : HandheldMotion
    rotations : tuple of int
        Index (among the motion's turns) of each full turn about a body axis x, y, z.
    """
    C_first = face_attitude(FACES[0], rng.uniform(0.0, 2.0 * np.pi))
    in_motion = initial_static_s <= 0
    # starting in motion: from a random attitude 60-120 deg away from the first face
    C_start = C_first @ exp_so3(_unit(rng.normal(size=3)) * np.radians(rng.uniform(60.0, 120.0))) \
        if in_motion else C_first
    motion = HandheldMotion(rate_hz, C_start)
    n_turns = 0

    def go(C_target, seconds):
        nonlocal n_turns
        motion.turn(log_so3(motion.attitude_now.T @ C_target), seconds)
        n_turns += 1

    if in_motion:
        go(C_first, rng.uniform(*turn_s))
        motion.hold(_length(rng, face_s))
    else:
        motion.hold(initial_static_s)

    for up in FACES[1:]:
        go(face_attitude(up, rng.uniform(0.0, 2.0 * np.pi)), rng.uniform(*turn_s))
        motion.hold(_length(rng, face_s))
    rotations = []
    for axis in range(3):
        faces = GUIDED_ROTATION_FACES if guided else ROTATION_FACES
        go(face_attitude(faces[axis], rng.uniform(0.0, 2.0 * np.pi)), rng.uniform(*turn_s))
        motion.hold(_length(rng, rest_s))
        phi = np.zeros(3)
        phi[axis] = 2.0 * np.pi * (1.0 if rng.uniform() < 0.5 else -1.0)
        motion.turn(phi, rng.uniform(*rotation_s))
        rotations.append(n_turns)
        n_turns += 1
        motion.hold(_length(rng, rest_s))
    return motion, tuple(rotations)


def _unit(v):
    return v / np.linalg.norm(v)


__all__ = ["FACES", "ROTATION_FACES", "GUIDED_ROTATION_FACES", "face_attitude", "ferraris_motion"]
