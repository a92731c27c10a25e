"""
How many PyTorch threads the package's entry points that train should use on the CPU: two probes, each with PyTorch's
default intra-op threads against the package's default (one thread), on the machine as it is and with other work
added (one busy process per core, as a second training run or a build would be):

- the zoo's command line (``--num-threads`` set to PyTorch's default, against ``sb3_classic.zoo.one_thread_unless_chosen``);
- a Python script that trains a ``REINFORCEPopulation`` of 4 CartPole-v1 seeds (``torch.set_num_threads`` to
  PyTorch's default, against the population's ``one_thread_unless_chosen``).

Each row is the wall time of the whole command (start-up included), as a user waits for it; the two commands of a
probe run in turn, pair by pair, so that a drift of the machine's speed moves both. Then the README's main job once
under the same load, with the package's default.

    python -m benchmarks.threads                 # into benchmarks/results/threads.md: 15 to 30 minutes on 2 cores
    python -m benchmarks.threads --repeats 1 --no-main-job --results-dir /tmp/threads   # a quick look
"""

import argparse
import multiprocessing
import os
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from benchmarks.common import DEFAULT_RESULTS_DIR, REPO_ROOT
from benchmarks.report import markdown_table
from sb3_classic.harness.common import code_versions

#: The probe: the main job's algorithm and env, without its evaluations, for a number of steps
PROBE = ["--algo", "nstep_sarsa", "--env", "Acrobot-v1", "--seed", "0", "--eval-freq", "-1"]
#: The README's main job, without its TensorBoard folder
MAIN_JOB = ["--algo", "nstep_sarsa", "--env", "Acrobot-v1", "--seed", "0"]


def _busy() -> None:
    while True:
        pass


@contextmanager
def load(processes: int) -> Iterator[None]:
    """
    Other work on the machine while the block runs: ``processes`` processes that keep a core busy each.

    :param processes: how many (0: none added)
    """
    workers = [multiprocessing.Process(target=_busy, daemon=True) for _ in range(processes)]
    for worker in workers:
        worker.start()
    try:
        yield
    finally:
        for worker in workers:
            worker.terminate()
            worker.join()


#: The population probe: a user's script, ``python -c POPULATION STEPS THREADS`` (THREADS 0: the package's choice)
POPULATION = """
import sys
import torch
from stable_baselines3.common.env_util import make_vec_env
from sb3_classic import REINFORCE
from sb3_classic.reinforce import REINFORCEPopulation
steps, threads = int(sys.argv[1]), int(sys.argv[2])
if threads:
    torch.set_num_threads(threads)
models = [REINFORCE("MlpPolicy", make_vec_env("CartPole-v1", n_envs=1, seed=seed), seed=seed) for seed in range(4)]
REINFORCEPopulation(models).learn(steps)
"""


def zoo_seconds(arguments: Sequence[str]) -> float:
    """
    :param arguments: ``rl_zoo3.train``'s arguments
    :return: the wall seconds of the whole command
    :raise RuntimeError: if the command fails (with its output)
    """
    with tempfile.TemporaryDirectory() as folder:
        return command_seconds([sys.executable, "-m", "rl_zoo3.train", *arguments, "--log-folder", folder], folder)


