"""
The book's figures, with the package's public API: Figs 7.2, 10.1, 10.3, 10.4, 13.1 and 13.2 of Sutton &
Barto, Reinforcement Learning: An Introduction, 2nd ed., reproduced with ``NStepSARSA`` and ``REINFORCE`` in their
per-step mode (the book's updates, see ``tests/test_book_updates.py``), and the book's numbers beside ours.

    python -m benchmarks.textbook                       # every figure, default run counts (about 7 minutes on 2 cores)
    python -m benchmarks.textbook --quick               # the whole pipeline in a minute, into benchmarks/cache/
    python -m benchmarks.textbook --figures 7.2 13.2 --runs 100   # the book's run count for some figures
    python -m benchmarks.textbook --report-only         # redraw from the runs cached so far

Every run is cached in ``benchmarks/cache/textbook/`` (one JSON file per setting and seed): an interrupted command
resumes where it stopped, and runs shared by two figures (Fig 10.3's runs give Fig 10.4's first 50 episodes of the
same settings; Fig 13.1's α = 2^-13 is Fig 13.2's plain REINFORCE) are made once.
"""

import argparse
import hashlib
import json
import math
import multiprocessing
import os
import platform
import shlex
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import torch as th
from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback

import sb3_classic
from sb3_classic import REINFORCE, NStepSARSA, TileCoding
from sb3_classic.envs import RANDOM_WALK_19_TRUE_VALUES, SHORT_CORRIDOR_OPTIMAL_VALUE
from sb3_classic.harness.common import positive_int

REPO_ROOT = Path(__file__).resolve().parent.parent
DEFAULT_CACHE_DIR = REPO_ROOT / "benchmarks" / "cache" / "textbook"
DEFAULT_RESULTS_DIR = REPO_ROOT / "benchmarks" / "results" / "textbook"
QUICK_RESULTS_DIR = REPO_ROOT / "benchmarks" / "cache" / "textbook-quick-results"

FIGURES = ("7.2", "10.1", "10.3", "10.4", "13.1", "13.2")

#: The tiles of the book's footnote to Example 10.1, ``tiles(iht, 8, [8*x/(0.5+1.2), 8*xdot/(0.07+0.07)], A)``:
#: 8 tilings of 8 × 8 tiles over position [−1.2, 0.5] and velocity [−0.07, 0.07], grids counted from 0 as tiles3
#: counts them (``origin="zero"``), one weight vector per action (a linear q̂ with one output per action)
MOUNTAIN_CAR_TILES: dict[str, Any] = dict(n_tilings=8, tiles_per_dim=8, low=(-1.2, -0.07), high=(0.5, 0.07), origin="zero")
MOUNTAIN_CAR_FEATURES: dict[str, Any] = dict(features_extractor_class=TileCoding, features_extractor_kwargs=MOUNTAIN_CAR_TILES)
#: An episode this long ends its run as diverged. Plain REINFORCE on the short corridor (no clamp of π, as in the
#: book's pseudocode; the book's code keeps π ≥ 0.05) can overshoot after a long episode: the per-step updates of one
#: episode of a few thousand steps move θ by hundreds, π(right) rounds to 0 or 1, and no later episode ends (always
#: left stays in s0, always right bounces between s0 and s1). The longest episode of a run that recovered was 12,826
#: steps; 50,000 is about 2 minutes of training.
DIVERGED_LENGTH = 50_000
#: The short corridor's initial policy of the book's code: θ = (θ_right, θ_left) = (−1.47, 1.47), π(right) ≈ 0.05
CORRIDOR_THETA_RIGHT, CORRIDOR_THETA_LEFT = -1.47, 1.47


# --- Settings and runs -----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Setting:
    """
    One learning setting of a figure.

    :param task: ``"random_walk"`` (n-step TD as one-action n-step SARSA, Fig 7.2), ``"mountain_car"`` (n-step
        SARSA with tile coding, Figs 10.1–10.4) or ``"corridor"`` (REINFORCE on the short corridor, Figs 13.1–13.2)
    :param alpha: the step size α (α^θ for REINFORCE); for Mountain Car the step size per weight, e.g. 0.3/8
    :param n: the n of n-step SARSA (0 for REINFORCE)
    :param alpha_w: REINFORCE's baseline step size α^w, None for plain REINFORCE
    :param snapshots: episodes after which the cost-to-go −max_a q̂ is recorded (Fig 10.1), empty otherwise
    """

    task: str
    alpha: float
    n: int = 0
    alpha_w: float | None = None
    snapshots: tuple[int, ...] = ()

    @property
    def label(self) -> str:
        """How the figures and tables name the setting."""
        if self.task == "random_walk":
            return f"n={self.n}, α={self.alpha:g}"
        if self.task == "mountain_car":
            return f"n={self.n}, α={self.alpha * 8:g}/8"
        if self.alpha_w is None:
            return f"REINFORCE α=2^{math.log2(self.alpha):g}"
        return f"REINFORCE with baseline α^θ=2^{math.log2(self.alpha):g}, α^w=2^{math.log2(self.alpha_w):g}"

    def slug(self) -> str:
        """:return: a folder name for the setting's runs"""
        parts = [self.task, f"n{self.n}", f"a{self.alpha:.6g}"]
        parts += [f"aw{self.alpha_w:.6g}"] if self.alpha_w is not None else []
        parts += ["snap" + "-".join(map(str, self.snapshots))] if self.snapshots else []
        return "_".join(parts)


@dataclass(frozen=True)
class Run:
    """One run: a setting, a seed, and how many episodes it needs."""

    setting: Setting
    seed: int
    episodes: int


def package_digest() -> str:
    """:return: the versions a run's result depends on, with a digest of the ``sb3_classic`` sources"""
    package = Path(sb3_classic.__file__).resolve().parent
    digest = hashlib.sha256()
    for source in sorted(package.rglob("*.py")):
        digest.update(source.relative_to(package).as_posix().encode())
        digest.update(source.read_bytes())
    import stable_baselines3

    versions = [f"sb3_classic {sb3_classic.__version__}+{digest.hexdigest()[:12]}"]
    versions += [
        f"stable_baselines3 {stable_baselines3.__version__}",
        f"gymnasium {gym.__version__}",
        f"torch {th.__version__}",
        f"numpy {np.__version__}",
    ]
    return ", ".join(versions)


def run_path(cache_dir: Path, run: Run, versions: str) -> Path:
    """:return: the cache file of ``run``: ``<setting>-<digest of the setting and versions>/seed_<k>.json``"""
    key = hashlib.sha256(json.dumps([asdict(run.setting), versions], sort_keys=True).encode()).hexdigest()[:12]
    return cache_dir / f"{run.setting.slug()}-{key}" / f"seed_{run.seed}.json"


