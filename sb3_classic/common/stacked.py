"""
K networks of one shape as one module, and the optimizer and gradient clipping that keep them K independent networks.

The K members' weights of each layer are one tensor of shape (K, in, out) and each layer is one batched matrix product
(``torch.baddbmm``), as CORL's ``VectorizedLinear`` does for ensembles of critics: one call per layer for all members
in place of K small ones, whose fixed cost dominates at the sizes of the classic tasks.
"""

from collections.abc import Sequence

import numpy as np
import torch as th
import torch.nn.functional as F
from torch import nn
from torch.optim.adam import adam

#: Elementwise activations without parameters: applied to the stacked (K, B, features) activations they act on each
#: member's features as on its own network's
ELEMENTWISE_ACTIVATIONS: tuple[type[nn.Module], ...] = (
    nn.ReLU,
    nn.ReLU6,
    nn.LeakyReLU,
    nn.ELU,
    nn.CELU,
    nn.SELU,
    nn.GELU,
    nn.SiLU,
    nn.Mish,
    nn.Tanh,
    nn.Sigmoid,
    nn.Softplus,
    nn.Hardtanh,
    nn.Identity,
)


class StackedLinear(nn.Module):
    """
    K linear layers y_k = x_k W_k + b_k as one module: ``weight`` of shape (K, in, out), ``bias`` of shape (K, 1, out),
    and one ``torch.baddbmm`` for all members (CORL's ``VectorizedLinear``).

    :param weight: the members' weights W_k, shape (K, in_features, out_features)
    :param bias: their biases b_k, shape (K, 1, out_features), or None for none
    """

    def __init__(self, weight: th.Tensor, bias: th.Tensor | None) -> None:
        super().__init__()
        self.weight = nn.Parameter(weight)
        self.bias = None if bias is None else nn.Parameter(bias)

    @classmethod
    def from_linears(cls, linears: Sequence[nn.Linear]) -> "StackedLinear":
        """
        :param linears: the members' layers, of one shape (``nn.Linear``'s weight is (out, in): stacked transposed)
        :return: a stacked layer holding copies of their weights, member k's those of ``linears[k]``
        """
        with th.no_grad():
            weight = th.stack([linear.weight.T for linear in linears])
            bias = None if linears[0].bias is None else th.stack([linear.bias for linear in linears]).unsqueeze(1)
        return cls(weight, bias)

    def forward(self, x: th.Tensor, members: th.Tensor | None = None) -> th.Tensor:
        """
        :param x: the members' inputs, shape (K, B, in_features), or (M, B, in_features) for the M ``members``
        :param members: the members whose layers to apply, shape (M,), int64; None: all K
        :return: x_k W_k + b_k for every member (each of ``members``), shape (K or M, B, out_features)
        """
        weight: th.Tensor = self.weight
        bias: th.Tensor | None = self.bias
        if members is not None:
            weight = weight.index_select(0, members)
            bias = None if bias is None else bias.index_select(0, members)
        if bias is None:
            return th.bmm(x, weight)
        return th.baddbmm(bias, x, weight)

    def share_with(self, linears: Sequence[nn.Linear]) -> None:
        """:param linears: the members' layers, in member order: their parameters become views of the stacked ones"""
        for member, linear in enumerate(linears):
            linear.weight.data = self.weight.data[member].T
            if linear.bias is not None and self.bias is not None:
                linear.bias.data = self.bias.data[member, 0]


