"""
What the algorithms actually train on, over whole ``learn()`` runs: with the weights frozen, every transition of
the logged trajectories must be trained exactly once, towards the book's target computed on the full log. This
covers what the pure functions cannot: episodes and n-step windows spanning rollouts, several envs ending
episodes at different times, rollouts shorter than n, time-limit truncations.
"""

import warnings
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from reference import episodes_of, reference_lambda_targets, reference_mc_returns, reference_nstep_targets
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env

from sb3_classic import REINFORCE, NStepSARSA
from sb3_classic.common.buffers import TrainingBatch
from sb3_classic.common.on_policy_algorithm import ClassicOnPolicyAlgorithm
from sb3_classic.common.returns import epsilon_greedy_expectation


class TrajectoryLog(BaseCallback):
    """Records every step the algorithm takes, from the locals of its rollout loop."""

    def _on_training_start(self) -> None:
        self.observations = [self.model._last_obs.copy()]  # type: ignore[union-attr]
        self.actions: list[np.ndarray] = []
        self.rewards: list[np.ndarray] = []
        self.dones: list[np.ndarray] = []
        self.truncated: list[np.ndarray] = []
        self.final_observations: dict[tuple[int, int], np.ndarray] = {}

    def _on_step(self) -> bool:
        t = len(self.actions)
        self.actions.append(self.locals["actions"].copy())
        self.rewards.append(self.locals["rewards"].copy())
        self.dones.append(self.locals["dones"].copy())
        self.observations.append(self.locals["new_obs"].copy())
        truncated = np.zeros_like(self.locals["dones"])
        for env, info in enumerate(self.locals["infos"]):
            if info.get("TimeLimit.truncated", False):
                truncated[env] = True
                self.final_observations[(t, env)] = info["terminal_observation"]
        self.truncated.append(truncated)
        return True

    def arrays(self) -> dict[str, np.ndarray]:
        return dict(
            observations=np.array(self.observations[:-1]),
            actions=np.array(self.actions),
            rewards=np.array(self.rewards, dtype=np.float32),
            dones=np.array(self.dones),
            truncated=np.array(self.truncated),
        )


def frozen_run(model: ClassicOnPolicyAlgorithm, total_timesteps: int) -> tuple[TrajectoryLog, list[TrainingBatch]]:
    """Learn with every optimizer step disabled, recording the trajectories and each update's batch."""
    for name in model._get_torch_save_params()[0][1:]:
        optimizer = model.policy.optimizer if name == "policy.optimizer" else getattr(model.policy, name.split(".")[1])
        optimizer.step = lambda *args, **kwargs: None  # type: ignore[method-assign]
    batches: list[TrainingBatch] = []
    make_batch = model._training_batch  # type: ignore[attr-defined]

    def spy() -> TrainingBatch | None:
        batch = make_batch()
        if batch is not None:
            batches.append(batch)
        return batch

    model._training_batch = spy  # type: ignore[attr-defined]
    log = TrajectoryLog()
    model.learn(total_timesteps, callback=log)
    return log, batches


def short_cartpole_env(n_envs: int, seed: int) -> Any:
    # A 12-step time limit gives a mix of terminations and truncations
    return make_vec_env(lambda: gym.make("CartPole-v1", max_episode_steps=12), n_envs=n_envs, seed=seed)


def assert_same_rows(actual: list[np.ndarray], expected: list[np.ndarray]) -> None:
    """The same multiset of rows (value tuples), up to float32 rounding."""

    def sorted_rows(columns: list[np.ndarray]) -> np.ndarray:
        rows = np.stack([np.asarray(column, dtype=np.float64) for column in columns], axis=1)
        return rows[np.lexsort(rows.T[::-1])]

    assert len(actual[0]) == len(expected[0])
    np.testing.assert_allclose(sorted_rows(actual), sorted_rows(expected), rtol=1e-4, atol=1e-4)


