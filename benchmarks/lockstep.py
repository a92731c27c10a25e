"""
CPU seconds of K seeds of one setting trained in lockstep (``NStepSARSAPopulation``, ``REINFORCEPopulation``) against
the same K seeds trained one after the other (``model.learn``), in one process with one PyTorch thread. NStepSARSA: the
per-step setting (2 × 128 MLP, n_steps 10 on CartPole-v1 and 5 on Acrobot-v1, learning_rate 5e-4, train_freq 1,
gradient_steps 1, update_mode "per_step"). REINFORCE: the CartPole-v1 and Acrobot-v1 entries of
``hyperparams/reinforce.yml`` (update_mode "batch"), and the seed report's per-step final model on CartPole-v1
(``studies/seed_report/fig08-reinforce-cartpole-final.yml``).

    python -m benchmarks.lockstep                       # writes benchmarks/results/lockstep.{csv,md}
    python -m benchmarks.lockstep --k 10 --steps 3000
    python -m benchmarks.lockstep --algo REINFORCE --out /tmp/lockstep

Seconds are ``time.process_time`` of training only (the models are built before the clock starts).
"""

import argparse
import csv
import os
import platform
import shlex
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch as th
import yaml
from stable_baselines3.common.env_util import make_vec_env

from sb3_classic import REINFORCE, NStepSARSA
from sb3_classic.harness.common import load_hyperparams, positive_int
from sb3_classic.reinforce import REINFORCEPopulation
from sb3_classic.sarsa import NStepSARSAPopulation

RESULTS = Path(__file__).resolve().parent / "results"
N_STEPS = {"CartPole-v1": 10, "Acrobot-v1": 5}
SETTING = "per_step: 2x128 MLP, lr 5e-4, train_freq 1, gradient_steps 1"
ALGOS = ("NStepSARSA", "REINFORCE")
#: The seed report's per-step final model of REINFORCE on CartPole-v1
FINAL_PER_STEP = Path(__file__).resolve().parent / "studies" / "seed_report" / "fig08-reinforce-cartpole-final.yml"


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


def _policy_kwargs(value: str | dict[str, Any] | None) -> dict[str, Any]:
    """
    :param value: ``policy_kwargs`` as a zoo YAML writes it (a string the zoo evaluates, with ``nn`` for torch.nn) or
        as a study YAML does (a mapping, classes named ``nn.X``)
    :return: the keyword arguments
    """
    if value is None:
        return {}
    if isinstance(value, str):
        return dict(eval(value, {"nn": th.nn, "dict": dict}))  # the zoo's own parsing of the string
    return {
        key: getattr(th.nn, item[3:]) if isinstance(item, str) and item.startswith("nn.") else item
        for key, item in value.items()
    }


def reinforce_settings() -> list[tuple[str, str, dict[str, Any]]]:
    """:return: (env id, setting name, REINFORCE's keyword arguments) of each REINFORCE row"""
    settings = []
    for env_id in N_STEPS:
        entry = load_hyperparams("reinforce", env_id)
        kwargs = {key: value for key, value in entry.items() if key not in ("n_timesteps", "policy", "n_envs")}
        kwargs["policy_kwargs"] = _policy_kwargs(kwargs.get("policy_kwargs"))
        settings.append((env_id, "batch: hyperparams/reinforce.yml", kwargs))
    study = yaml.safe_load(FINAL_PER_STEP.read_text())
    kwargs = {key: value for key, value in study["hyperparams"].items() if key not in ("policy", "n_envs")}
    kwargs["policy_kwargs"] = _policy_kwargs(kwargs.get("policy_kwargs"))
    settings.append((study["env"], "per_step: the seed report's final model (fig08)", kwargs))
    return settings


def make_reinforce_models(env_id: str, k: int, kwargs: dict[str, Any]) -> list[REINFORCE]:
    """:return: K REINFORCE members of one setting, seeds 0..K-1, each with its own env seeded as its model"""
    return [REINFORCE("MlpPolicy", make_vec_env(env_id, n_envs=1, seed=seed), seed=seed, **kwargs) for seed in range(k)]


def timed_reinforce(env_id: str, k: int, steps: int, kwargs: dict[str, Any]) -> tuple[float, float]:
    """:return: CPU seconds of the K REINFORCE seeds one after the other, and in lockstep"""
    models = make_reinforce_models(env_id, k, kwargs)
    start = time.process_time()
    for model in models:
        model.learn(steps)
    separate = time.process_time() - start
    models = make_reinforce_models(env_id, k, kwargs)
    start = time.process_time()
    REINFORCEPopulation(models).learn(steps)
    return separate, time.process_time() - start


