"""
Overshooting-bounded gradient descent (ObGD) with eligibility traces: the optimizer of the streaming recipe (Elsayed,
Vasan & Mahmood 2024, "Streaming Deep Reinforcement Learning Finally Works", arXiv 2410.14606), and the semi-gradient
TD(λ) step it makes (Sutton & Barto, Reinforcement Learning: An Introduction, 2nd ed., §12.2, §12.7).
"""

import math
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import numpy as np
import torch as th

#: ``ObGD``'s κ for a value learner (q̂, v̂), the paper's; an actor's is ``ACTOR_KAPPA``
DEFAULT_KAPPA = 2.0
#: ``ObGD``'s κ for an actor (a policy network), the paper's
ACTOR_KAPPA = 3.0


class ObGD(th.optim.Optimizer):
    r"""
    Overshooting-bounded gradient descent (Elsayed, Vasan & Mahmood 2024, arXiv 2410.14606): semi-gradient TD(λ) with
    accumulating eligibility traces (S&B §12.2, eqs. 12.5–12.7) whose step size is cut where a full step would
    overshoot the target. Each ``step`` takes the TD error :math:`\delta` of one transition and, in every parameter's
    ``.grad``, the gradient of the *prediction* (:math:`\nabla \hat q(S_t, A_t, \mathbf w)` or
    :math:`\nabla \hat v(S_t, \mathbf w)`, not a loss's), and makes

    .. math::

        \mathbf e &\leftarrow \gamma\lambda\, \mathbf e + \nabla \hat q \qquad \text{(eq. 12.5; the decay } \gamma\lambda
        \text{ is } \texttt{step}\text{'s } \texttt{trace\_decay}\text{)} \\
        \bar\delta &= \max(|\delta|, 1), \qquad M = \alpha \kappa \bar\delta \lVert \mathbf e \rVert_1 \\
        \mathbf w &\leftarrow \mathbf w + \frac{\alpha}{\max(M, 1)}\, \delta\, \mathbf e \qquad \text{(eq. 12.7, the
        step } \alpha \text{ cut to } \alpha / M \text{ where } M > 1\text{)}.

    :math:`\lVert \mathbf e \rVert_1` is over every parameter the optimizer holds. With :math:`\kappa = 0` the bound
    is off (:math:`M = 0`): the book's update with accumulating traces, step :math:`\alpha`. The paper's settings:
    α = 1 and κ = 2 for a value learner, 3 for an actor, with λ = 0.8.

    The traces are the optimizer's state (``state[p]["eligibility_trace"]``, the shape of ``p``): ``state_dict()``
    holds them, so a model saved and loaded continues with them. A trace starts at 0 and restarts with
    ``trace_decay=0`` (the first step of an episode: the book's :math:`\mathbf z \leftarrow \mathbf 0`).

    :param params: the parameters (or parameter groups) to train
    :param lr: the step size α (the algorithm's ``learning_rate`` sets it before every update)
    :param kappa: κ, the bound's scale: at most :math:`1/\kappa` of the way to the target per step (≥ 0; 0: no bound)
    :param unknown: refused (λ and γ are the algorithm's ``td_lambda`` and ``gamma``)
    :raises ValueError: for a negative or non-finite ``lr`` or ``kappa``
    :raises TypeError: for any other argument, naming where λ and γ are set
    """

    def __init__(self, params: Iterable[Any], lr: float = 1.0, kappa: float = DEFAULT_KAPPA, **unknown: Any) -> None:
        if unknown:
            # (Python's own error names no fix; the paper's code names λ and γ among the optimizer's arguments)
            raise TypeError(
                f"ObGD() got unexpected arguments {', '.join(map(repr, unknown))}: it takes lr (α) and kappa (κ). The "
                "traces' λ is the algorithm's td_lambda (NStepSARSA; REINFORCE's steps take λ = 0) and γ its gamma: "
                "pass them to the algorithm, not in optimizer_kwargs"
            )
        for name, value, hint in (
            ("lr", lr, "α = 1 is the paper's (the algorithm's learning_rate sets it)"),
            ("kappa", kappa, "κ = 2 is the paper's for a value learner, 3 for an actor; 0 turns the bound off"),
        ):
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or value < 0:
                raise ValueError(f"ObGD({name}={value!r}): must be a finite number >= 0; {hint}")
        super().__init__(params, {"lr": lr, "kappa": kappa})

    def step(  # type: ignore[override]
        self, closure: Callable[[], float] | None = None, *, td_error: float | None = None, trace_decay: float = 0.0
    ) -> None:
        r"""
        One step along the traces (see the class): :math:`\mathbf e \leftarrow \gamma\lambda \mathbf e + \nabla`, then
        :math:`\mathbf w \leftarrow \mathbf w + \frac{\alpha}{\max(M, 1)} \delta \mathbf e`, with each parameter's
        ``.grad`` as :math:`\nabla`. A parameter without a gradient (``.grad`` None) is left as it is, its trace too.

        :param closure: not supported (ObGD steps on one transition's TD error, given as ``td_error``)
        :param td_error: δ of the transition, e.g. :math:`R_{t+1} + \gamma \hat q(S_{t+1}, A_{t+1}) -
            \hat q(S_t, A_t)` (S&B eq. 12.6), a float
        :param trace_decay: γλ, the traces' decay before the gradient is added; 0 restarts them from the gradient
            (the first step of an episode)
        :raises ValueError: without ``td_error``, with a closure, or for a ``trace_decay`` outside [0, 1]
        """
        if closure is not None or td_error is None:
            raise ValueError(
                "ObGD.step(td_error=δ, trace_decay=γλ): ObGD steps along its eligibility traces by the TD error δ of one "
                "transition, with each parameter's .grad the gradient of the prediction (∇q̂ or ∇v̂, not of a loss); it "
                "takes no closure. NStepSARSA makes these steps itself with update_mode='per_step' and n_steps=1"
            )
        self.step_with_gradients([p.grad for p in self.parameter_list()], td_error=td_error, trace_decay=trace_decay)

    def parameter_list(self) -> list[th.Tensor]:
        """
        :return: the parameters the optimizer holds, group after group: the order in which ``step_with_gradients``
            takes their gradients
        """
        return [p for group in self.param_groups for p in group["params"]]

    def step_with_gradients(self, gradients: Sequence[th.Tensor | None], *, td_error: float, trace_decay: float = 0.0) -> None:
        r"""
        ``step`` with the gradients given instead of read from ``.grad``: the algorithms' per-step updates take them
        from ``torch.autograd.grad`` (``td_step``), which spares each env step the ``.grad`` round trip (``zero_grad``,
        accumulation) and the hooks of ``Optimizer.step``. The same arithmetic, in the same order, as ``step``.

        :param gradients: :math:`\nabla` of each parameter, in the order of ``parameter_list()``, each of its shape (None:
            that parameter and its trace are left as they are)
        :param td_error: δ of the transition (see ``step``)
        :param trace_decay: γλ (see ``step``)
        :raises ValueError: for a ``trace_decay`` outside [0, 1], or a number of gradients other than of parameters
        """
        if not 0.0 <= trace_decay <= 1.0:
            raise ValueError(f"ObGD.step(trace_decay={trace_decay!r}): the decay γλ of the traces must be in [0, 1]")
        gradients = list(gradients)
        n_parameters = sum(len(group["params"]) for group in self.param_groups)
        if len(gradients) != n_parameters:
            raise ValueError(
                f"ObGD.step_with_gradients: {len(gradients)} gradients for the optimizer's {n_parameters} parameters; "
                "give one per parameter of "
                "parameter_list(), in its order (None for a parameter without one)"
            )
        groups = []
        l1_norm = 0.0
        first = 0
        with th.no_grad():
            for group in self.param_groups:
                group_gradients = gradients[first : first + len(group["params"])]
                first += len(group["params"])
                pairs = [(p, g) for p, g in zip(group["params"], group_gradients, strict=True) if g is not None]
                if not pairs:
                    continue
                params = [p for p, _ in pairs]
                grads = [g for _, g in pairs]
                traces = [self._trace(p) for p in params]
                if trace_decay == 0.0:
                    # e ← ∇ (a restart: 0 · e would keep a non-finite entry of the old trace as NaN)
                    th._foreach_copy_(traces, grads)
                else:
                    # e ← γλ e + ∇ (S&B eq. 12.5)
                    th._foreach_mul_(traces, trace_decay)
                    th._foreach_add_(traces, grads)
                l1_norm += sum(norm.item() for norm in th._foreach_norm(traces, 1))
                groups.append((group, params, traces))
            # δ̄ = max(|δ|, 1); M = α κ δ̄ ‖e‖₁ (the paper's bound on the step's overshoot, ‖e‖₁ over every parameter)
            delta_bar = max(abs(td_error), 1.0)
            for group, params, traces in groups:
                bound = group["lr"] * group["kappa"] * delta_bar * l1_norm
                step_size = group["lr"] / bound if bound > 1.0 else group["lr"]
                # w ← w + (step) δ e (S&B eq. 12.7 with the bounded step)
                th._foreach_add_(params, traces, alpha=step_size * td_error)

    def _trace(self, parameter: th.Tensor) -> th.Tensor:
        """:return: the parameter's eligibility trace, zeros at first (made on its first step)"""
        state = self.state[parameter]
        if "eligibility_trace" not in state:
            state["eligibility_trace"] = th.zeros_like(parameter, memory_format=th.preserve_format)
        return state["eligibility_trace"]

    def reset_traces(self) -> None:
        """Set every eligibility trace to 0 (the book's :math:`\\mathbf z \\leftarrow \\mathbf 0`)."""
        for state in self.state.values():
            if "eligibility_trace" in state:
                state["eligibility_trace"].zero_()


