"""
What a run of the harness is: the algorithms and their hyperparameters (this package's YAMLs for ours, rl-zoo3's for
the others), the versions a result depends on, and the cache key of a run.
"""

import argparse
import dataclasses
import difflib
import hashlib
import importlib
import inspect
import json
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
import rl_zoo3
import stable_baselines3
import torch as th
import yaml

import sb3_classic
from sb3_classic import zoo

#: The reward threshold an evaluation's mean return must reach (Gymnasium's ``reward_threshold`` for CartPole-v1 and
#: LunarLander-v3, its "solved" level; the customary one for Acrobot-v1, whose spec has ``reward_threshold=-100.0``)
THRESHOLDS = {"CartPole-v1": 475.0, "Acrobot-v1": -100.0, "LunarLander-v3": 200.0}
OUR_ALGOS = ("reinforce", "nstep_sarsa")
PEER_ALGOS = ("a2c", "ppo", "dqn")
ALL_ALGOS = OUR_ALGOS + PEER_ALGOS
LABELS = {"reinforce": "REINFORCE", "nstep_sarsa": "NStepSARSA", "a2c": "A2C", "ppo": "PPO", "dqn": "DQN"}

#: rl-zoo3's tuned hyperparameters, inside the installed package
ZOO_HYPERPARAMS_DIR = Path(rl_zoo3.__file__).resolve().parent / "hyperparams"
#: Sub-packages of sb3_classic that are not the algorithms: left out of ``code_versions``'s digest (a run's cache key
#: names the algorithms' code; the Dask workers' check covers the harness, ``cluster.harness_digest``)
HARNESS_PACKAGES = ("harness", "studies")


#: Keys of a zoo YAML entry that the zoo consumes itself (not constructor arguments)
ZOO_KEYS = frozenset(
    {
        "n_envs",
        "normalize",
        "normalize_kwargs",
        "env_wrapper",
        "env_kwargs",
        "vec_env_wrapper",
        "callback",
        "frame_stack",
        "policy",
    }
)


def split_env_id(env_id: str) -> tuple[str | None, str]:
    """
    :param env_id: a Gymnasium env id, or Gymnasium's ``module:EnvId`` form (the module registers the env when
        imported, as in ``gymnasium.make("mychain:Chain-v0")``)
    :return: the module to import (None for a plain id) and the id in Gymnasium's registry
    """
    module, colon, gym_id = env_id.partition(":")
    return (module, gym_id) if colon else (None, env_id)


def env_spec(env_id: str) -> gymnasium.envs.registration.EnvSpec:
    """
    The env's registration, after importing the module of a ``module:EnvId`` id (as ``gymnasium.make`` does): in
    every process that builds the env (the pool's and Dask's workers too), the module registers it.

    :param env_id: a Gymnasium env id, or ``module:EnvId``
    :return: its ``EnvSpec``
    :raise ImportError: if the module cannot be imported
    :raise gymnasium.error.Error: if the id is not registered (after the import)
    """
    module, gym_id = split_env_id(env_id)
    if module is not None:
        importlib.import_module(module)
    return gymnasium.spec(gym_id)


def register_algorithms() -> None:
    """Put ``reinforce`` and ``nstep_sarsa`` into ``rl_zoo3.ALGOS``, so that the zoo's ExperimentManager builds them."""
    zoo.register()


def algorithm_arguments(algo: str) -> set[str]:
    """:return: the constructor arguments of ``rl_zoo3.ALGOS[algo]``"""
    register_algorithms()
    return set(inspect.signature(rl_zoo3.ALGOS[algo].__init__).parameters) - {"self", "env", "_init_setup_model"}


def algorithm_defaults(algo: str) -> dict[str, Any]:
    """:return: the constructor arguments of ``rl_zoo3.ALGOS[algo]`` that have a default, with it"""
    register_algorithms()
    parameters = inspect.signature(rl_zoo3.ALGOS[algo].__init__).parameters.items()
    return {name: parameter.default for name, parameter in parameters if parameter.default is not inspect.Parameter.empty}


