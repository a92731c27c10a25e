"""The short corridor with switched actions (Sutton & Barto Example 13.1, Fig 13.1)."""

import math
from typing import Any

import numpy as np
from gymnasium import Env, spaces

#: Probability of "right" of the best stochastic policy, 2 − √2 ≈ 0.586 (Example 13.1)
SHORT_CORRIDOR_OPTIMAL_P_RIGHT = 2 - math.sqrt(2)
#: Its value from the start state, v*(s0) = −(6 + 4√2) ≈ −11.657 (Example 13.1, Fig 13.1)
SHORT_CORRIDOR_OPTIMAL_VALUE = -(6 + 4 * math.sqrt(2))


def short_corridor_start_value(p_right: float) -> float:
    r"""
    The value :math:`v_\pi(s_0)` of the start state under the policy that goes right with probability ``p_right`` in
    every state (the curve of Fig 13.1): solving :math:`v_0 = -1 + p v_1 + (1 - p) v_0`,
    :math:`v_1 = -1 + p v_0 + (1 - p) v_2`, :math:`v_2 = -1 + (1 - p) v_1` gives
    :math:`v_\pi(s_0) = 2(p - 2) / (p(1 - p))`, largest at :math:`p = 2 - \sqrt 2` where it is
    :math:`-(6 + 4\sqrt 2)`.

    :param p_right: probability of action "right", in [0, 1]
    :return: :math:`v_\pi(s_0)` (γ = 1), −inf at p = 0 or 1 (the goal is never reached)
    :raises ValueError: if ``p_right`` is not in [0, 1]
    """
    if not 0.0 <= p_right <= 1.0:
        raise ValueError(f"p_right={p_right!r} must be a probability in [0, 1]")
    if p_right in (0.0, 1.0):
        return -math.inf
    return 2 * (p_right - 2) / (p_right * (1 - p_right))


class ShortCorridorEnv(Env[np.ndarray, np.int64]):
    r"""
    The short corridor with switched actions (Sutton & Barto Example 13.1): three non-terminal states s0, s1, s2 in a
    row and the goal (terminal) to the right of s2. Every step gives reward −1 (γ = 1 in the book). In s0 "left" does
    not move; in s1 the actions are switched ("right" moves left, "left" moves right). Episodes start in s0.

    The state is not observed: as in the book, where the features are x(s, right) = [1, 0] and x(s, left) = [0, 1] for
    every s, all states look alike. The observation is the constant 1.0 (Box [0, 1], shape (1,), float32), so a linear
    policy without bias has logits :math:`h(s, a, \boldsymbol\theta) = W[a, 0] \cdot 1`: the book's parameterisation
    with :math:`\boldsymbol\theta = (W[1, 0], W[0, 0]) = (\theta_\text{right}, \theta_\text{left})`,
    :math:`\pi(\text{right}) = \operatorname{softmax}(W)[1]` (eq. 13.2). A linear state-value baseline without bias is
    then one number, :math:`\hat v(s, w) = w`, the book's choice for Fig 13.2.

    Actions: Discrete(2), 0 = left, 1 = right. ``info["state"]`` is the true state (0, 1, 2, or 3 for the goal).

    There is no time limit, as in the book. A deterministic policy never reaches the goal (always right bounces
    between s0 and s1, always left stays in s0), so greedy evaluation needs one:
    ``gym.make("sb3_classic/ShortCorridor-v0", max_episode_steps=1000)``; REINFORCE's ``max_episode_length`` guards
    training the same way.

    :param render_mode: no rendering is offered; only None
    """

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012 (gymnasium's class attribute)

    LEFT = 0
    RIGHT = 1
    #: Number of non-terminal states; the goal is state ``N_STATES``
    N_STATES = 3
    #: The state whose actions are switched
    SWITCHED_STATE = 1

    def __init__(self, render_mode: str | None = None) -> None:
        if render_mode is not None:
            # A TypeError, as for an argument the env does not take: SB3's maybe_make_env asks for "rgb_array" and
            # falls back to gym.make(env_id) on it, so that NStepSARSA("MlpPolicy", env_id) works
            raise TypeError(f"render_mode={render_mode!r}: ShortCorridorEnv has no rendering, pass None")
        self.observation_space = spaces.Box(0.0, 1.0, shape=(1,), dtype=np.float32)
        self.action_space = spaces.Discrete(2)
        self.state = 0

    def _observation(self) -> np.ndarray:
        return np.ones(1, dtype=np.float32)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self.state = 0
        return self._observation(), {"state": self.state}

    def step(self, action: np.int64 | int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if not self.action_space.contains(action):
            raise ValueError(f"action={action!r} must be 0 (left) or 1 (right)")
        if self.state == self.N_STATES:
            raise RuntimeError("the episode has ended at the goal: call reset() before step()")
        move = 1 if int(action) == self.RIGHT else -1
        if self.state == self.SWITCHED_STATE:
            move = -move  # the second state reverses the actions
        self.state = max(0, self.state + move)  # "left" in s0 stays there
        terminated = self.state == self.N_STATES
        return self._observation(), -1.0, terminated, False, {"state": self.state}
