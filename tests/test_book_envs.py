"""The book's example envs: dynamics, values, Gymnasium's and SB3's env checkers, registration."""

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gymnasium_check_env
from gymnasium.wrappers import TimeLimit
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import sb3_classic
from sb3_classic.envs import (
    ENV_IDS,
    RANDOM_WALK_19_TRUE_VALUES,
    SHORT_CORRIDOR_OPTIMAL_P_RIGHT,
    SHORT_CORRIDOR_OPTIMAL_VALUE,
    RandomWalkEnv,
    ShortCorridorEnv,
    random_walk_true_values,
    register_envs,
    short_corridor_start_value,
)

# --- Registration and checkers -----------------------------------------------------------------------------------------


def test_ids_are_registered_by_importing_the_package() -> None:
    assert sb3_classic.envs.ENV_IDS == (
        "sb3_classic/ShortCorridor-v0",
        "sb3_classic/RandomWalk19-v0",
        "sb3_classic/MountainCarNoLimit-v0",
    )
    specs = [gym.spec(env_id) for env_id in ENV_IDS]
    register_envs()  # a second registration leaves them as they are, without Gymnasium's "Overriding" warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        register_envs()
    assert [gym.spec(env_id) for env_id in ENV_IDS] == specs
    assert isinstance(gym.make("sb3_classic/ShortCorridor-v0").unwrapped, ShortCorridorEnv)
    assert isinstance(gym.make("sb3_classic/RandomWalk19-v0").unwrapped, RandomWalkEnv)


def wrappers(env: gym.Env) -> list[type]:
    chain = []
    while isinstance(env, gym.Wrapper):
        chain.append(type(env))
        env = env.env
    return chain


def has_time_limit(env: gym.Env) -> bool:
    """:return: whether ``env`` is wrapped in a ``TimeLimit`` (once rl_zoo3 is imported: its ``PatchedTimeLimit``)"""
    return any(issubclass(wrapper, TimeLimit) for wrapper in wrappers(env))


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_no_time_limit(env_id: str) -> None:
    # As in the book: no TimeLimit wrapper, and Gymnasium's registry keeps max_episode_steps=None
    assert gym.spec(env_id).max_episode_steps is None
    env = gym.make(env_id)
    assert not has_time_limit(env)
    # gym.make(id, max_episode_steps=N) adds one when evaluation needs it (a deterministic short-corridor policy); once
    # rl_zoo3 is imported, it is the zoo's PatchedTimeLimit, a subclass
    assert has_time_limit(gym.make(env_id, max_episode_steps=50))


