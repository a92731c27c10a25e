"""
The harness of the diagnostic studies: one run of a variant (an algorithm class and hyperparameters) on one seed,
built by rl-zoo3's ExperimentManager as the benchmark builds it (``benchmarks/runner.py``), evaluated with the
benchmark's protocol (every 5,000 env steps and at the end, 10 deterministic episodes on a separate 10-env
VecEnv, one episode each), with probes that record what the evaluation's policy computed on the states it visited
and what each update saw. Runs are cached (``benchmarks/cache/diagnostics/<study>/<variant>/seed_<k>/``), so a study
resumes where it stopped.
"""

import argparse
import json
import tempfile
import time
from collections.abc import Callable, Sequence
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import rl_zoo3
import torch as th
import yaml
from rl_zoo3.exp_manager import ExperimentManager
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv

from benchmarks.common import DEFAULT_CACHE_DIR, load_hyperparams, register_algorithms
from benchmarks.report import stability

DIAGNOSTICS_CACHE = DEFAULT_CACHE_DIR / "diagnostics"
EVAL_FREQ = 5_000
N_EVAL_EPISODES = 10
THRESHOLD = -100.0

#: Probes of an evaluation: (model, observations of all envs at a step) → per-state quantities to keep
StepProbe = Callable[[BaseAlgorithm, th.Tensor], dict[str, np.ndarray]]


@dataclass
class Variant:
    """
    A candidate: an algorithm class (the package's, or a subclass trying a fix) and changes to the YAML entry.

    :param name: its label in tables and in the cache
    :param algo_class: the class the zoo builds
    :param overrides: keys replacing or adding to the YAML entry (None removes the key)
    :param note: what it tests
    """

    name: str
    algo_class: type[BaseAlgorithm]
    overrides: dict[str, Any] = field(default_factory=dict)
    note: str = ""

    def hyperparams(self, algo: str, env_id: str) -> dict[str, Any]:
        """:return: the YAML entry of ``algo`` on ``env_id`` with this variant's changes"""
        params = load_hyperparams(algo, env_id)
        for key, value in self.overrides.items():
            if value is None:
                params.pop(key, None)
            else:
                params[key] = value
        return params


