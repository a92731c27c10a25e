"""
CPU seconds of K seeds of one NStepSARSA setting trained in lockstep (``NStepSARSAPopulation``) against the same K
seeds trained one after the other (``model.learn``), in one process with one PyTorch thread: the per-step setting
(2 × 128 MLP, n_steps 10 on CartPole-v1 and 5 on Acrobot-v1, learning_rate 5e-4, train_freq 1, gradient_steps 1,
update_mode "per_step").

    python -m benchmarks.lockstep                       # writes benchmarks/results/lockstep.{csv,md}
    python -m benchmarks.lockstep --k 10 --steps 3000

Seconds are ``time.process_time`` of training only (the models are built before the clock starts).
"""

import argparse
import csv
import os
import platform
import shlex
import sys
import time
from pathlib import Path

import torch as th
from stable_baselines3.common.env_util import make_vec_env

from sb3_classic import NStepSARSA
from sb3_classic.harness.common import positive_int
from sb3_classic.sarsa import NStepSARSAPopulation

RESULTS = Path(__file__).resolve().parent / "results"
N_STEPS = {"CartPole-v1": 10, "Acrobot-v1": 5}
SETTING = "per_step: 2x128 MLP, lr 5e-4, train_freq 1, gradient_steps 1"


def make_models(env_id: str, k: int) -> list[NStepSARSA]:
    """:return: K members of the per-step setting, seeds 0..K-1, each with its own env seeded as its model"""
    return [
        NStepSARSA(
            "MlpPolicy",
            make_vec_env(env_id, n_envs=1, seed=seed),
            learning_rate=5e-4,
            n_steps=N_STEPS[env_id],
            train_freq=1,
            gradient_steps=1,
            update_mode="per_step",
            policy_kwargs=dict(net_arch=[128, 128]),
            seed=seed,
        )
        for seed in range(k)
    ]


def timed(env_id: str, k: int, steps: int) -> tuple[float, float]:
    """:return: CPU seconds of the K seeds one after the other, and in lockstep"""
    models = make_models(env_id, k)
    start = time.process_time()
    for model in models:
        model.learn(steps)
    separate = time.process_time() - start
    models = make_models(env_id, k)
    start = time.process_time()
    NStepSARSAPopulation(models).learn(steps)
    return separate, time.process_time() - start


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--k", type=positive_int, default=10, help="seeds (members)")
    parser.add_argument("--steps", type=positive_int, default=3000, help="env steps per seed")
    parser.add_argument("--env", nargs="+", default=list(N_STEPS), choices=list(N_STEPS))
    parser.add_argument("--out", type=Path, default=RESULTS, help="the folder of lockstep.csv and lockstep.md")
    args = parser.parse_args(argv)
    th.set_num_threads(1)
    rows = []
    for env_id in args.env:
        separate, lockstep = timed(env_id, args.k, args.steps)
        rows.append(dict(algo="NStepSARSA", env_id=env_id, setting=f"{SETTING}, n_steps {N_STEPS[env_id]}", k=args.k,
                         separate_cpu_s=f"{separate:.2f}", lockstep_cpu_s=f"{lockstep:.2f}"))  # fmt: skip
        print(f"{env_id}: separate {separate:.2f} s, lockstep {lockstep:.2f} s, {separate / lockstep:.2f}x", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "lockstep.csv", "w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    command = "python -m benchmarks.lockstep " + shlex.join(argv if argv is not None else sys.argv[1:])
    table = "\n".join(
        f"| {row['env_id']} | {row['k']} | {args.steps} | {row['separate_cpu_s']} | {row['lockstep_cpu_s']} | "
        f"{float(row['separate_cpu_s']) / float(row['lockstep_cpu_s']):.2f}× |"
        for row in rows
    )
    (args.out / "lockstep.md").write_text(
        f"""# K seeds in lockstep against one after the other

NStepSARSA, {SETTING} (n_steps 10 on CartPole-v1, 5 on Acrobot-v1); CPU seconds (`time.process_time`) of training
only, one process, one PyTorch thread (OMP_NUM_THREADS={os.environ.get("OMP_NUM_THREADS", "unset")}).

    {command.strip()}

Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} logical CPUs (shared with other jobs while
measured), Python {platform.python_version()}, torch {th.__version__}.

| env | K | env steps per seed | one after the other (s) | lockstep (s) | ratio |
|---|---|---|---|---|---|
{table}

Where the time goes (cProfile of 10 CartPole-v1 members, 1,500 env steps each): about half in the stacked gradient
steps, 1.4 per env step (at an episode's end a member trains its last n transitions one per step before its next env
step, so the members finish at different times), and half in each member's own Python work per env step (its env and
VecEnv, the rollout loop's bookkeeping, its windows and targets), which lockstep does not share.
"""
    )


if __name__ == "__main__":
    main()
