"""Invalid-action masking through sb3-contrib's interface, for both algorithms (the cases of sb3-contrib's own tests)."""

import functools
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from sb3_contrib.common.envs import InvalidActionEnvDiscrete, InvalidActionEnvMultiBinary, InvalidActionEnvMultiDiscrete
from sb3_contrib.common.maskable.callbacks import MaskableEvalCallback
from sb3_contrib.common.maskable.evaluation import evaluate_policy
from sb3_contrib.common.maskable.utils import get_action_masks
from sb3_contrib.common.wrappers import ActionMasker
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_classic import REINFORCE, NStepSARSA
from sb3_classic.common.returns import masked_epsilon_greedy_expectation
from sb3_classic.reinforce import REINFORCEPopulation
from sb3_classic.sarsa import NStepSARSAPopulation


class RefuseIllegalActions(gym.Wrapper):
    """Raises if the env is sent an action its mask does not allow."""

    def action_masks(self) -> np.ndarray:
        return np.asarray(self.env.get_wrapper_attr("action_masks")(), dtype=bool)

    def step(self, action: Any) -> Any:
        mask = self.action_masks()
        values = np.asarray(action).reshape(-1)
        space = self.action_space
        if isinstance(space, spaces.Discrete):
            entries = values - int(space.start)
        elif isinstance(space, spaces.MultiDiscrete):
            entries = np.cumsum([0, *space.nvec[:-1]]) + values
        else:
            entries = 2 * np.arange(len(values)) + values
        if not mask[entries].all():
            raise AssertionError(f"illegal action {action} for mask {mask.astype(int).tolist()}")
        return self.env.step(action)


def discrete_env() -> gym.Env:
    return RefuseIllegalActions(Monitor(InvalidActionEnvDiscrete(dim=6, ep_length=10, n_invalid_actions=4)))


def multi_discrete_env() -> gym.Env:
    return RefuseIllegalActions(Monitor(InvalidActionEnvMultiDiscrete(dims=[3, 4], ep_length=10, n_invalid_actions=3)))


def multi_binary_env() -> gym.Env:
    return RefuseIllegalActions(Monitor(InvalidActionEnvMultiBinary(dims=3, ep_length=10, n_invalid_actions=2)))


CASES = [
    (REINFORCE, dict(), discrete_env),
    (REINFORCE, dict(update_mode="per_step", use_baseline=False, ent_coef=0.01), discrete_env),
    (REINFORCE, dict(), multi_discrete_env),
    (REINFORCE, dict(), multi_binary_env),
    (NStepSARSA, dict(train_freq=4, gradient_steps=1), discrete_env),
    (NStepSARSA, dict(expected_sarsa=True, update_mode="per_step", train_freq=1, gradient_steps=1), discrete_env),
]
IDS = ["reinforce", "reinforce-per-step", "reinforce-multidiscrete", "reinforce-multibinary", "sarsa", "expected-sarsa"]


@pytest.mark.parametrize(("algo", "kwargs", "make_env"), CASES, ids=IDS)
def test_no_illegal_action_in_learn_predict_and_evaluation(algo: Any, kwargs: dict[str, Any], make_env: Any) -> None:
    eval_callback = MaskableEvalCallback(make_env(), eval_freq=100, n_eval_episodes=2, warn=False)
    model = algo("MlpPolicy", make_env(), seed=0, **kwargs).learn(300, callback=eval_callback)
    assert eval_callback.last_mean_reward > -np.inf
    env = make_env()
    obs, _ = env.reset(seed=1)
    for _ in range(30):
        for deterministic in (True, False):
            action, _ = model.predict(obs, action_masks=get_action_masks(env), deterministic=deterministic)
            assert env.action_space.contains(action)
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            obs, _ = env.reset()
    for deterministic in (True, False):
        evaluate_policy(model, make_env(), n_eval_episodes=3, deterministic=deterministic, warn=False)


@pytest.mark.parametrize("algo", [REINFORCE, NStepSARSA])
def test_vectorized_envs_and_action_masker(algo: Any) -> None:
    def legal_actions(env: Any) -> np.ndarray:
        return np.isin(np.arange(5), env.unwrapped.invalid_actions, invert=True)

    def make() -> gym.Env:
        # The masks from a function, through sb3-contrib's wrapper
        env = InvalidActionEnvDiscrete(dim=5, ep_length=8, n_invalid_actions=3)
        return RefuseIllegalActions(ActionMasker(env, legal_actions))

    vec_env = make_vec_env(make, n_envs=3, seed=0)
    model = algo("MlpPolicy", vec_env, seed=0).learn(200)
    evaluate_policy(model, vec_env, n_eval_episodes=4, warn=False)


