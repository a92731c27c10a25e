"""The 19-state random walk (Sutton & Barto Example 7.1, Fig 7.2) as a one-action task."""

from typing import Any

import numpy as np
from gymnasium import Env, spaces


def _check_n_states(n_states: int) -> None:
    """:raises ValueError: unless ``n_states`` is an odd integer >= 1 (the walk starts in the middle state)"""
    if isinstance(n_states, bool) or not isinstance(n_states, int | np.integer) or n_states < 1 or n_states % 2 == 0:
        raise ValueError(f"n_states={n_states!r} must be an odd integer >= 1 (19 in Example 7.1), so that it has a middle")


def random_walk_true_values(n_states: int = 19) -> np.ndarray:
    """
    The true values of the random walk with rewards −1 at the left exit and +1 at the right (γ = 1): v(s) is
    P(right exit) − P(left exit) = 2s/(n + 1) − 1. For the 19 states of Example 7.1: v(s) = (s − 10)/10,
    i.e. −0.9, −0.8, …, 0.9.

    :param n_states: number of non-terminal states n (odd, as ``RandomWalkEnv``'s)
    :return: v(1), …, v(n), shape (n_states,), float64 (index s − 1 holds state s)
    :raises ValueError: for a count ``RandomWalkEnv`` refuses
    """
    _check_n_states(n_states)
    states = np.arange(1, n_states + 1)
    return 2 * states / (n_states + 1) - 1


#: v(1), …, v(19) of Example 7.1, (s − 10)/10: the reference of Fig 7.2's RMS error
RANDOM_WALK_19_TRUE_VALUES = random_walk_true_values(19)
RANDOM_WALK_19_TRUE_VALUES.setflags(write=False)


class RandomWalkEnv(Env[np.ndarray, np.int64]):
    """
    The random walk of Sutton & Barto Example 7.1 (19 states, Fig 7.2; §6.2's walk has 5 and other rewards): states
    1…n in a row, episodes start in the middle ((n + 1)/2, state 10 of 19), and each step moves left or right with
    probability ½ each (drawn from the env's seeded ``np_random``). Leaving on the left (state 0) ends the episode
    with reward −1, on the right (state n + 1) with +1; every other reward is 0 (γ = 1).

    There is one action (Discrete(1), ignored), so that an action-value method on this env estimates the state values:
    n-step SARSA is then n-step TD (§7.1–7.2). The observation is the one-hot vector of the state (Box [0, 1],
    shape (n,), float32), so a linear q̂ without bias is the tabular estimate: its weight i is V(i + 1). The
    observation after an exit is all zeros (the terminal state's value is 0). ``info["state"]`` is the state number
    (0 or n + 1 after an exit). ``random_walk_true_values`` gives the values to measure the RMS error against.

    :param n_states: number of non-terminal states (odd, so that there is a middle)
    :param render_mode: no rendering is offered; only None
    """

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012 (gymnasium's class attribute)

    def __init__(self, n_states: int = 19, render_mode: str | None = None) -> None:
        _check_n_states(n_states)
        if render_mode is not None:
            # A TypeError, as for an argument the env does not take: SB3's maybe_make_env asks for "rgb_array" and
            # falls back to gym.make(env_id) on it, so that NStepSARSA("MlpPolicy", env_id) works
            raise TypeError(f"render_mode={render_mode!r}: RandomWalkEnv has no rendering, pass None")
        self.n_states = int(n_states)
        self.start_state = (self.n_states + 1) // 2
        self.observation_space = spaces.Box(0.0, 1.0, shape=(n_states,), dtype=np.float32)
        self.action_space = spaces.Discrete(1)
        self.state = self.start_state

    def _observation(self) -> np.ndarray:
        observation = np.zeros(self.n_states, dtype=np.float32)
        if 1 <= self.state <= self.n_states:
            observation[self.state - 1] = 1.0
        return observation

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self.state = self.start_state
        return self._observation(), {"state": self.state}

    def step(self, action: np.int64 | int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if not self.action_space.contains(action):
            raise ValueError(f"action={action!r} must be 0, the only action")
        if not 1 <= self.state <= self.n_states:
            raise RuntimeError("the episode has ended: call reset() before step()")
        self.state += 1 if self.np_random.random() < 0.5 else -1
        reward = -1.0 if self.state == 0 else 1.0 if self.state == self.n_states + 1 else 0.0
        terminated = not 1 <= self.state <= self.n_states
        return self._observation(), reward, terminated, False, {"state": self.state}
