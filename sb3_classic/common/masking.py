"""
Invalid-action masks as sb3-contrib defines them: an env method ``action_masks()`` (or sb3-contrib's
``ActionMasker(env, mask_fn)`` wrapper), read with ``sb3_contrib.common.maskable.utils.get_action_masks``.

A mask is a boolean vector with one entry per action value: ``n`` entries for ``Discrete(n)``, ``sum(nvec)`` for
``MultiDiscrete(nvec)`` (the values of each dimension in turn), ``2 * n`` for ``MultiBinary(n)`` (0 and 1 of each
dimension in turn). True marks a legal action. These checks run only where masks are used.
"""

from typing import Any

import numpy as np
from gymnasium import spaces
from sb3_contrib.common.maskable.utils import get_action_masks, is_masking_supported

__all__ = [
    "check_action_masks",
    "check_some_action_legal",
    "get_action_masks",
    "is_masking_supported",
    "mask_segments",
    "uniform_legal_actions",
]


def mask_segments(action_space: spaces.Space) -> list[int] | None:
    """
    :param action_space: an action space
    :return: the lengths of a mask's parts, one per action dimension (``[n]`` for ``Discrete(n)``, ``nvec`` for
        ``MultiDiscrete``, ``[2] * n`` for ``MultiBinary(n)``); None for a space that cannot be masked (``Box``,
        a multi-dimensional ``MultiBinary``)
    """
    if isinstance(action_space, spaces.Discrete):
        return [int(action_space.n)]
    if isinstance(action_space, spaces.MultiDiscrete) and action_space.nvec.ndim == 1:
        return [int(n) for n in action_space.nvec]
    if isinstance(action_space, spaces.MultiBinary) and isinstance(action_space.n, (int, np.integer)):
        return [2] * int(action_space.n)
    return None


def check_action_masks(action_masks: Any, n_rows: int, action_space: spaces.Space, name: str = "action_masks") -> np.ndarray:
    """
    :param action_masks: masks of ``n_rows`` states, shape (n_rows, mask_size), or (mask_size,) for one state
    :param n_rows: the states they are for (observations, envs)
    :param action_space: the action space they mask
    :param name: what they are, for the error message
    :return: the masks as a boolean array, shape (n_rows, mask_size)
    :raises ValueError: if the space cannot be masked, or the masks have another shape
    """
    segments = mask_segments(action_space)
    if segments is None:
        raise ValueError(
            f"{name}: {action_space} cannot be masked (sb3-contrib masks Discrete, MultiDiscrete and MultiBinary actions): "
            "pass action_masks=None to predict, or use_masking=False to learn"
        )
    size = sum(segments)
    masks = np.asarray(action_masks)
    if masks.shape == (size,) and n_rows == 1:
        masks = masks.reshape(1, size)
    if masks.shape != (n_rows, size):
        raise ValueError(
            f"{name} has shape {masks.shape}, but {action_space} with {n_rows} state(s) needs shape ({n_rows}, {size}), "
            f"or ({size},) for one state: one boolean per action value ({' + '.join(map(str, segments))}), "
            "True where the action is legal"
        )
    if masks.dtype != bool:
        masks = masks.astype(bool)
    return masks


def check_some_action_legal(masks: np.ndarray, action_space: spaces.Space, episode_steps: np.ndarray, where: str = "") -> None:
    """
    :param masks: masks of every env, shape (n_envs, mask_size), boolean
    :param action_space: the action space they mask
    :param episode_steps: the step of each env's episode the masks are for (0 for the first observation)
    :param where: which state they are for, if not the current one
    :raises ValueError: naming the env and the step, if a mask allows no action (in some action dimension)
    """
    segments = mask_segments(action_space)
    assert segments is not None
    if len(segments) == 1:
        legal = masks.any(axis=1)
    else:
        bounds = np.cumsum([0, *segments[:-1]])
        legal = np.logical_or.reduceat(masks, bounds, axis=1).all(axis=1)
    if not legal.all():
        env_idx = int(np.flatnonzero(~legal)[0])
        state = where or f"the observation at step {int(episode_steps[env_idx])} of its episode"
        raise ValueError(
            f"action_masks() of env {env_idx} allows no action for {state} (mask {masks[env_idx].astype(int).tolist()}): "
            "every state an action is chosen in needs at least one legal action (in each action dimension). "
            "End the episode before such a state, or allow an action there"
        )


def uniform_legal_actions(action_masks: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
    """
    :param action_masks: the legal actions of each row, shape (batch, n_actions), each row with at least one
    :param rng: the generator to draw from; None: NumPy's global one, as the unmasked draw (with every action legal,
        the same draws)
    :return: an action drawn uniformly from each row's legal ones, shape (batch,), int64
    """
    n_legal = np.count_nonzero(action_masks, axis=1)
    # The k-th legal action of each row, k uniform in 0, …, |L(s)| − 1
    k = np.random.randint(0, n_legal, size=len(action_masks)) if rng is None else rng.integers(0, n_legal)
    return (np.cumsum(action_masks, axis=1) > k[:, None]).argmax(axis=1)
