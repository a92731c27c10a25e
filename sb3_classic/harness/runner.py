"""One learning run, built and trained by rl-zoo3's ExperimentManager, evaluated periodically, cached on disk."""

import argparse
import io
import json
import os
import platform
import shutil
import signal
import tempfile
import time
import traceback
from collections.abc import Sequence
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import pandas as pd
import torch as th
import yaml
from rl_zoo3.exp_manager import ExperimentManager
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback, EvalCallback, StopTrainingOnMaxEpisodes
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import sync_envs_normalization

from sb3_classic.harness.common import RunSpec, code_versions, env_spec, population_class, register_algorithms, split_env_id

#: Files of a finished run (the run directory appears, complete, only when the run has finished)
RUN_FILE = "run.json"
EPISODES_FILE = "episodes.csv"
EVALUATIONS_FILE = "evaluations.csv"


class ProgressQueue(Protocol):
    """Where a run reports its progress: a ``multiprocessing.Queue`` (or a ``queue.Queue`` in one process)."""

    def put(self, obj: tuple[str, int]) -> None:
        """:param obj: the run's name and its env steps so far"""


#: The queue of a worker process of the pool (set by ``init_worker``)
_worker_queue: ProgressQueue | None = None
#: In a pool process, the temporary folder of the run it is running (removed if the run is stopped)
_worker_scratch: str | None = None


class TimedEvalCallback(EvalCallback):
    """SB3's ``EvalCallback`` that also adds up the wall-clock time spent in it, to leave out of ``learn()``'s."""

    eval_time = 0.0

    def _on_step(self) -> bool:
        start = time.perf_counter()
        continue_training = super()._on_step()
        self.eval_time += time.perf_counter() - start
        return continue_training


class ProgressCallback(BaseCallback):
    """
    Report ``num_timesteps`` to the parent process now and then.

    With an episode budget, the run's progress is its episodes, reported in the units of the progress display (its
    step cap): ``episodes / max_episodes × n_timesteps``, so that the bars show the fraction of the budget done.

    :param name: the run's label
    :param queue: where to put ``(name, num_timesteps)``
    :param every: env steps (or their equivalent) between two reports
    :param max_episodes: the run's episode budget, if it has one
    :param n_timesteps: its step cap (with ``max_episodes``)
    """

    def __init__(self, name: str, queue: ProgressQueue, every: int, max_episodes: int | None = None, n_timesteps: int = 0):
        super().__init__()
        self.name = name
        self.queue = queue
        self.every = every
        self.max_episodes = max_episodes
        self.n_timesteps = n_timesteps
        self._episodes = 0
        self._last = 0

    def _on_training_start(self) -> None:
        # Its bar shows as soon as its model is built and it starts training, not at its first share of the budget
        self.queue.put((self.name, 0))

    def _on_step(self) -> bool:
        if self.max_episodes is None:
            done = self.num_timesteps
        else:
            self._episodes += int(np.sum(self.locals["dones"]))
            done = min(self._episodes, self.max_episodes) * self.n_timesteps // self.max_episodes
        if done - self._last >= self.every:
            self._last = done
            self.queue.put((self.name, done))
        return True


def episodes_from_monitors(monitor_dir: Path, n_envs: int) -> pd.DataFrame:
    """
    The training episodes of all envs, in the order they ended, from the Monitor files of a run
    (``<rank>.monitor.csv``, one per env).

    The envs of a ``DummyVecEnv`` step in lockstep: when env ``i`` has taken ``k`` steps, the run has taken
    ``k * n_envs``. So the env step at which an episode ended is its env's cumulative episode length times ``n_envs``.

    :param monitor_dir: the folder of the Monitor files
    :param n_envs: the number of envs of the run
    :return: one row per episode: ``episode`` (1-based, in end order), ``env_rank``, ``return``, ``length``,
        ``end_step``
    """
    frames = []
    for rank in range(n_envs):
        monitor = pd.read_csv(monitor_dir / f"{rank}.{Monitor.EXT}", skiprows=1)
        frames.append(
            pd.DataFrame(
                {
                    "env_rank": rank,
                    "return": monitor["r"].astype(float),
                    "length": monitor["l"].astype(int),
                    "end_step": monitor["l"].cumsum().astype(int) * n_envs,
                }
            )
        )
    episodes = pd.concat(frames, ignore_index=True).sort_values(["end_step", "env_rank"], kind="stable")
    episodes.insert(0, "episode", np.arange(1, len(episodes) + 1))
    return episodes.reset_index(drop=True)


