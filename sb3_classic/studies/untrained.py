"""
The return of a policy that has learned nothing on a study's env: a uniformly random policy's, measured over
``EPISODES`` episodes of the env (with the variant's ``env_kwargs``), each seeded by its index, and cached with the
study's runs. A verdict between variants none of which rose above it compares runs that did not measurably learn, and
the study's outputs say so beside it (``stats.untrained_note``).
"""

import hashlib
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np

from sb3_classic.harness.common import env_spec, split_env_id

#: Episodes of the random policy (seeds 0 to EPISODES − 1)
EPISODES = 100
#: The measurement stops at the end of the episode that passes this many env steps (an env with a long time limit)
MAX_STEPS = 20_000
#: The cache's folder of the measurements
FOLDER = "untrained"


def random_returns(env_id: str, env_kwargs: Mapping[str, Any] | None = None, episodes: int = EPISODES) -> np.ndarray | None:
    """
    :param env_id: a Gymnasium env id, or ``module:EnvId``
    :param env_kwargs: the env's keyword arguments (a study's ``env_kwargs``)
    :param episodes: how many episodes, episode ``k`` reset with seed ``k`` and its actions drawn from the action space
        seeded with ``k``
    :return: the return of each episode of a uniformly random policy (the action space's ``sample()``), or None for
        an env without a time limit (an episode of a random policy may never end)
    """
    kwargs = dict(env_kwargs or {})
    spec = env_spec(env_id)
    if spec.max_episode_steps is None and kwargs.get("max_episode_steps") is None:
        return None
    env = gymnasium.make(split_env_id(env_id)[1], **kwargs)
    returns, steps = [], 0
    try:
        for episode in range(episodes):
            env.reset(seed=episode)
            env.action_space.seed(episode)
            total, done = 0.0, False
            while not done:
                _, reward, terminated, truncated, _ = env.step(env.action_space.sample())
                total += float(reward)
                steps += 1
                done = terminated or truncated
            returns.append(total)
            if steps >= MAX_STEPS:
                break
    finally:
        env.close()
    return np.array(returns)


def cached_random_returns(cache_dir: Path, env_id: str, env_kwargs: Mapping[str, Any] | None = None) -> np.ndarray | None:
    """
    ``random_returns``, measured once and kept in ``cache_dir/untrained/`` (the key: the env's id and keyword
    arguments, the episodes and Gymnasium's version; an env of one's own is not read: give it a new version,
    ``Chain-v1``, when it changes, as Gymnasium's ids do).

    :param cache_dir: the study's cache
    :param env_id: a Gymnasium env id, or ``module:EnvId``
    :param env_kwargs: the env's keyword arguments
    :return: the returns, or None (see ``random_returns``)
    """
    content = {
        "env_id": env_id,
        "env_kwargs": dict(env_kwargs or {}),
        "episodes": EPISODES,
        "max_steps": MAX_STEPS,
        "policy": "uniformly random",
        "gymnasium": gymnasium.__version__,
    }
    key = hashlib.sha256(json.dumps(content, sort_keys=True, default=repr).encode()).hexdigest()[:16]
    path = cache_dir / FOLDER / f"{split_env_id(env_id)[1]}-{key}.json"
    try:
        returns = json.loads(path.read_text())["returns"]
        return None if returns is None else np.asarray(returns, dtype=float)
    except (OSError, ValueError, KeyError, TypeError):
        pass  # not measured yet, or a damaged file: measured again
    measured = random_returns(env_id, env_kwargs)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f"{path.name}.{os.getpid()}.partial")
    partial.write_text(json.dumps({**content, "returns": None if measured is None else measured.tolist()}, indent=1) + "\n")
    partial.replace(path)
    return measured
