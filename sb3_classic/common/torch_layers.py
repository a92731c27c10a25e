"""
Network options shared by the policies: activations with arguments, He (Kaiming) initialisation, and the
optimizer's implementation.
"""

from collections.abc import Iterable
from functools import partial
from typing import Any, Literal

import torch as th
from torch import nn

from sb3_classic.common.utils import check_choice

#: ``weight_init`` choices: SB3's orthogonal scheme (A2C/PPO), He et al. 2015, or PyTorch's own defaults
WEIGHT_INITS = ("orthogonal", "kaiming", "default")

# The nonlinearity argument of nn.init.kaiming_normal_ for the activations it knows
Nonlinearity = Literal["relu", "leaky_relu", "tanh", "sigmoid", "selu"]
_KAIMING_NONLINEARITY: dict[type[nn.Module], Nonlinearity] = {
    nn.ReLU: "relu",
    nn.LeakyReLU: "leaky_relu",
    nn.Tanh: "tanh",
    nn.Sigmoid: "sigmoid",
    nn.SELU: "selu",
}


def make_activation(activation_fn: type[nn.Module], activation_kwargs: dict[str, Any] | None) -> type[nn.Module]:
    """
    SB3 builds activations by calling ``activation_fn()``; bind ``activation_kwargs`` so that e.g.
    ``activation_fn=nn.LeakyReLU, activation_kwargs=dict(negative_slope=0.1)`` (the seed report's Acrobot
    REINFORCE setting) can be written in a zoo YAML.

    :param activation_fn: activation class
    :param activation_kwargs: its constructor arguments
    :return: a callable building the activation
    """
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


def check_weight_init(weight_init: str) -> None:
    """:param weight_init: one of ``WEIGHT_INITS``"""
    check_choice("weight_init", weight_init, WEIGHT_INITS)


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
    """
    kwargs = dict(optimizer_kwargs or {})
    if issubclass(optimizer_class, (th.optim.Adam, th.optim.AdamW)) and not {"fused", "foreach"} & kwargs.keys():
        kwargs["fused"] = True
    return kwargs
