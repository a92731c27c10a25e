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

import functools
from typing import NamedTuple

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


class NStepWindows(NamedTuple):
    """
    The n-step window of every stored transition (S&B eq. 10.4), all of shape (n_steps_stored, n_envs):
    G_{t:t+n} = ``reward_sums[t]`` + ``bootstrap_discounts[t]`` × (the bootstrap value after step ``stop_rows[t]``).
    """

    reward_sums: np.ndarray  #: R_{t+1} + γR_{t+2} + … over the window's rewards, float32
    stop_rows: np.ndarray  #: the step whose reward is the window's last: its episode's end, or t + n − 1 (int64)
    bootstrap_discounts: np.ndarray  #: γ^K for a window of K rewards (float32)
    complete: np.ndarray  #: whether the target is known (bool)


def nstep_windows(rewards: np.ndarray, dones: np.ndarray, gamma: float, n_steps: int) -> NStepWindows:
    """
    The windows of n-step returns of semi-gradient n-step SARSA (Sutton & Barto §10.2, eq. 10.4): the target of step t
    sums the rewards R_{t+1}, …, R_{t+K} with K = n, or fewer where the episode ends first, and bootstraps after its
    last step (0 after a termination, the final state's value after a time-limit truncation, q̂(S_{t+n}, A_{t+n})
    otherwise). Vectorised over t and envs, a loop over k < min(n, steps held).

    A target is complete when the episode ended within its n steps, or when step t+n has been taken (so that
    A_{t+n}, and q̂(S_{t+n}, A_{t+n}), is known). Incomplete targets are never shortened: the caller keeps those
    transitions until the steps they need arrive.

    :param rewards: R_{t+1}, shape (n_steps_stored, n_envs)
    :param dones: whether the episode ended with step t, shape (n_steps_stored, n_envs)
    :param gamma: discount factor γ
    :param n_steps: the n of n-step returns, n ≥ 1
    :return: the windows (see ``NStepWindows``)
    """
    length = len(rewards)
    steps = np.arange(length)
    # Step t + k of the k-th reward of target t (k = 0, …, n − 1), where it has been taken; no k reaches past the
    # stored steps (k < length), so a large n costs no more than the steps held
    n_terms = min(n_steps, length)
    rows = steps[:, None] + np.arange(n_terms)
    taken = rows < length
    np.minimum(rows, length - 1, out=rows)
    ends = dones[rows]  # (t, k, env): the episode ended with step t + k
    ends &= taken[..., None]
    # The k-th reward belongs to the target if step t + k was taken and no episode end came before it
    included = np.empty_like(ends)
    included[:, 0] = True
    np.logical_not(np.logical_or.accumulate(ends[:, :-1], axis=1), out=included[:, 1:])
    included &= taken[..., None]
    # γ^k by repeated products (k = 0, …, K), and the bootstrap's discount γ^K after K rewards
    discounts = gamma_powers(gamma, n_terms)
    # R_{t+1} + γR_{t+2} + … + γ^{K−1}R_{t+K} (eq. 10.4 without its bootstrap term), summed term by term in float32 in
    # the order of k (accumulate is sequential), so that the targets are the same to the last bit whatever the batch
    terms = rewards[rows] * discounts[:n_terms, None]
    terms[~included] = 0.0
    reward_sums = np.add.accumulate(terms, axis=1)[:, -1]
    n_rewards = included.sum(axis=1)  # K ≥ 1: the first reward is always there
    stop_rows = steps[:, None] + n_rewards - 1
    # The window ended with an episode if its last reward's step ended one
    ended = np.take_along_axis(ends, n_rewards[:, None] - 1, axis=1)[:, 0]
    # q̂(S_{t+n}, A_{t+n}) is known once step t+n has been taken; an episode end needs no next step
    complete = ended | ((n_rewards == n_steps) & (stop_rows + 1 < length))
    return NStepWindows(
        reward_sums=reward_sums,
        stop_rows=stop_rows,
        bootstrap_discounts=discounts[n_rewards],
        complete=complete,
    )


class NStepWindow(NamedTuple):
    """The n-step window of one transition: ``NStepWindows`` at one ``[t, env]``."""

    reward_sum: np.float32  #: R_{t+1} + γR_{t+2} + … over the window's rewards
    stop_row: int  #: the step whose reward is the window's last
    bootstrap_discount: np.float32  #: γ^K for a window of K rewards
    complete: bool  #: whether the target is known


