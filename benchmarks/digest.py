"""
The parameter digest: a SHA-256 of everything seeded training produces, for a set of configurations that covers
every update path of both algorithms. A change to the code that must not change training (a refactor, a speed-up)
proves itself by leaving every digest as it was, to the bit: take them before, and check after.

What a digest covers, after ``learn()`` on the CPU with one PyTorch thread:

- every tensor of ``model.get_parameters()`` (the policy's and the optimizers' states), by name, as raw bytes;
- every value of the ``train/`` keys at every logger dump (``log_interval=1``: one dump per rollout), as ``float.hex``.

The populations (``population-*``: three seeds of one setting trained in lockstep, ``NStepSARSAPopulation`` or
``REINFORCEPopulation``) digest each member as above and hash the members' digests in member order, so that a change
to the lockstep code proves itself as a change to a separate run's does.

    python -m benchmarks.digest                      # the digests of every configuration, as JSON
    python -m benchmarks.digest --save FILE          # the same, written to FILE
    python -m benchmarks.digest --check FILE         # exit 1 and name each configuration whose digest differs

Seeded CPU runs repeat to the bit on one machine and one set of library versions; another CPU or another PyTorch
may round differently (an AVX-512 CPU against an AVX2 one, say), so a digest file is compared on the machine that wrote
it. The file names that machine (``"machine"``: the CPU, PyTorch and NumPy), and ``--check`` on another one says so:
there, take a reference of your own with ``--save`` before a change, and ``--check`` it after.
"""

import argparse
import hashlib
import json
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import torch as th
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.logger import KVWriter, Logger

import sb3_classic.envs  # noqa: F401  (registers the book's envs)
from benchmarks.lockstep import cpu_model, population_of
from sb3_classic import REINFORCE, NStepSARSA, TileCoding
from sb3_classic.common.obgd import ObGD
from sb3_classic.common.on_policy_algorithm import ClassicOnPolicyAlgorithm

SMALL_NET = dict(net_arch=[64, 64])
#: The key of a digest file that names the machine which wrote it (``machine``)
MACHINE = "machine"


class TrainLog(KVWriter):
    """The ``train/`` values of every logger dump, in order (a logger output format)."""

    def __init__(self) -> None:
        self.dumps: list[dict[str, str]] = []

    def write(self, key_values: dict[str, Any], key_excluded: dict[str, tuple[str, ...]], step: int = 0) -> None:
        values = {key: float(value).hex() for key, value in sorted(key_values.items()) if key.startswith("train/")}
        self.dumps.append(values)

    def close(self) -> None:
        pass


def machine() -> str:
    """:return: what a digest depends on besides the code and the configuration: the CPU, PyTorch and NumPy"""
    return f"{cpu_model()}, torch {th.__version__}, numpy {np.__version__}"


def digest(model: BaseAlgorithm, train_log: Sequence[dict[str, str]] = ()) -> str:
    """
    :param model: a trained model
    :param train_log: its logger's ``train/`` values at each dump (``TrainLog.dumps``)
    :return: the SHA-256 (hex) of its parameters, its optimizers' states and ``train_log``
    """
    hasher = hashlib.sha256()
    for name, state in sorted(model.get_parameters().items()):
        for key, value in _flatten(name, state):
            hasher.update(key.encode())
            if isinstance(value, th.Tensor):
                array = value.detach().cpu().contiguous().numpy()
                hasher.update(f"{array.dtype}{array.shape}".encode())
                hasher.update(array.tobytes())
            else:
                hasher.update(repr(value).encode())
    hasher.update(json.dumps(list(train_log)).encode())
    return hasher.hexdigest()


def _flatten(prefix: str, value: Any) -> list[tuple[str, Any]]:
    # A state dict nests dicts and lists (an optimizer's state and param_groups): their leaves, by path
    if isinstance(value, dict):
        return [item for key in sorted(value, key=str) for item in _flatten(f"{prefix}.{key}", value[key])]
    if isinstance(value, (list, tuple)):
        return [item for index, element in enumerate(value) for item in _flatten(f"{prefix}[{index}]", element)]
    return [(prefix, value)]


def _sarsa(
    env_id: str, n_envs: int, steps: int, policy: str = "MlpPolicy", seed: int = 0, **kwargs: Any
) -> tuple[ClassicOnPolicyAlgorithm, int]:
    env = make_vec_env(env_id, n_envs=n_envs, seed=seed)
    return NStepSARSA(policy, env, seed=seed, device="cpu", **kwargs), steps