@pytest.mark.parametrize("algo", [REINFORCE, NStepSARSA])
def test_without_masking_the_env_is_sent_illegal_actions(algo: Any) -> None:
    # The env of the tests above does refuse an action its mask does not allow
    model = algo("MlpPolicy", discrete_env(), seed=0)
    with pytest.raises(AssertionError, match="illegal action"):
        model.learn(300, use_masking=False)


def test_masked_epsilon_greedy_expectation_by_hand() -> None:
    q = np.array([[1.0, 5.0, 3.0, 2.0]], dtype=np.float32)
    mask = np.array([[True, False, True, True]])
    # (1 − ε) max over {1, 3, 2} + ε mean of {1, 3, 2}, the illegal 5 left out
    assert masked_epsilon_greedy_expectation(q, mask, 0.3)[0] == pytest.approx(0.7 * 3.0 + 0.3 * 2.0)
    assert masked_epsilon_greedy_expectation(q, mask, 0.0)[0] == pytest.approx(3.0)
    assert masked_epsilon_greedy_expectation(q, mask, 1.0)[0] == pytest.approx(2.0)


def test_masked_epsilon_greedy_probabilities() -> None:
    model = NStepSARSA("MlpPolicy", InvalidActionEnvDiscrete(dim=4, n_invalid_actions=1), seed=0)
    model.exploration_rate = 0.3
    n = 200_000
    mask = np.tile([True, False, True, True], (n, 1))
    actions = model._epsilon_greedy(np.full(n, 2), action_masks=mask)
    frequencies = np.bincount(actions, minlength=4) / n
    # π(a|s) = (1 − ε)·1[a greedy] + ε/|L(s)| for legal a, 0 for the illegal one
    assert frequencies[1] == 0.0
    np.testing.assert_allclose(frequencies, [0.1, 0.0, 0.7 + 0.1, 0.1], atol=0.005)


class StepMaskEnv(gym.Env):
    """
    Observation: the step within the episode (a float); 3 actions, whose legal ones depend on the step; reward 1; a
    time limit of 4 steps. The step's info reports the mask of the observation it returns.
    """

    observation_space = spaces.Box(-1.0, 10.0, shape=(1,))
    action_space = spaces.Discrete(3)
    MASKS = np.array(
        [[True, False, True], [False, True, True], [True, True, False], [False, False, True], [True, False, False]]
    )

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self.t = 0
        return self._obs(), {}

    def _obs(self) -> np.ndarray:
        return np.array([self.t], dtype=np.float32)

    def action_masks(self) -> np.ndarray:
        return self.MASKS[self.t]

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        assert self.MASKS[self.t][action], "illegal action"
        self.t += 1
        return self._obs(), 1.0, False, self.t == 4, {"action_mask": self.MASKS[self.t]}


def reference_expectation(q: np.ndarray, mask: np.ndarray, epsilon: float) -> float:
    """Σ_a π(a|s) q(s, a) with π written out action by action."""
    legal = np.flatnonzero(mask)
    greedy = legal[np.argmax(q[legal])]
    return sum(((1 - epsilon) * (a == greedy) + epsilon / len(legal)) * q[a] for a in legal)


