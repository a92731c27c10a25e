"""
The benchmark on a Dask cluster (``--scheduler``): a real scheduler and two workers on 127.0.0.1, the same results
as a local run, a worker killed mid-run, workers with other versions refused, and Dask imported only with the flag.
"""

import os
import queue
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from concurrent.futures import Future
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from benchmarks import run
from benchmarks.common import REPO_ROOT
from sb3_classic.harness import pool
from sb3_classic.harness.common import RunSpec, code_versions
from sb3_classic.harness.lockstep import plan_lockstep
from sb3_classic.harness.runner import (
    EPISODES_FILE,
    EVALUATIONS_FILE,
    RUN_FILE,
    RunResult,
    execute_population,
    execute_run,
    load_run,
    run_one,
    store_run,
)

#: The options of a small benchmark of our two algorithms on CartPole-v1 (seed 0 unless --seeds says more)
SMALL = ("--envs", "CartPole-v1", "--seeds", "1", "--peer-seeds", "0", "--eval-episodes", "2", "--skip-throughput")


def free_port() -> int:
    """:return: a TCP port of 127.0.0.1 free now"""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@dataclass
class Cluster:
    """A Dask scheduler and its workers, each a ``dask`` command in a subprocess; ``client`` watches them."""

    address: str
    client: Any
    workers: dict[str, subprocess.Popen]
    logs: Path

    def worker_logs(self) -> str:
        """:return: the output of the scheduler and the workers, for assertion messages"""
        return "\n".join(f"--- {path.name}\n{path.read_text()[-3000:]}" for path in sorted(self.logs.glob("*.log")))


@contextmanager
def dask_cluster(folder: Path, n_workers: int = 2) -> Iterator[Cluster]:
    """
    Start ``dask scheduler`` and ``n_workers`` ``dask worker --nthreads 1`` on 127.0.0.1, stopped at the end.

    The workers run in ``folder``, away from the repository and the client's cache, with this checkout first on
    their path: they import the package under test (the harness is ``sb3_classic.harness``), whatever else is installed.

    :param folder: where the processes run and write their logs
    :param n_workers: the workers (named ``worker-0``, …)
    """
    distributed = pytest.importorskip("distributed")
    # The `dask` command of this interpreter's environment
    dask = [sys.executable, "-m", "dask"]
    address = f"tcp://127.0.0.1:{free_port()}"
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(REPO_ROOT), os.environ.get("PYTHONPATH", "")]),
        # The scheduler's and workers' scratch space, instead of /tmp/dask-scratch-space
        "DASK_TEMPORARY_DIRECTORY": str(folder),
    }
    folder.mkdir(parents=True, exist_ok=True)
    processes: list[subprocess.Popen] = []

    def start(name: str, *arguments: str) -> subprocess.Popen:
        with open(folder / f"{name}.log", "w") as log:
            process = subprocess.Popen([*dask, *arguments], cwd=folder, env=env, stdout=log, stderr=subprocess.STDOUT)
        processes.append(process)
        return process

    client = None
    try:
        start("scheduler", "scheduler", "--host", "127.0.0.1", "--port", address.rpartition(":")[2], "--no-dashboard")
        # --no-nanny: each worker is the process started, and killing it kills the worker
        options = ("--nthreads", "1", "--no-dashboard", "--no-nanny")
        workers = {
            f"worker-{i}": start(f"worker-{i}", "worker", address, "--name", f"worker-{i}", *options) for i in range(n_workers)
        }
        client = distributed.Client(address, timeout=60, set_as_default=False)
        client.wait_for_workers(n_workers, timeout=60)
        yield Cluster(address, client, workers, folder)
    finally:
        if client is not None:
            client.close()
        # Nothing to save: killed, not shut down gracefully (which takes seconds)
        for process in processes:
            process.kill()
            process.wait()


def benchmark_command(cache_dir: Path, *options: str) -> list[str]:
    """:return: ``python -m benchmarks.run`` with ``options``, its cache in ``cache_dir``, its report next to it"""
    folders = ("--cache-dir", str(cache_dir), "--results-dir", str(cache_dir.with_name(cache_dir.name + "-results")))
    return [sys.executable, "-m", "benchmarks.run", *SMALL, *folders, *options]


