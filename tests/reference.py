"""Slow, obvious transcriptions of the book's returns and targets, and random trajectories to check against."""

import numpy as np


def random_trajectories(rng: np.random.Generator, n_steps: int, n_envs: int, p_end: float = 0.15) -> dict[str, np.ndarray]:
    """Steps of several envs with random rewards and episode ends, some of them time-limit truncations."""
    dones = rng.random((n_steps, n_envs)) < p_end
    return dict(
        rewards=rng.normal(size=(n_steps, n_envs)).astype(np.float32),
        dones=dones,
        truncated=dones & (rng.random((n_steps, n_envs)) < 0.5),
        # q̂(S_t, A_t) of each step, and v̂ of the final state where an episode was truncated
        q_taken=rng.normal(size=(n_steps, n_envs)).astype(np.float32),
        final_values=rng.normal(size=(n_steps, n_envs)).astype(np.float32),
    )


def episodes_of(dones: np.ndarray) -> list[tuple[int, int, bool]]:
    """(first step, last step, ended) of each episode of one env; the last one may still be running."""
    episodes, start = [], 0
    for t, done in enumerate(dones):
        if done:
            episodes.append((start, t, True))
            start = t + 1
    if start < len(dones):
        episodes.append((start, len(dones) - 1, False))
    return episodes


def reference_mc_returns(traj: dict[str, np.ndarray], env: int, gamma: float) -> dict[int, float]:
    """G_t = Σ_{k=t+1}^{T} γ^{k−t−1} R_k (S&B §13.3), plus γ^{T−t} v̂(S_T) after a truncation; ended episodes only."""
    rewards, truncated = traj["rewards"][:, env], traj["truncated"][:, env]
    returns = {}
    for first, last, ended in episodes_of(traj["dones"][:, env]):
        if not ended:
            continue
        for t in range(first, last + 1):
            g = sum(gamma ** (k - t) * rewards[k] for k in range(t, last + 1))
            if truncated[last]:
                g += gamma ** (last + 1 - t) * traj["final_values"][last, env]
            returns[t] = g
    return returns


def reference_nstep_targets(traj: dict[str, np.ndarray], env: int, gamma: float, n: int) -> dict[int, float]:
    """
    The book's n-step SARSA target for each τ whose target is computable (S&B §10.2 box):
    G = Σ_{i=τ+1}^{min(τ+n, T)} γ^{i−τ−1} R_i; if τ + n < T: G += γ^n q̂(S_{τ+n}, A_{τ+n}),
    extended to a truncated episode by bootstrapping from v̂ of its final state.
    """
    rewards, q_taken, truncated = traj["rewards"][:, env], traj["q_taken"][:, env], traj["truncated"][:, env]
    targets = {}
    for first, last, ended in episodes_of(traj["dones"][:, env]):
        # Times are relative to the episode start: S_0 at step `first`, R_i = rewards[first + i − 1]
        big_t = last - first + 1 if ended else None
        for tau in range(last - first + 1):
            if big_t is None and tau + n > last - first:
                continue  # S_{τ+n}, A_{τ+n} not taken yet
            horizon = tau + n if big_t is None else min(tau + n, big_t)
            g = sum(gamma ** (i - tau - 1) * rewards[first + i - 1] for i in range(tau + 1, horizon + 1))
            if big_t is None or tau + n < big_t:
                g += gamma**n * q_taken[first + tau + n]
            elif truncated[last]:
                g += gamma ** (big_t - tau) * traj["final_values"][last, env]
            targets[first + tau] = g
    return targets


def reference_lambda_targets(traj: dict[str, np.ndarray], env: int, gamma: float, n: int, lam: float) -> dict[int, float]:
    """
    The truncated λ-return of each τ whose n-step target is computable, by the book's weighted sum (S&B eq. 12.9):
    G^λ_{τ:h} = (1 − λ) Σ_{k=1}^{n−1} λ^{k−1} G_{τ:τ+k} + λ^{n−1} G_{τ:τ+n}, with h = τ + n; where the episode ends
    first, G_{τ:τ+k} is the return to its end for every k past it (eq. 12.9 with h = T gives the same).
    """
    by_k = [reference_nstep_targets(traj, env, gamma, k) for k in range(1, n + 1)]
    return {
        tau: (1 - lam) * sum(lam ** (k - 1) * by_k[k - 1][tau] for k in range(1, n)) + lam ** (n - 1) * g
        for tau, g in by_k[-1].items()
    }


def bootstrap_values(traj: dict[str, np.ndarray], unknown: float = np.nan) -> np.ndarray:
    """next_values as the algorithms build them: q̂(S_{t+1}, A_{t+1}), 0 at a termination, v̂ at a truncation."""
    next_values = np.full_like(traj["rewards"], unknown)
    next_values[:-1] = traj["q_taken"][1:]
    next_values[traj["dones"]] = 0.0
    next_values[traj["truncated"]] = traj["final_values"][traj["truncated"]]
    return next_values