@functools.lru_cache(maxsize=64)
def gamma_powers(gamma: float, n_steps: int) -> np.ndarray:
    """
    :param gamma: discount factor γ
    :param n_steps: the highest power n
    :return: γ^0, …, γ^n by repeated products in float64, as float32, shape (n + 1,), read-only (cached)
    """
    powers = np.cumprod(np.concatenate(([1.0], np.full(n_steps, gamma)))).astype(np.float32)
    powers.setflags(write=False)
    return powers


def nstep_window(rewards: np.ndarray, dones: np.ndarray, t: int, discounts: np.ndarray, n_steps: int) -> NStepWindow:
    """
    The window of one transition of one env, to the last bit what ``nstep_windows`` gives at ``[t, env]`` (S&B
    eq. 10.4, the same float32 sums in the same order), at a cost that grows with n instead of n × the steps held: the
    per-step mode with one env trains one or a few transitions per env step, for which the ~30 NumPy calls of
    ``nstep_windows`` over the n + 1 steps held cost more than the gradient step's Python overhead with a small n,
    and more than the gradient step itself with a large one (n = 512: 512 × 512 entries per env step).

    :param rewards: R_{t+1} of one env, shape (n_steps_stored,), float32
    :param dones: whether the episode ended with step t, shape (n_steps_stored,)
    :param t: the transition's step
    :param discounts: ``gamma_powers(gamma, n_steps)``
    :param n_steps: the n of n-step returns, n ≥ 1
    :return: the window (see ``NStepWindow``)
    """
    # K rewards: up to the first episode end in the window, else as many of the n as have been taken
    ends = np.flatnonzero(dones[t : t + n_steps])
    n_rewards = int(ends[0]) + 1 if len(ends) else min(n_steps, len(rewards) - t)
    return _window(rewards, t, n_rewards, len(ends) > 0, discounts, n_steps)


def _window(rewards: np.ndarray, t: int, n_rewards: int, ended: bool, discounts: np.ndarray, n_steps: int) -> NStepWindow:
    """``nstep_window`` of a window of ``n_rewards`` rewards, ending an episode or not (``ended``)."""
    # R_{t+1} + γR_{t+2} + … + γ^{K−1}R_{t+K}: float32 terms summed in order (accumulate is sequential)
    reward_sum = np.add.accumulate(rewards[t : t + n_rewards] * discounts[:n_rewards])[-1]
    stop_row = t + n_rewards - 1
    # q̂(S_{t+n}, A_{t+n}) is known once step t+n has been taken; an episode end needs no next step
    complete = ended or (n_rewards == n_steps and stop_row + 1 < len(rewards))
    return NStepWindow(reward_sum, stop_row, discounts[n_rewards], complete)


def nstep_targets(
    rewards: np.ndarray, dones: np.ndarray, next_values: np.ndarray, gamma: float, n_steps: int
) -> tuple[np.ndarray, np.ndarray]:
    """
    n-step returns of semi-gradient n-step SARSA (Sutton & Barto §10.2, eq. 10.4):

    G_{t:t+n} = R_{t+1} + γ R_{t+2} + … + γ^{n−1} R_{t+n} + γ^n q̂(S_{t+n}, A_{t+n}),

    and G_{t:t+n} = G_t when the episode ends first (no bootstrap past a termination; a time-limit truncation
    bootstraps from ``next_values`` at the step where it happened). See ``nstep_windows`` for when a target is
    complete.

    :param rewards: R_{t+1}, shape (n_steps_stored, n_envs)
    :param dones: whether the episode ended with step t, shape (n_steps_stored, n_envs)
    :param next_values: bootstrap value after step t, shape (n_steps_stored, n_envs); the last row is only read
        where the episode ended there (otherwise A_{t+1} has not been chosen yet)
    :param gamma: discount factor γ
    :param n_steps: the n of n-step returns, n ≥ 1
    :return: the targets G_{t:t+n} and a boolean mask of the complete ones, both of shape (n_steps_stored, n_envs)
    """
    windows = nstep_windows(rewards, dones, gamma, n_steps)
    bootstrap = np.take_along_axis(next_values, windows.stop_rows, axis=0)
    targets = nstep_returns(windows.reward_sums, windows.bootstrap_discounts, bootstrap.astype(np.float32))
    return targets.astype(np.float32), windows.complete


