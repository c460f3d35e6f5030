"""Write the table scenarios as bench programs: ``data/programs/<scenario>.toml`` (docs/programs.md).

``PYTHONPATH=. python scripts/scenario_programs.py [--seed 7] [--out data/programs]``

Each file is the scenario's experiment at that seed (its table commands tick for tick and its chamber
profile), so that ``graph-calib simulate --program`` and ``graph-calib predict`` can run it.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from graph_calib.io import atomic_write_text
from graph_calib.simulation import simulate
from graph_calib.simulation.program import program_text, scenario_program

SCENARIOS = ("nav-subrange", "nav-subrange-short")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "data" / "programs"))
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name in SCENARIOS:
        sim = simulate(name, rng=np.random.default_rng(args.seed))
        prog = scenario_program(sim, name=name, description=f"the {name} scenario's experiment at seed {args.seed} "
                                                            f"(scripts/scenario_programs.py)")
        atomic_write_text(out / f"{name}.toml", program_text(prog))
        print(f"{out / (name + '.toml')}: {len(prog.steps)} steps, {prog.duration_s / 3600:.2f} h")


if __name__ == "__main__":
    main()
