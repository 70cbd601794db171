"""The backend of a study without a GPU: choosing the device and refusing a missing one, the
planner's chunks, cost model and memory guard against a fake device (platform, memory limit),
the optional parts' refusals, and what a study records of where it ran."""

import math
import pathlib
import sys

import jax
import numpy as np
import pytest

import gnc_jax as gj
from gnc_jax import _config, backend, cli, montecarlo, planner
from gnc_jax.backend import Backend
from gnc_jax.scenario import ScenarioError

TOY = pathlib.Path(__file__).with_name("toy.toml")
H100 = Backend("gpu", "NVIDIA H100 80GB HBM3", ("gpu:0",), int(60.8e9))
"""A fake GPU: one device with the H100's allocator limit (75 % of its 80 GB)."""


def fake(platform="gpu", memory_gb=60.8, count=1) -> Backend:
    return Backend(platform, f"fake {platform}", tuple(range(count)), int(memory_gb * 1e9))


def refused(argv, capsys, monkeypatch) -> str:
    """The CLI's one-line refusal, before anything is built or compiled."""

    def no_compile(*args, **kwargs):
        raise AssertionError("compiled or built before refusing")

    monkeypatch.setattr(montecarlo, "build", no_compile)
    monkeypatch.setattr(montecarlo, "_compile", no_compile)
    assert cli.main(argv) == cli.EXIT_REFUSED
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


# ---- choosing the device ---------------------------------------------------------------------


def test_cpu_is_the_host_devices_and_auto_jax_default():
    cpu, auto = backend.select("cpu"), backend.select(None)
    assert cpu.platform == "cpu" and cpu.devices == tuple(jax.devices("cpu"))
    assert cpu.memory_bytes == backend.physical_memory() > 0
    assert auto.devices == tuple(jax.devices()) and auto.default


def test_a_gpu_where_there_is_none_is_refused_naming_the_extra(capsys, monkeypatch):
    with pytest.raises(ScenarioError, match=r"device: gpu, .*no GPU.*gnc_jax\[cuda12\]"):
        gj.run_study(gj.load_scenario(TOY), runs=4, device="gpu")
    err = refused(["run", str(TOY), "--runs", "4", "--device", "gpu"], capsys, monkeypatch)
    assert err.startswith("gnc-jax: error: device: gpu") and "gnc_jax[cuda12]" in err
    out = ["--out", "/nonexistent/x"]  # the device is checked first
    for command in (
        ["envelope", str(TOY), "--grid", "a.b=1:2:2"],
        ["tune", str(TOY), "--params", "a"],
    ):
        assert cli.main(command + out + ["--device", "gpu"]) == cli.EXIT_REFUSED
        assert "gnc_jax[cuda12]" in capsys.readouterr().err


def test_an_unknown_device_is_refused_in_one_line(capsys):
    with pytest.raises(ScenarioError, match="device: 'tpu'; allowed: auto, cpu, gpu"):
        backend.select("tpu")
    with pytest.raises(SystemExit) as e:
        cli.main(["run", str(TOY), "--device", "tpu"])
    assert e.value.code == 2
    assert "--device: invalid choice: 'tpu'" in capsys.readouterr().err


# ---- optional parts --------------------------------------------------------------------------


@pytest.mark.parametrize("option", [["--workers", "2"], ["--scheduler", "tcp://127.0.0.1:1"]])
def test_a_missing_cluster_extra_is_refused_naming_it(option, capsys, monkeypatch):
    # ``None`` in sys.modules makes ``import dask.distributed`` raise ImportError, as it does
    # after the README's install (no ``cluster`` extra).
    monkeypatch.setitem(sys.modules, "dask.distributed", None)
    err = refused(["run", "deep-impact-los", "--runs", "8", *option], capsys, monkeypatch)
    assert "needs dask.distributed" in err and "pip install 'gnc_jax[cluster]'" in err
    assert "internal error" not in err
    with pytest.raises(ScenarioError, match=r"workers: needs dask.distributed.*\[cluster\]"):
        gj.run_study(gj.load_scenario(TOY), runs=4, workers=2)


def test_require_names_the_extra_of_each_optional_module(monkeypatch):
    assert backend.require("numpy", "x") is np
    for module, extra in backend.EXTRAS.items():
        monkeypatch.setitem(sys.modules, module, None)
        with pytest.raises(ScenarioError, match=rf"--opt: needs {module}.*gnc_jax\[{extra}\]"):
            backend.require(module, "--opt")