@pytest.mark.parametrize("expected_sarsa", [False, True])
def test_sarsa_targets_follow_the_masks_of_the_bootstrap_states(expected_sarsa: bool) -> None:
    epsilon, gamma = 0.4, 0.9
    model = NStepSARSA(
        "MlpPolicy",
        StepMaskEnv(),
        n_steps=1,
        train_freq=8,
        gamma=gamma,
        expected_sarsa=expected_sarsa,
        exploration_schedule="linear",
        exploration_initial_eps=epsilon,
        exploration_final_eps=epsilon,
        seed=0,
    )
    # The policy's q̂ favours actions the masks make illegal, so that an unmasked target would differ
    output_layer = model.policy.q_net.q_net[-1]
    assert isinstance(output_layer, th.nn.Linear)
    with th.no_grad():
        output_layer.bias.copy_(th.tensor([0.0, 0.0, 50.0]))
    model._setup_masking(True)
    _, callback = model._setup_learn(8, None)
    assert model.env is not None
    model.collect_rollouts(model.env, callback, model.rollout_buffer)
    batch = model._training_batch()
    assert batch is not None
    q = model.policy.q_values(np.arange(5, dtype=np.float32).reshape(-1, 1))
    data = model.rollout_buffer.get()
    expected = []
    for row in range(len(batch.targets)):
        t = int(data.episode_steps[row, 0])
        if t == 3:  # the truncation: the final state's mask from its info, always the expectation
            expected.append(1.0 + gamma * reference_expectation(q[4], StepMaskEnv.MASKS[4], epsilon))
        elif expected_sarsa:
            expected.append(1.0 + gamma * reference_expectation(q[t + 1], StepMaskEnv.MASKS[t + 1], epsilon))
        else:
            next_action = int(data.actions[row + 1, 0])
            assert StepMaskEnv.MASKS[t + 1][next_action]
            expected.append(1.0 + gamma * q[t + 1, next_action])
    np.testing.assert_allclose(batch.targets, expected, rtol=1e-6)
    # The final state's only legal action is 0: its q̂ of 0 enters the bootstrap, not action 2's 50
    assert min(expected) < 1.0 + gamma * 50.0 * (1 - epsilon)


def test_reinforce_log_prob_has_no_gradient_for_masked_logits() -> None:
    model = REINFORCE("MlpPolicy", InvalidActionEnvDiscrete(dim=4, n_invalid_actions=2), seed=0)
    logits = th.tensor([[0.5, -1.0, 2.0, 0.3], [1.0, 1.0, 1.0, 1.0]], requires_grad=True)
    masks = th.tensor([[True, False, True, False], [False, True, True, True]])
    distribution = model.policy._masked_distribution(logits, masks)
    log_prob = distribution.log_prob(th.tensor([0, 3]))
    log_prob.sum().backward()
    assert logits.grad is not None
    assert (logits.grad[~masks] == 0).all()
    assert (logits.grad[masks] != 0).all()
    # ln π over the legal actions: log-soft-max of the legal logits
    assert log_prob[0].item() == pytest.approx(0.5 - np.log(np.exp(0.5) + np.exp(2.0)), rel=1e-6)
    assert log_prob[1].item() == pytest.approx(-np.log(3.0), rel=1e-6)
    # The entropy over the legal actions: ln 3 for three equal logits
    entropy = distribution.entropy()
    assert entropy is not None
    assert entropy[1].item() == pytest.approx(np.log(3.0), rel=1e-6)


def test_reinforce_update_uses_the_stored_masks() -> None:
    recorded: list[Any] = []

    class Recorder(BaseCallback):
        def _on_rollout_end(self) -> None:
            buffer: Any = self.model.rollout_buffer  # type: ignore[attr-defined]
            recorded.append(buffer.get().action_masks.copy())

        def _on_step(self) -> bool:
            return True

    env = discrete_env()
    model = REINFORCE("MlpPolicy", env, seed=0)
    seen: list[th.Tensor | None] = []
    evaluate = model.policy.evaluate_actions

    def evaluate_actions(obs: Any, actions: Any, action_masks: Any = None) -> Any:
        seen.append(action_masks)
        return evaluate(obs, actions, action_masks)

    model.policy.evaluate_actions = evaluate_actions  # type: ignore[method-assign]
    model.learn(10, callback=Recorder())
    masks = seen[0]
    assert masks is not None
    # One episode of 10 steps: the masks the env gave at each step, in order
    np.testing.assert_array_equal(masks.cpu().numpy(), recorded[0][:, 0])
    assert (~masks.cpu().numpy()).sum(axis=1).tolist() == [4] * 10


def all_legal_env(max_episode_steps: int) -> gym.Env:
    env = gym.make("CartPole-v1", max_episode_steps=max_episode_steps)
    return ActionMasker(env, lambda _: np.ones(2, dtype=bool))


