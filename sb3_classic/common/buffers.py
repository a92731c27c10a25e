"""The rollout buffer shared by REINFORCE and n-step SARSA: whole trajectories, kept across updates until used."""

from typing import Any, NamedTuple, SupportsFloat

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.buffers import BaseBuffer

Observations = np.ndarray | dict[str, np.ndarray]


class TrajectorySamples(NamedTuple):
    """
    Everything the buffer holds, time-major (``[t, env, ...]``), as views of its storage.

    ``pending`` marks the transitions not trained on yet; the rows before them are kept only as far as
    another env still needs them.
    """

    observations: Observations
    actions: np.ndarray
    rewards: np.ndarray
    dones: np.ndarray
    truncated: np.ndarray
    final_observations: Observations
    episode_steps: np.ndarray
    pending: np.ndarray
    #: the masks of S_t (``[t, env, mask_size]``), if the buffer stores masks
    action_masks: np.ndarray | None = None
    #: the masks of the final states of truncations, if the buffer stores masks
    final_action_masks: np.ndarray | None = None


class TrainingBatch(NamedTuple):
    """
    The transitions of one update, with what they are trained towards, in time order, as arrays of the buffer (the
    algorithm makes tensors of what its update needs).
    """

    #: S_t, shape (B, *obs_shape) (a dict of such arrays for ``Dict`` observations)
    observations: Observations
    #: A_t as the buffer stores them, shape (B, *action_shape)
    actions: np.ndarray
    #: the targets (G_t, G_{t:t+n}), shape (B,), float32
    targets: np.ndarray
    #: t, the step of each within its episode, shape (B,)
    episode_steps: np.ndarray
    #: how many of each env's first pending transitions they are, shape (n_envs,): marked trained after the update
    n_trained: np.ndarray
    #: the masks of S_t, shape (B, mask_size), boolean, if the buffer stores masks
    action_masks: np.ndarray | None = None

    def step_arguments(self, chunk: slice) -> tuple[Observations, np.ndarray, np.ndarray, np.ndarray]:
        """
        :param chunk: the transitions of one gradient step
        :return: their S_t, A_t, targets and episode steps t (where t = 0, S_t starts an episode)
        """
        return select(self.observations, chunk), self.actions[chunk], self.targets[chunk], self.episode_steps[chunk]


def select(observations: Observations, index: Any) -> Observations:
    """Index an observation array, or each array of a ``Dict`` observation."""
    if isinstance(observations, dict):
        return {key: obs[index] for key, obs in observations.items()}
    return observations[index]


def all_finite(observations: Observations | SupportsFloat | dict[str, Any]) -> bool:
    """
    :param observations: a batch of observations (an array, or a dict of arrays), or one observation as the env
        returned it (a VecEnv's ``terminal_observation``: a plain Python int for a ``Discrete`` space)
    :return: whether every entry is finite (integer arrays, e.g. images, always are)
    """
    if isinstance(observations, dict):
        return all(all_finite(obs) for obs in observations.values())
    observations = np.asarray(observations)
    return observations.dtype.kind not in "fc" or bool(np.isfinite(observations).all())


def non_finite_entries(values: Observations) -> tuple[int, str | None, float]:
    """
    :param values: a batch (first axis: envs), an array or a dict of arrays, with a non-finite entry
    :return: the row (env) of the first non-finite entry, its key in a dict (None for an array), and its value
    """
    arrays = values.items() if isinstance(values, dict) else [(None, values)]
    for key, array in arrays:
        array = np.asarray(array)
        if array.dtype.kind in "fc":
            bad = ~np.isfinite(array.reshape(len(array), -1))
            if bad.any():
                row = int(bad.any(axis=1).argmax())
                return row, key, float(array.reshape(len(array), -1)[row][bad[row]][0])
    raise ValueError("no non-finite entry")


def _allocate(space: spaces.Space, shape: tuple[int, ...]) -> Observations:
    if isinstance(space, spaces.Dict):
        return {key: _allocate(subspace, shape) for key, subspace in space.spaces.items()}  # type: ignore[misc]
    assert space.shape is not None
    return np.zeros(shape + space.shape, dtype=space.dtype)


def _write(storage: Observations, index: Any, values: Observations) -> None:
    if isinstance(storage, dict):
        assert isinstance(values, dict)
        for key in storage:
            storage[key][index] = values[key]
    else:
        storage[index] = values


