"""gnc_jax on a GPU, with the suite's numba peer on the same machine's CPU cores as the baseline.

    python -m benchmarks --device gpu [--quick]        # results_gpu.json, RESULTS_GPU.md
    python benchmarks/gpu.py [--device gpu] [--quick] [--sizes 10000 100000 1000000]

``deep-impact-los`` studies through ``gj.run_study(..., device=...)`` at 10^4, 10^5 and 10^6
runs (the planner's default chunks: on a GPU as many runs as fit its memory), each called twice:
the first call's compile time is reported apart, the wall is the better of the two calls after
compilation (``run_study`` returns numpy outcomes: every run has finished). The GPU's peak memory
is ``memory_stats()['peak_bytes_in_use']`` after each study (the process's running peak; the
sizes grow, so each study's figure is its own). In the same process, before the GPU studies:
the baseline, the suite's numba peer (``benchmarks/peers/numba_impactor.py``, its kernel drawing
its own normals, one thread per core) at 32,000 runs, best of two calls after its compilation,
and gnc_jax on the CPU's host devices (``device="cpu"``) at the same size. Every row's ratio is
its throughput over the numba peer's.
"""

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = "deep-impact-los"
BASELINE_RUNS = 32_000


def _peak_mb(device) -> float | None:
    try:
        stats = device.memory_stats() or {}
    except Exception:  # a platform without memory statistics (the CPU)
        return None
    peak = stats.get("peak_bytes_in_use")
    return None if peak is None else peak / 1e6


def _study_row(gj, scenario, runs, device, label, baseline_per_s=None) -> dict:
    first = gj.run_study(scenario, runs=runs, seed=0, progress=False, device=device)
    second = gj.run_study(scenario, runs=runs, seed=0, progress=False, device=device)
    wall = min(first.wall_s, second.wall_s)
    from gnc_jax.backend import select

    row = dict(
        name=label,
        runs=runs,
        chunk=second.chunk_size,
        compile_s=round(first.compile_s, 2),
        wall_s=round(wall, 4),
        per_s=round(runs / wall, 1),
        peak_mb=_peak_mb(select(device).devices[0]),
        failed=second.summary()["failed"],
    )
    if baseline_per_s:
        row["ratio_vs_numba"] = round(row["per_s"] / baseline_per_s, 2)
    return row


def _numba_row(scenario, runs) -> dict:
    """The numba peer drawing its own normals: compile call, then the best of two."""
    sys.path.insert(0, str(ROOT))
    from benchmarks.peers import numba_impactor as peer

    if peer.numba is None:
        return dict(name="numba peer (own draws)", skipped="numba not installed (bench extra)")
    t0 = time.perf_counter()
    peer.run_own(scenario, 16)
    compile_s = time.perf_counter() - t0
    timer = peer._own_timer(scenario, runs)
    wall = min(timer()[0] for _ in range(2))
    return dict(
        name=f"numba peer (own draws, {peer.numba.get_num_threads()} threads)",
        runs=runs,
        compile_s=round(compile_s, 2),
        wall_s=round(wall, 4),
        per_s=round(runs / wall, 1),
    )


def _guarded(row, name) -> dict:
    """A baseline row, or the one line saying why it failed (the device rows still run)."""
    try:
        return row()
    except Exception as e:  # a benchmark reports a failed baseline instead of stopping
        return dict(name=name, skipped=f"{type(e).__name__}: {str(e).splitlines()[0][:200]}")


def run(quick: bool = False, device: str | None = None, sizes=None) -> dict:
    device = device or os.environ.get("GNC_JAX_BENCH_DEVICE", "gpu")
    import gnc_jax as gj
    from gnc_jax.backend import describe, describe_line, select

    info = describe(select(device))
    scenario = gj.load_scenario(SCENARIO)
    sizes = sizes or ([64, 256] if quick else [10_000, 100_000, 1_000_000])
    base_runs = 128 if quick else BASELINE_RUNS
    numba = _guarded(lambda: _numba_row(scenario, base_runs), "numba peer")
    base = numba.get("per_s")
    cpu = _guarded(
        lambda: _study_row(gj, scenario, base_runs, "cpu", "gnc_jax, CPU host devices", base),
        "gnc_jax, CPU host devices",
    )
    rows = [numba, cpu]
    for n in sizes:
        rows.append(_study_row(gj, scenario, n, device, f"gnc_jax, {info['platform']}", base))
    return dict(
        title=f"gnc_jax on {info['platform']} ({info['device_kind']}) vs the numba peer",
        device=info,
        rows=rows,
        markdown=_markdown(rows),
        notes=[
            f"device: {describe_line(info)}",
            *(f"{r['name']}: skipped ({r['skipped']})" for r in rows if r.get("skipped")),
            f"{SCENARIO}, seed 0; walls after compilation (compile apart), best of two calls; "
            "ratio: throughput over the numba peer's (own draws, all cores) in the same run.",
        ],
    )


def _markdown(rows) -> str:
    cols = ["name", "runs", "chunk", "compile_s", "wall_s", "per_s", "peak_mb", "ratio_vs_numba"]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        lines.append(
            "| " + " | ".join("" if r.get(c) is None else str(r.get(c)) for c in cols) + " |"
        )
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", choices=("cpu", "gpu", "auto"), default="gpu")
    p.add_argument("--quick", action="store_true")
    p.add_argument("--sizes", type=int, nargs="+", default=None)
    args = p.parse_args()
    result = run(args.quick, args.device, args.sizes)
    print(f"# {result['title']}\n\n{result['markdown']}\n")
    for note in result["notes"]:
        print(f"- {note}")


if __name__ == "__main__":
    main()
