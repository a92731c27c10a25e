"""
The Optuna search spaces of ``python -m rl_zoo3.train -optimize`` for REINFORCE and n-step SARSA, and their
converters (``--trial-id``: a stored trial's parameters back into constructor arguments). ``sb3_classic.zoo``
registers them with rl-zoo3.

A search draws what the YAML entry it tunes can train with (the zoo puts a trial's values over the entry's:
``kwargs.update(sampled)``). Three kinds of entry:

- a **network** (``MlpPolicy``, ``CnnPolicy``, ...; a trial trains it with Adam): the network, the learning rates and their
  step decay, γ, and each algorithm's own settings;
- a **linear** q̂ (SARSA's ``LinearPolicy``, the book's features such as tile coding): the same without the network
  and the loss, which ``LinearPolicy`` fixes (its own SGD on ½δ², in the entry's features);
- the **streaming recipe** (``optimizer_class=ObGD``, Elsayed, Vasan & Mahmood 2024, arXiv 2410.14606): the network,
  κ (each network's), SARSA's λ and ε; the step size α, γ (that of the entry's ``VecNormalize`` too) and the one
  update per env step stay the entry's, and the network keeps the recipe's sparse initialisation and LayerNorm without
  parameters (``streaming_policy_kwargs``).

A trial's ``policy_kwargs`` replace the entry's (the drawn network with the default optimizer, or the recipe's with
ObGD), except a linear entry's, which it keeps. The sampler learns the kind from the entry the zoo's ``objective`` is
tuning (``searched_entry``, set by ``sb3_classic.zoo``); the converter from the trial's parameters (``kappa`` drawn:
the recipe; no network drawn: linear), so that a stored trial trains as it was tuned.
"""

import contextlib
from collections.abc import Callable, Iterator
from contextvars import ContextVar
from typing import TYPE_CHECKING, Any

from torch import nn

from sb3_classic.common.obgd import ObGD, uses_obgd
from sb3_classic.common.torch_layers import WEIGHT_INITS
from sb3_classic.sarsa.arguments import DEFAULT_EXPLORATION_DECAY_RATE
from sb3_classic.sarsa.policies import LinearQPolicy

if TYPE_CHECKING:
    import optuna

# The search spaces' names for what they sample, as the zoo's own samplers name them
ACTIVATIONS: dict[str, type[nn.Module]] = {"tanh": nn.Tanh, "relu": nn.ReLU, "leaky_relu": nn.LeakyReLU, "elu": nn.ELU}
LAYER_SIZES = (32, 64, 128, 256)
MAX_LAYERS = 3
# Learning-rate step decay: factor per decay (1.0: none), and every how many episodes
LR_DECAY_FACTORS = (1.0, 0.95, 0.9, 0.8, 0.5)
LR_DECAY_EVERY = (10, 25, 50, 100, 250)
#: ObGD's κ drawn for a value learner (q̂, v̂; the paper's: 2) and for a policy (the paper's: 3)
KAPPAS = (1.5, 2.0, 3.0, 4.0)
#: SARSA(λ)'s λ drawn for the streaming recipe (the paper's: 0.8)
TRACE_LAMBDAS = (0.0, 0.5, 0.8, 0.9, 0.95)

NETWORK, LINEAR, STREAMING = "network", "linear", "streaming"

#: The YAML entry (its hyperparameters as the zoo prepared them) the zoo's search is tuning while a trial's
#: ``objective`` runs; None outside one (the network search)
_searched_entry: ContextVar[dict[str, Any] | None] = ContextVar("searched_entry", default=None)


@contextlib.contextmanager
def searched_entry(hyperparams: dict[str, Any]) -> Iterator[None]:
    """
    :param hyperparams: the YAML entry a search's trial tunes (rl-zoo3's ``ExperimentManager._hyperparams``)
    :return: a context in which the samplers draw the search space of that entry's kind (``entry_kind``)
    """
    token = _searched_entry.set(hyperparams)
    try:
        yield
    finally:
        _searched_entry.reset(token)


def entry_kind(hyperparams: dict[str, Any] | None) -> str:
    """
    :param hyperparams: a YAML entry's hyperparameters (``policy`` a name or a class, ``policy_kwargs`` a dict)
    :return: ``STREAMING`` where its ``policy_kwargs`` choose ``ObGD``, ``LINEAR`` for SARSA's ``LinearPolicy``,
        else ``NETWORK``
    """
    hyperparams = hyperparams or {}
    policy = hyperparams.get("policy")
    if policy == "LinearPolicy" or (isinstance(policy, type) and issubclass(policy, LinearQPolicy)):
        return LINEAR
    policy_kwargs = hyperparams.get("policy_kwargs")
    return STREAMING if isinstance(policy_kwargs, dict) and uses_obgd(policy_kwargs) else NETWORK