def _reinforce(n_envs: int, steps: int, seed: int = 0, **kwargs: Any) -> tuple[ClassicOnPolicyAlgorithm, int]:
    env = make_vec_env("CartPole-v1", n_envs=n_envs, seed=seed)
    return REINFORCE("MlpPolicy", env, seed=seed, device="cpu", policy_kwargs=SMALL_NET, **kwargs), steps


#: Batched SARSA as on Acrobot: Expected SARSA's λ-returns, a bootstrap network and weight averaging
SARSA_ACROBOT_BATCH: dict[str, Any] = dict(
    n_steps=5,
    td_lambda=0.5,
    expected_sarsa=True,
    gamma=0.999,
    target_update_interval=1,
    tau=0.5,
    averaging_tau=0.05,
    policy_kwargs=SMALL_NET,
)


#: The streaming recipe's network (sparse initialisation, LayerNorm without parameters) under ObGD with a given κ
def _streaming_net(kappa: float, **optimizer: Any) -> dict[str, Any]:
    return dict(
        net_arch=[64, 64],
        activation_fn=th.nn.LeakyReLU,
        layer_norm=True,
        layer_norm_kwargs=dict(elementwise_affine=False),
        weight_init="sparse",
        optimizer_class=ObGD,
        optimizer_kwargs=dict(kappa=kappa),
        **optimizer,
    )


#: The configurations, each a model to train and its env steps: every update path of both algorithms
CONFIGURATIONS: dict[str, Callable[[], tuple[ClassicOnPolicyAlgorithm, int]]] = {
    # Batched SARSA as on Acrobot: 8 envs, Expected SARSA's λ-returns, a bootstrap network and weight averaging
    "sarsa-batch-lambda-bootstrap-averaging": lambda: _sarsa("Acrobot-v1", 8, 4000, **SARSA_ACROBOT_BATCH),
    # Batched SARSA as on CartPole: gradient clipping
    "sarsa-batch-clipping": lambda: _sarsa(
        "CartPole-v1", 8, 4000, n_steps=3, gamma=0.995, max_grad_norm=10.0, policy_kwargs=SMALL_NET
    ),
    # Per-step SARSA (the book's loop), n = 10 and n = 1
    "sarsa-per-step-n10": lambda: _sarsa(
        "CartPole-v1", 1, 1500, n_steps=10, update_mode="per_step", train_freq=1, gradient_steps=1, policy_kwargs=SMALL_NET
    ),
    "sarsa-per-step-n1": lambda: _sarsa(
        "CartPole-v1", 1, 1500, n_steps=1, update_mode="per_step", train_freq=1, gradient_steps=1, policy_kwargs=SMALL_NET
    ),
    # The book's Mountain Car: a linear q̂ over tile coding with its own SGD update, per step
    "sarsa-tile-coded-mountain-car": lambda: _sarsa(
        "sb3_classic/MountainCarNoLimit-v0",
        1,
        1500,
        n_steps=4,
        update_mode="per_step",
        train_freq=1,
        gradient_steps=1,
        gamma=1.0,
        learning_rate=0.5 / 8,
        exploration_initial_eps=0.0,
        exploration_final_eps=0.0,
        policy="LinearPolicy",
        policy_kwargs=dict(features_extractor_class=TileCoding, features_extractor_kwargs=dict(n_tilings=8, tiles_per_dim=8)),
    ),
    # SARSA(λ) along eligibility traces under ObGD (the streaming recipe), per step
    "sarsa-lambda-obgd": lambda: _sarsa(
        "CartPole-v1",
        1,
        1500,
        n_steps=1,
        update_mode="per_step",
        train_freq=1,
        gradient_steps=1,
        td_lambda=0.8,
        learning_rate=1.0,
        policy_kwargs=_streaming_net(2.0),
    ),
    # REINFORCE with a baseline: 1 env, 8 envs, and per step (§13.4's loop)
    "reinforce-1-env": lambda: _reinforce(1, 3000),
    "reinforce-8-envs": lambda: _reinforce(8, 4000, n_episodes=8),
    "reinforce-per-step": lambda: _reinforce(1, 1500, update_mode="per_step"),
    # REINFORCE's per-step updates each bounded by ObGD (the streaming recipe)
    "reinforce-per-step-obgd": lambda: (
        REINFORCE(
            "MlpPolicy",
            make_vec_env("CartPole-v1", n_envs=1, seed=0),
            seed=0,
            device="cpu",
            update_mode="per_step",
            learning_rate=1.0,
            value_learning_rate=1.0,
            policy_kwargs=_streaming_net(3.0, value_optimizer_kwargs=dict(kappa=2.0)),
        ),
        1500,
    ),
}

