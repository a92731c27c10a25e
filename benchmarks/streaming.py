"""
NStepSARSA or REINFORCE per step with the streaming recipe (the entries of ``hyperparams/nstep_sarsa_streaming.yml``:
SARSA(λ) along eligibility traces under ObGD, and ``hyperparams/reinforce_streaming.yml``: the book's per-step updates
each bounded by ObGD; sparse initialisation, LayerNorm without parameters, SB3's VecNormalize) against the same network,
initialisation and normalisation with Adam (SARSA: on the one-step squared TD error), over seeds, a fixed number of
episodes each (SARSA: ε as the entry says; a linear ε over the entry's first ``exploration_fraction`` ×
``n_timesteps`` env steps). One env, torch 1 thread per run.

Each finished run appends its episode returns to ``<out>/<algo>-<env>.csv`` and its summary to ``<out>/runs.csv``, with
a key of its settings (the YAML entry as written, the optimizer); a run found there under today's key is not run again,
so an interrupted benchmark resumes where it stopped, and a changed YAML entry is run anew. ``--report`` writes the
results page (``benchmarks/results/streaming.md``) and a figure per env from what is recorded.

``--cost STEPS`` measures the cost per env step instead, paired: for each seed, a run of each optimizer for STEPS env
steps, one after the other in this process (their order alternating from seed to seed), so that both see the same
machine and load; the page gives the ratio per seed (``<out>/cost.csv``, resumable as the runs).

    python -m benchmarks.streaming --algo nstep_sarsa --env CartPole-v1 --seeds 0 1 2 --workers 2
    python -m benchmarks.streaming --algo reinforce --env Acrobot-v1 --optimizers obgd --seeds 0 1
    python -m benchmarks.streaming --algo nstep_sarsa --env CartPole-v1 --cost 20000 --seeds 0 1 2 3 4
    python -m benchmarks.streaming --report
"""

import argparse
import hashlib
import json
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pandas as pd
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
NAMES = {"nstep_sarsa": "NStepSARSA (SARSA(λ))", "reinforce": "REINFORCE"}
HYPERPARAMS = Path(__file__).resolve().parent.parent / "hyperparams"
RESULTS = Path(__file__).resolve().parent / "results"
#: The level a run's 100-episode mean is timed to, per env (the zoo's thresholds; the seed report's −100 on Acrobot-v1)
LEVELS = {"CartPole-v1": 475.0, "Acrobot-v1": -100.0, "LunarLander-v3": 200.0}
#: Adam's step size per step (the same network otherwise)
ADAM_LEARNING_RATE = 5e-4
#: The columns of ``runs.csv`` before the settings' key
RUN_COLUMNS = ["algo", "env", "optimizer", "seed", "steps", "cpu_seconds", "episodes", "last_100", "first_at_level"]
#: Episodes of the moving mean (the last-100-episode mean, as the zoo's and the seed report's)
WINDOW = 100


def yaml_entry(algo: str, env_id: str) -> dict[str, Any]:
    """:return: the streaming YAML's entry of ``env_id``, as written"""
    return dict(yaml.safe_load((HYPERPARAMS / f"{algo}_streaming.yml").read_text())[env_id])


def exploration_steps(algo: str, env_id: str) -> int | None:
    """:return: the env steps over which the YAML entry's ε goes from its initial value to its final one
    (``exploration_fraction`` of ``n_timesteps``), None for REINFORCE"""
    entry = yaml_entry(algo, env_id)
    if "exploration_fraction" not in entry:
        return None
    return round(float(entry["exploration_fraction"]) * float(entry["n_timesteps"]))


def describe_entry(algo: str, env_id: str) -> str:
    """:return: the YAML entry's network and (SARSA) ε schedule in words, e.g. ``2×128 ReLU, ε ← 0.99 ε per episode
    from 1 to 0``"""
    entry = yaml_entry(algo, env_id)
    kwargs = eval(entry["policy_kwargs"], {"nn": nn, "th": th, "ObGD": ObGD})
    net = kwargs.get("net_arch", [])
    layers = f"{len(net)}×{net[0]}" if len(set(net)) == 1 else "–".join(map(str, net))
    words = f"{layers} {kwargs['activation_fn'].__name__}"
    if "exploration_schedule" not in entry:
        return words
    start, end = entry["exploration_initial_eps"], entry["exploration_final_eps"]
    if entry["exploration_schedule"] == "exponential":
        return f"{words}, ε ← {entry['exploration_decay_rate']} ε at each episode's end, from {start} to {end}"
    return f"{words}, ε linear from {start} to {end} over the first {exploration_steps(algo, env_id):,} env steps"


