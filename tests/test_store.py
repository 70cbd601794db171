"""Study directories: chunks on disk, resume, directory rules, interruption, Dask.

The study is the toy system of tests/toy_system.py (registered from outside the package, as
a user's), small enough that the subprocess and cluster tests spend their time on what they
test. Every comparison is bit for bit against the same study run in memory in one call.
"""

import json
import os
import pathlib
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pyarrow.parquet as pq
import pytest

import gnc_jax as gj
from gnc_jax import store
from gnc_jax.scenario import ScenarioError
from gnc_jax.study import run_study

TESTS = pathlib.Path(__file__).resolve().parent
TOY = TESTS / "toy.toml"
RUNS, CHUNK = 240, 40


@pytest.fixture(scope="module")
def toy():
    return gj.load_scenario(TOY)


@pytest.fixture(scope="module")
def reference(toy):
    """The study in memory, one call: what every other way of running it must equal."""
    return run_study(toy, runs=RUNS, chunk_size=RUNS, progress=False).outcomes


def _equal(outcomes, reference):
    assert set(outcomes) == set(reference)
    for k in reference:
        np.testing.assert_array_equal(outcomes[k], reference[k], err_msg=k)


def test_chunks_on_disk_equal_the_study_in_memory(toy, reference, tmp_path):
    out = tmp_path / "study"
    study = run_study(toy, runs=RUNS, chunk_size=CHUNK, progress=False, out=out)
    files = store.chunk_files(out)
    assert [f.name for f in files] == [f"chunk-{c:06d}.parquet" for c in range(RUNS // CHUNK)]
    assert json.loads((out / "study.json").read_text())["state"] == "complete"
    # the runs directory opens as one table, ordered by run
    table = pq.read_table(out / "runs")
    assert table.num_rows == RUNS
    np.testing.assert_array_equal(np.sort(table.column("run").to_numpy()), np.arange(RUNS))
    _equal(study.outcomes, reference)
    summary, runs, scenario = gj.load_results(out)
    assert summary["runs"] == RUNS and scenario.name == toy.name
    np.testing.assert_array_equal(runs["miss_m"], reference["miss_m"])
    # the summary read from the chunk files equals the one of the study in memory
    mem = run_study(toy, runs=RUNS, chunk_size=CHUNK, progress=False).summary()
    drop = ("wall_s", "compile_s", "write_s", "runs_per_s")
    assert {k: v for k, v in summary.items() if k not in drop} == {
        k: v for k, v in mem.items() if k not in drop
    }


def test_directory_rules(toy, tmp_path):
    out = tmp_path / "study"
    run_study(toy, runs=80, chunk_size=CHUNK, progress=False, out=out)
    with pytest.raises(ScenarioError, match="holds a complete study of toy-intercept-demo"):
        run_study(toy, runs=80, chunk_size=CHUNK, progress=False, out=out)
    with pytest.raises(ScenarioError, match="seed differs"):
        run_study(toy, runs=80, seed=1, chunk_size=CHUNK, progress=False, out=out, resume=True)
    changed = gj.load_scenario(TOY, overrides=["guidance.pn.n=4"])
    with pytest.raises(ScenarioError, match="scenario differs"):
        run_study(changed, runs=80, chunk_size=CHUNK, progress=False, out=out, resume=True)
    # a stale figure of the old study goes with it when the directory is replaced
    (out / "miss.png").write_bytes(b"old")
    run_study(changed, runs=40, chunk_size=CHUNK, progress=False, out=out, overwrite=True)
    assert not (out / "miss.png").exists() and len(store.chunk_files(out)) == 1
    # a directory of other files is never a study directory, not even with --overwrite
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    for kwargs in ({}, {"overwrite": True}):
        with pytest.raises(ScenarioError, match="not empty"):
            run_study(toy, runs=40, progress=False, out=other, **kwargs)
    assert (other / "notes.txt").read_text() == "mine"


def test_a_second_writer_is_kept_out(tmp_path):
    manifest = dict(scenario_name="x", seed=0, runs=1, chunk_size=1, code_version="v")
    with store.StudyStore(tmp_path / "s", manifest):
        with pytest.raises(ScenarioError, match="another process is writing"):
            store.StudyStore(tmp_path / "s", manifest, resume=True)
    store.StudyStore(tmp_path / "s", manifest, resume=True).close()  # free again


def test_interrupted_then_resumed_equals_uninterrupted(toy, reference, tmp_path, monkeypatch):
    out = tmp_path / "study"
    write = store.StudyStore.write_chunk
    calls = []

    def interrupted(self, c, start, outcomes):
        if len(calls) == 2:
            raise KeyboardInterrupt
        calls.append(c)
        write(self, c, start, outcomes)

    monkeypatch.setattr(store.StudyStore, "write_chunk", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_study(toy, runs=RUNS, chunk_size=CHUNK, progress=False, out=out)
    assert len(store.chunk_files(out)) == 2
    with pytest.raises(gj.ResultsError, match="partial study"):
        gj.load_results(out)
    monkeypatch.setattr(store.StudyStore, "write_chunk", write)
    _equal(run_study(toy, runs=RUNS, progress=False, out=out, resume=True).outcomes, reference)


def test_damaged_chunks_are_detected_and_recomputed(toy, reference, tmp_path, monkeypatch):
    out = tmp_path / "study"
    run_study(toy, runs=RUNS, chunk_size=CHUNK, progress=False, out=out)
    files = store.chunk_files(out)
    data = files[1].read_bytes()
    files[1].write_bytes(data[: len(data) // 2])  # truncated
    table = pq.read_table(files[2])
    miss = table.column("miss_m").to_numpy().copy()
    miss[3] += 1.0  # a readable file whose content changed: only the checksum can tell
    table = table.set_column(table.column_names.index("miss_m"), "miss_m", [miss])
    pq.write_table(table, files[2])
    files[4].unlink()  # missing
    (out / "runs" / ".chunk-000005.parquet.x.tmp").write_bytes(b"half")  # a killed writer's
    written = []
    write = store.StudyStore.write_chunk
    monkeypatch.setattr(
        store.StudyStore,
        "write_chunk",
        lambda self, c, *a: (written.append(c), write(self, c, *a))[1],
    )
    study = run_study(toy, runs=RUNS, progress=False, out=out, resume=True)
    assert sorted(written) == [1, 2, 4]
    assert not list((out / "runs").glob(".*.tmp"))
    _equal(study.outcomes, reference)
    # a complete study resumed has nothing left to run: it compiles nothing
    monkeypatch.setattr(gj.study, "_compile_local", lambda *a: pytest.fail("compiled"))
    again = run_study(toy, runs=RUNS, progress=False, out=out, resume=True)
    assert sorted(written) == [1, 2, 4] and again.compile_s == 0.0
    _equal(again.outcomes, reference)


def _cli(out, *extra):
    env = {
        **os.environ,
        "GNC_JAX_PLUGINS": "toy_system",
        "PYTHONPATH": os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")]),
        "GNC_JAX_HOST_DEVICES": "1",
    }
    cmd = [sys.executable, "-m", "gnc_jax", "run", str(TOY), "--runs", "4000"]
    cmd += ["--chunk-size", "100", "--out", str(out), "--no-progress", *extra]
    return cmd, env


def _kill_mid_study(cmd, env, out, sig, at_least):
    """Start ``cmd``, send ``sig`` once ``at_least`` chunk files exist; stderr and chunks."""
    # SIGINT back to its default in the child: a test worker (pytest-xdist) may ignore it,
    # and a child inherits an ignored signal (Python then installs no KeyboardInterrupt).
    proc = subprocess.Popen(
        cmd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.time() + 120
    while len(store.chunk_files(out)) < at_least and time.time() < deadline:
        if proc.poll() is not None:
            break
        time.sleep(0.02)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    return proc.returncode, err.decode(), len(store.chunk_files(out))


def test_cli_interrupted_and_killed_then_resumed(toy, tmp_path):
    """Ctrl-C (SIGINT), then SIGKILL of the resumed study, then --resume: the runs equal an
    uninterrupted study's, and until then the directory says it is partial."""
    out = tmp_path / "study"
    cmd, env = _cli(out)
    code, err, kept = _kill_mid_study(cmd, env, out, signal.SIGINT, 2)
    assert code == 130 and "chunks kept" in err and "--resume" in err, err[-2000:]
    assert 2 <= kept < 40, "the study must be stopped mid-way for this test to mean anything"
    code, err, kept_after_kill = _kill_mid_study(
        cmd + ["--resume"], env, out, signal.SIGKILL, kept + 2
    )
    assert code == -signal.SIGKILL and kept + 2 <= kept_after_kill < 40, err[-2000:]
    assert json.loads((out / "study.json").read_text())["state"] == "partial"
    assert not (out / "summary.json").exists()
    done = subprocess.run(cmd + ["--resume"], env=env, capture_output=True)
    assert done.returncode == 0, done.stderr.decode()[-2000:]
    reference = run_study(toy, runs=4000, chunk_size=4000, progress=False).outcomes
    _, runs, _ = gj.load_results(out)
    np.testing.assert_array_equal(runs["run"], np.arange(4000))
    for k in ("status", "miss_m", "dv_mps"):
        np.testing.assert_array_equal(runs[k], reference[k], err_msg=k)


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("dask.distributed")
    os.environ["GNC_JAX_PLUGINS"] = "toy_system"  # the workers inherit it (and the path)
    os.environ["PYTHONPATH"] = os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")])
    cl = distributed.LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        env={"GNC_JAX_HOST_DEVICES": "1"},
    )
    client = distributed.Client(cl)
    yield client
    client.close()
    cl.close()


def test_dask_cluster_equals_local_and_survives_a_lost_worker(toy, reference, cluster, tmp_path):
    study = run_study(toy, runs=RUNS, chunk_size=CHUNK, progress=False, client=cluster)
    _equal(study.outcomes, reference)
    assert study.summary()["dask_workers"] == 2
    # the planner's chunks: one per worker (the toy's default chunk holds all RUNS runs)
    planned = run_study(toy, runs=RUNS, progress=False, client=cluster)
    assert planned.chunk_size == RUNS // 2
    _equal(planned.outcomes, reference)
    # A worker dies mid-study: its chunks run again elsewhere, the study completes identically.
    out = tmp_path / "study"
    result = {}
    runner = threading.Thread(
        target=lambda: result.update(
            s=run_study(toy, runs=4000, chunk_size=100, progress=False, client=cluster, out=out)
        )
    )
    runner.start()
    deadline = time.time() + 120
    while len(store.chunk_files(out)) < 2 and time.time() < deadline:
        time.sleep(0.05)
    pids = cluster.run(os.getpid)
    os.kill(pids[sorted(pids)[0]], signal.SIGKILL)  # its nanny starts a new one
    runner.join(timeout=300)
    assert "s" in result
    full = run_study(toy, runs=4000, chunk_size=4000, progress=False).outcomes
    _equal(result["s"].outcomes, full)


def test_a_chunk_that_raises_is_reported_and_the_rest_go_on(toy, reference, tmp_path, monkeypatch):
    distributed = pytest.importorskip("dask.distributed")
    from gnc_jax import montecarlo
    from gnc_jax import study as study_module

    run_chunk = montecarlo.run_chunk

    def faulty(scenario, seed, start, stop, chunk, **options):
        # a worker compiles the layout of the whole study (run_chunk): it is told its run count
        assert options["study_runs"] == RUNS, options
        if start == 2 * CHUNK:
            raise FloatingPointError("injected")
        return run_chunk(scenario, seed, start, stop, chunk, **options)

    monkeypatch.setattr(montecarlo, "run_chunk", faulty)
    builds = []
    system = type(gj.get_system(toy.kind))  # not copied into a task: counts every build
    build = system.build
    monkeypatch.setattr(
        system, "build", lambda self, sc: (builds.append(sc.name), build(self, sc))[1]
    )
    out = tmp_path / "study"
    with distributed.Client(processes=False, n_workers=1, threads_per_worker=1) as client:
        with pytest.raises(study_module.StudyError, match=r"chunk 2 \(runs 80\.\.119\)") as e:
            run_study(toy, runs=RUNS, chunk_size=CHUNK, progress=False, client=client, out=out)
    assert e.value.errors == [dict(chunk=2, runs=[80, 120], error="FloatingPointError: injected")]
    assert builds == [toy.name]  # built once, by the study; its workers are sent the result
    names = [f.name for f in store.chunk_files(out)]
    assert len(names) == RUNS // CHUNK - 1 and "chunk-000002.parquet" not in names
    monkeypatch.setattr(montecarlo, "run_chunk", run_chunk)
    _equal(run_study(toy, runs=RUNS, progress=False, out=out, resume=True).outcomes, reference)


def test_envelope_cells_run_through_the_dask_path(toy):
    distributed = pytest.importorskip("dask.distributed")
    grid = ["guidance.pn.n=3:4:2"]
    local = gj.envelope(toy, grid, runs=CHUNK, progress=False)
    with distributed.Client(processes=False, n_workers=1, threads_per_worker=1) as client:
        remote = gj.envelope(toy, grid, runs=CHUNK, progress=False, client=client)
    drop = ("wall_s", "compile_s")
    strip = lambda cells: [{k: v for k, v in c.items() if k not in drop} for c in cells]  # noqa: E731
    assert strip(remote.cells) == strip(local.cells) and len(local.cells) == 2


def test_the_summary_on_disk_reads_a_column_its_first_chunk_did_not_need(toy, tmp_path):
    """The summary of a study on disk reads the columns its statistics use on the first chunk;
    one that a statistic reads only on a branch that chunk's runs did not take (a midcourse
    study's iterations, read only where a run corrected) is read when asked for."""
    from gnc_jax.results import _statistics_outcomes
    from gnc_jax.study import Study

    status = np.zeros(4, np.int32)
    outcomes = dict(status=status, burns=np.array([0, 0, 1, 2]), iters=np.array([7, 7, 3, 5]))
    manifest = dict(scenario_name="x", seed=0, runs=4, chunk_size=2, code_version="v")
    with store.StudyStore(tmp_path / "s", manifest) as st:
        for c in range(2):
            st.write_chunk(c, 2 * c, {k: v[2 * c : 2 * c + 2] for k, v in outcomes.items()})

    class System:
        def statistics(self, o, ok):
            burns = o["burns"][ok]
            return {"iters": float(np.mean(o["iters"][ok][burns > 0])) if burns.any() else 0.0}

    study = Study(toy, 4, 0, None, 0.0, 1.0, 1, 2, path=tmp_path / "s")
    o = _statistics_outcomes(study, System())
    assert System().statistics(o, status == 0) == {"iters": 4.0}
    assert "iters" in o and o.get("nothing") is None
