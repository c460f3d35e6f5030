r"""Atomic writing, for every module that writes files.

A file is written to a temporary file in the target folder, then renamed onto
the target with :func:`os.replace`, so that an error or an interruption never
leaves a half-written file: readers see the old file or the complete new one.

* :func:`atomic_path`: a context manager yielding the temporary path;
* :func:`atomic_write_text`, :func:`atomic_write_json`: text and JSON;
* :func:`no_empty_folder_if_refused`: a refused command leaves no empty output folder;
* :func:`dumps_json`, :func:`to_json_builtin`: the JSON text itself (numpy-safe,
  floats that read back exactly).
"""

from __future__ import annotations

import contextlib
import json
import numbers
import os
import tempfile
from pathlib import Path, PurePath

import numpy as np

from graph_calib.errors import InputError
from graph_calib.io.checks import _show


def _umask():
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def regular_target(path):
    """The file a write to ``path`` replaces: ``path`` itself, or the file a symbolic link at ``path`` points to (a
    link is written through, as ``cp`` does, never replaced by a file); InputError when that is a folder or exists
    and is no regular file (a device, a pipe, a socket: the rename of an atomic write would replace the node
    itself, ``/dev/stdout`` or ``/dev/full`` for a user who may).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Path
    """
    path = Path(path)
    if path.is_symlink():
        path = Path(os.path.realpath(path))
    if path.is_dir():
        raise InputError("is a folder, expected a file name", path=path)
    if path.exists() and not path.is_file():
        raise InputError("is not a regular file (a device, a pipe or a socket): name a file to write; the file is "
                         "written whole and then renamed into place", path=path)
    return path


@contextlib.contextmanager
def no_empty_folder_if_refused(folder):
    """Within the block, an :class:`~graph_calib.errors.InputError` removes ``folder`` when the block made it and left
    it empty: a refused command leaves no output folder behind (the error is raised on)."""
    made = not Path(folder).exists()
    try:
        yield
    except InputError:
        if made:
            with contextlib.suppress(OSError):
                Path(folder).rmdir()
        raise


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path next to ``path``; rename it onto ``path`` on success.

    The temporary file lives in the same folder, so the final :func:`os.replace`
    is atomic: readers see either the old file or the complete new one.  If the
    body raises (or is interrupted), the temporary file is removed and ``path``
    is left as it was.

    Parameters
    ----------
    path : str or Path
        Final file path.  Its folder must exist.

    Yields
    ------
    Path
        An empty file in the same folder, to be written (and closed) by the body.

    Raises
    ------
    InputError
        If the folder does not exist or ``path`` is a folder.
    """
    path = regular_target(path)
    folder = path.parent
    if not folder.is_dir():
        raise InputError(f"folder {folder} does not exist", path=path)
    fd, tmp_name = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        mode = (path.stat().st_mode & 0o777) if path.exists() else (0o666 & ~_umask())
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise
    with contextlib.suppress(OSError):  # make the rename durable where the OS allows it
        dir_fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)


def atomic_write_text(path, text, *, encoding="utf-8"):
    """Write ``text`` to ``path`` atomically (see :func:`atomic_path`).

    Parameters
    ----------
    path : str or Path
    text : str
    encoding : str
    """
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding=encoding)


def to_json_builtin(obj):
    """A copy of ``obj`` made of JSON built-in types.

    numpy arrays become (nested) lists, numpy scalars Python numbers, tuples
    lists, paths strings.  Dictionary keys must be strings.

    Raises
    ------
    TypeError
        For anything else.
    """
    if isinstance(obj, dict):
        out = {}
        for k, v in obj.items():
            if not isinstance(k, str):
                raise TypeError(f"JSON object keys must be strings, got {_show(k)}")
            out[k] = to_json_builtin(v)
        return out
    if isinstance(obj, (list, tuple)):
        return [to_json_builtin(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_json_builtin(obj.tolist())
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, numbers.Integral):
        return int(obj)
    if isinstance(obj, numbers.Real):
        return float(obj)
    if isinstance(obj, PurePath):
        return str(obj)
    raise TypeError(f"cannot write {type(obj).__name__} to JSON: {_show(obj)}")


def _is_scalar_json(v):
    return v is None or isinstance(v, (bool, int, float, str))


def _dump(obj, level, indent, allow_nan):
    """JSON text: objects indented, lists of scalars and small flat objects on one line."""
    if isinstance(obj, dict):
        if not obj:
            return "{}"
        if len(obj) <= 4 and all(_is_scalar_json(v) for v in obj.values()):
            return json.dumps(obj, allow_nan=allow_nan)
        pad = " " * (indent * (level + 1))
        items = [f"{pad}{json.dumps(k)}: {_dump(v, level + 1, indent, allow_nan)}" for k, v in obj.items()]
        return "{\n" + ",\n".join(items) + "\n" + " " * (indent * level) + "}"
    if isinstance(obj, list):
        if all(_is_scalar_json(v) for v in obj):
            return json.dumps(obj, allow_nan=allow_nan)
        pad = " " * (indent * (level + 1))
        items = [pad + _dump(v, level + 1, indent, allow_nan) for v in obj]
        return "[\n" + ",\n".join(items) + "\n" + " " * (indent * level) + "]"
    return json.dumps(obj, allow_nan=allow_nan)


def dumps_json(obj, *, indent=2, allow_nan=False):
    """JSON text of ``obj`` (numpy-safe), floats written with ``repr`` so they read back exactly.

    Nested objects are indented; lists of numbers (matrix rows included) and small
    flat objects such as ``{"value": v, "sigma": s}`` stay on one line.

    Parameters
    ----------
    obj : object
        Anything :func:`to_json_builtin` accepts.
    indent : int
    allow_nan : bool
        Whether NaN and infinities may be written (they are not standard JSON; by
        default they raise ``ValueError``).
    """
    return _dump(to_json_builtin(obj), 0, indent, allow_nan) + "\n"


def atomic_write_json(path, obj, *, indent=2, allow_nan=False):
    """Write ``obj`` as JSON to ``path`` atomically; numpy arrays and scalars are accepted.

    Parameters
    ----------
    path : str or Path
    obj : object
        See :func:`dumps_json`.
    indent : int
    allow_nan : bool
        See :func:`dumps_json`.
    """
    text = dumps_json(obj, indent=indent, allow_nan=allow_nan)  # fails before any file exists
    atomic_write_text(path, text)
