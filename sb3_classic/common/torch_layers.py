"""
Network options shared by the policies: activations with arguments, He (Kaiming) and sparse initialisation, and the
optimizer's implementation.
"""

import math
import numbers
from collections.abc import Iterable, Sequence
from functools import partial
from typing import Any, Literal

import numpy as np
import torch as th
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from sb3_classic.common.utils import check_choice

#: ``weight_init`` choices: SB3's orthogonal scheme (A2C/PPO), He et al. 2015, or PyTorch's own defaults
WEIGHT_INITS = ("orthogonal", "kaiming", "default")
#: ``weight_init`` choices of a policy that also offers the streaming recipe's sparse initialisation (``sparse_init``)
WEIGHT_INITS_WITH_SPARSE = (*WEIGHT_INITS, "sparse")

#: The fraction of each unit's incoming weights that ``sparse_init`` sets to 0 (Elsayed, Vasan & Mahmood 2024's)
SPARSITY = 0.9

# The nonlinearity argument of nn.init.kaiming_normal_ for the activations it knows
Nonlinearity = Literal["relu", "leaky_relu", "tanh", "sigmoid", "selu"]
_KAIMING_NONLINEARITY: dict[type[nn.Module], Nonlinearity] = {
    nn.ReLU: "relu",
    nn.LeakyReLU: "leaky_relu",
    nn.Tanh: "tanh",
    nn.Sigmoid: "sigmoid",
    nn.SELU: "selu",
}


def check_net_arch(net_arch: Any, keys: Sequence[str] = ()) -> None:
    """
    :param net_arch: hidden layer sizes, a list of positive integers (or None for the policy's default)
    :param keys: the keys a dict of such lists may have (ActorCriticPolicy's ``pi``, ``vf``); none: only a list
    :raises ValueError: for anything else, e.g. ``64`` for ``[64]``, a size of 0 or less, or a dict key the policy
        would ignore (SAC/TD3's ``qf``)
    """
    if net_arch is None:
        return
    example = "e.g. [64, 64] (one hidden layer: [64]; none: [])"
    if isinstance(net_arch, dict) and not keys:
        raise ValueError(
            f"net_arch={net_arch!r}: this network takes a list of hidden layer sizes, {example}; dict(pi=..., vf=...) "
            "and dict(pi=..., qf=...) are for actor-critic methods"
        )
    if isinstance(net_arch, dict):
        unknown = sorted(set(net_arch) - set(keys), key=str)
        if unknown:
            raise ValueError(
                f"net_arch={net_arch!r}: unknown key(s) {', '.join(map(repr, unknown))}; this policy takes a list of "
                f"hidden layer sizes for its networks, {example}, or a dict with the keys {', '.join(map(repr, keys))}"
            )
        for key, sizes in net_arch.items():
            _check_layer_sizes(f"net_arch[{key!r}]", sizes, example)
        return
    separate = [part for part in net_arch if isinstance(part, dict)] if isinstance(net_arch, list) else []
    if separate:
        # SB3's form before 1.8, [shared sizes..., dict(pi=..., vf=...)], which A2C/PPO still accept with a warning
        fix = f"net_arch={separate[0]!r} (SB3's form since 1.8; no shared layers)"
        if not keys:
            fix = f"a list of hidden layer sizes, {example}"
        raise ValueError(f"net_arch={net_arch!r}: a dict inside the list is SB3's older form; write {fix}")
    _check_layer_sizes("net_arch", net_arch, example)


def _check_layer_sizes(name: str, sizes: Any, example: str) -> None:
    if isinstance(sizes, np.ndarray) and sizes.ndim == 1:
        raise ValueError(f"{name}={sizes!r}: write it as a list, net_arch={sizes.tolist()!r}")
    if isinstance(sizes, (str, bytes, dict)) or not isinstance(sizes, Sequence):
        raise ValueError(f"{name}={sizes!r} must be a list of hidden layer sizes, {example}")
    for size in sizes:
        if isinstance(size, bool) or not isinstance(size, numbers.Integral) or size < 1:
            raise ValueError(f"{name}={sizes!r}: each hidden layer size must be an integer >= 1, {example}")