@pytest.mark.parametrize(
    ("n_steps", "train_freq", "n_envs", "expected_sarsa", "update_mode", "td_lambda"),
    [
        (4, 3, 3, False, "batch", 1.0),
        (1, 1, 1, False, "batch", 1.0),
        (6, 2, 2, True, "batch", 1.0),
        (3, 10, 2, False, "batch", 1.0),
        # One env, an update every step: the book's loop, whose batches are built without the whole-buffer arrays
        (4, 1, 1, True, "per_step", 1.0),
        (3, 1, 1, False, "per_step", 1.0),
        # Truncated λ-returns G^λ_{t:t+n} (S&B eq. 12.9) instead of G_{t:t+n}
        (4, 3, 3, False, "batch", 0.5),
        (6, 2, 2, True, "batch", 0.8),
        (3, 1, 1, False, "per_step", 0.3),
    ],
)
def test_sarsa_trains_every_transition_once_on_its_full_nstep_target(
    n_steps: int, train_freq: int, n_envs: int, expected_sarsa: bool, update_mode: str, td_lambda: float
) -> None:
    epsilon, gamma = 0.3, 0.9
    model = NStepSARSA(
        "MlpPolicy",
        short_cartpole_env(n_envs, seed=1),
        n_steps=n_steps,
        train_freq=train_freq,
        update_mode=update_mode,
        gamma=gamma,
        expected_sarsa=expected_sarsa,
        td_lambda=td_lambda,
        exploration_initial_eps=epsilon,
        exploration_final_eps=epsilon,
        seed=1,
        device="cpu",
    )
    log, batches = frozen_run(model, total_timesteps=300)
    traj = log.arrays()

    def q_values(obs: np.ndarray) -> np.ndarray:
        with th.no_grad():
            return model.policy.q_net(th.as_tensor(obs)).numpy()

    q_all = q_values(traj["observations"].reshape(-1, 4)).reshape(*traj["rewards"].shape, -1)
    q_taken = np.take_along_axis(q_all, traj["actions"][..., None], axis=-1)[..., 0]
    final_values = np.zeros_like(traj["rewards"])
    for (t, env), final_obs in log.final_observations.items():
        final_values[t, env] = epsilon_greedy_expectation(q_values(final_obs[None])[0], epsilon)
    # The reference bootstraps from "q̂(S_{t+n}, A_{t+n})": for Expected SARSA, that is V̄(S_{t+n})
    bootstrap = epsilon_greedy_expectation(q_all, epsilon) if expected_sarsa else q_taken
    reference_traj = dict(traj, q_taken=bootstrap, final_values=final_values)

    expected_q, expected_targets = [], []
    for env in range(n_envs):
        if td_lambda < 1.0:
            references = reference_lambda_targets(reference_traj, env, gamma, n_steps, td_lambda)
        else:
            references = reference_nstep_targets(reference_traj, env, gamma, n_steps)
        for t, target in references.items():
            expected_q.append(q_taken[t, env])
            expected_targets.append(target)
    assert expected_targets, "the run must produce complete targets"

    trained_q = np.concatenate(
        [
            model.policy.q_net(th.as_tensor(b.observations))
            .gather(1, th.as_tensor(b.actions)[:, None])
            .flatten()
            .detach()
            .numpy()
            for b in batches
        ]
    )
    trained_targets = np.concatenate([b.targets for b in batches])
    assert_same_rows([trained_q, trained_targets], [np.array(expected_q), np.array(expected_targets)])


@pytest.mark.parametrize(("n_episodes", "n_envs"), [(1, 1), (2, 3), (5, 2)])
def test_reinforce_trains_every_step_of_each_episode_once_on_its_return(n_episodes: int, n_envs: int) -> None:
    gamma = 0.9
    model = REINFORCE(
        "MlpPolicy", short_cartpole_env(n_envs, seed=2), n_episodes=n_episodes, gamma=gamma, seed=2, device="cpu"
    )
    log, batches = frozen_run(model, total_timesteps=400)
    traj = log.arrays()

    def values(obs: np.ndarray) -> np.ndarray:
        with th.no_grad():
            return model.policy.predict_values(th.as_tensor(obs)).flatten().numpy()

    state_values = values(traj["observations"].reshape(-1, 4)).reshape(traj["rewards"].shape)
    final_values = np.zeros_like(traj["rewards"])
    for (t, env), final_obs in log.final_observations.items():
        final_values[t, env] = values(final_obs[None])[0]
    reference_traj = dict(traj, final_values=final_values)

    expected = []
    for env in range(n_envs):
        returns = reference_mc_returns(reference_traj, env, gamma)
        for first, last, ended in episodes_of(traj["dones"][:, env]):
            expected += [(state_values[t, env], returns[t], t - first) for t in range(first, last + 1) if ended]
    assert sum(step == 0 for *_, step in expected) >= 3, "the run must end several episodes"

    trained = [
        (values_, returns_, steps)
        for batch in batches
        for values_, returns_, steps in zip(
            model.policy.predict_values(th.as_tensor(batch.observations)).flatten().detach().numpy(),
            batch.targets,
            batch.episode_steps,
            strict=True,
        )
    ]
    # Each update uses at least n_episodes complete episodes, and every step of each ended episode exactly once
    assert all((batch.episode_steps == 0).sum() >= n_episodes for batch in batches)
    assert_same_rows(list(map(np.array, zip(*trained, strict=True))), list(map(np.array, zip(*expected, strict=True))))


def test_reinforce_cuts_an_episode_that_never_ends() -> None:
    class Endless(gym.Env):
        observation_space = gym.spaces.Box(-1.0, 1.0, (2,))
        action_space = gym.spaces.Discrete(2)

        def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
            super().reset(seed=seed)
            return np.zeros(2, dtype=np.float32), {}

        def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict]:
            return self.observation_space.sample(), 1.0, False, False, {}

    model = REINFORCE("MlpPolicy", Endless(), max_episode_length=50, seed=0, device="cpu")
    with pytest.warns(UserWarning, match="max_episode_length=50"):
        model.learn(1_000)
    # Cut into 50-step episodes and trained on: the buffer never held more than one of them
    assert model._n_updates == 1_000 // 50
    assert model.rollout_buffer.buffer_size <= 1024
    # The env goes on from where the cut left it in the next learn(): no reset, no warning about a file (the cut was
    # taken for an episode missing from the buffer, as after load(force_reset=False))
    resets: list[int] = []
    reset = model.env.reset  # type: ignore[union-attr]

    def counted_reset() -> Any:
        resets.append(1)
        return reset()

    model.env.reset = counted_reset  # type: ignore[method-assign, union-attr]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=".*max_episode_length")
        model.learn(100, reset_num_timesteps=False)
    assert resets == []
