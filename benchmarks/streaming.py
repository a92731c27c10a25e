"""
NStepSARSA or REINFORCE per step with the streaming recipe (the entries of ``hyperparams/nstep_sarsa_streaming.yml``:
SARSA(λ) along eligibility traces under ObGD, and ``hyperparams/reinforce_streaming.yml``: the book's per-step updates
each bounded by ObGD; sparse initialisation, LayerNorm without parameters, SB3's VecNormalize) against the same network,
initialisation and normalisation with Adam (SARSA: on the one-step squared TD error), over seeds, a fixed number of
episodes each (SARSA: ε linear from 1 to 0.01 over the first 20k env steps). One env, torch 1 thread. It prints, per run:
the mean return of the last 100 episodes, the first episode whose 100-episode mean reaches the level, and µs per env
step.

    python -m benchmarks.streaming --seeds 0 1 2 --episodes 1000
    python -m benchmarks.streaming --seeds 0 --optimizers obgd
    python -m benchmarks.streaming --algo reinforce --seeds 0 --optimizers obgd --episodes 500
"""

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch as th
import yaml
from stable_baselines3.common.callbacks import StopTrainingOnMaxEpisodes
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize
from torch import nn

from sb3_classic import REINFORCE, NStepSARSA
from sb3_classic.common.obgd import ObGD

#: The algorithms, each with its streaming YAML
ALGORITHMS: dict[str, type[NStepSARSA] | type[REINFORCE]] = {"nstep_sarsa": NStepSARSA, "reinforce": REINFORCE}
HYPERPARAMS = Path(__file__).resolve().parent.parent / "hyperparams"
#: The level a run's 100-episode mean is timed to, per env
LEVELS = {"CartPole-v1": 475.0, "Acrobot-v1": -100.0}
#: Env steps over which ε goes from 1 to its final value
EXPLORATION_STEPS = 20_000
#: Adam's step size per step (the same network otherwise)
ADAM_LEARNING_RATE = 5e-4


def settings(algo: str, env_id: str, optimizer: str) -> dict[str, Any]:
    """:return: the YAML entry's constructor arguments, with Adam in place of ObGD for ``optimizer="adam"``"""
    entry = dict(yaml.safe_load((HYPERPARAMS / f"{algo}_streaming.yml").read_text())[env_id])
    for key in ("n_timesteps", "n_envs", "normalize"):
        entry.pop(key)
    entry["policy_kwargs"] = eval(entry["policy_kwargs"], {"nn": nn, "th": th, "ObGD": ObGD})
    if optimizer == "adam":
        entry["policy_kwargs"].update(optimizer_class=th.optim.Adam, optimizer_kwargs=None)
        entry["policy_kwargs"].pop("value_optimizer_kwargs", None)
        entry["learning_rate"] = ADAM_LEARNING_RATE
        if algo == "reinforce":
            entry["value_learning_rate"] = ADAM_LEARNING_RATE
    return entry


def run(algo: str, env_id: str, optimizer: str, seed: int, episodes: int) -> dict[str, Any]:
    """:return: the run's episode returns, env steps and seconds"""
    kwargs = settings(algo, env_id, optimizer)
    # A bound on the env steps (the callback stops at the episode count); ε decays over the first EXPLORATION_STEPS
    total = max(episodes * 500, 2 * EXPLORATION_STEPS)
    if algo == "nstep_sarsa":
        kwargs["exploration_fraction"] = EXPLORATION_STEPS / total
    env = VecNormalize(make_vec_env(env_id, n_envs=1, seed=seed), gamma=kwargs["gamma"])
    model = ALGORITHMS[algo](env=env, seed=seed, device="cpu", **kwargs)
    start = time.perf_counter()
    model.learn(total, callback=StopTrainingOnMaxEpisodes(episodes))
    seconds = time.perf_counter() - start
    returns = np.asarray(env.env_method("get_episode_rewards")[0][:episodes], dtype=float)
    return {"returns": returns, "steps": model.num_timesteps, "seconds": seconds}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--algo", default="nstep_sarsa", choices=sorted(ALGORITHMS))
    parser.add_argument("--env", default="CartPole-v1", choices=sorted(LEVELS))
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--optimizers", nargs="+", default=["obgd", "adam"], choices=["obgd", "adam"])
    args = parser.parse_args(argv)
    th.set_num_threads(1)
    level = LEVELS[args.env]
    print(f"| {args.env} | seed | last 100 episodes | first episode at {level:g} (100-episode mean) | env steps | µs/step |")
    print("|---|---|---|---|---|---|")
    for optimizer in args.optimizers:
        for seed in args.seeds:
            result = run(args.algo, args.env, optimizer, seed, args.episodes)
            returns = result["returns"]
            means = np.convolve(returns, np.ones(100) / 100, mode="valid")
            reached = np.flatnonzero(means >= level)
            first = str(int(reached[0]) + 100) if len(reached) else "never"
            micros = 1e6 * result["seconds"] / result["steps"]
            print(
                f"| {optimizer} | {seed} | {returns[-100:].mean():.1f} | {first} | {result['steps']} | {micros:.0f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
