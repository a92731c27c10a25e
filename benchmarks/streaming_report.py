"""
The results page of ``python -m benchmarks.streaming``: per env, the streaming recipe against the same network with Adam
per step and against the batch entries (``benchmarks/results/learning-runs.csv`` and ``lunar-lander/``), from the runs
recorded in ``benchmarks/results/streaming/``; a figure of the learning curves per env.
"""

import platform
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from benchmarks.report import markdown_table
from benchmarks.streaming import LEVELS, NAMES, RESULTS, WINDOW, current_runs, describe_entry
from sb3_classic.harness.common import code_versions

#: The batch entries' results (``python -m benchmarks.run``), per env
BATCH_RUNS = {
    "CartPole-v1": RESULTS / "learning-runs.csv",
    "Acrobot-v1": RESULTS / "learning-runs.csv",
    "LunarLander-v3": RESULTS / "lunar-lander" / "learning-runs.csv",
}
OPTIMIZERS = {"obgd": "streaming recipe (ObGD)", "adam": "Adam per step"}
#: The runs the page's commands make: (algorithm, env, optimizer), 10 seeds each
PLANNED = [
    *((algo, env_id, optimizer) for algo in NAMES for env_id in ("CartPole-v1", "Acrobot-v1") for optimizer in OPTIMIZERS),
    ("nstep_sarsa", "LunarLander-v3", "obgd"),
]
SEEDS = 10
#: The YAML entries the page describes: those of the planned runs
ENTRIES = list(dict.fromkeys((algo, env_id) for algo, env_id, _ in PLANNED))
COLORS = {
    ("nstep_sarsa", "obgd"): "C0",
    ("nstep_sarsa", "adam"): "C9",
    ("reinforce", "obgd"): "C3",
    ("reinforce", "adam"): "C1",
}


def _median_range(values: pd.Series, total: int) -> str:
    values = values.dropna()
    if len(values) == 0:
        return f"never (0/{total})"
    return f"{values.median():,.0f} ({values.min():,.0f}–{values.max():,.0f}), {len(values)}/{total}"


def stayed(episodes: pd.DataFrame, level: float) -> str:
    """
    :param episodes: the recorded episodes of one algorithm and optimizer (``seed``, ``episode``, ``return``)
    :return: of the ``WINDOW``-episode means after each seed's first one at ``level``, the share still at it, pooled
        over seeds, and the lowest of them
    """
    at = total = 0
    lowest = np.inf
    for _, run in episodes.groupby("seed"):
        means = np.convolve(run.sort_values("episode")["return"].to_numpy(), np.ones(WINDOW) / WINDOW, mode="valid")
        reached = np.flatnonzero(means >= level)
        if len(reached):
            after = means[reached[0] :]
            at, total, lowest = at + int((after >= level).sum()), total + len(after), min(lowest, float(after.min()))
    return f"{at / total:.0%} (lowest {lowest:,.0f})" if total else "–"


def streaming_table(runs: pd.DataFrame, episodes: dict[tuple[str, str], pd.DataFrame], env_id: str) -> pd.DataFrame:
    """:return: one row per (algorithm, optimizer) recorded on ``env_id``, as strings"""
    level = LEVELS[env_id]
    rows = []
    for (algo, optimizer), group in runs[runs["env"] == env_id].groupby(["algo", "optimizer"], sort=False):
        micros = 1e6 * group["cpu_seconds"] / group["steps"]
        first = pd.to_numeric(group["first_at_level"], errors="coerce")
        rows.append(
            {
                "Algorithm": NAMES[algo],
                "Updates": OPTIMIZERS[optimizer],
                "Seeds": len(group),
                f"Last-{WINDOW}-episode mean, mean over seeds": f"{group['last_100'].mean():,.1f}",
                "Lowest seed": f"{group['last_100'].min():,.1f}",
                "Seeds' last-100 means": ", ".join(f"{value:.0f}" for value in group.sort_values("seed")["last_100"]),
                f"First episode with the {WINDOW}-episode mean ≥ {level:g}": _median_range(first, len(group)),
                f"{WINDOW}-episode means at {level:g} after it": stayed(episodes[(algo, optimizer)], level),
                "µs per env step": f"{micros.mean():,.0f} ± {micros.std():,.0f}",
            }
        )
    return pd.DataFrame(rows)


