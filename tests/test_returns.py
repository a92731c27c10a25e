"""The return and target math against slow, obvious transcriptions of the book, on random trajectories."""

import numpy as np
import pytest
from reference import (
    bootstrap_values,
    random_trajectories,
    reference_lambda_targets,
    reference_mc_returns,
    reference_nstep_targets,
)

from sb3_classic.common.returns import (
    discounted_returns,
    epsilon_greedy_expectation,
    gamma_powers,
    greedy_random_ties,
    nstep_targets,
    nstep_window,
    nstep_windows,
    truncated_lambda_returns,
)


@pytest.mark.parametrize("seed", range(20))
@pytest.mark.parametrize("gamma", [0.9, 1.0])
def test_discounted_returns_match_reference(seed: int, gamma: float) -> None:
    rng = np.random.default_rng(seed)
    traj = random_trajectories(rng, n_steps=int(rng.integers(1, 40)), n_envs=3)
    next_values = np.where(traj["truncated"], traj["final_values"], 0.0)
    returns = discounted_returns(traj["rewards"], traj["dones"], next_values, gamma)
    n_checked = 0
    for env in range(3):
        for t, expected in reference_mc_returns(traj, env, gamma).items():
            assert returns[t, env] == pytest.approx(expected, rel=1e-4, abs=1e-4)
            n_checked += 1
    assert n_checked == sum(end + 1 for end in np.where(traj["dones"], np.arange(len(traj["dones"]))[:, None], -1).max(0))


def test_discounted_returns_by_hand() -> None:
    # One env: an episode terminated after 3 rewards, then one truncated after 2 with v̂(S_final) = 10
    rewards = np.array([[1.0], [2.0], [3.0], [4.0], [5.0]])
    dones = np.array([[False], [False], [True], [False], [True]])
    next_values = np.array([[0.0], [0.0], [0.0], [0.0], [10.0]])
    returns = discounted_returns(rewards, dones, next_values, gamma=0.5)
    np.testing.assert_allclose(returns[:, 0], [1 + 0.5 * 2 + 0.25 * 3, 2 + 0.5 * 3, 3, 4 + 0.5 * 5 + 0.25 * 10, 5 + 0.5 * 10])


