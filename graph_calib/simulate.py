"""The simulator's public entry points (a short alias of :mod:`graph_calib.simulation`).

>>> from graph_calib.simulate import simulate, scenario_names, write_simulation
"""

from graph_calib.simulation import *  # noqa: F401,F403
from graph_calib.simulation import __all__  # noqa: F401
