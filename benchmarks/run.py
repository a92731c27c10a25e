"""
The benchmarks, in one command: REINFORCE and NStepSARSA with the package's hyperparameters, and SB3's
A2C, PPO and DQN with rl-zoo3's, on CartPole-v1 and Acrobot-v1 (and LunarLander-v3 when ``--envs`` names it) with
the same step budget and seeds; then the tables and plots of benchmarks/results/; then the throughput of learn() against
A2C's.

    python -m benchmarks.run            # the committed results (hours on 2 cores)
    python -m benchmarks.run --quick    # a smoke test of the whole pipeline (minutes), into benchmarks/cache/
    python -m benchmarks.run --scheduler tcp://HOST:8786   # the runs on a Dask cluster (benchmarks/README.md)

Finished runs are cached in benchmarks/cache/ and never run again: an interrupted benchmark resumes where it stopped.
The runs are the harness's (``sb3_classic.harness``: a run built by rl-zoo3's ExperimentManager, its cache, the
process pool or the Dask cluster, the progress display); this module is the benchmark's settings, report and command.
"""

import argparse
import os
import platform
import shlex
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import yaml
from rich.console import Console
from rich.markup import escape

from benchmarks.common import (
    DEFAULT_CACHE_DIR,
    DEFAULT_RESULTS_DIR,
    ENV_IDS,
    OPTIONAL_ENV_IDS,
    QUICK_RESULTS_DIR,
    check_overridden_settings,
    overrides_from_args,
)
from benchmarks.report import load_results, markdown_table, summary_table, threshold_crossings, write_learning_report
from benchmarks.throughput import ThroughputSettings, run_throughput, throughput_header, write_throughput_report
from sb3_classic.harness.common import (
    ALL_ALGOS,
    LABELS,
    OUR_ALGOS,
    RunSpec,
    code_versions,
    hyperparams_path,
    int_at_least,
    positive_int,
)
from sb3_classic.harness.lockstep import plan_lockstep
from sb3_classic.harness.pool import report_missing, run_missing_runs
from sb3_classic.harness.runner import RUN_FILE, DamagedRunError


@dataclass
class Settings:
    """
    What a benchmark runs.

    :param seeds: seeds of our algorithms (0 to seeds − 1)
    :param peer_seeds: seeds of A2C, PPO and DQN (0 to peer_seeds − 1: the first of ours)
    :param budgets: env steps of every run, per env (the same for all algorithms)
    :param eval_freq: env steps between two evaluations
    :param eval_episodes: episodes per evaluation
    :param throughput: the throughput benchmark's settings
    """

    seeds: int
    peer_seeds: int
    budgets: dict[str, int]
    eval_freq: int
    eval_episodes: int
    throughput: ThroughputSettings = field(default_factory=ThroughputSettings)


#: The committed results. 200k steps: our algorithms reach the thresholds within 45k (CartPole-v1) and 135k steps
#: (Acrobot-v1) and every run of ours still has at least 400 episodes; it is 4× DQN's zoo budget on CartPole-v1 (50k)
#: and 2× on Acrobot-v1 (100k), 2× PPO's on CartPole-v1 (100k); A2C's (500k) and PPO's on Acrobot-v1 (1M) are longer.
#: LunarLander-v3 (only when ``--envs`` names it): 500k, between the zoo's budgets there (DQN 100k, A2C 200k, PPO 1M).
FULL = Settings(
    seeds=10,
    peer_seeds=5,
    budgets={**dict.fromkeys(ENV_IDS, 200_000), "LunarLander-v3": 500_000},
    eval_freq=5_000,
    eval_episodes=10,
)
#: A smoke test of the pipeline
QUICK = Settings(
    seeds=2,
    peer_seeds=2,
    budgets=dict.fromkeys(ENV_IDS + OPTIONAL_ENV_IDS, 10_000),
    eval_freq=1_000,
    eval_episodes=5,
    throughput=ThroughputSettings(steps=2_000, repeats=3),
)


