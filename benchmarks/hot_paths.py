"""
Microbenchmarks of the three hot paths where sb3_classic departs from SB3's and PyTorch's defaults, so that a reader
can re-run the numbers behind those choices on their own machine:

- **NStepSARSA's gradient step** (forward, loss, backward and Adam step of a 64×64 Q-network on 128 transitions, the
  batch of the tuned settings on 8 envs; ``NStepSARSA.train`` takes 8 per update) with each Adam implementation:
  the loop over parameter tensors (PyTorch's default on CPU), ``foreach`` and ``fused`` (sb3_classic's default);
- **REINFORCE's action sampling** in the rollout loop, for 1 and 8 envs: SB3's ``get_distribution(obs).get_actions()``
  against ``REINFORCEPolicy.sample_actions`` (the same draw, without building a ``torch.distributions`` object);
- **NStepSARSA's per-step update of a linear q̂** over tile coding with plain SGD (the book's Figs 10.1–10.4), through
  autograd and ``torch.optim.SGD`` against ``LinearPolicy``'s own update, applied to the weights directly
  (``LinearQPolicy.sgd_step``), on the dense features and over the active tiles.

Timed with ``torch.utils.benchmark`` (one thread, CPU).

    python -m benchmarks.hot_paths
"""

import argparse
import functools
import shlex
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch as th
from rich.console import Console
from stable_baselines3.common.base_class import BaseAlgorithm
from torch.utils.benchmark import Timer

from benchmarks.common import DEFAULT_RESULTS_DIR, ENV_IDS, QUICK_RESULTS_DIR
from benchmarks.report import markdown_table
from benchmarks.throughput import NET_ARCH
from sb3_classic import REINFORCE, NStepSARSA, TileCoding
from sb3_classic.harness.common import code_versions

#: The Adam implementations compared, as the ``optimizer_kwargs`` that choose them (sb3_classic's default: none)
ADAM_VARIANTS = {
    "Adam, loop over tensors (PyTorch's CPU default)": dict(foreach=False),
    "Adam, foreach": dict(foreach=True),
    "Adam, fused (sb3_classic's default)": {},
}
#: The env of the linear update's path: Mountain Car, as in the book's Figs 10.1–10.4
LINEAR_ENV_ID = "MountainCar-v0"
#: Transitions per update of the tuned NStepSARSA settings: train_freq 16 × 8 envs
BATCH_SIZE = 128
HEADER = f"""Median µs per call (`torch.utils.benchmark`, 1 thread, CPU), networks `net_arch={NET_ARCH}`.

- *NStepSARSA gradient step*: forward, loss, backward and Adam step of the Q-network on {BATCH_SIZE} transitions (the
  batch of the tuned settings on 8 envs; `NStepSARSA.train` takes 8 per update), with each Adam implementation.
- *REINFORCE action sampling*: the actions of the rollout loop, with SB3's `get_distribution(obs).get_actions()` and
  with `REINFORCEPolicy.sample_actions(obs)`, which makes the same draw.

- *NStepSARSA per-step linear update*: one transition's update W_a ← W_a + α[G − q̂]x(S) of a linear q̂ over the tile
  coding of Figs 10.1–10.4 (Mountain Car, 8 tilings of 8 × 8), plain SGD: through autograd and `torch.optim.SGD`,
  applied directly to the dense features (the same weights to the last bit), and over the active tiles as the book's
  code does (the same weights to float32 rounding; the observation's tiles cached, as the rollout leaves them).

Speed-up: the first variant of each path divided by this one."""


def time_call(function: Callable[[], Any], min_run_time: float) -> float:
    """:return: the median time of a call of ``function``, in µs"""
    timer = Timer("function()", globals={"function": function}, num_threads=1)
    return timer.blocked_autorange(min_run_time=min_run_time).median * 1e6


def observation_batch(model: BaseAlgorithm, n: int) -> np.ndarray:
    """:return: ``n`` observations sampled (seeded) from ``model``'s observation space"""
    space = model.observation_space
    space.seed(0)
    return np.stack([space.sample() for _ in range(n)])


def sarsa_gradient_step(env_id: str, optimizer_kwargs: dict[str, Any]) -> Callable[[], None]:
    """
    :return: one gradient step of ``NStepSARSA.train`` on a fixed batch, with an NStepSARSA built with
        ``optimizer_kwargs``
    """
    policy_kwargs = dict(net_arch=NET_ARCH, optimizer_kwargs=optimizer_kwargs)
    model = NStepSARSA("MlpPolicy", env_id, policy_kwargs=policy_kwargs, seed=0, device="cpu")
    observations = observation_batch(model, BATCH_SIZE)
    rng = np.random.default_rng(0)
    actions = rng.integers(int(model.action_space.n), size=BATCH_SIZE)
    targets = rng.standard_normal(BATCH_SIZE).astype(np.float32)
    episode_steps = np.arange(BATCH_SIZE)

    def step() -> None:
        model._gradient_step(observations, actions, targets, episode_steps)

    return step


def reinforce_samplers(env_id: str, n_envs: int) -> dict[str, Callable[[], th.Tensor]]:
    """:return: SB3's sampling and REINFORCE's, of the actions of ``n_envs`` observations, without gradient"""
    model = REINFORCE("MlpPolicy", env_id, policy_kwargs=dict(net_arch=NET_ARCH), seed=0, device="cpu")
    observations, policy = th.as_tensor(observation_batch(model, n_envs)), model.policy

    @th.no_grad()
    def sb3() -> th.Tensor:
        return policy.get_distribution(observations).get_actions()

    @th.no_grad()
    def ours() -> th.Tensor:
        return policy.sample_actions(observations)

    return {"SB3: get_distribution(obs).get_actions()": sb3, "REINFORCEPolicy.sample_actions(obs)": ours}