@pytest.mark.parametrize(
    ("algo", "kwargs"),
    [
        (REINFORCE, dict()),
        (REINFORCE, dict(update_mode="per_step", ent_coef=0.01)),
        (NStepSARSA, dict(expected_sarsa=True)),
        (NStepSARSA, dict(update_mode="per_step", train_freq=1, gradient_steps=1, n_steps=2)),
    ],
    ids=["reinforce", "reinforce-per-step", "expected-sarsa", "sarsa-per-step"],
)
def test_all_legal_masks_train_as_unmasked_to_the_bit(algo: Any, kwargs: dict[str, Any]) -> None:
    parameters = []
    for use_masking in (True, False):
        # A time limit of 15: the truncations' bootstrap included
        model = algo("MlpPolicy", all_legal_env(15), seed=3, **kwargs).learn(400, use_masking=use_masking)
        assert model._use_masking == use_masking
        parameters.append([p.detach().clone() for p in model.policy.parameters()])
    for masked, unmasked in zip(*parameters, strict=True):
        assert th.equal(masked, unmasked)


@pytest.mark.parametrize("algo", [REINFORCE, NStepSARSA])
def test_save_load_with_and_without_masks(algo: Any, tmp_path: Any) -> None:
    env = discrete_env()
    model = algo("MlpPolicy", env, seed=0).learn(200)
    obs = np.stack([env.observation_space.sample() for _ in range(5)])
    masks = np.tile([True, False, True, False, False, True], (5, 1))
    before, _ = model.predict(obs, action_masks=masks, deterministic=True)
    model.save(tmp_path / "model.zip")
    loaded = algo.load(tmp_path / "model.zip")
    after, _ = loaded.predict(obs, action_masks=masks, deterministic=True)
    np.testing.assert_array_equal(before, after)
    assert set(after.tolist()) <= {0, 2, 5}
    unmasked, _ = loaded.predict(obs, deterministic=True)
    np.testing.assert_array_equal(unmasked, model.predict(obs, deterministic=True)[0])
    # Loaded with an env, it trains masked again
    algo.load(tmp_path / "model.zip", env=discrete_env()).learn(100, reset_num_timesteps=False)


@pytest.mark.parametrize("algo", [REINFORCE, NStepSARSA])
def test_mask_of_the_wrong_shape(algo: Any) -> None:
    model = algo("MlpPolicy", InvalidActionEnvDiscrete(dim=4, n_invalid_actions=1), seed=0)
    obs = np.array([0, 1])
    with pytest.raises(ValueError, match=r"action_masks has shape \(2, 3\).*needs shape \(2, 4\)"):
        model.predict(obs, action_masks=np.ones((2, 3), dtype=bool))
    # One observation takes one mask
    action, _ = model.predict(np.array(0), action_masks=np.array([False, False, True, False]))
    assert int(action) == 2

    class WrongMasks(gym.Wrapper):
        def action_masks(self) -> np.ndarray:
            return np.ones(5, dtype=bool)

    model = algo("MlpPolicy", WrongMasks(InvalidActionEnvDiscrete(dim=4)), seed=0)
    with pytest.raises(ValueError, match=r"action_masks\(\) has shape \(1, 5\).*needs shape \(1, 4\)"):
        model.learn(10)


class NoLegalActionAt(gym.Wrapper):
    """Three actions, all legal but at step ``bad_step`` of each episode, where none is (None: never)."""

    def __init__(self, env: gym.Env, bad_step: int | None):
        super().__init__(env)
        self.bad_step = bad_step
        self.t = 0

    def reset(self, **kwargs: Any) -> Any:
        self.t = 0
        return self.env.reset(**kwargs)

    def step(self, action: Any) -> Any:
        self.t += 1
        return self.env.step(action)

    def action_masks(self) -> np.ndarray:
        return np.full(3, self.t != self.bad_step)


@pytest.mark.parametrize("algo", [REINFORCE, NStepSARSA])
def test_a_state_without_legal_actions_is_an_error_before_any_update(algo: Any) -> None:
    def make(bad_step: int | None) -> gym.Env:
        return NoLegalActionAt(InvalidActionEnvDiscrete(dim=3, ep_length=20), bad_step)

    vec_env = DummyVecEnv([functools.partial(make, None), functools.partial(make, 2)])
    # (n-step SARSA's first update would need n = 3 steps)
    model = algo("MlpPolicy", vec_env, seed=0, **(dict(train_freq=1) if algo is NStepSARSA else {}))
    initial = [p.detach().clone() for p in model.policy.parameters()]
    with pytest.raises(ValueError, match=r"env 1 allows no action for the observation at step 2 of its episode"):
        model.learn(100)
    assert model._n_updates == 0
    assert all(th.equal(p, q) for p, q in zip(model.policy.parameters(), initial, strict=True))


