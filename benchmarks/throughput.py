"""
Throughput of ``learn()``: env steps per second of REINFORCE and NStepSARSA divided by A2C's, on the same env with
the same network size, measured in one process, interleaved and repeated so that the machine's noise cancels; and
where each ``learn()`` spends its time (the envs' ``step``, ``train()``, and the rest of the rollout loop).

Run it alone with ``python -m benchmarks.throughput`` (``python -m benchmarks.run`` runs it after the learning runs).
"""

import argparse
import functools
import shlex
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass, field
from io import StringIO
from pathlib import Path
from typing import Any, TypeVar

import pandas as pd
import torch as th
from rich.console import Console
from rich.progress import Progress
from rl_zoo3.exp_manager import ExperimentManager
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm

from benchmarks.common import DEFAULT_RESULTS_DIR, ENV_IDS, QUICK_RESULTS_DIR, overrides_from_args
from benchmarks.report import markdown_table
from sb3_classic.harness.common import (
    LABELS,
    code_versions,
    hyperparams_path,
    load_hyperparams,
    positive_int,
    register_algorithms,
)

THROUGHPUT_ALGOS = ("a2c", "reinforce", "nstep_sarsa")
BASELINE = "a2c"
NET_ARCH = [64, 64]
#: The target with the tuned settings: at least this many times A2C's env steps per second
TARGET_RATIO = 2.0

T = TypeVar("T")


@dataclass(frozen=True)
class ThroughputSettings:
    """
    :param env_ids: the envs
    :param n_envs: the numbers of envs to measure with
    :param steps: env steps of each timed ``learn()``
    :param repeats: timed ``learn()`` calls per algorithm, env and number of envs
    :param overrides: per algorithm, keys replacing those of its YAML entries (``--set``; ``parse_overrides``)
    """

    env_ids: tuple[str, ...] = ENV_IDS
    n_envs: tuple[int, ...] = (1, 8)
    steps: int = 20_000
    repeats: int = 5
    overrides: dict[str, dict[str, Any]] = field(default_factory=dict)


def throughput_hyperparams(
    algo: str, env_id: str, n_envs: int, overrides: dict[str, dict[str, Any]] | None = None
) -> dict[str, Any]:
    """
    The overrides of the zoo YAML entry for the throughput runs: ``n_envs``, no ``VecNormalize``, and
    ``net_arch=[64, 64]`` with the entry's other ``policy_kwargs``; and the algorithm's changes of ``--set``.

    :param algo: the algorithm
    :param env_id: the env
    :param n_envs: the number of envs
    :param overrides: per algorithm, keys replacing those of its YAML entry (the throughput's own three win)
    :return: the overrides (``policy_kwargs`` as a string, for the zoo to evaluate as it does the YAML's)
    """
    yaml_kwargs = load_hyperparams(algo, env_id).get("policy_kwargs")
    # A dict display overriding the YAML's net_arch (a string too: the zoo evaluates it as it does the YAML's)
    policy_kwargs = f"{{**{yaml_kwargs or 'dict()'}, 'net_arch': {NET_ARCH}}}"
    return {**(overrides or {}).get(algo, {}), "n_envs": n_envs, "normalize": False, "policy_kwargs": policy_kwargs}


def build_model(
    algo: str, env_id: str, n_envs: int, seed: int, log_folder: Path, overrides: dict[str, dict[str, Any]] | None = None
) -> BaseAlgorithm:
    """
    :return: ``algo`` on ``n_envs`` copies of ``env_id``, built by rl-zoo3 from its YAML and ``throughput_hyperparams``
    """
    exp_manager = ExperimentManager(
        argparse.Namespace(),
        algo,
        env_id,
        str(log_folder),
        hyperparams=throughput_hyperparams(algo, env_id, n_envs, overrides),
        eval_freq=0,
        seed=seed,
        log_interval=-1,
        verbose=0,
        device="cpu",
        config=str(hyperparams_path(algo)),
    )
    with redirect_stdout(StringIO()), redirect_stderr(StringIO()):
        setup = exp_manager.setup_experiment()
    assert setup is not None
    return setup[0]


