"""
How many PyTorch threads a zoo run of these algorithms should use on the CPU: the zoo's command line with PyTorch's
default intra-op threads (``--num-threads`` set to that number) against the package's default (one thread, set by
``sb3_classic.zoo.one_thread_unless_chosen``), on the machine as it is and with other work added (one busy process
per core, as a second training run or a build would be).

Each row is the wall time of the whole command (start-up and evaluations included), as a user waits for it; the two
commands run in turn, pair by pair, so that a drift of the machine's speed moves both. Then the README's main job
once under the same load, with the package's default.

    python -m benchmarks.threads                 # into benchmarks/results/threads.md: 10 to 25 minutes on 2 cores
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


def zoo_seconds(arguments: Sequence[str]) -> float:
    """
    :param arguments: ``rl_zoo3.train``'s arguments
    :return: the wall seconds of the whole command
    :raise RuntimeError: if the command fails (with its output)
    """
    # OMP_NUM_THREADS would choose the number of threads for both commands
    env = {name: value for name, value in os.environ.items() if name != "OMP_NUM_THREADS"}
    with tempfile.TemporaryDirectory() as folder:
        command = [sys.executable, "-m", "rl_zoo3.train", *arguments, "--log-folder", folder]
        start = time.perf_counter()
        process = subprocess.run(command, env=env, capture_output=True, text=True, cwd=folder)
        seconds = time.perf_counter() - start
    if process.returncode != 0:
        raise RuntimeError(f"{shlex.join(command)} failed:\n{process.stdout[-2000:]}\n{process.stderr[-2000:]}")
    return seconds


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter)
    parser.add_argument("--steps", type=int, default=16_000, help="the probe's env steps (default 16000)")
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
    commands = {
        f"PyTorch's default, {default_threads} threads (`--num-threads {default_threads}`)": [
            *probe,
            "--num-threads",
            str(default_threads),
        ],
        "sb3_classic's default, 1 thread": probe,
    }
    rows = []
    for busy in (0, cores):
        times: dict[str, list[float]] = {name: [] for name in commands}
        with load(busy):
            for _ in range(args.repeats):
                for name, arguments in commands.items():
                    times[name].append(zoo_seconds(arguments))
                    print(f"{busy} busy, {name}: {times[name][-1]:.1f} s", flush=True)
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
                    "Steps/s": f"{args.steps / median:,.0f}",
                    "Speed-up": f"{speed_up:.2f}×",
                }
            )

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
    page = f"""# PyTorch threads on the CPU

Produced by:

```
python -m benchmarks.threads
```

The zoo's command `python -m rl_zoo3.train {shlex.join(probe)}` ({args.steps:,} env steps, no evaluations), timed
whole (start-up included) {args.repeats} times in turn with each number of threads, on this machine ({cores} cores)
as it was and with {cores} processes added that keep a core busy each. The networks are small (two layers of 64 to 256 units,
a batch of one to a few hundred rows) and take a gradient step every few env steps: waking PyTorch's intra-op threads
costs more than they save, and with the cores busy each step waits for the scheduler to run every thread. So a zoo
run of these algorithms on the CPU uses one thread unless the user chose a number (`--num-threads N`, or
`OMP_NUM_THREADS`), and prints so; the study runner's processes use one thread each.

Speed-up: PyTorch's default's wall time divided by this row's, pair by pair (the median of the pairs).

Versions: {", ".join(f"{name} {version}" for name, version in versions.items())}.

{markdown_table(pd.DataFrame(rows))}
{main_job}"""
    args.results_dir.mkdir(parents=True, exist_ok=True)
    path = args.results_dir / "threads.md"
    path.write_text(page)
    print(f"wrote {path.relative_to(REPO_ROOT) if path.is_relative_to(REPO_ROOT) else path}")


if __name__ == "__main__":
    main()