def td_step(
    optimizer: ObGD, prediction: th.Tensor, target: th.Tensor, trace_decay: float, restart: bool
) -> tuple[np.ndarray, float]:
    r"""
    One update of semi-gradient TD(λ) with eligibility traces under ObGD (S&B §12.2; with
    :math:`\hat q(S_t, A_t, \mathbf w)` as the prediction, the Sarsa(λ) of §12.7):

    .. math::

        \delta_t = G_{t:t+1} - \hat q(S_t, A_t, \mathbf w), \qquad
        \mathbf e \leftarrow \gamma\lambda\, \mathbf e + \nabla \hat q(S_t, A_t, \mathbf w), \qquad
        \mathbf w \leftarrow \mathbf w + \alpha' \delta_t\, \mathbf e,

    with :math:`G_{t:t+1} = R_{t+1} + \gamma \hat q(S_{t+1}, A_{t+1}, \mathbf w)` (eq. 12.6's TD error for action
    values) and :math:`\alpha'` ObGD's bounded step.

    :param optimizer: the ObGD of the prediction's parameters
    :param prediction: :math:`\hat q(S_t, A_t, \mathbf w)` (or :math:`\hat v(S_t, \mathbf w)`) of one transition,
        shape (1,), with its graph
    :param target: its one-step target :math:`G_{t:t+1}`, shape (1,), without gradient (semi-gradient)
    :param trace_decay: γλ
    :param restart: whether :math:`S_t` starts an episode: the traces restart from its gradient (the book's
        :math:`\mathbf z \leftarrow \mathbf 0` at the start of each episode; the same as zeroing them at its end)
    :return: the prediction before the step, shape (1,), float32, and :math:`\tfrac12 \delta_t^2`
    :raises ValueError: for more than one transition
    """
    if prediction.numel() != 1:
        raise ValueError(
            f"an ObGD step takes one transition at a time (its TD error and traces), not {prediction.numel()}: train "
            "with update_mode='per_step', n_steps=1 and one env"
        )
    # δ_t = G_{t:t+1} − q̂(S_t, A_t, w) (S&B eq. 12.6; the target without gradient: semi-gradient)
    td_error = (target - prediction.detach()).item()
    # ∇q̂(S_t, A_t, w)
    parameters = optimizer.parameter_list()
    gradients = th.autograd.grad(prediction.sum(), parameters, allow_unused=True)
    # e ← γλe + ∇q̂ (e ← ∇q̂ at an episode's start); w ← w + (bounded step) δ e
    optimizer.step_with_gradients(gradients, td_error=td_error, trace_decay=0.0 if restart else trace_decay)
    return prediction.detach().cpu().numpy(), 0.5 * td_error * td_error