class StackedLayerNorm(nn.Module):
    """
    K layer normalisations (Ba, Kiros & Hinton 2016; torch's ``nn.LayerNorm`` over the last dimension) as one module:
    each member's features normalised on their own, then its own gain and bias, ``weight`` and ``bias`` of shape
    (K, 1, features) (None where the members' layers have none).

    :param weight: the members' gains, shape (K, 1, features), or None
    :param bias: their biases, shape (K, 1, features), or None
    :param eps: the members' ``eps``
    """

    def __init__(self, weight: th.Tensor | None, bias: th.Tensor | None, eps: float) -> None:
        super().__init__()
        self.weight = None if weight is None else nn.Parameter(weight)
        self.bias = None if bias is None else nn.Parameter(bias)
        self.eps = eps

    @classmethod
    def from_layer_norms(cls, norms: Sequence[nn.LayerNorm]) -> "StackedLayerNorm":
        """
        :param norms: the members' layers, of one shape, each over the last dimension only
        :return: a stacked layer holding copies of their gains and biases
        :raises TypeError: for a normalisation over more than the last dimension
        """
        first = norms[0]
        if len(first.normalized_shape) != 1:
            raise TypeError(
                f"{first!r} normalises over {len(first.normalized_shape)} dimensions: a stacked network normalises each "
                "member's features, the last dimension only"
            )
        with th.no_grad():
            weight = None if first.weight is None else th.stack([norm.weight for norm in norms]).unsqueeze(1)
            bias = None if first.bias is None else th.stack([norm.bias for norm in norms]).unsqueeze(1)
        return cls(weight, bias, first.eps)

    def forward(self, x: th.Tensor, members: th.Tensor | None = None) -> th.Tensor:
        """
        :param x: the members' features, shape (K, B, features), or (M, B, features) for the M ``members``
        :param members: the members whose layers to apply, shape (M,), int64; None: all K
        :return: each member's (x − mean) / √(var + eps) · gain + bias, over its own features, same shape as x
        """
        y = F.layer_norm(x, x.shape[-1:], None, None, self.eps)
        weight: th.Tensor | None = self.weight
        bias: th.Tensor | None = self.bias
        if members is not None:
            weight = None if weight is None else weight.index_select(0, members)
            bias = None if bias is None else bias.index_select(0, members)
        if weight is not None:
            y = y * weight
        return y if bias is None else y + bias

    def share_with(self, norms: Sequence[nn.LayerNorm]) -> None:
        """:param norms: the members' layers, in member order: their gains and biases become views of the stacked ones"""
        for member, norm in enumerate(norms):
            if norm.weight is not None and self.weight is not None:
                norm.weight.data = self.weight.data[member, 0]
            if norm.bias is not None and self.bias is not None:
                norm.bias.data = self.bias.data[member, 0]