def test_dask_workers_share_a_gpu_without_preallocating_it(monkeypatch):
    for var in ("XLA_PYTHON_CLIENT_PREALLOCATE", "XLA_PYTHON_CLIENT_MEM_FRACTION"):
        monkeypatch.delenv(var, raising=False)
    cpu_only = montecarlo.worker_environment(2, gpus=0)
    assert "XLA_PYTHON_CLIENT_PREALLOCATE" not in cpu_only
    for workers, gpus in [(1, 1), (2, 1), (3, 1), (4, 2), (3, 2)]:
        env = montecarlo.worker_environment(workers, gpus)
        assert env["XLA_PYTHON_CLIENT_PREALLOCATE"] == "false"
        per_gpu = math.ceil(workers / gpus)  # the most workers one GPU holds
        assert per_gpu * float(env["XLA_PYTHON_CLIENT_MEM_FRACTION"]) <= 0.9 + 1e-9
    monkeypatch.setenv("XLA_PYTHON_CLIENT_MEM_FRACTION", "0.2")  # the user's choice is kept
    assert montecarlo.worker_environment(2, 1)["XLA_PYTHON_CLIENT_MEM_FRACTION"] == "0.2"


def test_a_local_worker_gets_its_host_devices_in_place_of_the_submitters(monkeypatch):
    """Twice its share of the cores, at most the cores, in place of the count the submitting
    process's XLA_FLAGS name (which a worker would otherwise inherit and keep)."""
    monkeypatch.setattr(montecarlo.os, "cpu_count", lambda: 16)
    flag = "--xla_force_host_platform_device_count"
    monkeypatch.setenv("XLA_FLAGS", f"{flag}=16 --xla_cpu_enable_fast_math=false")
    env = montecarlo.worker_environment(8, gpus=0)
    assert env["GNC_JAX_HOST_DEVICES"] == "4"
    assert env["XLA_FLAGS"] == f"{flag}=4 --xla_cpu_enable_fast_math=false"
    monkeypatch.delenv("XLA_FLAGS")
    assert montecarlo.worker_environment(32, gpus=0)["XLA_FLAGS"] == f"{flag}=2"
    assert montecarlo.worker_environment(1, gpus=0)["GNC_JAX_HOST_DEVICES"] == "16"


_WORKER_PROBE = """
import os, sys
import gnc_jax.cli  # as the gnc-jax command's main module: each spawned worker imports it again


def probe():
    import jax

    return len(jax.devices()), jax.config.jax_compilation_cache_dir


if __name__ == "__main__":
    from gnc_jax.montecarlo import local_cluster

    client = local_cluster(2)
    seen = sorted(client.run(probe).values())
    client.close()
    cores = os.cpu_count() or 1
    share = min(cores, 2 * max(1, cores // 2))
    print(seen, share, os.environ.get("GNC_JAX_HOST_DEVICES"), os.environ.get("XLA_FLAGS"))
"""