def test_mountain_car_runs_past_200_steps() -> None:
    env = gym.make("sb3_classic/MountainCarNoLimit-v0")
    assert gym.spec("sb3_classic/MountainCarNoLimit-v0").entry_point == gym.spec("MountainCar-v0").entry_point
    env.reset(seed=0)
    for _ in range(1000):  # never pushing, the car never reaches the goal; nothing cuts the episode
        _, reward, terminated, truncated, _ = env.step(1)
        assert (reward, terminated, truncated) == (-1.0, False, False)
    # Gymnasium's own id keeps its 200 steps even with max_episode_steps=None; -1 removes them
    assert has_time_limit(gym.make("MountainCar-v0", max_episode_steps=None))
    assert not has_time_limit(gym.make("MountainCar-v0", max_episode_steps=-1))


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_gymnasium_and_sb3_env_checkers_pass(env_id: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # neither checker warns about anything
        # No rendering to check: the book's envs offer none, and MountainCar's needs pygame and a display
        gymnasium_check_env(gym.make(env_id).unwrapped, skip_render_check=True)
        sb3_check_env(gym.make(env_id))


# --- Short corridor (Example 13.1) ------------------------------------------------------------------------------------


def test_short_corridor_dynamics() -> None:
    env = ShortCorridorEnv()
    left, right = ShortCorridorEnv.LEFT, ShortCorridorEnv.RIGHT
    assert (left, right) == (0, 1)
    assert env.action_space == gym.spaces.Discrete(2)
    observation, info = env.reset(seed=0)
    np.testing.assert_array_equal(observation, np.ones(1, dtype=np.float32))
    assert observation.dtype == np.float32
    assert info == {"state": 0}
    # (state, action) → next state: left in s0 stays, s1 is switched, right in s2 reaches the goal (3)
    transitions = {(0, left): 0, (0, right): 1, (1, left): 2, (1, right): 0, (2, left): 1, (2, right): 3}
    for (state, action), expected in transitions.items():
        env.state = state
        observation, reward, terminated, truncated, info = env.step(action)
        assert info["state"] == expected
        assert reward == -1.0
        assert terminated == (expected == 3)
        assert not truncated
        np.testing.assert_array_equal(observation, [1.0])  # the state is not observed
    # The shortest path: right, left (switched), right
    env.reset()
    outcomes = [env.step(action)[1:3] for action in (right, left, right)]
    assert outcomes == [(-1.0, False), (-1.0, False), (-1.0, True)]
    with pytest.raises(RuntimeError, match="reset"):
        env.step(right)
    with pytest.raises(ValueError, match="action=2"):
        ShortCorridorEnv().step(2)


def exact_start_value(p_right: float) -> float:
    """v_π(s0) from the linear equations v = r + P v (γ = 1) built by stepping the env from each state."""
    env = ShortCorridorEnv()
    n = ShortCorridorEnv.N_STATES
    transition_matrix, rewards = np.zeros((n, n)), np.zeros(n)
    for state in range(n):
        for action, probability in ((ShortCorridorEnv.RIGHT, p_right), (ShortCorridorEnv.LEFT, 1 - p_right)):
            env.state = state
            _, reward, terminated, _, info = env.step(action)
            rewards[state] += probability * reward
            if not terminated:
                transition_matrix[state, info["state"]] += probability
    return float(np.linalg.solve(np.eye(n) - transition_matrix, rewards)[0])


def test_short_corridor_values() -> None:
    # Example 13.1: the best stochastic policy goes right with probability 2 − √2 and has v*(s0) = −(6 + 4√2) ≈ −11.66
    assert abs(SHORT_CORRIDOR_OPTIMAL_P_RIGHT - 0.5858) < 1e-4
    assert abs(SHORT_CORRIDOR_OPTIMAL_VALUE - -11.657) < 1e-3
    assert exact_start_value(SHORT_CORRIDOR_OPTIMAL_P_RIGHT) == pytest.approx(SHORT_CORRIDOR_OPTIMAL_VALUE, abs=1e-9)
    for p_right in (0.05, 0.3, 0.5, 0.9, 0.95):
        assert exact_start_value(p_right) == pytest.approx(short_corridor_start_value(p_right), rel=1e-9)
        assert short_corridor_start_value(p_right) < SHORT_CORRIDOR_OPTIMAL_VALUE
    # Fig 13.1's curve has its maximum there
    grid = np.linspace(0.01, 0.99, 981)
    best = grid[np.argmax([short_corridor_start_value(p) for p in grid])]
    assert best == pytest.approx(2 - math.sqrt(2), abs=1e-3)
    assert short_corridor_start_value(0.0) == short_corridor_start_value(1.0) == -math.inf
    with pytest.raises(ValueError, match=r"p_right=1\.5"):
        short_corridor_start_value(1.5)


def test_short_corridor_monte_carlo_value() -> None:
    # The mean return of the registered env under P(right) = 2 − √2, within 4 standard errors of v*(s0)
    env = gym.make("sb3_classic/ShortCorridor-v0")
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    returns = []
    for _ in range(3000):
        env.reset()
        episode_return, terminated = 0.0, False
        while not terminated:
            action = int(rng.random() < SHORT_CORRIDOR_OPTIMAL_P_RIGHT)
            _, reward, terminated, _, _ = env.step(action)
            episode_return += float(reward)
        returns.append(episode_return)
    standard_error = np.std(returns) / np.sqrt(len(returns))
    assert 0.05 < standard_error < 0.5
    assert abs(np.mean(returns) - SHORT_CORRIDOR_OPTIMAL_VALUE) < 4 * standard_error


# --- Random walk (Example 7.1) ----------------------------------------------------------------------------------------


def test_random_walk_true_values() -> None:
    np.testing.assert_allclose(RANDOM_WALK_19_TRUE_VALUES, [(s - 10) / 10 for s in range(1, 20)], atol=1e-15)
    assert RANDOM_WALK_19_TRUE_VALUES[9] == 0.0
    assert not RANDOM_WALK_19_TRUE_VALUES.flags.writeable
    np.testing.assert_allclose(random_walk_true_values(5), [-2 / 3, -1 / 3, 0, 1 / 3, 2 / 3], atol=1e-15)


def test_random_walk_dynamics() -> None:
    env = gym.make("sb3_classic/RandomWalk19-v0")
    assert env.action_space == gym.spaces.Discrete(1)
    assert env.observation_space == gym.spaces.Box(0.0, 1.0, (19,), np.float32)
    observation, info = env.reset(seed=0)
    assert info == {"state": 10}
    np.testing.assert_array_equal(observation, np.eye(19, dtype=np.float32)[9])
    n_episodes, exits = 400, {0: 0, 20: 0}
    lengths = []
    for _ in range(n_episodes):
        state, length, terminated = 10, 0, False
        while not terminated:
            observation, reward, terminated, truncated, info = env.step(0)
            length += 1
            assert not truncated
            assert abs(info["state"] - state) == 1  # one step left or right
            state = info["state"]
            if terminated:
                assert state in (0, 20)
                assert reward == (-1.0 if state == 0 else 1.0)
                np.testing.assert_array_equal(observation, np.zeros(19, dtype=np.float32))
                exits[state] += 1
            else:
                assert reward == 0.0
                np.testing.assert_array_equal(observation, np.eye(19, dtype=np.float32)[state - 1])
        lengths.append(length)
        observation, info = env.reset()
        assert info == {"state": 10}
    # Symmetric walk from the middle: each exit half the time; expected length 10 · 10 = 100 steps
    assert abs(exits[20] - n_episodes / 2) < 3 * math.sqrt(n_episodes / 4)
    assert abs(np.mean(lengths) - 100) < 4 * np.std(lengths) / math.sqrt(n_episodes)


def test_random_walk_is_seeded() -> None:
    def walk(seed: int) -> list[int]:
        env = gym.make("sb3_classic/RandomWalk19-v0")
        env.reset(seed=seed)
        return [env.step(0)[4]["state"] for _ in range(8)]

    assert walk(3) == walk(3)
    assert walk(3) != walk(4)


@pytest.mark.parametrize("n_states", [0, 4, -3, 2.0, True])
def test_random_walk_bad_n_states(n_states: object) -> None:
    with pytest.raises(ValueError, match=f"n_states={n_states!r} must be an odd integer"):
        RandomWalkEnv(n_states)  # type: ignore[arg-type]
    # The true values of a walk the env refuses: they were [] for 0 and -3, and values of no walk for 4
    with pytest.raises(ValueError, match=f"n_states={n_states!r} must be an odd integer"):
        random_walk_true_values(n_states)  # type: ignore[arg-type]


def test_random_walk_takes_a_numpy_integer() -> None:
    env = RandomWalkEnv(np.int64(5))  # type: ignore[arg-type]
    assert env.observation_space.shape == (5,)
    assert env.start_state == 3


@pytest.mark.parametrize("env_id", ["sb3_classic/RandomWalk19-v0", "sb3_classic/ShortCorridor-v0"])
def test_the_algorithms_build_the_envs_by_id(env_id: str) -> None:
    """SB3 asks for render_mode="rgb_array" first and falls back on a TypeError: the ids work as a string."""
    from sb3_classic import REINFORCE, NStepSARSA

    for model_class in (NStepSARSA, REINFORCE):
        model = model_class("MlpPolicy", env_id, seed=0, device="cpu")
        assert model.get_env() is not None
        model.learn(50)