def load_cached(cache_dir: Path, run: Run, versions: str) -> dict[str, Any] | None:
    """:return: the cached result of ``run`` if one with at least ``run.episodes`` episodes exists, else None"""
    path = run_path(cache_dir, run, versions)
    if not path.exists():
        return None
    result: dict[str, Any] = json.loads(path.read_text())
    return result if result["episodes"] >= run.episodes or result["capped"] or result.get("diverged") else None


# --- The models, as a student would build them -----------------------------------------------------------------------


def linear_sgd(**kwargs: Any) -> dict[str, Any]:
    """:return: the policy_kwargs of the book's linear methods: one linear layer, no bias, weights 0, plain SGD"""
    return dict(net_arch=[], with_bias=False, weight_init=0.0, optimizer_class=th.optim.SGD, **kwargs)


def make_model(setting: Setting, seed: int) -> NStepSARSA | REINFORCE:
    """
    :return: the book's algorithm of ``setting``, built with the public API only
    """
    if setting.task in ("random_walk", "mountain_car"):
        random_walk = setting.task == "random_walk"
        # n-step SARSA of §10.2, one update per step (per_step, train_freq=1), ε = 0 (greedy, ties broken at random)
        return NStepSARSA(
            # q̂ = wᵀx(s, a) with the book's SGD update, weights 0, no bias (LinearPolicy's defaults)
            "LinearPolicy",
            # gym.make(): given the id, SB3 first asks for render_mode="rgb_array", which these envs do not offer (a warning)
            gym.make("sb3_classic/RandomWalk19-v0" if random_walk else "sb3_classic/MountainCarNoLimit-v0"),
            learning_rate=setting.alpha,
            n_steps=setting.n,
            train_freq=1,
            gradient_steps=1,
            update_mode="per_step",
            gamma=1.0,
            exploration_initial_eps=0.0,
            exploration_final_eps=0.0,
            policy_kwargs={} if random_walk else MOUNTAIN_CAR_FEATURES,
            seed=seed,
            device="cpu",
        )
    model = REINFORCE(
        "MlpPolicy",
        gym.make("sb3_classic/ShortCorridor-v0"),
        learning_rate=setting.alpha,
        # Unused by plain REINFORCE (use_baseline=False), which has no v̂
        value_learning_rate=setting.alpha_w if setting.alpha_w is not None else 1.0,
        update_mode="per_step",
        use_baseline=setting.alpha_w is not None,
        gamma=1.0,
        gamma_t_factor=True,  # γ^t = 1 with γ = 1, as in the book
        policy_kwargs=linear_sgd(),
        seed=seed,
        device="cpu",
    )
    # The book's initial policy, π(right) ≈ 0.05
    set_corridor_logits(model, left=CORRIDOR_THETA_LEFT, right=CORRIDOR_THETA_RIGHT)
    return model


def set_corridor_logits(model: REINFORCE, left: float, right: float) -> None:
    """Set θ of the short corridor's linear policy: its logits h(s, a, θ) are action_net.weight[a, 0] (0 left, 1 right)."""
    action_net = model.policy.action_net
    assert isinstance(action_net, th.nn.Linear)
    with th.no_grad():
        action_net.weight.copy_(th.tensor([[left], [right]]))


def linear_weights(model: BaseAlgorithm) -> np.ndarray:
    """:return: a copy of the weights of the linear q̂ of a ``NStepSARSA`` with ``net_arch=[]``, shape (actions, features)"""
    assert isinstance(model, NStepSARSA)
    layer = model.policy.q_net.q_net[0]
    assert isinstance(layer, th.nn.Linear)
    return layer.weight.detach().numpy().copy()


def random_walk_rms(model: BaseAlgorithm) -> float:
    """:return: the RMS error over the 19 states of V(s) = the weight of state s's one-hot feature (Fig 7.2)"""
    values = linear_weights(model)[0]
    return float(np.sqrt(np.mean((values - RANDOM_WALK_19_TRUE_VALUES) ** 2)))


#: The grid of Fig 10.1's cost-to-go plots: position × velocity
COST_TO_GO_POSITIONS = np.linspace(-1.2, 0.5, 41)
COST_TO_GO_VELOCITIES = np.linspace(-0.07, 0.07, 41)


def cost_to_go(model: BaseAlgorithm) -> list[list[float]]:
    """:return: −max_a q̂(s, a) on the grid of positions × velocities (Fig 10.1), rows by velocity"""
    positions, velocities = np.meshgrid(COST_TO_GO_POSITIONS, COST_TO_GO_VELOCITIES)
    observations = th.as_tensor(np.stack([positions.ravel(), velocities.ravel()], axis=1), dtype=th.float32)
    assert isinstance(model, NStepSARSA)
    with th.no_grad():
        q_values = model.policy.q_net(observations).numpy()
    return (-q_values.max(axis=1)).reshape(positions.shape).tolist()


class EpisodeRecorder(BaseCallback):
    """
    Records every episode's length and return (from the Monitor's ``info["episode"]``) and, after an episode's
    updates, ``measure(model)`` (episodes in ``measure_at``, or all); stops training after ``n_episodes`` episodes.

    An episode's last updates are made after its last step's callback (SARSA's final n updates, REINFORCE's whole
    episode): the measure is taken at the start of the next rollout, after them, and training stops at the first step
    after the last measure (a callback that stopped at the last step of episode N, as ``StopTrainingOnMaxEpisodes``
    does, would leave episode N's updates unmade).

    An episode that reaches ``diverged_length`` steps stops training too, and sets ``diverged``: a policy whose
    probabilities have rounded to 0 or 1 never leaves the short corridor (see ``DIVERGED_LENGTH``).

    :param n_episodes: episodes to train for
    :param measure: what to record after an episode's updates, or None
    :param measure_at: the episodes (counted from 1) to measure after; None for every episode
    :param diverged_length: the episode length at which a run is declared diverged and stopped; None: never
    """

    def __init__(
        self,
        n_episodes: int,
        measure: Callable[[BaseAlgorithm], Any] | None = None,
        measure_at: Iterable[int] | None = None,
        diverged_length: int | None = None,
    ) -> None:
        super().__init__()
        self.n_episodes = n_episodes
        self.diverged_length = diverged_length
        self.diverged = False
        self._episode_length = 0
        self.measure = measure
        self.measure_at = None if measure_at is None else set(measure_at)
        self.lengths: list[int] = []
        self.returns: list[float] = []
        self.measures: dict[int, Any] = {}
        self._unmeasured: list[int] = []

    def _wanted(self, episode: int) -> bool:
        return self.measure is not None and (self.measure_at is None or episode in self.measure_at)

    def _on_rollout_start(self) -> None:
        for episode in self._unmeasured:
            assert self.measure is not None
            self.measures[episode] = self.measure(self.model)
        self._unmeasured = []

    def _on_step(self) -> bool:
        self._episode_length += 1
        if self.diverged_length is not None and self._episode_length >= self.diverged_length:
            self.diverged = True
            return False
        for info in self.locals["infos"]:
            if "episode" in info:
                self._episode_length = 0
                self.lengths.append(int(info["episode"]["l"]))
                self.returns.append(float(info["episode"]["r"]))
                if self._wanted(len(self.lengths)):
                    self._unmeasured.append(len(self.lengths))
        return len(self.lengths) < self.n_episodes or bool(self._unmeasured)