def settings_key(algo: str, env_id: str, optimizer: str) -> str:
    """:return: a digest of what a run's settings come from (the YAML entry as written, the optimizer, Adam's step
    size): a recorded run counts only while its key is the current one, so that a changed entry is run anew"""
    content: dict[str, Any] = {"entry": yaml_entry(algo, env_id), "optimizer": optimizer}
    if optimizer == "adam":
        content["adam_learning_rate"] = ADAM_LEARNING_RATE
    return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()[:12]


def settings(algo: str, env_id: str, optimizer: str) -> dict[str, Any]:
    """:return: the YAML entry's constructor arguments, with Adam in place of ObGD for ``optimizer="adam"``"""
    entry = yaml_entry(algo, env_id)
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


def run(algo: str, env_id: str, optimizer: str, seed: int, episodes: int | None, steps: int | None = None) -> dict[str, Any]:
    """
    :param episodes: episodes to train for (None: ``steps`` env steps)
    :param steps: env steps to train for, where ``episodes`` is None
    :return: the run's episode returns, env steps and seconds of ``learn()``
    """
    th.set_num_threads(1)
    kwargs = settings(algo, env_id, optimizer)
    # A bound on the env steps (the callback stops at the episode count); ε decays over the YAML entry's env steps
    max_episode_steps = gym.spec(env_id).max_episode_steps or 1000
    decay = exploration_steps(algo, env_id)
    total = max(episodes * max_episode_steps, 2 * (decay or 0)) if episodes is not None else steps
    assert total is not None, "run() takes episodes or steps"
    if decay is not None:
        kwargs["exploration_fraction"] = min(1.0, decay / total)
    env = VecNormalize(make_vec_env(env_id, n_envs=1, seed=seed), gamma=kwargs["gamma"])
    model = ALGORITHMS[algo](env=env, seed=seed, device="cpu", **kwargs)
    start = time.process_time()
    model.learn(total, callback=StopTrainingOnMaxEpisodes(episodes) if episodes is not None else None)
    seconds = time.process_time() - start
    returns = np.asarray(env.env_method("get_episode_rewards")[0][:episodes], dtype=float)
    return {
        "algo": algo,
        "env": env_id,
        "optimizer": optimizer,
        "seed": seed,
        "returns": returns,
        "steps": model.num_timesteps,
        "cpu_seconds": seconds,
    }


def summary(returns: np.ndarray, level: float) -> tuple[float, int | None]:
    """:return: the mean of the last ``WINDOW`` episodes and the first episode (1-based) whose ``WINDOW``-episode mean
    reaches ``level`` (None if none does)"""
    means = np.convolve(returns, np.ones(WINDOW) / WINDOW, mode="valid")
    reached = np.flatnonzero(means >= level)
    return float(returns[-WINDOW:].mean()), (int(reached[0]) + WINDOW if len(reached) else None)


def record(result: dict[str, Any], out: Path) -> None:
    """Appends a finished run's episode returns and summary to ``out`` (the run is then done for a resumed benchmark)"""
    out.mkdir(parents=True, exist_ok=True)
    returns = result["returns"]
    episodes = pd.DataFrame(
        {
            "optimizer": result["optimizer"],
            "seed": result["seed"],
            "episode": np.arange(1, len(returns) + 1),
            "return": returns,
        }
    )
    path = out / f"{result['algo']}-{result['env']}.csv"
    episodes.to_csv(path, mode="a", header=not path.exists(), index=False, float_format="%.6g")
    last, first = summary(returns, LEVELS[result["env"]])
    row = {key: result[key] for key in ("algo", "env", "optimizer", "seed", "steps", "cpu_seconds")}
    row.update(episodes=len(returns), last_100=round(last, 2), first_at_level=first or "")
    row.update(settings=settings_key(result["algo"], result["env"], result["optimizer"]))
    runs = out / "runs.csv"
    pd.DataFrame([row]).to_csv(runs, mode="a", header=not runs.exists(), index=False)


def current_runs(out: Path, name: str = "runs.csv") -> pd.DataFrame:
    """:return: the runs recorded in ``out / name`` (``runs.csv``, or ``cost.csv``) under today's settings
    (``settings_key``), the last of any repeated one"""
    path = out / name
    if not path.exists():
        return pd.DataFrame(columns=[*RUN_COLUMNS, "settings"])
    table = pd.read_csv(path)
    groups = list(table[["algo", "env", "optimizer"]].itertuples(index=False, name=None))
    keys = {group: settings_key(*group) for group in set(groups)}
    current = [keys[group] == key for group, key in zip(groups, table["settings"], strict=True)]
    return table[current].drop_duplicates(["algo", "env", "optimizer", "seed"], keep="last")


