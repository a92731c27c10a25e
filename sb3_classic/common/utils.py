"""Argument checks shared by the algorithms: each error names the argument, the value and what to pass instead."""

import math
import numbers
from collections.abc import Sequence
from typing import Any

import numpy as np
from stable_baselines3.common.type_aliases import Schedule
from stable_baselines3.common.utils import FloatSchedule


def check_learning_rate(name: str, value: float | Schedule, allow_zero: bool = False) -> None:
    """
    :param name: the argument's name
    :param value: a positive float, or an SB3 schedule whose values are positive
    :param allow_zero: also accept 0 (``load(..., learning_rate=0.0)``: a model that is evaluated, not trained, as
        rl-zoo3's ``enjoy`` loads it)
    """
    try:
        start, end = FloatSchedule(value)(1.0), FloatSchedule(value)(0.0)
    except (AssertionError, TypeError) as error:
        raise TypeError(f"{name}={value!r} must be a float or an SB3 schedule (e.g. LinearSchedule)") from error
    if not ((start > 0 or (allow_zero and start == 0)) and end >= 0 and math.isfinite(start) and math.isfinite(end)):
        raise ValueError(
            f"{name}={value!r} must be finite and > 0 (a learning rate of {start} at the start, {end} at the end)"
        )


def check_range(name: str, value: Any, low: float, high: float, *, low_open: bool = False, hint: str = "") -> None:
    """
    :param name: the argument's name
    :param value: the number to check
    :param low: smallest allowed value
    :param high: largest allowed value; ``math.inf`` for no bound, which excludes infinity itself (an infinite
        coefficient would turn the first loss into NaN)
    :param low_open: exclude ``low`` itself
    :param hint: what to pass instead, appended to the message
    """
    # Any real number (NumPy's included), not a bool
    number = isinstance(value, numbers.Real) and not isinstance(value, bool)
    ok = number and (low < value if low_open else low <= value) and (value <= high if math.isfinite(high) else value < high)
    if not ok:
        interval = f"{'(' if low_open else '['}{low}, {high}{']' if math.isfinite(high) else ')'}"
        raise ValueError(f"{name}={value!r} must be a number in {interval}{'. ' + hint if hint else ''}")


def check_positive_int(name: str, value: Any, hint: str = "") -> None:
    """
    :param name: the argument's name
    :param value: the value to check
    :param hint: what to pass instead, appended to the message
    """
    # Any integer (NumPy's included), not a bool
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
        raise ValueError(f"{name}={value!r} must be an integer >= 1{'. ' + hint if hint else ''}")


def check_total_timesteps(name: str, value: Any) -> None:
    """
    :param name: the argument's name (``learn``'s ``total_timesteps``)
    :param value: env steps to train for: a number >= 0 (0 sets the model up without training, as SB3's ``learn(0)``)
    """
    # Any real number (NumPy's included, and a float such as 1e5, which SB3's loop takes), not a bool
    number = isinstance(value, numbers.Real) and not isinstance(value, bool)
    if not number:
        raise TypeError(f"{name}={value!r} must be a number of env steps >= 0, e.g. {name}=10_000")
    if not value >= 0:
        raise ValueError(f"{name}={value!r} must be >= 0: the env steps to train for (0 sets the model up without training)")


def check_choice(name: str, value: Any, choices: Sequence[str], hint: str = "") -> None:
    """
    :param name: the argument's name
    :param value: the value to check
    :param choices: allowed values
    :param hint: what else is accepted, or what a common wrong value means, appended to the message
    """
    if value not in choices:
        raise ValueError(f"{name}={value!r} must be one of {', '.join(map(repr, choices))}{'. ' + hint if hint else ''}")


def check_bool(name: str, value: Any) -> None:
    """
    :param name: the argument's name
    :param value: the value to check: True or False (NumPy's included), not a string or a number, whose truth
        would be taken silently (``expected_sarsa="False"``, a quoted YAML value, is true)
    """
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name}={value!r} must be True or False (in a zoo YAML: true or false, unquoted)")