def train_run(run: Run) -> dict[str, Any]:
    """
    Train one run from scratch (in a worker process).

    :return: the run's per-episode data: ``lengths``, ``returns``, and ``rms`` (Fig 7.2) or ``cost_to_go``
        (Fig 10.1, by episode), with ``num_timesteps``, ``seconds`` and ``capped`` (stopped by the step cap before
        its episodes)
    """
    th.set_num_threads(1)
    setting = run.setting
    model = make_model(setting, run.seed)
    if setting.task == "random_walk":
        recorder = EpisodeRecorder(run.episodes, random_walk_rms, diverged_length=DIVERGED_LENGTH)
    elif setting.snapshots:
        snapshots = [e for e in setting.snapshots if e <= run.episodes]
        recorder = EpisodeRecorder(run.episodes, cost_to_go, snapshots, diverged_length=DIVERGED_LENGTH)
    else:
        recorder = EpisodeRecorder(run.episodes, diverged_length=DIVERGED_LENGTH)
    # A cap on env steps, so that a diverging setting cannot run forever (no setting used here comes near it)
    cap = run.episodes * (100_000 if setting.task == "mountain_car" else 10_000)
    start = time.perf_counter()
    model.learn(total_timesteps=cap, callback=recorder)
    seconds = time.perf_counter() - start
    n = min(len(recorder.lengths), run.episodes)
    result: dict[str, Any] = dict(
        episodes=n,
        capped=n < run.episodes and not recorder.diverged,
        diverged=recorder.diverged,
        lengths=recorder.lengths[:n],
        returns=recorder.returns[:n],
        num_timesteps=int(model.num_timesteps),
        seconds=seconds,
    )
    if setting.task == "random_walk":
        result["rms"] = [recorder.measures[e] for e in range(1, n + 1)]
    elif setting.snapshots:
        result["cost_to_go"] = {str(e): v for e, v in recorder.measures.items()}
    return result


# --- What each figure runs -------------------------------------------------------------------------------------------


@dataclass
class Plan:
    """
    The settings of a benchmark: per figure, its settings and runs.

    :param runs: runs per setting, per figure
    :param random_walk_alphas: Fig 7.2's α grid, per n
    :param mountain_car_alphas: Fig 10.4's α × 8 grid, per n
    :param mountain_car_episodes: episodes of Fig 10.3's runs
    :param mountain_car_first: Fig 10.4's first episodes
    :param snapshots: Fig 10.1's episodes
    :param corridor_episodes: episodes of Figs 13.1–13.2
    """

    runs: dict[str, int]
    random_walk_alphas: dict[int, tuple[float, ...]]
    mountain_car_alphas: dict[int, tuple[float, ...]]
    mountain_car_episodes: int = 500
    mountain_car_first: int = 50
    snapshots: tuple[int, ...] = (1, 12, 104, 1000)
    corridor_episodes: int = 1000
    random_walk_episodes: int = 10
    notes: list[str] = field(default_factory=list)

    def settings(self, figure: str) -> list[tuple[Setting, int]]:
        """:return: the settings of ``figure``, each with the episodes its runs need"""
        if figure == "7.2":
            return [
                (Setting("random_walk", alpha, n), self.random_walk_episodes)
                for n, alphas in self.random_walk_alphas.items()
                for alpha in alphas
            ]
        if figure == "10.1":
            return [(Setting("mountain_car", 0.3 / 8, 1, snapshots=self.snapshots), max(self.snapshots))]
        if figure == "10.3":
            return [(s, self.mountain_car_episodes) for s in FIG_10_3]
        if figure == "10.4":
            return [
                (Setting("mountain_car", a / 8, n), self.mountain_car_first)
                for n, alphas in self.mountain_car_alphas.items()
                for a in alphas
            ]
        if figure == "13.1":
            return [(Setting("corridor", 2.0**-k), self.corridor_episodes) for k in (12, 13, 14)]
        if figure == "13.2":
            return [(s, self.corridor_episodes) for s in FIG_13_2]
        raise ValueError(f"figure {figure!r} must be one of {FIGURES}")


FIG_10_3 = (Setting("mountain_car", 0.5 / 8, 1), Setting("mountain_car", 0.3 / 8, 8))
FIG_13_2 = (Setting("corridor", 2.0**-13), Setting("corridor", 2.0**-9, alpha_w=2.0**-6))
FIG_7_2_NS = (1, 2, 4, 8, 16, 32, 64, 128, 256, 512)

#: The book's grids (``--full-grid``): α = 0, 0.1, …, 1 for Fig 7.2 (0 is left out: nothing learns);
#: α × 8 = 0.1, 0.2, …, 1.6 for Fig 10.4 (the book's x axis)
BOOK_RANDOM_WALK_ALPHAS = {n: tuple(round(0.1 * k, 1) for k in range(1, 11)) for n in FIG_7_2_NS}
BOOK_MOUNTAIN_CAR_ALPHAS = {n: tuple(round(0.1 * k, 1) for k in range(1, 17)) for n in (1, 2, 4, 8, 16)}

#: The default plan (the committed results used it with ``--runs 7.2=20 10.1=1 10.3=4 10.4=4 13.1=3 13.2=20``, as
#: ``textbook.md`` says): about 7 minutes on 2 cores. α grids reduced to the points around the book's optimum of
#: each n and a few more; run counts from the measured cost of each figure (see ``benchmarks/README.md``)
DEFAULT = Plan(
    runs={"7.2": 20, "10.1": 1, "10.3": 4, "10.4": 4, "13.1": 10, "13.2": 20},
    random_walk_alphas={
        1: (0.4, 0.6, 0.8, 1.0),
        2: (0.2, 0.4, 0.6, 0.8),
        4: (0.2, 0.3, 0.4, 0.5, 0.6),
        8: (0.1, 0.2, 0.3, 0.4),
        16: (0.05, 0.1, 0.15, 0.2),
        32: (0.05, 0.1),
        64: (0.02, 0.05),
        128: (0.02, 0.05),
        256: (0.02, 0.05),
        512: (0.02, 0.05),
    },
    mountain_car_alphas={
        1: (0.5, 0.7, 0.9, 1.1, 1.3, 1.5),
        2: (0.3, 0.5, 0.7, 0.9, 1.1),
        4: (0.3, 0.5, 0.7, 0.9),
        8: (0.3, 0.4, 0.5),
        16: (0.2, 0.3),
    },
)
#: The pipeline end to end in about a minute: tiny runs, nothing comparable with the book
QUICK = Plan(
    runs=dict.fromkeys(FIGURES, 2),
    random_walk_alphas={1: (0.6,), 4: (0.4,), 16: (0.1,)},
    mountain_car_alphas={1: (0.5,), 8: (0.3,)},
    mountain_car_episodes=1,
    mountain_car_first=1,
    snapshots=(1,),
    corridor_episodes=10,
)