def parse_budgets(values: Sequence[str], env_ids: Sequence[str], defaults: dict[str, int]) -> dict[str, int]:
    """
    :param values: ``ENV=STEPS`` (one env) or ``STEPS`` (every env); STEPS may be written ``5e5``
    :param env_ids: the envs of the benchmark
    :param defaults: the budgets of the envs not given
    :return: the budget of each env
    """
    budgets = {env_id: defaults[env_id] for env_id in env_ids}
    for value in values:
        env_id, _, steps = value.rpartition("=")
        if env_id and env_id not in env_ids:
            raise ValueError(f"--budget {value!r}: {env_id!r} is not one of the envs benchmarked ({', '.join(env_ids)})")
        if not steps.replace(".", "", 1).replace("e", "", 1).isdigit() or float(steps) < 1:
            raise ValueError(f"--budget {value!r}: the budget must be a positive number of env steps, e.g. 500000 or 5e5")
        for target in [env_id] if env_id else env_ids:
            budgets[target] = int(float(steps))
    return budgets


def make_specs(
    settings: Settings,
    env_ids: Sequence[str],
    algos: Sequence[str],
    overrides: dict[str, dict[str, Any]] | None = None,
    lockstep: bool = True,
) -> list[RunSpec]:
    """
    :param settings: what the benchmark runs
    :param env_ids: its envs
    :param algos: its algorithms
    :param overrides: per algorithm, keys replacing those of its YAML entries (``parse_overrides``)
    :param lockstep: train the seeds of each of our settings in lockstep where its population covers it
        (``plan_lockstep``); False: every run alone (``--separate``)
    :return: every run of the benchmark, seed by seed (so an interrupted benchmark has whole seeds done)
    """
    specs = []
    for seed in range(max(settings.seeds, settings.peer_seeds)):
        for env_id in env_ids:
            for algo in algos:
                if seed < (settings.seeds if algo in OUR_ALGOS else settings.peer_seeds):
                    budget = settings.budgets[env_id]
                    spec = RunSpec.create(algo, env_id, seed, budget, settings.eval_freq, settings.eval_episodes)
                    if overrides and algo in overrides:
                        changed = yaml.safe_dump({**spec.hyperparams, **overrides[algo]}, sort_keys=True)
                        spec = replace(spec, hyperparams_yaml=changed)
                    specs.append(spec)
    return plan_lockstep(specs, lockstep)


def learning_header(
    command: str,
    settings: Settings,
    env_ids: Sequence[str],
    algos: Sequence[str],
    workers: int,
    scheduler: str | None = None,
    ran: int | None = None,
    specs: Sequence[RunSpec] = (),
) -> str:
    """
    :param command: the command line
    :param settings: what the benchmark ran
    :param env_ids: its envs
    :param algos: its algorithms
    :param workers: the runs in parallel on this machine (without ``scheduler``)
    :param scheduler: the Dask scheduler the runs were sent to, if any
    :param ran: how many of the runs this command trained (the rest came from the cache); None: all of them
    :param specs: the runs (which were trained in lockstep)
    :return: the markdown above the learning tables: the command, the settings and how to read the columns
    """
    budgets = ", ".join(f"{env_id} {settings.budgets[env_id]:,}" for env_id in env_ids)
    ours = [LABELS[algo] for algo in algos if algo in OUR_ALGOS]
    peers = [LABELS[algo] for algo in algos if algo not in OUR_ALGOS]
    versions = ", ".join(f"{name} {version}" for name, version in code_versions("reinforce").items())
    if ran == 0:
        # A report from the cache: this command's --workers and machine are not those the runs had
        where = "Every run was in the cache (`--cache-dir`): this command trained none of them, torch 1 thread each."
    elif scheduler is None:
        where = f"{workers} runs in parallel, torch 1 thread each, CPU ({platform.machine()}, {os.cpu_count()} cores)."
    else:
        where = "Runs on a Dask cluster (`--scheduler`), torch 1 thread each."
    if ran:
        where += f" This command trained {ran} of the runs; the rest were in the cache."
    lockstep = sorted({LABELS[spec.algo] for spec in specs if spec.lockstep})
    if lockstep:
        where += (
            f" The seeds of {', '.join(lockstep)} trained in lockstep (one population per setting, one process; each "
            "run's learn time is its share of the population's); `--separate` trains each alone."
        )
    return f"""# Learning benchmarks

Produced by:

```
{command}
```

- Env steps per run (every algorithm): {budgets}.
- Seeds 0–{settings.seeds - 1} for {", ".join(ours) or "–"}; 0–{settings.peer_seeds - 1} for {", ".join(peers) or "–"}.
- Hyperparameters: `hyperparams/*.yml` for ours, rl-zoo3's tuned `a2c/ppo/dqn.yml` for the others (listed at the end),
  built by rl-zoo3's `ExperimentManager` (its `n_envs`, `VecNormalize`, schedules). The zoo's progress-relative
  settings (`lin_` schedules, DQN's `exploration_fraction`) span the budget above, as with `python -m rl_zoo3.train -n`.
- Evaluation: {settings.eval_episodes} episodes, deterministic, on a separate env, every {settings.eval_freq:,} env steps
  and at the end of training.
- {where}
- Versions: {versions}.

Columns: *Final eval return*: the mean return of the evaluation at the end of training, mean ± std over seeds.
*Env steps / Episodes to threshold*: at the first evaluation whose mean return reaches the threshold (episodes: the
training episodes ended by then), median (min–max) over the seeds that reached it. *Final ≥ threshold*: the seeds
whose final evaluation is at the threshold. *Stayed*: of the evaluations after each seed's first one at the
threshold, the fraction still at it, pooled over seeds (and the worst seed's fraction). *Learn time*: wall-clock seconds of
`learn()` without the evaluations; *Env steps/s*: env steps over that time, each algorithm with its own `n_envs` (the
zoo's): the like-for-like speed comparison is `throughput.md`. Plots: `<env>-episodes.png`, the
training return of each episode (the seed report's figure; mean ± std over seeds, up to the episode count every seed
reached); `<env>-steps.png`, the evaluation return against env steps."""


