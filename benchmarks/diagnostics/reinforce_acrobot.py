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

from benchmarks.diagnostics.candidates import RecordedREINFORCE, reinforce_probe
from benchmarks.diagnostics.common import Variant, run_study

VARIANTS = [
    Variant("yaml", RecordedREINFORCE, {}, "hyperparams/reinforce.yml as committed"),
    Variant("ent_0.01", RecordedREINFORCE, {"ent_coef": 0.01}, "entropy bonus"),
    Variant("norm_adv", RecordedREINFORCE, {"normalize_advantage": True}, "advantages standardised per batch"),
    Variant("vlr_1e-2", RecordedREINFORCE, {"value_learning_rate": 1e-2}, "value learning rate 0.01"),
    Variant("vlr_1e-3", RecordedREINFORCE, {"value_learning_rate": 1e-3}, "value learning rate 0.001"),
    Variant("episodes4", RecordedREINFORCE, {"n_envs": 4, "n_episodes": 4}, "4 envs, 4 episodes per update"),
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
