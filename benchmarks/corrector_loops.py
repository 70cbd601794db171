"""The capsule's loops with and without a loop predicate, on whatever JAX runs on.

    python benchmarks/corrector_loops.py [--runs 200] [--out FILE]

``lunar-skip-entry``, seed 0, one compiled batch of ``--runs`` runs on one device, compile
apart, best of two calls after a warm-up: the flight's cycles and the corrector's rounds as
``lax.while_loop`` (``loop_kind = "lax"``, the default) against the same loops as masked
``lax.scan`` of their bounds (``"fixed"``: every round runs, no predicate for a GPU to wait on
between rounds). The per-run outcomes of the two are compared (statuses and integers equal,
the largest float difference), and the ratio printed.
"""

import argparse
import dataclasses
import json
import pathlib
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
import gnc_jax as gj  # noqa: E402
from benchmarks._timing import warmed_best_of  # noqa: E402


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=200)
    p.add_argument("--out", default=None)
    args = p.parse_args()
    system = gj.get_system("capsule")
    sim, law = gj.build(gj.load_scenario("lunar-skip-entry"))
    idx = jnp.arange(args.runs)
    rows, outs = {}, {}
    for kind in ("lax", "fixed"):
        s = dataclasses.replace(sim, loop_kind=kind)
        fn = jax.jit(jax.vmap(lambda i, s=s: system.simulate(s, law, gj.run_key(0, i))[0]))
        t0 = time.perf_counter()
        compiled = fn.lower(idx).compile()
        compile_s = time.perf_counter() - t0
        wall = warmed_best_of(lambda c=compiled: c(idx), 2)
        outs[kind] = {k: np.asarray(v) for k, v in compiled(idx)._asdict().items()}
        rows[kind] = dict(compile_s=round(compile_s, 2), wall_s=round(wall, 4))
        print(f"{kind:6s} compile {compile_s:6.1f} s, {args.runs} runs {wall:8.3f} s", flush=True)
    a, b = outs["lax"], outs["fixed"]
    ints_equal = all(
        np.array_equal(a[k], b[k]) for k in a if not np.issubdtype(a[k].dtype, np.floating)
    )
    float_diff = max(
        float(np.nanmax(np.abs(a[k] - b[k]))) for k in a if np.issubdtype(a[k].dtype, np.floating)
    )
    ratio = rows["fixed"]["wall_s"] / rows["lax"]["wall_s"]
    print(
        f"fixed / lax: {ratio:.2f}; statuses and integers equal: {ints_equal}; "
        f"largest float difference {float_diff:.3g}"
    )
    result = dict(
        backend=jax.default_backend(), device=jax.devices()[0].device_kind, runs=args.runs,
        rows=rows, ratio=round(ratio, 3), ints_equal=ints_equal, float_diff=float_diff,
    )  # fmt: skip
    if args.out:
        pathlib.Path(args.out).write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
