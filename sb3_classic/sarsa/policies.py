"""Q-network policies of n-step SARSA: q̂(s, ·, w), one output per action."""

import copy
from functools import partial
from typing import Any, NamedTuple

import numpy as np
import torch as th
import torch.nn.functional as F
from gymnasium import spaces
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.preprocessing import is_image_space
from stable_baselines3.common.torch_layers import (
    BaseFeaturesExtractor,
    CombinedExtractor,
    FlattenExtractor,
    NatureCNN,
    create_mlp,
)
from stable_baselines3.common.type_aliases import PyTorchObs, Schedule
from stable_baselines3.common.utils import get_parameters_by_name, obs_as_tensor, polyak_update
from stable_baselines3.dqn.policies import QNetwork
from torch import nn

from sb3_classic.common.policies import EnvActionsMixin, mode_dependent
from sb3_classic.common.returns import greedy_random_ties
from sb3_classic.common.tile_coding import TileCoding
from sb3_classic.common.torch_layers import (
    WEIGHT_INITS_WITH_SPARSE,
    check_constant_init_is_linear,
    check_net_arch,
    check_weight_init,
    constant_init,
    is_library_extractor,
    kaiming_init,
    make_activation,
    optimizer_kwargs_with_defaults,
    sparse_init,
)
from sb3_classic.common.utils import check_bool


class TileWeights(NamedTuple):
    """A linear q̂ over tiles: its tile coder, and its weights W and bias b as NumPy views of the parameters."""

    tile_coding: TileCoding
    weight: np.ndarray  #: W, shape (n_actions, features_dim)
    bias: np.ndarray | None  #: b, shape (n_actions,)


