"""Output paths checked before any work starts (exit 2 with one line naming the option), in every command.

A command that finds out only after an hour of work that ``--out`` names a file
where it writes a folder (or the reverse) wastes the hour; each command calls
:func:`output_file` or :func:`output_folder` first.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from graph_calib.errors import InputError
from graph_calib.io.atomic import regular_target


def _parent_ok(path, option):
    """The nearest existing ancestor of ``path`` is a folder that takes new entries (so the missing ones can be
    created)."""
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise InputError(f"cannot be created: {parent} is a file, not a folder", path=path, dataset=option)
            _writable(parent, path, option)
            return


def _writable(folder, path, option):
    """A file can be made in ``folder`` (tried: permission bits do not tell for every user, root among them)."""
    try:
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".graph-calib-probe-"):
            pass
    except OSError as exc:
        raise InputError(f"cannot be written: {folder} takes no new files ({exc.strerror or exc})", path=path,
                         dataset=option) from None


def output_file(path, *, option="--out", suffixes=None):
    """``path`` as a Path where a file can be written: not a folder, its parents creatable, a known suffix.

    Parameters
    ----------
    suffixes : sequence of str, optional
        Suffixes accepted (``(".yaml", ".yml")``); another one is refused naming them.
    """
    path = Path(path)
    if path.is_dir():
        raise InputError("is a folder; it names the file to write", path=path, dataset=option)
    try:
        path = regular_target(path)
    except InputError as exc:
        raise InputError(exc.reason, path=exc.path, dataset=option) from None
    if suffixes and path.suffix.lower() not in suffixes:
        raise InputError(f"ends in {path.suffix or 'no suffix'!r}; this file is written as "
                         f"{' or '.join(suffixes)}", path=path, dataset=option)
    _parent_ok(path, option)
    return path


def output_folder(path, *, option="--out"):
    """``path`` as a Path where a folder can be written: not an existing file, its parents creatable."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError("is a file; it names the folder to write into", path=path, dataset=option)
    if path.is_dir():
        _writable(path, path, option)
    else:
        _parent_ok(path, option)
    return path


def make_output_folder(path, *, option="--out"):
    """Create the output folder ``path`` (checked by :func:`output_folder` first); one clear error if it cannot be."""
    path = output_folder(path, option=option)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the output folder: {exc}", path=path, dataset=option) from None
    return path


def earlier_results(folder, written, *, solver_names):
    """The result files in ``folder`` that this run did not write (``written``: names): a solver's ``<name>.json`` or
    ``comparison.json`` of an earlier run, which a reader would take for this one's; sorted names."""
    return sorted(p.name for p in Path(folder).iterdir() if p.name not in written and p.suffix == ".json"
                  and (p.stem in solver_names or p.name == "comparison.json"))


__all__ = ["output_file", "output_folder", "make_output_folder", "earlier_results"]