# --- Running ---------------------------------------------------------------------------------------------------------


def _init_worker() -> None:
    th.set_num_threads(1)


def plan_runs(plan: Plan, figures: Sequence[str]) -> list[Run]:
    """:return: every run the figures need (a run shared by two figures once, with the most episodes), run 0 of
    every setting first, figure by figure"""
    needed: dict[tuple[Setting, int], int] = {}
    order: list[tuple[Setting, int]] = []
    for figure in figures:
        for setting, episodes in plan.settings(figure):
            for seed in range(plan.runs[figure]):
                key = (setting, seed)
                if key not in needed:
                    order.append(key)
                needed[key] = max(needed.get(key, 0), episodes)
    order.sort(key=lambda key: key[1])
    return [Run(setting, seed, needed[(setting, seed)]) for setting, seed in order]


def run_all(runs: Sequence[Run], workers: int, cache_dir: Path, versions: str, console: Console) -> float:
    """
    Train the runs not in the cache yet, ``workers`` at a time, and cache each as it ends.

    :return: CPU seconds spent in ``learn()`` by the runs made now
    """
    pending = [run for run in runs if load_cached(cache_dir, run, versions) is None]
    console.print(f"{len(runs)} runs, {len(runs) - len(pending)} cached, {len(pending)} to train on {workers} workers")
    if not pending:
        return 0.0
    seconds = 0.0
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn())
    context = multiprocessing.get_context("spawn")
    with (
        ProcessPoolExecutor(workers, mp_context=context, initializer=_init_worker) as pool,
        Progress(*columns, console=console) as progress,
    ):
        task = progress.add_task("runs", total=len(pending))
        futures: dict[Future[dict[str, Any]], Run] = {pool.submit(train_run, run): run for run in pending}
        remaining = set(futures)
        try:
            while remaining:
                done, remaining = wait(remaining, timeout=1.0, return_when=FIRST_COMPLETED)
                for future in done:
                    run = futures[future]
                    result = future.result()
                    path = run_path(cache_dir, run, versions)
                    path.parent.mkdir(parents=True, exist_ok=True)
                    partial = path.with_suffix(".partial")
                    partial.write_text(json.dumps(dict(result, setting=asdict(run.setting), seed=run.seed, versions=versions)))
                    partial.replace(path)
                    seconds += result["seconds"]
                    rate = result["num_timesteps"] / result["seconds"]
                    progress.update(
                        task, advance=1, description=f"runs (last: {run.setting.label} seed {run.seed}, {rate:,.0f} steps/s)"
                    )
        except KeyboardInterrupt:
            pool.shutdown(wait=False, cancel_futures=True)
            raise
    return seconds


# --- Results ---------------------------------------------------------------------------------------------------------


@dataclass
class SettingRuns:
    """The cached runs of a setting: per-episode arrays (runs × episodes) and timings."""

    setting: Setting
    data: list[dict[str, Any]]

    @property
    def n_runs(self) -> int:
        return len(self.data)

    def array(self, key: str, episodes: int) -> np.ndarray:
        """:return: ``key`` of the first ``episodes`` episodes of every run with that many, shape (runs, episodes)"""
        rows = [run[key][:episodes] for run in self.data if len(run[key]) >= episodes]
        return np.array(rows, dtype=np.float64).reshape(len(rows), episodes)

    def window(self, key: str, first: int, last: int) -> tuple[float, float, int]:
        """:return: mean over runs of each run's mean of episodes first..last (from 1), its standard error, and runs"""
        per_run = self.array(key, last)[:, first - 1 : last].mean(axis=1)
        if len(per_run) == 0:
            return math.nan, math.nan, 0
        se = per_run.std(ddof=1) / math.sqrt(len(per_run)) if len(per_run) > 1 else math.nan
        return float(per_run.mean()), float(se), len(per_run)

    def diverged_before(self, episodes: int) -> int:
        """:return: how many runs diverged before ``episodes`` episodes (left out of every mean that needs them)"""
        return sum(1 for run in self.data if run.get("diverged") and run["episodes"] < episodes)

    def runs_text(self, episodes: int, used: int) -> str:
        """:return: the runs used for a mean over the first ``episodes`` episodes, and the diverged ones left out"""
        diverged = self.diverged_before(episodes)
        return f"{used} (+{diverged} diverged)" if diverged else str(used)

    @property
    def steps_per_second(self) -> float:
        return sum(run["num_timesteps"] for run in self.data) / max(sum(run["seconds"] for run in self.data), 1e-9)


def collect(plan: Plan, figure: str, cache_dir: Path, versions: str) -> list[SettingRuns]:
    """:return: the cached runs of each setting of ``figure`` (up to the plan's run count; missing ones left out)"""
    found = []
    for setting, episodes in plan.settings(figure):
        data = [load_cached(cache_dir, Run(setting, seed, episodes), versions) for seed in range(plan.runs[figure])]
        found.append(SettingRuns(setting, [run for run in data if run is not None]))
    return found


@dataclass(frozen=True)
class BookNumber:
    """A number of the book's, and how ours is measured."""

    figure: str
    setting: Setting
    what: str
    key: str
    first: int
    last: int
    book: float
    book_se: float | None
    source: str