class ProbedEvaluation(BaseCallback):
    """
    The benchmark's evaluation (``evaluate_policy`` with 10 episodes on 10 envs: one episode each, deterministic),
    written out so that ``probe`` sees every state the evaluated policy visits.

    :param eval_env: a VecEnv of ``n_eval_episodes`` envs
    :param eval_freq: env steps between two evaluations (all envs together)
    :param probe: per-state quantities to record at each step of the evaluation episodes
    :param n_envs: the training envs (the callback is called once per step of all of them)
    """

    def __init__(self, eval_env: VecEnv, eval_freq: int, probe: StepProbe | None, n_envs: int):
        super().__init__()
        self.eval_env = eval_env
        self.every = max(eval_freq // n_envs, 1)
        self.probe = probe
        self.rows: list[dict[str, Any]] = []
        self.eval_time = 0.0

    def _on_step(self) -> bool:
        if self.n_calls % self.every == 0:
            self.evaluate()
        return True

    def evaluate(self) -> None:
        """Evaluate the model now: one row per evaluation, with the probe's summaries (``summarize_probe``)."""
        start = time.perf_counter()
        # NStepSARSA or REINFORCE (gamma, predict on arrays)
        model: Any = self.model
        env = self.eval_env
        n = env.num_envs
        obs = env.reset()
        returns, lengths = np.zeros(n), np.zeros(n, dtype=int)
        done = np.zeros(n, dtype=bool)
        rewards_by_env: list[list[float]] = [[] for _ in range(n)]
        probes_by_env: list[list[dict[str, float]]] = [[] for _ in range(n)]
        while not done.all():
            if self.probe is not None:
                with th.no_grad():
                    values = self.probe(model, th.as_tensor(obs, dtype=th.float32))
                for idx in np.flatnonzero(~done):
                    probes_by_env[idx].append({key: float(array[idx]) for key, array in values.items()})
            actions, _ = model.predict(obs, deterministic=True)
            obs, rewards, dones, _ = env.step(actions)
            for idx in np.flatnonzero(~done):
                returns[idx] += rewards[idx]
                lengths[idx] += 1
                rewards_by_env[idx].append(float(rewards[idx]))
            done |= dones
        row: dict[str, Any] = {
            "timesteps": model.num_timesteps,
            "mean_return": float(returns.mean()),
            "returns": returns.tolist(),
            "lengths": lengths.tolist(),
        }
        if getattr(model, "diagnose_epsilon", False):
            row["stochastic_mean_return"] = self._stochastic_mean_return(model)
        if self.probe is not None:
            row.update(summarize_probe(probes_by_env, rewards_by_env, lengths, model.gamma))
        row.update(training_state(model))
        self.rows.append(row)
        self.eval_time += time.perf_counter() - start

    def _stochastic_mean_return(self, model: Any) -> float:
        """:return: the mean return of one episode per eval env with the behaviour policy (ε-greedy)"""
        env = self.eval_env
        obs = env.reset()
        returns = np.zeros(env.num_envs)
        done = np.zeros(env.num_envs, dtype=bool)
        while not done.all():
            actions, _ = model.predict(obs, deterministic=False)
            obs, rewards, dones, _ = env.step(actions)
            returns += np.where(done, 0.0, rewards)
            done |= dones
        return float(returns.mean())


def summarize_probe(
    probes_by_env: Sequence[Sequence[dict[str, float]]],
    rewards_by_env: Sequence[Sequence[float]],
    lengths: np.ndarray,
    gamma: float,
    max_length: int = 500,
) -> dict[str, float]:
    """
    Summaries of the per-state probe values over the states the evaluation visited: the mean of each, and split by
    episodes that hit the time limit (``loop_``) and those that reached the goal (``goal_``). Also the discounted
    return-to-go G_t the greedy policy actually obtained from each visited state (``g_true``; an episode cut at the
    time limit continues as the loop it is in, −1 per step: −1/(1−γ) from there), and ``bias``, the probe's
    ``value`` minus G_t.

    :return: flat summary columns
    """
    out: dict[str, float] = {}
    frames = []
    for idx, (probes, rewards) in enumerate(zip(probes_by_env, rewards_by_env, strict=True)):
        frame = pd.DataFrame(probes)
        g = np.zeros(len(rewards))
        running = -1.0 / (1.0 - gamma) if lengths[idx] >= max_length else 0.0
        for t in reversed(range(len(rewards))):
            running = rewards[t] + gamma * running
            g[t] = running
        frame["g_true"] = g[: len(frame)]
        if "value" in frame:
            frame["bias"] = frame["value"] - frame["g_true"]
        frame["loop"] = lengths[idx] >= max_length
        frames.append(frame)
    states = pd.concat(frames, ignore_index=True)
    keys = [key for key in states.columns if key != "loop"]
    for key in keys:
        out[key] = float(states[key].mean())
        for name, part in (("loop", states[states["loop"]]), ("goal", states[~states["loop"]])):
            out[f"{name}_{key}"] = float(part[key].mean()) if len(part) else float("nan")
    out["n_loops"] = int((lengths >= max_length).sum())
    return out


def training_state(model: Any) -> dict[str, float]:
    """:return: the schedules' current values: learning rate(s), ε, completed episodes"""
    state: dict[str, float] = {"learning_rate": float(model.policy.optimizer.param_groups[0]["lr"])}
    if hasattr(model.policy, "value_optimizer"):
        state["value_learning_rate"] = float(model.policy.value_optimizer.param_groups[0]["lr"])
    if hasattr(model, "exploration_rate"):
        state["exploration_rate"] = float(model.exploration_rate)
    state["completed_episodes"] = int(getattr(model, "_completed_episodes", 0))
    return state


def run_variant(
    study: str,
    algo: str,
    env_id: str,
    variant: Variant,
    seed: int,
    n_timesteps: int,
    probe: StepProbe | None = None,
    cache_dir: Path = DIAGNOSTICS_CACHE,
    eval_freq: int = EVAL_FREQ,
) -> Path:
    """
    Train ``variant`` on one seed (unless cached) and cache its evaluations (``evals.json``), its per-update
    records (``updates.csv``, if the class keeps ``update_records``) and a summary (``run.json``).

    :return: the run's folder
    """
    params = variant.hyperparams(algo, env_id)
    suffix = "" if eval_freq == EVAL_FREQ else f"-eval{eval_freq}"
    run_dir = cache_dir / study / env_id / variant.name / f"seed_{seed}-{n_timesteps}{suffix}"
    if (run_dir / "run.json").exists():
        cached = json.loads((run_dir / "run.json").read_text())
        if cached["hyperparams"] == params:
            return run_dir
    th.set_num_threads(1)
    register_algorithms()
    previous = rl_zoo3.ALGOS[algo]
    rl_zoo3.ALGOS[algo] = variant.algo_class
    try:
        with tempfile.TemporaryDirectory(prefix="sb3-classic-diag-") as scratch:
            folder = Path(scratch)
            config = folder / "hyperparams.yml"
            config.write_text(yaml.safe_dump({env_id: params}, sort_keys=True))
            with open(folder / "train.log", "w") as log, redirect_stdout(log), redirect_stderr(log):
                manager = ExperimentManager(
                    argparse.Namespace(),
                    algo,
                    env_id,
                    str(folder / "zoo"),
                    n_timesteps=n_timesteps,
                    eval_freq=0,
                    seed=seed,
                    log_interval=-1,
                    verbose=0,
                    device="cpu",
                    config=str(config),
                )
                setup = manager.setup_experiment()
                assert setup is not None
                model, _ = setup
                eval_env = manager.create_envs(N_EVAL_EPISODES, eval_env=True)
                evaluation = ProbedEvaluation(eval_env, eval_freq, probe, manager.n_envs)
                start = time.perf_counter()
                model.learn(n_timesteps, callback=[*manager.callbacks, evaluation])
                learn_time = time.perf_counter() - start - evaluation.eval_time
                if not evaluation.rows or evaluation.rows[-1]["timesteps"] != model.num_timesteps:
                    evaluation.evaluate()
    finally:
        rl_zoo3.ALGOS[algo] = previous
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "evals.json").write_text(json.dumps(evaluation.rows))
    records = getattr(model, "update_records", None)
    if records:
        pd.DataFrame(records).to_csv(run_dir / "updates.csv", index=False, float_format="%.6g")
    summary = {
        "variant": variant.name,
        "seed": seed,
        "hyperparams": params,
        "num_timesteps": int(model.num_timesteps),
        "n_episodes": int(getattr(model, "_completed_episodes", 0)),
        "learn_time_s": learn_time,
        "final_return": evaluation.rows[-1]["mean_return"],
    }
    (run_dir / "run.json").write_text(json.dumps(summary, indent=1, default=str))
    return run_dir