def evaluations_frame(timesteps: list[int], returns: list[list[float]], lengths: list[list[int]]) -> pd.DataFrame:
    """
    :return: one row per evaluation episode: ``eval_index`` (0-based), ``timesteps``, ``return``, ``length``
    """
    rows = [
        {"eval_index": index, "timesteps": step, "return": float(episode_return), "length": int(length)}
        for index, (step, episode_returns, episode_lengths) in enumerate(zip(timesteps, returns, lengths, strict=True))
        for episode_return, length in zip(episode_returns, episode_lengths, strict=True)
    ]
    return pd.DataFrame(rows, columns=["eval_index", "timesteps", "return", "length"])


class DamagedRunError(ValueError):
    """A cached run whose files cannot be read (cut short, emptied, deleted): the message names its folder and the fix."""


def _damaged(run_dir: Path, what: str) -> DamagedRunError:
    return DamagedRunError(
        f"The cached run in {run_dir} is damaged ({what}): delete that folder and run the command again to rerun it"
    )


def load_run(run_dir: Path) -> dict[str, Any]:
    """
    :return: the summary (``run.json``) of a finished run
    :raise DamagedRunError: if it cannot be read
    """
    try:
        summary = json.loads((run_dir / RUN_FILE).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise _damaged(run_dir, f"{RUN_FILE}: {error}") from error
    if not isinstance(summary, dict):
        raise _damaged(run_dir, f"{RUN_FILE} holds {type(summary).__name__}, not a run's summary")
    return summary


def load_run_table(run_dir: Path, name: str, min_rows: int = 0) -> pd.DataFrame:
    """
    :param run_dir: a finished run's folder
    :param name: ``EPISODES_FILE`` or ``EVALUATIONS_FILE``
    :param min_rows: rows it must have at least (an episode budget's episodes)
    :return: the table
    :raise DamagedRunError: if it cannot be read, or has fewer rows
    """
    try:
        table = pd.read_csv(run_dir / name)
    except (OSError, UnicodeDecodeError, pd.errors.ParserError, pd.errors.EmptyDataError) as error:
        raise _damaged(run_dir, f"{name}: {error}") from error
    if len(table) < min_rows:
        raise _damaged(run_dir, f"{name} has {len(table)} rows, fewer than the {min_rows} of its budget")
    return table


@dataclass
class RunResult:
    """
    A finished run, as it travels from where it trained (a pool process, a Dask worker) to the process that caches it.

    :param summary: the run's summary (``run.json``)
    :param files: every file of the run's folder, by path relative to it (``run.json``, ``episodes.csv``,
        ``evaluations.csv``, ``hyperparams.yml``, ``train.log``, the zoo's folder)
    :param host: the machine it trained on (and the Dask worker, if any)
    """

    summary: dict[str, Any]
    files: dict[str, bytes]
    host: str


class RunError(RuntimeError):
    """
    A run that raised: its message names the error and the machine, and it carries the run's ``train.log``.

    :param message: what failed
    :param log: the run's log (the zoo's output and the traceback)
    """

    def __init__(self, message: str, log: str):
        super().__init__(message)
        self.log = log

    def __reduce__(self) -> tuple[type["RunError"], tuple[str, str]]:
        # Pickled back to the parent process or the Dask client with its log
        return type(self), (str(self), self.log)


class ClusterError(RuntimeError):
    """The Dask cluster of ``--scheduler`` cannot run the runs: unreachable, or workers with other versions."""


def run_one(spec: RunSpec, cache_dir: Path, queue: ProgressQueue | None = None) -> dict[str, Any]:
    """
    Train ``spec`` unless it is cached, and cache it: ``run.json`` (settings, versions, timings),
    ``episodes.csv`` (training episodes, from the Monitor files), ``evaluations.csv`` (the periodic deterministic
    evaluations, and one at the end of training), ``hyperparams.yml``, ``train.log`` and the zoo's folder.

    :param spec: the run
    :param cache_dir: the cache root
    :param queue: where to report progress (the run's name and its env steps), if anywhere
    :return: the run's summary (``run.json``)
    """
    run_dir = spec.run_dir(cache_dir)
    if (run_dir / RUN_FILE).exists():
        return load_run(run_dir)
    return store_run(spec, cache_dir, execute_run(spec, queue))


def execute_run(spec: RunSpec, queue: ProgressQueue | None = None, host: str | None = None) -> RunResult:
    """
    Train ``spec`` in a temporary folder and return the contents of its files: wherever it runs, the process that
    called ``store_run`` writes the cache (Dask workers need no filesystem shared with it).

    :param spec: the run
    :param queue: where to report progress (the run's name and its env steps), if anywhere
    :param host: the machine it runs on, for messages (default: its hostname)
    :return: the run's summary and files
    :raise RunError: if training failed (with the run's log)
    """
    host = host or platform.node()
    global _worker_scratch
    with tempfile.TemporaryDirectory(prefix="sb3-classic-run-") as scratch:
        _worker_scratch = scratch
        folder = Path(scratch)
        config = _write_config(spec, folder)
        th.set_num_threads(1)
        with open(folder / "train.log", "w") as log:
            try:
                with redirect_stdout(log), redirect_stderr(log):
                    summary = _train(spec, folder, config, queue)
            except Exception as error:
                log.write(traceback.format_exc())
                log.close()
                message = f"{error!r} on {host}"
                raise RunError(message, (folder / "train.log").read_text(errors="replace")) from error
        (folder / RUN_FILE).write_text(json.dumps(summary, indent=2, sort_keys=True))
        files = {path.relative_to(folder).as_posix(): path.read_bytes() for path in folder.rglob("*") if path.is_file()}
    return RunResult(summary=summary, files=files, host=host)


def execute_population(
    specs: Sequence[RunSpec], queue: ProgressQueue | None = None, host: str | None = None
) -> list[RunResult | RunError]:
    """
    Train the lockstep runs of one setting (its seeds) as one population of their algorithm (``lockstep``), each run
    with its own model, envs, callbacks and temporary folder built as ``execute_run`` builds them, and return each
    run's files as ``execute_run`` does: the cache does not know which way a run was trained but from its key and its
    ``run.json`` (``training``: ``"lockstep"``, ``population``: K). Each run's ``learn_time_s`` is its share, 1/K, of
    the population's ``learn()`` (without the members' periodic evaluations), and its ``train.log`` the population's.

    :param specs: the runs, of one setting (``RunSpec.setting_key``), marked ``lockstep``
    :param queue: where to report progress (each run's name and its env steps), if anywhere
    :param host: the machine it runs on, for messages (default: its hostname)
    :return: each run's result, or its ``RunError`` (a member stopped by its env's NaN; every member's, if the
        population failed as a whole)
    :raise ValueError: for runs of different settings, or not marked ``lockstep``
    """
    if len({spec.setting_key() for spec in specs}) != 1 or not all(spec.lockstep for spec in specs):
        raise ValueError("execute_population trains the lockstep runs of one setting: use lockstep_jobs to group them")
    host = host or platform.node()
    global _worker_scratch
    with tempfile.TemporaryDirectory(prefix="sb3-classic-population-") as scratch:
        _worker_scratch = scratch
        root = Path(scratch)
        th.set_num_threads(1)
        log_path = root / "train.log"
        with open(log_path, "w") as log:
            try:
                with redirect_stdout(log), redirect_stderr(log):
                    outcomes = _train_population(specs, root, queue)
            except Exception as error:
                log.write(traceback.format_exc())
                log.close()
                text = log_path.read_text(errors="replace")
                return [RunError(f"{error!r} on {host} (a population of {len(specs)} seeds)", text) for _ in specs]
        text = log_path.read_text(errors="replace")
        results: list[RunResult | RunError] = []
        for folder, outcome in outcomes:
            if isinstance(outcome, Exception):
                results.append(RunError(f"{outcome!r} on {host}", text))
                continue
            (folder / "train.log").write_text(text)
            (folder / RUN_FILE).write_text(json.dumps(outcome, indent=2, sort_keys=True))
            files = {path.relative_to(folder).as_posix(): path.read_bytes() for path in folder.rglob("*") if path.is_file()}
            results.append(RunResult(summary=outcome, files=files, host=host))
    return results


def _train_population(
    specs: Sequence[RunSpec], root: Path, queue: ProgressQueue | None
) -> list[tuple[Path, dict[str, Any] | Exception]]:
    """:return: each member's folder, and its summary or the error that stopped it"""
    trainings = []
    for spec in specs:
        folder = root / f"seed_{spec.seed}"
        folder.mkdir()
        trainings.append(_prepare(spec, folder, _write_config(spec, folder), queue))
    population = population_class(specs[0].algo)
    if population is None:
        raise ValueError(f"{specs[0].algo} has no population class to train in lockstep: train its runs alone")
    population = population([training.model for training in trainings])
    member_errors: dict[int, Exception] = {}
    start = time.perf_counter()
    try:
        population.learn(specs[0].n_timesteps, callback=[training.callbacks for training in trainings])
    except ValueError as error:
        # Members stopped by their envs' NaN (the population's MemberError): the others trained to the end
        stopped = getattr(error, "member_errors", None)
        if not isinstance(stopped, dict):
            raise
        member_errors.update(stopped)
    learn_time = time.perf_counter() - start - sum(training.evaluation.eval_time for training in trainings)
    how = {"training": "lockstep", "population": len(specs)}
    outcomes: list[tuple[Path, dict[str, Any] | Exception]] = []
    for k, training in enumerate(trainings):
        outcome: dict[str, Any] | Exception
        if k in member_errors:
            outcome = member_errors[k]
            assert training.model.env is not None
            training.model.env.close()
            training.eval_env.close()
        else:
            try:
                outcome = _summary(training, learn_time / len(specs), how)
            except RuntimeError as error:
                outcome = error
        outcomes.append((training.folder, outcome))
    return outcomes


def _version_differences(reference: dict[str, str], reference_label: str, other: dict[str, str], other_label: str) -> str:
    """:return: ``"name <other's> <other_label>, <reference's> <reference_label>"`` for each version that differs"""
    return ", ".join(
        f"{name} {other.get(name, 'missing')} {other_label}, {version} {reference_label}"
        for name, version in reference.items()
        if other.get(name) != version
    )


def store_run(spec: RunSpec, cache_dir: Path, result: RunResult) -> dict[str, Any]:
    """
    Write a finished run into the cache. The folder is built in ``<run dir>.partial`` and renamed when complete:
    an interrupted benchmark leaves no partial cache entry.

    :param spec: the run
    :param cache_dir: the cache root
    :param result: what ``execute_run`` returned for ``spec``
    :return: the run's summary (``run.json``)
    :raise ValueError: if the run was trained with other code versions than this process's (its cache key differs)
    """
    if result.summary["key"] != spec.key():
        differences = _version_differences(code_versions(spec.algo), "here", result.summary["versions"], "there")
        raise ValueError(
            f"{spec.name} was trained on {result.host} with other versions than this process's "
            f"({differences or 'its cache key differs'}): install the same versions there, or run it here"
        )
    run_dir = spec.run_dir(cache_dir)
    partial = run_dir.with_name(run_dir.name + ".partial")
    shutil.rmtree(partial, ignore_errors=True)
    for name, content in result.files.items():
        path = partial / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(content)
    shutil.rmtree(run_dir, ignore_errors=True)
    partial.rename(run_dir)
    return result.summary


def store_failure(spec: RunSpec, cache_dir: Path, log: str) -> Path:
    """
    Keep the log of a failed run where the cache has its partial folder, for the user to read.

    :param spec: the run
    :param cache_dir: the cache root
    :param log: its ``train.log``
    :return: the log's path
    """
    run_dir = spec.run_dir(cache_dir)
    partial = run_dir.with_name(run_dir.name + ".partial")
    shutil.rmtree(partial, ignore_errors=True)
    partial.mkdir(parents=True)
    path = partial / "train.log"
    path.write_text(log)
    return path


def init_worker(queue: ProgressQueue) -> None:
    """
    Initializer of the pool's processes: a multiprocessing queue reaches them at process start only. A Ctrl-C is the
    parent's to handle (it stops the pool: ``pool.PoolRuns.cancel``), and the SIGTERM it stops a run with unwinds the
    run (its temporary folder removed) instead of killing the process where it stands.

    :param queue: where ``run_in_worker`` reports progress
    """
    global _worker_queue
    _worker_queue = queue
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _exit_on_sigterm)


