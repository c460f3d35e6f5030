r"""The import formats by name: a format is one module of :mod:`graph_calib.importers` and one entry here.

Each format module defines ``FORMAT``, an :class:`ImportFormat`: its name, the
inputs it takes, the options only it takes (:class:`Option`), an example command
and ``read(inputs, options) -> Experiment``.  ``graph-calib import`` builds its
options and its help from :data:`FORMATS` and calls ``read``; it has no branch of
its own per format.  Adding a format: write the module with its ``FORMAT`` and add
the module's name to :data:`FORMAT_MODULES`.

``options`` handed to ``read`` is a dict of the options given on the command line
(by their ``dest``, absent when not given) and the common ones, already in SI:
``latitude_rad``, ``gravity_mps2``, ``temperature_degC``, ``imu_id``,
``description``.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Callable

#: Modules of :mod:`graph_calib.importers` holding a ``FORMAT``, in the order the command line lists them.
FORMAT_MODULES = ("xsens", "mpu6050", "csv", "rosbag", "ulog")


@dataclass(frozen=True)
class Option:
    """One command-line option a format takes (``argparse.add_argument`` keyword arguments in ``kwargs``)."""

    flag: str
    help: str
    kwargs: dict = field(default_factory=dict)

    @property
    def dest(self):
        """The option's name in ``options``: ``--rate-hz`` -> ``rate_hz``."""
        return self.kwargs.get("dest") or self.flag.lstrip("-").replace("-", "_")


@dataclass(frozen=True)
class ImportFormat:
    """One import format.

    Attributes
    ----------
    name : str
        The FORMAT word of ``graph-calib import FORMAT``.
    inputs : tuple of str
        Placeholder of each input (``("ACC_FILE", "GYRO_FILE")``); the count is enforced.
    summary : str
        One line: what the format reads.
    example : str
        A command that imports a file of this format.
    read : callable
        ``read(inputs: list[Path], options: dict) -> Experiment``; raises InputError on bad input.
    options : tuple of Option
        Options only this format takes (an option several formats share is declared by each, alike).
    notes : callable or None
        ``notes(experiment, options) -> list[str]``: lines printed after the summary.
    """

    name: str
    inputs: tuple
    summary: str
    example: str
    read: Callable
    options: tuple = ()
    notes: Callable | None = None


def _load():
    formats = {}
    for module in FORMAT_MODULES:
        fmt = importlib.import_module(f"graph_calib.importers.{module}").FORMAT
        if fmt.name in formats:
            raise RuntimeError(f"import format {fmt.name!r} registered twice")
        formats[fmt.name] = fmt
    return formats


_FORMATS = None


def formats():
    """``{name: ImportFormat}`` of every registered format, in :data:`FORMAT_MODULES` order."""
    global _FORMATS
    if _FORMATS is None:
        _FORMATS = _load()
    return _FORMATS


def format_named(name):
    """The :class:`ImportFormat` called ``name`` (``KeyError`` naming the known ones)."""
    known = formats()
    if name not in known:
        raise KeyError(f"unknown import format {name!r}; known: {', '.join(known)}")
    return known[name]


__all__ = ["FORMAT_MODULES", "Option", "ImportFormat", "formats", "format_named"]
