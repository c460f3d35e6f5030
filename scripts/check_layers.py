"""Check the package's layers (docs/architecture.md): every import points down, no circle, no module too long.

Usage: ``python scripts/check_layers.py`` (exit 1 and one line per breach).  Reads every ``.py`` file of
``graph_calib/`` and ``kf_reference/`` with :mod:`ast`; imports inside functions count like the others, so a
function-local import cannot hide an upward arrow.  Also run by ``tests/test_architecture.py``.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Layer of each module (longest matching prefix wins), as drawn in docs/architecture.md.
LAYERS = {
    "graph_calib.constants": 0, "graph_calib.errors": 0, "graph_calib.navigation.rotations": 0, "graph_calib.records.experiment": 0,
    "graph_calib": 0,                         # the package root: conventions docstring and version only
    "graph_calib.sensors.effects": 1,
    "graph_calib.sensors.params": 2, "graph_calib.sensors.sensor_model": 2,
    "graph_calib.io": 3, "graph_calib.navigation.strapdown": 3, "graph_calib.navigation.static_detection": 3, "graph_calib.navigation.alignment": 3,
    "graph_calib.model": 4, "graph_calib.records.plausibility": 4, "graph_calib.noise": 4,
    "graph_calib.options": 5, "graph_calib.records.problem": 5, "graph_calib.compensation.calibration": 5, "graph_calib.records.grade_choice": 5,
    "graph_calib.solvers": 6,
    "graph_calib.solvers.factor_graph": 7, "graph_calib.solvers.joint": 7, "kf_reference": 7,
    "graph_calib.calibrate": 8, "graph_calib.diagnosis": 8, "graph_calib.stitching": 8, "graph_calib.evaluation.validation": 8,
    "graph_calib.design.prediction": 8, "graph_calib.design.program_search": 8,
    "graph_calib.simulation": 8, "graph_calib.importers": 8, "graph_calib.compensation": 8,
    "graph_calib.campaign.warmup": 8, "graph_calib.evaluation.imu_tk": 8,
    "graph_calib.reports": 9,
    "graph_calib.campaign": 10,
    "graph_calib.commands": 11, "graph_calib.cli": 11,
}

#: Longest module allowed, lines (docs/architecture.md; the compiled kernel is the one exception).
MAX_LINES = 620
LONG_ALLOWED = {"graph_calib.model.kernel"}


def layer(module):
    """Layer of a module name, or None outside the package."""
    best = None
    for prefix, lay in LAYERS.items():
        if module == prefix or module.startswith(prefix + "."):
            if best is None or len(prefix) > len(best[0]):
                best = (prefix, lay)
    return None if best is None else best[1]


def module_name(path):
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def imports_of(path, module):
    """``[(imported module, line)]`` of every import in ``path`` (relative imports resolved)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.extend((a.name, node.lineno) for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([base] if base else []))
            out.append((base, node.lineno))
            # `from graph_calib import io` imports the submodule graph_calib.io
            for a in node.names:
                sub = f"{base}.{a.name}"
                if layer(sub) is not None and (ROOT / Path(*sub.split("."))).exists() or \
                        (ROOT / Path(*sub.split("."))).with_suffix(".py").exists():
                    out.append((sub, node.lineno))
    return out


def check():
    """Breaches, one line each."""
    problems = []
    modules = {}
    for top in ("graph_calib", "kf_reference"):
        for path in sorted((ROOT / top).rglob("*.py")):
            modules[module_name(path)] = path
    graph = {}
    for module, path in modules.items():
        mine = layer(module)
        n_lines = len(path.read_text().splitlines())
        if n_lines > MAX_LINES and module not in LONG_ALLOWED:
            problems.append(f"{path.relative_to(ROOT)}: {n_lines} lines (at most {MAX_LINES})")
        graph[module] = set()
        for target, line in imports_of(path, module):
            theirs = layer(target)
            if theirs is None or target == module:
                continue
            if theirs > mine:
                problems.append(f"{path.relative_to(ROOT)}:{line}: layer {mine} imports {target} (layer {theirs})")
            if target in modules and not module.startswith(target + "."):
                graph[module].add(target)
    # circles between modules (a package's __init__ importing its own submodules is not one)
    state = {}

    def visit(m, stack):
        state[m] = 1
        for t in sorted(graph.get(m, ())):
            if t.startswith(m + "."):
                continue
            if state.get(t) == 1:
                cyc = stack[stack.index(t):] + [t] if t in stack else [m, t]
                problems.append("import circle: " + " -> ".join(cyc))
            elif state.get(t) is None:
                visit(t, stack + [t])
        state[m] = 2

    for m in sorted(graph):
        if state.get(m) is None:
            visit(m, [m])
    return problems


def main():
    problems = check()
    for p in problems:
        print(p)
    print(f"{len(problems)} breach(es) of docs/architecture.md" if problems else "layers as drawn: no upward "
          "import, no circle, no module too long")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