def _exit_on_sigterm(signum: int, frame: Any) -> None:
    # At once (an exception would be the run's result, and the worker would take the next run), without the
    # temporary folder of the run it stops
    if _worker_scratch is not None:
        shutil.rmtree(_worker_scratch, ignore_errors=True)
    os._exit(128 + signum)


def run_in_worker(spec: RunSpec, expected: dict[str, str] | None = None) -> RunResult:
    """
    ``execute_run`` in a pool process, reporting progress to the queue of ``init_worker``.

    :param spec: the run
    :param expected: the command's ``code_versions`` when it started, if they are to be checked first
    :return: the run's summary and files
    :raise ValueError: if this process's versions differ from ``expected`` (the package's sources were edited since
        the command started: its result would have been refused by ``store_run`` after training)
    """
    _check_versions(spec, expected)
    return execute_run(spec, _worker_queue)


def run_population_in_worker(specs: Sequence[RunSpec], expected: dict[str, str] | None = None) -> list[RunResult | RunError]:
    """
    ``execute_population`` in a pool process, reporting progress to the queue of ``init_worker``.

    :param specs: the lockstep runs of one setting
    :param expected: the command's ``code_versions`` when it started, if they are to be checked first
    :return: each run's result or error
    :raise ValueError: if this process's versions differ from ``expected`` (see ``run_in_worker``)
    """
    _check_versions(specs[0], expected)
    return execute_population(specs, _worker_queue)


