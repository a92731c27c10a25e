"""
Candidate fixes of issue 13, built as subclasses of the package's algorithms so that the diagnostic studies could
measure them before they were built: per-update records for both algorithms, and the ε of SARSA's bootstrap
expectation. The bootstrap (target) network and LayerNorm measured here are now NStepSARSA's own options
(``target_update_interval``/``tau``, ``policy_kwargs=dict(layer_norm=True)``), which this subclass passes on.
"""

from typing import Any

import numpy as np
import torch as th

from sb3_classic import REINFORCE, NStepSARSA


class CandidateSARSA(NStepSARSA):
    """
    ``NStepSARSA`` with a bootstrap network (SB3 DQN's names): the n-step targets bootstrap from ``q_net_target``,
    which follows the online network by ``polyak_update(tau)`` every ``target_update_interval`` env steps (0: no
    target network, the package's algorithm). ``policy_kwargs=dict(layer_norm=True)`` adds LayerNorm.
    ``target_exploration_rate``: the ε of the bootstrap expectation (the behaviour's if None; 0 with
    ``expected_sarsa=True`` bootstraps from max_a q̂). Keeps a record of every update in ``update_records``.

    :param target_update_interval: env steps (all envs together) between two updates of the target network; 0 for none
    :param tau: the Polyak coefficient of those updates (1: a copy)
    :param target_exploration_rate: ε of the bootstrap's ε-greedy expectation; None: the behaviour's
    :param kwargs: the arguments of ``NStepSARSA``
    """

    #: The evaluation also runs the ε-greedy policy (``stochastic_mean_return``), to compare with the greedy one
    diagnose_epsilon = True

    def __init__(
        self,
        policy: Any,
        env: Any,
        target_update_interval: int = 0,
        tau: float = 1.0,
        target_exploration_rate: float | None = None,
        **kwargs: Any,
    ):
        self.target_exploration_rate = target_exploration_rate
        self.update_records: list[dict[str, float]] = []
        # The bootstrap network and LayerNorm are NStepSARSA's own options now (0 here: none)
        super().__init__(policy, env, target_update_interval=target_update_interval or None, tau=tau, **kwargs)

    def _bootstrap_values(self, q_values: th.Tensor) -> np.ndarray:
        # target_exploration_rate=0 with expected_sarsa: bootstrap from max_a q̂ (n-step Q-learning, PQN's target)
        if self.target_exploration_rate is None:
            return super()._bootstrap_values(q_values)
        behaviour = self.exploration_rate
        self.exploration_rate = self.target_exploration_rate
        try:
            return super()._bootstrap_values(q_values)
        finally:
            self.exploration_rate = behaviour

    def train(self) -> None:
        super().train()
        values = self.logger.name_to_value
        if "train/loss" in values:
            self.update_records.append(
                {
                    "timesteps": self.num_timesteps,
                    "loss": values["train/loss"],
                    "q_mean": values["train/q_mean"],
                    "target_mean": values["train/target_mean"],
                    "learning_rate": values["train/learning_rate"],
                    "exploration_rate": self.exploration_rate,
                }
            )


class RecordedREINFORCE(REINFORCE):
    """``REINFORCE`` that keeps a record of every update (losses, entropy, explained variance) in ``update_records``."""

    def __init__(self, *args: Any, **kwargs: Any):
        self.update_records: list[dict[str, float]] = []
        super().__init__(*args, **kwargs)

    def train(self) -> None:
        n_updates = self._n_updates
        super().train()
        if self._n_updates == n_updates:
            return
        values = self.logger.name_to_value
        self.update_records.append(
            {
                "timesteps": self.num_timesteps,
                "episodes": self._completed_episodes,
                "policy_loss": values["train/policy_loss"],
                "value_loss": values["train/value_loss"],
                "entropy": -values["train/entropy_loss"],
                "explained_variance": values["train/explained_variance"],
                "ep_return": float(np.mean([info["r"] for info in list(self.ep_info_buffer)[-1:]]))
                if self.ep_info_buffer
                else float("nan"),
            }
        )


def sarsa_probe(model: Any, obs: th.Tensor) -> dict[str, np.ndarray]:
    """
    :return: per state, ``value`` (max_a q̂, the greedy policy's value estimate), ``gap`` (max − second max: how
        decisive the greedy action is), ``spread`` (max − min), ``small_gap`` (1 if gap < 0.1, the return of a tenth of a step)
    """
    q = model.policy.q_net(obs)
    top = th.sort(q, dim=1, descending=True).values.cpu().numpy()
    gap = top[:, 0] - top[:, 1]
    return {"value": top[:, 0], "gap": gap, "spread": top[:, 0] - top[:, -1], "small_gap": (gap < 0.1).astype(float)}


def reinforce_probe(model: Any, obs: th.Tensor) -> dict[str, np.ndarray]:
    """:return: per state, the policy's ``entropy``, its largest action probability ``p_max``, and ``value`` (v̂)"""
    distribution = model.policy.get_distribution(obs)
    probs = distribution.distribution.probs
    return {
        "entropy": distribution.entropy().cpu().numpy(),
        "p_max": probs.max(dim=1).values.cpu().numpy(),
        "value": model.policy.predict_values(obs).flatten().cpu().numpy(),
    }