def sarsa_rows(env_ids: list[str], k: int, steps: int) -> list[dict[str, Any]]:
    """:return: the NStepSARSA rows, one per env"""
    rows = []
    for env_id in env_ids:
        separate, lockstep = timed(env_id, k, steps)
        rows.append(dict(algo="NStepSARSA", env_id=env_id, setting=f"{SETTING}, n_steps {N_STEPS[env_id]}", k=k,
                         separate_cpu_s=f"{separate:.2f}", lockstep_cpu_s=f"{lockstep:.2f}"))  # fmt: skip
        print(
            f"NStepSARSA {env_id}: separate {separate:.2f} s, lockstep {lockstep:.2f} s, {separate / lockstep:.2f}x",
            flush=True,
        )
    return rows


def reinforce_rows(env_ids: list[str], k: int, steps: int) -> list[dict[str, Any]]:
    """:return: the REINFORCE rows, one per setting of ``reinforce_settings`` on the given envs"""
    rows = []
    for env_id, setting, kwargs in reinforce_settings():
        if env_id not in env_ids:
            continue
        separate, lockstep = timed_reinforce(env_id, k, steps, kwargs)
        rows.append(dict(algo="REINFORCE", env_id=env_id, setting=setting, k=k,
                         separate_cpu_s=f"{separate:.2f}", lockstep_cpu_s=f"{lockstep:.2f}"))  # fmt: skip
        print(
            f"REINFORCE {env_id} {setting}: separate {separate:.2f} s, lockstep {lockstep:.2f} s, {separate / lockstep:.2f}x",
            flush=True,
        )
    return rows


#: Each algorithm's rows
ROWS: dict[str, Callable[[list[str], int, int], list[dict[str, Any]]]] = {
    "NStepSARSA": sarsa_rows,
    "REINFORCE": reinforce_rows,
}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--k", type=positive_int, default=10, help="seeds (members)")
    parser.add_argument("--steps", type=positive_int, default=3000, help="env steps per seed")
    parser.add_argument("--env", nargs="+", default=list(N_STEPS), choices=list(N_STEPS))
    parser.add_argument("--algo", nargs="+", default=list(ALGOS), choices=list(ALGOS), help="the algorithms' rows")
    parser.add_argument("--out", type=Path, default=RESULTS, help="the folder of lockstep.csv and lockstep.md")
    args = parser.parse_args(argv)
    th.set_num_threads(1)
    rows = [row for algo in args.algo for row in ROWS[algo](args.env, args.k, args.steps)]
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "lockstep.csv", "w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    command = "python -m benchmarks.lockstep " + shlex.join(argv if argv is not None else sys.argv[1:])
    table = "\n".join(
        f"| {row['algo']} | {row['env_id']} | {row['setting']} | {row['k']} | {args.steps} | {row['separate_cpu_s']} | "
        f"{row['lockstep_cpu_s']} | {float(row['separate_cpu_s']) / float(row['lockstep_cpu_s']):.2f}× |"
        for row in rows
    )
    threads = os.environ.get("OMP_NUM_THREADS", "unset")
    (args.out / "lockstep.md").write_text(
        f"""# K seeds in lockstep against one after the other

NStepSARSA, {SETTING} (n_steps 10 on CartPole-v1, 5 on Acrobot-v1).
REINFORCE, the CartPole-v1 and Acrobot-v1 entries of hyperparams/reinforce.yml (update_mode batch) and the seed
report's per-step final model on CartPole-v1 (studies/seed_report/fig08-reinforce-cartpole-final.yml).
CPU seconds (`time.process_time`) of training only, one process, one PyTorch thread (OMP_NUM_THREADS={threads}).

    {command.strip()}

Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} logical CPUs (shared with other jobs while
measured), Python {platform.python_version()}, torch {th.__version__}.

| algorithm | env | setting | K | env steps per seed | one after the other (s) | lockstep (s) | ratio |
|---|---|---|---|---|---|---|---|
{table}

Where NStepSARSA's time goes (cProfile of 10 CartPole-v1 members, 1,500 env steps each): about half in the stacked
gradient steps, 1.4 per env step (at an episode's end a member trains its last n transitions one per step before its
next env step, so the members finish at different times), and half in each member's own Python work per env step (its
env and VecEnv, the rollout loop's bookkeeping, its windows and targets), which lockstep does not share.

REINFORCE's batch mode shares the forward pass of the rollouts; its updates, one per episode and member, seldom fall
on the same env step, so most stacked gradient steps train one member, and each member's own work per env step (its
env and VecEnv, the rollout loop's bookkeeping) is most of the time. The per-step mode trains an episode's T steps one
stacked gradient step at a time while the other members go on with theirs, and shares those steps too.
"""
    )


if __name__ == "__main__":
    main()