def load_evals(run_dir: Path) -> pd.DataFrame:
    """:return: one row per evaluation of a cached run"""
    return pd.DataFrame(json.loads((run_dir / "evals.json").read_text()))


def curve_from(means: pd.DataFrame, threshold: float) -> float:
    """
    :param means: per evaluation index, ``timesteps`` and the ``mean`` over seeds of the evaluations' mean returns
    :return: the first env step from which the mean curve stays ≥ ``threshold`` to the end (NaN if it ends below)
    """
    below = np.flatnonzero(means["mean"].to_numpy() < threshold)
    if len(below) == 0:
        return float(means["timesteps"].iloc[0])
    if below[-1] == len(means) - 1:
        return float("nan")
    return float(means["timesteps"].iloc[below[-1] + 1])


def issue_metrics(evals_by_seed: dict[int, pd.DataFrame], threshold: float = THRESHOLD) -> dict[str, Any]:
    """
    The issue's metrics of one variant over its seeds.

    :param evals_by_seed: per seed, its evaluations (``timesteps``, ``mean_return``)
    :return: ``final_mean``/``final_std`` (over seeds), ``worst_final``, ``finals_at`` (seeds whose final evaluation
        is ≥ threshold), ``reached`` (seeds that ever reached it), ``curve_from`` (``curve_from`` of the mean curve
        over the evaluations every seed has), ``stayed_pooled`` and ``stayed_median`` (``benchmarks.report.stability``)
    """
    finals = np.array([evals["mean_return"].iloc[-1] for evals in evals_by_seed.values()])
    seeds_curve = pd.concat(
        [evals[["timesteps", "mean_return"]].assign(index=np.arange(len(evals))) for evals in evals_by_seed.values()]
    )
    counts = seeds_curve.groupby("index")["mean_return"].count()
    complete = counts[counts == len(evals_by_seed)].index
    means = (
        seeds_curve[seeds_curve["index"].isin(complete)]
        .groupby("index")
        .agg(timesteps=("timesteps", "first"), mean=("mean_return", "mean"))
    )
    # The final evaluations may differ in steps by a rollout; the curve's last point is their mean
    stab = stability({seed: evals["mean_return"].to_numpy() for seed, evals in evals_by_seed.items()}, threshold)
    return {
        "seeds": len(finals),
        "final_mean": float(finals.mean()),
        "final_std": float(finals.std(ddof=1)) if len(finals) > 1 else 0.0,
        "worst_final": float(finals.min()),
        "finals_at": int((finals >= threshold).sum()),
        "reached": stab["reached"],
        "curve_from": curve_from(means, threshold),
        "stayed_pooled": stab["stayed_pooled"],
        "stayed_median": stab["stayed_median"],
        "finals": finals.tolist(),
    }