class StackedMLP(nn.Module):
    """
    K multilayer perceptrons of one shape (the same layer sizes and activations, weights per member) as one module:
    ``StackedLinear`` and ``StackedLayerNorm`` layers and the members' elementwise activations.

    :param layers: the stacked layers and the activations between them, in order
    """

    def __init__(self, layers: Sequence[nn.Module]) -> None:
        super().__init__()
        self.layers = nn.Sequential(*layers)

    @classmethod
    def from_sequentials(cls, networks: Sequence[nn.Sequential], name: str = "q̂") -> "StackedMLP":
        """
        :param networks: the members' MLPs: ``nn.Linear`` and ``nn.LayerNorm`` layers and elementwise activations
            without parameters (``ELEMENTWISE_ACTIVATIONS``), of the same sizes and activations
        :param name: the networks' name in the errors
        :return: the stacked MLP holding copies of their weights (``share_with`` makes the members' parameters views of
            them)
        :raises TypeError: for a layer of another kind
        :raises ValueError: for members of different shapes or activations
        """
        first = list(networks[0])
        layers: list[nn.Module] = []
        for index, layer in enumerate(first):
            column = [list(network)[index] if len(network) == len(first) else None for network in networks]
            for member, other in enumerate(column):
                if other is None or type(other) is not type(layer) or repr(other) != repr(layer):
                    raise ValueError(
                        f"member {member}'s {name} differs from member 0's at layer {index} ({other!r} against {layer!r}): "
                        "the members of a population have one setting (the same net_arch, activation_fn and its kwargs)"
                    )
            if isinstance(layer, nn.Linear):
                layers.append(StackedLinear.from_linears(column))  # type: ignore[arg-type]
            elif isinstance(layer, nn.LayerNorm):
                layers.append(StackedLayerNorm.from_layer_norms(column))  # type: ignore[arg-type]
            elif isinstance(layer, ELEMENTWISE_ACTIVATIONS) and next(layer.parameters(), None) is None:
                layers.append(layer)
            else:
                raise TypeError(
                    f"layer {index} of {name} is a {type(layer).__name__}: a stacked network holds linear layers, "
                    "LayerNorm and elementwise activations "
                    f"({', '.join(kind.__name__ for kind in ELEMENTWISE_ACTIVATIONS)}). Train these members one after the "
                    "other (model.learn)"
                )
        return cls(layers)

    def share_with(self, networks: Sequence[nn.Sequential]) -> None:
        """
        Make each member's parameters views into the stacked ones (shared storage, the same ``Parameter`` objects): a
        forward pass of a member's own network, its ``state_dict`` and its polyak copies read the stacked weights as
        they are, with no copying.

        :param networks: the members' MLPs, in member order
        """
        stacked = [layer for layer in self.layers if isinstance(layer, StackedLinear | StackedLayerNorm)]
        for index, layer in enumerate(stacked):
            layer.share_with([parametrized_layers(network)[index] for network in networks])  # type: ignore[misc]

    @staticmethod
    def own_storage(networks: Sequence[nn.Sequential]) -> None:
        """
        Give each member's parameters storage of their own again (a contiguous copy of what they hold now), so that the
        stacked module can go and a saved member holds its own weights only.

        :param networks: the members' MLPs
        """
        for network in networks:
            for parameter in network.parameters():
                parameter.data = parameter.data.clone(memory_format=th.contiguous_format)

    def forward(self, x: th.Tensor, members: th.Tensor | None = None) -> th.Tensor:
        """
        The layers are called directly (``torch.baddbmm`` and each activation's ``forward``), past ``nn.Module``'s call
        machinery, whose cost is most of a small network's forward pass.

        :param x: the members' inputs, shape (K, B, in_features), or (M, B, in_features) for the M ``members``
        :param members: the members whose networks to apply, shape (M,), int64; None: all K (a gradient then reaches
            the given members' slices only)
        :return: every member's outputs (each of ``members``'), shape (K or M, B, out_features)
        """
        for layer in self.layers:
            x = layer.forward(x, members) if isinstance(layer, StackedLinear | StackedLayerNorm) else layer.forward(x)
        return x

    @th.no_grad()
    def inference(self, x: th.Tensor) -> th.Tensor:
        """
        :param x: the members' inputs, shape (K, B, in_features)
        :return: ``forward`` without gradient (the action choice of a population at every env step), shape
            (K, B, out_features)
        """
        return self.forward(x)


def parametrized_layers(network: nn.Sequential) -> list[nn.Linear | nn.LayerNorm]:
    """:return: the network's layers with parameters, ``nn.Linear`` and ``nn.LayerNorm``, in order (a stacked MLP's)"""
    return [layer for layer in network if isinstance(layer, nn.Linear | nn.LayerNorm)]


def clip_grad_norms_per_member(parameters: Sequence[th.Tensor], max_norm: float) -> th.Tensor:
    """
    ``torch.nn.utils.clip_grad_norm_`` for each member on its own: member k's gradients, all layers together, scaled by
    min(1, max_norm / (‖g_k‖ + 1e-6)) with ‖g_k‖ the global 2-norm of its slices (not of the whole stack).

    :param parameters: stacked parameters, member first (shape (K, ...)), with gradients
    :param max_norm: the largest norm a member's gradient keeps
    :return: each member's norm before clipping, shape (K,)
    """
    grads = [parameter.grad for parameter in parameters if parameter.grad is not None]
    norms = th.stack([th.linalg.vector_norm(grad.flatten(1), 2, dim=1) for grad in grads])
    total_norms = th.linalg.vector_norm(norms, 2, dim=0)
    clip_coef = th.clamp(max_norm / (total_norms + 1e-6), max=1.0)
    for grad in grads:
        grad.mul_(clip_coef.view(-1, *([1] * (grad.dim() - 1))))
    return total_norms