#: The seeds of a population's members
POPULATION_SEEDS = (0, 1, 2)

#: The populations, each a maker of one member (by seed) and its env steps: both algorithms' lockstep paths, per step
#: and in the batch mode (SARSA's with several envs, λ-returns and the copies of q̂)
POPULATIONS: dict[str, Callable[[int], tuple[ClassicOnPolicyAlgorithm, int]]] = {
    "population-sarsa-per-step-n10": lambda seed: _sarsa(
        "CartPole-v1",
        1,
        1500,
        seed=seed,
        n_steps=10,
        update_mode="per_step",
        train_freq=1,
        gradient_steps=1,
        policy_kwargs=SMALL_NET,
    ),
    "population-sarsa-batch-lambda-bootstrap-averaging": lambda seed: _sarsa(
        "Acrobot-v1", 8, 4000, seed=seed, max_grad_norm=10.0, **SARSA_ACROBOT_BATCH
    ),
    "population-reinforce-1-env": lambda seed: _reinforce(1, 3000, seed=seed),
    "population-reinforce-per-step": lambda seed: _reinforce(1, 1500, seed=seed, update_mode="per_step"),
}


@contextmanager
def one_thread() -> Iterator[None]:
    """One PyTorch thread while it lasts (seeded CPU runs repeat to the bit with a given thread count)."""
    threads = th.get_num_threads()
    th.set_num_threads(1)
    try:
        yield
    finally:
        th.set_num_threads(threads)


def logged(model: BaseAlgorithm) -> TrainLog:
    """:return: the ``train/`` log of ``model``'s logger dumps from now on (its logger replaced by one that writes it)"""
    train_log = TrainLog()
    model.set_logger(Logger(folder=None, output_formats=[train_log]))
    return train_log


def configuration_digest(name: str) -> str:
    """
    :param name: a key of ``CONFIGURATIONS``
    :return: the digest of its seeded training
    """
    with one_thread():
        model, steps = CONFIGURATIONS[name]()
        train_log = logged(model)
        model.learn(steps, log_interval=1)
        return digest(model, train_log.dumps)


def population_digest(name: str) -> str:
    """
    :param name: a key of ``POPULATIONS``
    :return: the digest of its members' seeded training in lockstep (each member's digest, hashed in member order)
    """
    with one_thread():
        built = [POPULATIONS[name](seed) for seed in POPULATION_SEEDS]
        models, steps = [model for model, _ in built], built[0][1]
        train_logs = [logged(model) for model in models]
        population_of(models).learn(steps, log_interval=1)
        hasher = hashlib.sha256()
        for model, train_log in zip(models, train_logs, strict=True):
            hasher.update(digest(model, train_log.dumps).encode())
        return hasher.hexdigest()


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--save", type=Path, help="write the digests to this JSON file")
    group.add_argument("--check", type=Path, help="compare with the digests of this JSON file (exit 1 if any differ)")
    parser.add_argument("--only", nargs="+", choices=sorted([*CONFIGURATIONS, *POPULATIONS]), help="these configurations only")
    args = parser.parse_args(argv)

    names = args.only or [*CONFIGURATIONS, *POPULATIONS]
    digests = {}
    for name in names:
        digests[name] = population_digest(name) if name in POPULATIONS else configuration_digest(name)
        print(f"{name}: {digests[name]}", file=sys.stderr, flush=True)
    if args.check is not None:
        expected = json.loads(args.check.read_text())
        differ = [name for name in names if expected.get(name) != digests[name]]
        for name in differ:
            print(f"{name}: {digests[name]}, {args.check} has {expected.get(name)}")
        print(f"{len(names) - len(differ)} of {len(names)} digests as in {args.check}")
        written_on, here = expected.get(MACHINE), machine()
        if differ and written_on != here:
            print(
                f"{args.check} was written on {written_on or 'a machine it does not name'}; this is {here}. Another CPU "
                "or library version may round otherwise: compare digests taken on one machine (--save a reference "
                "before the change, --check it after)"
            )
        return 1 if differ else 0
    text = json.dumps({MACHINE: machine(), **digests}, indent=2) + "\n"
    if args.save is not None:
        args.save.write_text(text)
    else:
        print(text, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