def streaming_policy_kwargs(
    net_arch: list[int], activation_fn: type[nn.Module], kappa: float, value_kappa: float | None = None
) -> dict[str, Any]:
    """
    The streaming recipe's network and optimizer (Elsayed, Vasan & Mahmood 2024): sparse initialisation, LayerNorm
    without learnable parameters before each activation, ObGD.

    :param net_arch: hidden layer sizes
    :param activation_fn: the activation
    :param kappa: ObGD's κ (REINFORCE: the policy's)
    :param value_kappa: REINFORCE's κ of v̂ (None: SARSA, one network)
    :return: ``policy_kwargs``
    """
    policy_kwargs: dict[str, Any] = {
        "net_arch": net_arch,
        "activation_fn": activation_fn,
        "layer_norm": True,
        "layer_norm_kwargs": {"elementwise_affine": False},
        "weight_init": "sparse",
        "optimizer_class": ObGD,
        "optimizer_kwargs": {"kappa": kappa},
    }
    if value_kappa is not None:
        policy_kwargs["value_optimizer_kwargs"] = {"kappa": value_kappa}
    return policy_kwargs


def _suggest_network(trial: "optuna.Trial", weight_init: bool = True) -> dict[str, Any]:
    """Sample the network's depth, width, activation and (``weight_init``) initialisation, the same for every network."""
    return {
        "n_layers": trial.suggest_int("n_layers", 1, MAX_LAYERS),
        "layer_size": trial.suggest_categorical("layer_size", LAYER_SIZES),
        "activation_fn": trial.suggest_categorical("activation_fn", tuple(ACTIVATIONS)),
        **({"weight_init": trial.suggest_categorical("weight_init", WEIGHT_INITS)} if weight_init else {}),
    }


def _suggest_lr_decay(trial: "optuna.Trial") -> dict[str, Any]:
    """Sample a step decay of the learning rate(s), counted in episodes (1.0: no decay)."""
    return {
        "lr_decay_factor": trial.suggest_categorical("lr_decay_factor", LR_DECAY_FACTORS),
        "lr_decay_every": trial.suggest_categorical("lr_decay_every", LR_DECAY_EVERY),
    }


def _convert_common(sampled_params: dict[str, Any]) -> dict[str, Any]:
    """
    The conversions the search spaces share: γ from 1 − γ, ``policy_kwargs`` from the network's parameters (none
    drawn: the entry's stay), and a step decay counted in episodes that replaces the YAML's (whose milestones would
    conflict with ``lr_decay_every``).

    :param sampled_params: a trial's parameters
    :return: constructor arguments
    """
    hyperparams = dict(sampled_params)
    if "one_minus_gamma" in hyperparams:
        hyperparams["gamma"] = 1 - hyperparams.pop("one_minus_gamma")
    if "n_layers" in hyperparams:
        net_arch = [hyperparams.pop("layer_size")] * hyperparams.pop("n_layers")
        activation_fn = ACTIVATIONS[hyperparams.pop("activation_fn")]
        if "kappa" in hyperparams:
            kappas = hyperparams.pop("kappa"), hyperparams.pop("value_kappa", None)
            hyperparams["policy_kwargs"] = streaming_policy_kwargs(net_arch, activation_fn, *kappas)
        else:
            hyperparams["policy_kwargs"] = {
                "net_arch": net_arch,
                "activation_fn": activation_fn,
                "weight_init": hyperparams.pop("weight_init"),
            }
    if "lr_decay_factor" in hyperparams:
        hyperparams.update(lr_decay_milestones=None, lr_decay_unit="episode")
    return hyperparams


def _record_unused(trial: "optuna.Trial", sampled_params: dict[str, Any], unused: list[str]) -> None:
    """
    The zoo reports every sampled parameter: name those the trial does not train with (``report_*.csv``'s
    ``user_attrs_unused`` column), among them a decay's period where it does not decay.
    """
    if sampled_params.get("lr_decay_factor") == 1.0:
        unused = [*unused, "lr_decay_every"]
    if unused:
        trial.set_user_attr("unused", ", ".join(unused))