def test_local_workers_start_with_their_environment_under_the_gnc_jax_command(tmp_path):
    """A local cluster's worker process imports the submitting program's main module first;
    under the gnc-jax command that configures JAX (gnc_jax._config) before Dask's post-start
    environment: the workers' device count and compilation cache must be theirs from the
    start, and the submitting process's environment is left as it was."""
    pytest.importorskip("dask.distributed")
    import os
    import subprocess

    script = tmp_path / "submit.py"
    script.write_text(_WORKER_PROBE)
    env = {**os.environ, "HOME": str(tmp_path), "GNC_JAX_HOST_DEVICES": "3"}
    for var in ("XLA_FLAGS", "JAX_COMPILATION_CACHE_DIR"):
        env.pop(var, None)
    done = subprocess.run(
        [sys.executable, str(script)], env=env, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    seen, share, host_devices, flags = done.stdout.strip().splitlines()[-1].rsplit(" ", 3)
    cache = str(tmp_path / ".cache" / "gnc_jax" / "xla")
    assert seen == str([(int(share), cache)] * 2)
    assert (host_devices, flags) == ("3", "--xla_force_host_platform_device_count=3")


def test_the_host_device_flag_goes_before_a_bare_xla_token(monkeypatch):
    monkeypatch.setenv("XLA_FLAGS", "intra_op_parallelism_threads=1")
    monkeypatch.setenv("GNC_JAX_HOST_DEVICES", "3")
    _config._configure_host_devices()
    import os

    flags = os.environ["XLA_FLAGS"].split()
    assert flags == ["--xla_force_host_platform_device_count=3", "intra_op_parallelism_threads=1"]


# ---- cost model ------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["deep-impact-los", "bennu-apn", "lunar-skip-entry"])
def test_the_gpu_cost_is_throughput_plus_sequential_latency(name):
    scenario = gj.load_scenario(name)
    system = gj.get_system(scenario.kind)
    steps = system.steps_per_run(scenario.config)
    cost = system.step_cost("gpu")
    for runs in (2_000, 200_000):
        est = gj.estimate_cost(scenario, runs, device=H100)
        want = runs * steps * cost.run_step_s + steps * cost.step_latency_s
        assert est.seconds == pytest.approx(want) and est.platform == "gpu"
        assert est.latency_s == pytest.approx(steps * cost.step_latency_s)
    two_gpus = gj.estimate_cost(scenario, 200_000, device=fake(count=2))
    assert two_gpus.seconds == pytest.approx(
        100_000 * steps * cost.run_step_s + steps * cost.step_latency_s
    )


def test_bennu_on_a_gpu_is_latency_bound_and_not_refused():
    # the H100's measured walls through the CLI: 2,000 runs 2.30 s, 200,000 runs 19.8 s
    scenario = gj.load_scenario("bennu-apn")
    small, large = (gj.estimate_cost(scenario, n, device=H100) for n in (2_000, 200_000))
    assert 2.30 / 3 < small.seconds < 2.30 * 3 and 19.8 / 3 < large.seconds < 19.8 * 3
    assert small.latency_s / small.seconds > 0.9
    assert "sequential-step latency" in str(small)
    from gnc_jax.study import _checked_cost

    assert _checked_cost(scenario, 200_000, None, 24.0, H100).seconds == large.seconds
    # on one CPU device 400,000 runs are estimated at about 22 min: over a 0.2 h limit
    cpu = gj.estimate_cost(scenario, 400_000, 1, backend.select("cpu"))
    assert 0.2 * 3600 < cpu.seconds < 3600
    with pytest.raises(ScenarioError, match="cost: 400000 runs"):
        _checked_cost(scenario, 400_000, 1, 0.2, backend.select("cpu"))


def test_the_cpu_estimate_is_unchanged_and_an_uncalibrated_platform_is_unknown():
    scenario = gj.load_scenario("phoenix-midcourse")
    system = gj.get_system(scenario.kind)
    steps = system.steps_per_run(scenario.config)
    cpu = gj.estimate_cost(scenario, 100, n_devices=1, device=fake("cpu"))
    assert cpu.seconds == pytest.approx(100 * steps * system.step_seconds) and cpu.latency_s == 0
    assert system.step_cost("gpu") is None
    gpu = gj.estimate_cost(scenario, 100, device=H100)
    assert gpu.seconds is None and "time unknown" in str(gpu) and "about" not in str(gpu)
    assert "cost_calibration.py --device gpu" in str(gpu)


# ---- chunks ----------------------------------------------------------------------------------


def plan(name, runs, device, chunk_size=None, fraction=0.5, n_dev=None):
    scenario = gj.load_scenario(name)
    n_dev = n_dev or device.count
    cost = gj.estimate_cost(scenario, runs, n_dev, device)
    announce = cost.seconds is not None and cost.seconds > montecarlo.ANNOUNCE_S
    system = gj.get_system(scenario.kind)
    return planner.plan_chunk(
        system, runs, chunk_size, device, n_dev, cost, announce, False, fraction
    ), cost


def test_cpu_chunks_are_the_cache_sized_ones():
    # impactor: 2048 runs per device, equal chunks, padded to 8 lanes per device
    # 6,000 runs on 2 devices: 2 chunks of 3000 -> 1500 per device -> 1504 -> 3008; 10,000
    # runs (about 2 s: not announced): 3 chunks of 3334 -> 1667 per device -> 1672 -> 3344;
    # 400,000 runs (about 71 s: announced, chunks of 10 s would be 56,000 runs): the
    # cache-sized chunks, 98 of 4082 -> 2041 per device -> 2048 -> 4096
    assert plan("deep-impact-los", 6_000, fake("cpu", count=2))[0] == 3008
    assert plan("deep-impact-los", 10_000, fake("cpu", count=2))[0] == 3344
    chunk, cost = plan("deep-impact-los", 400_000, fake("cpu", count=2))
    assert chunk == 4096 and 50 < cost.seconds < 100
    # capsule: 256 per device, no lanes: 1000 runs on 2 devices -> 2 chunks of 500
    assert plan("lunar-skip-entry", 1000, fake("cpu", count=2))[0] == 500


def test_a_dask_study_has_a_chunk_per_worker():
    """On Dask a chunk is one worker's task: a study of one default chunk is split so that no
    worker idles; a larger one keeps the cache-sized chunks; a chunk size given is kept."""
    cpu = fake("cpu", count=1)

    def chunk(name, runs, workers, chunk_size=None):
        scenario = gj.load_scenario(name)
        cost = gj.estimate_cost(scenario, runs, 1, cpu)
        system = gj.get_system(scenario.kind)
        return planner.plan_chunk(system, runs, chunk_size, cpu, 1, cost, False, True, 0.5, workers)

    assert chunk("lunar-skip-entry", 256, 2) == 128  # one chunk of 256 per device locally
    assert chunk("lunar-skip-entry", 257, 2) == 129  # equal chunks, the last one short
    assert chunk("lunar-skip-entry", 256, 1) == 256
    assert chunk("lunar-skip-entry", 3, 4) == 1
    assert chunk("lunar-skip-entry", 2000, 2) == 250  # cache-sized: 8 chunks of 250
    assert chunk("lunar-skip-entry", 256, 2, chunk_size=256) == 256
    assert chunk("deep-impact-los", 2000, 2) == 1000


def test_a_local_clusters_chunks_are_planned_for_its_workers_devices(monkeypatch):
    """A local cluster's chunk is sized for one worker's host devices (twice its share of the
    cores), not the submitting process's; a cluster of one's own (a client) and a GPU keep
    the submitting process's count."""
    from gnc_jax.study import _chunk_devices

    monkeypatch.setattr(montecarlo.os, "cpu_count", lambda: 16)
    cpu = fake("cpu", count=16)
    assert _chunk_devices(cpu, 16, None, 8) == 4
    assert _chunk_devices(cpu, 16, None, 2) == 16
    assert _chunk_devices(cpu, 16, None, None) == 16
    assert _chunk_devices(cpu, 16, object(), None) == 16
    assert _chunk_devices(fake("gpu", count=1), 1, None, 2) == 1


@pytest.mark.parametrize(
    "name, runs",
    [("lunar-skip-entry", 100_000), ("bennu-apn", 200_000), ("bennu-apn", 2_000)],
)
def test_a_gpu_runs_what_fits_in_one_chunk(name, runs):
    chunk, cost = plan(name, runs, H100)
    assert chunk == runs, (chunk, str(cost))


def test_a_gpu_batch_stops_where_a_larger_one_runs_no_faster():
    # the H100's best chunk for 1,000,000 deep-impact-los runs was 125,000 (3.84 s; one chunk
    # of 1,000,000: 5.37 s): 15 kB per run, at most 2 GB per chunk -> 8 equal chunks
    chunk, _ = plan("deep-impact-los", 1_000_000, H100)
    assert chunk == 125_000
    assert chunk * gj.get_system("impactor").run_bytes <= planner.GPU_BATCH_BYTES


@pytest.mark.parametrize("memory_gb", [0.05, 1.0, 8.0])
def test_gpu_chunks_fit_the_device_memory(memory_gb):
    device = fake(memory_gb=memory_gb)
    runs = 1_000_000
    chunk, _ = plan("deep-impact-los", runs, device, fraction=0.5)
    run_bytes = gj.get_system("impactor").run_bytes
    limit = min(0.5 * memory_gb * 1e9, planner.GPU_BATCH_BYTES)
    assert chunk * run_bytes <= limit
    n = math.ceil(runs / chunk)
    assert (chunk - 1) * n < runs  # equal chunks: no fewer would fit
    assert math.ceil(runs / (n - 1)) * run_bytes > limit if n > 1 else True


def test_a_long_gpu_study_is_cut_for_progress_only_where_latency_stays_small():
    # deep-impact-los: 20,000,000 runs (~39 s: announced) already run in chunks of at most
    # GPU_BATCH_BYTES, each well under PROGRESS_CHUNK_S: no further cut
    runs = 20_000_000
    chunk, cost = plan("deep-impact-los", runs, H100)
    assert cost.seconds > montecarlo.ANNOUNCE_S
    run_bytes = gj.get_system("impactor").run_bytes
    assert chunk == math.ceil(runs / math.ceil(runs / int(planner.GPU_BATCH_BYTES / run_bytes)))
    assert (cost.seconds - cost.latency_s) * chunk / runs < planner.PROGRESS_CHUNK_S
    # bennu: 1.5 s of latency per chunk: a 41 s study is cut in 3 (the extra chunks' latency
    # under a tenth of the estimate), not in 4 chunks of 10 s
    chunk, cost = plan("bennu-apn", 1_000_000, H100)
    model = gj.get_system("intercept").step_cost("gpu")
    steps = cost.steps_per_run
    assert cost.latency_s == pytest.approx(steps * model.step_latency_s)
    assert cost.seconds == pytest.approx(1_000_000 * steps * model.run_step_s + cost.latency_s)
    assert (cost.seconds - cost.latency_s) / planner.PROGRESS_CHUNK_S > 3.5  # 4 chunks of 10 s
    assert math.ceil(1_000_000 / chunk) == 3
    assert 2 * cost.latency_s < planner.LATENCY_SHARE * cost.seconds < 3 * cost.latency_s


def test_the_chunk_size_asked_for_is_kept_on_a_gpu():
    assert plan("deep-impact-los", 100_000, H100, chunk_size=25_000)[0] == 25_000


# ---- memory guard ----------------------------------------------------------------------------


def test_a_planned_chunk_too_large_for_memory_is_halved_an_asked_one_refused():
    scenario = gj.load_scenario(TOY)
    whole = gj.run_study(scenario, runs=64, chunk_size=64, progress=False)
    sim, law = gj.build(scenario)
    need = {n: _need(scenario, sim, law, n) for n in (64, 32)}
    assert need[32] < need[64]
    fraction = 0.5 * (need[32] + need[64]) / backend.physical_memory()  # 32 fits, 64 does not
    halved = gj.run_study(scenario, runs=64, progress=False, max_memory_fraction=fraction)
    assert halved.chunk_size == 64  # the chunk (store, progress) is kept; its batch halved
    for field, x in whole.outcomes.items():
        np.testing.assert_array_equal(halved.outcomes[field], x, err_msg=field)
    with pytest.raises(ScenarioError, match=r"chunk_size: 64 runs need .* allowed: chunk_size <="):
        gj.run_study(scenario, runs=64, chunk_size=64, max_memory_fraction=fraction)


def _need(scenario, sim, law, n):
    import jax.numpy as jnp

    system = gj.get_system(scenario.kind)
    fn, n_dev = montecarlo.batch_function(system)
    devices = jax.devices()[:n_dev]
    seed = jnp.asarray(0, jnp.uint32)
    where = montecarlo._where(backend.select("auto"), devices)
    compiled, _ = montecarlo._compile(system, fn, where, sim, law, seed, n)
    return planner.compiled_bytes(compiled)


def test_the_memory_refusal_names_the_gpu_and_its_limit():
    e = planner.memory_refusal(int(40e9), 1_000_000, H100, 0.5, 0.5 * 60.8e9)
    assert "NVIDIA H100 80GB HBM3's 60.8 GB" in str(e) and "chunk_size <= 760000" in str(e)


def test_a_study_placed_on_a_non_default_platform_equals_the_default_one(monkeypatch):
    # what ``device="cpu"`` does on a machine whose default is a GPU: the program placed on the
    # chosen devices through a mesh (even for one device) and the arrays made there
    scenario = gj.load_scenario(TOY)
    reference = gj.run_study(scenario, runs=8, n_devices=1, progress=False)
    cpu = backend.select("cpu")
    placed = Backend(cpu.platform, cpu.device_kind, cpu.devices, cpu.memory_bytes, default=False)
    from gnc_jax import study as study_module

    monkeypatch.setattr(study_module, "select", lambda device: placed)
    calls = []
    real = montecarlo.batch_function

    def recorded(system, n_devices=None, devices=None):
        calls.append(devices)
        return real(system, n_devices, devices)

    monkeypatch.setattr(montecarlo, "batch_function", recorded)
    other = gj.run_study(scenario, runs=8, n_devices=1, progress=False)
    assert calls == [placed.devices]
    assert other.compile_s > 0  # its own executable, not the default program's
    rtol, atol = gj.get_system(scenario.kind).batch_tolerance
    for field, x in reference.outcomes.items():
        np.testing.assert_allclose(other.outcomes[field], x, rtol=rtol, atol=atol, err_msg=field)


# ---- the record ------------------------------------------------------------------------------


def test_the_study_records_its_device(tmp_path, capsys):
    out = tmp_path / "s"
    assert cli.main(["run", str(TOY), "--runs", "8", "--out", str(out), "--device", "cpu"]) == 0
    line = capsys.readouterr().out.splitlines()[0]
    import json

    summary = json.loads((out / "summary.json").read_text())
    device = summary["device"]
    n_cpu = len(jax.devices("cpu"))
    assert device["platform"] == "cpu" and device["device_count"] == n_cpu
    assert device["jax"] == jax.__version__ and device["jaxlib"]
    assert summary["write_s"] >= 0 and f"jax {jax.__version__}" in summary["machine"]
    assert f"{n_cpu} CPU host devices" in line and ", write " in line