def make_activation(activation_fn: type[nn.Module], activation_kwargs: dict[str, Any] | None) -> type[nn.Module]:
    """
    SB3 builds activations by calling ``activation_fn()``; bind ``activation_kwargs`` so that e.g.
    ``activation_fn=nn.LeakyReLU, activation_kwargs=dict(negative_slope=0.1)`` (the seed report's Acrobot
    REINFORCE setting) can be written in a zoo YAML.

    :param activation_fn: activation class
    :param activation_kwargs: its constructor arguments
    :return: a callable building the activation
    :raises TypeError: if ``activation_fn`` is not an ``nn.Module`` class (a string, or an instance such as ``nn.ReLU()``)
    """
    if not (isinstance(activation_fn, type) and issubclass(activation_fn, nn.Module)):
        arguments = (
            f" (for its arguments: activation_fn={activation_fn.func.__name__}, activation_kwargs={activation_fn.keywords!r})"
            if isinstance(activation_fn, partial) and isinstance(activation_fn.func, type)
            else ""
        )
        raise TypeError(
            f"activation_fn={activation_fn!r} must be an activation class such as nn.ReLU (the class, not a string, a "
            f'partial or an instance nn.ReLU()){arguments}; in a zoo YAML: policy_kwargs: "dict(activation_fn=nn.ReLU)"'
        )
    if not activation_kwargs:
        return activation_fn
    return partial(activation_fn, **activation_kwargs)  # type: ignore[return-value]


def kaiming_init(
    modules: Iterable[nn.Module], activation_fn: type[nn.Module], activation_kwargs: dict[str, Any] | None
) -> None:
    """
    He (Kaiming) normal initialisation of the weights of every linear and convolutional layer in ``modules``, with
    the gain of ``activation_fn`` (ReLU's for activations ``nn.init`` has no gain for), and zero biases.

    :param modules: the hidden layers to initialise
    :param activation_fn: the activation that follows them
    :param activation_kwargs: its arguments (LeakyReLU's ``negative_slope`` enters the gain)
    """
    nonlinearity: Nonlinearity = _KAIMING_NONLINEARITY.get(activation_fn, "relu")
    slope = (activation_kwargs or {}).get("negative_slope", 0.01) if nonlinearity == "leaky_relu" else 0.0
    for module in modules:
        for layer in module.modules():
            if isinstance(layer, (nn.Linear, nn.Conv2d)):
                nn.init.kaiming_normal_(layer.weight, a=slope, nonlinearity=nonlinearity)
                if layer.bias is not None:
                    nn.init.zeros_(layer.bias)


def sparse_init(modules: Iterable[nn.Module], sparsity: float = SPARSITY) -> None:
    r"""
    Sparse initialisation (Elsayed, Vasan & Mahmood 2024, "Streaming Deep Reinforcement Learning Finally Works", arXiv
    2410.14606): every weight of the linear layers in ``modules`` drawn LeCun-uniform,
    :math:`U(-\sqrt{3 / n}, \sqrt{3 / n})` for a layer of fan-in :math:`n` (variance :math:`1/n`, LeCun et al. 1998),
    then :math:`\lfloor s n \rfloor` of each unit's :math:`n` incoming weights, chosen at random, set to 0; biases 0.
    With :math:`s` = 0.9 a unit of a 128-unit layer starts with 13 inputs, and one over CartPole-v1's 4 observations
    with 1. Draws from torch's global generator (seeded with the model).

    :param modules: the networks to initialise (each ``nn.Linear`` inside them, output layers included)
    :param sparsity: :math:`s`, the fraction of each unit's incoming weights set to 0, in [0, 1)
    :raises ValueError: for a ``sparsity`` outside [0, 1)
    """
    if not 0.0 <= sparsity < 1.0:
        raise ValueError(
            f"sparsity={sparsity!r} must be in [0, 1): the fraction of each unit's inputs set to 0 (0.9 is the paper's)"
        )
    for module in modules:
        for layer in module.modules():
            if isinstance(layer, nn.Linear):
                fan_in = layer.in_features
                bound = math.sqrt(3.0 / fan_in)
                with th.no_grad():
                    layer.weight.uniform_(-bound, bound)
                    # ⌊s n⌋ of each row (a unit's incoming weights) at random positions
                    n_zeros = math.floor(sparsity * fan_in)
                    zeros = th.rand(layer.weight.shape, device=layer.weight.device).argsort(dim=1)[:, :n_zeros]
                    layer.weight.scatter_(1, zeros, 0.0)
                if layer.bias is not None:
                    nn.init.zeros_(layer.bias)


