"""
Speed of the per-step mode against hand-written loops of the same algorithm, env steps per second of
training from scratch, one env, torch 1 thread:

1. ``NStepSARSA`` (per step, tile coding, linear SGD: the book's Figs 10.1–10.4) on Mountain Car against a NumPy
   transcription of the book's box of §10.2 with the same tiles (``textbook_numpy.mountain_car_sarsa``); target ≥ 0.25×;
2. ``NStepSARSA`` (per step, n = 1, a 2 × 128 MLP, Adam) on CartPole-v1 against a plain PyTorch loop of one-step SARSA
   with the same network and optimizer (``torch_mlp_sarsa``); target ≥ 1.0×.

    python -m benchmarks.per_step_speed             # prints, and writes benchmarks/results/textbook/per_step_speed.md
    python -m benchmarks.per_step_speed --steps 20000 --repeats 5

Each repeat times the package and the loop back to back (order alternating) on the same number of env steps; the
ratio is the package's steps/s over the loop's of the same repeat; the table gives medians and the range of ratios.
"""

import argparse
import itertools
import os
import platform
import shlex
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch as th
from torch import nn

import sb3_classic
from benchmarks.textbook import Setting, make_model
from benchmarks.textbook_numpy import mountain_car_sarsa
from sb3_classic import NStepSARSA
from sb3_classic.harness.common import positive_int

RESULTS = Path(__file__).resolve().parent / "results" / "textbook" / "per_step_speed.md"
MOUNTAIN_CAR_N, MOUNTAIN_CAR_ALPHA = 8, 0.3 / 8
CARTPOLE_NET, CARTPOLE_LR, CARTPOLE_EPS, CARTPOLE_GAMMA = (128, 128), 1e-3, 0.1, 0.99


def numpy_tile_sarsa(total_steps: int, seed: int = 0) -> int:
    """
    The book's box of §10.2 in NumPy with the same tiles and settings (``benchmarks.textbook_numpy.mountain_car_sarsa``).

    :return: env steps taken (``total_steps``, or more: the episode running then is finished)
    """
    return sum(mountain_car_sarsa(seed, MOUNTAIN_CAR_N, MOUNTAIN_CAR_ALPHA, total_steps=total_steps))


def package_tile_sarsa(total_steps: int, seed: int = 0) -> int:
    """:return: env steps taken by ``NStepSARSA``'s per-step mode with the same settings as ``numpy_tile_sarsa``"""
    model = make_model(Setting("mountain_car", MOUNTAIN_CAR_ALPHA, MOUNTAIN_CAR_N), seed)
    model.learn(total_steps)
    return int(model.num_timesteps)


def torch_mlp_sarsa(total_steps: int, seed: int = 0) -> int:
    """
    One-step SARSA with a 2 × 128 ReLU MLP and Adam, one update per env step, written as a plain PyTorch loop.

    :return: env steps taken (``total_steps``)
    """
    th.manual_seed(seed)
    rng = np.random.default_rng(seed)
    env = gym.make("CartPole-v1")
    sizes = (4, *CARTPOLE_NET)
    layers: list[nn.Module] = []
    for fan_in, fan_out in itertools.pairwise(sizes):
        layers += [nn.Linear(fan_in, fan_out), nn.ReLU()]
    q_net = nn.Sequential(*layers, nn.Linear(sizes[-1], 2))
    optimizer = th.optim.Adam(q_net.parameters(), lr=CARTPOLE_LR)

    def act(obs: np.ndarray) -> tuple[th.Tensor, int]:
        x = th.as_tensor(obs, dtype=th.float32)
        with th.no_grad():
            q = q_net(x)
        return x, int(rng.integers(2)) if rng.random() < CARTPOLE_EPS else int(q.argmax())

    obs, _ = env.reset(seed=seed)
    x, action = act(obs)
    for _ in range(total_steps):
        obs, reward, terminated, truncated, _ = env.step(action)
        next_x, next_action = act(obs)
        with th.no_grad():
            target = float(reward) + (0.0 if terminated else CARTPOLE_GAMMA * float(q_net(next_x)[next_action]))
        loss = 0.5 * (q_net(x)[action] - target) ** 2
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        if terminated or truncated:
            obs, _ = env.reset()
            next_x, next_action = act(obs)
        x, action = next_x, next_action
    return total_steps


