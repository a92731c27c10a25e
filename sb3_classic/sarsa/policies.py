"""Q-network policies of n-step SARSA: q̂(s, ·, w), one output per action."""

import copy
from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.torch_layers import (
    BaseFeaturesExtractor,
    CombinedExtractor,
    FlattenExtractor,
    NatureCNN,
    create_mlp,
)
from stable_baselines3.common.type_aliases import PyTorchObs, Schedule
from stable_baselines3.dqn.policies import QNetwork
from torch import nn

from sb3_classic.common.policies import EnvActionsMixin, mode_dependent
from sb3_classic.common.returns import greedy_random_ties
from sb3_classic.common.torch_layers import (
    check_constant_init_is_linear,
    check_net_arch,
    check_weight_init,
    constant_init,
    is_library_extractor,
    kaiming_init,
    make_activation,
    optimizer_kwargs_with_defaults,
)
from sb3_classic.common.utils import check_bool


class SARSAPolicy(EnvActionsMixin, BasePolicy):
    """
    The action-value network q̂(s, a, w) of semi-gradient SARSA (Sutton & Barto §10.1–10.2), with its optimizer.
    It is SB3's DQN ``QNetwork`` without a target network: SARSA bootstraps from the online network.
    ``predict`` is greedy, in the env's action values (``start`` of the ``Discrete`` space added; q̂'s outputs are
    indexed from 0), with ties broken at random unless ``deterministic=True``; the ε-greedy behaviour policy lives in
    ``NStepSARSA``, as ε is training state.

    :param observation_space: observation space
    :param action_space: action space (Discrete)
    :param lr_schedule: learning-rate schedule (could be constant)
    :param net_arch: hidden layer sizes, e.g. ``[128, 128]``
    :param activation_fn: activation class of the hidden layers
    :param activation_kwargs: arguments of ``activation_fn``, e.g. ``dict(negative_slope=0.1)`` for ``nn.LeakyReLU``
    :param weight_init: ``"kaiming"`` (He initialisation of the hidden layers, the seed report's choice; the output
        layer keeps PyTorch's default), ``"orthogonal"`` (SB3's A2C/PPO scheme: gain √2 hidden, 1 output),
        ``"default"`` (PyTorch's default everywhere, as SB3's DQN), or a number: every weight starts at that constant
        and every bias at 0 (the book's linear methods start at 0)
    :param with_bias: whether the linear layers have a bias (SB3's ``create_mlp`` name). The book's linear q̂(s, a, w)
        = wᵀx(s, a) is ``net_arch=[], with_bias=False, weight_init=0.0`` over features x such as ``TileCoding``'s
    :param layer_norm: LayerNorm after every hidden linear layer, before its activation (as CleanRL's PQN, which
        learns with on-policy Q-targets from the online network: it keeps the features' scale, and so the targets',
        from drifting)
    :param target_network: also build ``q_net_target``, a copy of q̂ that NStepSARSA bootstraps from and moves towards
        q̂ every ``target_update_interval`` steps (SB3's DQN); the book bootstraps from q̂ itself
    :param averaged_network: also build ``q_net_average``, a Polyak average of q̂'s weights that ``NStepSARSA`` updates
        after every update (``averaging_tau``) and that the greedy policy of ``predict`` uses (weight averaging for a
        stable greedy policy, Nikishin et al. 2018); the book's greedy policy is q̂'s own
    :param features_extractor_class: features extractor to use
    :param features_extractor_kwargs: keyword arguments to pass to the features extractor
    :param normalize_images: whether to divide images by 255
    :param optimizer_class: the optimizer to use, ``th.optim.Adam`` by default
    :param optimizer_kwargs: additional keyword arguments, excluding the learning rate, to pass to the optimizer
        (Adam and AdamW get ``fused=True``, PyTorch's one-kernel implementation of the same update, unless these
        choose ``fused`` or ``foreach``)
    """

    action_space: spaces.Discrete

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Discrete,
        lr_schedule: Schedule,
        net_arch: list[int] | None = None,
        activation_fn: type[nn.Module] = nn.ReLU,
        activation_kwargs: dict[str, Any] | None = None,
        weight_init: str | float = "kaiming",
        with_bias: bool = True,
        layer_norm: bool = False,
        target_network: bool = False,
        averaged_network: bool = False,
        features_extractor_class: type[BaseFeaturesExtractor] = FlattenExtractor,
        features_extractor_kwargs: dict[str, Any] | None = None,
        normalize_images: bool = True,
        optimizer_class: type[th.optim.Optimizer] = th.optim.Adam,
        optimizer_kwargs: dict[str, Any] | None = None,
    ) -> None:
        check_weight_init(weight_init)
        super().__init__(
            observation_space,
            action_space,
            features_extractor_class,
            features_extractor_kwargs,
            optimizer_class=optimizer_class,
            optimizer_kwargs=optimizer_kwargs,
            normalize_images=normalize_images,
        )
        check_net_arch(net_arch)
        check_bool("with_bias", with_bias)
        check_bool("layer_norm", layer_norm)
        check_bool("normalize_images", normalize_images)
        if net_arch is None:
            net_arch = [] if features_extractor_class == NatureCNN else [64, 64]
        if layer_norm and not net_arch:
            raise ValueError(
                f"layer_norm=True normalises q̂'s hidden layers, and net_arch={list(net_arch)} has none (q̂ is linear in "
                "the features): give hidden layers (e.g. net_arch=[64, 64]) or drop layer_norm"
            )
        self.net_arch = net_arch
        self.activation_fn = activation_fn
        self.activation_kwargs = activation_kwargs
        self.weight_init = weight_init
        self.with_bias = with_bias
        self.layer_norm = layer_norm
        self.target_network = target_network
        self.averaged_network = averaged_network

        self.q_net = self.make_q_net()
        if not isinstance(self.q_net, QNetwork):
            # (AttributeError: '...' object has no attribute 'features_extractor' below)
            raise TypeError(
                f"make_q_net returned a {type(self.q_net).__name__}: {type(self).__name__} needs an SB3 QNetwork (its "
                "features_extractor and q_net Sequential are initialised, copied and read here). Return "
                "QNetwork(...) or a subclass of it with its own forward (or its own layers in q_net)"
            )
        features_extractor = self.q_net.features_extractor
        layers = list(self.q_net.q_net)
        # (a features extractor of the user's keeps the initialisation it was built with)
        own = [features_extractor] if is_library_extractor(features_extractor) else []
        hidden, output = [*own, *layers[:-1]], layers[-1]
        check_constant_init_is_linear(weight_init, [*own, self.q_net.q_net], [output])
        if not isinstance(weight_init, str):
            constant_init([*own, self.q_net.q_net], weight_init)
        elif weight_init == "kaiming":
            kaiming_init(hidden, activation_fn, activation_kwargs)
        elif weight_init == "orthogonal":
            for module in hidden:
                module.apply(lambda layer: self.init_weights(layer, gain=np.sqrt(2)))
            output.apply(lambda layer: self.init_weights(layer, gain=1.0))
        #: Whether q̂'s forward may depend on train/eval mode (``common.policies.mode_dependent``; see
        #: set_training_mode): BatchNorm's running statistics among them
        self.mode_dependent = mode_dependent(self.q_net)
        #: Whether a subclass overrides ``_predict`` (its greedy policy, e.g. action masking): the ε-greedy behaviour
        #: policy is then ε-greedy in it, as SB3's DQN's is
        self.own_predict = type(self)._predict is not SARSAPolicy._predict
        # q̂'s one layer if q̂ is linear in features without parameters (see linear_layer); in __dict__, not registered
        # as a submodule again (the state dict keeps its keys)
        linear = len(layers) == 1 and isinstance(output, nn.Linear) and next(features_extractor.parameters(), None) is None
        self.__dict__["_linear_layer"] = output if linear else None
        self.q_net_target = self._frozen_copy() if target_network else None
        self.q_net_average = self._frozen_copy() if averaged_network else None
        optimizer_kwargs = optimizer_kwargs_with_defaults(self.optimizer_class, self.optimizer_kwargs)
        self.optimizer = self.optimizer_class(self.q_net.parameters(), lr=lr_schedule(1), **optimizer_kwargs)  # type: ignore[call-arg]

    @property
    def linear_layer(self) -> nn.Linear | None:
        """
        q̂'s only layer when q̂ is linear in its features, q̂(s, ·, w) = W x(s) (+ b): ``net_arch=[]`` over a features
        extractor without parameters (``TileCoding``, ``FlattenExtractor``), the book's linear methods (§9.4, §10.1),
        computed by SB3's ``QNetwork`` (a subclass's own ``forward`` or ``extract_features``, from ``make_q_net``,
        could compute anything); None otherwise. Its gradient is then ∇_{W_a} q̂(s, a, w) = x(s) (S&B §9.4, after
        eq. 9.8), so that the SGD update is w ← w + α[U − q̂]x(s) (eq. 9.9), which ``NStepSARSA`` applies without
        autograd.
        """
        layer: nn.Linear | None = self.__dict__["_linear_layer"]
        if layer is None:
            return None
        q_net = type(self.q_net)
        if q_net.forward is not QNetwork.forward or q_net.extract_features is not QNetwork.extract_features:
            return None
        # (None if q̂'s layers were replaced since construction)
        modules = self.q_net.q_net._modules
        return layer if len(modules) == 1 and modules.get("0") is layer else None

    def _frozen_copy(self) -> QNetwork:
        """:return: a copy of q̂ as it is now, without gradients, in evaluation mode, outside the optimizer"""
        frozen = copy.deepcopy(self.q_net)
        frozen.requires_grad_(False)
        frozen.set_training_mode(False)
        return frozen

    @property
    def bootstrap_net(self) -> QNetwork:
        """The network the n-step targets bootstrap from: ``q_net_target`` if there is one, else q̂ itself."""
        return self.q_net if self.q_net_target is None else self.q_net_target

    def forward(self, obs: PyTorchObs, deterministic: bool = True) -> th.Tensor:
        """:return: the greedy actions argmax_a q̂(obs, a)"""
        return self._predict(obs, deterministic=deterministic)

    def make_q_net(self) -> QNetwork:
        """
        Build q̂ (SB3 DQN's hook of the same name: a subclass may override it to build another network, an SB3
        ``QNetwork`` or a subclass of it, with its own ``forward`` or layers; the initialisation, the optimizer and the
        bootstrap copy and the average are made from what it returns).

        :return: the Q-network: a features extractor, then ``net_arch`` hidden layers and one output per action
        """
        features_extractor = self.make_features_extractor()
        activation = make_activation(self.activation_fn, self.activation_kwargs)
        q_net = QNetwork(
            self.observation_space,
            self.action_space,
            features_extractor=features_extractor,
            features_dim=features_extractor.features_dim,
            net_arch=self.net_arch,
            activation_fn=activation,
            normalize_images=self.normalize_images,
        )
        if self.layer_norm or not self.with_bias:
            # SB3's QNetwork has neither option: the same MLP from SB3's create_mlp, with them
            mlp = create_mlp(
                features_extractor.features_dim,
                int(self.action_space.n),
                self.net_arch,
                activation,
                with_bias=self.with_bias,
                post_linear_modules=[nn.LayerNorm] if self.layer_norm else None,
            )
            q_net.q_net = nn.Sequential(*mlp)
        return q_net

    @property
    def greedy_net(self) -> QNetwork:
        """The network of the greedy policy (``predict``): ``q_net_average`` if there is one, else q̂ itself."""
        return self.q_net if self.q_net_average is None else self.q_net_average

    def _predict(self, observation: PyTorchObs, deterministic: bool = True) -> th.Tensor:
        """
        :param observation: the observations
        :param deterministic: the first of tied greedy actions (reproducible); False: one of them at random, as the
            behaviour policy breaks ties (``greedy_random_ties``, NumPy's global RNG): a q̂ of zeros (the book's
            Mountain Car) would otherwise always pick action 0
        :return: the greedy actions argmax_a q̂(obs, a) of ``greedy_net``
        """
        if deterministic:
            return self.greedy_net._predict(observation, deterministic=True)
        q_values = self.greedy_net(observation)
        return th.as_tensor(greedy_random_ties(q_values.cpu().numpy()), device=q_values.device)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(
            net_arch=self.net_arch,
            activation_fn=self.activation_fn,
            activation_kwargs=self.activation_kwargs,
            weight_init=self.weight_init,
            with_bias=self.with_bias,
            layer_norm=self.layer_norm,
            target_network=self.target_network,
            averaged_network=self.averaged_network,
            lr_schedule=self._dummy_schedule,  # not needed to load the policy alone
            optimizer_class=self.optimizer_class,
            optimizer_kwargs=self.optimizer_kwargs,
            features_extractor_class=self.features_extractor_class,
            features_extractor_kwargs=self.features_extractor_kwargs,
        )
        return data

    def set_training_mode(self, mode: bool) -> None:
        """
        :param mode: train (True) or evaluation (False) mode of every module; nothing to do if already there (the
            per-step loop switches at every env step, and ``nn.Module.train`` visits every submodule)
        """
        if self.training == mode and self.q_net.training == mode:
            return
        if not self.mode_dependent:
            # No module behaves differently in the two modes (every one is of SB3's or torch's plain layers, none a
            # subclass that could read self.training): only the flags change, which saves the per-step loop a walk
            # over every submodule twice per env step. They are plain attributes, set past nn.Module.__setattr__
            # (its checks for parameters and submodules cost more than the assignment)
            self.__dict__["training"] = self.q_net.__dict__["training"] = mode
            return
        self.q_net.set_training_mode(mode)
        self.training = mode