def check_weight_init(weight_init: str | float, choices: tuple[str, ...] = WEIGHT_INITS) -> None:
    """
    :param weight_init: one of ``choices``, or a finite number (every weight starts at that constant)
    :param choices: the schemes the policy offers (``WEIGHT_INITS``, or ``WEIGHT_INITS_WITH_SPARSE``)
    """
    if isinstance(weight_init, numbers.Real) and not isinstance(weight_init, bool):
        if not math.isfinite(weight_init):
            raise ValueError(f"weight_init={weight_init!r} must be finite (0.0 is the book's start for linear methods)")
        return
    check_choice(
        "weight_init",
        weight_init,
        choices,
        hint="'kaiming' is He initialisation; a number (e.g. 0.0, the book's start for linear methods) sets all weights to it",
    )


def check_constant_init_is_linear(
    weight_init: str | float, modules: Iterable[nn.Module], outputs: Iterable[nn.Module]
) -> None:
    """
    A constant ``weight_init`` is for linear models: in a network with hidden layers every hidden unit would start
    with the same weights, get the same gradient and stay identical to the others (only the output biases learn).

    :param weight_init: the policy's ``weight_init``
    :param modules: the networks ``constant_init`` would set
    :param outputs: their output layers, the only layers a linear model has
    :raises ValueError: if ``weight_init`` is a number and ``modules`` hold a linear or convolutional layer that is not
        one of ``outputs``
    """
    if isinstance(weight_init, str):
        return
    output_ids = {id(layer) for layer in outputs}
    # Each layer once (a features extractor shared by two networks is one)
    hidden = list(
        {
            id(layer): layer
            for module in modules
            for layer in module.modules()
            if isinstance(layer, (nn.Linear, nn.Conv2d)) and id(layer) not in output_ids
        }.values()
    )
    if not hidden:
        return
    extractors = {
        id(extractor): extractor
        for module in modules
        for extractor in module.modules()
        if isinstance(extractor, BaseFeaturesExtractor)
    }
    in_extractors: dict[str, int] = {}  # per class (REINFORCE's actor and critic have a NatureCNN each)
    for extractor in extractors.values():
        ids = {id(layer) for layer in extractor.modules()}
        count = sum(id(layer) in ids for layer in hidden)
        if count:
            name = type(extractor).__name__
            in_extractors[name] = in_extractors.get(name, 0) + count
    if in_extractors:
        # CnnPolicy's NatureCNN, say: net_arch=[] does not remove those layers
        names = ", ".join(f"{name}'s {count}" for name, count in in_extractors.items())
        where = (
            f"{sum(in_extractors.values())} of them are in the features extractor ({names}), which net_arch=[] does "
            "not remove: for a linear model pass net_arch=[] and a features extractor without weights "
            "(FlattenExtractor, TileCoding, or fixed features of your own) in policy_kwargs"
        )
    else:
        where = "Pass net_arch=[] for a linear model"
    raise ValueError(
        f"weight_init={weight_init!r} sets every weight to one number, which is for a linear model (net_arch=[] "
        f"over features such as TileCoding's, the book's linear methods): the policy's networks have {len(hidden)} "
        "hidden layer(s) with weights in all (an actor-critic policy's counts the actor's and the critic's), whose units "
        "would all start and stay identical, so they "
        f"could not learn. {where}, "
        "or pass weight_init='kaiming', 'orthogonal' or 'default' for this network"
    )


def constant_init(modules: Iterable[nn.Module], value: float) -> None:
    """
    Every weight of the linear and convolutional layers in ``modules`` set to ``value``, biases to 0: the book's
    linear methods start from w = 0 (S&B §9.4, §10.1), or from an optimistic constant (§2.6).

    :param modules: the layers to initialise
    :param value: the constant
    """
    for module in modules:
        for layer in module.modules():
            if isinstance(layer, (nn.Linear, nn.Conv2d)):
                nn.init.constant_(layer.weight, value)
                if layer.bias is not None:
                    nn.init.zeros_(layer.bias)