def _check_versions(spec: RunSpec, expected: dict[str, str] | None) -> None:
    found = code_versions(spec.algo)
    if expected is not None and found != expected:
        differences = _version_differences(expected, "when the command started", found, "now")
        raise ValueError(
            f"{spec.name} was not trained: the installed code changed since this command started ({differences}: its "
            "sources were edited, or another version installed), and a result of other code than the command's is not "
            "cached. Run the command again once the code is settled: the finished runs are cached"
        )


def check_run(spec: RunSpec) -> None:
    """
    Build the run's envs and model as ``execute_run`` does (rl-zoo3's ``ExperimentManager``), without training: a
    setting the zoo or the algorithm rejects (an unknown policy or ``policy_kwargs`` key, a value out of its range)
    fails here in a second, before any run starts.

    :param spec: the run
    :raise RunError: with the error the zoo or the algorithm raised, and the log of the attempt
    """
    log = io.StringIO()
    try:
        with redirect_stdout(log), redirect_stderr(log):
            model = built_model(spec)
            assert model.env is not None
            model.env.close()
    except Exception as error:
        raise RunError(f"{type(error).__name__}: {error}", log.getvalue() + traceback.format_exc()) from error


def built_model(spec: RunSpec) -> BaseAlgorithm:
    """
    :param spec: a run
    :return: its model, with its envs, built as ``execute_run`` builds it (rl-zoo3's ``ExperimentManager``), not
        trained; the caller closes ``model.env``
    :raise Exception: what the zoo or the algorithm raised for the setting
    """
    with tempfile.TemporaryDirectory(prefix="sb3-classic-check-") as scratch:
        folder = Path(scratch)
        config = _write_config(spec, folder)
        setup = _experiment_manager(spec, folder, config).setup_experiment()
        assert setup is not None, "the ExperimentManager only returns None when optimizing hyperparameters"
        model, _ = setup
        return model


