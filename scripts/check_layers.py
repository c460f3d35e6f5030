"""Check the package's layers (docs/architecture.md): every import points down, no circle, no module too long,
and the reference filter independent of the batch solvers.

Usage: ``python scripts/check_layers.py [ROOT]`` (exit 1 and one line per breach; ROOT: the checkout, by
default this one).  Reads every ``.py`` file of ``graph_calib/`` and ``kf_reference/`` with :mod:`ast`;
imports inside functions count like the others, so a function-local import cannot hide an upward arrow.
Also run by ``tests/test_architecture.py``.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Layer of each module (longest matching prefix wins), as drawn in docs/architecture.md.
LAYERS = {
    "graph_calib.constants": 0, "graph_calib.errors": 0, "graph_calib.navigation.rotations": 0, "graph_calib.records.experiment": 0,
    "graph_calib.kernel_cache": 0,           # numba's cache stamped with the kernels' dependencies: imports nothing of the package
    "graph_calib": 0,                         # the package root: conventions docstring and version only
    "graph_calib.sensors.effects": 1,
    "graph_calib.sensors.params": 2, "graph_calib.sensors.sensor_model": 2,
    "graph_calib.solvers.registry": 2,        # solver names and the dispatch: imports nothing of the package
    "graph_calib.io": 3, "graph_calib.navigation.strapdown": 3, "graph_calib.navigation.static_detection": 3, "graph_calib.navigation.alignment": 3,
    "graph_calib.model": 4, "graph_calib.records.plausibility": 4, "graph_calib.noise": 4,
    "graph_calib.options": 5, "graph_calib.records.problem": 5, "graph_calib.records.saturation": 5, "graph_calib.compensation.calibration": 5, "graph_calib.records.grade_choice": 5,
    "graph_calib.solvers": 6,
    "graph_calib.solvers.factor_graph": 7, "graph_calib.solvers.joint": 7, "kf_reference": 7,
    "graph_calib.calibrate": 8, "graph_calib.diagnosis": 8, "graph_calib.stitching": 8, "graph_calib.evaluation": 8,
    "graph_calib.design.prediction": 8, "graph_calib.design.program_search": 8,
    "graph_calib.design.procedures": 8, "graph_calib.design.comparison": 8, "graph_calib.design.comparison_check": 8,
    "graph_calib.simulation": 8, "graph_calib.importers": 8, "graph_calib.compensation": 8,
    "graph_calib.campaign.warmup": 8, "graph_calib.evaluation.imu_tk": 8,
    "graph_calib.reports": 9,
    "graph_calib.campaign": 10,
    "graph_calib.commands": 11, "graph_calib.cli": 11,
}

#: Imports forbidden although the layers allow them: the reference filter is an independent check of the batch
#: solvers, so nothing of ``kf_reference`` may import the factor graph or the joint solver (importer prefix ->
#: forbidden target prefixes).
FORBIDDEN = {
    "kf_reference": ("graph_calib.solvers.factor_graph", "graph_calib.solvers.joint"),
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


def _within(module, prefix):
    return module == prefix or module.startswith(prefix + ".")


def module_name(path, root=None):
    root = ROOT if root is None else root
    rel = path.relative_to(root).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def imports_of(path, module, root=None):
    """``[(imported module, line)]`` of every import in ``path`` (relative imports resolved)."""
    root = ROOT if root is None else root
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
                if layer(sub) is not None and (root / Path(*sub.split("."))).exists() or \
                        (root / Path(*sub.split("."))).with_suffix(".py").exists():
                    out.append((sub, node.lineno))
    return out


def check(root=None):
    """Breaches of the checkout at ``root`` (default: this one), one line each."""
    root = ROOT if root is None else Path(root)
    problems = []
    modules = {}
    for top in ("graph_calib", "kf_reference"):
        for path in sorted((root / top).rglob("*.py")):
            modules[module_name(path, root)] = path
    graph = {}
    for module, path in modules.items():
        mine = layer(module)
        n_lines = len(path.read_text().splitlines())
        if n_lines > MAX_LINES and module not in LONG_ALLOWED:
            problems.append(f"{path.relative_to(root)}: {n_lines} lines (at most {MAX_LINES})")
        graph[module] = set()
        forbidden = [t for importer, ts in FORBIDDEN.items() if _within(module, importer) for t in ts]
        for target, line in imports_of(path, module, root):
            bad = next((t for t in forbidden if _within(target, t)), None)
            if bad is not None:
                problems.append(f"{path.relative_to(root)}:{line}: {module} imports {target}: the reference filter "
                                f"must not depend on {bad} (docs/architecture.md)")
            theirs = layer(target)
            if theirs is None or target == module:
                continue
            if theirs > mine:
                problems.append(f"{path.relative_to(root)}:{line}: layer {mine} imports {target} (layer {theirs})")
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


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    problems = check(Path(argv[0]) if argv else None)
    for p in problems:
        print(p)
    print(f"{len(problems)} breach(es) of docs/architecture.md" if problems else "layers as drawn: no upward "
          "import, no circle, no module too long")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
