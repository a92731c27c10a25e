r"""
REINFORCE with baseline per step under ObGD: the book's per-step updates (Sutton & Barto, Reinforcement Learning: An
Introduction, 2nd ed., §13.4) with each step bounded as in the streaming recipe of Elsayed, Vasan & Mahmood (2024,
"Streaming Deep Reinforcement Learning Finally Works", arXiv 2410.14606).

ObGD steps along an eligibility trace :math:`\mathbf e` by an error :math:`\delta` (``sb3_classic.common.obgd``). A
Monte-Carlo return needs no trace: with λ = 0 the trace of step t is that step's gradient alone, so each of the book's
two updates is one ObGD step of its own network, by its own error, with its own κ.
"""

from typing import Any

import numpy as np
import torch as th

from sb3_classic.common.obgd import ObGD, check_obgd_settings, uses_obgd
from sb3_classic.reinforce.policies import REINFORCEPolicy


def reinforce_obgd_step(
    policy: REINFORCEPolicy,
    log_prob: th.Tensor,
    entropy: th.Tensor,
    values: th.Tensor,
    returns: th.Tensor,
    episode_steps: np.ndarray,
    gamma: float,
    gamma_t_factor: bool,
) -> dict[str, th.Tensor]:
    r"""
    Step t of REINFORCE with baseline (the loop of S&B §13.4's box) with both updates bounded by ObGD, λ = 0:

    .. math::

        \delta_t &= G_t - \hat v(S_t, \mathbf w) \\
        \mathbf w &\leftarrow \mathbf w + \frac{\alpha^{\mathbf w}}{\max(M^{\mathbf w}, 1)}\, \delta_t \nabla \hat v(S_t,
        \mathbf w), \qquad M^{\mathbf w} = \alpha^{\mathbf w} \kappa^{\mathbf w} \max(|\delta_t|, 1)\,
        \lVert \nabla \hat v(S_t, \mathbf w) \rVert_1 \\
        \boldsymbol\theta &\leftarrow \boldsymbol\theta + \frac{\alpha^{\boldsymbol\theta}}{\max(M^{\boldsymbol\theta},
        1)}\, \gamma^t \delta_t \nabla \ln \pi(A_t \mid S_t, \boldsymbol\theta), \qquad M^{\boldsymbol\theta} =
        \alpha^{\boldsymbol\theta} \kappa^{\boldsymbol\theta} \max(|\gamma^t \delta_t|, 1)\, \lVert \nabla \ln \pi(A_t
        \mid S_t, \boldsymbol\theta) \rVert_1

    (:math:`\gamma^t` with ``gamma_t_factor``, else 1; the norms over each network's own parameters). Where M ≤ 1 these
    are the book's updates; where M > 1 the step is cut to α/M. In ObGD's terms, v̂ is a value learner (κ = 2, the
    paper's) with error :math:`\delta_t` and trace :math:`\nabla \hat v`, and the policy an actor (κ = 3) with error
    :math:`\gamma^t \delta_t`, the weight the book gives its gradient, and trace :math:`\nabla \ln \pi`, as the paper's
    streaming actor-critic steps its actor by its TD error along :math:`\nabla \ln \pi`. Where the bound is active and
    :math:`|\gamma^t \delta_t| \ge 1`, the policy's step is :math:`\mathrm{sign}(\delta_t) \nabla \ln \pi /
    (\kappa \lVert \nabla \ln \pi \rVert_1)`: the size of :math:`\delta_t` then no longer matters, only its sign.

    :param policy: the policy, with ObGD as ``optimizer`` (θ) and ``value_optimizer`` (w; None without a baseline)
    :param log_prob: :math:`\ln \pi(A_t \mid S_t, \boldsymbol\theta)` of one step, shape (1,), with its graph
    :param entropy: the entropy of :math:`\pi(\cdot \mid S_t, \boldsymbol\theta)`, shape (1,) (logged; not trained)
    :param values: :math:`\hat v(S_t, \mathbf w)` before the step, shape (1,), with its graph (zeros without a baseline:
        plain REINFORCE, :math:`\delta_t = G_t`, S&B §13.3)
    :param returns: :math:`G_t`, shape (1,)
    :param episode_steps: t, the step's index within its episode, shape (1,)
    :param gamma: γ
    :param gamma_t_factor: weight the policy's gradient by :math:`\gamma^t` (S&B eq. 13.8)
    :return: ``REINFORCE._gradient_step``'s: the losses whose gradients the updates follow, at this step (policy:
        :math:`-\gamma^t \delta_t \ln \pi`; value: :math:`\tfrac12 \delta_t^2`; entropy: :math:`-H`), shape (), and
        :math:`\hat v(S_t)` before the step, shape (1,)
    :raises ValueError: for more than one step
    :raises TypeError: for a policy whose optimizers are not ObGD
    """
    if log_prob.numel() != 1:
        raise ValueError(
            f"an ObGD step of REINFORCE takes one step t at a time (its δ_t bounds the step), not {log_prob.numel()}: "
            "train with update_mode='per_step'"
        )
    # δ_t = G_t − v̂(S_t, w), from w before this step's updates (S&B §13.4's box); plain REINFORCE: δ_t = G_t (§13.3)
    td_error = (returns - values.detach()).item()
    # γ^t δ_t: the weight of ∇ln π(A_t|S_t, θ) in the box's θ update (S&B eq. 13.11 with b(S_t) = v̂(S_t, w))
    policy_error = gamma ** int(episode_steps[0]) * td_error if gamma_t_factor else td_error
    policy_optimizer, value_optimizer = policy.optimizer, policy.value_optimizer
    if not isinstance(policy_optimizer, ObGD) or not isinstance(value_optimizer, ObGD | None):
        raise TypeError(
            f"reinforce_obgd_step steps both networks with ObGD, not {type(policy_optimizer).__name__} and "
            f"{type(value_optimizer).__name__}: build the policy with optimizer_class=ObGD"
        )
    policy_parameters = policy_optimizer.parameter_list()
    value_parameters = value_optimizer.parameter_list() if value_optimizer is not None else []
    # ∇ln π(A_t|S_t, θ) and ∇v̂(S_t, w): the networks' parameters are disjoint (no shared features extractor), so one
    # backward pass of the sum gives each network the gradient of its own output
    gradients = th.autograd.grad(log_prob.sum() + values.sum(), [*policy_parameters, *value_parameters], allow_unused=True)
    if value_optimizer is not None:
        # w ← w + (α^w / max(M^w, 1)) δ_t ∇v̂(S_t, w): ObGD with trace e = ∇v̂ (λ = 0; the paper's κ = 2)
        value_optimizer.step_with_gradients(gradients[len(policy_parameters) :], td_error=td_error, trace_decay=0.0)
    # θ ← θ + (α^θ / max(M^θ, 1)) γ^t δ_t ∇ln π(A_t|S_t, θ): ObGD with trace e = ∇ln π (λ = 0; the paper's actor κ = 3)
    policy_optimizer.step_with_gradients(gradients[: len(policy_parameters)], td_error=policy_error, trace_decay=0.0)
    # (the distribution holds this step's graph: dropped, as REINFORCE's other gradient steps drop it)
    policy.release_distributions()
    return dict(
        policy_loss=-policy_error * log_prob.detach().squeeze(0),
        value_loss=th.tensor(0.5 * td_error * td_error, device=values.device),
        entropy_loss=-entropy.detach().squeeze(0),
        values=values.detach(),
    )