class SARSACnnPolicy(SARSAPolicy):
    """
    ``SARSAPolicy`` with SB3's NatureCNN features extractor, for image observations.

    :param observation_space: observation space
    :param action_space: action space (Discrete)
    :param lr_schedule: learning-rate schedule (could be constant)
    :param kwargs: the other arguments of ``SARSAPolicy``
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Discrete,
        lr_schedule: Schedule,
        features_extractor_class: type[BaseFeaturesExtractor] = NatureCNN,
        **kwargs: Any,
    ) -> None:
        super().__init__(
            observation_space, action_space, lr_schedule, features_extractor_class=features_extractor_class, **kwargs
        )


class SARSAMultiInputPolicy(SARSAPolicy):
    """
    ``SARSAPolicy`` with SB3's CombinedExtractor, for ``Dict`` observations.

    :param observation_space: observation space
    :param action_space: action space (Discrete)
    :param lr_schedule: learning-rate schedule (could be constant)
    :param kwargs: the other arguments of ``SARSAPolicy``
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Discrete,
        lr_schedule: Schedule,
        features_extractor_class: type[BaseFeaturesExtractor] = CombinedExtractor,
        **kwargs: Any,
    ) -> None:
        super().__init__(
            observation_space, action_space, lr_schedule, features_extractor_class=features_extractor_class, **kwargs
        )


MlpPolicy = SARSAPolicy
CnnPolicy = SARSACnnPolicy
MultiInputPolicy = SARSAMultiInputPolicy