def _write_config(spec: RunSpec, folder: Path) -> Path:
    """:return: the zoo YAML of the run's exact entry (the source YAML may be edited meanwhile), written in ``folder``"""
    register_algorithms()
    config = folder / "hyperparams.yml"
    config.write_text(yaml.safe_dump({split_env_id(spec.env_id)[1]: spec.hyperparams}, sort_keys=True))
    return config


def _experiment_manager(spec: RunSpec, folder: Path, config: Path) -> ExperimentManager:
    # A module:EnvId id: the module registers the env in this process (a worker's too), and the zoo gets the id of the
    # registry (its ExperimentManager looks the env up with gymnasium.spec, which imports nothing)
    env_spec(spec.env_id)
    return ExperimentManager(
        argparse.Namespace(),
        spec.algo,
        split_env_id(spec.env_id)[1],
        str(folder / "zoo"),
        n_timesteps=spec.n_timesteps,
        # The harness adds its own evaluation below, timed apart from learning
        eval_freq=0,
        seed=spec.seed,
        # The algorithm's default log interval, as the zoo's command line
        log_interval=-1,
        verbose=0,
        device="cpu",
        config=str(config),
    )


@dataclass
class _Training:
    """A run set up to train: its model, envs and callbacks (``_prepare``), and what ``_summary`` reads after ``learn``."""

    spec: RunSpec
    folder: Path
    exp_manager: ExperimentManager
    model: BaseAlgorithm
    eval_env: Any
    evaluation: TimedEvalCallback
    callbacks: list[BaseCallback]