def done(out: Path) -> set[tuple[str, str, str, int]]:
    """:return: the (algo, env, optimizer, seed) runs recorded in ``out`` under today's settings"""
    return _keys(current_runs(out))


def _keys(table: pd.DataFrame) -> set[tuple[str, str, str, int]]:
    """:return: the (algo, env, optimizer, seed) of each row of a table of runs"""
    return {(a, e, o, int(s)) for a, e, o, s in table[["algo", "env", "optimizer", "seed"]].itertuples(index=False)}


def measure_cost(algos: Sequence[str], env_ids: Sequence[str], seeds: Sequence[int], steps: int, out: Path) -> None:
    """
    The cost per env step, paired: for each seed a run of each optimizer for ``steps`` env steps, in this process one
    after the other (ObGD first for even seeds, Adam first for odd ones), each appended to ``<out>/cost.csv`` as it
    finishes, with its settings' key (a pair recorded under today's settings is not measured again).
    """
    path = out / "cost.csv"
    recorded = _keys(current_runs(out, "cost.csv"))
    out.mkdir(parents=True, exist_ok=True)
    for algo in algos:
        for env_id in env_ids:
            for seed in seeds:
                order = ["obgd", "adam"] if seed % 2 == 0 else ["adam", "obgd"]
                for optimizer in order:
                    if (algo, env_id, optimizer, seed) in recorded:
                        continue
                    result = run(algo, env_id, optimizer, seed, episodes=None, steps=steps)
                    row = {key: result[key] for key in ("algo", "env", "optimizer", "seed", "steps", "cpu_seconds")}
                    row.update(settings=settings_key(algo, env_id, optimizer))
                    pd.DataFrame([row]).to_csv(path, mode="a", header=not path.exists(), index=False)
                    micros = 1e6 * result["cpu_seconds"] / result["steps"]
                    print(f"cost: {algo} {env_id} {optimizer} seed {seed}: {micros:.0f} µs/step", flush=True)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--algo", nargs="+", default=["nstep_sarsa"], choices=sorted(ALGORITHMS))
    parser.add_argument("--env", nargs="+", default=["CartPole-v1"], choices=sorted(LEVELS))
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(10)))
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--optimizers", nargs="+", default=["obgd", "adam"], choices=["obgd", "adam"])
    parser.add_argument("--workers", type=int, default=1, help="runs in parallel, each on one torch thread")
    parser.add_argument("--out", type=Path, default=RESULTS / "streaming", help="where runs are recorded")
    parser.add_argument(
        "--cost", type=int, metavar="STEPS", help="measure the cost per env step instead: both optimizers, paired per seed"
    )
    parser.add_argument("--report", action="store_true", help="only write the results page from the recorded runs")
    parser.add_argument("--page", type=Path, default=RESULTS / "streaming.md", help="the results page")
    args = parser.parse_args(argv)
    if args.cost is not None and not args.report:
        measure_cost(args.algo, args.env, args.seeds, args.cost, args.out)
    elif not args.report:
        recorded = done(args.out)
        jobs = [
            (algo, env_id, optimizer, seed, args.episodes)
            for algo in args.algo
            for env_id in args.env
            for optimizer in args.optimizers
            for seed in args.seeds
            if (algo, env_id, optimizer, seed) not in recorded
        ]
        print(f"{len(jobs)} runs to do ({len(recorded)} recorded in {args.out})", flush=True)
        # Runs record from this process only, one at a time as they finish
        with ProcessPoolExecutor(max_workers=args.workers) as pool:
            for future in as_completed([pool.submit(run, *job) for job in jobs]):
                result = future.result()
                record(result, args.out)
                last, first = summary(result["returns"], LEVELS[result["env"]])
                micros = 1e6 * result["cpu_seconds"] / result["steps"]
                name = " ".join(str(result[key]) for key in ("algo", "env", "optimizer", "seed"))
                print(f"{name}: last 100 episodes {last:.1f}, first at level {first}, {micros:.0f} µs/step", flush=True)
    from benchmarks.streaming_report import write_report

    write_report(args.out, args.page)


if __name__ == "__main__":
    main()