BOOK_NUMBERS = (
    BookNumber("7.2", Setting("random_walk", 0.4, 4), "RMS error, mean of episodes 1–10", "rms", 1, 10, 0.266, 0.003,
               "Fig 7.2, 100 runs"),
    BookNumber("7.2", Setting("random_walk", 0.1, 16), "RMS error, mean of episodes 1–10", "rms", 1, 10, 0.324, None,
               "Fig 7.2"),
    BookNumber("10.3", FIG_10_3[1], "steps per episode, mean of episodes 91–100", "lengths", 91, 100, 119.0, None,
               "Fig 10.3 (≈, read from the figure)"),
    BookNumber("13.2", FIG_13_2[1], "return per episode, mean of episodes 1–100", "returns", 1, 100, -20.5, 0.7,
               "Fig 13.2, 100 runs"),
    BookNumber("13.2", FIG_13_2[0], "return per episode, mean of episodes 401–500", "returns", 401, 500, -15.1, 0.2,
               "Figs 13.1–13.2, 100 runs"),
)  # fmt: skip
#: Fig 10.4: the book's mean steps per episode over the first 50 episodes at each n's best α, read from the figure
FIG_10_4_BOOK_RANGE = (230.0, 243.0)
#: Fig 10.4 without the package: the box of §10.2 in NumPy with the same tiles (``textbook_numpy.mountain_car_sarsa``),
#: mean steps per episode over episodes 1–50 ± SE over FIG_10_4_NUMPY_RUNS runs on its own seeds, by (n, α × 8);
#: printed by ``python -m benchmarks.textbook_numpy`` (its ``FIG_10_4_GRID``)
FIG_10_4_NUMPY_RUNS = 30
FIG_10_4_NUMPY: dict[tuple[int, float], tuple[float, float]] = {
    (1, 0.9): (240.3, 0.8),
    (1, 1.1): (232.2, 0.9),
    (1, 1.3): (229.2, 0.8),
    (1, 1.5): (230.3, 0.9),
    (2, 0.7): (233.4, 1.0),
    (2, 0.9): (229.3, 0.9),
    (2, 1.1): (226.3, 1.1),
    (4, 0.5): (230.9, 1.6),
    (4, 0.7): (221.5, 1.3),
    (4, 0.9): (222.0, 1.5),
    (8, 0.3): (237.1, 2.8),
    (8, 0.4): (228.4, 4.7),
    (8, 0.5): (228.6, 4.4),
    (16, 0.2): (249.5, 4.4),
    (16, 0.3): (239.0, 6.9),
}


def agreement(ours: float, ours_se: float, book: float, book_se: float | None) -> str:
    """:return: whether ours is within 2 combined standard errors of the book's (the book's SE taken as 0 if unknown)"""
    if math.isnan(ours):
        return "–"
    combined = math.sqrt(ours_se**2 + (book_se or 0.0) ** 2) if not math.isnan(ours_se) else math.nan
    if math.isnan(combined):
        return "?"
    z = (ours - book) / combined
    return f"{'yes' if abs(z) <= 2 else '**no**'} ({z:+.1f} SE)"


def fmt(mean: float, se: float, digits: int) -> str:
    if math.isnan(mean):
        return "–"
    return f"{mean:.{digits}f}" if math.isnan(se) else f"{mean:.{digits}f} ± {se:.{digits}f}"


def book_table(plan: Plan, cache_dir: Path, versions: str) -> tuple[str, list[dict[str, Any]]]:
    """:return: the markdown table of the book's numbers beside ours, and its rows"""
    lines = [
        "| Figure | Setting | Measure | Book | Ours (mean ± SE) | Runs | Within 2 SE |",
        "|---|---|---|---|---|---|---|",
    ]
    rows = []
    for number in BOOK_NUMBERS:
        episodes = number.last
        data = [
            load_cached(cache_dir, Run(number.setting, seed, episodes), versions) for seed in range(plan.runs[number.figure])
        ]
        runs = SettingRuns(number.setting, [run for run in data if run is not None])
        mean, se, n = runs.window(number.key, number.first, number.last) if runs.n_runs else (math.nan, math.nan, 0)
        digits = 3 if number.key == "rms" else 1
        book = fmt(number.book, number.book_se if number.book_se is not None else math.nan, digits)
        check = agreement(mean, se, number.book, number.book_se)
        used, ours = runs.runs_text(number.last, n), fmt(mean, se, digits)
        lines.append(f"| {number.figure} | {number.setting.label} | {number.what} | {book} | {ours} | {used} | {check} |")
        rows.append(dict(figure=number.figure, setting=number.setting.label, mean=mean, se=se, runs=n, book=number.book))
    # Fig 10.4: the book gives curves, not numbers. Each n is checked at the NumPy box's best α (chosen without our runs:
    # the best of our own few runs per α would be biased low), against the box's mean there; the spread of a run is
    # the box's (30 runs), since a few runs cannot estimate it: z = (ours − box) / (sd_box √(1/runs + 1/30)), which
    # is what 2 SE means if the package runs the box's algorithm
    fig_10_4 = {
        (runs.setting.n, round(runs.setting.alpha * 8, 2)): runs for runs in collect(plan, "10.4", cache_dir, versions)
    }
    low, high = FIG_10_4_BOOK_RANGE
    for n in sorted({n for n, _ in fig_10_4}):
        box = {alpha8: value for (box_n, alpha8), value in FIG_10_4_NUMPY.items() if box_n == n}
        if not box or plan.mountain_car_first != 50:
            continue
        alpha8 = min(box, key=lambda a: box[a][0])
        at_alpha = fig_10_4.get((n, alpha8))
        mean, se, count = at_alpha.window("lengths", 1, 50) if at_alpha and at_alpha.n_runs else (math.nan, math.nan, 0)
        box_mean, box_se = box[alpha8]
        spread = box_se * math.sqrt(FIG_10_4_NUMPY_RUNS)
        check = agreement(mean, spread / math.sqrt(count), box_mean, box_se) if count else "–"
        lines.append(
            f"| 10.4 | n={n}, α={alpha8:g}/8 (the box's best α) | steps per episode, mean of episodes 1–50 "
            f"| ≈ {low:.0f}–{high:.0f} (figure); the box in NumPy: {fmt(box_mean, box_se, 1)} | {fmt(mean, se, 1)} "
            f"| {count} | {check} |"
        )
    return "\n".join(lines), rows


# --- Figures in the book's form --------------------------------------------------------------------------------------


def _errorbar(axes: Any, x: Sequence[float], means: Sequence[float], ses: Sequence[float], label: str) -> None:
    axes.errorbar(x, means, yerr=[0 if math.isnan(s) else s for s in ses], label=label, capsize=2, marker="o", markersize=3)


