"""
Invalid-action masking: REINFORCE and NStepSARSA with and without masks beside sb3-contrib's ``MaskablePPO``, on
sb3-contrib's ``InvalidActionEnvDiscrete`` (an identity task: reward 1 when the action equals the observed state,
else 0; in each state a fixed number of the other actions is illegal, and ``action_masks()`` says which).

    python -m benchmarks.masking                 # the committed benchmarks/results/masking.md and masking.png
    python -m benchmarks.masking --seeds 3 --budget 10000 --results-dir /tmp/masking   # a smaller run

Each (algorithm, variant, seed) run is evaluated every ``--eval-freq`` env steps (and before training and at its end)
with sb3-contrib's ``evaluate_policy``, deterministic, with masks for the masked variants and ``MaskablePPO`` and
without for the unmasked ones, on an env of its own. A run's learning curve is written to
``<results-dir>/masking/<algo>-<variant>-seed_<k>.json`` when it finishes; a rerun with the same settings and package
versions skips the runs written, so an interrupted command resumes.
"""

import argparse
import hashlib
import inspect
import json
import shlex
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import gymnasium
import matplotlib.pyplot as plt
import numpy as np
import sb3_contrib
import stable_baselines3
import torch as th
from sb3_contrib import MaskablePPO
from sb3_contrib.common.envs import InvalidActionEnvDiscrete
from sb3_contrib.common.maskable.evaluation import evaluate_policy
from stable_baselines3.common.callbacks import BaseCallback

import sb3_classic
from sb3_classic import REINFORCE, NStepSARSA
from sb3_classic.harness.common import HARNESS_PACKAGES, positive_int
from sb3_classic.studies.stats import Interval, episode_band, interval

RESULTS_DIR = Path(__file__).resolve().parent / "results"

# (algorithm, variant): masked runs learn and are evaluated with masks, unmasked ones without
RUNS = [
    ("reinforce", "masked"),
    ("reinforce", "unmasked"),
    ("nstep_sarsa", "masked"),
    ("nstep_sarsa", "unmasked"),
    ("maskable_ppo", "masked"),
]
ALGO_NAMES = {"reinforce": "REINFORCE", "nstep_sarsa": "NStepSARSA", "maskable_ppo": "MaskablePPO"}
ALGO_CLASSES: dict[str, type[REINFORCE] | type[NStepSARSA] | type[MaskablePPO]] = {
    "reinforce": REINFORCE,
    "nstep_sarsa": NStepSARSA,
    "maskable_ppo": MaskablePPO,
}
EVAL_SEED_OFFSET = 10_000  # the evaluation env's seed is the run's plus this


@dataclass(frozen=True)
class Settings:
    """What a run's result depends on, besides its algorithm, variant and seed."""

    dim: int = 20
    n_invalid_actions: int = 15
    ep_length: int = 100
    # The action does not change the next state, so the return after the current reward is the same for every
    # action: a long horizon only adds a large action-independent term to q̂ and v̂. sb3-contrib's example for this
    # env uses 0.4 (with MaskablePPO); every algorithm gets it.
    gamma: float = 0.4
    budget: int = 10_000
    eval_freq: int = 250
    n_eval_episodes: int = 5

    @property
    def max_return(self) -> float:
        """Every step rewarded."""
        return float(self.ep_length)

    @property
    def threshold(self) -> float:
        """90% of the maximum return."""
        return 0.9 * self.max_return


def make_env(settings: Settings) -> InvalidActionEnvDiscrete:
    return InvalidActionEnvDiscrete(
        dim=settings.dim, ep_length=settings.ep_length, n_invalid_actions=settings.n_invalid_actions
    )


def run_path(cache_dir: Path, algo: str, variant: str, seed: int) -> Path:
    return cache_dir / f"{algo}-{variant}-seed_{seed}.json"


def training_sources_digest() -> str:
    """:return: a digest of the package's sources that training depends on (not the zoo registration, the harness or
    the study runner)"""
    package = Path(sb3_classic.__file__).resolve().parent
    digest = hashlib.sha256()
    for source in sorted(package.rglob("*.py")):
        relative = source.relative_to(package)
        if relative.parts[0] not in (*HARNESS_PACKAGES, "zoo.py"):
            digest.update(relative.as_posix().encode())
            digest.update(source.read_bytes())
    return digest.hexdigest()[:12]