def assert_same_results(spec: RunSpec, cache_dir: Path, reference_dir: Path) -> None:
    """The cached run of ``spec`` in ``cache_dir`` is the one in ``reference_dir``: same files, episodes, evaluations."""
    run_dir, reference = spec.run_dir(cache_dir), spec.run_dir(reference_dir)
    assert sorted(path.relative_to(run_dir) for path in run_dir.rglob("*")) == sorted(
        path.relative_to(reference) for path in reference.rglob("*")
    )
    for name in (EPISODES_FILE, EVALUATIONS_FILE):
        pd.testing.assert_frame_equal(pd.read_csv(run_dir / name), pd.read_csv(reference / name))
    summary, expected = load_run(run_dir), load_run(reference)
    for key in ("key", "versions", "num_timesteps", "n_episodes", "n_envs"):
        assert summary[key] == expected[key], key


def progress_events(cluster: Cluster) -> list[tuple[str, int, str]]:
    """:return: the progress the workers reported, ``(run name, env steps, worker address)``"""
    from sb3_classic.harness.cluster import PROGRESS_TOPIC

    return [tuple(message) for _, message in cluster.client.get_events(PROGRESS_TOPIC)]


def test_a_benchmark_on_a_cluster_gives_the_local_results(tmp_path: Path) -> None:
    specs = run.make_specs(
        run.Settings(seeds=1, peer_seeds=0, budgets={"CartPole-v1": 1000}, eval_freq=500, eval_episodes=2),
        ["CartPole-v1"],
        ["reinforce", "nstep_sarsa"],
    )
    for spec in specs:
        run_one(spec, tmp_path / "local")
    with dask_cluster(tmp_path / "cluster") as cluster:
        command = benchmark_command(
            tmp_path / "cache", "--budget", "1000", "--eval-freq", "500", "--scheduler", cluster.address
        )
        completed = subprocess.run(command, cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)
        assert completed.returncode == 0, completed.stdout + completed.stderr + cluster.worker_logs()
        events = progress_events(cluster)
        workers = set(cluster.client.scheduler_info()["workers"])
    assert "2 workers, 2 threads" in completed.stdout
    # The runs trained on the workers, which reported their progress, and came back to the client's cache
    assert {name for name, _, _ in events} == {spec.name for spec in specs}
    assert {address for _, _, address in events} <= workers
    assert len(list((tmp_path / "cache").rglob(RUN_FILE))) == len(specs)
    assert not list((tmp_path / "cache").rglob("*.partial"))
    for spec in specs:
        assert_same_results(spec, tmp_path / "cache", tmp_path / "local")
    assert pd.read_csv(tmp_path / "cache-results" / "learning-runs.csv")["algo"].tolist() == ["reinforce", "nstep_sarsa"]

    # Interrupted or not, the command resumes from its cache: nothing left to run, no cluster needed
    again = subprocess.run(
        benchmark_command(tmp_path / "cache", "--budget", "1000", "--eval-freq", "500", "--scheduler", "tcp://127.0.0.1:1"),
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert again.returncode == 0, again.stdout + again.stderr
    assert "2 runs: 2 cached, 0 to run" in again.stdout


def test_a_run_whose_worker_dies_runs_again(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    budget = 15_000
    # The killed worker cannot remove the temporary folder of the run it trained: in tmp_path, not the machine's /tmp
    (tmp_path / "tmp").mkdir()
    monkeypatch.setenv("TMPDIR", str(tmp_path / "tmp"))
    with dask_cluster(tmp_path / "cluster") as cluster:
        command = benchmark_command(
            tmp_path / "cache", "--algos", "reinforce", "--seeds", "2", "--budget", str(budget), "--eval-freq", "5000"
        )
        benchmark = subprocess.Popen(
            [*command, "--scheduler", cluster.address],
            cwd=REPO_ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        try:
            # Kill a worker while it trains a run: after its first progress report, before the run's middle
            deadline = time.monotonic() + 120
            victim = None
            while victim is None and time.monotonic() < deadline and benchmark.poll() is None:
                time.sleep(0.2)
                for name, steps, address in progress_events(cluster):
                    if steps < budget // 2 and cluster.client.processing().get(address):
                        victim = (name, address)
                        break
            assert victim is not None, "no run reported progress on a worker"
            killed_run, killed_worker = victim
            worker_name = cluster.client.scheduler_info()["workers"][killed_worker]["name"]
            cluster.workers[worker_name].kill()
            output, _ = benchmark.communicate(timeout=240)
        finally:
            benchmark.kill()
        events = progress_events(cluster)
        survivors = set(cluster.client.scheduler_info()["workers"])
    assert benchmark.returncode == 0, output + cluster.worker_logs()
    assert killed_worker not in survivors
    assert len(survivors) == 1
    # The killed run started again on the other worker, and finished there
    assert {address for name, _, address in events if name == killed_run} == {killed_worker, *survivors}
    assert max(steps for name, steps, address in events if name == killed_run and address in survivors) >= budget // 2
    # The two seeds trained in lockstep, one population: the whole population started again on the other worker
    specs = plan_lockstep(
        [RunSpec.create("reinforce", "CartPole-v1", seed, budget, eval_freq=5000, n_eval_episodes=2) for seed in (0, 1)]
    )
    assert all(spec.lockstep for spec in specs)
    assert len(list((tmp_path / "cache").rglob(RUN_FILE))) == len(specs)
    assert not list((tmp_path / "cache").rglob("*.partial"))
    for spec in specs:
        assert (spec.run_dir(tmp_path / "cache") / RUN_FILE).exists(), spec.name
    # The population done again is the one a local process trains
    for spec, result in zip(specs, execute_population(specs), strict=True):
        assert isinstance(result, RunResult)
        store_run(spec, tmp_path / "local", result)
    for spec in specs:
        assert_same_results(spec, tmp_path / "cache", tmp_path / "local")


def test_without_scheduler_dask_is_not_imported(tmp_path: Path) -> None:
    options = [*SMALL, "--algos", "nstep_sarsa", "--seeds", "1", "--budget", "300", "--eval-freq", "100", "--workers", "1"]
    options += ["--cache-dir", str(tmp_path / "cache"), "--results-dir", str(tmp_path / "results")]
    code = f"""
import sys
from benchmarks.run import main
status = main({options!r})
print("status", status)
cluster = ("benchmarks.cluster", "sb3_classic.harness.cluster")
dask = [name for name in sys.modules if name.split(".")[0] in ("dask", "distributed") or name in cluster]
print("imported", sorted(dask))
"""
    completed = subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)
    assert completed.returncode == 0, completed.stdout + completed.stderr
    assert "status 0\n" in completed.stdout
    assert "imported []\n" in completed.stdout
    assert len(list((tmp_path / "cache").rglob(RUN_FILE))) == 1


@pytest.fixture(scope="module")
def tiny_result() -> tuple[RunSpec, RunResult]:
    """One real run of 300 steps, as a worker returns it."""
    spec = RunSpec.create("reinforce", "CartPole-v1", seed=0, n_timesteps=300, eval_freq=100, n_eval_episodes=2)
    return spec, execute_run(spec)


def test_a_result_of_other_versions_is_refused(tiny_result: tuple[RunSpec, RunResult], tmp_path: Path) -> None:
    spec, result = tiny_result
    summary = {**result.summary, "key": "0123456789abcdef", "versions": {**code_versions("reinforce"), "torch": "1.0"}}
    other = RunResult(summary=summary, files=result.files, host="node7 (Dask worker tcp://10.0.0.7:4000)")
    with pytest.raises(ValueError, match=r"node7 \(Dask worker tcp://10.0.0.7:4000\) .*torch 1.0 there, "):
        store_run(spec, tmp_path, other)
    assert not list(tmp_path.iterdir())
    # The same result with this process's versions is cached, with the files of the run
    assert store_run(spec, tmp_path, result) == result.summary
    assert sorted(path.relative_to(spec.run_dir(tmp_path)).as_posix() for path in spec.run_dir(tmp_path).rglob("*.csv")) == [
        EPISODES_FILE,
        EVALUATIONS_FILE,
        *(f"zoo/reinforce/CartPole-v1_1/{rank}.monitor.csv" for rank in range(result.summary["n_envs"])),
    ]


def test_workers_with_other_versions_are_refused_before_any_run() -> None:
    cluster = pytest.importorskip("sb3_classic.harness.cluster")
    expected = cluster.worker_versions()

    class FakeClient:
        def run(self, function: Any, on_error: str) -> dict[str, object]:
            assert function is cluster.worker_versions
            assert on_error == "return"
            return {
                "tcp://10.0.0.1:4000": dict(expected),
                "tcp://10.0.0.2:4000": {**expected, "torch": "1.0"},
                "tcp://10.0.0.3:4000": ModuleNotFoundError("No module named 'sb3_classic'"),
            }

    with pytest.raises(cluster.ClusterError) as error:
        cluster.check_workers(FakeClient(), expected, "tcp://10.0.0.9:8786")
    message = str(error.value)
    assert message.startswith("--scheduler tcp://10.0.0.9:8786: workers refused")
    assert "tcp://10.0.0.1:4000" not in message
    assert f"worker tcp://10.0.0.2:4000: torch: {expected['torch']} on the client, 1.0 on the worker" in message
    assert "worker tcp://10.0.0.3:4000 cannot run the harness" in message
    assert "No module named 'sb3_classic'" in message

    class SameClient:
        def run(self, function: Any, on_error: str) -> dict[str, object]:
            return {"tcp://10.0.0.1:4000": dict(expected)}

    cluster.check_workers(SameClient(), expected, "tcp://10.0.0.9:8786")


def test_a_run_lost_with_its_workers_is_reported_not_missing(
    tiny_result: tuple[RunSpec, RunResult], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Seed 0 comes back, seed 1 fails as Dask fails a task whose workers all died: the command says which, exits 1."""
    spec, result = tiny_result

    class LostRuns:
        def __init__(self, lose_all: bool):
            self.lose_all = lose_all
            self.progress: queue.Queue[tuple[str, int]] = queue.Queue()

        def submit(self, submitted: RunSpec) -> "Future[RunResult]":
            future: Future[RunResult] = Future()
            if submitted == spec and not self.lose_all:
                future.set_result(result)
            else:
                future.set_exception(RuntimeError("Attempted to run task 'run_on_worker-1' on 4 different workers"))
            return future

        def cancel(self) -> None:
            pass

    monkeypatch.setattr(pool, "open_runs", lambda *args: nullcontext(LostRuns(lose_all=False)))
    # Each seed a job of its own (--separate), so that one is lost and the other comes back
    options = [*SMALL, "--algos", "reinforce", "--seeds", "2", "--budget", "300", "--eval-freq", "100", "--separate"]
    status = run.main([*options, "--cache-dir", str(tmp_path / "cache"), "--results-dir", str(tmp_path / "results")])
    output = capsys.readouterr().out
    assert status == 1
    assert "failed: REINFORCE CartPole-v1 seed 1: RuntimeError: Attempted to run task" in output
    assert "1 runs failed, not in the cache: REINFORCE CartPole-v1 seed 1" in output
    assert (spec.run_dir(tmp_path / "cache") / RUN_FILE).exists()

    # With no run cached at all: no report to draw, the same list and status
    monkeypatch.setattr(pool, "open_runs", lambda *args: nullcontext(LostRuns(lose_all=True)))
    status = run.main([*options, "--cache-dir", str(tmp_path / "empty"), "--results-dir", str(tmp_path / "results-empty")])
    output = capsys.readouterr().out
    assert status == 1
    assert "2 runs failed, not in the cache: REINFORCE CartPole-v1 seed 0, REINFORCE CartPole-v1 seed 1" in output