def nstep_returns(reward_sums: np.ndarray, bootstrap_discounts: np.ndarray, bootstrap: np.ndarray) -> np.ndarray:
    """
    :param reward_sums: R_{t+1} + γR_{t+2} + … + γ^{K−1}R_{t+K} of each window of K rewards, float32
    :param bootstrap_discounts: γ^K of each, float32
    :param bootstrap: the value each bootstraps from after its last reward (0 after a termination), float32
    :return: G_{t:t+n} (S&B eq. 10.4), float32, of the arrays' shape
    """
    # G_{t:t+n} = R_{t+1} + γR_{t+2} + … + γ^{n−1}R_{t+n} + γ^n q̂(S_{t+n}, A_{t+n}) (S&B eq. 10.4)
    return reward_sums + bootstrap_discounts * bootstrap


class CompletedWindows(NamedTuple):
    """
    The n-step windows of the transitions not trained on yet whose targets are known, all of shape (B,), in time order
    (row-major: step t of every env, then step t + 1): ``NStepWindows`` at those ``[rows, envs]``.
    """

    rows: np.ndarray  #: the step t of each transition (int64)
    envs: np.ndarray  #: its env (int64)
    stop_rows: np.ndarray  #: the step whose reward is its window's last (int64)
    reward_sums: np.ndarray  #: R_{t+1} + γR_{t+2} + … over the window's rewards, float32
    bootstrap_discounts: np.ndarray  #: γ^K for a window of K rewards (float32)


def completed_windows(
    rewards: np.ndarray, dones: np.ndarray, start: np.ndarray, gamma: float, n_steps: int
) -> CompletedWindows:
    """
    The windows (S&B eq. 10.4) of every transition not trained on yet (``t >= start[env]``) whose target is known
    (``NStepWindows.complete``). The pending transitions of an env complete in time order, so those returned are the
    first pending ones of each env.

    With one env and at most n + 1 pending steps (the book's loop: an update at every env step), each window is
    computed alone (``nstep_window``): the same bits as ``nstep_windows``, whose arrays over the buffer would cost more
    than the gradient step's own overhead at every env step.

    :param rewards: R_{t+1}, shape (n_steps_stored, n_envs)
    :param dones: whether the episode ended with step t, shape (n_steps_stored, n_envs)
    :param start: the first step not trained on yet, per env, shape (n_envs,)
    :param gamma: discount factor γ
    :param n_steps: the n of n-step returns, n ≥ 1
    :return: the windows (see ``CompletedWindows``), B = 0 if none is complete
    """
    length, n_envs = rewards.shape
    if n_envs == 1 and length - int(start[0]) <= n_steps + 1:
        return _windows_one_at_a_time(rewards, dones, int(start[0]), gamma, n_steps)
    return _windows_vectorised(rewards, dones, start, gamma, n_steps)


def _windows_one_at_a_time(rewards: np.ndarray, dones: np.ndarray, first: int, gamma: float, n_steps: int) -> CompletedWindows:
    """``completed_windows`` of one env from step ``first`` on, each window computed alone (``nstep_window``)."""
    discounts = gamma_powers(gamma, n_steps)
    env_rewards, env_dones = rewards[:, 0], dones[:, 0]
    if np.count_nonzero(env_dones[first:]):
        # An episode ended: the pending transitions up to it complete together (the complete ones are a prefix)
        windows = []
        for t in range(first, len(rewards)):
            window = nstep_window(env_rewards, env_dones, t, discounts, n_steps)
            if not window.complete:
                break
            windows.append(window)
    else:
        # Without an episode end, each window holds n rewards, and G_{t:t+n} is known once step t+n has been taken
        # (S_{t+n}, A_{t+n} stored)
        last = len(rewards) - n_steps
        windows = [_window(env_rewards, t, n_steps, False, discounts, n_steps) for t in range(first, last)]
    # (one array of the integer columns and one of the float32 ones, whose values are float32 already: the columns are
    # views, and the per-step mode makes these at every env step)
    steps = np.array([(t, 0, window.stop_row) for t, window in enumerate(windows, first)], np.int64).reshape(-1, 3)
    pairs = [(window.reward_sum, window.bootstrap_discount) for window in windows]
    sums_and_discounts = np.array(pairs, np.float32).reshape(-1, 2)
    return CompletedWindows(
        rows=steps[:, 0],
        envs=steps[:, 1],
        stop_rows=steps[:, 2],
        reward_sums=sums_and_discounts[:, 0],
        bootstrap_discounts=sums_and_discounts[:, 1],
    )