def is_library_extractor(extractor: nn.Module) -> bool:
    """
    :param extractor: a policy's features extractor
    :return: whether its class is SB3's or this package's (``FlattenExtractor``, ``NatureCNN``, ``CombinedExtractor``,
        ``TileCoding``): the initialisation schemes and ``with_bias=False`` apply to those, not to a class of the
        user's, which keeps the weights and biases it was built with (pretrained ones, say), as SB3's DQN keeps them
    """
    return type(extractor).__module__.startswith(("stable_baselines3.", "sb3_classic."))


def remove_biases(module: nn.Module, keep: Iterable[nn.Module] = ()) -> None:
    """
    Replace every ``nn.Linear`` inside ``module`` by one without bias, in place (same weights). A linear q̂(s, a, w) =
    wᵀx(s, a) of the book has no bias term (S&B eq. 9.8): with one-hot or tile features a bias would be one more
    feature active in every state, coupling all states' values.

    :param module: the network (SB3's ``QNetwork.q_net``, ``MlpExtractor``, a policy holding ``action_net``, ...)
    :param keep: submodules to leave as they are (a features extractor of the user's)
    """
    keep = list(keep)
    for name, child in module.named_children():
        if any(child is kept for kept in keep):
            continue
        if isinstance(child, nn.Linear) and child.bias is not None:
            linear = nn.Linear(child.in_features, child.out_features, bias=False, device=child.weight.device)
            with th.no_grad():
                linear.weight.copy_(child.weight)
            setattr(module, name, linear)
        else:
            remove_biases(child, keep)


def optimizer_kwargs_with_defaults(
    optimizer_class: type[th.optim.Optimizer], optimizer_kwargs: dict[str, Any] | None
) -> dict[str, Any]:
    """
    The arguments to build ``optimizer_class`` with: ``optimizer_kwargs``, and for Adam and AdamW PyTorch's fused
    implementation (``fused=True``) unless they choose one (``fused`` or ``foreach``). Fused Adam is the same update
    in one kernel per step instead of a loop of small ops over the parameter tensors: on CPU it takes a gradient
    step of a 64×64 network a quarter faster, and it runs on every device type SB3 supports.

    :param optimizer_class: the optimizer class
    :param optimizer_kwargs: the policy's ``optimizer_kwargs``
    :return: a new dict (the policy's ``optimizer_kwargs`` are saved with the model as given)
    :raises ValueError: if they set ``lr`` (or ``learning_rate``), which the algorithm's learning rate sets
    :raises TypeError: if ``optimizer_class`` is not an optimizer class (a string, say)
    """
    kwargs = dict(optimizer_kwargs or {})
    for key in {"lr", "learning_rate"} & kwargs.keys():
        # (torch's own error would be "got multiple values for keyword argument 'lr'", or an unexpected keyword
        # argument 'learning_rate', from deep in the policy)
        raise ValueError(
            f"policy_kwargs=dict(optimizer_kwargs=dict({key}={kwargs[key]!r})): the step size is the algorithm's "
            "learning_rate (and REINFORCE's value_learning_rate for v̂), which sets the optimizer's lr before every "
            f"update (a float or an SB3 schedule). Pass learning_rate=... to the algorithm instead, and drop {key} from "
            "optimizer_kwargs"
        )
    if not (isinstance(optimizer_class, type) and issubclass(optimizer_class, th.optim.Optimizer)):
        raise TypeError(
            f"policy_kwargs=dict(optimizer_class={optimizer_class!r}): give the optimizer class itself, e.g. "
            "optimizer_class=th.optim.Adam or ObGD (from sb3_classic import ObGD); in a zoo YAML, inside the "
            "policy_kwargs string, where ObGD is in scope"
        )
    if issubclass(optimizer_class, (th.optim.Adam, th.optim.AdamW)) and not {"fused", "foreach"} & kwargs.keys():
        kwargs["fused"] = True
    return kwargs