@pytest.mark.parametrize("seed", range(30))
@pytest.mark.parametrize("n", [1, 2, 5, 50])
def test_nstep_targets_match_reference(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    # Rollouts shorter and longer than n, several envs, random terminations and truncations
    traj = random_trajectories(rng, n_steps=int(rng.integers(1, 30)), n_envs=3, p_end=float(rng.choice([0.0, 0.1, 0.4])))
    gamma = float(rng.choice([0.9, 1.0]))
    targets, complete = nstep_targets(traj["rewards"], traj["dones"], bootstrap_values(traj), gamma, n)
    for env in range(3):
        expected = reference_nstep_targets(traj, env, gamma, n)
        # The same transitions are complete (no target shortened, none left out) ...
        assert set(np.flatnonzero(complete[:, env])) == set(expected)
        # ... with the same targets, never reading the unknown bootstrap after the last step
        for t, target in expected.items():
            assert targets[t, env] == pytest.approx(target, rel=1e-4, abs=1e-4)


def test_nstep_targets_by_hand() -> None:
    # n = 2, γ = 0.5, one env: a terminated episode of 3 steps, then a running one of 2 steps
    rewards = np.array([[1.0], [2.0], [3.0], [4.0], [5.0]])
    dones = np.array([[False], [False], [True], [False], [False]])
    q_next = np.array([[7.0], [8.0], [0.0], [9.0], [np.nan]])  # q̂(S_{t+1}, A_{t+1}); 0 after the termination
    targets, complete = nstep_targets(rewards, dones, q_next, gamma=0.5, n_steps=2)
    # The last two need q̂(S_5, A_5): step 5 has not been taken
    assert complete[:, 0].tolist() == [True, True, True, False, False]
    np.testing.assert_allclose(targets[:3, 0], [1 + 0.5 * 2 + 0.25 * 8, 2 + 0.5 * 3, 3])


@pytest.mark.parametrize("seed", range(10))
def test_nstep_reward_sums_are_sequential_float32_sums_whatever_the_batch(seed: int) -> None:
    # Seeded runs repeat to the last bit only if a target's rewards are summed the same way whatever else the buffer
    # holds: term by term in float32, γ^k by repeated products, as the docstring says
    rng = np.random.default_rng(seed)
    n, gamma = int(rng.integers(1, 9)), 0.99
    rewards = (rng.normal(size=(14, 3)) * 37).astype(np.float32)
    dones = rng.random((14, 3)) < 0.15
    windows = nstep_windows(rewards, dones, gamma, n)
    for t, env in zip(*np.nonzero(windows.complete), strict=True):
        expected, discount = np.float32(0.0), 1.0
        for k in range(int(windows.stop_rows[t, env]) - t + 1):
            expected = np.float32(expected + np.float32(discount) * rewards[t + k, env])
            discount *= gamma
        assert windows.reward_sums[t, env].tobytes() == expected.tobytes()
        # The same window in a buffer that starts at step t (rows before it trained and dropped)
        later = nstep_windows(rewards[t:], dones[t:], gamma, n)
        assert later.reward_sums[0, env].tobytes() == expected.tobytes()
        assert later.bootstrap_discounts[0, env] == windows.bootstrap_discounts[t, env]


@pytest.mark.parametrize("seed", range(20))
def test_one_window_is_the_vectorised_window_to_the_last_bit(seed: int) -> None:
    # The per-step mode with one env computes its windows one at a time (nstep_window); a seeded run must give the same
    # parameters as with nstep_windows, so every field must be the same bits, complete or not
    rng = np.random.default_rng(seed)
    n, gamma = int(rng.choice([1, 2, 5, 30])), float(rng.choice([0.9, 0.99, 1.0]))
    length = int(rng.integers(1, 20))
    rewards = (rng.normal(size=(length, 1)) * 37).astype(np.float32)
    dones = rng.random((length, 1)) < float(rng.choice([0.0, 0.15, 0.5]))
    windows = nstep_windows(rewards, dones, gamma, n)
    for t in range(length):
        window = nstep_window(rewards[:, 0], dones[:, 0], t, gamma_powers(gamma, n), n)
        assert window.complete == windows.complete[t, 0]
        assert window.stop_row == windows.stop_rows[t, 0]
        assert window.reward_sum.tobytes() == windows.reward_sums[t, 0].tobytes()
        assert window.bootstrap_discount.tobytes() == windows.bootstrap_discounts[t, 0].tobytes()


def complete_windows(traj: dict[str, np.ndarray], gamma: float, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:return: the first step, env and last step of every complete n-step window of ``traj``"""
    windows = nstep_windows(traj["rewards"], traj["dones"], gamma, n)
    rows, envs = np.nonzero(windows.complete)
    return rows, envs, windows.stop_rows[rows, envs]


@pytest.mark.parametrize("seed", range(15))
@pytest.mark.parametrize(("n", "lam"), [(1, 0.5), (3, 0.0), (4, 0.5), (6, 0.8), (10, 0.3)])
def test_truncated_lambda_returns_match_the_books_weighted_sum(seed: int, n: int, lam: float) -> None:
    """The recursion against eq. 12.9's sum of k-step returns, episode ends and truncations inside windows included."""
    rng = np.random.default_rng(seed)
    traj = random_trajectories(rng, n_steps=int(rng.integers(1, 40)), n_envs=3)
    gamma = 0.9
    rows, envs, stop_rows = complete_windows(traj, gamma, n)
    next_values = bootstrap_values(traj, unknown=0.0)
    returns = truncated_lambda_returns(traj["rewards"], next_values, rows, envs, stop_rows, gamma, lam)
    expected = {env: reference_lambda_targets(traj, env, gamma, n, lam) for env in range(3)}
    assert sorted(zip(envs.tolist(), rows.tolist(), strict=True)) == sorted((e, t) for e in expected for t in expected[e])
    for target, t, env in zip(returns, rows.tolist(), envs.tolist(), strict=True):
        assert target == pytest.approx(expected[env][t], rel=1e-5, abs=1e-5)


@pytest.mark.parametrize("seed", range(5))
def test_truncated_lambda_returns_are_the_nstep_and_one_step_returns_at_1_and_0(seed: int) -> None:
    rng = np.random.default_rng(seed)
    traj = random_trajectories(rng, n_steps=30, n_envs=2)
    gamma, n = 0.95, 5
    next_values = bootstrap_values(traj, unknown=0.0)
    rows, envs, stop_rows = complete_windows(traj, gamma, n)
    nstep, _ = nstep_targets(traj["rewards"], traj["dones"], next_values, gamma, n)
    lam_1 = truncated_lambda_returns(traj["rewards"], next_values, rows, envs, stop_rows, gamma, 1.0)
    np.testing.assert_allclose(lam_1, nstep[rows, envs], rtol=1e-5, atol=1e-5)
    one_step = traj["rewards"][rows, envs] + gamma * next_values[rows, envs]
    lam_0 = truncated_lambda_returns(traj["rewards"], next_values, rows, envs, stop_rows, gamma, 0.0)
    np.testing.assert_allclose(lam_0, one_step, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("epsilon", [0.0, 0.1, 1.0])
def test_epsilon_greedy_expectation(epsilon: float) -> None:
    q = np.array([[1.0, 4.0, 2.0], [0.0, 0.0, 3.0]])
    expected = [sum(q[i, a] * ((1 - epsilon) * (a == q[i].argmax()) + epsilon / 3) for a in range(3)) for i in range(2)]
    np.testing.assert_allclose(epsilon_greedy_expectation(q, epsilon), expected)


def reference_greedy_random_ties(q_values: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """S&B §2.2's greedy action, ties broken at random: row by row, a draw only where several actions are greatest."""
    actions = []
    for row in q_values:
        greatest = np.flatnonzero(row == row.max())
        actions.append(greatest[0] if len(greatest) == 1 else rng.choice(greatest))
    return np.array(actions, dtype=np.int64)


@pytest.mark.parametrize("n_rows", [1, 4])
def test_greedy_random_ties_draws_as_the_book_row_by_row(n_rows: int) -> None:
    # Values in {0, 1, 2}: most rows tie; one env (one row, the book's loop) takes a path of its own
    q_values = np.random.default_rng(1).integers(0, 3, size=(200, n_rows, 4)).astype(np.float32)
    rng, reference_rng = np.random.default_rng(2), np.random.default_rng(2)
    drawn = np.stack([greedy_random_ties(q.copy(), rng) for q in q_values])
    expected = np.stack([reference_greedy_random_ties(q, reference_rng) for q in q_values])
    # Exact: action indices drawn from one seeded stream, and maxima of small integers, which round on no CPU
    np.testing.assert_array_equal(drawn, expected)
    # The same draws, so the generators are left in the same state
    assert rng.random() == reference_rng.random()
    # Every tied action is drawn, none that is not greatest
    assert set(np.unique(drawn[:, 0])) == set(range(4))
    assert np.all(np.take_along_axis(q_values, drawn[..., None], axis=2)[..., 0] == q_values.max(axis=2))