def package_mlp_sarsa(total_steps: int, seed: int = 0) -> int:
    """:return: env steps taken by ``NStepSARSA``'s per-step mode with the settings of ``torch_mlp_sarsa``"""
    model = NStepSARSA(
        "MlpPolicy",
        "CartPole-v1",
        learning_rate=CARTPOLE_LR,
        n_steps=1,
        train_freq=1,
        gradient_steps=1,
        update_mode="per_step",
        gamma=CARTPOLE_GAMMA,
        exploration_initial_eps=CARTPOLE_EPS,
        exploration_final_eps=CARTPOLE_EPS,
        policy_kwargs=dict(net_arch=list(CARTPOLE_NET)),
        seed=seed,
        device="cpu",
    )
    model.learn(total_steps)
    return int(model.num_timesteps)


def steps_per_second(train: Callable[[int, int], int], steps: int, seed: int) -> float:
    start = time.perf_counter()
    taken = train(steps, seed)
    return taken / (time.perf_counter() - start)


COMPARISONS = (
    ("Mountain Car, tile coding (8 × 8 × 8), linear, SGD, n = 8", package_tile_sarsa, numpy_tile_sarsa, "NumPy loop", 0.25),
    ("CartPole-v1, 2 × 128 MLP, Adam, n = 1, ε = 0.1", package_mlp_sarsa, torch_mlp_sarsa, "PyTorch loop", 1.0),
)


def timing_arguments(
    argv: list[str] | None, description: str | None, steps: int, repeats: int, output: Path
) -> argparse.Namespace:
    """
    The command line of a timing comparison (``--steps``, ``--repeats``, ``--output``), parsed; torch set to 1 thread.

    :param argv: the arguments (None: ``sys.argv``)
    :param description: the command's help text
    :param steps: the default env steps per timed run
    :param repeats: the default timed runs of each
    :param output: the default markdown file written
    :return: the parsed arguments
    """
    parser = argparse.ArgumentParser(description=description, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=positive_int, default=steps, help=f"env steps per timed run (default {steps:,})")
    parser.add_argument("--repeats", type=positive_int, default=repeats, help=f"timed runs of each (default {repeats})")
    parser.add_argument("--output", type=Path, default=output)
    args = parser.parse_args(argv)
    th.set_num_threads(1)
    return args


def main(argv: list[str] | None = None) -> int:
    args = timing_arguments(argv, __doc__, steps=10_000, repeats=3, output=RESULTS)
    load_before = os.getloadavg()[0]
    rows = []
    for name, package, loop, loop_name, target in COMPARISONS:
        package(500, 0), loop(500, 0)  # warm-up: imports, first calls
        ours: list[float] = []
        theirs: list[float] = []
        for repeat in range(args.repeats):
            pair = [(package, ours), (loop, theirs)]
            for train, into in pair if repeat % 2 == 0 else pair[::-1]:
                into.append(steps_per_second(train, args.steps, repeat))
        ratios = [a / b for a, b in zip(ours, theirs, strict=True)]
        row = (
            f"| {name} | {statistics.median(ours):,.0f} | {loop_name}: {statistics.median(theirs):,.0f} "
            f"| {statistics.median(ratios):.2f}× ({min(ratios):.2f}–{max(ratios):.2f}) | ≥ {target:g}× "
            f"| {'met' if statistics.median(ratios) >= target else '**not met**'} |"
        )
        print(row, flush=True)
        rows.append(row)
    load = f"load average {load_before:.1f} before, {os.getloadavg()[0]:.1f} after, on {os.cpu_count()} cores"
    command = "python -m benchmarks.per_step_speed " + shlex.join(sys.argv[1:] if argv is None else argv)
    text = f"""# Per-step speed against hand-written loops

Produced by:

```
{command.strip()}
```

sb3_classic {sb3_classic.__version__}, torch {th.__version__}, 1 thread, CPU ({platform.machine()}, {load}); {args.steps:,} env
steps of training from scratch per timed run, {args.repeats} repeats, the package and the loop back to back in each
(order alternating). Steps/s: medians; ratio: median (min–max) of the package's over the loop's of the same repeat.
The loops: `benchmarks/textbook_numpy.py`'s `mountain_car_sarsa` is the box of S&B §10.2 with the same tiles,
`benchmarks/per_step_speed.py`'s `torch_mlp_sarsa` one-step SARSA with the same network and Adam, one update per step.

| Comparison | `NStepSARSA` per step (steps/s) | Loop (steps/s) | Ratio | Target | |
|---|---|---|---|---|---|
{chr(10).join(rows)}
"""
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(text)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
