"""K ``NStepSARSA`` models of one setting, each with its own seed and env, trained in lockstep on one stacked q̂."""

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch as th
from stable_baselines3.common.preprocessing import is_image_space
from stable_baselines3.common.torch_layers import FlattenExtractor
from stable_baselines3.dqn.policies import QNetwork

from sb3_classic.common.population import MemberUpdate, Population, StackedPart, check_population
from sb3_classic.common.stacked import StackedMLP, clip_grad_norms_per_member
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


class _StackedQ:
    """
    The stacked q̂ of the members of one ``learn`` call (the population's ``Trainer``): built from their weights,
    shared with them while it lives, handed back by ``close``.

    :param models: the members
    """

    #: A member takes its first n − 1 steps of an episode, with nothing to train, without waiting for the others'
    #: gradient steps: its weights do not change before its next update
    steps_again = True

    def __init__(self, models: list[NStepSARSA]) -> None:
        self.models = models
        device = models[0].device
        self.device = device
        self.q = StackedPart(
            [model.policy.q_net.q_net for model in models], [model.policy.optimizer for model in models], "q̂", device
        )
        self.stacked, self.parameters = self.q.stacked, self.q.parameters
        self.optimizer = self.q.optimizer
        # The copies of q̂ (bootstrap network, weight average) stacked as q̂ is, each member's copy a view of its slice:
        # its own code reads and moves them (its targets' bootstrap values, _move_copies' Polyak updates) as in its
        # separate run, on its slice only
        self.copies = [
            StackedPart([getattr(model.policy, name).q_net for model in models], None, name, device)
            for name in ("q_net_target", "q_net_average")
            if getattr(models[0].policy, name) is not None
        ]
        #: the length of a flattened observation
        self.features = int(np.prod(models[0].observation_space.shape or (1,)))
        self.max_grad_norm = models[0].max_grad_norm
        self.huber = models[0].loss_function == "huber"

    def forward(self) -> np.ndarray:
        """
        :return: q̂(S, ·) of every member's current observations, one stacked forward pass, shape (K, n_envs, n_actions):
            member k's ε-greedy choice takes row k in place of a forward pass of its own
        """
        observations = np.stack([np.asarray(model._last_obs) for model in self.models])
        x = th.as_tensor(observations, device=self.device).float()
        return self.stacked.inference(x.reshape(*x.shape[:2], -1)).cpu().numpy()

    def step(self, updates: dict[int, MemberUpdate]) -> list[int]:
        """
        One stacked gradient step: every member with an update in progress takes its next gradient step (its
        ``_update``'s: its whole batch in the batch mode, its next transition in time order in the per-step mode,
        ``gradient_steps`` times over), each on the mean loss of its own transitions; the others are not stepped.

        :param updates: the members' updates in progress, by member
        :return: the members whose update this step finished
        """
        if not updates:
            return []
        n_members = len(self.models)
        sizes = np.zeros(n_members, dtype=np.int64)
        for k, update in updates.items():
            sizes[k] = len(update.arguments[2])
        width = int(sizes.max())
        # The members' transitions side by side, padded with zeros to the longest (the padding weighs nothing in the
        # losses)
        x = np.zeros((n_members, width, self.features), dtype=np.float32)
        actions = np.zeros((n_members, width, 1), dtype=np.int64)
        targets = np.zeros((n_members, width), dtype=np.float32)
        for k, update in updates.items():
            observations, member_actions, member_targets = update.arguments
            size = sizes[k]
            x[k, :size] = np.reshape(observations, (size, -1))
            actions[k, :size, 0] = np.reshape(member_actions, size)
            targets[k, :size] = member_targets
        learning_rates = np.array([model.policy.optimizer.param_groups[0]["lr"] for model in self.models], dtype=np.float64)
        active = np.array(list(updates))
        q_predicted, member_losses = self._gradient_step(x, actions, targets, sizes, active, learning_rates)
        # (what each member's _gradient_step returns: q̂(S_t, A_t) before the step, and its loss)
        return [k for k, update in updates.items() if not update.send((q_predicted[k, : sizes[k]], float(member_losses[k])))]

    def _gradient_step(
        self,
        x: np.ndarray,
        actions: np.ndarray,
        targets: np.ndarray,
        sizes: np.ndarray,
        members: np.ndarray,
        learning_rates: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """
        One gradient step of the given members, each on the mean loss of its own transitions
        (``NStepSARSA._gradient_step``).

        :param x: S_t of every member's transitions, padded with zeros to the longest, shape (K, B, features)
        :param actions: A_t, shape (K, B, 1)
        :param targets: G_{t:t+n}, shape (K, B)
        :param sizes: how many of the B are member k's (the rest is padding), shape (K,); 0 for the members not stepped
        :param members: the members to step, shape (M,)
        :param learning_rates: every member's α, shape (K,)
        :return: every member's q̂(S_t, A_t) before the step, shape (K, B), and its loss, shape (K,) (meaningful for
            the given members and their own transitions)
        """
        device = self.device
        q_predicted = self.stacked(th.as_tensor(x, device=device)).gather(2, th.as_tensor(actions, device=device))
        q_predicted = q_predicted.squeeze(2)
        target = th.as_tensor(targets, device=device)
        # (one transition each: no padding)
        member_losses = sarsa_losses(q_predicted, target, self.huber, None if x.shape[1] == 1 else sizes)
        self.optimizer.zero_grad()
        if len(members) == len(self.models):
            member_losses.sum().backward()
        else:
            member_losses.index_select(0, th.as_tensor(members, device=device)).sum().backward()
        if self.max_grad_norm is not None and np.isfinite(self.max_grad_norm):
            clip_grad_norms_per_member(self.parameters, self.max_grad_norm)
        self.optimizer.step(members, learning_rates)
        return q_predicted.detach().cpu().numpy(), member_losses.detach().cpu().numpy()

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
    optimizer = policy.optimizer
    group = optimizer.param_groups[0]
    if type(optimizer) is not th.optim.Adam or group["weight_decay"] or group["amsgrad"] or group["maximize"]:
        raise TypeError(
            f"{name}: optimizer {type(optimizer).__name__} with weight_decay={group.get('weight_decay')!r}, "
            f"amsgrad={group.get('amsgrad')!r}, maximize={group.get('maximize')!r}: a population's optimizer is Adam "
            "without weight decay, AMSGrad or maximize (StackedAdam); leave optimizer_class and those kwargs out"
        )


__all__ = ["NStepSARSAPopulation", "check_members"]