def plot_7_2(groups: list[SettingRuns], episodes: int, path: Path) -> None:
    figure, axes = plt.subplots(figsize=(6, 4.5))
    for n in sorted({g.setting.n for g in groups}):
        points = sorted((g.setting.alpha, *g.window("rms", 1, episodes)[:2]) for g in groups if g.setting.n == n and g.n_runs)
        if points:
            alphas, means, ses = zip(*points, strict=True)
            _errorbar(axes, alphas, means, ses, f"n={n}")
    axes.set(
        xlabel="α", ylabel=f"Average RMS error over 19 states\nand first {episodes} episodes", xlim=(0, 1), ylim=(0.25, 0.55)
    )
    axes.legend(fontsize=7, ncol=2)
    axes.set_title("Fig 7.2: n-step TD on the 19-state random walk")
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def plot_10_1(groups: list[SettingRuns], path: Path) -> None:
    snapshots = groups[0].data[0]["cost_to_go"] if groups and groups[0].n_runs else {}
    if not snapshots:
        return
    figure = plt.figure(figsize=(4 * len(snapshots), 4))
    positions, velocities = np.meshgrid(COST_TO_GO_POSITIONS, COST_TO_GO_VELOCITIES)
    for index, (episode, grid) in enumerate(sorted(snapshots.items(), key=lambda item: int(item[0]))):
        axes = figure.add_subplot(1, len(snapshots), index + 1, projection="3d")
        axes.plot_surface(positions, velocities, np.array(grid), cmap="viridis", linewidth=0)
        axes.set(xlabel="Position", ylabel="Velocity", title=f"Episode {episode}")
        axes.tick_params(labelsize=6)
    figure.suptitle(f"Fig 10.1: cost-to-go −max_a q̂(s, a, w), one run of {groups[0].setting.label}")
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


#: Episodes of the moving average of the per-episode curves (Figs 10.3, 13.1, 13.2): with fewer runs than the book's
#: 100, the run average alone is too noisy to read
SMOOTHING = 10


def smoothed(values: np.ndarray, window: int = SMOOTHING) -> np.ndarray:
    """:return: the trailing moving average of ``values`` over ``window`` episodes (fewer at the start)"""
    sums = np.cumsum(np.insert(values, 0, 0.0))
    counts = np.minimum(np.arange(1, len(values) + 1), window)
    return (sums[1:] - sums[np.maximum(np.arange(1, len(values) + 1) - window, 0)]) / counts


def plot_10_3(groups: list[SettingRuns], episodes: int, path: Path) -> None:
    figure, axes = plt.subplots(figsize=(6, 4.5))
    for group in groups:
        lengths = group.array("lengths", episodes)
        if len(lengths):
            axes.plot(
                np.arange(1, episodes + 1),
                smoothed(lengths.mean(axis=0)),
                label=f"{group.setting.label} ({len(lengths)} runs)",
            )
    ylabel = f"Mountain Car\nSteps per episode\nlog scale ({SMOOTHING}-episode moving average)"
    axes.set(xlabel="Episode", ylabel=ylabel, yscale="log", ylim=(100, 1000))
    axes.legend()
    axes.set_title("Fig 10.3: one-step vs 8-step semi-gradient SARSA")
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def plot_10_4(groups: list[SettingRuns], episodes: int, path: Path) -> None:
    figure, axes = plt.subplots(figsize=(6, 4.5))
    lowest = 220.0  # the book's axis is 220–300; it extends down to what was measured below it
    for n in sorted({g.setting.n for g in groups}):
        points = sorted(
            (g.setting.alpha * 8, *g.window("lengths", 1, episodes)[:2]) for g in groups if g.setting.n == n and g.n_runs
        )
        if points:
            alphas, means, ses = zip(*points, strict=True)
            _errorbar(axes, alphas, means, ses, f"n={n}")
            lowest = min(lowest, *(mean - (se if math.isfinite(se) else 0.0) for mean, se in zip(means, ses, strict=True)))
    axes.set(
        xlabel="α × number of tilings (8)",
        ylabel=f"Mountain Car\nSteps per episode\naveraged over first {episodes} episodes",
        ylim=(math.floor(lowest / 5) * 5, 300),
    )
    axes.legend()
    axes.set_title("Fig 10.4: n-step semi-gradient SARSA, α and n")
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def plot_13(groups: list[SettingRuns], episodes: int, path: Path, title: str) -> None:
    figure, axes = plt.subplots(figsize=(6, 4.5))
    for group in groups:
        returns = group.array("returns", episodes)
        if len(returns):
            axes.plot(
                np.arange(1, episodes + 1),
                smoothed(returns.mean(axis=0)),
                label=f"{group.setting.label} ({len(returns)} runs)",
                linewidth=0.8,
            )
    axes.axhline(SHORT_CORRIDOR_OPTIMAL_VALUE, linestyle="--", color="gray", label="v*(s0)")
    axes.set(
        xlabel="Episode",
        ylabel=f"Total reward on episode\n(averaged over runs, {SMOOTHING}-episode moving average)",
        ylim=(-90, -10),
    )
    axes.legend(fontsize=7)
    axes.set_title(title)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def draw(plan: Plan, figures: Sequence[str], cache_dir: Path, versions: str, results_dir: Path) -> dict[str, str]:
    """Draw each figure from the cached runs. :return: the PNG of each figure drawn"""
    pngs = {}
    for figure in figures:
        groups = collect(plan, figure, cache_dir, versions)
        path = results_dir / f"fig_{figure.replace('.', '_')}.png"
        if figure == "7.2":
            plot_7_2(groups, plan.random_walk_episodes, path)
        elif figure == "10.1":
            plot_10_1(groups, path)
        elif figure == "10.3":
            plot_10_3(groups, plan.mountain_car_episodes, path)
        elif figure == "10.4":
            plot_10_4(groups, plan.mountain_car_first, path)
        elif figure == "13.1":
            plot_13(groups, plan.corridor_episodes, path, "Fig 13.1: REINFORCE on the short corridor")
        else:
            plot_13(groups, plan.corridor_episodes, path, "Fig 13.2: REINFORCE with and without baseline")
        if path.exists():
            pngs[figure] = path.name
    return pngs


def settings_table(plan: Plan, figure: str, cache_dir: Path, versions: str) -> str:
    """:return: a markdown table of each setting of ``figure``: runs, its figure's number, steps/s"""
    lines = ["| Setting | Runs | Measure (mean ± SE over runs) | Env steps/s |", "|---|---|---|---|"]
    for group in collect(plan, figure, cache_dir, versions):
        if figure == "7.2":
            measure = fmt(*group.window("rms", 1, plan.random_walk_episodes)[:2], 3) + " RMS, episodes 1–10"
        elif figure in ("10.3", "10.4"):
            last = plan.mountain_car_first if figure == "10.4" else plan.mountain_car_episodes
            measure = fmt(*group.window("lengths", 1, last)[:2], 1) + f" steps, episodes 1–{last}"
        elif figure == "10.1":
            # Each run's env steps over its episodes (the sum over runs was shown before, under "mean ± SE")
            steps = np.array([run["num_timesteps"] for run in group.data], dtype=float)
            episodes = max(plan.snapshots)
            measure = f"{steps.mean():,.0f}" if len(steps) else "–"
            if len(steps) > 1:
                measure += f" ± {steps.std(ddof=1) / math.sqrt(len(steps)):,.0f}"
            if len(steps):
                measure += f" steps in {episodes} episode{'s' if episodes != 1 else ''}"
        else:
            last = plan.corridor_episodes
            measure = fmt(*group.window("returns", 1, last)[:2], 2) + f" return, episodes 1–{last}"
        rate = f"{group.steps_per_second:,.0f}" if group.n_runs else "–"
        diverged = sum(1 for run in group.data if run.get("diverged"))
        runs = f"{group.n_runs} ({diverged} diverged)" if diverged else str(group.n_runs)
        lines.append(f"| {group.setting.label} | {runs} | {measure} | {rate} |")
    return "\n".join(lines)