def convert_reinforce_params(sampled_params: dict[str, Any]) -> dict[str, Any]:
    """
    Turn the parameters of a trial of ``sample_reinforce_params`` into ``REINFORCE`` arguments
    (rl-zoo3 calls it to train with a stored trial: ``--storage ... --study-name ... --trial-id N``).

    :param sampled_params: the trial's parameters (``trial.params``)
    :return: keyword arguments of ``REINFORCE``; with ``normalize_advantage=True``, ``update_mode="batch"`` too
        (standardising δ needs a batch: a YAML's ``per_step`` would be refused and end the study)
    """
    params = _convert_common(sampled_params)
    if params.get("normalize_advantage"):
        params["update_mode"] = "batch"
    return params


def sample_reinforce_params(
    trial: "optuna.Trial", n_actions: int, n_envs: int, additional_args: dict[str, Any]
) -> dict[str, Any]:
    """
    Optuna search space of REINFORCE with baseline (rl-zoo3's ``-optimize``): both learning rates, episodes per
    update, γ, advantage normalisation, entropy bonus, learning-rate step decay, and the networks' depth, width,
    activation and initialisation. A trial that draws advantage normalisation trains in batch mode (its
    ``update_mode`` user attribute says so), whatever the YAML's ``update_mode``. For an entry of the streaming
    recipe: the networks' depth, width and activation, and ObGD's κ of each network.

    :param trial: the Optuna trial to sample from
    :param n_actions: size of a Box action space (unused)
    :param n_envs: number of envs (unused)
    :param additional_args: rl-zoo3's extra information (unused)
    :return: keyword arguments of ``REINFORCE``
    """
    if entry_kind(_searched_entry.get()) == STREAMING:
        sampled_params = {
            **_suggest_network(trial, weight_init=False),
            "kappa": trial.suggest_categorical("kappa", KAPPAS),
            "value_kappa": trial.suggest_categorical("value_kappa", KAPPAS),
        }
        return convert_reinforce_params(sampled_params)
    sampled_params = {
        # α^θ and α^w: the seed report's best are 0.003/0.01 (CartPole) and 0.001/0.1 (Acrobot)
        "learning_rate": trial.suggest_float("learning_rate", 1e-4, 1e-2, log=True),
        "value_learning_rate": trial.suggest_float("value_learning_rate", 1e-4, 1e-1, log=True),
        "n_episodes": trial.suggest_categorical("n_episodes", (1, 2, 4, 8, 16)),
        "one_minus_gamma": trial.suggest_float("one_minus_gamma", 1e-4, 0.03, log=True),
        "normalize_advantage": trial.suggest_categorical("normalize_advantage", (False, True)),
        "ent_coef": trial.suggest_float("ent_coef", 1e-8, 0.1, log=True),
        **_suggest_lr_decay(trial),
        **_suggest_network(trial),
    }
    trial.set_user_attr("gamma", 1 - sampled_params["one_minus_gamma"])
    if sampled_params["normalize_advantage"]:
        trial.set_user_attr("update_mode", "batch")
    _record_unused(trial, sampled_params, [])
    return convert_reinforce_params(sampled_params)


def convert_nstep_sarsa_params(sampled_params: dict[str, Any]) -> dict[str, Any]:
    """
    Turn the parameters of a trial of ``sample_nstep_sarsa_params`` into ``NStepSARSA`` arguments
    (rl-zoo3 calls it to train with a stored trial: ``--storage ... --study-name ... --trial-id N``).

    :param sampled_params: the trial's parameters (``trial.params``)
    :return: keyword arguments of ``NStepSARSA``, the parameter of the ε schedule not chosen at its neutral value
        (the default ``exploration_decay_rate``, or ``exploration_fraction=None``): ``NStepSARSA`` refuses the other
        schedule's parameter, and a YAML's or ``-params``' value of it would otherwise stay and end the study
    """
    params = _convert_common(sampled_params)
    if params.get("exploration_schedule") == "linear":
        params["exploration_decay_rate"] = DEFAULT_EXPLORATION_DECAY_RATE
    else:
        params["exploration_fraction"] = None
    return params


