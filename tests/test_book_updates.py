"""
The book's per-step updates, exactly: with a linear model and plain SGD, the weights after several episodes equal those
of a direct NumPy transcription of the book's pseudocode (same features, same actions), to 1e-6.

- n-step SARSA: the box "Episodic semi-gradient n-step Sarsa for estimating q̂ ≈ q*" (S&B §10.2), for n = 1, 4 and
  an n longer than every episode;
- REINFORCE: the boxes of §13.3 (plain, eq. 13.8) and §13.4 (with baseline), with and without the γ^t factor.

The transcriptions below follow the boxes line by line, with the actions the algorithm took replayed (ε-greedy or
sampled actions are the algorithm's business; the update is what is checked).
"""

from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from stable_baselines3.common.vec_env import DummyVecEnv
from stable_baselines3.dqn.policies import QNetwork

from sb3_classic import REINFORCE, NStepSARSA, TileCoding
from sb3_classic.common import returns
from sb3_classic.sarsa import nstep_sarsa
from sb3_classic.sarsa.policies import LinearQPolicy, SARSAPolicy

N_ACTIONS, N_FEATURES = 3, 4
# Episodes of 1 to 9 steps: shorter and longer than n, and a one-step episode
LENGTHS = [5, 1, 7, 2, 9, 3, 6]


class FeatureEpisodes(gym.Env[np.ndarray, Any]):
    """
    Episodes of the given lengths, in turn, whose observations are fixed random feature vectors x(S_t) and whose
    rewards are fixed random numbers R(episode, t, A_t); it records every (x(S_t), A_t, R_{t+1}).

    :param lengths: the length of each episode
    :param seed: the seed of the features and rewards
    """

    def __init__(self, lengths: list[int], seed: int = 0) -> None:
        rng = np.random.default_rng(seed)
        self.features = [rng.normal(size=(length, N_FEATURES)).astype(np.float32) for length in lengths]
        self.rewards = [rng.normal(size=(length, N_ACTIONS)) for length in lengths]
        self.lengths = lengths
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(N_FEATURES,), dtype=np.float32)
        self.action_space = spaces.Discrete(N_ACTIONS)
        self.episodes: list[list[tuple[np.ndarray, int, float]]] = []
        self._episode, self._t = -1, 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self._episode, self._t = self._episode + 1, 0
        self.episodes.append([])
        return self.features[self._episode % len(self.lengths)][0], {}

    def step(self, action: int) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        k = self._episode % len(self.lengths)
        reward = float(np.float32(self.rewards[k][self._t, int(action)]))
        self.episodes[-1].append((self.features[k][self._t], int(action), reward))
        self._t += 1
        terminated = self._t == self.lengths[k]
        obs = np.zeros(N_FEATURES, dtype=np.float32) if terminated else self.features[k][self._t]
        return obs, reward, terminated, False, {}


def vec(env: gym.Env) -> DummyVecEnv:
    """:return: ``env`` as the one env of a VecEnv"""
    return DummyVecEnv([lambda: env])


def weights(layer: Any) -> np.ndarray:
    """:return: a copy of a linear layer's weight matrix"""
    return layer.weight.detach().numpy().copy()


def linear_sgd(**policy_kwargs: Any) -> dict[str, Any]:
    return dict(net_arch=[], with_bias=False, optimizer_class=th.optim.SGD) | policy_kwargs


# --- n-step SARSA (S&B §10.2) ----------------------------------------------------------------------------------------


