"""
Why a seed of REINFORCE never leaves −500 on Acrobot-v1 with the YAML settings, and which change fixes it.

    python -m benchmarks.diagnostics.reinforce_acrobot --list
    python -m benchmarks.diagnostics.reinforce_acrobot --variants yaml --seeds 0-29 --steps 30000   # the seed scan
    python -m benchmarks.diagnostics.reinforce_acrobot --variants yaml,ent_0.01 --seeds 0-4,9

Each evaluation records, over the states the deterministic policy visits: the policy's ``entropy`` (ln 3 ≈ 1.10 is
uniform) and largest action probability ``p_max``, v̂ (``value``), the return-to-go actually obtained (``g_true``)
and ``bias`` = v̂ − g_true. Each update records (``updates.csv``) the entropy over its batch, the value loss, the
explained variance of v̂ and the return of the last training episode.
"""

from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.diagnostics.candidates import RecordedREINFORCE, reinforce_probe
from benchmarks.diagnostics.common import Variant, load_evals, run_study

VARIANTS = [
    Variant("yaml", RecordedREINFORCE, {}, "hyperparams/reinforce.yml as committed"),
    Variant("ent_0.01", RecordedREINFORCE, {"ent_coef": 0.01}, "entropy bonus"),
    Variant("norm_adv", RecordedREINFORCE, {"normalize_advantage": True}, "advantages standardised per batch"),
    Variant("vlr_1e-2", RecordedREINFORCE, {"value_learning_rate": 1e-2}, "value learning rate 0.01"),
    Variant("vlr_1e-3", RecordedREINFORCE, {"value_learning_rate": 1e-3}, "value learning rate 0.001"),
    Variant("episodes4", RecordedREINFORCE, {"n_envs": 4, "n_episodes": 4}, "4 envs, 4 episodes per update"),
    Variant("episodes8", RecordedREINFORCE, {"n_envs": 8, "n_episodes": 8}, "8 envs, 8 episodes per update"),
    Variant(
        "init_kaiming",
        RecordedREINFORCE,
        {
            "policy_kwargs": "dict(net_arch=[256], activation_fn=nn.LeakyReLU, "
            "activation_kwargs=dict(negative_slope=0.1), weight_init='kaiming')"
        },
        "He initialisation, output layers PyTorch's default (the seed report's): a less uniform initial policy",
    ),
    Variant(
        "norm_adv_vlr_1e-2",
        RecordedREINFORCE,
        {"normalize_advantage": True, "value_learning_rate": 1e-2},
        "advantages standardised and value learning rate 0.01",
    ),
    Variant(
        "vlr_1e-3_ent_0.01",
        RecordedREINFORCE,
        {"value_learning_rate": 1e-3, "ent_coef": 0.01},
        "value learning rate 0.001 and an entropy bonus",
    ),
    Variant(
        "vlr_1e-3_ent_0.03",
        RecordedREINFORCE,
        {"value_learning_rate": 1e-3, "ent_coef": 0.03},
        "value learning rate 0.001 and a larger entropy bonus",
    ),
    Variant(
        "norm_adv_ent",
        RecordedREINFORCE,
        {"normalize_advantage": True, "ent_coef": 0.01},
        "advantages standardised and an entropy bonus",
    ),
]

PROBE_COLUMNS = ["n_loops", "entropy", "p_max", "value", "g_true", "bias", "learning_rate", "value_learning_rate"]


def main(argv: list[str] | None = None) -> None:
    """Run the study's command line (see the module's docstring)."""
    run_study("reinforce", "reinforce", "Acrobot-v1", VARIANTS, reinforce_probe, argv)


if __name__ == "__main__":
    main()


def first_success_table(runs: dict[int, Path]) -> str:
    """
    Per seed: the first training episode that reached the goal, and what the updates before it looked like
    (the policy's entropy over the batch, ln 3 ≈ 1.099 being uniform; the value loss; the explained variance).

    :param runs: one variant's runs by seed
    :return: a markdown table
    """
    lines = [
        "| Seed | Final | First success (episode, env step) | Entropy before (min–max) | Value loss: 1st, 10th, 50th update "
        "| Explained var. before (median) | Successes in training |",
        "|---|---|---|---|---|---|---|",
    ]
    for seed, path in runs.items():
        updates = pd.read_csv(path / "updates.csv")
        final = load_evals(path)["mean_return"].iloc[-1]
        success = np.flatnonzero(updates["ep_return"].to_numpy() > -500)
        before = updates.iloc[: success[0]] if len(success) else updates
        first = f"{success[0] + 1}, {updates['timesteps'].iloc[success[0]]:,}" if len(success) else "never"
        losses = ", ".join(f"{updates['value_loss'].iloc[k]:.3g}" for k in (0, 9, 49) if k < len(updates))
        entropy = f"{before['entropy'].min():.3f}–{before['entropy'].max():.3f}" if len(before) else "–"
        variance = f"{before['explained_variance'].median():.2f}" if len(before) else "–"
        lines.append(f"| {seed} | {final:.1f} | {first} | {entropy} | {losses} | {variance} | {len(success)}/{len(updates)} |")
    return "\n".join(lines)