def _windows_vectorised(
    rewards: np.ndarray, dones: np.ndarray, start: np.ndarray, gamma: float, n_steps: int
) -> CompletedWindows:
    """``completed_windows`` from ``nstep_windows`` over every stored step."""
    windows = nstep_windows(rewards, dones, gamma, n_steps)
    rows, envs = np.nonzero(windows.complete & (np.arange(len(rewards))[:, None] >= start))  # row-major: time order
    return CompletedWindows(
        rows=rows,
        envs=envs,
        stop_rows=windows.stop_rows[rows, envs],
        reward_sums=windows.reward_sums[rows, envs],
        bootstrap_discounts=windows.bootstrap_discounts[rows, envs],
    )


def sarsa_targets(
    windows: CompletedWindows,
    bootstrap: np.ndarray,
    rewards: np.ndarray,
    step_values: np.ndarray | None,
    gamma: float,
    td_lambda: float,
) -> np.ndarray:
    """
    The targets of n-step SARSA's transitions: G_{t:t+n} (S&B eq. 10.4), or with λ < 1 the truncated λ-return
    G^λ_{t:t+n} over the same window (eq. 12.9, ``truncated_lambda_returns``).

    :param windows: the transitions' windows
    :param bootstrap: the value each window bootstraps from after its last reward: q̂(S_{t+n}, A_{t+n}) (or the
        ε-greedy expectation) while the episode goes on, 0 after a termination, the final state's value after a
        time-limit truncation; shape (B,), float32
    :param rewards: R_{t+1}, shape (n_steps_stored, n_envs) (λ < 1 only)
    :param step_values: q̂(S_t, A_t) (or the expectation) of every stored step t, shape (n_steps_stored, n_envs):
        what G^λ bootstraps from inside a window; None for λ = 1, or for windows of one reward (n = 1), whose λ-return
        is the one-step return G_{t:t+1} whatever λ (eq. 12.9)
    :param gamma: discount factor γ
    :param td_lambda: λ in [0, 1]
    :return: the targets, shape (B,), float32
    """
    if td_lambda == 1.0 or step_values is None:
        return nstep_returns(windows.reward_sums, windows.bootstrap_discounts, bootstrap)
    # The value after each step k of a window: q̂(S_{k+1}, A_{k+1}), and its bootstrap after the window's last
    next_values = np.zeros_like(step_values)
    next_values[:-1] = step_values[1:]
    next_values[windows.stop_rows, windows.envs] = bootstrap
    return truncated_lambda_returns(rewards, next_values, windows.rows, windows.envs, windows.stop_rows, gamma, td_lambda)