class SARSAPolicy(EnvActionsMixin, BasePolicy):
    r"""
    The action-value network :math:`\hat q(s, a, \mathbf w)` of semi-gradient SARSA (Sutton & Barto §10.1–10.2), with
    its optimizer. It is SB3's DQN ``QNetwork`` without a target network: SARSA bootstraps from the online network.
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
        ``"default"`` (PyTorch's default everywhere, as SB3's DQN), ``"sparse"`` (every layer's, the output's too: 90% of
        each unit's incoming weights 0, the rest LeCun-uniform, biases 0; ``sparse_init``, the streaming recipe of
        Elsayed, Vasan & Mahmood 2024), or a number: every weight starts at that constant and every bias at 0 (the
        book's linear methods start at 0)
    :param with_bias: whether the linear layers have a bias (SB3's ``create_mlp`` name). The book's linear
        :math:`\hat q(s, a, \mathbf w) = \mathbf w^\top \mathbf x(s, a)` with its own SGD update is ``LinearQPolicy``
        (``"LinearPolicy"``)
    :param layer_norm: LayerNorm after every hidden linear layer, before its activation (as CleanRL's PQN, which
        learns with on-policy Q-targets from the online network: it keeps the features' scale, and so the targets',
        from drifting)
    :param layer_norm_kwargs: arguments of ``nn.LayerNorm`` (``layer_norm=True`` only), e.g.
        ``dict(elementwise_affine=False)``: LayerNorm without learnable gain and bias, the streaming recipe's
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
        layer_norm_kwargs: dict[str, Any] | None = None,
        target_network: bool = False,
        averaged_network: bool = False,
        features_extractor_class: type[BaseFeaturesExtractor] = FlattenExtractor,
        features_extractor_kwargs: dict[str, Any] | None = None,
        normalize_images: bool = True,
        optimizer_class: type[th.optim.Optimizer] = th.optim.Adam,
        optimizer_kwargs: dict[str, Any] | None = None,
    ) -> None:
        check_weight_init(weight_init, WEIGHT_INITS_WITH_SPARSE)
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
        if layer_norm_kwargs is not None and not layer_norm:
            raise ValueError(
                f"layer_norm_kwargs={layer_norm_kwargs!r} are the arguments of q̂'s LayerNorm, and layer_norm is False (no "
                "LayerNorm): pass layer_norm=True as well, or drop layer_norm_kwargs"
            )
        self.net_arch = net_arch
        self.activation_fn = activation_fn
        self.activation_kwargs = activation_kwargs
        self.weight_init = weight_init
        self.with_bias = with_bias
        self.layer_norm = layer_norm
        self.layer_norm_kwargs = layer_norm_kwargs
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
        elif weight_init == "sparse":
            sparse_init([*own, self.q_net.q_net])
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
        self.q_net_target = self._frozen_copy() if target_network else None
        self.q_net_average = self._frozen_copy() if averaged_network else None
        optimizer_kwargs = optimizer_kwargs_with_defaults(self.optimizer_class, self.optimizer_kwargs)
        self.optimizer = self.optimizer_class(self.q_net.parameters(), lr=lr_schedule(1), **optimizer_kwargs)  # type: ignore[call-arg]

    def _frozen_copy(self) -> QNetwork:
        """:return: a copy of q̂ as it is now, without gradients, in evaluation mode, outside the optimizer"""
        frozen = copy.deepcopy(self.q_net)
        frozen.requires_grad_(False)
        frozen.set_training_mode(False)
        return frozen

    def polyak_update(self, copy: QNetwork, tau: float) -> None:
        """
        Move a copy of q̂ towards it: w' ← τw + (1 − τ)w' of the parameters (SB3's ``polyak_update``), and the running
        statistics of normalisation layers (BatchNorm's ``running_mean``, ``running_var``) copied, as SB3's DQN copies
        them to its target network: they are not parameters, and a copy whose statistics never moved normalises
        otherwise (looked for only where ``mode_dependent``: the walk over the state dict costs more than the update of
        a small q̂).

        :param copy: ``q_net_target`` or ``q_net_average``
        :param tau: the coefficient τ, in (0, 1]
        """
        polyak_update(self.q_net.parameters(), copy.parameters(), tau)
        if self.mode_dependent:
            statistics = get_parameters_by_name(self.q_net, ["running_"])
            polyak_update(statistics, get_parameters_by_name(copy, ["running_"]), 1.0)

    @property
    def device(self) -> th.device:
        """
        The device of q̂'s parameters, read from its optimizer's first one: SB3's ``BaseModel.device`` walks every
        module for it, which costs more than the per-step loop's forward pass of a small q̂.
        """
        optimizer = self.__dict__.get("optimizer")
        if optimizer is None:  # (while the policy is being built)
            return super().device
        return optimizer.param_groups[0]["params"][0].device

    @property
    def bootstrap_net(self) -> QNetwork:
        """The network the n-step targets bootstrap from: ``q_net_target`` if there is one, else q̂ itself."""
        return self.q_net if self.q_net_target is None else self.q_net_target

    def q_values(self, observations: np.ndarray | dict[str, np.ndarray]) -> np.ndarray:
        """
        :param observations: a batch of observations, as a VecEnv returns them
        :return: q̂(s, ·, w) of each, shape (batch, n_actions), float32, detached: what the ε-greedy behaviour policy of
            ``NStepSARSA`` chooses from (call it under ``th.no_grad()``, as the rollout loop does, to build no graph)
        """
        return self.q_net(obs_as_tensor(observations, self.device)).detach().cpu().numpy()

    def forward(self, obs: PyTorchObs, deterministic: bool = True) -> th.Tensor:
        r""":return: the greedy actions :math:`\operatorname{argmax}_a \hat q(\text{obs}, a)`"""
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
            norm = partial(nn.LayerNorm, **(self.layer_norm_kwargs or {}))
            mlp = create_mlp(
                features_extractor.features_dim,
                int(self.action_space.n),
                self.net_arch,
                activation,
                with_bias=self.with_bias,
                post_linear_modules=[norm] if self.layer_norm else None,  # type: ignore[list-item]
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

    def _predict_masked(self, observation: PyTorchObs, deterministic: bool, action_masks: np.ndarray) -> th.Tensor:
        """
        :param observation: the observations
        :param deterministic: the first of tied greedy actions; False: one of them at random (as ``_predict``)
        :param action_masks: the legal actions of each observation, shape (batch, n_actions), boolean (sb3-contrib's
            masks)
        :return: the greedy actions argmax_{a legal} q̂(obs, a) of ``greedy_net``
        """
        # Illegal actions at −∞: never the argmax while some action is legal
        q_masked = np.where(action_masks, self.greedy_net(observation).cpu().numpy(), -np.inf)
        greedy = q_masked.argmax(axis=1) if deterministic else greedy_random_ties(q_masked)
        return th.as_tensor(greedy, device=self.device)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(
            net_arch=self.net_arch,
            activation_fn=self.activation_fn,
            activation_kwargs=self.activation_kwargs,
            weight_init=self.weight_init,
            with_bias=self.with_bias,
            layer_norm=self.layer_norm,
            layer_norm_kwargs=self.layer_norm_kwargs,
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
        q_net = self._modules["q_net"]  # (nn.Module's attribute lookup costs more than the rest of this)
        assert q_net is not None
        if self.training == mode and q_net.training == mode:
            return
        if not self.mode_dependent:
            # No module behaves differently in the two modes (every one is of SB3's or torch's plain layers, none a
            # subclass that could read self.training): only the flags change, which saves the per-step loop a walk
            # over every submodule twice per env step. They are plain attributes, set past nn.Module.__setattr__
            # (its checks for parameters and submodules cost more than the assignment)
            self.__dict__["training"] = q_net.__dict__["training"] = mode
            return
        self.q_net.set_training_mode(mode)
        self.training = mode


class LinearQPolicy(SARSAPolicy):
    r"""
    The book's linear action-value function :math:`\hat q(s, a, \mathbf w) = W_a \mathbf x(s)\ (+\, b_a)` over features
    :math:`\mathbf x(s)` without parameters (Sutton & Barto §9.4, §10.1: ``TileCoding``'s, or the observation itself),
    with its own SGD update (``sgd_step``) in place of autograd and the optimizer's step. ``NStepSARSA`` trains it with
    that update (``policy="LinearPolicy"``).

    The gradient of a linear q̂ is :math:`\nabla_{W_a} \hat q(s, a, \mathbf w) = \mathbf x(s)` (§9.4, after eq. 9.8),
    so the update of eq. 10.5 is (eq. 9.9)

    .. math::

        W_a \leftarrow W_a + \alpha [G - \hat q(S_t, A_t, \mathbf w)]\, \mathbf x(S_t):

    ``sgd_step`` applies it to the weights without autograd, the same arithmetic as autograd's gradient of
    :math:`\tfrac12 (G - \hat q)^2` and ``torch.optim.SGD``'s step (the same weights to float32 rounding: the two
    may order their products differently), at a fraction of the cost: the book's per-step loop makes this update at
    every env step.
    Over ``TileCoding`` on the CPU, q̂ and the update go over the active tiles as the book's ``tiles3`` code does (S&B
    §9.5.4): :math:`\hat q(s, a) = \sum_i W[a, i(s)]` over the active tiles :math:`i(s)`, and
    :math:`\alpha [G - \hat q]` added to each active tile's weight, without the dense :math:`\mathbf x(s)`: the same
    values to float32 rounding (the sum's order differs), several times faster (``benchmarks/results/hot_paths.md``).
    A ``torch.nn.EmbeddingBag(mode="sum")`` over the tiles with ``torch.optim.SGD`` makes the same update, at many
    times the cost per update.

    ``optimizer`` is a plain ``torch.optim.SGD``: it holds the learning rate α that the schedules set, and its state
    is saved as for every policy, but its ``step`` is not called.

    :param observation_space: observation space
    :param action_space: action space (Discrete)
    :param lr_schedule: learning-rate schedule (could be constant)
    :param weight_init: the initial weights: a number (every weight that constant, every bias 0; the book's linear
        methods start at 0, the default) or ``SARSAPolicy``'s schemes
    :param with_bias: whether q̂ has a bias :math:`b_a` (the book's :math:`\hat q = \mathbf w^\top \mathbf x` has none,
        the default)
    :param features_extractor_class: the features :math:`\mathbf x(s)`: an extractor without parameters (``TileCoding``,
        ``FlattenExtractor``)
    :param optimizer_class: ``torch.optim.SGD`` (the update is plain SGD)
    :param optimizer_kwargs: SGD's arguments other than the learning rate, at their defaults (no momentum, dampening,
        weight decay, Nesterov or ``maximize``, which the update does not have)
    :param kwargs: the other arguments of ``SARSAPolicy`` (``net_arch`` must be empty: q̂ is linear in x)
    :raises ValueError: for hidden layers, an optimizer other than plain SGD, or features with parameters
    """

    #: The tiles of this many single observations are kept (``_active_tiles``): the per-step update codes S_t again
    #: n steps after the rollout coded it to choose A_t, so n-step returns up to n = 62 find them there
    TILES_KEPT = 64

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Discrete,
        lr_schedule: Schedule,
        weight_init: str | float = 0.0,
        with_bias: bool = False,
        features_extractor_class: type[BaseFeaturesExtractor] = FlattenExtractor,
        optimizer_class: type[th.optim.Optimizer] = th.optim.SGD,
        optimizer_kwargs: dict[str, Any] | None = None,
        **kwargs: Any,
    ) -> None:
        net_arch = kwargs.setdefault("net_arch", [])
        if net_arch:
            raise ValueError(
                f"net_arch={net_arch!r}: LinearPolicy's q̂ is linear in its features (q̂(s, a, w) = W_a x(s)), without "
                "hidden layers. Pass net_arch=[] (or leave it out), or use 'MlpPolicy' for a network with hidden layers"
            )
        if optimizer_class is not th.optim.SGD:
            raise ValueError(
                f"optimizer_class={optimizer_class.__name__}: LinearPolicy's update is plain SGD, W_a ← W_a + α[G − q̂]x "
                "(S&B eq. 9.9), applied without the optimizer. Leave optimizer_class out, or use 'MlpPolicy' with "
                "policy_kwargs=dict(net_arch=[]) for a linear q̂ trained by another optimizer"
            )
        super().__init__(
            observation_space,
            action_space,
            lr_schedule,
            weight_init=weight_init,
            with_bias=with_bias,
            features_extractor_class=features_extractor_class,
            optimizer_class=optimizer_class,
            optimizer_kwargs=optimizer_kwargs,
            **kwargs,
        )
        group = self.optimizer.param_groups[0]
        extras = {key: group[key] for key in ("momentum", "dampening", "weight_decay", "nesterov", "maximize") if group[key]}
        if extras:
            raise ValueError(
                f"optimizer_kwargs={self.optimizer_kwargs!r}: LinearPolicy's update is plain SGD (S&B eq. 9.9), without "
                f"{', '.join(extras)}. Drop them, or use 'MlpPolicy' with policy_kwargs=dict(net_arch=[]) and SGD's options"
            )
        q_net, layers = type(self.q_net), list(self.q_net.q_net)
        own_forward = q_net.forward is not QNetwork.forward or q_net.extract_features is not QNetwork.extract_features
        if own_forward or len(layers) != 1:
            raise TypeError(
                f"make_q_net returned a {q_net.__name__} with its own forward or layers: LinearPolicy's update needs SB3's "
                "QNetwork with one linear layer over the features. Use 'MlpPolicy' for another network"
            )
        extractor = self.q_net.features_extractor
        if next(extractor.parameters(), None) is not None:
            raise ValueError(
                f"features_extractor_class={type(extractor).__name__} has parameters: LinearPolicy's q̂ is linear in "
                "features without parameters (its gradient is x(s)). Use a features extractor without parameters "
                "(TileCoding, FlattenExtractor), or 'MlpPolicy' with policy_kwargs=dict(net_arch=[]) to train them too"
            )
        # q̂'s layer and tile coder are kept in __dict__, not registered as submodules again (the state dict keeps its
        # keys, and a saved LinearPolicy loads as any SARSAPolicy)
        #: q̂'s linear layer: W (n_actions, features_dim) and b
        self.layer: nn.Linear
        self.__dict__["layer"] = layers[0]
        # The tile path: TileCoding's own features (a subclass's forward could compute anything from the tiles), and not
        # scaled images (preprocess_obs would divide them by 255 first)
        tiles = type(extractor).forward is TileCoding.forward and not (
            self.normalize_images and is_image_space(observation_space)
        )
        #: q̂'s tile coder, if q̂ and the update go over its active tiles (on the CPU); else None
        self.tile_coding: TileCoding | None
        self.__dict__["tile_coding"] = extractor if isinstance(extractor, TileCoding) and tiles else None
        # The active tiles of the last single observations, by their float32 bytes
        self._tiles_kept: dict[bytes, np.ndarray] = {}
        # _over_tiles's views, and the memory addresses of the parameters they show
        self._views: TileWeights | None = None
        self._views_of: tuple[int, int | None] | None = None

    def check_layers(self) -> None:
        """
        :raises RuntimeError: if q̂'s layers were replaced since the policy was built (``sgd_step`` would train the old
            layer); ``NStepSARSA`` checks at the start of each ``learn()``
        """
        if self.q_net.q_net._modules.get("0") is not self.layer or len(self.q_net.q_net) != 1:
            raise RuntimeError(
                "q̂'s layers were replaced after the LinearPolicy was built, and its update would train the old layer: "
                "build the model again with the network you want (a LinearPolicy subclass's make_q_net)"
            )

    def _over_tiles(self) -> TileWeights | None:
        """
        :return: q̂'s tile coder and its weights and bias as NumPy views of the parameters' memory, if q̂ goes over the
            active tiles (its weights on the CPU); else None. The views are made again when a parameter's memory
            changes (``to()``, a new ``Parameter``), and otherwise kept: making them costs more than a step of the book's
            Mountain Car
        """
        if self.tile_coding is None:
            return None
        # (the parameters from the layer's dict: nn.Module's attribute lookup costs more than the rest of this)
        weight, bias = self.layer._parameters["weight"], self.layer._parameters["bias"]
        assert weight is not None
        memory = (weight.data_ptr(), None if bias is None else bias.data_ptr())
        if memory != self._views_of:
            cpu = weight.is_cpu and (bias is None or bias.is_cpu)
            self._views = (
                TileWeights(self.tile_coding, weight.detach().numpy(), None if bias is None else bias.detach().numpy())
                if cpu
                else None
            )
            self._views_of = memory
        return self._views

    def _active_tiles(self, tile_coding: TileCoding, observations: np.ndarray) -> np.ndarray:
        """
        :param tile_coding: q̂'s tile coder
        :param observations: a batch of observations, shape (batch, *obs_shape)
        :return: their active tiles, shape (batch, n_tilings) (``TileCoding.active_tiles_numpy`` of the observations cast
            to float32, as ``preprocess_obs`` casts them); those of a single observation are kept for ``TILES_KEPT``
            later observations (the tiles are a function of the observation's values alone)
        """
        observations = observations.astype(np.float32, copy=False)
        if len(observations) != 1:
            return tile_coding.active_tiles_numpy(observations)
        key = observations.tobytes()
        tiles = self._tiles_kept.get(key)
        if tiles is None:
            tiles = self._tiles_kept[key] = tile_coding.active_tiles_numpy(observations)
            if len(self._tiles_kept) > self.TILES_KEPT:
                del self._tiles_kept[next(iter(self._tiles_kept))]  # the oldest
        return tiles

    def q_values(self, observations: np.ndarray | dict[str, np.ndarray]) -> np.ndarray:
        r"""
        ``SARSAPolicy.q_values``; over tiles, :math:`\hat q(s, \cdot) = \sum_i W[\cdot, i(s)]\ (+\, b)` over the active
        tiles :math:`i(s)` (S&B §9.5.4, the ``tiles3`` code's ``sum(w[tiles])``), without the dense :math:`\mathbf x(s)`:
        the same values to float32 rounding.

        :param observations: a batch of observations
        :return: q̂(s, ·, w) of each, shape (batch, n_actions), float32
        """
        over_tiles = self._over_tiles()
        if over_tiles is None:
            return super().q_values(observations)
        tiles = self._active_tiles(over_tiles.tile_coding, observations)  # type: ignore[arg-type]
        q_values: np.ndarray = over_tiles.weight[:, tiles].sum(axis=-1).T
        if over_tiles.bias is not None:
            q_values = q_values + over_tiles.bias
        return q_values

    def sgd_step(
        self, observations: np.ndarray | dict[str, np.ndarray], actions: np.ndarray, targets: np.ndarray
    ) -> tuple[np.ndarray, float]:
        r"""
        One SGD step on the mean of :math:`\tfrac12 (G - \hat q(S_t, A_t, \mathbf w))^2` over the given transitions,
        without autograd (S&B eq. 10.5 with :math:`\nabla \hat q = \mathbf x`, eq. 9.9),

        .. math::

            W_a \leftarrow W_a + \frac{\alpha}{B} \sum_{t:\, A_t = a} [G_t - \hat q(S_t, A_t, \mathbf w)]\, \mathbf x(S_t),

        and the same for :math:`b_a`; one transition (B = 1) is the book's update. The learning rate α is the
        optimizer's. A frozen parameter (``requires_grad=False``) is not changed, as the optimizer would leave it.

        :param observations: :math:`S_t`, a batch of B
        :param actions: :math:`A_t` as indices, shape (B,)
        :param targets: the targets G, shape (B,), float32
        :return: :math:`\hat q(S_t, A_t, \mathbf w)` before the step, shape (B,), float32, and the loss (the mean of
            :math:`\tfrac12 (G - \hat q)^2`)
        """
        over_tiles = self._over_tiles()
        if over_tiles is not None:
            return self._tile_sgd_step(over_tiles, observations, actions, targets)  # type: ignore[arg-type]
        layer, learning_rate = self.layer, float(self.optimizer.param_groups[0]["lr"])
        with th.no_grad():
            features = self.q_net.extract_features(obs_as_tensor(observations, self.device), self.q_net.features_extractor)
            index = th.as_tensor(actions, device=features.device)
            q_predicted = F.linear(features, layer.weight, layer.bias).gather(1, index[:, None]).flatten()
            # ∂½(G − q̂)²/∂q̂ = q̂ − G: the gradient of W_a is (q̂ − G) x(S_t), of b_a (q̂ − G); SGD adds −α × the mean gradient
            error = q_predicted - th.as_tensor(targets, device=features.device)
            if len(error) == 1:
                # One transition: the row A_t alone (the arithmetic of autograd's step)
                action = int(actions[0])
                if layer.weight.requires_grad:
                    layer.weight[action].add_(features[0] * error, alpha=-learning_rate)
                if layer.bias is not None and layer.bias.requires_grad:
                    layer.bias[action : action + 1].add_(error, alpha=-learning_rate)
            else:
                gradient = error / len(error)
                if layer.weight.requires_grad:
                    layer.weight.index_add_(0, index, features * gradient[:, None], alpha=-learning_rate)
                if layer.bias is not None and layer.bias.requires_grad:
                    layer.bias.index_add_(0, index, gradient, alpha=-learning_rate)
            loss = 0.5 * error.square()
        return q_predicted.cpu().numpy(), (loss if len(loss) == 1 else loss.mean()).item()

    def _tile_sgd_step(
        self, over_tiles: TileWeights, observations: np.ndarray, actions: np.ndarray, targets: np.ndarray
    ) -> tuple[np.ndarray, float]:
        """
        ``sgd_step`` over the active tiles, as the book's code for Mountain Car does: α[G − q̂] (over B) added to the
        weight of each active tile i(S_t) in row A_t (and to b_a); a hashed tile met by k tilings gets it k times, as its
        feature is k. The arithmetic of autograd's gradient and ``torch.optim.SGD``'s step in float32, with q̂ summed
        over the active tiles: the weights agree with theirs to float32 rounding.
        """
        learning_rate = np.float32(self.optimizer.param_groups[0]["lr"])
        tiles = self._active_tiles(over_tiles.tile_coding, observations)
        # (views: the update changes the parameters themselves)
        tile_coding, weights, bias = over_tiles
        if len(actions) == 1:
            # The book's update of one transition: its action's row of weights, a view
            action, row_tiles, row = int(actions[0]), tiles[0], weights[int(actions[0])]
            q_predicted = row[row_tiles].sum(keepdims=True) + (bias[action] if bias is not None else np.float32(0.0))
            # ∂½(G − q̂)²/∂W_a = (q̂ − G) x(S_t): SGD adds −α(q̂ − G) to each active tile's weight, once per tiling
            error = q_predicted - targets
            step = -learning_rate * error[0]
            if self.layer.weight.requires_grad:
                if tile_coding.hash_size is None:
                    row[row_tiles] += step  # (one tile per tiling, all distinct)
                else:
                    np.add.at(row, row_tiles, step)
            if bias is not None and self.layer.bias.requires_grad:
                bias[action] += step
            return q_predicted, float(np.float32(0.5) * error[0] * error[0])
        q_predicted = weights[actions[:, None], tiles].sum(axis=1)
        if bias is not None:
            q_predicted = q_predicted + bias[actions]
        # The mean loss's gradient: −α(q̂ − G)/B to each active tile's weight of each transition
        error = q_predicted - targets
        steps = -learning_rate * error / np.float32(len(error))
        if self.layer.weight.requires_grad:
            np.add.at(weights, (actions[:, None], tiles), steps[:, None])
        if bias is not None and self.layer.bias.requires_grad:
            np.add.at(bias, actions, steps)
        return q_predicted, float((np.float32(0.5) * error * error).mean())


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
LinearPolicy = LinearQPolicy
CnnPolicy = SARSACnnPolicy
MultiInputPolicy = SARSAMultiInputPolicy
