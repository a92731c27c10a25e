"""
The return and target math of both algorithms, as pure functions of time-major arrays.

Every array is indexed ``[t, env]`` over the steps a buffer holds, in the order they were taken:

- ``rewards[t]`` is R_{t+1}, the reward received for the action taken at step t;
- ``dones[t]`` says that the episode ended with that step (S_{t+1} is terminal, or the episode was truncated);
- ``next_values[t]`` is what a target bootstraps from *after* step t when it stops there: 0 when the episode
  terminated, the estimated value of the final state when it was truncated by a time limit, and (for n-step
  SARSA) q̂(S_{t+1}, A_{t+1}) while the episode goes on.

An entry whose return depends on steps not taken yet is flagged incomplete; its value is meaningless.
"""

import numpy as np


def discounted_returns(rewards: np.ndarray, dones: np.ndarray, next_values: np.ndarray, gamma: float) -> np.ndarray:
    """
    Monte-Carlo returns G_t = R_{t+1} + γ R_{t+2} + … over each episode (Sutton & Barto eq. 3.8, computed
    backwards with the recursion G_t = R_{t+1} + γ G_{t+1} of eq. 3.9). An episode that ended by termination
    adds nothing after its last reward; one cut by a time limit adds γ·``next_values`` there (the bootstrap
    that treats the time limit as not part of the task).

    Entries after the last episode end of an env belong to an episode still running: they are returned but
    meaningless (the caller trains only on complete episodes).

    :param rewards: R_{t+1}, shape (n_steps, n_envs)
    :param dones: whether the episode ended with step t, shape (n_steps, n_envs)
    :param next_values: value to bootstrap from where an episode ended (0 at a termination), shape (n_steps, n_envs)
    :param gamma: discount factor γ
    :return: the returns G_t, shape (n_steps, n_envs), float32
    """
    returns = np.empty(rewards.shape, dtype=np.float32)
    next_return = np.zeros(rewards.shape[1:], dtype=np.float32)
    for t in reversed(range(len(rewards))):
        # G_t = R_{t+1} + γ G_{t+1}, with G_{t+1} replaced by the bootstrap value where the episode ended (eq. 3.9)
        next_return = rewards[t] + gamma * np.where(dones[t], next_values[t], next_return)
        returns[t] = next_return
    return returns


def nstep_targets(
    rewards: np.ndarray, dones: np.ndarray, next_values: np.ndarray, gamma: float, n_steps: int
) -> tuple[np.ndarray, np.ndarray]:
    """
    n-step returns of semi-gradient n-step SARSA (Sutton & Barto §10.2, eq. 10.4):

    G_{t:t+n} = R_{t+1} + γ R_{t+2} + … + γ^{n−1} R_{t+n} + γ^n q̂(S_{t+n}, A_{t+n}),

    and G_{t:t+n} = G_t when the episode ends first (no bootstrap past a termination; a time-limit truncation
    bootstraps from ``next_values`` at the step where it happened).

    A target is complete when the episode ended within its n steps, or when step t+n has been taken (so that
    q̂(S_{t+n}, A_{t+n}) is known). Incomplete targets are never shortened: the caller keeps those transitions
    until the steps they need arrive.

    :param rewards: R_{t+1}, shape (n_steps_stored, n_envs)
    :param dones: whether the episode ended with step t, shape (n_steps_stored, n_envs)
    :param next_values: bootstrap value after step t, shape (n_steps_stored, n_envs); the last row is only read
        where the episode ended there (otherwise A_{t+1} has not been chosen yet)
    :param gamma: discount factor γ
    :param n_steps: the n of n-step returns, n ≥ 1
    :return: the targets G_{t:t+n} and a boolean mask of the complete ones, both of shape (n_steps_stored, n_envs)
    """
    length = len(rewards)
    steps = np.arange(length)
    targets = np.zeros(rewards.shape, dtype=np.float32)
    complete = np.zeros(rewards.shape, dtype=bool)
    # Targets still accumulating rewards: their episode has not ended in the steps added so far
    alive = np.ones(rewards.shape, dtype=bool)
    discount = 1.0  # γ^k
    for k in range(n_steps):
        # Add the (k+1)-th term for every target t, reading step t+k where it has been taken
        taken = (steps + k < length)[:, None]
        alive &= taken
        rows = np.minimum(steps + k, length - 1)
        targets += np.where(alive, discount * rewards[rows], 0.0)
        # Stop at an episode end, or after n rewards: + γ^{k+1} × bootstrap value (0 after a termination)
        stop = alive & (dones[rows] | (k == n_steps - 1))
        targets += np.where(stop, discount * gamma * next_values[rows], 0.0)
        # q̂(S_{t+k+1}, A_{t+k+1}) is known once step t+k+1 has been taken; an episode end needs no next step
        complete |= stop & (dones[rows] | (steps + k + 1 < length)[:, None])
        alive &= ~dones[rows]
        discount *= gamma
    return targets, complete


def epsilon_greedy_expectation(q_values: np.ndarray | float, epsilon: float) -> np.ndarray:
    """
    V̄(s) = Σ_a π(a|s) q̂(s, a) under the ε-greedy policy π (Sutton & Barto eq. 7.8): the greedy action gets
    probability 1 − ε + ε/|A|, every other action ε/|A|.

    :param q_values: q̂(s, ·), shape (..., n_actions)
    :param epsilon: exploration rate ε
    :return: V̄(s), shape (...)
    """
    q = np.asarray(q_values)
    return (1.0 - epsilon) * q.max(axis=-1) + epsilon * q.mean(axis=-1)


def greedy_random_ties(q_values: np.ndarray) -> np.ndarray:
    """
    argmax_a q̂(s, a) for each row, ties broken uniformly at random (S&B §2.2: "ties broken arbitrarily", which the
    book's code and figures do at random). The RNG (NumPy's global one, seeded by SB3, as DQN's ε-greedy draws) is
    drawn from only where there is a tie, so a network with distinct outputs gets the plain argmax.

    :param q_values: q̂(s, ·), shape (batch, n_actions)
    :return: the greedy actions, shape (batch,), int64
    """
    greedy = q_values.argmax(axis=1)
    is_max = q_values == q_values.max(axis=1, keepdims=True)
    if is_max.sum() > len(q_values):
        for row in np.flatnonzero(is_max.sum(axis=1) > 1):
            greedy[row] = np.random.choice(np.flatnonzero(is_max[row]))
    return greedy