class StackedAdam:
    """
    Adam (Kingma & Ba 2015) over stacked parameters (member first, shape (K, ...)) as K independent Adams: each member
    its own step count (hence bias corrections) and learning rate, and a step moves only the members it is given.

    torch's ``Adam`` keeps one step count per tensor and moves every element of it at each step (its moments decay even
    where the gradient is 0), and no library optimizer takes a mask over slices of a tensor, which a population needs:
    n-step SARSA's members at an episode's end train several transitions one after the other while the others train one
    or none. Here each member's slice of each stacked parameter is a tensor of its own (a view) with its own step count,
    and a step passes the slices of the members it moves to torch's Adam kernel: the arithmetic is
    ``torch.optim.Adam``'s, fused or not as the members' optimizers are. A step of every member when all have the same
    step count and learning rate (the members of a population whose updates keep in step) passes the whole stacked
    tensors instead, with one step count each: the same elementwise arithmetic on the same values, in one kernel call
    per parameter rather than K (torch's kernels cost a fixed overhead per tensor, which dominates at the sizes of small
    networks). torch's fused CPU kernel may round an element differently in the last bit by where it sits in its
    tensor (reordering a tensor's elements changes some of its results): as a member's slice is laid out otherwise than
    its own ``nn.Linear`` weight (transposed) and a whole stack otherwise than its slices, a fused step may differ from
    the member's own optimizer's in the last bits of some elements (the unfused implementations give the same bits).

    The step counts of the slices are the entries of one tensor of shape (parameters, K). Fused on the CPU, a step
    writes its members' new counts into it with one copy from ``steps`` and calls torch's fused kernel
    (``torch._fused_adam_``, the op that ``torch.optim.Adam(fused=True)`` calls) on the slices directly: torch's
    functional ``adam`` would group the slices by device and increment each slice's count with a call of its own, which
    costs several times the kernel at these sizes. Elsewhere (the other implementations, and any device but the CPU,
    where that copy would wait for the device at every step) a step goes through torch's functional ``adam``, which
    increments the counts it is given.

    :param parameters: the stacked parameters, member first
    :param n_members: K
    :param betas: (β₁, β₂)
    :param eps: ε
    :param fused: torch's fused kernel (the members' optimizers' ``fused``)
    :param foreach: torch's multi-tensor path (their ``foreach``)
    :param flush_denormal: flush denormal numbers to zero during each step (``torch.set_flush_denormal``, on the CPUs
        that support it; off again after the step, torch's default, as torch cannot read the setting): Adam's second
        moments of weights whose gradients are rarely non-zero decay into the denormal range, where the CPU's
        arithmetic is many times slower (the fused step of a small network's Adam then costs several times its normal
        cost). The update changes only where a moment or weight below 1.2e-38 in magnitude is read or written as 0
    """

    def __init__(
        self,
        parameters: Sequence[th.Tensor],
        n_members: int,
        betas: tuple[float, float] = (0.9, 0.999),
        eps: float = 1e-8,
        fused: bool | None = None,
        foreach: bool | None = None,
        flush_denormal: bool = False,
    ) -> None:
        self.parameters = list(parameters)
        self.flush_denormal = flush_denormal
        self.n_members = n_members
        self.beta1, self.beta2 = betas
        self.eps = eps
        self.fused, self.foreach = fused, foreach
        device = self.parameters[0].device
        #: whether a step calls torch's fused kernel itself (fused, on the CPU, and the kernel is there)
        self._fused_kernel = bool(fused) and device.type == "cpu" and hasattr(th, "_fused_adam_")
        self.exp_avgs = [th.zeros_like(parameter, memory_format=th.contiguous_format) for parameter in self.parameters]
        self.exp_avg_sqs = [th.zeros_like(parameter, memory_format=th.contiguous_format) for parameter in self.parameters]
        # Member k's slices, one tensor each: parameters, moments, and its step count t (one per slice, as torch's)
        self._parameter_slices = [parameter.data.unbind(0) for parameter in self.parameters]
        self._exp_avg_slices = [exp_avg.unbind(0) for exp_avg in self.exp_avgs]
        self._exp_avg_sq_slices = [exp_avg_sq.unbind(0) for exp_avg_sq in self.exp_avg_sqs]
        # Every member's step count t, and every slice's as torch's Adam reads it: entry (p, k) of one float32 tensor
        # (its views, _steps[p][k], are the slices' counts)
        self._member_steps = np.zeros(n_members, dtype=np.int64)
        self._slice_steps = th.zeros((len(self.parameters), n_members), dtype=th.float32, device=device)
        self._steps = [row.unbind(0) for row in self._slice_steps]

    @property
    def steps(self) -> np.ndarray:
        """Each member's step count t, shape (K,)."""
        return self._member_steps.copy()

    def set_state(self, member: int, step: int) -> None:
        """:param member: k; :param step: its step count t (its moments are set in ``exp_avgs``/``exp_avg_sqs``)"""
        self._member_steps[member] = step
        self._slice_steps[:, member] = step

    def zero_grad(self) -> None:
        """Drop the gradients (``set_to_none``, as torch's optimizers)."""
        for parameter in self.parameters:
            parameter.grad = None

    @th.no_grad()
    def step(self, members: np.ndarray, learning_rates: np.ndarray) -> None:
        """
        One Adam step of the given members; the others' weights, moments and step counts are left as they are.

        :param members: the members to step, shape (M,)
        :param learning_rates: every member's learning rate α, shape (K,)
        """
        if not self.flush_denormal:
            self._step(members, learning_rates)
            return
        th.set_flush_denormal(True)
        try:
            self._step(members, learning_rates)
        finally:
            th.set_flush_denormal(False)

    def _step(self, members: np.ndarray, learning_rates: np.ndarray) -> None:
        grads = [th.zeros_like(parameter) if parameter.grad is None else parameter.grad for parameter in self.parameters]
        counts = self._member_steps[members]
        if len(members) == self.n_members and (counts == counts[0]).all() and (learning_rates == learning_rates[0]).all():
            self._step_whole_stack(grads, int(counts[0]), float(learning_rates[0]))
            return
        self._member_steps[members] += 1
        if self._fused_kernel:
            # (the others' counts are written as they are)
            self._slice_steps.copy_(th.from_numpy(self._member_steps).expand_as(self._slice_steps))
        grad_slices = [grad.unbind(0) for grad in grads]
        # One call per learning rate (one, unless the members' schedules or decays have parted them)
        for learning_rate in sorted(set(learning_rates[members].tolist())):
            group = [int(k) for k in members if learning_rates[k] == learning_rate]
            self._adam(
                [slices[k] for slices in self._parameter_slices for k in group],
                [slices[k] for slices in grad_slices for k in group],
                [slices[k] for slices in self._exp_avg_slices for k in group],
                [slices[k] for slices in self._exp_avg_sq_slices for k in group],
                [steps[k] for steps in self._steps for k in group],
                learning_rate,
            )

    def _step_whole_stack(self, grads: list[th.Tensor], step: int, learning_rate: float) -> None:
        """A step of every member, all at step count ``step`` with one learning rate: torch's Adam on the stacks."""
        self._slice_steps += 1
        # The stack's count: member 0's, as every member's (fused); a tensor per stack at t before the step, which torch's
        # adam increments (otherwise)
        steps = (
            [steps[0] for steps in self._steps]
            if self._fused_kernel
            else [th.tensor(float(step), dtype=th.float32, device=self._slice_steps.device) for _ in self.parameters]
        )
        self._adam(
            [parameter.data for parameter in self.parameters], grads, self.exp_avgs, self.exp_avg_sqs, steps, learning_rate
        )
        self._member_steps += 1

    def _adam(
        self,
        parameters: list[th.Tensor],
        grads: list[th.Tensor],
        exp_avgs: list[th.Tensor],
        exp_avg_sqs: list[th.Tensor],
        steps: list[th.Tensor],
        learning_rate: float,
    ) -> None:
        """
        torch's Adam step of the given tensors. Fused, ``steps`` hold their step counts t after this step (the caller
        increments them); otherwise before it (torch's ``adam`` increments them).
        """
        if self._fused_kernel:
            th._fused_adam_(
                parameters,
                grads,
                exp_avgs,
                exp_avg_sqs,
                [],
                steps,
                amsgrad=False,
                lr=learning_rate,
                beta1=self.beta1,
                beta2=self.beta2,
                weight_decay=0.0,
                eps=self.eps,
                maximize=False,
            )
            return
        adam(
            parameters,
            grads,
            exp_avgs,
            exp_avg_sqs,
            [],
            steps,
            foreach=self.foreach,
            fused=self.fused,
            amsgrad=False,
            beta1=self.beta1,
            beta2=self.beta2,
            lr=learning_rate,
            weight_decay=0.0,
            eps=self.eps,
            maximize=False,
        )