def batch_table(env_id: str) -> pd.DataFrame:
    """:return: the batch entries of our algorithms on ``env_id`` (their own benchmark's measures), as strings"""
    path = BATCH_RUNS[env_id]
    if not path.exists():
        return pd.DataFrame()
    table = pd.read_csv(path)
    rows = []
    for algo, group in table[(table["env_id"] == env_id) & table["algo"].isin(list(NAMES))].groupby("algo", sort=False):
        micros = 1e6 / group["steps_per_s"]
        rows.append(
            {
                "Algorithm": NAMES[algo].split(" ")[0],
                "Seeds": len(group),
                "n_envs": int(group["n_envs"].iloc[0]),
                "Env steps": f"{group['num_timesteps'].median():,.0f}",
                "Final evaluation (10 episodes, deterministic)": f"{group['final_return'].mean():,.1f} ± "
                f"{group['final_return'].std():,.1f}",
                f"Episodes to an evaluation ≥ {LEVELS[env_id]:g}": _median_range(group["episodes_to_threshold"], len(group)),
                "µs per env step (wall, all envs)": f"{micros.mean():,.0f}",
            }
        )
    return pd.DataFrame(rows)


def plot_curves(episodes: dict[tuple[str, str], pd.DataFrame], env_id: str, path: Path) -> None:
    """The ``WINDOW``-episode moving mean of the training return, mean ± std over seeds, per algorithm and optimizer"""
    figure, axes = plt.subplots(figsize=(7, 4))
    for (algo, optimizer), frame in episodes.items():
        curves = []
        for _, run in frame.groupby("seed"):
            returns = run.sort_values("episode")["return"].to_numpy()
            curves.append(np.convolve(returns, np.ones(WINDOW) / WINDOW, mode="valid"))
        length = min(len(curve) for curve in curves)
        stacked = np.stack([curve[:length] for curve in curves])
        x = np.arange(WINDOW, WINDOW + length)
        mean, std = stacked.mean(axis=0), stacked.std(axis=0)
        color = COLORS[(algo, optimizer)]
        label = f"{NAMES[algo]}, {OPTIMIZERS[optimizer]} ({len(curves)} seeds)"
        axes.plot(x, mean, color=color, label=label, linewidth=1.0)
        axes.fill_between(x, mean - std, mean + std, color=color, alpha=0.2, linewidth=0)
    axes.axhline(LEVELS[env_id], color="grey", linestyle=":", linewidth=0.8)
    axes.set_xlabel("episode")
    axes.set_ylabel(f"return, mean of the last {WINDOW} episodes")
    axes.set_title(f"{env_id}: per step, one env (mean ± std over seeds)")
    axes.legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def cost_table(cost: pd.DataFrame) -> pd.DataFrame:
    """
    :param cost: the paired cost runs (``python -m benchmarks.streaming --cost STEPS``)
    :return: per algorithm and env, the µs per env step of each optimizer (median over seeds) and their ratio per seed
        (only the seeds with both recorded), as strings
    """
    rows = []
    for (algo, env_id), group in cost.groupby(["algo", "env"], sort=False):
        micros = group.assign(micros=1e6 * group["cpu_seconds"] / group["steps"]).pivot_table(
            index="seed", columns="optimizer", values="micros", aggfunc="last"
        )
        if not set(OPTIMIZERS) <= set(micros.columns):
            continue
        pairs = micros.dropna(subset=list(OPTIMIZERS))
        if pairs.empty:
            continue
        ratios = pairs["obgd"] / pairs["adam"]
        rows.append(
            {
                "Algorithm": NAMES[algo],
                "Env": env_id,
                "Env steps per run": f"{int(group['steps'].median()):,}",
                "Seeds (pairs)": len(pairs),
                "µs per env step, ObGD (median)": f"{pairs['obgd'].median():,.0f}",
                "µs per env step, Adam (median)": f"{pairs['adam'].median():,.0f}",
                "ObGD / Adam per seed": ", ".join(f"{ratio:.2f}" for ratio in ratios),
                "ObGD / Adam, median (range)": f"{ratios.median():.2f} ({ratios.min():.2f}–{ratios.max():.2f})",
            }
        )
    return pd.DataFrame(rows)


def _still_to_run(runs: pd.DataFrame) -> str:
    """:return: the sentence naming the planned runs not recorded yet (the commands above resume them)"""
    counts = runs.groupby(["algo", "env", "optimizer"]).size()
    left = {planned: SEEDS - int(counts.get(planned, 0)) for planned in PLANNED}
    missing = [
        f"{NAMES[algo].split(' ')[0]} {env_id} {OPTIMIZERS[optimizer]} ({seeds})"
        for (algo, env_id, optimizer), seeds in left.items()
        if seeds > 0
    ]
    return "- Still to run (seeds): " + ", ".join(missing) + "." if missing else "- Every planned run is recorded."