def uses_obgd(policy_kwargs: dict[str, Any] | None) -> bool:
    """
    :param policy_kwargs: a model's ``policy_kwargs``
    :return: whether they choose ``ObGD`` (or a subclass of it) as ``optimizer_class``
    """
    optimizer_class = (policy_kwargs or {}).get("optimizer_class")
    return isinstance(optimizer_class, type) and issubclass(optimizer_class, ObGD)


def check_obgd_settings(why: str, required: Sequence[tuple[str, Any, Any, str]], max_grad_norm: float | None) -> None:
    """
    The check an algorithm makes of its settings where ``policy_kwargs`` choose ``ObGD``: each setting ObGD's step
    needs, and no gradient clipping (ObGD bounds its own step).

    :param why: what ObGD's step is in the algorithm, for the messages
    :param required: (argument, its value, the value ObGD needs, the fix) for each setting
    :param max_grad_norm: ``max_grad_norm`` (``math.inf`` or None: no clipping)
    :raises ValueError: naming every setting ObGD cannot train with, each with its fix
    """
    problems = [
        f"{name}={value!r} with optimizer_class=ObGD: {fix}" for name, value, needed, fix in required if value != needed
    ]
    if max_grad_norm is not None and math.isfinite(max_grad_norm):
        problems.append(
            f"max_grad_norm={max_grad_norm!r} with optimizer_class=ObGD: drop max_grad_norm (ObGD bounds its own step, "
            "M = ακδ̄‖e‖₁)"
        )
    if problems:
        raise ValueError(f"{why}. " + "; ".join(problems) + ". Or use another optimizer")