FIGURE_NOTES = {
    "7.2": "n-step TD on the 19-state random walk: `NStepSARSA` on `sb3_classic/RandomWalk19-v0` (one action, one-hot "
    "states, so a linear q̂ without bias is the table V), V = 0 initially, γ = 1. The RMS error over the 19 states is "
    "read from the weights after each episode's updates and averaged over the first 10 episodes. The box of §7.2 in "
    "NumPy (`python -m benchmarks.textbook_numpy`, 400 runs) gives 0.264 ± 0.003 at n = 4, α = 0.4 and 0.323 ± 0.002 at "
    "n = 16, α = 0.1. Every setting sees the same walks for a seed (one action: the walk does not depend on the agent), "
    "and the walks of the first seeds happen to be hard: seeds 0, 4 and 5 start with 6 exits on the same side (3.5% "
    "of walks do), which raises every setting's error when there are few runs.",
    "10.1": "The cost-to-go −max_a q̂ of one run of one-step semi-gradient SARSA (α = 0.3/8, the book's code's), after "
    "the episodes shown. Reduced: the book's episode 9000 (about a million more steps) and its step 428 of episode 1 "
    "are left out.",
    "10.3": "Steps per episode of one-step (α = 0.5/8) and 8-step (α = 0.3/8) semi-gradient SARSA, averaged over runs. "
    "The book's ≈ 119 at episodes 91–100 is read from its figure (no standard error). The box of §10.2 in NumPy with the "
    "same tiles (`benchmarks.textbook_numpy.mountain_car_sarsa`, 30 runs) gives 126.8 ± 5.1 there and 237.1 ± 2.8 over "
    "episodes 1–50; a run's mean over 10 episodes varies by about ±30 steps, so a few runs cannot pin it down.",
    "10.4": "Mean steps per episode over the first 50 episodes, for each n and α run (error bars: standard errors). The "
    "runs of n = 1, α = 0.5/8 and n = 8, α = 0.3/8 are Fig 10.3's first 50 episodes. The book gives curves, not numbers: "
    "the table above checks each n at the best α of the box of §10.2 in NumPy (`python -m benchmarks.textbook_numpy`, 30 "
    "runs on its own seeds; chosen without the package's runs, whose own best of a few runs per α would be biased "
    "low), with the spread of a run taken from the box's 30 (4 runs cannot estimate it), and gives the figure's lowest "
    "points read by eye beside it. The box has the same shape as the package: n = 1 and 2 improve up to α ≈ 1.1–1.3/8 "
    "(an earlier grid that stopped at 0.7/8 and 0.5/8 put them 12 steps above the figure), and at its best α every n "
    "is at 221–239 steps, at or a little below the figure's reading.",
    "13.1": "Plain REINFORCE (§13.3) on the short corridor, total reward per episode averaged over runs, with v*(s0). "
    "The curves average the runs that completed all their episodes. Plain REINFORCE as the book's pseudocode has it (no "
    "clamp of π) can diverge: after an episode of a few thousand steps, the per-step updates of that one episode move θ "
    "by hundreds (each ∇ln π is taken at the θ the previous step left, and |G_t| is in the thousands), π(right) rounds "
    "to 0 or 1, and the corridor is never left again (seed 0 of α = 2^-13: episode 42 of 933 steps took θ to "
    "(θ_left, θ_right) = (−2.8, 2.8), episode 45 of 2,562 steps to (268, −268); episode 46 never ended). The book's "
    "code keeps π ≥ 0.05, which prevents it; the package does what the pseudocode says.",
    "13.2": "REINFORCE with baseline (α^θ = 2^-9, α^w = 2^-6) against plain REINFORCE (α = 2^-13). The per-run means "
    "of REINFORCE with baseline over episodes 1–100 are heavy-tailed: now and then a run has an episode of thousands of "
    "steps (seed 4: 12,826) and recovers. The box of §13.4 in NumPy (`python -m benchmarks.textbook_numpy`, 2000 runs) "
    "gives −21.01 ± 0.33, median −18.9, worst run −454.8; the box of §13.3 at α = 2^-13, episodes 401–500, 100 runs: "
    "−15.12 ± 0.17. The package's runs are that box replayed on their own actions "
    "(`tests/test_textbook.py::test_corridor_run_is_the_books_box_replayed`): they differ from the NumPy runs by the "
    "random draws only.",
}