def hyperparams_section(specs: Sequence[RunSpec]) -> str:
    """:return: markdown listing the zoo YAML entry each algorithm used on each env"""
    entries: dict[str, dict[str, object]] = {}
    for spec in specs:
        entries.setdefault(spec.algo, {})[spec.env_id] = spec.hyperparams
    blocks = [
        f"### {LABELS[algo]} (`{hyperparams_path(algo).name}`)\n\n```yaml\n{yaml.safe_dump(envs, sort_keys=False)}```"
        for algo, envs in entries.items()
    ]
    note = (
        "The zoo YAML entries, as read when the command started, with the changes of its `--set` if any (`n_timesteps` "
        "is replaced by the budget above)."
    )
    return "## Hyperparameters used\n\n" + note + "\n\n" + "\n\n".join(blocks)


def main(argv: Sequence[str] | None = None) -> int:
    """The command line (``python -m benchmarks.run --help``). :return: the exit status"""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--quick", action="store_true", help="2 seeds, 10k steps, short throughput; results in the scratch folder"
    )
    parser.add_argument(
        "--envs",
        nargs="+",
        choices=ENV_IDS + OPTIONAL_ENV_IDS,
        default=list(ENV_IDS),
        help=f"envs to benchmark (default {' '.join(ENV_IDS)})",
    )
    parser.add_argument("--algos", nargs="+", choices=ALL_ALGOS, default=list(ALL_ALGOS), help="algorithms to benchmark")
    parser.add_argument("--seeds", type=int_at_least(0), help=f"seeds of REINFORCE and NStepSARSA (default {FULL.seeds})")
    parser.add_argument("--peer-seeds", type=int_at_least(0), help=f"seeds of A2C, PPO and DQN (default {FULL.peer_seeds})")
    parser.add_argument(
        "--budget",
        nargs="+",
        default=[],
        metavar="[ENV=]STEPS",
        help="env steps per run, for one env (CartPole-v1=3e5) or all (3e5); default 2e5, LunarLander-v3 5e5",
    )
    parser.add_argument("--eval-freq", type=positive_int, help=f"env steps between two evaluations (default {FULL.eval_freq})")
    parser.add_argument("--eval-episodes", type=positive_int, help=f"episodes per evaluation (default {FULL.eval_episodes})")
    parser.add_argument(
        "--workers", type=positive_int, default=os.cpu_count() or 1, help="runs in parallel (default: the cores)"
    )
    parser.add_argument(
        "--scheduler",
        metavar="tcp://HOST:PORT",
        help="run on the Dask cluster of this scheduler instead of local processes (needs the dask extra)",
    )
    parser.add_argument("--cache-dir", type=Path, default=DEFAULT_CACHE_DIR, help="where finished runs are kept")
    parser.add_argument("--results-dir", type=Path, help=f"tables and plots (default {DEFAULT_RESULTS_DIR}; --quick: scratch)")
    parser.add_argument(
        "--set",
        nargs="+",
        default=[],
        metavar="ALGO.KEY=VALUE",
        help="try a change to the YAML entries of an algorithm (e.g. nstep_sarsa.max_grad_norm=10.0) on the benchmark's "
        "learning runs (not the throughput's); needs --results-dir, so that the committed results stay those of the YAML",
    )
    parser.add_argument(
        "--separate",
        action="store_true",
        help="train every seed alone, not the seeds of REINFORCE's and NStepSARSA's settings in lockstep (other cache "
        "entries: the two ways draw the actions from different generators)",
    )
    parser.add_argument("--skip-throughput", action="store_true", help="only the learning runs and their report")
    parser.add_argument("--throughput-steps", type=positive_int, help="env steps of each timed learn() (default 20,000)")
    parser.add_argument(
        "--throughput-repeats", type=positive_int, help="timed learn() calls per algorithm and setting (default 5)"
    )
    args = parser.parse_args(argv)

    overrides = overrides_from_args(parser, args.set, args.results_dir, args.algos)
    base = QUICK if args.quick else FULL
    try:
        budgets = parse_budgets(args.budget, args.envs, base.budgets)
    except ValueError as error:
        parser.error(str(error))
    settings = Settings(
        seeds=base.seeds if args.seeds is None else args.seeds,
        peer_seeds=base.peer_seeds if args.peer_seeds is None else args.peer_seeds,
        budgets=budgets,
        eval_freq=base.eval_freq if args.eval_freq is None else args.eval_freq,
        eval_episodes=base.eval_episodes if args.eval_episodes is None else args.eval_episodes,
        throughput=ThroughputSettings(
            env_ids=tuple(args.envs),
            steps=base.throughput.steps if args.throughput_steps is None else args.throughput_steps,
            repeats=base.throughput.repeats if args.throughput_repeats is None else args.throughput_repeats,
        ),
    )
    results_dir = args.results_dir or (QUICK_RESULTS_DIR if args.quick else DEFAULT_RESULTS_DIR)
    command = shlex.join(["python", "-m", "benchmarks.run", *(sys.argv[1:] if argv is None else argv)])
    console = Console()

    specs = make_specs(settings, args.envs, args.algos, overrides, lockstep=not args.separate)
    if not specs:
        parser.error(f"--seeds {settings.seeds} and --peer-seeds {settings.peer_seeds}: no run of {args.algos} to make")
    pending = [spec for spec in specs if not (spec.run_dir(args.cache_dir) / RUN_FILE).exists()]
    problems = check_overridden_settings(pending, overrides)
    if problems:
        console.print(
            "[red]Nothing was run: the algorithm rejects these --set values:\n  "
            + "\n  ".join(map(escape, problems))
            + "[/red]",
            highlight=False,
            soft_wrap=True,
        )
        return 2
    start = time.perf_counter()
    status = run_missing_runs(len(specs), pending, args.workers, args.cache_dir, console, args.scheduler)
    if status is not None:
        return status
    learning_time = time.perf_counter() - start

    try:
        results = load_results(specs, args.cache_dir)
    except DamagedRunError as error:
        console.print(f"[red]{escape(str(error))}[/red]", highlight=False, soft_wrap=True)
        return 2
    if results.runs.empty:
        return report_missing(results.missing, console)
    ran = None if len(pending) == len(specs) else len({spec.key() for spec in pending})
    header = learning_header(command, settings, args.envs, args.algos, args.workers, args.scheduler, ran, specs)
    path = write_learning_report(results, args.envs, args.algos, header, results_dir, footer=hyperparams_section(specs))
    crossings = threshold_crossings(results)
    for env_id in args.envs:
        console.print(
            f"\n{env_id}\n{markdown_table(summary_table(results, crossings, env_id, args.algos))}",
            soft_wrap=True,
            markup=False,
        )
    console.print(f"\nLearning runs: {learning_time:.0f} s; wrote {path}")

    if not args.skip_throughput:
        start = time.perf_counter()
        measurements = run_throughput(settings.throughput, console)
        path = write_throughput_report(measurements, throughput_header(command, settings.throughput), results_dir)
        console.print(
            f"\n{path.read_text()}\nThroughput: {time.perf_counter() - start:.0f} s; wrote {path}",
            soft_wrap=True,
            markup=False,
        )
    return report_missing(results.missing, console)


if __name__ == "__main__":
    sys.exit(main())