def truncated_lambda_returns(
    rewards: np.ndarray,
    next_values: np.ndarray,
    rows: np.ndarray,
    envs: np.ndarray,
    stop_rows: np.ndarray,
    gamma: float,
    td_lambda: float,
) -> np.ndarray:
    """
    Truncated λ-returns over the n-step windows of ``nstep_windows`` (Sutton & Barto §12.3, eq. 12.9): for the window
    of transition t, whose last reward is at step h − 1 (``stop_rows``, so h = t + n, or the episode's end),

    G^λ_{t:h} = (1 − λ) Σ_{k=1}^{h−t−1} λ^{k−1} G_{t:t+k} + λ^{h−t−1} G_{t:h},

    the window's k-step returns averaged with weights (1 − λ)λ^{k−1}, and λ^{h−t−1} for the longest: λ = 1 gives the
    n-step return G_{t:t+n} (eq. 10.4), λ = 0 the one-step return. Computed backwards through each window with the recursion
    G^λ_{k:h} = R_{k+1} + γ[(1 − λ) q̂(S_{k+1}, A_{k+1}) + λ G^λ_{k+1:h}] from G^λ_{h−1:h} = R_h + γ × (the window's
    bootstrap value), in float64, vectorised over the windows (a loop over k < n). CleanRL's PQN uses the same
    recursion over whole rollouts (Q(λ), with max_a q̂).

    :param rewards: R_{t+1}, shape (n_steps_stored, n_envs)
    :param next_values: the value after step t: q̂(S_{t+1}, A_{t+1}) (or the ε-greedy expectation) inside a window,
        and at each window's last step its bootstrap value (0 after a termination, the final state's after a
        truncation), shape (n_steps_stored, n_envs); read only at the windows' steps
    :param rows: the first step t of each window, shape (B,)
    :param envs: the env of each window, shape (B,)
    :param stop_rows: the step of each window's last reward, shape (B,), ``stop_rows >= rows``
    :param gamma: discount factor γ
    :param td_lambda: λ in [0, 1]
    :return: G^λ_{t:h} of each window, shape (B,), float32
    """
    rewards = rewards.astype(np.float64)
    next_values = next_values.astype(np.float64)
    returns = rewards[stop_rows, envs] + gamma * next_values[stop_rows, envs]
    lengths = stop_rows - rows + 1
    for k in range(int(lengths.max(initial=1)) - 2, -1, -1):
        # Step t + k of each window that has a later step (the others keep their return)
        inside = k < lengths - 1
        step = np.where(inside, rows + k, stop_rows)
        # G^λ_{k:h} = R_{k+1} + γ[(1 − λ) q̂(S_{k+1}, A_{k+1}) + λ G^λ_{k+1:h}] (S&B eq. 12.9, recursively)
        earlier = rewards[step, envs] + gamma * ((1.0 - td_lambda) * next_values[step, envs] + td_lambda * returns)
        returns = np.where(inside, earlier, returns)
    return returns.astype(np.float32)


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


def masked_epsilon_greedy_expectation(q_values: np.ndarray, action_masks: np.ndarray, epsilon: float) -> np.ndarray:
    """
    V̄(s) = Σ_a π(a|s) q̂(s, a) under the ε-greedy policy over the legal actions L(s) (Sutton & Barto eq. 7.8):
    π(a|s) = (1 − ε)·1[a greedy among L(s)] + ε/|L(s)| for a in L(s), 0 otherwise. So
    V̄(s) = (1 − ε) max_{a ∈ L(s)} q̂(s, a) + ε mean_{a ∈ L(s)} q̂(s, a): an illegal action's q̂ never enters it. With
    every action legal it is ``epsilon_greedy_expectation`` to the bit.

    :param q_values: q̂(s, ·), shape (..., n_actions)
    :param action_masks: the legal actions, shape (..., n_actions), boolean, each row with at least one
    :param epsilon: exploration rate ε
    :return: V̄(s), shape (...)
    """
    q = np.asarray(q_values)
    greedy = np.where(action_masks, q, -np.inf).max(axis=-1)
    # The mean as NumPy's mean computes it (a sum, then a division in q's precision)
    mean = np.where(action_masks, q, 0).sum(axis=-1) / np.count_nonzero(action_masks, axis=-1).astype(q.dtype)
    return (1.0 - epsilon) * greedy + epsilon * mean


def greedy_random_ties(q_values: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
    """
    argmax_a q̂(s, a) for each row, ties broken uniformly at random (S&B §2.2: "ties broken arbitrarily", which the
    book's code and figures do at random). The RNG (NumPy's global one, seeded by SB3, as DQN's ε-greedy draws) is
    drawn from only where there is a tie, so a network with distinct outputs gets the plain argmax.

    :param q_values: q̂(s, ·), shape (batch, n_actions)
    :param rng: the generator to break ties with; None: NumPy's global one
    :return: the greedy actions, shape (batch,), int64
    """
    greedy = q_values.argmax(axis=1)
    # Each row's greatest value; with one env (the book's loop, at every env step) its argmax's, read without a
    # reduction over the array, which costs more than the rest of the check
    greatest = q_values[0, greedy[0]] if len(q_values) == 1 else q_values.max(axis=1, keepdims=True)
    is_max = q_values == greatest
    if np.count_nonzero(is_max) > len(q_values):
        for row in np.flatnonzero(is_max.sum(axis=1) > 1):
            ties = np.flatnonzero(is_max[row])
            greedy[row] = np.random.choice(ties) if rng is None else rng.choice(ties)
    return greedy