def write_report(
    plan: Plan,
    figures: Sequence[str],
    cache_dir: Path,
    versions: str,
    results_dir: Path,
    command: str,
    workers: int,
    cpu_seconds: float,
) -> Path:
    """Write ``textbook.md`` and the PNGs into ``results_dir``. :return: the markdown's path"""
    results_dir.mkdir(parents=True, exist_ok=True)
    pngs = draw(plan, figures, cache_dir, versions, results_dir)
    table, _ = book_table(plan, cache_dir, versions)
    sections = []
    for figure in figures:
        image = f"\n![Fig {figure}]({pngs[figure]})\n" if figure in pngs else ""
        sections.append(
            f"## Fig {figure}\n\n{FIGURE_NOTES[figure]}\n\n{settings_table(plan, figure, cache_dir, versions)}\n{image}"
        )
    runs = ", ".join(f"Fig {figure}: {plan.runs[figure]}" for figure in figures)
    if (plan.mountain_car_episodes, plan.corridor_episodes) == (DEFAULT.mountain_car_episodes, DEFAULT.corridor_episodes):
        not_reduced = "The settings not reduced: episodes per run, α of the named settings, initial weights, γ = 1, ε = 0."
    else:
        not_reduced = (
            f"Episodes per run are cut too (Fig 10.3: {plan.mountain_car_episodes}, Fig 10.4: {plan.mountain_car_first}, "
            f"Figs 13.1–13.2: {plan.corridor_episodes}; `--quick`): a test of the pipeline, whose numbers are not the "
            "figures' (the measures that need later episodes are empty, and so are the plots that need them)."
        )
    spent = (
        f" This invocation trained for {cpu_seconds / 60:.1f} CPU minutes (runs already cached not counted)."
        if cpu_seconds
        else ""
    )
    text = f"""# The book's figures, reproduced

Produced by:

```
{command}
```

Versions: {versions}. {workers} run{"s" if workers != 1 else ""} in parallel, torch 1 thread each,
CPU ({platform.machine()}, {os.cpu_count()} cores).{spent}

Runs per setting: {runs}. Seeds 0, 1, …; every algorithm is the package's per-step mode with plain SGD on a linear
q̂ or policy without bias, weights 0 (the book's; `tests/test_book_updates.py` checks the updates against a
transcription of the boxes). A run whose episode reaches {DIVERGED_LENGTH:,} steps is stopped as diverged (the
policy's probabilities have rounded to 0 or 1: see the notes of Figs 13.1–13.2); the means that need episodes it did not
reach leave it out, and the tables count it ("+k diverged"). Standard errors (SE) are over runs: the sample standard
deviation of each run's mean over the episodes named, divided by √runs. "Within 2 SE": |ours − book| ≤
2 √(SE_ours² + SE_book²) (the book's SE taken as 0 where it gives none; Fig 10.4's figure gives no numbers: it is
checked against the book's box run in NumPy, see its notes).

## The book's numbers beside ours

{table}

Reduced against the book, to fit a few minutes on 2 cores (`--runs 100` and `--full-grid` give the book's
run counts and α grids): the α grids of Figs 7.2 and 10.4 are the points around each n's optimum; Fig 10.1 stops at
episode {max(plan.snapshots)}; run counts are above. {not_reduced}

How the models are built (public API only, `benchmarks/textbook.py`'s `make_model`):

- n-step SARSA: `NStepSARSA("MlpPolicy", env, learning_rate=α, n_steps=n, train_freq=1, gradient_steps=1,
  update_mode="per_step", gamma=1.0, exploration_initial_eps=0.0, exploration_final_eps=0.0,
  policy_kwargs=dict(net_arch=[], with_bias=False, weight_init=0.0, optimizer_class=th.optim.SGD))`; greedy ties are
  broken at random. Mountain Car adds `features_extractor_class=TileCoding` with 8 tilings of 8 × 8 over position
  [−1.2, 0.5] × velocity [−0.07, 0.07], `origin="zero"` (the grids of the book's footnote), dense (no hashing, so
  no collisions), on `sb3_classic/MountainCarNoLimit-v0` (no time limit).
- REINFORCE: `REINFORCE("MlpPolicy", env, learning_rate=α^θ, value_learning_rate=α^w, update_mode="per_step",
  use_baseline=..., gamma=1.0, gamma_t_factor=True, policy_kwargs=<the same>)`, then the book's code's initial policy
  θ = (θ_right, θ_left) = (−1.47, 1.47), π(right) ≈ 0.05, set with
  `with th.no_grad(): model.policy.action_net.weight.copy_(th.tensor([[1.47], [-1.47]]))` (row 0 is "left").
  The book's code also keeps π(a) ≥ 0.05 by clipping the policy; the package (and the book's pseudocode) does not.
- Per-episode data: a callback (`EpisodeRecorder`) reads the Monitor's episode length and return, and for Fig 7.2 the
  weights after the episode's last updates (made after the episode's last step, so read at the next rollout's start).

{"".join(sections)}"""
    path = results_dir / "textbook.md"
    path.write_text(text)
    return path


# --- Command line ----------------------------------------------------------------------------------------------------


def parse_runs(values: Sequence[str], defaults: dict[str, int]) -> dict[str, int]:
    """:param values: ``N`` (every figure) or ``FIG=N``. :return: runs per figure"""
    runs = dict(defaults)
    for value in values:
        figure, _, count = value.rpartition("=")
        if figure and figure not in FIGURES:
            raise ValueError(f"--runs {value!r}: {figure!r} is not one of the figures {FIGURES}")
        if not count.isdigit() or int(count) < 1:
            raise ValueError(f"--runs {value!r}: the count must be a positive integer, e.g. 100 or 13.2=100")
        for target in [figure] if figure else FIGURES:
            runs[target] = int(count)
    return runs


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--figures", nargs="+", default=list(FIGURES), choices=FIGURES, help="figures to make (default: all)")
    parser.add_argument("--runs", nargs="+", default=[], help="runs per setting: N for every figure, or FIG=N (e.g. 13.2=100)")
    parser.add_argument(
        "--quick", action="store_true", help="tiny runs, the whole pipeline in about a minute (scratch output)"
    )
    parser.add_argument("--full-grid", action="store_true", help="the book's α grids for Figs 7.2 and 10.4 (much longer)")
    parser.add_argument(
        "--workers", type=positive_int, default=os.cpu_count() or 1, help="runs in parallel (default: the cores)"
    )
    parser.add_argument("--report-only", action="store_true", help="train nothing: draw what the cache holds")
    parser.add_argument("--cache-dir", type=Path, default=DEFAULT_CACHE_DIR)
    parser.add_argument(
        "--results-dir", type=Path, default=None, help="default: benchmarks/results/textbook/ (--quick: scratch)"
    )
    args = parser.parse_args(argv)
    try:
        parse_runs(args.runs, DEFAULT.runs)
    except ValueError as error:
        parser.error(str(error))
    return args


def make_plan(args: argparse.Namespace) -> Plan:
    base = QUICK if args.quick else DEFAULT
    plan = Plan(**{**base.__dict__, "runs": parse_runs(args.runs, base.runs)})
    if args.full_grid:
        plan.random_walk_alphas = BOOK_RANDOM_WALK_ALPHAS
        plan.mountain_car_alphas = BOOK_MOUNTAIN_CAR_ALPHAS
    return plan


def shown_arguments(argv: Sequence[str]) -> list[str]:
    """
    :return: the arguments that change the results: without ``--figures``, ``--report-only`` and ``--workers``, which
        only choose which runs are trained now and how (a run's result depends on its setting and seed alone, so the
        report of runs trained in parts is the report of the whole command)
    """
    shown, skipping = [], False
    for argument in argv:
        if argument.startswith("--"):
            skipping = argument.split("=")[0] in ("--figures", "--report-only", "--workers")
        if not skipping:
            shown.append(argument)
    return shown


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    console = Console()
    plan = make_plan(args)
    figures = [figure for figure in FIGURES if figure in args.figures]
    results_dir = args.results_dir or (QUICK_RESULTS_DIR if args.quick else DEFAULT_RESULTS_DIR)
    versions = package_digest()
    cpu_seconds = 0.0
    if not args.report_only:
        cpu_seconds = run_all(plan_runs(plan, figures), args.workers, args.cache_dir, versions, console)
    command = "python -m benchmarks.textbook " + shlex.join(shown_arguments(sys.argv[1:] if argv is None else list(argv)))
    path = write_report(plan, FIGURES, args.cache_dir, versions, results_dir, command.strip(), args.workers, cpu_seconds)
    console.print(f"wrote {path}")
    table, _ = book_table(plan, args.cache_dir, versions)
    print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
