"""
A user's own env, as a study names it: ``env: chain_env:ShortChain-v0``. Importing this module registers it (Gymnasium's
``module:EnvId`` form imports the module); the study runner imports it in every process that builds the env.

A chain of ``length`` states: action 1 moves right, action 0 left (the left end stays), −1 per step, and the episode
ends at the right end; the time limit is 20 steps. The best return is −(length − 1); a uniformly random policy's is
lower (it walks back and forth).
"""

from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces


class ShortChain(gymnasium.Env[np.ndarray, np.int64]):
    """
    :param length: states of the chain (at least 2)
    """

    def __init__(self, length: int = 4):
        if length < 2:
            raise ValueError(f"length={length}: a chain has at least 2 states")
        self.length = length
        self.observation_space = spaces.Box(0.0, 1.0, (length,), np.float32)
        self.action_space = spaces.Discrete(2)
        self.position = 0

    def _observation(self) -> np.ndarray:
        observation = np.zeros(self.length, np.float32)
        observation[self.position] = 1.0
        return observation

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self.position = 0
        return self._observation(), {}

    def step(self, action: np.int64) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        self.position = min(self.position + 1, self.length - 1) if action == 1 else max(self.position - 1, 0)
        return self._observation(), -1.0, self.position == self.length - 1, False, {}


gymnasium.register(id="ShortChain-v0", entry_point="chain_env:ShortChain", max_episode_steps=20)
