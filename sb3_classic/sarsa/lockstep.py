"""K ``NStepSARSA`` models of one setting, each with its own seed and env, trained in lockstep on one stacked q̂."""

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch as th
from stable_baselines3.common.preprocessing import is_image_space
from stable_baselines3.common.torch_layers import FlattenExtractor
from stable_baselines3.dqn.policies import QNetwork

from sb3_classic.common.population import (
    Population,
    StackedPart,
    Trainer,
    check_adam,
    check_population,
    side_by_side,
    stacked_step,
)
from sb3_classic.common.stacked import StackedMLP
from sb3_classic.sarsa.nstep_sarsa import LOG_EVERY_STEPS, NStepSARSA, sarsa_losses
from sb3_classic.sarsa.policies import LinearQPolicy


class NStepSARSAPopulation(Population[NStepSARSA]):
    """
    K ``NStepSARSA`` models of one setting (episodic semi-gradient n-step SARSA, Sutton & Barto §10.2) trained in
    lockstep (``Population``): each member with its own ε, n-step targets and draws (ε and ties), their q̂s one
    ``StackedMLP``. A member's update makes the gradient steps of its separate run's ``train``: in the per-step mode one
    per transition, in time order, in the batch mode ``gradient_steps`` on the mean loss of its whole batch; a member
    with nothing to train at a stacked step is not moved.

    The copies of q̂ (the bootstrap network of ``target_update_interval``, the weight average of ``averaging_tau``)
    are stacked as q̂ is, each member's copy a view of its slice: each member's targets bootstrap from its own copy,
    and its ``_move_copies`` moves its copy (w⁻ ← τw + (1 − τ)w⁻) after its own updates only, as in its separate run.

    Covered: both ``update_mode`` values with any ``train_freq``, ``gradient_steps`` and ``n_steps``, ``loss_function``,
    ``expected_sarsa``, ``td_lambda``, the copies of q̂, schedules and decays, several envs per member, envs with action
    masks; ``"MlpPolicy"`` (linear layers, LayerNorm and elementwise activations) over flat Box observations, and
    ``torch.optim.Adam`` without weight decay, AMSGrad or ``maximize``. Anything else (``"LinearPolicy"``, CNN, Dict or
    Discrete observations, another optimizer) is refused with a ``ValueError``/``TypeError`` that names it.

    :param models: the members, ``NStepSARSA`` models of one setting (every argument but ``seed`` and ``env``), each
        with its own seed (not None) and env
    :raises ValueError: for members of different settings, or without a seed or an env
    :raises TypeError: for a q̂, observations or optimizer not covered
    """

    def _check(self, models: Sequence[Any]) -> None:
        check_members(models)

    def _trainer(self) -> "_StackedQ":
        return _StackedQ(self.models)

    def _log_interval(self) -> int:
        # (NStepSARSA.learn's "auto": a dump about every LOG_EVERY_STEPS env steps per env)
        return -(-LOG_EVERY_STEPS // self.models[0].train_freq)


class _StackedQ(Trainer[NStepSARSA]):
    """
    The stacked q̂ of the members of one ``learn`` call (the population's ``Trainer``): built from their weights,
    shared with them while it lives, handed back by ``close``.

    :param models: the members
    """

    #: A member takes its first n − 1 steps of an episode, with nothing to train, without waiting for the others'
    #: gradient steps: its weights do not change before its next update
    steps_again = True

    def __init__(self, models: list[NStepSARSA]) -> None:
        super().__init__(models)
        self.q = StackedPart(
            [model.policy.q_net.q_net for model in models], [model.policy.optimizer for model in models], "q̂", self.device
        )
        # The copies of q̂ (bootstrap network, weight average) stacked as q̂ is, each member's copy a view of its slice:
        # its own code reads and moves them (its targets' bootstrap values, _move_copies' Polyak updates) as in its
        # separate run, on its slice only
        self.copies = [
            StackedPart([getattr(model.policy, name).q_net for model in models], None, name, self.device)
            for name in ("q_net_target", "q_net_average")
            if getattr(models[0].policy, name) is not None
        ]
        self.huber = models[0].loss_function == "huber"

    def forward(self) -> np.ndarray:
        """
        :return: q̂(S, ·) of every member's current observations, one stacked forward pass, shape (K, n_envs, n_actions):
            member k's ε-greedy choice takes row k in place of a forward pass of its own
        """
        observations = np.stack([np.asarray(model._last_obs) for model in self.models])
        x = th.as_tensor(observations, device=self.device).float()
        return self.q.stacked.inference(x.reshape(*x.shape[:2], -1)).cpu().numpy()

    def _gradient_step(
        self, chunks: list[tuple[Any, ...]], lengths: np.ndarray, members: np.ndarray
    ) -> list[tuple[np.ndarray, float]]:
        """
        One gradient step of the given members, each on the mean loss of its own transitions (S_t, A_t, G_{t:t+n})
        (``NStepSARSA._gradient_step``: its whole batch in the batch mode, its next transition in the per-step mode).

        :return: each given member's q̂(S_t, A_t) before the step, shape (n,), and its loss
        """
        observations, actions, targets, _ = zip(*chunks, strict=True)
        device = self.device
        x = th.as_tensor(side_by_side(observations, lengths, (self.features,), np.float32), device=device)
        index = th.as_tensor(side_by_side(actions, lengths, (1,), np.int64), device=device)
        q_predicted = self.q.stacked(x, self.subset(members)).gather(2, index).squeeze(2)
        target = th.as_tensor(side_by_side(targets, lengths, (), np.float32), device=device)
        # (one transition each: no padding)
        member_losses = sarsa_losses(q_predicted, target, self.huber, None if x.shape[1] == 1 else lengths)
        stacked_step([self.q], member_losses.sum(), members, self.max_grad_norm)
        q_values, losses = q_predicted.detach().cpu().numpy(), member_losses.detach().cpu().numpy()
        # (what each member's _gradient_step returns)
        return [(q_values[row, :n], float(losses[row])) for row, n in enumerate(lengths)]

    def close(self) -> None:
        """Each member's parameters get storage of their own again, and its optimizer its slice's Adam state."""
        self.q.close()
        for copy in self.copies:
            copy.close()


def check_members(models: Sequence[Any]) -> None:
    """
    :param models: the would-be members of a population
    :raises ValueError: for no members, a model twice, members of different settings, or without a seed or an env
    :raises TypeError: for a member that is not ``NStepSARSA``, or a q̂ or optimizer not covered
    """
    check_population(models, NStepSARSA, _check_member)
    # (raises for layers a stacked network does not hold)
    StackedMLP.from_sequentials([model.policy.q_net.q_net for model in models])


def _check_member(k: int, model: NStepSARSA) -> None:
    name = f"member {k} (seed {model.seed})"
    policy = model.policy
    if isinstance(policy, LinearQPolicy):
        raise TypeError(
            f"{name}: policy='LinearPolicy' has its own SGD update, not a stacked network's; use 'MlpPolicy', or train "
            "one model after the other (model.learn)"
        )
    extractor = policy.q_net.features_extractor
    if type(policy.q_net) is not QNetwork or policy.own_predict or policy.mode_dependent:
        raise TypeError(
            f"{name}: q̂ is a {type(policy.q_net).__name__} of a {type(policy).__name__} with its own forward, greedy "
            "policy or train/eval modes: a population stacks SB3's QNetwork of 'MlpPolicy'; train this one alone"
        )
    if type(extractor) is not FlattenExtractor or is_image_space(model.observation_space):
        raise TypeError(
            f"{name}: features_extractor={type(extractor).__name__} over {model.observation_space}: a population stacks "
            "an MLP over flat Box observations ('MlpPolicy'); train CNN and Dict (MultiInputPolicy) models one after the "
            "other (model.learn)"
        )
    check_adam(name, policy.optimizer)


__all__ = ["NStepSARSAPopulation", "check_members"]
