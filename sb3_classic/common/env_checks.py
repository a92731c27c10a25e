"""
Checks of what the envs return to the rollout loop (a NaN or ±inf value, a final observation of the wrong shape, a
truncation without its final observation, an episode that does not end), with errors and warnings that name the env,
the step and the fix. The loop
runs them before a step is stored, so that no update trains on such a value.
"""

import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.base_class import BaseAlgorithm

from sb3_classic.common.buffers import Observations, all_finite, non_finite_entries

#: The advice of a non-finite value's error, for the values ``step()`` returns
FIND_NON_FINITE = (
    "To find where the value comes from, wrap the env in stable_baselines3.common.vec_env.VecCheckNan(env, "
    "raise_exception=True); if the env's values are finite, a callback changed them in place in its _on_step."
)
#: What a final observation is, in the errors
FINAL_OBSERVATION = "final observation (infos[i]['terminal_observation'])"


def raise_non_finite(
    model: BaseAlgorithm,
    episode_length: np.ndarray,
    values: Observations,
    field: str,
    where: str = "",
    after_reset: np.ndarray | None = None,
    env_indices: Sequence[int] | None = None,
    find: str = FIND_NON_FINITE,
) -> None:
    """
    Raise a ValueError naming the env, the step and the field of a NaN or ±inf an env returned (an observation, a
    reward, or a final observation). The callers raise it before the step is stored, so no update ever sees the
    value and the model stays as its last update left it.

    :param model: the algorithm training on the envs
    :param episode_length: the steps of each env's episode stored so far (the buffer's)
    :param values: the batch (first axis: envs) holding a non-finite entry
    :param field: what it is (``"observation"``, ``"reward"``, ...)
    :param where: when it was returned, if not at the current step of the env's episode
    :param after_reset: envs whose episode ended at this step (their observation is a new episode's first)
    :param env_indices: the env index of each row of ``values`` (default: row i is env i)
    :param find: how to find where the value comes from
    :raises ValueError: always
    """
    row, key, value = non_finite_entries(values)
    env_idx = int(env_indices[row]) if env_indices is not None else row
    if key is not None:
        field = f"{field}[{key!r}]"
    if not where:
        step = int(episode_length[env_idx]) + 1
        where = (
            f"the first observation of a new episode (after the reset that ended step {step} of the previous one)"
            if after_reset is not None and after_reset[env_idx]
            else f"step {step} of its episode"
        )
    raise ValueError(
        f"Env {env_idx} returned a non-finite {field} ({value}) at {where}, {model.num_timesteps} env steps into "
        f"training (all envs together). {type(model).__name__} stopped before storing or training on it: the "
        f"model's parameters are those of its last update, and it can be saved. {find}"
    )


def check_final_observation(model: BaseAlgorithm, episode_length: np.ndarray, final_obs: Any, env_idx: int) -> None:
    """
    :param model: the algorithm training on the envs
    :param episode_length: the steps of each env's episode stored so far (the buffer's)
    :param final_obs: a truncated episode's final observation (``infos[i]['terminal_observation']``), which its
        target bootstraps from
    :param env_idx: its env
    :raises ValueError: naming the env and the step, if it does not have the observation space's shape (it would be
        broadcast into the buffer: shape (1,) into (3,) becomes [x, x, x]) or holds NaN or ±inf
    """
    observation_space = model.observation_space
    space_of: dict[Any, spaces.Space] = (
        {**observation_space.spaces} if isinstance(observation_space, spaces.Dict) else {None: observation_space}
    )
    values: dict[Any, Any] = final_obs if isinstance(final_obs, dict) else {None: final_obs}
    for key, space in space_of.items():
        shape = np.shape(values[key]) if key in values else None
        if space.shape is not None and shape != space.shape:
            name = FINAL_OBSERVATION if key is None else f"{FINAL_OBSERVATION}[{key!r}]"
            step = int(episode_length[env_idx]) + 1
            raise ValueError(
                f"Env {env_idx} returned a {name} of shape {shape} at step {step} of its episode, where "
                f"{type(model).__name__} bootstraps from it: the observation space {space} has shape {space.shape}. "
                "Make the env return final observations of the space's shape (a VecEnv of your own: the "
                "observation before its automatic reset)"
            )
    if not all_finite(final_obs):
        batch = (
            {key: np.asarray(obs)[None] for key, obs in final_obs.items()}
            if isinstance(final_obs, dict)
            else np.asarray(final_obs)[None]
        )
        # (VecCheckNan checks what step() returns, not the infos)
        find = "It is the observation the env returned at that step, before the VecEnv reset it: check the env there."
        raise_non_finite(model, episode_length, batch, FINAL_OBSERVATION, env_indices=[env_idx], find=find)


def warn_truncation_without_final_observation(model: BaseAlgorithm, env_idx: int) -> None:
    """
    A truncation without ``terminal_observation`` (a VecEnv of the user's) has nothing to bootstrap from: warn that
    it is trained as a termination.

    :param model: the algorithm training on the envs
    :param env_idx: the env that reported it
    """
    warnings.warn(
        f"Env {env_idx} reported a time-limit truncation (infos[i]['TimeLimit.truncated']) without its final "
        "observation (infos[i]['terminal_observation']): there is nothing to bootstrap from, so "
        f"{type(model).__name__} trains it as a termination. SB3's VecEnvs put it there; a VecEnv of your own should "
        "too (or pass handle_timeout_termination=False to treat every truncation as a termination)",
        stacklevel=4,
    )


def warn_episodes_cut(model: BaseAlgorithm, env_indices: list[int], max_episode_length: int) -> None:
    """
    Episodes that reach ``max_episode_length`` are cut for training, but their envs go on: warn what that means.

    :param model: the algorithm training on the envs
    :param env_indices: the envs whose episodes are cut
    :param max_episode_length: the cap
    """
    warnings.warn(
        f"Episodes of envs {env_indices} reached max_episode_length={max_episode_length} steps without ending: "
        f"{type(model).__name__} cut them there for training (their returns end there, bootstrapped as at a time limit), "
        "but the envs go on: the next episodes trained on start where these stopped, and the Monitor and callbacks do not "
        "count the cuts. Wrap the env in gymnasium.wrappers.TimeLimit (which resets it), or raise max_episode_length.",
        stacklevel=4,
    )
