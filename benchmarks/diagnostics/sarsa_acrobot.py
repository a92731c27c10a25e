"""
Why NStepSARSA's greedy policy falls into −500 loops on Acrobot-v1 with the YAML settings, and which change fixes it.

    python -m benchmarks.diagnostics.sarsa_acrobot --list
    python -m benchmarks.diagnostics.sarsa_acrobot --variants yaml,layer_norm --seeds 0-4

Each evaluation records, over the states the greedy policy visits: max_a q̂ (``value``), the gap between the best
and second-best action values (``gap``), the fraction of states with a gap under 0.1 (``small_gap``), the discounted
return-to-go actually obtained (``g_true``; −1/(1−γ) = −100 is the bound of a policy that never swings up) and
``bias`` = value − g_true, each also split by episodes that loop to the time limit (``loop_``) and those that reach
the goal (``goal_``); and the learning rate and ε at that moment.
"""

from benchmarks.diagnostics.candidates import CandidateSARSA, sarsa_probe
from benchmarks.diagnostics.common import Variant, run_study

NET = "dict(net_arch=[256, 256], weight_init='default')"
NET_LN = "dict(net_arch=[256, 256], weight_init='default', layer_norm=True)"

VARIANTS = [
    Variant("yaml", CandidateSARSA, {}, "hyperparams/nstep_sarsa.yml as committed"),
    Variant("layer_norm", CandidateSARSA, {"policy_kwargs": NET_LN}, "LayerNorm after each hidden layer"),
    Variant(
        "target_2k",
        CandidateSARSA,
        {"target_update_interval": 2000, "tau": 1.0},
        "bootstrap network copied every 2,000 env steps",
    ),
    # A bootstrap network moved by Polyak averaging after every update (stop 14; 0.05 first, the others after it)
    *(
        Variant(
            f"polyak_{tau}",
            CandidateSARSA,
            {"target_update_interval": 1, "tau": tau},
            f"bootstrap network, Polyak tau {tau} after every update",
        )
        for tau in (0.05, 0.1, 0.2, 0.01, 0.02)
    ),
    Variant(
        "gamma_0.995",
        CandidateSARSA,
        {"gamma": 0.995},
        "γ = 0.995: a policy that never swings up is worth −200 instead of −100, twice the gap to the goal's values",
    ),
    Variant(
        "gamma_0.995_eps_lin_0.1",
        CandidateSARSA,
        {"gamma": 0.995, "exploration_schedule": "linear", "exploration_fraction": 0.1},
        "γ = 0.995 and the linear ε",
    ),
    Variant(
        "gamma_0.995_eps_0.99",
        CandidateSARSA,
        {"gamma": 0.995, "exploration_decay_rate": 0.99},
        "γ = 0.995 and ε × 0.99 per episode (twice the decay)",
    ),
    Variant(
        "gamma_0.999",
        CandidateSARSA,
        {"gamma": 0.999},
        "γ = 0.999: a policy that never swings up is worth −1000",
    ),
    Variant(
        "gamma_0.995_n5",
        CandidateSARSA,
        {"gamma": 0.995, "n_steps": 5},
        "γ = 0.995 and 5-step returns",
    ),
    Variant(
        "eps_lin_0.1",
        CandidateSARSA,
        {"exploration_schedule": "linear", "exploration_fraction": 0.1},
        "ε from 1 to 0.05 over the first 10% of the steps (SB3 DQN's schedule) instead of ×0.995 per episode",
    ),
    Variant(
        "eps_lin_0.1_ln",
        CandidateSARSA,
        {"exploration_schedule": "linear", "exploration_fraction": 0.1, "policy_kwargs": NET_LN},
        "linear ε and LayerNorm",
    ),
    Variant(
        "eps_lin_0.1_target_2k",
        CandidateSARSA,
        {"exploration_schedule": "linear", "exploration_fraction": 0.1, "target_update_interval": 2000, "tau": 1.0},
        "linear ε and a bootstrap network",
    ),
    Variant(
        "eps_lin_0.1_lr_3e-4",
        CandidateSARSA,
        {"exploration_schedule": "linear", "exploration_fraction": 0.1, "learning_rate": "lin_3e-4"},
        "linear ε and a lower learning rate",
    ),
    Variant(
        "eps_lin_0.1_lr_c3e-4",
        CandidateSARSA,
        {"exploration_schedule": "linear", "exploration_fraction": 0.1, "learning_rate": 3e-4},
        "linear ε and a lower constant learning rate",
    ),
    Variant(
        "eps_lin_0.1_max",
        CandidateSARSA,
        {"exploration_schedule": "linear", "exploration_fraction": 0.1, "target_exploration_rate": 0.0},
        "linear ε, bootstrap from max_a q̂ (n-step Q-learning target, as PQN)",
    ),
    Variant(
        "eps_lin_0.1_final_0.01",
        CandidateSARSA,
        {"exploration_schedule": "linear", "exploration_fraction": 0.1, "exploration_final_eps": 0.01},
        "linear ε down to 0.01",
    ),
    Variant(
        "eps_lin_0.1_lr_steps",
        CandidateSARSA,
        {
            "exploration_schedule": "linear",
            "exploration_fraction": 0.1,
            "learning_rate": 1e-3,
            "lr_decay_factor": 0.3,
            "lr_decay_milestones": [400, 800],
            "lr_decay_unit": "update",
        },
        "linear ε, lr 1e-3 then ×0.3 after 400 and 800 updates (51k and 102k steps)",
    ),
    Variant("lr_const_1e-3", CandidateSARSA, {"learning_rate": 1e-3}, "constant learning rate"),
    Variant("lr_lin_3e-4", CandidateSARSA, {"learning_rate": "lin_3e-4"}, "lower learning rate"),
    Variant("n8", CandidateSARSA, {"n_steps": 8}, "n = 8"),
    Variant("plain_sarsa", CandidateSARSA, {"expected_sarsa": False}, "bootstrap from the action taken"),
    Variant("envs16", CandidateSARSA, {"n_envs": 16}, "16 envs (twice the batch)"),
    Variant(
        "lr_half_200u",
        CandidateSARSA,
        {"learning_rate": 1e-3, "lr_decay_factor": 0.5, "lr_decay_every": 200, "lr_decay_unit": "update"},
        "lr 1e-3 halved every 200 updates (25.6k steps): below 3e-4 from 51k steps",
    ),
    Variant(
        "lr_lin_half_200u",
        CandidateSARSA,
        {"lr_decay_factor": 0.5, "lr_decay_every": 200, "lr_decay_unit": "update"},
        "lin_1e-3 also halved every 200 updates",
    ),
    Variant("huber", CandidateSARSA, {"loss_function": "huber"}, "Huber loss (DQN's)"),
    Variant("clip_10", CandidateSARSA, {"max_grad_norm": 10.0}, "gradient norm clipped to 10 (DQN's)"),
    Variant(
        "ln_target_2k",
        CandidateSARSA,
        {"policy_kwargs": NET_LN, "target_update_interval": 2000, "tau": 1.0},
        "LayerNorm and a bootstrap network",
    ),
]

PROBE_COLUMNS = [
    "stochastic_mean_return",
    "n_loops",
    "gap",
    "loop_gap",
    "goal_gap",
    "loop_small_gap",
    "goal_small_gap",
    "value",
    "g_true",
    "bias",
    "loop_bias",
    "learning_rate",
    "exploration_rate",
]


def main(argv: list[str] | None = None) -> None:
    """Run the study's command line (see the module's docstring)."""
    run_study("sarsa", "nstep_sarsa", "Acrobot-v1", VARIANTS, sarsa_probe, argv)


if __name__ == "__main__":
    main()