def check_streaming_settings(
    policy_kwargs: dict[str, Any] | None, update_mode: str, ent_coef: float, max_grad_norm: float | None
) -> None:
    """
    ``ObGD`` bounds each of REINFORCE's per-step updates by its own step's error (``reinforce_obgd_step``).

    :param policy_kwargs: the policy's arguments (``optimizer_class``, ``share_features_extractor``)
    :param update_mode: ``update_mode``
    :param ent_coef: ``ent_coef``
    :param max_grad_norm: ``max_grad_norm`` (``math.inf`` or None: no clipping)
    :raises ValueError: for a setting these updates cannot make, naming it and the fix
    """
    if not uses_obgd(policy_kwargs):
        return
    why = "ObGD bounds each of REINFORCE's per-step updates (S&B §13.4's box) by the step's δ_t, one step t at a time"
    share = (policy_kwargs or {}).get("share_features_extractor", False)
    required = (
        ("update_mode", update_mode, "per_step", "pass update_mode='per_step' (each step's own updates, in time order)"),
        (
            "ent_coef",
            ent_coef,
            0.0,
            "drop ent_coef: ObGD steps by an error times a gradient (δ_t ∇ln π), which an entropy bonus is not",
        ),
        (
            "policy_kwargs['share_features_extractor']",
            share,
            False,
            "drop share_features_extractor: each network's step is bounded by the norm of its own gradient",
        ),
    )
    check_obgd_settings(why, required, max_grad_norm)
