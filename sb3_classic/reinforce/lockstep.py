"""K ``REINFORCE`` models of one setting, each with its own seed and env, trained in lockstep on stacked networks."""

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch as th
import torch.nn.functional as F
from gymnasium import spaces
from stable_baselines3.common.preprocessing import is_image_space
from stable_baselines3.common.torch_layers import FlattenExtractor
from torch import nn

from sb3_classic.common.population import (
    Population,
    StackedPart,
    Trainer,
    check_adam,
    check_population,
    layer_parameters,
    side_by_side,
    stacked_step,
)
from sb3_classic.common.stacked import StackedMLP
from sb3_classic.reinforce.policies import REINFORCEPolicy
from sb3_classic.reinforce.reinforce import REINFORCE, reinforce_losses, softmax_cdf

#: An illegal action's logit in sb3-contrib's ``MaskableCategorical``
MASKED_LOGIT = -1e8


class REINFORCEPopulation(Population[REINFORCE]):
    """
    K ``REINFORCE`` models of one setting (REINFORCE with baseline, Sutton & Barto §13.4, or plain REINFORCE, §13.3)
    trained in lockstep (``Population``): each member with its own episodes and returns G_t, its policy networks
    π(a|s, θ) (``mlp_extractor.policy_net`` and ``action_net``) one ``StackedMLP`` and its value networks v̂(s, w)
    (``mlp_extractor.value_net`` and ``value_net``) another, each member's α^θ and α^w as its own optimizers hold them
    after its schedule and decay, and each network's gradient clipped on its own, as ``REINFORCE`` clips them. A
    member's update is one gradient step of each network on the mean over its batch (``update_mode="batch"``), or the
    book's loop (``"per_step"``), the update's T steps one stacked gradient step at a time. Member k's actions are drawn
    from its logits by the inverse CDF of their soft-max (``categorical_inverse_cdf``: the soft-max of every member at
    once, then one uniform draw per env and step of its generator).

    Covered: both update modes, ``use_baseline`` True and False, ``n_episodes``, ``normalize_advantage``,
    ``gamma_t_factor``, ``ent_coef``, ``max_grad_norm``, schedules and decays, several envs per member, Discrete
    actions, envs with action masks, ``"MlpPolicy"`` (linear layers and elementwise activations) over flat Box
    observations, and ``torch.optim.Adam`` without weight decay, AMSGrad or ``maximize``. Anything else is refused
    with a ``ValueError``/``TypeError`` that names it.

    :param models: the members, ``REINFORCE`` models of one setting (every argument but ``seed`` and ``env``), each
        with its own seed (not None) and env
    :raises ValueError: for members of different settings, without a seed or an env, or of a setting not covered
    :raises TypeError: for networks, observations or optimizers not covered
    """

    def _check(self, models: Sequence[Any]) -> None:
        check_members(models)

    def _trainer(self) -> "_StackedPolicy":
        return _StackedPolicy(self.models)

    def _log_interval(self) -> int:
        return 4  # (REINFORCE.learn's default)


def _policy_network(policy: REINFORCEPolicy) -> nn.Sequential:
    """:return: π's layers, h(s, ·, θ) from the flat observation (``mlp_extractor.policy_net``, ``action_net``)"""
    return nn.Sequential(*policy.mlp_extractor.policy_net, policy.action_net)


def _value_network(policy: REINFORCEPolicy) -> nn.Sequential:
    """:return: v̂'s layers, v̂(s, w) from the flat observation (``mlp_extractor.value_net``, ``value_net``)"""
    return nn.Sequential(*policy.mlp_extractor.value_net, policy.value_net)