def write_report(out: Path, page: Path) -> None:
    """
    :param out: where ``python -m benchmarks.streaming`` recorded its runs
    :param page: the results page to write (its figures beside it, ``streaming-<env>.png``)
    """
    runs_path = out / "runs.csv"
    if not runs_path.exists() and not (out / "cost.csv").exists():
        print(f"no runs recorded in {out}")
        return
    runs = current_runs(out)
    versions = code_versions("nstep_sarsa")
    lines = [
        "# Per-step deep RL: the streaming recipe",
        "",
        "Produced by (resumable: each finished run is recorded in `benchmarks/results/streaming/`):",
        "",
        "```",
        "python -m benchmarks.streaming --algo nstep_sarsa --env CartPole-v1 Acrobot-v1 --workers 2",
        "python -m benchmarks.streaming --algo reinforce --env CartPole-v1 Acrobot-v1 --workers 2",
        "python -m benchmarks.streaming --algo nstep_sarsa --env LunarLander-v3 --optimizers obgd --workers 2",
        "python -m benchmarks.streaming --report",
        "```",
        "",
        "- Settings: `hyperparams/nstep_sarsa_streaming.yml` (SARSA(λ), λ = 0.8, along eligibility traces under ObGD, "
        "α = 1, κ = 2) and `hyperparams/reinforce_streaming.yml` (the per-step updates of S&B §13.4 each bounded by ObGD, "
        "κ = 3 for the policy, 2 for v̂); networks with sparse initialisation and LayerNorm without parameters; SB3's "
        "`VecNormalize` (observations, and rewards by the running std of the discounted return); one env, one update per "
        "env step (REINFORCE: the episode's per-step updates at its end). Per entry: "
        + "; ".join(f"{NAMES[algo].split(' ')[0]} {env_id}: {describe_entry(algo, env_id)}" for algo, env_id in ENTRIES)
        + ". A run counts while its YAML entry is as it was run (`runs.csv`'s `settings`); a changed one is run anew.",
        "- *Adam per step*: the same network, initialisation and normalisation with Adam (step size 5e-4; SARSA on the "
        "one-step squared TD error, REINFORCE's per-step updates of the same box).",
        "- 1,000 episodes per run, seeds 0–9; the return is the env's (before `VecNormalize`'s scaling).",
        f"- µs per env step: the run's CPU time in `learn()` over its env steps, torch 1 thread ({platform.machine()}, "
        "2 runs in parallel on 2 cores).",
        "- Versions: " + ", ".join(f"{name} {version}" for name, version in versions.items() if name != "sb3_classic") + ".",
        "",
        _still_to_run(runs),
        "",
        "The batch entries (`hyperparams/nstep_sarsa.yml`, `reinforce.yml`) are those of the learning benchmark "
        "(`learning.md`, `lunar-lander/learning.md`), measured by evaluations there: their final deterministic evaluation "
        "and the training episodes by the first evaluation at the level.",
    ]
    for env_id in LEVELS:
        episodes = {}
        for (algo, optimizer), _ in runs[runs["env"] == env_id].groupby(["algo", "optimizer"], sort=False):
            frame = pd.read_csv(out / f"{algo}-{env_id}.csv")
            seeds = runs[(runs["algo"] == algo) & (runs["env"] == env_id) & (runs["optimizer"] == optimizer)]["seed"]
            frame = frame[(frame["optimizer"] == optimizer) & frame["seed"].isin(seeds)]
            frame = frame.drop_duplicates(["seed", "episode"], keep="last")
            episodes[(algo, optimizer)] = frame
        table = streaming_table(runs, episodes, env_id)
        if table.empty:
            continue
        lines += ["", f"## {env_id} (level {LEVELS[env_id]:g})", "", markdown_table(table), ""]
        batch = batch_table(env_id)
        if not batch.empty:
            lines += ["Batch entries:", "", markdown_table(batch), ""]
        figure = page.parent / f"streaming-{env_id}.png"
        plot_curves(episodes, env_id, figure)
        lines += [f"![{env_id}: per-step learning curves]({figure.name})"]
    if (out / "cost.csv").exists():
        table = cost_table(current_runs(out, "cost.csv"))
        if not table.empty:
            lines += [
                "",
                "## Cost per env step, paired",
                "",
                "The µs per env step of the tables above come from long runs that shared the machine with others. Here "
                "each seed's two runs (`python -m benchmarks.streaming --cost STEPS`: both optimizers, the same settings "
                "as above, a fixed number of env steps from the start of training) ran one after the other in one process, "
                "their order alternating from seed to seed, so that their ratio compares them on the same machine and load.",
                "",
                markdown_table(table),
            ]
    page.write_text("\n".join(lines) + "\n")
    print(f"wrote {page}")