def _suggest_exploration(trial: "optuna.Trial") -> dict[str, Any]:
    """Sample the ε schedule: exponential per episode or linear, its start and its floor."""
    return {
        # ε ← max(ε_final, ε · rate) per episode, or linear over a fraction of training; both are sampled (without
        # conditional parameters, multivariate TPE samples jointly) and the one of the schedule not chosen is dropped
        "exploration_schedule": trial.suggest_categorical("exploration_schedule", ("exponential", "linear")),
        "exploration_decay_rate": trial.suggest_categorical("exploration_decay_rate", (0.9, 0.95, 0.98, 0.99, 0.995, 0.999)),
        "exploration_fraction": trial.suggest_categorical("exploration_fraction", (0.05, 0.1, 0.2, 0.4)),
        # The initial ε too, at or above the floor: the YAML's would be kept (MountainCar-v0's 0.0, below a sampled
        # floor, was refused and ended the study)
        "exploration_initial_eps": trial.suggest_categorical("exploration_initial_eps", (0.2, 0.5, 1.0)),
        "exploration_final_eps": trial.suggest_float("exploration_final_eps", 0.0, 0.2),
    }


def sample_nstep_sarsa_params(
    trial: "optuna.Trial", n_actions: int, n_envs: int, additional_args: dict[str, Any]
) -> dict[str, Any]:
    """
    Optuna search space of n-step SARSA (rl-zoo3's ``-optimize``): n, learning rate, steps and gradient steps per
    update, γ, Expected SARSA or not, the λ of the targets, the weight average of the greedy policy, the ε schedule
    (exponential per episode or linear, its start and its floor), the loss, learning-rate step decay, and the
    Q-network's depth, width, activation and initialisation. For a ``LinearPolicy`` entry: the same without the
    network and the loss. For an entry of the streaming recipe: the network's depth, width and activation, ObGD's κ,
    the traces' λ, Expected SARSA or not, and the ε schedule.

    :param trial: the Optuna trial to sample from
    :param n_actions: size of a Box action space (unused)
    :param n_envs: number of envs (unused)
    :param additional_args: rl-zoo3's extra information (unused)
    :return: keyword arguments of ``NStepSARSA``
    """
    kind = entry_kind(_searched_entry.get())
    if kind == STREAMING:
        sampled_params = {
            **_suggest_network(trial, weight_init=False),
            "kappa": trial.suggest_categorical("kappa", KAPPAS),
            "td_lambda": trial.suggest_categorical("td_lambda", TRACE_LAMBDAS),
            "expected_sarsa": trial.suggest_categorical("expected_sarsa", (False, True)),
            **_suggest_exploration(trial),
        }
    else:
        sampled_params = {
            # The seed report's best: n=10, α=0.0005 (CartPole); n=5, α=0.001 (Acrobot)
            "n_steps": trial.suggest_categorical("n_steps", (1, 2, 3, 5, 10, 20)),
            "learning_rate": trial.suggest_float("learning_rate", 1e-5, 1e-2, log=True),
            "train_freq": trial.suggest_categorical("train_freq", (1, 4, 8, 16, 32, 64)),
            "gradient_steps": trial.suggest_categorical("gradient_steps", (1, 2, 4, 8, 16)),
            "one_minus_gamma": trial.suggest_float("one_minus_gamma", 1e-4, 0.03, log=True),
            "expected_sarsa": trial.suggest_categorical("expected_sarsa", (False, True)),
            "td_lambda": trial.suggest_categorical("td_lambda", (0.3, 0.5, 0.65, 0.8, 0.9, 1.0)),
            # The greedy policy (so the trial's evaluations) from a Polyak average of q̂'s weights, or from q̂ (None)
            "averaging_tau": trial.suggest_categorical("averaging_tau", (None, 0.02, 0.05, 0.1, 0.2)),
            **_suggest_exploration(trial),
            **_suggest_lr_decay(trial),
        }
        if kind == NETWORK:
            sampled_params["loss_function"] = trial.suggest_categorical("loss_function", ("mse", "huber"))
            sampled_params |= _suggest_network(trial)
        trial.set_user_attr("gamma", 1 - sampled_params["one_minus_gamma"])
    linear = sampled_params["exploration_schedule"] == "linear"
    unused = ["exploration_decay_rate" if linear else "exploration_fraction"]
    if kind != STREAMING and sampled_params["n_steps"] == 1:
        unused.append("td_lambda")  # (the λ-return of one step is the one-step return)
    _record_unused(trial, sampled_params, unused)
    return convert_nstep_sarsa_params(sampled_params)


SAMPLERS: dict[str, Callable[["optuna.Trial", int, int, dict[str, Any]], dict[str, Any]]] = {
    "reinforce": sample_reinforce_params,
    "nstep_sarsa": sample_nstep_sarsa_params,
}
CONVERTERS: dict[str, Callable[[dict[str, Any]], dict[str, Any]]] = {
    "reinforce": convert_reinforce_params,
    "nstep_sarsa": convert_nstep_sarsa_params,
}
