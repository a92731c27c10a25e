"""
NumPy transcriptions of the book's boxes, to check ``benchmarks/textbook.py``'s numbers against the algorithms without
the package: n-step TD on the 19-state random walk (S&B §7.1, Fig 7.2), and REINFORCE on the short corridor (§13.3
and §13.4, Figs 13.1–13.2) with the same features (x(s, right) = [1, 0], x(s, left) = [0, 1]), the same initial
θ = (θ_right, θ_left) = (−1.47, 1.47), γ = 1, per-step updates; and episodic semi-gradient n-step SARSA on Mountain
Car (§10.2, Figs 10.3–10.4) with the tiles of ``benchmarks/textbook.py`` (8 tilings of 8 × 8, tiles3's offsets).

    python -m benchmarks.textbook_numpy                 # Figs 7.2's, 10.4's and 13.2's numbers (about 15 minutes)
    python -m benchmarks.textbook_numpy --clamp         # with the book's code's π ≥ 0.05

The per-run means of REINFORCE with baseline over episodes 1–100 are heavy-tailed (a run now and then has an
episode of thousands of steps): this prints their median and worst values beside the mean.
"""

import argparse
import math
import sys

import gymnasium as gym
import numpy as np

import sb3_classic  # noqa: F401  (registers sb3_classic/MountainCarNoLimit-v0)


def corridor_reinforce(
    seed: int, episodes: int, alpha_theta: float, alpha_w: float | None = None, clamp: bool = False, max_length: int = 50_000
) -> np.ndarray:
    """
    The box of §13.3 (``alpha_w=None``) or §13.4 on the short corridor with switched actions (Example 13.1).

    :param clamp: keep each action's probability ≥ 0.05, as the book's code does (the pseudocode does not)
    :param max_length: stop the run at an episode this long (it never ends once π has rounded to 0 or 1)
    :return: the return of each episode (fewer than ``episodes`` if the run was stopped)
    """
    rng = np.random.default_rng(seed)
    theta = np.array([-1.47, 1.47])  # (right, left)
    w = 0.0
    returns: list[float] = []

    def policy() -> np.ndarray:
        z = np.exp(theta - theta.max())
        p = z / z.sum()
        if clamp and p.min() < 0.05:
            p = np.where(p == p.min(), 0.05, 0.95)
        return p

    for _ in range(episodes):
        state, actions = 0, []
        while state != 3:
            right = rng.random() < policy()[0]
            actions.append(0 if right else 1)
            move = 1 if right else -1
            state = max(0, state + (-move if state == 1 else move))  # s1 switches the actions
            if len(actions) >= max_length:
                return np.array(returns, dtype=float)
        big_t = len(actions)
        for t in range(big_t):  # t = 0, …, T − 1
            g = -(big_t - t)  # G_t: −1 per step, γ = 1
            delta = g - (w if alpha_w is not None else 0.0)  # δ ← G − v̂(S_t, w), or G without baseline
            if alpha_w is not None:
                w += alpha_w * delta  # w ← w + α^w δ ∇v̂, ∇v̂ = 1
            grad_ln_pi = -policy()  # ∇ln π(A_t|S_t, θ) = x(s, A_t) − Σ_b π(b) x(s, b)  (eq. 13.9)
            grad_ln_pi[actions[t]] += 1.0
            theta = theta + alpha_theta * delta * grad_ln_pi
        returns.append(-big_t)
    return np.array(returns, dtype=float)


RANDOM_WALK_TRUE_VALUES = np.arange(-9, 10) / 10


def random_walk_td(seed: int, n: int, alpha: float, episodes: int = 10) -> np.ndarray:
    """
    The box of §7.2 (n-step TD for estimating V ≈ v_π) on the 19-state random walk of Example 7.1, V = 0 initially.

    :return: the RMS error over the 19 states after each episode
    """
    rng = np.random.default_rng(seed)
    values = np.zeros(21)  # states 0 and 20 are the terminal ones
    errors = []
    for _ in range(episodes):
        states, rewards, big_t, t = [10], [0.0], math.inf, 0
        while True:
            if t < big_t:
                state = states[-1] + (1 if rng.random() < 0.5 else -1)
                states.append(state)
                rewards.append(-1.0 if state == 0 else 1.0 if state == 20 else 0.0)
                if state in (0, 20):
                    big_t = t + 1
            tau = t - n + 1
            if tau >= 0:
                g = sum(rewards[tau + 1 : int(min(tau + n, big_t)) + 1])  # γ = 1
                if tau + n < big_t:
                    g += values[states[tau + n]]
                values[states[tau]] += alpha * (g - values[states[tau]])
            if tau == big_t - 1:
                break
            t += 1
        errors.append(math.sqrt(np.mean((values[1:20] - RANDOM_WALK_TRUE_VALUES) ** 2)))
    return np.array(errors)


MOUNTAIN_CAR_LOW, MOUNTAIN_CAR_HIGH = np.array([-1.2, -0.07]), np.array([0.5, 0.07])
N_TILINGS, TILES = 8, 8