def reference_nstep_sarsa(
    episodes: list[list[tuple[np.ndarray, int, float]]], w: np.ndarray, n: int, alpha: float, gamma: float
) -> np.ndarray:
    """The box of §10.2, with q̂(s, a, w) = w[a]ᵀx(s), replaying the recorded actions."""
    w = w.astype(np.float64).copy()

    def q_hat(x: np.ndarray, a: int) -> float:
        return float(w[a] @ x)

    for episode in episodes:
        x = [step[0].astype(np.float64) for step in episode]
        actions = [step[1] for step in episode]
        rewards = [0.0] + [step[2] for step in episode]  # R_1, …, R_T at indices 1..T
        big_t = len(episode)
        t = 0
        while True:
            # (Take A_t, observe R_{t+1} and S_{t+1}: recorded; T is known once S_{t+1} is terminal)
            tau = t - n + 1  # the time whose estimate is being updated
            if tau >= 0:
                g = sum(gamma ** (i - tau - 1) * rewards[i] for i in range(tau + 1, min(tau + n, big_t) + 1))
                if tau + n < big_t:
                    g += gamma**n * q_hat(x[tau + n], actions[tau + n])  # G ← G + γ^n q̂(S_{τ+n}, A_{τ+n}, w)
                # w ← w + α [G − q̂(S_τ, A_τ, w)] ∇q̂(S_τ, A_τ, w)   (eq. 10.5)
                w[actions[tau]] += alpha * (g - q_hat(x[tau], actions[tau])) * x[tau]
            if tau == big_t - 1:
                break
            t += 1
    return w


@pytest.mark.parametrize("n", [1, 4, 12])
def test_per_step_nstep_sarsa_is_the_books(n: int) -> None:
    env = FeatureEpisodes(LENGTHS)
    alpha, gamma = 0.05, 0.9
    model = NStepSARSA(
        "MlpPolicy",
        vec(env),
        n_steps=n,
        train_freq=1,
        gradient_steps=1,
        update_mode="per_step",
        learning_rate=alpha,
        gamma=gamma,
        exploration_initial_eps=0.5,
        exploration_final_eps=0.5,
        policy_kwargs=linear_sgd(weight_init=0.1),
        seed=0,
        device="cpu",
    )
    w0 = weights(model.policy.q_net.q_net[0]).copy()
    np.testing.assert_array_equal(w0, np.full((N_ACTIONS, N_FEATURES), 0.1, dtype=np.float32))
    model.learn(2 * sum(LENGTHS))  # every episode twice, ending at an episode's end
    episodes = env.episodes[: 2 * len(LENGTHS)]
    assert len({a for episode in episodes for _, a, _ in episode}) == N_ACTIONS, "every action should have been taken"
    expected = reference_nstep_sarsa(episodes, w0, n, alpha, gamma)
    np.testing.assert_allclose(weights(model.policy.q_net.q_net[0]), expected, rtol=0, atol=1e-6)
    # Not the batch mean: the same data with update_mode="batch" ends elsewhere
    assert np.abs(expected - w0).max() > 1e-2