def unknown_setting(algo: str, key: str) -> str | None:
    """
    :param algo: a key of ``rl_zoo3.ALGOS``
    :param key: a key of a zoo YAML entry for it
    :return: None if ``key`` is a constructor argument of ``algo`` or a key the zoo reads itself (``ZOO_KEYS``), else
        the error: ``algo`` has no such argument, with the closest one ("did you mean")
    """
    known = algorithm_arguments(algo) | ZOO_KEYS
    if key in known:
        return None
    close = difflib.get_close_matches(key, sorted(known), n=1)
    hint = f"did you mean {close[0]!r}?" if close else f"see the arguments of {rl_zoo3.ALGOS[algo].__name__}"
    return f"{algo} has no argument {key!r}: {hint}"


def int_at_least(minimum: int) -> Callable[[str], int]:
    """
    An ``argparse`` type for counts (seeds, episodes, env steps, workers, repeats), so that a count below ``minimum``
    is a usage error before any work, not an empty run, a default taken instead, or a traceback.

    :param minimum: the smallest count allowed
    :return: the type: it returns the option's value as an int, or raises ``argparse.ArgumentTypeError``
    """

    def count(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = minimum - 1
        if value < minimum:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer >= {minimum}")
        return value

    return count


#: ``int_at_least(1)``
positive_int = int_at_least(1)


def hyperparams_path(algo: str) -> Path:
    """
    :return: the YAML ``RunSpec.create`` reads ``algo``'s hyperparameters from: this package's (shipped inside it,
        ``sb3_classic.zoo.hyperparams_path``) for ours, rl-zoo3's tuned ones for A2C, PPO and DQN
    """
    if algo in OUR_ALGOS:
        return zoo.hyperparams_path(algo)
    if algo in PEER_ALGOS:
        return ZOO_HYPERPARAMS_DIR / f"{algo}.yml"
    raise ValueError(f"algo={algo!r} has no hyperparameter file here: choose one of {ALL_ALGOS}")


def load_hyperparams(algo: str, env_id: str) -> dict[str, Any]:
    """
    The hyperparameters of ``algo`` on ``env_id`` as the zoo reads them (the env's entry, else ``default``),
    before its preprocessing.

    :param algo: a key of ``LABELS``
    :param env_id: a Gymnasium env id
    :return: the YAML entry, as loaded
    """
    path = hyperparams_path(algo)
    entries = yaml.safe_load(path.read_text())
    if env_id in entries:
        return dict(entries[env_id])
    if "default" in entries:
        return dict(entries["default"])
    raise ValueError(f"{path} has no entry for {env_id} and no 'default' entry: add one")


@cache
def code_versions(algo: str) -> dict[str, str]:
    """
    The versions of everything a run's result depends on besides its settings: the libraries, and for our
    algorithms a digest of the package's sources (they change between releases while being tuned), without the
    harness's and the study runner's (``HARNESS_PACKAGES``: editing them changes no result, as when they were in the
    repository's ``benchmarks/``).

    :param algo: the algorithm
    :return: name → version
    """
    versions = {
        "stable_baselines3": stable_baselines3.__version__,
        "rl_zoo3": rl_zoo3.__version__,
        "gymnasium": gymnasium.__version__,
        "torch": th.__version__,
        "numpy": np.__version__,
    }
    if algo in OUR_ALGOS:
        package = Path(sb3_classic.__file__).resolve().parent
        digest = hashlib.sha256()
        sources = (path for path in package.rglob("*.py") if path.relative_to(package).parts[0] not in HARNESS_PACKAGES)
        for source in sorted(sources):
            digest.update(source.relative_to(package).as_posix().encode())
            digest.update(source.read_bytes())
        versions["sb3_classic"] = f"{sb3_classic.__version__}+{digest.hexdigest()[:12]}"
    return versions


#: The population class of each algorithm that has one: (module, class)
POPULATIONS = {
    "nstep_sarsa": ("sb3_classic.sarsa.lockstep", "NStepSARSAPopulation"),
    "reinforce": ("sb3_classic.reinforce.lockstep", "REINFORCEPopulation"),
}


def population_class(algo: str) -> Any:
    """
    :param algo: a harness algorithm's name
    :return: its population class (``learn(total_timesteps, callback=[one per member])``), or None if it has none
    """
    if algo not in POPULATIONS:
        return None
    module_name, name = POPULATIONS[algo]
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as error:
        if error.name != module_name:
            raise
        return None
    return getattr(module, name)


@dataclass(frozen=True)
class RunSpec:
    """
    One learning run: an algorithm on an env with one seed, for a step budget, evaluated periodically.

    :param algo: the algorithm (a key of ``LABELS``)
    :param env_id: the Gymnasium env id, or ``module:EnvId`` (the module, imported where the run is built, registers
        the env)
    :param seed: the seed of the model and the envs
    :param n_timesteps: the step budget (env steps, all envs together)
    :param eval_freq: env steps between two evaluations
    :param n_eval_episodes: episodes per evaluation
    :param hyperparams_yaml: the zoo YAML entry used, as text (read once, so a YAML edited during a benchmark
        cannot make a run differ from its key)
    :param max_episodes: an episode budget: training stops when this many episodes (all envs together) have ended,
        and ``n_timesteps`` is only a cap (a study's budget in episodes, as the seed report's); None: the step budget
    :param label: the run's name in progress displays and messages (default: algorithm, env and seed); not part of
        the key, so runs of the same settings named differently share their cache entry
    :param lockstep: trained in lockstep with the other seeds of its setting (``harness.lockstep``: one population of
        the algorithm, its seed a member of it) rather than alone; part of the key (the two ways draw the behaviour
        policy's actions from different generators, so their results differ)
    """

    algo: str
    env_id: str
    seed: int
    n_timesteps: int
    eval_freq: int
    n_eval_episodes: int
    hyperparams_yaml: str
    max_episodes: int | None = None
    label: str | None = None
    lockstep: bool = False

    @classmethod
    def create(cls, algo: str, env_id: str, seed: int, n_timesteps: int, eval_freq: int, n_eval_episodes: int) -> "RunSpec":
        """
        :return: the run, with the hyperparameters read now from ``hyperparams_path(algo)``
        """
        hyperparams = yaml.safe_dump(load_hyperparams(algo, env_id), sort_keys=True)
        return cls(algo, env_id, seed, n_timesteps, eval_freq, n_eval_episodes, hyperparams)

    @property
    def hyperparams(self) -> dict[str, Any]:
        """The zoo YAML entry the run uses."""
        return yaml.safe_load(self.hyperparams_yaml)

    def key(self) -> str:
        """
        :return: a digest of everything that changes the result of the run and is not in its path: the
            hyperparameters, the evaluation settings and the code versions
        """
        content = {
            "algo": self.algo,
            "env_id": self.env_id,
            "seed": self.seed,
            "n_timesteps": self.n_timesteps,
            "eval_freq": self.eval_freq,
            "n_eval_episodes": self.n_eval_episodes,
            "hyperparams": self.hyperparams,
            "versions": code_versions(self.algo),
        }
        if self.max_episodes is not None:
            # Only when set, so that the keys of step-budget runs cached before it existed stay the same
            content["max_episodes"] = self.max_episodes
        if self.lockstep:
            # Likewise: the key of a run trained alone is the same as before lockstep existed
            content["training"] = "lockstep"
        return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()[:16]

    def setting_key(self) -> str:
        """:return: the key of the run's setting: its key but for the seed (the seeds of one setting share it)"""
        return dataclasses.replace(self, seed=0, label=None).key()

    def run_dir(self, cache_dir: Path) -> Path:
        """
        :return: where the finished run is cached: ``<env>/<algo>/seed_<k>/<budget>-<key>``, the budget in env steps
            or ``<N>ep`` for an episode budget (``<env>`` without the module of a ``module:EnvId`` id, which the key
            covers: no ``:`` in a folder's name)
        """
        budget = f"{self.max_episodes}ep" if self.max_episodes is not None else str(self.n_timesteps)
        return cache_dir / split_env_id(self.env_id)[1] / self.algo / f"seed_{self.seed}" / f"{budget}-{self.key()}"

    @property
    def name(self) -> str:
        """A short label for progress displays."""
        if self.label is not None:
            return self.label
        return f"{LABELS.get(self.algo, self.algo)} {self.env_id} seed {self.seed}"