def timed(function: Callable[..., T], timers: dict[str, float], key: str) -> Callable[..., T]:
    """:return: ``function``, adding the seconds each call takes to ``timers[key]``"""

    @functools.wraps(function)
    def wrapper(*args: Any, **kwargs: Any) -> T:
        start = time.perf_counter()
        try:
            return function(*args, **kwargs)
        finally:
            timers[key] += time.perf_counter() - start

    return wrapper


def measure(
    algo: str,
    env_id: str,
    n_envs: int,
    steps: int,
    seed: int,
    log_folder: Path,
    overrides: dict[str, dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """
    Time ``learn(steps)`` of a new model (its construction is not timed), and the parts of it spent in the envs'
    ``step`` and in ``train()``.

    :param overrides: per algorithm, keys replacing those of its YAML entry (``ThroughputSettings.overrides``)
    :return: the measurement: ``algo``, ``env_id``, ``n_envs``, ``seed``, ``steps`` (taken), ``seconds``, ``env_s``,
        ``train_s``, ``steps_per_s``
    """
    model = build_model(algo, env_id, n_envs, seed, log_folder, overrides)
    env = model.env
    assert env is not None
    assert isinstance(model, OnPolicyAlgorithm)
    timers = {"env_s": 0.0, "train_s": 0.0}
    # Every on-policy loop steps self.env, and learn() calls self.train
    env.step = timed(env.step, timers, "env_s")  # type: ignore[method-assign]
    model.train = timed(model.train, timers, "train_s")  # type: ignore[method-assign]
    start = time.perf_counter()
    model.learn(steps)
    seconds = time.perf_counter() - start
    env.close()
    return {
        "algo": algo,
        "env_id": env_id,
        "n_envs": n_envs,
        "seed": seed,
        "steps": model.num_timesteps,
        "seconds": seconds,
        **timers,
        "steps_per_s": model.num_timesteps / seconds,
    }


def run_throughput(settings: ThroughputSettings, console: Console | None = None) -> pd.DataFrame:
    """
    Measure every algorithm ``settings.repeats`` times per env and number of envs. Within a repeat the algorithms
    run back to back, in an order that rotates between repeats, so each ratio compares neighbours in time.

    :param settings: what to measure
    :param console: where to show progress
    :return: one row per measurement (see ``measure``), with its ``repeat``
    """
    th.set_num_threads(1)
    register_algorithms()
    rows = []
    n_algos = len(THROUGHPUT_ALGOS)
    total = len(settings.env_ids) * len(settings.n_envs) * n_algos * (settings.repeats + 1)
    with tempfile.TemporaryDirectory() as folder, Progress(console=console, transient=True) as progress:
        task = progress.add_task("throughput", total=total)
        for env_id in settings.env_ids:
            for n_envs in settings.n_envs:
                for algo in THROUGHPUT_ALGOS:
                    # Warm-up, not recorded: first calls, lazy imports, allocator
                    progress.update(task, description=f"warm-up {LABELS[algo]} {env_id} n_envs={n_envs}")
                    measure(algo, env_id, n_envs, min(settings.steps, 1000), 0, Path(folder), settings.overrides)
                    progress.advance(task)
                for repeat in range(settings.repeats):
                    shift = repeat % n_algos
                    for algo in THROUGHPUT_ALGOS[shift:] + THROUGHPUT_ALGOS[:shift]:
                        progress.update(task, description=f"{LABELS[algo]} {env_id} n_envs={n_envs} repeat {repeat + 1}")
                        measured = measure(algo, env_id, n_envs, settings.steps, repeat, Path(folder), settings.overrides)
                        rows.append({**measured, "repeat": repeat})
                        progress.advance(task)
    return pd.DataFrame(rows)


def throughput_ratios(measurements: pd.DataFrame) -> pd.DataFrame:
    """
    :param measurements: ``run_throughput``'s rows
    :return: per env, number of envs and algorithm: the median steps/s over repeats, and the steps/s divided by A2C's
        of the same repeat (median, min and max over repeats)
    """
    steps_per_s = measurements.pivot_table(index=["env_id", "n_envs", "repeat"], columns="algo", values="steps_per_s")
    ratios = steps_per_s.div(steps_per_s[BASELINE], axis=0)
    by_setting = ["env_id", "n_envs"]
    summary = pd.concat(
        {
            "steps_per_s": steps_per_s.groupby(level=by_setting, sort=False).median().stack(),
            "ratio": ratios.groupby(level=by_setting, sort=False).median().stack(),
            "ratio_min": ratios.groupby(level=by_setting, sort=False).min().stack(),
            "ratio_max": ratios.groupby(level=by_setting, sort=False).max().stack(),
        },
        axis=1,
    )
    return summary.reset_index()


def throughput_table(measurements: pd.DataFrame) -> pd.DataFrame:
    """
    :param measurements: ``run_throughput``'s rows
    :return: one row per env and number of envs: each algorithm's median steps/s, ours divided by A2C's as
        median (min–max) over repeats, and whether the median meets the target
    """
    summary = throughput_ratios(measurements).set_index(["env_id", "n_envs", "algo"])
    rows = []
    # In the order measured
    for env_id, n_envs in measurements[["env_id", "n_envs"]].drop_duplicates().itertuples(index=False):
        row: dict[str, Any] = {"Env": env_id, "n_envs": n_envs}
        for algo in THROUGHPUT_ALGOS:
            result = summary.loc[(env_id, n_envs, algo)]
            row[f"{LABELS[algo]} steps/s"] = f"{result['steps_per_s']:,.0f}"
            if algo != BASELINE:
                ratio = f"{result['ratio']:.2f}× ({result['ratio_min']:.2f}–{result['ratio_max']:.2f})"
                row[f"{LABELS[algo]} / {LABELS[BASELINE]}"] = ratio
                row[f"{LABELS[algo]} ≥ {TARGET_RATIO:g}×"] = "yes" if result["ratio"] >= TARGET_RATIO else "no"
        rows.append(row)
    return pd.DataFrame(rows)


def time_breakdown_table(measurements: pd.DataFrame) -> pd.DataFrame:
    """
    :param measurements: ``run_throughput``'s rows
    :return: one row per env, number of envs and algorithm: the seconds of ``learn()`` per 10,000 env steps, and of
        them in the envs' ``step``, in ``train()`` and in the rest of the rollout loop (choosing actions, storing
        them, callbacks), median over repeats
    """
    per_10k = 10_000 / measurements["steps"]
    parts = pd.DataFrame(
        {
            "learn": measurements["seconds"] * per_10k,
            "env": measurements["env_s"] * per_10k,
            "train": measurements["train_s"] * per_10k,
            "rest": (measurements["seconds"] - measurements["env_s"] - measurements["train_s"]) * per_10k,
        }
    )
    keys = [measurements["env_id"], measurements["n_envs"], measurements["algo"]]
    medians = parts.groupby(keys, sort=False).median()
    rows = []
    for (env_id, n_envs, algo), seconds in medians.iterrows():
        row: dict[str, Any] = {"Env": env_id, "n_envs": n_envs, "Algorithm": LABELS[algo]}
        row["learn() s"] = f"{seconds['learn']:.3f}"
        for part, label in (("env", "env.step"), ("train", "train()"), ("rest", "rest of the loop")):
            row[f"{label} s"] = f"{seconds[part]:.3f} ({seconds[part] / seconds['learn']:.0%})"
        rows.append(row)
    return pd.DataFrame(rows)


def throughput_header(command: str, settings: ThroughputSettings) -> str:
    """:return: the markdown above the throughput table: the command and the settings"""
    versions = ", ".join(f"{name} {version}" for name, version in code_versions("reinforce").items())
    changes = ", ".join(
        f"`{algo}.{key}={value!r}`" for algo, keys in settings.overrides.items() for key, value in keys.items()
    )
    return (
        "# Throughput of `learn()`\n\n"
        f"Produced by:\n\n```\n{command}\n```\n\n"
        f"Env steps per second of `learn({settings.steps})` from a new model (construction not timed), "
        f"{settings.repeats} repeats, the algorithms interleaved in one process in a rotating order; "
        f"all networks `net_arch={NET_ARCH}`, otherwise each algorithm's zoo YAML entry for the env "
        "(A2C: rl-zoo3's, which is SB3's defaults here), without VecNormalize; torch 1 thread, device cpu. "
        f"Ratios are ours divided by A2C's within the same repeat: median (min–max) over repeats. "
        f"Target: ≥ {TARGET_RATIO:g}× A2C's env steps per second at n_envs 1 and 8.\n\nVersions: {versions}."
        + (f"\n\nChanged from the YAML entries (`--set`): {changes}." if changes else "")
    )


BREAKDOWN_HEADER = """## Where the time goes

The same `learn()` calls, timed in parts: seconds per 10,000 env steps in the envs' `step` (the env itself and the
VecEnv, which copies observations and deep-copies infos: the same for every algorithm), in `train()`, and the rest of
the rollout loop (choosing the actions, storing them, the callbacks). Medians over repeats, so the parts need not add
up to the whole exactly; percentages of the median `learn()`."""


def write_throughput_report(measurements: pd.DataFrame, header: str, results_dir: Path) -> Path:
    """
    Write ``throughput.md`` (header, ratios and time breakdown) and ``throughput.csv`` (every measurement).

    :return: the markdown file
    """
    results_dir.mkdir(parents=True, exist_ok=True)
    measurements.to_csv(results_dir / "throughput.csv", index=False, float_format="%.6g")
    path = results_dir / "throughput.md"
    path.write_text(
        f"{header}\n\n{markdown_table(throughput_table(measurements))}\n\n"
        f"{BREAKDOWN_HEADER}\n\n{markdown_table(time_breakdown_table(measurements))}\n"
    )
    return path


def main(argv: Sequence[str] | None = None) -> None:
    """The command line: ``python -m benchmarks.throughput [--quick] [--steps N] [--repeats N] ...``."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="2,000 steps, 3 repeats, written to the scratch folder")
    parser.add_argument("--envs", nargs="+", default=list(ENV_IDS), choices=ENV_IDS, help="envs to measure")
    parser.add_argument("--n-envs", nargs="+", type=positive_int, default=[1, 8], help="numbers of envs to measure with")
    parser.add_argument("--steps", type=positive_int, help="env steps of each timed learn() (default 20,000)")
    parser.add_argument("--repeats", type=positive_int, help="timed learn() calls per algorithm and setting (default 5)")
    parser.add_argument("--results-dir", type=Path, help=f"where to write (default {DEFAULT_RESULTS_DIR})")
    parser.add_argument(
        "--set",
        nargs="+",
        default=[],
        metavar="ALGO.KEY=VALUE",
        help="time a change to the YAML entries of an algorithm (e.g. nstep_sarsa.gradient_steps=4); needs "
        "--results-dir, so that the committed results stay those of the YAML",
    )
    args = parser.parse_args(argv)
    overrides = overrides_from_args(parser, args.set, args.results_dir, THROUGHPUT_ALGOS)
    quick = ThroughputSettings(steps=2_000, repeats=3) if args.quick else ThroughputSettings()
    settings = ThroughputSettings(
        env_ids=tuple(args.envs),
        n_envs=tuple(args.n_envs),
        steps=quick.steps if args.steps is None else args.steps,
        repeats=quick.repeats if args.repeats is None else args.repeats,
        overrides=overrides,
    )
    results_dir = args.results_dir or (QUICK_RESULTS_DIR if args.quick else DEFAULT_RESULTS_DIR)
    console = Console()
    command = shlex.join(["python", "-m", "benchmarks.throughput", *(sys.argv[1:] if argv is None else argv)])
    start = time.perf_counter()
    measurements = run_throughput(settings, console)
    path = write_throughput_report(measurements, throughput_header(command, settings), results_dir)
    console.print(markdown_table(throughput_table(measurements)), soft_wrap=True, markup=False)
    console.print(f"Wrote {path} in {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
