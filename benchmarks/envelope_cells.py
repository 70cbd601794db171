"""An envelope's cells one after another against one batch per program, on JAX's default
backend.

    python benchmarks/envelope_cells.py FILE

``bennu-apn`` over ``guidance.apn.n0=4:10:4`` at 500 runs per cell and ``deep-impact-los`` over
``guidance.los.k1=3:6:8`` at 5,000, seed 0, each through ``gj.envelope`` with
``batch_cells=False`` and ``True``: the envelope's wall time, the compile time its cells report
and the rest (the runs), the failed runs per cell. Results: ``FILE`` (JSON) and one line each.
"""

import json
import os
import sys
import time

sys.path.insert(0, os.getcwd())
import jax  # noqa: E402

import gnc_jax as gj  # noqa: E402

GRIDS = [
    ("bennu-apn", ["guidance.apn.n0=4:10:4"], 500),
    ("deep-impact-los", ["guidance.los.k1=3:6:8"], 5000),
]


def main(out: str) -> None:
    rows = []
    for name, grid, runs in GRIDS:
        sc = gj.load_scenario(name)
        for batch in (False, True):
            t = time.perf_counter()
            env = gj.envelope(sc, grid, runs=runs, seed=0, progress=False, batch_cells=batch)
            total = time.perf_counter() - t
            comp = sum(c.get("compile_s") or 0 for c in env.cells)
            r = dict(
                scenario=name, grid=grid, runs=runs, cells=len(env.cells), batched=batch,
                total_s=round(total, 2), compile_s=round(comp, 2), run_s=round(total - comp, 3),
                failed=[c.get("failed") for c in env.cells],
            )  # fmt: skip
            print(json.dumps(r), flush=True)
            rows.append(r)
    with open(out, "w") as f:
        json.dump(dict(device=jax.devices()[0].device_kind, rows=rows), f, indent=1)


if __name__ == "__main__":
    main(sys.argv[1])
