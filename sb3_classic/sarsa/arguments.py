"""The rules of ``NStepSARSA``'s own arguments, as a table (``ARGUMENT_RULES``), with the checks that relate them."""

import math
from collections.abc import Callable
from functools import partial
from typing import Any

from sb3_classic.common.arguments import ArgumentRule, optional
from sb3_classic.common.obgd import check_obgd_settings, uses_obgd
from sb3_classic.common.utils import check_bool, check_choice, check_positive_int, check_range
from sb3_classic.sarsa.policies import LinearQPolicy

# The linear ε schedule's, when exploration_fraction is None (SB3's DQN's default)
DEFAULT_EXPLORATION_FRACTION = 0.1
# The exponential ε schedule's per-episode factor (the constructor's default)
DEFAULT_EXPLORATION_DECAY_RATE = 0.995
# The first ε and the last (the linear schedule's) or the floor (the exponential one's): the constructor's defaults
DEFAULT_EXPLORATION_INITIAL_EPS, DEFAULT_EXPLORATION_FINAL_EPS = 1.0, 0.05

#: How ε decays per episode under the exponential schedule, for the messages
EXPONENTIAL = "ε ← max(ε_final, ε · exploration_decay_rate) per episode"


def check_exploration_schedule(name: str, value: Any) -> None:
    """
    :param name: ``exploration_schedule``
    :param value: ``"exponential"``, ``"linear"``, or a schedule (a callable of the progress remaining)
    """
    if not callable(value):
        check_choice(
            name,
            value,
            ("exponential", "linear"),
            hint="Or a schedule: a callable of the progress remaining, e.g. stable_baselines3.common.utils.LinearSchedule",
        )


def check_own_schedule_alone(schedule: Any, initial: float, final: float, fraction: float | None, rate: float) -> None:
    """
    A schedule of the user's gives every ε: the other ``exploration_`` arguments are refused unless at their defaults.

    :param schedule: ``exploration_schedule``
    :param initial: ``exploration_initial_eps``
    :param final: ``exploration_final_eps``
    :param fraction: ``exploration_fraction``
    :param rate: ``exploration_decay_rate``
    """
    if not callable(schedule):
        return
    for name, value, unused in (
        ("exploration_initial_eps", initial, DEFAULT_EXPLORATION_INITIAL_EPS),
        ("exploration_final_eps", final, DEFAULT_EXPLORATION_FINAL_EPS),
        ("exploration_fraction", fraction, None),
        ("exploration_decay_rate", rate, DEFAULT_EXPLORATION_DECAY_RATE),
    ):
        if value != unused:
            raise ValueError(
                f"{name}={value!r} belongs to the 'linear' or 'exponential' ε schedule, but exploration_schedule="
                f"{schedule!r} is a schedule of your own, which would ignore it: drop {name} (your schedule gives every ε)"
            )


def check_fraction_is_linear(schedule: Any, fraction: float | None) -> None:
    """
    :param schedule: ``exploration_schedule``
    :param fraction: ``exploration_fraction``, the linear schedule's
    """
    if fraction is not None and schedule == "exponential":
        raise ValueError(
            f"exploration_fraction={fraction!r} is the linear schedule's (SB3's DQN), but exploration_schedule is "
            f"'exponential' ({EXPONENTIAL}; the constructor's default), which would ignore it. Pass "
            "exploration_schedule='linear' as well to decay ε linearly over that fraction of training, or drop "
            "exploration_fraction"
        )


def check_decay_rate_is_exponential(schedule: Any, rate: float) -> None:
    """
    :param schedule: ``exploration_schedule``
    :param rate: ``exploration_decay_rate``, the exponential schedule's
    """
    if schedule == "linear" and rate != DEFAULT_EXPLORATION_DECAY_RATE:
        raise ValueError(
            f"exploration_decay_rate={rate!r} is the exponential schedule's ({EXPONENTIAL}), but exploration_schedule is "
            "'linear' (ε from initial to final over exploration_fraction of training), which would ignore it. Pass "
            "exploration_schedule='exponential' to decay ε per episode, or drop exploration_decay_rate"
        )


def check_exponential_decays(schedule: Any, initial: float, final: float) -> None:
    """
    :param schedule: ``exploration_schedule``
    :param initial: ``exploration_initial_eps``
    :param final: ``exploration_final_eps``, the exponential schedule's floor
    """
    if schedule == "exponential" and initial < final:
        raise ValueError(
            f"exploration_initial_eps={initial!r} is below exploration_final_eps={final!r}: the exponential schedule "
            f"({EXPONENTIAL}) would run at ε = {final!r} from the start. For a constant ε (the book's ε = 0), set both "
            "to it; for an ε that grows, exploration_schedule='linear'"
        )


def check_tau_has_a_copy(interval: int | None, tau: float) -> None:
    """
    :param interval: ``target_update_interval`` (None: no bootstrap network)
    :param tau: ``tau``, the bootstrap network's soft update coefficient
    """
    if interval is None and tau != 1.0:
        raise ValueError(
            f"tau={tau!r} is the soft update coefficient of the bootstrap network, but target_update_interval is None, "
            "so there is none (the targets bootstrap from q̂ itself, as the book's do) and tau would be ignored. Pass "
            "target_update_interval as well (env steps between two moves of the copy towards q̂, e.g. 1: after every "
            "update; SB3's DQN uses 10000), or drop tau"
        )