def command_seconds(command: Sequence[str], folder: str | None = None) -> float:
    """
    :param command: a command line
    :param folder: its working directory (None: a temporary one)
    :return: the wall seconds of the whole command
    :raise RuntimeError: if the command fails (with its output)
    """
    # OMP_NUM_THREADS would choose the number of threads for both commands
    env = {name: value for name, value in os.environ.items() if name != "OMP_NUM_THREADS"}
    with tempfile.TemporaryDirectory() as scratch:
        folder = folder or scratch
        start = time.perf_counter()
        process = subprocess.run(command, env=env, capture_output=True, text=True, cwd=folder)
        seconds = time.perf_counter() - start
    if process.returncode != 0:
        raise RuntimeError(f"{shlex.join(command)} failed:\n{process.stdout[-2000:]}\n{process.stderr[-2000:]}")
    return seconds


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter)
    parser.add_argument("--steps", type=int, default=16_000, help="the zoo probe's env steps (default 16000)")
    parser.add_argument(
        "--population-steps", type=int, default=5_000, help="the population probe's env steps per seed (default 5000)"
    )
    parser.add_argument("--repeats", type=int, default=3, help="pairs of runs per machine state (default 3)")
    parser.add_argument("--no-main-job", action="store_true", help="without the main job under load")
    parser.add_argument("--results-dir", type=Path, default=DEFAULT_RESULTS_DIR, help="where threads.md goes")
    args = parser.parse_args(argv)

    cores = os.cpu_count() or 1
    # PyTorch's default: what a process started without OMP_NUM_THREADS gets (the number of physical cores)
    default_threads = int(
        subprocess.run(
            [sys.executable, "-c", "import torch; print(torch.get_num_threads())"],
            env={name: value for name, value in os.environ.items() if name != "OMP_NUM_THREADS"},
            capture_output=True,
            text=True,
            check=True,
        ).stdout
    )
    probe = [*PROBE, "-n", str(args.steps)]
    population = [sys.executable, "-c", POPULATION, str(args.population_steps)]
    # Each probe: its two commands (PyTorch's default, the package's), and the env steps one command takes
    probes = {
        "zoo": (
            {
                f"PyTorch's default, {default_threads} threads (`--num-threads {default_threads}`)": lambda: zoo_seconds(
                    [*probe, "--num-threads", str(default_threads)]
                ),
                "sb3_classic's default, 1 thread": lambda: zoo_seconds(probe),
            },
            args.steps,
        ),
        "population": (
            {
                f"PyTorch's default, {default_threads} threads (`torch.set_num_threads({default_threads})`)": lambda: (
                    command_seconds([*population, str(default_threads)])
                ),
                "sb3_classic's default, 1 thread": lambda: command_seconds([*population, "0"]),
            },
            4 * args.population_steps,
        ),
    }
    tables = {}
    for probe_name, (commands, steps) in probes.items():
        rows = []
        for busy in (0, cores):
            times: dict[str, list[float]] = {name: [] for name in commands}
            with load(busy):
                for _ in range(args.repeats):
                    for name, seconds_of in commands.items():
                        times[name].append(seconds_of())
                        print(f"{probe_name}, {busy} busy, {name}: {times[name][-1]:.1f} s", flush=True)
            baseline_times = times[next(iter(commands))]
            for name, seconds in times.items():
                median = statistics.median(seconds)
                # Pair by pair (the two commands ran one after the other): a drift of the machine's speed moves both
                speed_up = statistics.median(before / after for before, after in zip(baseline_times, seconds, strict=True))
                rows.append(
                    {
                        "Load added": "none" if busy == 0 else f"{busy} busy processes",
                        "Threads": name,
                        "Wall s (median)": f"{median:.1f}",
                        "min–max": f"{min(seconds):.1f}–{max(seconds):.1f}",
                        "Steps/s": f"{steps / median:,.0f}",
                        "Speed-up": f"{speed_up:.2f}×",
                    }
                )
        tables[probe_name] = rows

    main_job = ""
    if not args.no_main_job:
        with load(cores):
            main_seconds = zoo_seconds(MAIN_JOB)
        main_job = (
            f"\nThe README's main job (`python -m rl_zoo3.train {shlex.join(MAIN_JOB)}`: 200k steps, evaluations every "
            f"25k) with {cores} busy processes and sb3_classic's default: **{main_seconds:.0f} s**.\n"
        )
        print(main_job, flush=True)

    import pandas as pd

    versions = code_versions("nstep_sarsa")
    command = " ".join(["python -m benchmarks.threads", shlex.join(argv if argv is not None else sys.argv[1:])]).strip()
    page = f"""# PyTorch threads on the CPU

Produced by:

```
{command}
```

Each command timed whole (start-up included) {args.repeats} times in turn with each number of threads, on this
machine ({cores} cores) as it was and with {cores} processes added that keep a core busy each. The networks are small
(two layers of 64 to 256 units, a batch of one to a few hundred rows) and take a gradient step every few env steps:
waking PyTorch's intra-op threads costs more than they save, and with the cores busy each step waits for the scheduler
to run every thread. So the package's entry points that train use one thread on the CPU unless the user chose a
number (`--num-threads N` of the zoo, `OMP_NUM_THREADS`, or `torch.set_num_threads` in a script): a zoo run (and it
prints so), a population's `learn`, the study runner's processes and the benchmarks. A model's own `learn()` leaves
the threads to the user's script, as SB3's algorithms do: call `torch.set_num_threads(1)` first.

Speed-up: PyTorch's default's wall time divided by this row's, pair by pair (the median of the pairs).

Versions: {", ".join(f"{name} {version}" for name, version in versions.items())}.

## The zoo's command

`python -m rl_zoo3.train {shlex.join(probe)}` ({args.steps:,} env steps, no evaluations).

{markdown_table(pd.DataFrame(tables["zoo"]))}
{main_job}
## A population in a script

A `REINFORCEPopulation` of 4 CartPole-v1 seeds (`REINFORCE("MlpPolicy", ...)`, the defaults), {args.population_steps:,}
env steps each (`benchmarks/threads.py`'s `POPULATION`).

{markdown_table(pd.DataFrame(tables["population"]))}
"""
    args.results_dir.mkdir(parents=True, exist_ok=True)
    path = args.results_dir / "threads.md"
    path.write_text(page)
    print(f"wrote {path.relative_to(REPO_ROOT) if path.is_relative_to(REPO_ROOT) else path}")


if __name__ == "__main__":
    main()