class StepRecorder(gym.Wrapper[Any, Any, Any, Any]):
    """Records every (S_t, A_t, R_{t+1}, terminated) of the env it wraps."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.steps: list[tuple[int, int, float, bool]] = []
        self._state = 0

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self._state = int(obs)
        return obs, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.steps.append((self._state, int(action), float(reward), terminated))
        self._state = int(obs)
        return obs, reward, terminated, truncated, info


def reference_tabular_sarsa(
    steps: list[tuple[int, int, float, bool]], n_states: int, n_actions: int, alpha: float, epsilon: float, expected: bool
) -> np.ndarray:
    """
    The box of §6.4 (one-step SARSA), or Expected SARSA (§6.6, eq. 6.9: Σ_a π(a|S')Q(S', a) under the ε-greedy π),
    γ = 1, Q = 0 at the start and at terminal states, replaying the recorded steps; a step is updated once A_{t+1} is
    known (the last one of an unfinished episode is not).
    """
    q = np.zeros((n_states, n_actions), dtype=np.float32)
    for t, (state, action, reward, terminated) in enumerate(steps):
        if terminated:
            target = np.float32(reward)
        elif t + 1 < len(steps):
            next_state, next_action = steps[t + 1][:2]
            next_value = (
                (1 - epsilon) * q[next_state].max() + epsilon * q[next_state].mean()
                if expected
                else q[next_state, next_action]
            )
            target = np.float32(reward) + np.float32(next_value)
        else:
            break
        q[state, action] += np.float32(alpha) * (target - q[state, action])  # Q(S, A) ← Q(S, A) + α[target − Q(S, A)]
    return q


@pytest.mark.parametrize("expected", [False, True], ids=["sarsa", "expected sarsa"])
def test_tabular_sarsa_on_cliff_walking_is_the_books(expected: bool) -> None:
    """
    The README's tabular recipe (a Discrete observation, which SB3 one-hot encodes, under the linear recipe) on Example
    6.6's Cliff Walking with its settings (α = 0.5, ε = 0.1, γ = 1, no time limit): the table after 30 episodes is the
    book's box's, replaying the same actions.
    """
    env_id = "CliffWalking-v1" if "CliffWalking-v1" in gym.registry else "CliffWalking-v0"  # (v1 from Gymnasium 1.1)
    env = StepRecorder(gym.make(env_id))
    model = NStepSARSA(
        "MlpPolicy",
        vec(env),
        learning_rate=0.5,
        n_steps=1,
        train_freq=1,
        gradient_steps=1,
        update_mode="per_step",
        gamma=1.0,
        expected_sarsa=expected,
        exploration_initial_eps=0.1,
        exploration_final_eps=0.1,
        policy_kwargs=linear_sgd(weight_init=0.0),
        seed=0,
        device="cpu",
    )

    def first_step_of_episode_31(_locals: dict[str, Any], _globals: dict[str, Any]) -> bool:
        # (StopTrainingOnMaxEpisodes would stop at episode 30's last step, before its last two updates)
        return sum(terminated for *_, terminated in env.steps) < 30 or env.steps[-1][3]

    model.learn(10**6, callback=first_step_of_episode_31)
    assert sum(terminated for *_, terminated in env.steps) == 30
    assert any(reward == -100 for _, _, reward, _ in env.steps), "the agent should have fallen off the cliff"
    table = reference_tabular_sarsa(env.steps, 48, 4, alpha=0.5, epsilon=0.1, expected=expected)
    # w[a, s] = Q(s, a): the weight of state s's one-hot feature
    np.testing.assert_allclose(weights(model.policy.q_net.q_net[0]).T, table, rtol=0, atol=1e-5)
    assert np.abs(table).max() > 10


@pytest.mark.parametrize(
    "kwargs",
    [dict(n_steps=1), dict(n_steps=3, expected_sarsa=True), dict(n_steps=2, exploration_schedule="linear")],
    ids=["n=1", "n=3 expected", "n=2 linear eps"],
)
def test_the_book_loops_windows_give_train_the_same_bits(kwargs: dict[str, Any], monkeypatch: pytest.MonkeyPatch) -> None:
    """
    With one env and an update every step (the book's loop), ``completed_windows`` computes each update's windows one
    at a time, for the per-step mode's speed: training against the windows of ``nstep_windows`` over the buffer, a 2×32
    MLP with Adam and time-limit truncations (CartPole cut at 30 steps), the same parameters bit for bit and the same
    log.
    """

    def run() -> tuple[list[th.Tensor], dict[str, Any]]:
        env = DummyVecEnv([lambda: gym.make("CartPole-v1", max_episode_steps=30)])
        model = NStepSARSA(
            "MlpPolicy", env, train_freq=1, gradient_steps=1, update_mode="per_step", exploration_initial_eps=0.3,
            policy_kwargs=dict(net_arch=[32, 32]), seed=5, device="cpu", **kwargs,
        )  # fmt: skip
        model.learn(600)
        return [p.detach().clone() for p in model.policy.parameters()], dict(model.logger.name_to_value)

    calls = [0]
    one_at_a_time = returns._windows_one_at_a_time

    def counted(*args: Any) -> Any:
        calls[0] += 1
        return one_at_a_time(*args)

    monkeypatch.setattr(returns, "_windows_one_at_a_time", counted)
    fast, fast_log = run()
    assert calls[0] > 300, "the book loop's windows must be computed one at a time"
    monkeypatch.setattr(nstep_sarsa, "completed_windows", returns._windows_vectorised)
    general, general_log = run()
    assert all(th.equal(a, b) for a, b in zip(fast, general, strict=True))
    assert fast_log == general_log


MOUNTAIN_CAR_TILES = dict(n_tilings=8, tiles_per_dim=8, low=(-1.2, -0.07), high=(0.5, 0.07))


def tile_coded_sarsa(
    with_bias: bool = False, hash_size: int | None = None, policy: str = "LinearPolicy", **kwargs: Any
) -> NStepSARSA:
    """
    :param policy: ``"LinearPolicy"`` (its own SGD update) or ``"MlpPolicy"`` (the same q̂ through autograd and
        ``torch.optim.SGD``)
    :return: per-step linear SARSA with plain SGD over tile coding on Mountain Car (the book's Figs 10.1–10.4)
    """
    tiles = MOUNTAIN_CAR_TILES | dict(hash_size=hash_size)
    return NStepSARSA(
        policy, "MountainCar-v0", learning_rate=0.3 / 8, gradient_steps=1, update_mode="per_step", gamma=1.0,
        exploration_initial_eps=0.1, exploration_final_eps=0.1,
        policy_kwargs=linear_sgd(
            with_bias=with_bias, weight_init=0.0, features_extractor_class=TileCoding, features_extractor_kwargs=tiles
        ),
        seed=3, device="cpu", **(dict(train_freq=1) | kwargs),
    )  # fmt: skip


def _linear_sarsa_runs(
    kwargs: dict[str, Any], steps: int, direct: str, monkeypatch: pytest.MonkeyPatch
) -> tuple[int, list[tuple[Any, ...]]]:
    """
    Train ``tile_coded_sarsa(**kwargs)`` for ``steps`` env steps twice: with ``"LinearPolicy"``, counting the calls of
    its update ``direct``, then with ``"MlpPolicy"`` (the linear update through autograd and ``torch.optim.SGD``).

    :return: the direct updates made in the first run, and each run's parameters and last log
    """
    calls = [0]
    update = getattr(LinearQPolicy, direct)

    def counted(self: LinearQPolicy, *args: Any) -> Any:
        calls[0] += 1
        return update(self, *args)

    monkeypatch.setattr(LinearQPolicy, direct, counted)
    runs = []
    for policy in ("LinearPolicy", "MlpPolicy"):
        model = tile_coded_sarsa(policy=policy, **kwargs)
        model.learn(steps)
        runs.append(([p.detach().clone() for p in model.policy.parameters()], dict(model.logger.name_to_value)))
    return calls[0], runs


LINEAR_SETTINGS = [dict(n_steps=4), dict(n_steps=1, expected_sarsa=True, with_bias=True), dict(n_steps=3, train_freq=4)]
LINEAR_IDS = ["n=4", "n=1 expected, bias", "n=3 train_freq=4"]


@pytest.mark.parametrize("kwargs", LINEAR_SETTINGS, ids=LINEAR_IDS)
def test_direct_linear_sgd_update_is_autograds_to_float32_rounding(
    kwargs: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    """
    ``LinearPolicy``'s update of a linear q̂ on dense features, applied to W_a without autograd (for the per-step
    mode's speed), gives the parameters and the log of autograd and ``torch.optim.SGD`` to float32 rounding:
    over tile coding's dense features on Mountain Car (its sparse path switched off), with a bias, Expected SARSA and
    updates of several transitions at once.
    """
    monkeypatch.setattr(LinearQPolicy, "_over_tiles", lambda self: None)
    direct_updates, (fast, general) = _linear_sarsa_runs(kwargs, 1200, "sgd_step", monkeypatch)
    assert direct_updates > 1000
    # Close, not equal: autograd's weight gradient is a matrix product (BLAS sums, whose order and use of FMA differ
    # between CPUs) where the direct update adds each transition's row in turn; the tolerance of the tile-coded test
    # below, whose sums differ in order at every step (3.8e-6 apart after these 1,200 steps)
    for a, b in zip(fast[0], general[0], strict=True):
        np.testing.assert_allclose(a.numpy(), b.numpy(), rtol=1e-5, atol=1e-5)
    assert fast[1].keys() == general[1].keys()
    for key, value in fast[1].items():
        assert value == pytest.approx(general[1][key], rel=1e-5, abs=1e-5), key
    assert fast[0][0].abs().max() > 0.1, "the weights should have moved"


@pytest.mark.parametrize(
    "kwargs", [*LINEAR_SETTINGS, dict(n_steps=4, hash_size=64)], ids=[*LINEAR_IDS, "n=4 hashed, collisions"]
)
def test_tile_coded_sgd_update_is_autograds_to_float32_rounding(
    kwargs: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    """
    Over tile coding, the rollout's q̂ and the per-step update go over the active tiles, as the book's code does:
    q̂ = Σ_t W[a, i_t(s)], and α[G − q̂] added to each active tile's weight (``LinearQPolicy.q_values``, ``sgd_step``).
    The same learning as the dense features through autograd and ``torch.optim.SGD``, to float32 rounding (the sum's
    order differs), over 1,200 steps of Mountain Car: with a bias, Expected SARSA, several transitions at once, and
    hashed tiles that collide (a tile met by two tilings gets the step twice, as its feature is 2).
    """
    direct_updates, (fast, general) = _linear_sarsa_runs(kwargs, 1200, "_tile_sgd_step", monkeypatch)
    assert direct_updates > 300 if kwargs.get("train_freq") else direct_updates > 1000
    for a, b in zip(fast[0], general[0], strict=True):
        np.testing.assert_allclose(a.numpy(), b.numpy(), rtol=1e-5, atol=1e-5)
    assert fast[0][0].abs().max() > 0.1, "the weights should have moved"
    assert fast[1].keys() == general[1].keys()
    for key, value in fast[1].items():
        assert value == pytest.approx(general[1][key], rel=1e-5, abs=1e-5), key
    if kwargs.get("hash_size"):
        model = tile_coded_sarsa(**kwargs)
        extractor = model.policy.q_net.features_extractor
        assert isinstance(extractor, TileCoding)
        tiles = extractor.active_tiles_numpy(np.random.default_rng(0).uniform(-1, 0.5, (500, 2)) * [1, 0.07])
        assert any(len(set(row)) < len(row) for row in tiles.tolist()), "the hash should collide within an observation"


def test_tile_q_values_are_the_dense_forward_pass() -> None:
    """The rollout's q̂ over the active tiles equals the policy's dense forward pass, with and without bias and hashing."""
    rng = np.random.default_rng(1)
    obs = (rng.uniform(-1.3, 0.6, (200, 2)) * [1, 0.07 / 0.6]).astype(np.float32)
    for with_bias, hash_size in ((False, None), (True, None), (True, 64)):
        model = tile_coded_sarsa(with_bias=with_bias, hash_size=hash_size)
        assert isinstance(model.policy, LinearQPolicy)
        assert model.policy.tile_coding is not None
        with th.no_grad():
            for parameter in model.policy.q_net.parameters():
                parameter.normal_()
            dense = model.policy.q_net(th.as_tensor(obs)).numpy()
        np.testing.assert_allclose(model.policy.q_values(obs), dense, rtol=1e-5, atol=1e-5)
    # Other features: the dense forward pass
    dense_model = NStepSARSA("LinearPolicy", "MountainCar-v0")
    assert isinstance(dense_model.policy, LinearQPolicy)
    assert dense_model.policy.tile_coding is None
    np.testing.assert_allclose(dense_model.policy.q_values(obs), dense_model.policy.q_net(th.as_tensor(obs)).detach().numpy())


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(policy_kwargs=dict(optimizer_kwargs=dict(momentum=0.9))), "momentum"),
        (dict(policy_kwargs=dict(optimizer_kwargs=dict(weight_decay=1e-3))), "weight_decay"),
        (dict(max_grad_norm=1.0), "max_grad_norm"),
        (dict(loss_function="huber"), "loss_function"),
        (dict(policy_kwargs=dict(optimizer_class=th.optim.Adam)), "optimizer_class"),
        (dict(policy_kwargs=dict(net_arch=[8])), "net_arch"),
    ],
    ids=["momentum", "weight decay", "clipping", "huber", "adam", "hidden layer"],
)
def test_linear_policy_refuses_what_its_update_is_not(kwargs: dict[str, Any], match: str) -> None:
    """LinearPolicy's update is plain SGD on ½(G − q̂)² of a linear q̂: anything else is an error naming the argument."""
    with pytest.raises(ValueError, match=match):
        NStepSARSA("LinearPolicy", vec(FeatureEpisodes(LENGTHS)), **kwargs)
    # The same q̂ and options through autograd and the optimizer
    assert not isinstance(
        NStepSARSA("MlpPolicy", vec(FeatureEpisodes(LENGTHS)), policy_kwargs=linear_sgd()).policy, LinearQPolicy
    )
    plain = NStepSARSA("LinearPolicy", vec(FeatureEpisodes(LENGTHS)), train_freq=1, update_mode="per_step")
    assert plain.policy.layer is plain.policy.q_net.q_net[0]
    # A q̂ whose layers were replaced after construction is not updated through the old layer
    plain.policy.q_net.q_net = th.nn.Sequential(th.nn.Linear(N_FEATURES, N_ACTIONS, bias=False))
    with pytest.raises(RuntimeError, match="replaced"):
        plain.learn(20)


def test_batch_mode_differs_from_the_book_at_episode_ends() -> None:
    """The batch mean gives each of the last n transitions α/n: the reason the per-step mode exists."""
    results = {}
    for mode in ("batch", "per_step"):
        env = FeatureEpisodes(LENGTHS)
        model = NStepSARSA(
            "MlpPolicy", vec(env), n_steps=4, train_freq=1, gradient_steps=1, update_mode=mode,
            learning_rate=0.05, gamma=0.9, policy_kwargs=linear_sgd(weight_init=0.0), seed=0, device="cpu",
        )  # fmt: skip
        model.learn(sum(LENGTHS))
        results[mode] = weights(model.policy.q_net.q_net[0])
    assert np.abs(results["batch"] - results["per_step"]).max() > 1e-3


def test_random_tie_breaking_in_the_behaviour_policy_and_stochastic_predict() -> None:
    """
    A q̂ of zeros: the behaviour policy tries every action, and so does predict(deterministic=False) (it took action 0
    1000 times in 1000, with ε = 0); predict(deterministic=True) stays reproducible.
    """
    env = FeatureEpisodes(LENGTHS)
    model = NStepSARSA(
        "MlpPolicy", vec(env), exploration_initial_eps=0.0, exploration_final_eps=0.0,
        policy_kwargs=linear_sgd(weight_init=0.0), seed=0, device="cpu",
    )  # fmt: skip
    obs = th.as_tensor(np.stack([env.features[0][0]] * 300))
    with th.no_grad():  # as in the rollout loop
        sampled = model._sample_actions(obs.numpy())
    assert set(sampled.tolist()) == set(range(N_ACTIONS))
    assert np.bincount(sampled, minlength=N_ACTIONS).min() > 60
    greedy, _ = model.predict(obs.numpy(), deterministic=True)
    np.testing.assert_array_equal(greedy, np.zeros(300))
    stochastic, _ = model.predict(obs.numpy(), deterministic=False)
    assert np.bincount(stochastic, minlength=N_ACTIONS).min() > 60
    one = [int(model.predict(obs[0].numpy(), deterministic=False)[0]) for _ in range(60)]
    assert set(one) == set(range(N_ACTIONS))


# --- REINFORCE (S&B §13.3, §13.4) ------------------------------------------------------------------------------------


def softmax(logits: np.ndarray) -> np.ndarray:
    z = np.exp(logits - logits.max())
    return z / z.sum()


def reference_reinforce(
    episodes: list[list[tuple[np.ndarray, int, float]]],
    theta: np.ndarray,
    w: np.ndarray | None,
    alpha_theta: float,
    alpha_w: float,
    gamma: float,
    gamma_t: bool,
) -> tuple[np.ndarray, np.ndarray | None]:
    """
    The boxes of §13.3 (``w is None``: plain REINFORCE) and §13.4, with the soft-max linear policy
    π(a|s, θ) ∝ exp(θ[a]ᵀx(s)) (eq. 13.2–13.3) and v̂(s, w) = wᵀx(s), replaying the recorded actions.
    """
    theta = theta.astype(np.float64).copy()
    w = None if w is None else w.astype(np.float64).copy()
    for episode in episodes:
        big_t = len(episode)
        for t in range(big_t):  # Loop for each step of the episode, t = 0, 1, …, T − 1
            x, a = episode[t][0].astype(np.float64), episode[t][1]
            g = sum(gamma ** (k - t - 1) * episode[k - 1][2] for k in range(t + 1, big_t + 1))  # G
            delta = g if w is None else g - float(w @ x)  # δ ← G − v̂(S_t, w)
            if w is not None:
                w = w + alpha_w * delta * x  # w ← w + α^w δ ∇v̂(S_t, w)
            # ∇ln π(a|s, θ) = x(s, a) − Σ_b π(b|s, θ) x(s, b)   (eq. 13.9), here (onehot(a) − π) ⊗ x(s)
            grad_ln_pi = np.outer(np.eye(N_ACTIONS)[a] - softmax(theta @ x), x)
            theta = theta + alpha_theta * (gamma**t if gamma_t else 1.0) * delta * grad_ln_pi
    return theta, w


@pytest.mark.parametrize("use_baseline", [True, False], ids=["with baseline", "plain"])
@pytest.mark.parametrize("gamma_t_factor", [True, False], ids=["gamma^t", "no gamma^t"])
def test_per_step_reinforce_is_the_books(use_baseline: bool, gamma_t_factor: bool) -> None:
    env = FeatureEpisodes(LENGTHS)
    alpha_theta, alpha_w, gamma = 0.05, 0.1, 0.9
    model = REINFORCE(
        "MlpPolicy",
        vec(env),
        learning_rate=alpha_theta,
        value_learning_rate=alpha_w,
        update_mode="per_step",
        use_baseline=use_baseline,
        gamma=gamma,
        gamma_t_factor=gamma_t_factor,
        policy_kwargs=linear_sgd(weight_init=0.0),
        seed=0,
        device="cpu",
    )
    policy = model.policy
    theta0 = weights(policy.action_net).copy()
    w0 = weights(policy.value_net).copy()[0] if use_baseline else None
    model.learn(2 * sum(LENGTHS))
    episodes = env.episodes[: 2 * len(LENGTHS)]
    assert sum(len(episode) for episode in episodes) == model.num_timesteps
    theta, w = reference_reinforce(episodes, theta0, w0, alpha_theta, alpha_w, gamma, gamma_t_factor)
    np.testing.assert_allclose(weights(policy.action_net), theta, rtol=0, atol=1e-6)
    assert np.abs(theta - theta0).max() > 1e-2
    if use_baseline:
        assert w is not None
        np.testing.assert_allclose(weights(policy.value_net)[0], w, rtol=0, atol=1e-6)
    else:
        # Plain REINFORCE builds no value network, and saves one optimizer
        assert policy.value_optimizer is None
        assert all("value" not in name for name, _ in policy.named_parameters())
        assert model._get_torch_save_params()[0] == ["policy", "policy.optimizer"]


def test_plain_reinforce_saves_and_loads(tmp_path: Any) -> None:
    model = REINFORCE("MlpPolicy", "CartPole-v1", use_baseline=False, policy_kwargs=dict(net_arch=[8]), seed=0, device="cpu")
    model.learn(300)
    model.save(tmp_path / "plain")
    loaded = REINFORCE.load(tmp_path / "plain", env=model.get_env(), device="cpu")
    assert not loaded.use_baseline
    assert loaded.policy.value_optimizer is None
    obs = np.zeros((5, 4), dtype=np.float32)
    np.testing.assert_array_equal(loaded.predict(obs, deterministic=True)[0], model.predict(obs, deterministic=True)[0])
    # Every method that returns v̂ says there is none (forward and evaluate_actions returned the features unchanged)
    for returns_values in (
        lambda: loaded.policy.predict_values(th.zeros(1, 4)),
        lambda: loaded.policy(th.zeros(1, 4)),
        lambda: loaded.policy.evaluate_actions(th.zeros(1, 4), th.zeros(1)),
    ):
        with pytest.raises(
            ValueError, match=r"use_baseline=False.*get_distribution.*wrap policy\._predict\(obs, deterministic=True\)"
        ):
            returns_values()
    # What the message offers for an export acts as predict does
    actions = loaded.policy._predict(th.as_tensor(obs), deterministic=True).numpy()
    np.testing.assert_array_equal(actions, model.predict(obs, deterministic=True)[0])
    assert loaded.policy.get_distribution(th.zeros(1, 4)).log_prob(th.zeros(1)).shape == (1,)
    loaded.learn(200)


def test_per_step_and_normalize_advantage_are_refused() -> None:
    with pytest.raises(ValueError, match=r"normalize_advantage=True .* update_mode='batch'"):
        REINFORCE("MlpPolicy", "CartPole-v1", update_mode="per_step", normalize_advantage=True)
    with pytest.raises(ValueError, match="update_mode='per-step' must be one of"):
        NStepSARSA("MlpPolicy", "CartPole-v1", update_mode="per-step")


def test_direct_updates_only_where_they_are_what_autograd_would_do() -> None:
    """
    LinearPolicy's update stands for q̂ = W x(s) and autograd's SGD step; it is not made where those are something else:
    over a TileCoding subclass with features of its own the dense features are used (over the tiles, its q̂ would be
    8× the policy's), a QNetwork subclass with its own forward (from make_q_net) is refused, and a frozen bias is
    left alone, over tiles and dense features.
    """

    class ScaledTiles(TileCoding):
        def forward(self, observations: th.Tensor) -> th.Tensor:
            return super().forward(observations) / self.n_tilings

    class HalfQ(QNetwork):
        def forward(self, obs: th.Tensor) -> th.Tensor:  # type: ignore[override]
            return 0.5 * super().forward(obs)

    class HalfPolicy(SARSAPolicy):
        def make_q_net(self) -> QNetwork:
            q_net = super().make_q_net()
            q_net.__class__ = HalfQ
            return q_net

    class HalfLinearPolicy(LinearQPolicy):
        def make_q_net(self) -> QNetwork:
            q_net = super().make_q_net()
            q_net.__class__ = HalfQ
            return q_net

    tiles = dict(features_extractor_class=TileCoding, features_extractor_kwargs=MOUNTAIN_CAR_TILES)
    scaled_tiles = dict(features_extractor_class=ScaledTiles, features_extractor_kwargs=MOUNTAIN_CAR_TILES)
    scaled = NStepSARSA("LinearPolicy", "MountainCar-v0", policy_kwargs=scaled_tiles, device="cpu")
    assert isinstance(scaled.policy, LinearQPolicy)
    assert scaled.policy.tile_coding is None  # (its dense features, through its own forward)
    with pytest.raises(TypeError, match="own forward"):
        NStepSARSA(HalfLinearPolicy, "MountainCar-v0", policy_kwargs=tiles, device="cpu")
    assert (
        NStepSARSA(HalfPolicy, "MountainCar-v0", policy_kwargs=linear_sgd(**tiles), device="cpu").policy.q_net.__class__
        is HalfQ
    )

    for over_tiles in (True, False):
        frozen = tile_coded_sarsa(with_bias=True)
        assert isinstance(frozen.policy, LinearQPolicy)
        if not over_tiles:
            frozen.policy.__dict__["tile_coding"] = None
        layer = frozen.policy.layer
        assert layer.bias is not None
        bias = layer.bias
        bias.requires_grad_(False)
        with th.no_grad():
            bias.fill_(0.25)
        frozen.learn(500)
        np.testing.assert_array_equal(bias.detach().numpy(), np.full(3, 0.25, dtype=np.float32))
        assert layer.weight.abs().max() > 0.1, "the weights, not frozen, should have moved"