class _StackedPolicy(Trainer[REINFORCE]):
    """
    The stacked networks of the members of one ``learn`` call (the population's ``Trainer``): built from their
    weights, shared with them while they live, handed back by ``close``.

    :param models: the members
    """

    #: One env step per stacked gradient step: a rollout is whole episodes, which the other members' updates wait for
    steps_again = False

    def __init__(self, models: list[REINFORCE]) -> None:
        super().__init__(models)
        policies = [model.policy for model in models]
        networks = [_policy_network(policy) for policy in policies]
        self.policy = StackedPart(networks, [policy.optimizer for policy in policies], "π", self.device)
        self.value: StackedPart | None = None
        if models[0].use_baseline:
            self.value = StackedPart(
                [_value_network(policy) for policy in policies],
                [policy.value_optimizer for policy in policies],  # type: ignore[misc]
                "v̂",
                self.device,
            )
        first = models[0]
        self.n_actions = int(first.action_space.n)  # type: ignore[attr-defined]
        self.gamma, self.gamma_t_factor = first.gamma, first.gamma_t_factor
        self.normalize_advantage, self.ent_coef = first.normalize_advantage, first.ent_coef
        #: every member's current observations, flattened, refilled at each env step (one array, no stacking)
        self._observations = np.zeros((len(models), first.n_envs, self.features), dtype=np.float32)

    def forward(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """
        :return: by member, h(S, ·, θ) of its current observations, shape (n_envs, n_actions), and the cumulative
            probabilities of their soft-max (``softmax_cdf``), the same shape (one stacked forward pass, one soft-max
            of all members): what its draw takes in place of a forward pass of its own
        """
        observations = self._observations
        for k, model in enumerate(self.models):
            observations[k] = np.reshape(model._last_obs, observations.shape[1:])  # type: ignore[arg-type]
        with th.no_grad():
            logits = self.policy.stacked(th.as_tensor(observations, device=self.device)).cpu().numpy()
        return list(zip(logits, softmax_cdf(logits), strict=True))

    def _gradient_step(
        self, chunks: list[tuple[Any, ...]], lengths: np.ndarray, members: np.ndarray
    ) -> list[dict[str, th.Tensor]]:
        """
        One gradient step of each network of the given members, each on the mean over its own steps (S_t, A_t, G_t, t,
        masks) (``REINFORCE._gradient_step``: its whole batch, or its next step in time order).

        :return: each given member's policy, entropy and value losses, and v̂(S_t) before the step (zeros without a
            baseline), shape (n,), detached
        """
        observations, actions, returns, episode_steps, action_masks = zip(*chunks, strict=True)
        device = self.device
        subset = self.subset(members)
        obs = th.as_tensor(side_by_side(observations, lengths, (self.features,), np.float32), device=device)
        returns_t = th.as_tensor(side_by_side(returns, lengths, (), np.float32), device=device)
        logits = self.policy.stacked(obs, subset)
        # (every action legal where no member's chunk has masks that make one illegal, and in the padding)
        if any(chunk_masks is not None and not bool(chunk_masks.all()) for chunk_masks in action_masks):
            masks = th.as_tensor(side_by_side(action_masks, lengths, (self.n_actions,), bool, True), device=device)
            # sb3-contrib's MaskableCategorical: an illegal action's logit at -1e8, its probability 0
            logits = th.where(masks, logits, MASKED_LOGIT)
        else:
            masks = None
        # log π and the entropy from one log-soft-max: the values of torch's Categorical, which SB3's and sb3-contrib's
        # distributions (the member's own) wrap, to rounding; a Categorical of the stacked logits costs twice these calls
        log_probs = F.log_softmax(logits, dim=-1)
        index = th.as_tensor(side_by_side(actions, lengths, (1,), np.int64), device=device)
        log_prob = log_probs.gather(2, index).squeeze(-1)
        p_log_p = log_probs.exp() * log_probs
        # (an illegal action adds nothing to the entropy, as in MaskableCategorical)
        entropy = -(p_log_p if masks is None else th.where(masks, p_log_p, 0.0)).sum(-1)
        values = th.zeros_like(returns_t) if self.value is None else self.value.stacked(obs, subset).squeeze(-1)
        member_losses = reinforce_losses(
            log_prob,
            entropy,
            values,
            returns_t,
            th.as_tensor(side_by_side(episode_steps, lengths, (), np.int64), device=device),
            self.gamma,
            self.gamma_t_factor,
            self.normalize_advantage,
            self.ent_coef,
            self.value is not None,
            # (one step each: no padding)
            None if obs.shape[1] == 1 else th.as_tensor(lengths, device=device),
        )
        # π, and v̂ with a baseline, each member at the α^θ and α^w its _update set
        parts = [self.policy] if self.value is None else [self.policy, self.value]
        stacked_step(parts, member_losses.total.sum(), members, self.max_grad_norm)
        # (each member's losses and values as views, unbound in one call per tensor rather than indexed per member)
        losses = th.stack([member_losses.policy, member_losses.entropy, member_losses.value]).detach()
        policy_losses, entropy_losses, value_losses = (loss.unbind(0) for loss in losses.unbind(0))
        member_values = values.detach().unbind(0)
        width = obs.shape[1]
        # (what each member's _gradient_step returns)
        return [
            dict(
                policy_loss=policy_losses[row],
                entropy_loss=entropy_losses[row],
                value_loss=value_losses[row],
                values=member_values[row] if n == width else member_values[row][:n],
            )
            for row, n in enumerate(lengths)
        ]

    def close(self) -> None:
        """Each member's parameters get storage of their own again, and its optimizers their slices' Adam states."""
        self.policy.close()
        if self.value is not None:
            self.value.close()


def check_members(models: Sequence[Any]) -> None:
    """
    :param models: the would-be members of a population
    :raises ValueError: for no members, a model twice, members of different settings, without a seed or an env, or of
        a setting not covered (actions other than Discrete)
    :raises TypeError: for a member that is not ``REINFORCE``, or networks or optimizers not covered
    """
    check_population(models, REINFORCE, _check_member)
    # (raises for layers a stacked network does not hold)
    StackedMLP.from_sequentials([_policy_network(model.policy) for model in models], "π")
    if models[0].use_baseline:
        StackedMLP.from_sequentials([_value_network(model.policy) for model in models], "v̂")


def _check_member(k: int, model: REINFORCE) -> None:
    name = f"member {k} (seed {model.seed})"
    if not isinstance(model.action_space, spaces.Discrete):
        raise ValueError(
            f"{name}: action_space={model.action_space}: a population draws Discrete actions from its stacked logits; "
            "train Box, MultiDiscrete and MultiBinary models one after the other (model.learn)"
        )
    policy = model.policy
    extractors = {policy.pi_features_extractor, policy.vf_features_extractor}
    if any(type(extractor) is not FlattenExtractor for extractor in extractors) or is_image_space(model.observation_space):
        names = sorted({type(extractor).__name__ for extractor in extractors})
        raise TypeError(
            f"{name}: features_extractor={', '.join(names)} over {model.observation_space}: a population stacks MLPs over "
            "flat Box observations ('MlpPolicy'); train CNN and Dict (MultiInputPolicy) models one after the other "
            "(model.learn)"
        )
    if type(policy) is not REINFORCEPolicy or policy._own_forward or not policy._sb3_distribution:
        raise TypeError(
            f"{name}: policy {type(policy).__name__} with its own forward, distribution or layers: a population stacks "
            "REINFORCEPolicy's ('MlpPolicy') networks; train this one alone (model.learn)"
        )
    networks = {"optimizer": _policy_network(policy), "value_optimizer": _value_network(policy)}
    # (raises for layers a stacked network does not hold)
    StackedMLP.from_sequentials([networks["optimizer"]], f"{name}'s π")
    if model.use_baseline:
        StackedMLP.from_sequentials([networks["value_optimizer"]], f"{name}'s v̂")
    optimizers = {"optimizer": policy.optimizer, "value_optimizer": policy.value_optimizer}
    for key, optimizer in optimizers.items():
        if optimizer is None:
            continue
        check_adam(name, optimizer, f"policy.{key}")
        trained = {id(parameter) for group in optimizer.param_groups for parameter in group["params"]}
        stacked = {id(parameter) for parameter in layer_parameters(networks[key])}
        if len(optimizer.param_groups) != 1 or trained != stacked:
            raise TypeError(
                f"{name}: policy.{key} trains other parameters than its network's linear layers (a features extractor "
                "with parameters, or parameter groups of its own): a population trains the stacked layers only; train "
                "this one alone (model.learn)"
            )


__all__ = ["REINFORCEPopulation", "check_members"]
