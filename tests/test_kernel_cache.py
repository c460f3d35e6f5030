"""numba's kernel cache kept fresh (graph_calib/kernel_cache.py): a kernel whose dependency changed is compiled
again, and every module with cached kernels stamps them with their dependencies."""

import json
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

from graph_calib import kernel_cache

ROOT = Path(__file__).resolve().parents[1]

_DEP = textwrap.dedent("""\
    import numba


    @numba.njit(cache=True, inline="always")
    def value():
        return {value}
    """)

_USER = textwrap.dedent("""\
    import numba

    from graph_calib import kernel_cache

    kernel_cache.install()

    from {package}.dep import value


    @numba.njit(cache=True)
    def kernel():
        return value() + 0.0
    """)

_RUN = textwrap.dedent("""\
    import json, sys
    from graph_calib import kernel_cache
    kernel_cache.watch("watched", sys.argv[1] + "/watched")       # the other package is left as numba has it
    from watched.user import kernel as a
    from unwatched.user import kernel as b
    out = {}
    for name, k in (("watched", a), ("unwatched", b)):
        v = k()
        out[name] = [v, k.stats.cache_hits.get(k.signatures[0], 0) > 0]
    print(json.dumps(out))
    """)


def _package(folder, name, value):
    pkg = folder / name
    pkg.mkdir(exist_ok=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "dep.py").write_text(_DEP.format(value=value))
    (pkg / "user.py").write_text(_USER.format(package=name))


def _run(folder):
    env = {**os.environ, "PYTHONPATH": f"{folder}:{ROOT}"}
    proc = subprocess.run([sys.executable, "-c", _RUN, str(folder)], env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_a_kernel_whose_inlined_dependency_changed_is_compiled_again(tmp_path):
    for name in ("watched", "unwatched"):
        _package(tmp_path, name, 1.0)
    first = _run(tmp_path)
    assert first == {"watched": [1.0, False], "unwatched": [1.0, False]}        # compiled, written
    again = _run(tmp_path)
    assert again == {"watched": [1.0, True], "unwatched": [1.0, True]}          # a fresh cache is used
    for name in ("watched", "unwatched"):
        (tmp_path / name / "dep.py").write_text(_DEP.format(value=2.0))          # only the dependency edited
    edited = _run(tmp_path)
    assert edited["watched"] == [2.0, False]                                     # compiled again: the new code
    # numba alone keeps the old machine code (the hazard this module removes): the test can see it
    assert edited["unwatched"] == [1.0, True]


def test_every_module_with_cached_kernels_installs_the_stamp_before_its_first_kernel():
    found = []
    for path in sorted([*ROOT.joinpath("graph_calib").rglob("*.py"), *ROOT.joinpath("kf_reference").rglob("*.py")]):
        text = path.read_text()
        kernel = re.search(r"^@numba\.njit\(.*cache=True", text, re.M)
        if kernel is None:
            continue
        found.append(path.name)
        install = text.find("\nkernel_cache.install()")
        assert 0 <= install < kernel.start(), f"{path.relative_to(ROOT)}: kernel_cache.install() before its first kernel"
    assert {"kernel.py", "sensor_model.py", "rotations.py", "sqrt_kf.py"} <= set(found)


def test_the_preintegration_kernel_depends_on_the_sensor_model_and_the_rotations():
    files = {kernel_cache._module_of(f) for f in kernel_cache._imports(ROOT / "graph_calib" / "model" / "kernel.py")}
    assert {"graph_calib.sensors.sensor_model", "graph_calib.navigation.rotations"} <= files
    digest = kernel_cache.dependency_digest(ROOT / "graph_calib" / "model" / "kernel.py")
    assert re.fullmatch(r"[0-9a-f]{64}", digest)
    assert digest != kernel_cache.dependency_digest(ROOT / "graph_calib" / "navigation" / "strapdown.py")