def run_key(algo: str, variant: str, seed: int, settings: Settings) -> str:
    """:return: a digest of the run's settings and of the versions of the code that trains it"""
    versions = {
        "sb3_classic": f"{sb3_classic.__version__}+{training_sources_digest()}",
        "sb3_contrib": sb3_contrib.__version__,
        "stable_baselines3": stable_baselines3.__version__,
        "gymnasium": gymnasium.__version__,
        "torch": th.__version__,
        "numpy": np.__version__,
    }
    text = json.dumps({"algo": algo, "variant": variant, "seed": seed, **asdict(settings), **versions}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


class _Evaluations(BaseCallback):
    """Evaluates every ``eval_freq`` env steps (one env: one step per call) with sb3-contrib's ``evaluate_policy``."""

    def __init__(self, eval_env: InvalidActionEnvDiscrete, settings: Settings, use_masking: bool):
        super().__init__()
        self.eval_env = eval_env
        self.settings = settings
        self.use_masking = use_masking
        self.timesteps: list[int] = []
        self.mean_returns: list[float] = []

    def evaluate(self) -> None:
        mean_return, _ = evaluate_policy(
            self.model,  # type: ignore[arg-type]
            self.eval_env,
            n_eval_episodes=self.settings.n_eval_episodes,
            deterministic=True,
            warn=False,
            use_masking=self.use_masking,
        )
        self.timesteps.append(int(self.model.num_timesteps))
        self.mean_returns.append(float(np.mean(mean_return)))

    def _on_step(self) -> bool:
        if self.model.num_timesteps % self.settings.eval_freq == 0:
            self.evaluate()
        return True


def train_run(algo: str, variant: str, seed: int, settings: Settings) -> dict[str, Any]:
    """
    :return: the run's learning curve (``timesteps``, ``mean_return`` of each evaluation) and its training time
    """
    use_masking = variant == "masked"
    model = ALGO_CLASSES[algo]("MlpPolicy", make_env(settings), gamma=settings.gamma, seed=seed)
    eval_env = make_env(settings)
    eval_env.reset(seed=seed + EVAL_SEED_OFFSET)
    eval_env.action_space.seed(seed + EVAL_SEED_OFFSET)
    evaluations = _Evaluations(eval_env, settings, use_masking)
    evaluations.init_callback(model)
    evaluations.evaluate()  # before training
    start = time.perf_counter()
    model.learn(settings.budget, callback=evaluations, use_masking=use_masking)
    seconds = time.perf_counter() - start
    if evaluations.timesteps[-1] != model.num_timesteps:
        evaluations.evaluate()  # at the end of training
    return {"timesteps": evaluations.timesteps, "mean_return": evaluations.mean_returns, "seconds": seconds}


def load_or_train(algo: str, variant: str, seed: int, settings: Settings, cache_dir: Path) -> tuple[dict[str, Any], bool]:
    """
    :return: the run's record, and whether it was trained now (False: read from ``cache_dir``)
    """
    path = run_path(cache_dir, algo, variant, seed)
    key = run_key(algo, variant, seed, settings)
    if path.exists():
        record = json.loads(path.read_text())
        if record.get("key") == key:
            return record, False
    th.set_num_threads(1)
    curve = train_run(algo, variant, seed, settings)
    record = {"key": key, "algo": algo, "variant": variant, "seed": seed, "settings": asdict(settings), **curve}
    cache_dir.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix(".partial")
    partial.write_text(json.dumps(record, indent=1) + "\n")
    partial.rename(path)  # a run's file appears only once it is complete
    return record, True


def first_reaching(timesteps: np.ndarray, returns: np.ndarray, target: float) -> int | None:
    """:return: the env steps of the first evaluation at ``target`` or above, None if there is none"""
    reached = np.flatnonzero(returns >= target)
    return int(timesteps[reached[0]]) if len(reached) else None


@dataclass
class Summary:
    algo: str
    variant: str
    timesteps: np.ndarray  # the evaluations' env steps (the same for every seed)
    returns: np.ndarray  # seeds × evaluations
    seconds: float  # mean training time of a run

    @property
    def label(self) -> str:
        name = ALGO_NAMES[self.algo]
        return name if self.algo == "maskable_ppo" else f"{name}, {self.variant}"

    @property
    def final(self) -> Interval:
        return interval(self.returns[:, -1])

    def mean_curve_reaching(self, target: float) -> int | None:
        """:return: the env steps where the mean over seeds first reaches ``target``"""
        return first_reaching(self.timesteps, self.returns.mean(axis=0), target)

    def seeds_reaching(self, target: float) -> list[int]:
        """:return: each seed's env steps to its first evaluation at ``target``, of the seeds that reach it"""
        steps = (first_reaching(self.timesteps, seed_returns, target) for seed_returns in self.returns)
        return [step for step in steps if step is not None]


def summarize(records: list[dict[str, Any]]) -> Summary:
    timesteps = [record["timesteps"] for record in records]
    # Runs of whole episodes (REINFORCE) may end a few steps past the budget: the curves are compared at the
    # evaluation steps, the last one being each run's end
    length = min(len(steps) for steps in timesteps)
    returns = np.array([record["mean_return"][:length] for record in records])
    return Summary(
        algo=records[0]["algo"],
        variant=records[0]["variant"],
        timesteps=np.array(timesteps[0][:length]),
        returns=returns,
        seconds=float(np.mean([record["seconds"] for record in records])),
    )


def _steps(value: int | None) -> str:
    return "not reached" if value is None else f"{value:,}"


def _seed_steps(steps: list[int], n_seeds: int) -> str:
    if not steps:
        return f"0/{n_seeds}"
    return f"{np.median(steps):,.0f} ({min(steps):,}–{max(steps):,}), {len(steps)}/{n_seeds}"


def targets(summaries: dict[tuple[str, str], Summary], settings: Settings) -> list[str]:
    """:return: one line per target, with its verdict"""
    lines = []
    budget = f"more than {settings.budget:,}"
    for algo in ("reinforce", "nstep_sarsa"):
        masked = summaries[algo, "masked"].mean_curve_reaching(settings.threshold)
        unmasked = summaries[algo, "unmasked"].mean_curve_reaching(settings.threshold)
        met = masked is not None and (unmasked is None or masked < unmasked)
        lines.append(
            f"- Masked {ALGO_NAMES[algo]} reaches {settings.threshold:g} in fewer env steps than unmasked "
            f"(mean curves: {_steps(masked)} against {_steps(unmasked) if unmasked is not None else budget}): "
            f"{'met' if met else '**not met**'}."
        )
    ppo = summaries["maskable_ppo", "masked"]
    ppo_final = float(ppo.returns[:, -1].mean())
    ppo_steps = ppo.mean_curve_reaching(ppo_final)
    assert ppo_steps is not None  # the final evaluation is there
    ours = {algo: summaries[algo, "masked"].mean_curve_reaching(ppo_final) for algo in ("reinforce", "nstep_sarsa")}
    met = any(steps is not None and steps <= ppo_steps for steps in ours.values())
    reached = "; ".join(f"masked {ALGO_NAMES[algo]} at {_steps(steps)}" for algo, steps in ours.items())
    lines.append(
        f"- Masked REINFORCE or NStepSARSA reaches MaskablePPO's final mean return ({ppo_final:.1f}) in no more env steps "
        f"than MaskablePPO (mean curves: MaskablePPO at {ppo_steps:,}; {reached}): {'met' if met else '**not met**'}."
    )
    return lines


def plot(summaries: dict[tuple[str, str], Summary], settings: Settings, path: Path) -> None:
    figure, axes = plt.subplots(figsize=(8, 4.8))
    colors = {"reinforce": "tab:blue", "nstep_sarsa": "tab:orange", "maskable_ppo": "tab:green"}
    for (algo, variant), summary in summaries.items():
        mean, low, high = episode_band(summary.returns)
        style = "-" if variant == "masked" else "--"
        axes.plot(summary.timesteps, mean, style, color=colors[algo], label=summary.label)
        axes.fill_between(summary.timesteps, low, high, color=colors[algo], alpha=0.15, linewidth=0)
    axes.axhline(settings.threshold, color="grey", linewidth=0.8, linestyle=":")
    axes.set_xlabel("env steps")
    axes.set_ylabel(f"mean evaluation return ({settings.n_eval_episodes} episodes)")
    n_seeds = next(iter(summaries.values())).returns.shape[0]
    axes.set_title(
        f"InvalidActionEnvDiscrete(dim={settings.dim}, n_invalid_actions={settings.n_invalid_actions}): "
        f"mean and 95% bootstrap interval over {n_seeds} seeds",
        fontsize=9,
    )
    axes.set_ylim(0, settings.max_return * 1.02)
    axes.legend(fontsize=8, loc="lower right")
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def default(algo: str, name: str) -> Any:
    """:return: the default of the constructor argument ``name`` of ``algo``"""
    return inspect.signature(ALGO_CLASSES[algo]).parameters[name].default


def report(summaries: dict[tuple[str, str], Summary], settings: Settings, command: str, figure_name: str) -> str:
    n_seeds = next(iter(summaries.values())).returns.shape[0]
    threshold = f"{settings.threshold:g}"
    rows = [
        f"| {summary.label} | {summary.final.format()} | {_steps(summary.mean_curve_reaching(settings.threshold))} "
        f"| {_seed_steps(summary.seeds_reaching(settings.threshold), n_seeds)} | {summary.seconds:.1f} |"
        for summary in summaries.values()
    ]
    header = (
        f"| Algorithm | Final mean return | Steps to {threshold}, mean curve "
        f"| Steps to {threshold} per seed: median (range), seeds | Time per run (s) |"
    )
    random_masked = settings.ep_length / (settings.dim - settings.n_invalid_actions)
    versions = (
        f"sb3_classic {sb3_classic.__version__}, sb3-contrib {sb3_contrib.__version__}, "
        f"Stable-Baselines3 {stable_baselines3.__version__}"
    )
    env = (
        f"InvalidActionEnvDiscrete(dim={settings.dim}, ep_length={settings.ep_length}, "
        f"n_invalid_actions={settings.n_invalid_actions})"
    )
    return f"""# Invalid-action masking

Produced by:

```
{command}
```

{versions}, torch {th.__version__} (1 thread, CPU).

## The task

sb3-contrib's `{env}`: the observation is a state drawn uniformly from {settings.dim}, the reward is 1 when the action
equals it and 0 otherwise, for {settings.ep_length} steps (maximum return {settings.max_return:g}). In each state
{settings.n_invalid_actions} of the other actions are illegal, drawn at random, and `action_masks()` gives them. The env
does not stop an illegal action, it rewards it 0: a uniform choice among all actions is right once in {settings.dim}
steps (return {settings.ep_length / settings.dim:g}), among the legal ones once in
{settings.dim - settings.n_invalid_actions} (return {random_masked:g}).

## Settings

- {n_seeds} seeds (0–{n_seeds - 1}) of each algorithm and variant, one env, {settings.budget:,} env steps per run.
- **Hyperparameters**: each algorithm's defaults (`REINFORCE`'s and `NStepSARSA`'s constructors, sb3-contrib's
  `MaskablePPO`'s), `"MlpPolicy"`, except γ = {settings.gamma:g} for all three. The package's YAMLs have no entry for
  this env, and its defaults are the settings a user gets without one. The γ is sb3-contrib's example's for this env:
  the action does not change the next state, so the return after the current reward is the same for every action, and
  a long horizon only adds to q̂ and v̂ a large term that no action changes. Nothing was tuned.
- **When each updates**, with these defaults: REINFORCE after every episode ({settings.ep_length} steps), NStepSARSA
  every {default("nstep_sarsa", "train_freq")} steps (`train_freq`), MaskablePPO after each rollout of
  {default("maskable_ppo", "n_steps"):,} steps (`n_steps`): MaskablePPO's first
  evaluations are of its initial policy, which is how masked REINFORCE and NStepSARSA reach its final return first.
- **Masked** runs learn with `learn(use_masking=True)` (the default; `MaskablePPO` always masks) and are evaluated with
  masks; **unmasked** runs learn with `learn(use_masking=False)` and are evaluated without.
- **Evaluation**: sb3-contrib's `evaluate_policy`, deterministic, {settings.n_eval_episodes} episodes on an env of the
  run's own (seeded apart from the training env), before training, every {settings.eval_freq:,} env steps and at the
  end of training.

## Results

{header}
|---|---|---|---|---|
{chr(10).join(rows)}

- **Final mean return**: each seed's last evaluation, mean over seeds and its 95% bootstrap interval
  (`scipy.stats.bootstrap`, BCa, 10,000 resamples).
- **Steps to {threshold}**, in env steps ({threshold} is 90% of the maximum return): the first evaluation where the mean over
  seeds is at {threshold} or above; per seed, the first evaluation of the seed there, over the seeds that got there.
- **Time per run**: wall-clock of `learn()`, evaluations included, mean over seeds.

![Learning curves]({figure_name})

## Targets

{chr(10).join(targets(summaries, settings))}
"""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    defaults = Settings()
    parser.add_argument("--seeds", type=positive_int, default=10, help="seeds 0..N-1 of each run (default 10)")
    parser.add_argument("--budget", type=positive_int, default=defaults.budget, help="env steps per run")
    parser.add_argument("--eval-freq", type=positive_int, default=defaults.eval_freq, help="env steps between evaluations")
    parser.add_argument("--eval-episodes", type=positive_int, default=defaults.n_eval_episodes, help="episodes per evaluation")
    parser.add_argument("--results-dir", type=Path, default=RESULTS_DIR, help="masking.md, .png and masking/ (the runs)")
    args = parser.parse_args(argv)
    settings = Settings(budget=args.budget, eval_freq=args.eval_freq, n_eval_episodes=args.eval_episodes)
    cache_dir = args.results_dir / "masking"
    summaries = {}
    for algo, variant in RUNS:
        records = []
        for seed in range(args.seeds):
            record, trained = load_or_train(algo, variant, seed, settings, cache_dir)
            records.append(record)
            state = f"trained in {record['seconds']:.1f} s" if trained else "cached"
            print(f"{algo} {variant} seed {seed}: final {record['mean_return'][-1]:.1f} ({state})", flush=True)
        summaries[algo, variant] = summarize(records)
    command = "python -m benchmarks.masking " + shlex.join(sys.argv[1:] if argv is None else argv)
    args.results_dir.mkdir(parents=True, exist_ok=True)
    plot(summaries, settings, args.results_dir / "masking.png")
    text = report(summaries, settings, command.strip(), "masking.png")
    (args.results_dir / "masking.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