def metrics_table(rows: Sequence[dict[str, Any]]) -> str:
    """:return: the issue's metrics of several variants as a markdown table"""
    lines = [
        "| Variant | Seeds | Final (mean ± std) | Worst final | Finals ≥ −100 | Reached | Mean curve ≥ −100 from "
        "| Stayed (pooled) | Stayed (median) | Learn s | Per-seed finals |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        curve = "never" if np.isnan(row["curve_from"]) else f"{row['curve_from']:,.0f}"
        stayed = (
            "–" if np.isnan(row["stayed_pooled"]) else f"{row['stayed_pooled']:.0%}",
            "–" if np.isnan(row["stayed_median"]) else f"{row['stayed_median']:.0%}",
        )
        lines.append(
            f"| {row['variant']} | {row['seeds']} | {row['final_mean']:.1f} ± {row['final_std']:.1f} "
            f"| {row['worst_final']:.1f} | {row['finals_at']}/{row['seeds']} | {row['reached']}/{row['seeds']} "
            f"| {curve} | {stayed[0]} | {stayed[1]} | {row.get('learn_time_s', float('nan')):.0f} "
            f"| {', '.join(f'{final:.0f}' for final in row['finals'])} |"
        )
    return "\n".join(lines)


def parse_seeds(text: str) -> list[int]:
    """:return: the seeds of ``"0-4"`` or ``"0,3,9"``"""
    seeds: list[int] = []
    for part in text.split(","):
        low, _, high = part.partition("-")
        seeds += list(range(int(low), int(high or low) + 1))
    return seeds


def collect(
    study: str,
    algo: str,
    env_id: str,
    variants: Sequence[Variant],
    n_timesteps: int,
    cache_dir: Path = DIAGNOSTICS_CACHE,
) -> dict[str, dict[int, Path]]:
    """
    :return: per variant, the cached runs of the study with this budget, by seed. A variant is a change to the YAML
        entry, so runs made while the entry was different are another setting: they are listed under the variant's
        name followed by the settings that differed then (``yaml [earlier: gamma=0.99]``)
    """
    found: dict[str, dict[int, Path]] = {}
    for variant in variants:
        current = variant.hyperparams(algo, env_id)
        folder = cache_dir / study / env_id / variant.name
        for path in sorted(folder.glob(f"seed_*-{n_timesteps}")):
            if not (path / "run.json").exists():
                continue
            params = json.loads((path / "run.json").read_text())["hyperparams"]
            changed = sorted(key for key in current.keys() | params.keys() if current.get(key) != params.get(key))
            name = variant.name
            if changed:
                name += " [earlier: " + ", ".join(f"{key}={params.get(key, '(unset)')}" for key in changed) + "]"
            found.setdefault(name, {})[int(path.name.split("-")[0].removeprefix("seed_"))] = path
    return {name: dict(sorted(runs.items())) for name, runs in found.items()}


def variant_metrics(name: str, runs: dict[int, Path], seeds: Sequence[int] | None = None) -> dict[str, Any]:
    """:return: ``issue_metrics`` of one variant's cached runs (those of ``seeds`` if given), with its learn time"""
    chosen = {seed: path for seed, path in runs.items() if seeds is None or seed in seeds}
    metrics = issue_metrics({seed: load_evals(path) for seed, path in chosen.items()})
    times = [json.loads((path / "run.json").read_text())["learn_time_s"] for path in chosen.values()]
    return {"variant": name, **metrics, "learn_time_s": float(np.mean(times))}


def probe_table(runs: dict[int, Path], columns: Sequence[str], every: int = 4) -> str:
    """
    :param runs: one variant's runs by seed
    :param columns: the evaluation columns to show (mean over seeds; ``n_loops`` summed)
    :param every: show every this many evaluations (and the last)
    :return: a markdown table, one row per evaluation
    """
    frames = [load_evals(path).assign(seed=seed, index=lambda f: np.arange(len(f))) for seed, path in runs.items()]
    evals = pd.concat(frames, ignore_index=True)
    present = [column for column in columns if column in evals]
    agg: dict[str, Any] = {column: ("sum" if column == "n_loops" else "mean") for column in present}
    table = evals.groupby("index").agg({"timesteps": "first", "mean_return": "mean", **agg})
    shown = table.iloc[[*range(0, len(table) - 1, every), len(table) - 1]]
    header = ["step", "mean return", *present]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for _, row in shown.iterrows():
        cells = [f"{row['timesteps']:,.0f}", f"{row['mean_return']:.1f}"]
        cells += [f"{row[column]:.3g}" for column in present]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def run_study(
    study: str,
    algo: str,
    env_id: str,
    variants: Sequence[Variant],
    probe: StepProbe | None,
    argv: Sequence[str] | None = None,
) -> None:
    """
    The command line of a study: ``--variants a,b --seeds 0-4 --steps 200000`` trains what is not cached, then prints
    the issue's metrics of every variant with cached runs.
    """
    by_name = {variant.name: variant for variant in variants}
    parser = argparse.ArgumentParser(description=f"Diagnostic study {study} ({algo} on {env_id})")
    parser.add_argument("--variants", default="", help=f"comma-separated, of: {', '.join(by_name)}")
    parser.add_argument("--seeds", default="0-4", help="e.g. 0-4 or 0,3,9")
    parser.add_argument("--steps", type=int, default=200_000, help="env steps per run")
    parser.add_argument("--eval-freq", type=int, default=EVAL_FREQ, help="env steps between evaluations")
    parser.add_argument("--list", action="store_true", help="list the variants and exit")
    args = parser.parse_args(argv)
    if args.list:
        for variant in variants:
            print(f"{variant.name}: {variant.note} {variant.overrides}")
        return
    for name in filter(None, args.variants.split(",")):
        for seed in parse_seeds(args.seeds):
            start = time.perf_counter()
            run_dir = run_variant(study, algo, env_id, by_name[name], seed, args.steps, probe, eval_freq=args.eval_freq)
            summary = json.loads((run_dir / "run.json").read_text())
            print(
                f"{name} seed {seed}: final {summary['final_return']:.1f}, {summary['n_episodes']} training episodes "
                f"({time.perf_counter() - start:.0f} s)",
                flush=True,
            )
    found = collect(study, algo, env_id, variants, args.steps)
    print(metrics_table([variant_metrics(name, runs) for name, runs in found.items()]))