def mountain_car_sarsa(
    seed: int, n: int, alpha: float, episodes: int | None = None, total_steps: int | None = None
) -> list[int]:
    """
    The box of §10.2 (episodic semi-gradient n-step SARSA, ε = 0, greedy ties at random, γ = 1, w = 0 initially) on
    Mountain Car without its time limit, with the tiles of Example 10.1's footnote (8 tilings of 8 × 8, tiles3's
    asymmetric offsets, grid from 0; no hashing).

    :param episodes: stop after this many episodes
    :param total_steps: or stop at the end of the episode running when this many env steps have been taken
    :return: the length of every episode run
    """
    env = gym.make("sb3_classic/MountainCarNoLimit-v0")
    rng = np.random.default_rng(seed)
    low, high = MOUNTAIN_CAR_LOW, MOUNTAIN_CAR_HIGH
    offsets = np.arange(N_TILINGS)[:, None] * np.array([1, 3])  # tiling t displaced by t·(1, 3)/8 of a tile
    first = np.floor((np.floor(TILES * low / (high - low) * N_TILINGS) + offsets) / N_TILINGS)
    size = TILES + 2  # tiles of one tiling along each dimension, enough for the range from any origin
    w = np.zeros((3, N_TILINGS * size * size))

    def tiles(s: np.ndarray) -> np.ndarray:
        q = np.floor(TILES * np.clip(s, low, high) / (high - low) * N_TILINGS)
        c = np.floor((q + offsets) / N_TILINGS) - first
        return np.arange(N_TILINGS) * size * size + (c[:, 0] * size + c[:, 1]).astype(np.int64)

    def greedy(x: np.ndarray) -> int:
        q = w[:, x].sum(axis=1)
        return int(rng.choice(np.flatnonzero(q == q.max())))

    lengths: list[int] = []
    steps = 0
    obs, _ = env.reset(seed=seed)
    while (episodes is None or len(lengths) < episodes) and (total_steps is None or steps < total_steps):
        xs, actions, rewards = [tiles(obs)], [greedy(tiles(obs))], [0.0]
        big_t, t = math.inf, 0
        while True:
            if t < big_t:
                obs, reward, terminated, _, _ = env.step(actions[t])
                steps += 1
                rewards.append(float(reward))
                if terminated:
                    big_t = t + 1
                else:
                    xs.append(tiles(obs))
                    actions.append(greedy(xs[-1]))
            tau = t - n + 1
            if tau >= 0:
                g = sum(rewards[tau + 1 : int(min(tau + n, big_t)) + 1])  # γ = 1
                if tau + n < big_t:
                    g += w[actions[tau + n], xs[tau + n]].sum()
                x, a = xs[tau], actions[tau]
                w[a, x] += alpha * (g - w[a, x].sum())  # ∇q̂ = x(S_τ, A_τ), binary
            if tau == big_t - 1:
                break
            t += 1
        lengths.append(int(big_t))
        obs, _ = env.reset()
    return lengths


#: Fig 10.4's settings run by ``main``: n and α × 8 around each n's optimum (the package's grid in textbook.py)
FIG_10_4_GRID = {1: (0.9, 1.1, 1.3, 1.5), 2: (0.7, 0.9, 1.1), 4: (0.5, 0.7, 0.9), 8: (0.3, 0.4, 0.5), 16: (0.2, 0.3)}


def summary(per_run: list[float], runs: int, digits: int = 2) -> str:
    values = np.array(per_run)
    se = values.std(ddof=1) / math.sqrt(len(values))
    return (
        f"{values.mean():.{digits}f} ± {se:.{digits}f} ({len(values)} runs of {runs}), median {np.median(values):.{digits}f}, "
        f"extremes {np.sort(values)[[0, -1]].round(digits).tolist()}"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--clamp", action="store_true", help="keep π ≥ 0.05 as the book's code does")
    parser.add_argument("--baseline-runs", type=int, default=2000)
    parser.add_argument("--plain-runs", type=int, default=100)
    parser.add_argument("--walk-runs", type=int, default=400)
    parser.add_argument("--mountain-car-runs", type=int, default=30)
    args = parser.parse_args(argv)
    for n, alphas in FIG_10_4_GRID.items():
        for alpha8 in alphas:
            per_run = [
                float(np.mean(mountain_car_sarsa(k, n, alpha8 / 8, episodes=50))) for k in range(args.mountain_car_runs)
            ]
            print(f"n-step SARSA n={n}, α={alpha8}/8, steps per episode 1–50: {summary(per_run, args.mountain_car_runs, 1)}")
    for n, alpha, book in ((4, 0.4, "0.266 ± 0.003"), (16, 0.1, "0.324")):
        per_run = [float(random_walk_td(k, n, alpha).mean()) for k in range(args.walk_runs)]
        print(f"n-step TD n={n}, α={alpha}, RMS of episodes 1–10 (book {book}): {summary(per_run, args.walk_runs, 4)}")
    baseline = [corridor_reinforce(k, 100, 2**-9, 2**-6, args.clamp) for k in range(args.baseline_runs)]
    complete = [r[:100].mean() for r in baseline if len(r) >= 100]
    print(f"with baseline α^θ=2^-9, α^w=2^-6, episodes 1–100 (book −20.5 ± 0.7): {summary(complete, len(baseline))}")
    plain = [corridor_reinforce(k, 500, 2**-13, None, args.clamp) for k in range(args.plain_runs)]
    complete = [r[400:500].mean() for r in plain if len(r) >= 500]
    print(f"plain α=2^-13, episodes 401–500 (book −15.1 ± 0.2): {summary(complete, len(plain))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
