"""
The book's example tasks, registered with Gymnasium when ``sb3_classic`` is imported:

- ``sb3_classic/ShortCorridor-v0``: the short corridor with switched actions (Example 13.1, Figs 13.1–13.2), no time
  limit (``ShortCorridorEnv``);
- ``sb3_classic/RandomWalk19-v0``: the 19-state random walk (Example 7.1, Fig 7.2), one action, one-hot observations
  (``RandomWalkEnv``);
- ``sb3_classic/MountainCarNoLimit-v0``: Gymnasium's ``MountainCar-v0`` (Example 10.1, Figs 10.1–10.4, same dynamics
  and start) without its 200-step time limit, as in the book. ``gym.make("MountainCar-v0", max_episode_steps=-1)``
  does the same without this package (``max_episode_steps=None`` keeps the registered 200 steps).
"""

import gymnasium as gym

from sb3_classic.envs.random_walk import RANDOM_WALK_19_TRUE_VALUES, RandomWalkEnv, random_walk_true_values
from sb3_classic.envs.short_corridor import (
    SHORT_CORRIDOR_OPTIMAL_P_RIGHT,
    SHORT_CORRIDOR_OPTIMAL_VALUE,
    ShortCorridorEnv,
    short_corridor_start_value,
)

#: Gymnasium's keyword arguments of each registered id
ENV_SPECS: dict[str, dict[str, object]] = {
    "sb3_classic/ShortCorridor-v0": dict(entry_point="sb3_classic.envs.short_corridor:ShortCorridorEnv"),
    "sb3_classic/RandomWalk19-v0": dict(entry_point="sb3_classic.envs.random_walk:RandomWalkEnv", kwargs=dict(n_states=19)),
    "sb3_classic/MountainCarNoLimit-v0": dict(
        entry_point="gymnasium.envs.classic_control.mountain_car:MountainCarEnv", max_episode_steps=None
    ),
}
ENV_IDS = tuple(ENV_SPECS)


def register_envs() -> None:
    """Register the ids of ``ENV_SPECS`` with Gymnasium; ids already registered are left as they are."""
    for env_id, spec in ENV_SPECS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, **spec)  # type: ignore[arg-type]


register_envs()

__all__ = [
    "ENV_IDS",
    "RANDOM_WALK_19_TRUE_VALUES",
    "SHORT_CORRIDOR_OPTIMAL_P_RIGHT",
    "SHORT_CORRIDOR_OPTIMAL_VALUE",
    "RandomWalkEnv",
    "ShortCorridorEnv",
    "random_walk_true_values",
    "register_envs",
    "short_corridor_start_value",
]
