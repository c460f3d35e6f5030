"""numba's on-disk kernel cache, kept fresh when a module a kernel depends on changes.

numba checks a cached kernel against its own source file only.  A kernel that calls or inlines kernels of
another module, or reads another module's constants (frozen into its machine code), would keep its old
machine code when only that other module changes: the preintegration kernel (``model/kernel.py``) calls
``sensors/sensor_model.py``'s kernels and inlines ``navigation/rotations.py``'s, and would silently compute
the old model.  :func:`install` puts cache locators first in numba's list that stamp each cached kernel of
a watched package with a hash of the sources it depends on besides its own: a kernel whose dependencies
changed finds its index stale and compiles again (and overwrites it), whatever the files' times say.

A module's dependencies are the modules of the watched packages it imports (every import statement,
``from P import name`` counting ``P.name`` when that is a module, else ``P``), followed on through every
one that itself uses numba; a module that does not is included but not followed (its constants may be frozen into
a kernel, its imports cannot).  Every module of ``graph_calib`` and ``kf_reference`` with a cached kernel
calls :func:`install` before its first kernel is defined (``tests/test_kernel_cache.py`` checks it and
shows a stale kernel is not used).  The sources are read once per process (a few milliseconds).
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

#: The packages whose kernels are watched, and their folders.
PACKAGES = {"graph_calib": Path(__file__).resolve().parent,
            "kf_reference": Path(__file__).resolve().parent.parent / "kf_reference"}

_DIGESTS = {}     # path -> hash of its dependencies' sources (this process)
_IMPORTS = {}     # path -> the files it imports from the watched packages
_INSTALLED = []


def watch(package, folder):
    """Watch the kernels of ``package`` (top-level name) in ``folder`` too (a test's package)."""
    PACKAGES[package] = Path(folder).resolve()


def _file_of(module):
    """The source file of a module of a watched package, or None."""
    top, _, rest = module.partition(".")
    folder = PACKAGES.get(top)
    if folder is None:
        return None
    base = folder.joinpath(*rest.split(".")) if rest else folder
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate.resolve()
    return None


def _module_of(path):
    for top, folder in PACKAGES.items():
        try:
            rel = path.relative_to(folder).with_suffix("")
        except ValueError:
            continue
        parts = [top, *rel.parts]
        return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
    return None


#: An import statement at the start of a line: ``from X import names`` (parenthesised over lines too) or
#: ``import X, Y``; a line of prose that looks like one only adds a dependency (safe).
_IMPORT = re.compile(r"^[ \t]*(?:from[ \t]+([\w.]+)[ \t]+import[ \t]+(\([^)]*\)|[^\n#;]*)|import[ \t]+([^\n#;]*))", re.M)


def _names(text):
    return [n.split()[0] for n in text.strip("() \t\n").replace("\n", " ").split(",") if n.strip()]


def _imports(path):
    """The watched packages' files that ``path`` imports (every import statement of the module, read as text:
    a regular expression, not :mod:`ast`, which would take about 10 ms a module)."""
    if path in _IMPORTS:
        return _IMPORTS[path]
    module = _module_of(path) or ""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = set()
    for base, names, plain in _IMPORT.findall(path.read_text()):
        if plain:
            found.update(_file_of(n) for n in _names(plain))
            continue
        level = len(base) - len(base.lstrip("."))
        if level:
            parts = package.split(".")
            base = ".".join(parts[:len(parts) - level + 1] + ([base.lstrip(".")] if base.lstrip(".") else []))
        subs = [_file_of(f"{base}.{n}") for n in _names(names)]
        found.update(subs)
        if not all(subs):        # a name that is not a module: the package's own ``__init__`` is a dependency
            found.add(_file_of(base))
    found.discard(None)
    found.discard(path)
    _IMPORTS[path] = sorted(found)
    return _IMPORTS[path]


def dependency_digest(py_file):
    """SHA-256 of the sources ``py_file``'s kernels depend on besides its own (module doc), hex."""
    path = Path(py_file).resolve()
    if path not in _DIGESTS:
        seen, todo = set(), [path]
        while todo:
            f = todo.pop()
            for dep in _imports(f):
                if dep not in seen:
                    seen.add(dep)
                    if b"numba" in dep.read_bytes():
                        todo.append(dep)
        h = hashlib.sha256()
        for dep in sorted(seen - {path}):
            h.update(f"{_module_of(dep)}\0".encode() + dep.read_bytes() + b"\0")
        _DIGESTS[path] = h.hexdigest()
    return _DIGESTS[path]


def _watched(py_file):
    try:
        path = Path(py_file).resolve()
    except (OSError, TypeError):
        return False
    return any(path.is_relative_to(folder) for folder in PACKAGES.values())


def _dependent(locator_class):
    """``locator_class`` for the watched packages' files, its source stamp extended by their dependencies."""

    class Dependent(locator_class):
        def get_source_stamp(self):
            return (super().get_source_stamp(), dependency_digest(self._py_file))

        @classmethod
        def from_function(cls, py_func, py_file):
            if not _watched(py_file):
                return None
            return super().from_function(py_func, py_file)

    Dependent.__name__ = Dependent.__qualname__ = f"Dependent{locator_class.__name__.lstrip('_')}"
    return Dependent


def install():
    """Put the dependency-stamped locators first in numba's list (once per process; module doc)."""
    if _INSTALLED:
        return
    from numba.core import caching

    impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl
    names = ("UserProvidedCacheLocator", "InTreeCacheLocator", "UserWideCacheLocator")
    bases = [getattr(caching, n, None) or getattr(caching, "_" + n) for n in names]
    impl._locator_classes[0:0] = [_dependent(b) for b in bases]
    _INSTALLED.append(True)


__all__ = ["PACKAGES", "install", "watch", "dependency_digest"]