def test_box_actions_with_masks_are_refused() -> None:
    class BoxWithMasks(gym.Wrapper):
        def action_masks(self) -> np.ndarray:
            return np.ones(1, dtype=bool)

    model = REINFORCE("MlpPolicy", BoxWithMasks(gym.make("Pendulum-v1")), seed=0)
    with pytest.raises(ValueError, match="use_masking=False"):
        model.learn(10)
    model.learn(10, use_masking=False)


@pytest.mark.parametrize("capacity", [16, 2], ids=["no growth", "growth"])
def test_stored_masks_stay_with_their_steps_when_rows_are_dropped_and_the_buffer_grows(capacity: int) -> None:
    """The mask of S_t moves with S_t when trained rows are dropped and when the storage doubles."""
    from sb3_classic.common.buffers import TrajectoryBuffer

    n_actions, n_envs = 4, 2
    buffer = TrajectoryBuffer(capacity, spaces.Box(-1, 1, (1,)), spaces.Discrete(n_actions), device="cpu", n_envs=n_envs)
    buffer.set_mask_size(n_actions)
    rng = np.random.default_rng(0)
    added = []
    for step in range(9):
        masks = rng.random((n_envs, n_actions)) < 0.5
        masks[:, 0] = True
        added.append(masks)
        observation = np.full((n_envs, 1), step / 10, dtype=np.float32)
        buffer.add(observation, np.zeros(n_envs, dtype=np.int64), np.zeros(n_envs), np.zeros(n_envs, dtype=bool),
                   np.zeros(n_envs, dtype=bool), {}, action_masks=masks)  # fmt: skip
        if step in (3, 6):
            buffer.mark_trained(np.array([2, 2]))
    data = buffer.get()
    assert data.action_masks is not None
    assert isinstance(data.observations, np.ndarray)
    first = round(float(data.observations[0, 0, 0]) * 10)
    assert first == 4  # (four rows dropped)
    np.testing.assert_array_equal(data.action_masks, np.stack(added[first:]))


@pytest.mark.parametrize(
    ("algo", "kwargs"),
    [
        (NStepSARSA, dict(expected_sarsa=True, update_mode="per_step", train_freq=1, gradient_steps=1)),
        (NStepSARSA, dict(train_freq=4, gradient_steps=2)),
        (REINFORCE, dict(ent_coef=0.01)),
        (REINFORCE, dict(update_mode="per_step", use_baseline=False)),
    ],
    ids=["sarsa-per-step", "sarsa-batch", "reinforce", "reinforce-per-step"],
)
def test_a_population_member_chooses_legal_actions_as_its_separate_run(algo: Any, kwargs: dict[str, Any]) -> None:
    # Each member reads its own env's masks at each of its steps: no illegal action reaches an env (the env raises),
    # and a member draws and trains as its separate run drawing from the member's generator. The stacked layers'
    # batched products may round differently from nn.Linear's in the last bits: close, not equal
    def legal_actions(env: Any) -> np.ndarray:
        # (CartPole's observations are Box, as a population's stacked networks take: pushing outwards is illegal)
        return np.array([env.unwrapped.state[0] < 0.05, env.unwrapped.state[0] > -0.05])

    def make(seed: int) -> Any:
        env = make_vec_env(lambda: RefuseIllegalActions(ActionMasker(gym.make("CartPole-v1"), legal_actions)), 2, seed)
        return algo("MlpPolicy", env, seed=seed, policy_kwargs=dict(net_arch=[16]), **kwargs)

    separate = []
    for seed in (0, 1):
        model = make(seed)
        model._action_rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0,)))
        separate.append(model.learn(200))
    members = [make(seed) for seed in (0, 1)]
    population = NStepSARSAPopulation if algo is NStepSARSA else REINFORCEPopulation
    population(members).learn(200)
    for member, model in zip(members, separate, strict=True):
        assert member._use_masking
        assert member.rollout_buffer.action_masks is not None
        assert member._n_updates == model._n_updates > 0
        seed = member.seed
        for p, q in zip(member.policy.parameters(), model.policy.parameters(), strict=True):
            th.testing.assert_close(p, q, atol=1e-5, rtol=1e-4, msg=lambda m, seed=seed: f"seed {seed}: {m}")  # type: ignore[misc]