#: The policy_kwargs that make MlpPolicy's q̂ LinearPolicy's (one layer, no bias, weights 0, plain SGD)
MLP_AS_LINEAR: dict[str, Any] = dict(net_arch=[], with_bias=False, weight_init=0.0, optimizer_class=th.optim.SGD)


def linear_sgd_updates() -> dict[str, Callable[[], None]]:
    """
    :return: one per-step update of a linear q̂ over tile coding with plain SGD: through autograd, applied directly to
        the dense features, and over the active tiles (the observation's tiles cached, as the rollout leaves them)
    """
    features = dict(
        features_extractor_class=TileCoding,
        features_extractor_kwargs=dict(n_tilings=8, tiles_per_dim=8, low=(-1.2, -0.07), high=(0.5, 0.07)),
    )
    updates: dict[str, Callable[[], None]] = {}
    variants = (
        ("autograd + torch.optim.SGD", "MlpPolicy"),
        ("applied directly to the dense features", "LinearPolicy"),
        ("over the active tiles (sb3_classic's)", "LinearPolicy"),
    )
    for variant, policy in variants:
        # MlpPolicy: the same q̂ (one layer, no bias, weights 0) with plain SGD, through autograd
        policy_kwargs = features if policy == "LinearPolicy" else dict(features, **MLP_AS_LINEAR)
        model = NStepSARSA(
            policy, LINEAR_ENV_ID, learning_rate=0.3 / 8, update_mode="per_step", policy_kwargs=policy_kwargs,
            seed=0, device="cpu",
        )  # fmt: skip
        if variant.startswith("applied directly"):
            model.policy.__dict__["tile_coding"] = None  # (LinearPolicy's dense update)
        # One transition: an observation, its action and its target (the weights move at every call, as in training)
        updates[variant] = functools.partial(
            model._gradient_step,
            observation_batch(model, 1),
            np.array([1]),
            np.array([-3.0], dtype=np.float32),
            np.array([1]),  # (its step in the episode: not the first, which restarts ObGD's traces)
        )  # type: ignore[assignment]
    return updates


def run_hot_paths(env_ids: Sequence[str], min_run_time: float) -> pd.DataFrame:
    """
    :param env_ids: the envs whose spaces size the networks
    :param min_run_time: seconds to time each variant for (at least)
    :return: one row per path, env and variant: ``path``, ``env_id``, ``variant``, ``us`` (median µs per call) and
        ``speedup`` (the first variant of the path's time divided by this one's)
    """
    th.set_num_threads(1)
    paths: list[tuple[str, str, dict[str, Callable[[], Any]]]] = []
    for env_id in env_ids:
        steps = {name: sarsa_gradient_step(env_id, kwargs) for name, kwargs in ADAM_VARIANTS.items()}
        paths.append(("NStepSARSA gradient step", env_id, steps))
        for n_envs in (1, 8):
            name = f"REINFORCE action sampling, {n_envs} env{'s' * (n_envs > 1)}"
            paths.append((name, env_id, reinforce_samplers(env_id, n_envs)))
    paths.append(("NStepSARSA per-step linear update", LINEAR_ENV_ID, linear_sgd_updates()))
    rows = []
    for path, env_id, variants in paths:
        baseline = None
        for variant, function in variants.items():
            micros = time_call(function, min_run_time)
            if baseline is None:
                baseline = micros
            rows.append({"path": path, "env_id": env_id, "variant": variant, "us": micros, "speedup": baseline / micros})
    return pd.DataFrame(rows)


def hot_paths_table(measurements: pd.DataFrame) -> pd.DataFrame:
    """:return: ``run_hot_paths``'s rows, formatted"""
    return pd.DataFrame(
        {
            "Path": measurements["path"],
            "Env": measurements["env_id"],
            "Variant": measurements["variant"],
            "µs per call": measurements["us"].map("{:.1f}".format),
            "Speed-up": measurements["speedup"].map("{:.2f}×".format),
        }
    )


def main(argv: Sequence[str] | None = None) -> None:
    """The command line: ``python -m benchmarks.hot_paths [--quick] [--envs ...] [--results-dir DIR]``."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="time each variant briefly, into the scratch folder")
    parser.add_argument("--envs", nargs="+", default=list(ENV_IDS), choices=ENV_IDS, help="envs to size the networks")
    parser.add_argument("--results-dir", type=Path, help=f"where to write (default {DEFAULT_RESULTS_DIR})")
    args = parser.parse_args(argv)
    results_dir: Path = args.results_dir or (QUICK_RESULTS_DIR if args.quick else DEFAULT_RESULTS_DIR)
    command = shlex.join(["python", "-m", "benchmarks.hot_paths", *(sys.argv[1:] if argv is None else argv)])
    measurements = run_hot_paths(args.envs, min_run_time=0.05 if args.quick else 2.0)
    versions = ", ".join(f"{name} {version}" for name, version in code_versions("reinforce").items())
    table = markdown_table(hot_paths_table(measurements))
    results_dir.mkdir(parents=True, exist_ok=True)
    path = results_dir / "hot_paths.md"
    path.write_text(f"# Hot paths\n\nProduced by:\n\n```\n{command}\n```\n\n{HEADER}\n\nVersions: {versions}.\n\n{table}\n")
    Console().print(table, soft_wrap=True, markup=False)
    Console().print(f"Wrote {path}")


if __name__ == "__main__":
    main()