def _prepare(spec: RunSpec, folder: Path, config: Path, queue: ProgressQueue | None) -> _Training:
    """:return: the run's model (rl-zoo3's ``ExperimentManager``), its evaluation env and its callbacks"""
    exp_manager = _experiment_manager(spec, folder, config)
    setup = exp_manager.setup_experiment()
    assert setup is not None, "the ExperimentManager only returns None when optimizing hyperparameters"
    model, _ = setup
    n_envs = exp_manager.n_envs
    # The zoo gives a YAML's env_kwargs to the training envs only (its evaluation envs take the command line's
    # --eval-env-kwargs, none here): the run is evaluated on the env it trains on
    exp_manager.eval_env_kwargs = exp_manager.env_kwargs
    # One env per evaluation episode (up to 16): the episodes of an evaluation run side by side
    eval_env = exp_manager.create_envs(min(spec.n_eval_episodes, 16), eval_env=True)
    evaluation = TimedEvalCallback(
        eval_env,
        n_eval_episodes=spec.n_eval_episodes,
        # Counted in calls, one per step of all envs (as the zoo does); eval_freq 0: only the final evaluation
        eval_freq=max(spec.eval_freq // n_envs, 1) if spec.eval_freq > 0 else spec.n_timesteps + 1,
        # The callback keeps its results only with a log path (it writes evaluations.npz there)
        log_path=str(folder),
        deterministic=exp_manager.deterministic_eval,
        verbose=0,
    )
    callbacks: list[BaseCallback] = [*exp_manager.callbacks, evaluation]
    if spec.max_episodes is not None:
        # SB3's callback counts episodes per env (max_episodes × n_envs in all): at least the budget, all envs together
        callbacks.append(StopTrainingOnMaxEpisodes(-(-spec.max_episodes // n_envs)))
    if queue is not None:
        every = max(spec.n_timesteps // 200, 1)
        callbacks.append(ProgressCallback(spec.name, queue, every, spec.max_episodes, spec.n_timesteps))
    return _Training(spec, folder, exp_manager, model, eval_env, evaluation, callbacks)


def _train(spec: RunSpec, folder: Path, config: Path, queue: ProgressQueue | None) -> dict[str, Any]:
    training = _prepare(spec, folder, config, queue)
    # model.learn, not exp_manager.learn: the zoo's swallows KeyboardInterrupt, and an interrupted run must not be cached
    start = time.perf_counter()
    training.model.learn(spec.n_timesteps, callback=training.callbacks)
    learn_wall_time = time.perf_counter() - start
    return _summary(training, learn_wall_time - training.evaluation.eval_time, {"training": "alone"})


def _summary(training: _Training, learn_time: float, how: dict[str, Any]) -> dict[str, Any]:
    """
    The end of a run after ``learn``: its final evaluation, its episodes and evaluations written to its folder.

    :param training: the run
    :param learn_time: the wall-clock seconds of its ``learn()``, without its periodic evaluations
    :param how: how it was trained (``training``: ``"alone"`` or ``"lockstep"``, and the population's size)
    :return: its summary (``run.json``)
    :raise RuntimeError: if it stopped before its budget
    """
    spec, model, evaluation, folder = training.spec, training.model, training.evaluation, training.folder
    n_envs = training.exp_manager.n_envs
    if spec.max_episodes is None and model.num_timesteps < spec.n_timesteps:
        raise RuntimeError(f"{spec.name} stopped at {model.num_timesteps} of {spec.n_timesteps} steps")
    final_eval_time = _final_evaluation(model, evaluation)
    assert model.env is not None
    model.env.close()
    training.eval_env.close()

    episodes = episodes_from_monitors(Path(training.exp_manager.save_path), n_envs)
    if spec.max_episodes is not None and len(episodes) < spec.max_episodes:
        raise RuntimeError(
            f"{spec.name} reached its step cap ({spec.n_timesteps} env steps) after {len(episodes)} of its "
            f"{spec.max_episodes} episodes: raise the cap (in a study file, budget: {{episodes: "
            f"{spec.max_episodes}, max_steps: ...}})"
        )
    episodes.to_csv(folder / EPISODES_FILE, index=False)
    evaluations = evaluations_frame(
        evaluation.evaluations_timesteps, evaluation.evaluations_results, evaluation.evaluations_length
    )
    evaluations.to_csv(folder / EVALUATIONS_FILE, index=False)
    return {
        "algo": spec.algo,
        "env_id": spec.env_id,
        "seed": spec.seed,
        "n_timesteps": spec.n_timesteps,
        "eval_freq": spec.eval_freq,
        "n_eval_episodes": spec.n_eval_episodes,
        "max_episodes": spec.max_episodes,
        "key": spec.key(),
        "hyperparams": spec.hyperparams,
        "versions": code_versions(spec.algo),
        "n_envs": n_envs,
        "num_timesteps": int(model.num_timesteps),
        "n_episodes": len(episodes),
        "learn_time_s": learn_time,
        "eval_time_s": evaluation.eval_time + final_eval_time,
        "steps_per_s": model.num_timesteps / learn_time,
        "torch_threads": th.get_num_threads(),
        "machine": f"{platform.machine()} {platform.processor() or platform.platform()}",
        "finished": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        **how,
    }


def _final_evaluation(model: BaseAlgorithm, evaluation: TimedEvalCallback) -> float:
    """
    Evaluate the trained model once more unless the last periodic evaluation was at the end of training,
    so that every run's last evaluation is of its final model.

    :return: the time it took
    """
    if evaluation.evaluations_timesteps and evaluation.evaluations_timesteps[-1] == model.num_timesteps:
        return 0.0
    start = time.perf_counter()
    training_env = model.get_env()
    if model.get_vec_normalize_env() is not None and training_env is not None:
        sync_envs_normalization(training_env, evaluation.eval_env)
    returns, lengths = evaluate_policy(
        model,
        evaluation.eval_env,
        n_eval_episodes=evaluation.n_eval_episodes,
        deterministic=evaluation.deterministic,
        return_episode_rewards=True,
    )
    assert isinstance(returns, list), "evaluate_policy returns lists with return_episode_rewards=True"
    assert isinstance(lengths, list)
    evaluation.evaluations_timesteps.append(model.num_timesteps)
    evaluation.evaluations_results.append(returns)
    evaluation.evaluations_length.append(lengths)
    return time.perf_counter() - start