class TrajectoryBuffer(BaseBuffer):
    """
    Stores the steps of ``n_envs`` environments in lockstep, time-major, and keeps every transition until the
    algorithm has trained on it. An update can then use whatever its targets need (whole episodes for REINFORCE,
    n further steps for n-step SARSA) even when that spans several rollouts: nothing is dropped and nothing is
    cut short at a rollout boundary. Storage grows (doubling) as needed.

    For each env, the transitions not trained on yet are a suffix of its steps (both algorithms' targets become
    known in time order); ``mark_trained`` advances that suffix and drops the rows no env needs any more.

    :param buffer_size: initial capacity in steps per env (grows when full)
    :param observation_space: observation space
    :param action_space: action space
    :param device: PyTorch device of the tensors the algorithms build from this buffer
    :param n_envs: number of parallel environments
    :param mask_size: store the action masks of every S_t and of the final states of truncations, with this many
        entries each (``set_mask_size``); None (the default): no masks
    """

    observations: Observations
    final_observations: Observations
    action_masks: np.ndarray | None
    final_action_masks: np.ndarray | None

    def __init__(
        self,
        buffer_size: int,
        observation_space: spaces.Space,
        action_space: spaces.Space,
        device: th.device | str = "auto",
        n_envs: int = 1,
        mask_size: int | None = None,
    ):
        super().__init__(buffer_size, observation_space, action_space, device, n_envs=n_envs)
        self.mask_size = mask_size
        # Integer actions (Discrete, MultiDiscrete) stay integers: they index logits and Q-values
        integer_actions = isinstance(action_space, (spaces.Discrete, spaces.MultiDiscrete))
        self.action_dtype = np.int64 if integer_actions else np.float32
        self._allocate(buffer_size)
        self.reset()

    def _allocate(self, capacity: int) -> None:
        shape = (capacity, self.n_envs)
        self.observations = _allocate(self.observation_space, shape)
        # Only written where an episode was truncated: the state to bootstrap from
        self.final_observations = _allocate(self.observation_space, shape)
        assert self.action_space.shape is not None
        self.actions = np.zeros(shape + self.action_space.shape, dtype=self.action_dtype)
        self.rewards = np.zeros(shape, dtype=np.float32)
        self.dones = np.zeros(shape, dtype=bool)
        self.truncated = np.zeros(shape, dtype=bool)
        self.episode_steps = np.zeros(shape, dtype=np.int64)
        self.action_masks = self.final_action_masks = None
        if self.mask_size is not None:
            # All legal where nothing was written (a final state whose env reported no mask)
            self.action_masks = np.ones((*shape, self.mask_size), dtype=bool)
            self.final_action_masks = np.ones((*shape, self.mask_size), dtype=bool)
        self.buffer_size = capacity
        # (the list, made once: _drop_rows runs at every update)
        self._stored_arrays = self._arrays()

    def set_mask_size(self, mask_size: int | None) -> None:
        """
        Start or stop storing action masks. The steps stored before masks are stored count as allowing every action.

        :param mask_size: entries per mask, or None to store none
        """
        if mask_size == self.mask_size:
            return
        self.mask_size = mask_size
        self.action_masks = self.final_action_masks = None
        if mask_size is not None:
            shape = (self.buffer_size, self.n_envs, mask_size)
            self.action_masks = np.ones(shape, dtype=bool)
            self.final_action_masks = np.ones(shape, dtype=bool)
        self._stored_arrays = self._arrays()

    def reset(self) -> None:
        """Forget everything, including the episodes in progress (call it when the envs are reset)."""
        super().reset()
        # First row not trained on yet, per env
        self.start = np.zeros(self.n_envs, dtype=np.int64)
        # Steps taken so far in the episode each env is running
        self.episode_length = np.zeros(self.n_envs, dtype=np.int64)

    def add(
        self,
        obs: Observations,
        actions: np.ndarray,
        rewards: np.ndarray,
        dones: np.ndarray,
        truncated: np.ndarray,
        final_observations: dict[int, Any],
        action_masks: np.ndarray | None = None,
        final_action_masks: dict[int, np.ndarray] | None = None,
    ) -> None:
        """
        Append one step of every env.

        :param obs: S_t, the observations the actions were chosen from
        :param actions: A_t
        :param rewards: R_{t+1}
        :param dones: whether the episode ended with this step
        :param truncated: whether it ended by a time limit (its final state is then bootstrapped from)
        :param final_observations: S_{t+1} of the truncated envs, by env index
        :param action_masks: the masks of S_t, shape (n_envs, mask_size), if the buffer stores masks
        :param final_action_masks: the masks of the final states of truncated envs that reported one, by env index
            (the others count as allowing every action)
        """
        if self.pos == self.buffer_size:
            self._grow()
        row = self.pos
        _write(self.observations, row, obs)
        self.actions[row] = actions
        self.rewards[row] = rewards
        self.dones[row] = dones
        self.truncated[row] = truncated
        self.episode_steps[row] = self.episode_length
        for env_idx, final_obs in final_observations.items():
            _write(self.final_observations, (row, env_idx), final_obs)
        if self.action_masks is not None:
            assert self.final_action_masks is not None
            assert action_masks is not None
            self.action_masks[row] = action_masks
            self.final_action_masks[row] = True
            for env_idx, final_masks in (final_action_masks or {}).items():
                self.final_action_masks[row, env_idx] = final_masks
        self.episode_length += 1
        self.episode_length[dones] = 0
        self.pos += 1

    def truncate(self, env_indices: np.ndarray, final_observations: Observations) -> None:
        """
        End the running episodes of ``env_indices`` at the last step added, for training, as a time limit would
        (the envs themselves go on: what follows counts as a new episode).

        :param env_indices: the envs whose episodes to cut
        :param final_observations: the current observations of those envs, bootstrapped from
        """
        row = self.pos - 1
        self.dones[row, env_indices] = True
        self.truncated[row, env_indices] = True
        _write(self.final_observations, (row, env_indices), final_observations)
        self.episode_length[env_indices] = 0

    def get(self) -> TrajectorySamples:
        """:return: views of the stored steps, oldest first"""
        rows = slice(0, self.pos)
        return TrajectorySamples(
            observations=select(self.observations, rows),
            actions=self.actions[rows],
            rewards=self.rewards[rows],
            dones=self.dones[rows],
            truncated=self.truncated[rows],
            final_observations=select(self.final_observations, rows),
            episode_steps=self.episode_steps[rows],
            pending=np.arange(self.pos)[:, None] >= self.start,
            action_masks=None if self.action_masks is None else self.action_masks[rows],
            final_action_masks=None if self.final_action_masks is None else self.final_action_masks[rows],
        )

    def mark_trained(self, n_trained: np.ndarray) -> None:
        """
        Record that the algorithm trained on the first ``n_trained[env]`` pending transitions of each env, and drop the
        rows that no env needs any more.

        :param n_trained: a count per env, shape (n_envs,)
        """
        if self.n_envs == 1:
            # (Python ints: NumPy's calls on one-element arrays cost more than the rest of this, at every env step of
            # the per-step mode)
            start = int(self.start[0]) + int(n_trained[0])
            self.start[0] = start
            self._drop_rows(start)
            return
        self.start = self.start + n_trained
        self._drop_rows(int(self.start.min()))

    def _drop_rows(self, n_rows: int) -> None:
        if n_rows == 0:
            return
        for array in self._stored_arrays:
            array[: self.pos - n_rows] = array[n_rows : self.pos]
        self.pos -= n_rows
        self.start -= n_rows

    def _grow(self) -> None:
        old = self._arrays()
        self._allocate(2 * self.buffer_size)
        for new_array, old_array in zip(self._arrays(), old, strict=True):
            new_array[: self.pos] = old_array[: self.pos]

    def _arrays(self) -> list[np.ndarray]:
        arrays = [self.actions, self.rewards, self.dones, self.truncated, self.episode_steps]
        if self.action_masks is not None and self.final_action_masks is not None:
            arrays += [self.action_masks, self.final_action_masks]
        for observations in (self.observations, self.final_observations):
            arrays += list(observations.values()) if isinstance(observations, dict) else [observations]
        return arrays

    def _get_samples(self, batch_inds: np.ndarray, env: Any = None) -> Any:
        raise NotImplementedError("TrajectoryBuffer is read whole with get(): its algorithms train on every transition")
