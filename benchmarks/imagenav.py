"""Image front end throughput: frames rendered + centroided per second, and a 300-run study.

    python benchmarks/imagenav.py [--sizes 1 100 1000 10000] [--runs 300]

Frames come from random geometries along the approach (range 612-73 440 km, 60 deg phase,
binning chosen as on board, random sub-pixel position, shot and read noise), each rendered in
the scenario's ROI and centroided by the seed 002 pipeline. Each batch size is compiled ahead
of time (compile time reported separately), timed with ``block_until_ready``, best of
``--repeats``. The baseline is a Python loop calling the jitted single-frame function, measured
in the same process. The last lines time the full ``autonav-predictive`` Monte Carlo the way
``gnc-jax run`` does (both cores), and the same study with the noise front end.
"""

import argparse
import time

import jax
import jax.numpy as jnp
from _timing import best_of  # benchmarks/_timing.py

import gnc_jax as gj  # first: float64 and one XLA device per core
from gnc_jax.navigation.centroid import extract_centroid
from gnc_jax.navigation.render import choose_binning, render_frame, roi_to_tangent


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[1, 100, 1000, 10000])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--loop-frames", type=int, default=200)
    p.add_argument("--runs", type=int, default=300)
    args = p.parse_args()

    scenario = gj.load_scenario("autonav-predictive")
    sim, _ = gj.build(scenario)
    cam, tgt = sim.camera, sim.target

    def frame(key):
        """One frame at a random approach geometry; returns the centroid error (rad)."""
        k1, k2, k3 = jax.random.split(key, 3)
        rho = jax.random.uniform(k1, minval=6.12e5, maxval=7.344e7)
        off = jax.random.uniform(k2, (2,), minval=-0.5, maxval=0.5)
        # camera on +x looking at the target along -x (60 deg phase with the scenario's Sun)
        c = jnp.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
        b = choose_binning(cam, tgt.bounding_radius_m / rho, 30e-6)
        uv_true = off * cam.ifov_rad * b
        r_cam = rho * (c.T @ jnp.array([uv_true[0], uv_true[1], 1.0]))
        f = render_frame(cam, tgt, c, r_cam, jnp.zeros(2), b, k3)
        cen = extract_centroid(f.dn, cam.window_px, cam.label_iterations)
        return roi_to_tangent(cam, f.origin_px, f.bin, cen.xy) - uv_true

    print(
        f"# autonav-predictive image front end: ROI {cam.roi_px}x{cam.roi_px}, window "
        f"{cam.window_px}, {cam.samples}^2 rays, {cam.label_iterations} label sweeps; "
        f"{len(jax.devices())} XLA host devices; jax {jax.__version__}"
    )
    single = jax.jit(frame)
    t0 = time.perf_counter()
    jax.block_until_ready(single(jax.random.key(0)))
    loop_compile = time.perf_counter() - t0
    keys = [jax.random.key(i) for i in range(args.loop_frames)]
    loop_s = best_of(lambda: [single(k) for k in keys], 2)
    loop_rate = args.loop_frames / loop_s
    print(f"python loop of jit(frame): compile {loop_compile:.2f} s, {loop_rate:,.0f} frames/s")
    print()
    print("| frames | compile (s) | run (s) | frames/s | vs Python loop |")
    print("|---:|---:|---:|---:|---:|")
    for n in args.sizes:
        batch = jax.jit(jax.vmap(frame))
        ks = jax.random.split(jax.random.key(1), n)
        t0 = time.perf_counter()
        compiled = batch.lower(ks).compile()
        compile_s = time.perf_counter() - t0
        run_s = best_of(lambda c=compiled, k=ks: c(k), args.repeats)
        rate = n / run_s
        print(f"| {n} | {compile_s:.2f} | {run_s:.4f} | {rate:,.0f} | {rate / loop_rate:.1f}x |")
    print("(one XLA device; the Monte Carlo below shards runs over both cores)")
    print()
    for measurement in ("image", "noise"):
        sc = scenario.with_overrides({"navigation.measurement": measurement})
        s = gj.run_study(sc, runs=args.runs, seed=0, progress=False).summary()
        print(
            f"gnc-jax run autonav-predictive --runs {args.runs} --set navigation.measurement="
            f"{measurement}: compile {s['compile_s']:.2f} s, study wall {s['wall_s']:.2f} s "
            f"after compilation ({s['runs_per_s']:.1f} runs/s); miss max {s['miss_max_m']:.1f} m"
            + ("; target <= 300 s" if measurement == "image" else "")
        )
    print(f"machine: {s['machine']}")


if __name__ == "__main__":
    main()