def check_linear_policy_update(policy_class: type, loss_function: str, max_grad_norm: float | None) -> None:
    """
    :param policy_class: the policy's class (``LinearQPolicy``'s update is plain SGD on ½(G − q̂)²)
    :param loss_function: ``loss_function``
    :param max_grad_norm: ``max_grad_norm`` (``math.inf`` or None: no clipping)
    """
    if not issubclass(policy_class, LinearQPolicy):
        return
    for name, value, plain in (("loss_function", loss_function, "mse"), ("max_grad_norm", max_grad_norm, math.inf)):
        if value not in (plain, None):
            raise ValueError(
                f"{name}={value!r}: LinearPolicy's update is plain SGD on ½(G − q̂)² (S&B eq. 10.5), without it. Drop "
                f"{name}, or use 'MlpPolicy' with policy_kwargs=dict(net_arch=[]) for a linear q̂ trained through autograd"
            )


def check_trace_settings(
    policy_kwargs: dict[str, Any] | None,
    update_mode: str,
    n_steps: int,
    gradient_steps: int,
    n_envs: int | None,
    loss_function: str,
    max_grad_norm: float | None,
) -> None:
    """
    ``ObGD`` makes SARSA(λ)'s update along eligibility traces (S&B §12.7): one transition at a time, by its one-step TD
    error, in one stream of time steps.

    :param policy_kwargs: the policy's arguments (``optimizer_class``)
    :param update_mode: ``update_mode``
    :param n_steps: ``n_steps``
    :param gradient_steps: ``gradient_steps``
    :param n_envs: the number of envs (None: no env yet)
    :param loss_function: ``loss_function``
    :param max_grad_norm: ``max_grad_norm`` (``math.inf`` or None: no clipping)
    :raises ValueError: for a setting the update along traces cannot make, naming it and the fix
    """
    if not uses_obgd(policy_kwargs):
        return
    why = "ObGD makes SARSA(λ)'s update along eligibility traces (S&B §12.7), one transition at a time"
    required = (
        ("update_mode", update_mode, "per_step", "pass update_mode='per_step' (each transition's own update, in time order)"),
        ("n_steps", n_steps, 1, "pass n_steps=1: δ is the one-step TD error, and td_lambda is the traces' λ"),
        ("gradient_steps", gradient_steps, 1, "pass gradient_steps=1: a second pass would decay the traces twice"),
        ("loss_function", loss_function, "mse", "drop loss_function: ObGD's bound on δ̄ = max(|δ|, 1) is its own clipping"),
    )
    check_obgd_settings(why, required, max_grad_norm)
    if n_envs is not None and n_envs != 1:
        raise ValueError(
            f"{n_envs} envs with optimizer_class=ObGD: {why}, with one trace over one stream of time steps; train on one "
            "env (rl-zoo3: n_envs: 1), or use another optimizer"
        )


def _probability(low_open: bool = False, hint: str = "") -> Callable[[str, Any], None]:
    return partial(check_range, low=0.0, high=1.0, low_open=low_open, hint=hint)


#: The rules of ``NStepSARSA``'s arguments beyond the base class's, in the order they are checked
ARGUMENT_RULES: tuple[ArgumentRule, ...] = (
    ("n_steps", partial(check_positive_int, hint="n=1 is one-step SARSA; the seed report used 5 and 10")),
    (
        "train_freq",
        partial(
            check_positive_int,
            hint="It counts env steps per env; SB3's tuple form (4, 'step') is not supported, and there is no 'episode' unit",
        ),
    ),
    (
        "gradient_steps",
        partial(
            check_positive_int,
            hint="A count per update; SB3's DQN's -1 (as many as the env steps of the rollout) would be train_freq here",
        ),
    ),
    ("update_mode", partial(check_choice, choices=("batch", "per_step"))),
    (
        (
            "exploration_schedule",
            "exploration_initial_eps",
            "exploration_final_eps",
            "exploration_fraction",
            "exploration_decay_rate",
        ),
        check_own_schedule_alone,
    ),
    ("exploration_schedule", check_exploration_schedule),
    ("exploration_initial_eps", _probability()),
    ("exploration_final_eps", _probability()),
    ("exploration_fraction", optional(_probability(low_open=True))),
    (("exploration_schedule", "exploration_fraction"), check_fraction_is_linear),
    ("exploration_decay_rate", _probability(low_open=True)),
    (("exploration_schedule", "exploration_decay_rate"), check_decay_rate_is_exponential),
    (("exploration_schedule", "exploration_initial_eps", "exploration_final_eps"), check_exponential_decays),
    ("loss_function", partial(check_choice, choices=("mse", "huber"))),
    ("td_lambda", _probability(hint="1.0 is the n-step return G_{t:t+n} (S&B §10.2)")),
    ("target_update_interval", optional(partial(check_positive_int, hint="Pass None for no target network"))),
    ("tau", _probability(low_open=True, hint="1.0 copies q̂ at every target update")),
    (("target_update_interval", "tau"), check_tau_has_a_copy),
    ("expected_sarsa", check_bool),
    (
        "averaging_tau",
        optional(
            _probability(
                low_open=True,
                hint="e.g. 0.05 (an average over about 20 updates), or None for the greedy policy of q̂ itself",
            )
        ),
    ),
    (("policy_class", "loss_function", "max_grad_norm"), check_linear_policy_update),
    (
        ("policy_kwargs", "update_mode", "n_steps", "gradient_steps", "n_envs", "loss_function", "max_grad_norm"),
        check_trace_settings,
    ),
)
