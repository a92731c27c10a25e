"""Policies of REINFORCE with baseline: a policy network π(a|s, θ) and a state-value network v̂(s, w)."""

from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from sb3_contrib.common.maskable.distributions import MaskableDistribution, make_masked_proba_distribution
from stable_baselines3.common.distributions import CategoricalDistribution, Distribution
from stable_baselines3.common.policies import ActorCriticPolicy, BaseModel
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, CombinedExtractor, FlattenExtractor, NatureCNN
from stable_baselines3.common.type_aliases import PyTorchObs, Schedule
from torch import nn

from sb3_classic.common.masking import mask_segments
from sb3_classic.common.obgd import ACTOR_KAPPA, ObGD
from sb3_classic.common.policies import EnvActionsMixin
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
    remove_biases,
    sparse_init,
)
from sb3_classic.common.utils import check_bool


class REINFORCEPolicy(EnvActionsMixin, ActorCriticPolicy):
    r"""
    The two networks of REINFORCE with baseline (Sutton & Barto §13.4): the policy :math:`\pi(a \mid s,
    \boldsymbol\theta)` and the baseline :math:`\hat v(s, \mathbf w)`. They are separate networks by default
    (``net_arch=dict(pi=[64, 64], vf=[64, 64])``, no shared features extractor) with separate optimizers, so each has
    its own learning rate (:math:`\alpha^{\boldsymbol\theta}` and :math:`\alpha^{\mathbf w}`).
    The action distributions are SB3's (Discrete, Box, MultiDiscrete, MultiBinary); the networks work with action
    indices and ``predict`` returns the env's values (``start`` of ``Discrete``/``MultiDiscrete`` added).

    With action masks (``get_distribution``, ``evaluate_actions``, ``sample_actions``, ``predict`` take
    ``action_masks`` as sb3-contrib's ``MaskableActorCriticPolicy`` does), the distribution is sb3-contrib's
    masked one (``MaskableCategoricalDistribution``, ``MaskableMultiCategoricalDistribution``; for MultiBinary,
    ``MaskableBernoulliDistribution`` over the two logits (0, l) of each Bernoulli logit l, the same probabilities):
    an illegal action has probability 0 and gets no gradient, and the entropy is over the legal actions. A batch
    whose masks allow every action gets SB3's distribution itself (the same probabilities; sb3-contrib's would
    normalise the logits a second time, which changes their last bit).

    :param observation_space: observation space
    :param action_space: action space
    :param lr_schedule: learning-rate schedule of the policy network (α^θ)
    :param value_lr_schedule: learning-rate schedule of the value network (α^w); ``lr_schedule`` if None
    :param net_arch: hidden layers, e.g. ``[64, 64]`` for both networks or ``dict(pi=[64, 64], vf=[256])`` (SB3's
        older ``[dict(pi=..., vf=...)]`` is converted with SB3's deprecation warning, as A2C and PPO convert it)
    :param activation_fn: activation class of the hidden layers
    :param activation_kwargs: arguments of ``activation_fn``, e.g. ``dict(negative_slope=0.1)`` for ``nn.LeakyReLU``
    :param weight_init: ``"orthogonal"`` (SB3's A2C/PPO scheme), ``"kaiming"`` (He initialisation of the hidden
        layers; output layers keep PyTorch's default), ``"default"`` (PyTorch's default everywhere), ``"sparse"``
        (every linear layer of both networks, output layers too: 90% of each unit's incoming weights 0, the rest
        LeCun-uniform, biases 0; ``sparse_init``, the streaming recipe of Elsayed, Vasan & Mahmood 2024), or a number:
        every weight starts at that constant and every bias at 0 (the book's linear methods start at 0)
    :param with_bias: whether the linear layers have a bias (SB3's ``create_mlp`` name). The book's linear policy
        :math:`h(s, a, \boldsymbol\theta) = \boldsymbol\theta^\top \mathbf x(s, a)` (S&B eq. 13.3) and baseline
        :math:`\hat v(s, \mathbf w) = \mathbf w^\top \mathbf x(s)` are ``net_arch=[], with_bias=False``
    :param layer_norm: LayerNorm after every hidden linear layer of both networks, before its activation (the
        streaming recipe's, which keeps the features' scale from drifting under per-step updates)
    :param layer_norm_kwargs: arguments of ``nn.LayerNorm`` (``layer_norm=True`` only), e.g.
        ``dict(elementwise_affine=False)``: LayerNorm without learnable gain and bias, the streaming recipe's
    :param use_baseline: build the value network :math:`\hat v(s, \mathbf w)` and its optimizer (REINFORCE with
        baseline, §13.4); False builds none (plain REINFORCE, §13.3)
    :param log_std_init: initial log standard deviation of Gaussian actions (Box action spaces)
    :param features_extractor_class: features extractor to use
    :param features_extractor_kwargs: keyword arguments to pass to the features extractor
    :param share_features_extractor: share one features extractor between the two networks (its parameters are then
        trained by the policy optimizer, on the gradient of both losses)
    :param normalize_images: whether to divide images by 255
    :param optimizer_class: optimizer of both networks, ``th.optim.Adam`` by default; ``ObGD`` with
        ``update_mode="per_step"`` for the streaming recipe's bounded steps (``REINFORCE``'s per-step mode). ObGD's κ is
        then the paper's for each network unless the kwargs give one: 3 for the policy (an actor), 2 for v̂
    :param optimizer_kwargs: additional keyword arguments, excluding the learning rate, to pass to both optimizers
        (Adam and AdamW get ``fused=True``, PyTorch's one-kernel implementation of the same update, unless these
        choose ``fused`` or ``foreach``)
    :param value_optimizer_kwargs: keyword arguments of the value network's optimizer that replace those of
        ``optimizer_kwargs`` for it, e.g. ``dict(kappa=2.0)`` for ObGD's κ of v̂; None: ``optimizer_kwargs`` alone
    :raises ValueError: for ``layer_norm`` without hidden layers, or ``layer_norm_kwargs`` without ``layer_norm``
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Space,
        lr_schedule: Schedule,
        value_lr_schedule: Schedule | None = None,
        net_arch: list[int] | dict[str, list[int]] | None = None,
        activation_fn: type[nn.Module] = nn.Tanh,
        activation_kwargs: dict[str, Any] | None = None,
        weight_init: str | float = "orthogonal",
        with_bias: bool = True,
        layer_norm: bool = False,
        layer_norm_kwargs: dict[str, Any] | None = None,
        use_baseline: bool = True,
        log_std_init: float = 0.0,
        features_extractor_class: type[BaseFeaturesExtractor] = FlattenExtractor,
        features_extractor_kwargs: dict[str, Any] | None = None,
        share_features_extractor: bool = False,
        normalize_images: bool = True,
        optimizer_class: type[th.optim.Optimizer] = th.optim.Adam,
        optimizer_kwargs: dict[str, Any] | None = None,
        value_optimizer_kwargs: dict[str, Any] | None = None,
    ):
        check_weight_init(weight_init, WEIGHT_INITS_WITH_SPARSE)
        # SB3's form before 1.8, [dict(pi=..., vf=...)]: ActorCriticPolicy converts it with its deprecation warning, as
        # for A2C and PPO (a list with shared layers before the dict, which it cannot convert, is refused)
        legacy = isinstance(net_arch, list) and len(net_arch) == 1 and isinstance(net_arch[0], dict)
        check_net_arch(net_arch[0] if legacy else net_arch, keys=("pi", "vf"))  # type: ignore[index]
        check_bool("with_bias", with_bias)
        check_bool("layer_norm", layer_norm)
        if layer_norm_kwargs is not None and not layer_norm:
            raise ValueError(
                f"layer_norm_kwargs={layer_norm_kwargs!r} are the arguments of the networks' LayerNorm, and layer_norm is "
                "False (no LayerNorm): pass layer_norm=True as well, or drop layer_norm_kwargs"
            )
        check_bool("use_baseline", use_baseline)
        # SB3's ActorCriticPolicy takes their truth: share_features_extractor="False" would share it
        check_bool("share_features_extractor", share_features_extractor)
        check_bool("normalize_images", normalize_images)
        # (checked before ActorCriticPolicy builds an optimizer of its own with them)
        optimizer_kwargs_with_defaults(optimizer_class, optimizer_kwargs)
        optimizer_kwargs_with_defaults(optimizer_class, value_optimizer_kwargs)
        # (read by _build_mlp_extractor, which ActorCriticPolicy's constructor calls)
        self.layer_norm = layer_norm
        self.layer_norm_kwargs = layer_norm_kwargs
        super().__init__(
            observation_space,
            action_space,
            lr_schedule,
            net_arch=net_arch,
            activation_fn=make_activation(activation_fn, activation_kwargs),
            ortho_init=weight_init == "orthogonal",
            log_std_init=log_std_init,
            features_extractor_class=features_extractor_class,
            features_extractor_kwargs=features_extractor_kwargs,
            share_features_extractor=share_features_extractor,
            normalize_images=normalize_images,
            optimizer_class=optimizer_class,
            optimizer_kwargs=optimizer_kwargs,
        )
        for part in ("policy_net", "value_net"):
            if not isinstance(getattr(self.mlp_extractor, part, None), nn.Module):
                raise TypeError(
                    f"mlp_extractor={type(self.mlp_extractor).__name__} (from _build_mlp_extractor) has no {part}: "
                    "REINFORCE gives the policy and the value network their own optimizers by mlp_extractor.policy_net "
                    "and mlp_extractor.value_net, SB3's MlpExtractor's names (those of SB3's custom-policy example); "
                    "name its two parts so"
                )
        #: Whether the action distribution is SB3's own (no subclass overrides a hook ``get_distribution`` calls), which
        #: ``sample_actions`` may then draw from without building it
        hooks = ("get_distribution", "_get_action_dist_from_latent", "extract_features")
        self._sb3_distribution = all(getattr(type(self), hook) is getattr(REINFORCEPolicy, hook) for hook in hooks)
        #: Whether a subclass overrides ``forward``, whose actions SB3's A2C and PPO act with in their rollouts
        self._own_forward = type(self).forward is not REINFORCEPolicy.forward
        #: sb3-contrib's masked distribution for masked actions (None for a space that cannot be masked: Box)
        self.masked_action_dist: MaskableDistribution | None = None
        if mask_segments(action_space) is not None:
            self.masked_action_dist = make_masked_proba_distribution(action_space)
        self.activation_fn = activation_fn
        self.activation_kwargs = activation_kwargs
        self.weight_init = weight_init
        self.with_bias = with_bias
        self.use_baseline = use_baseline
        if not use_baseline:
            # Plain REINFORCE: no v̂ (ActorCriticPolicy always builds one; nothing of it is kept)
            self.mlp_extractor.value_net = nn.Sequential()
            self.value_net = nn.Sequential()  # type: ignore[assignment]
            if not share_features_extractor:
                self.vf_features_extractor = self.pi_features_extractor
        # The networks built here, and SB3's or this package's features extractors: one of the user's keeps the weights
        # and biases it was built with (SB3's orthogonal scheme, A2C's, re-initialises it as in A2C)
        extractors = {self.pi_features_extractor, self.vf_features_extractor}
        if not with_bias:
            remove_biases(self, keep=[extractor for extractor in extractors if not is_library_extractor(extractor)])
        # (after remove_biases, which replaces action_net and value_net)
        built = [self.mlp_extractor, self.action_net, self.value_net, *filter(is_library_extractor, extractors)]
        check_constant_init_is_linear(weight_init, built, [self.action_net, self.value_net])
        if not isinstance(weight_init, str):
            constant_init(built, weight_init)
        elif weight_init == "kaiming":
            hidden = {self.mlp_extractor, *filter(is_library_extractor, extractors)}
            kaiming_init(hidden, activation_fn, activation_kwargs)
        elif weight_init == "sparse":
            sparse_init(built)

        # Two optimizers instead of ActorCriticPolicy's one: α^θ for the policy network, α^w for the value network
        value_modules = [self.mlp_extractor.value_net, self.value_net]
        if not share_features_extractor and use_baseline:
            value_modules.append(self.vf_features_extractor)
        value_parameters = [param for module in value_modules for param in module.parameters()]
        value_ids = {id(param) for param in value_parameters}
        policy_parameters = [param for param in self.parameters() if id(param) not in value_ids]
        value_lr_schedule = value_lr_schedule or lr_schedule
        optimizer_kwargs = optimizer_kwargs_with_defaults(self.optimizer_class, self.optimizer_kwargs)
        if self.optimizer_class is th.optim.Adam:
            # SB3's ActorCriticPolicy gives Adam eps=1e-5 (A2C's and PPO's) only where optimizer_kwargs is None: choosing
            # the implementation (fused, foreach) would otherwise change the update too (eps=1e-8)
            optimizer_kwargs.setdefault("eps", 1e-5)
        self.value_optimizer_kwargs = value_optimizer_kwargs
        value_kwargs = {**optimizer_kwargs, **(value_optimizer_kwargs or {})}
        if issubclass(self.optimizer_class, ObGD):
            # The paper's κ of an actor for the policy (ObGD's own default, 2, is a value learner's)
            optimizer_kwargs.setdefault("kappa", ACTOR_KAPPA)
        self.optimizer = self.optimizer_class(policy_parameters, lr=lr_schedule(1), **optimizer_kwargs)  # type: ignore[call-arg]
        self.value_optimizer: th.optim.Optimizer | None = None
        if use_baseline:
            self.value_optimizer = self.optimizer_class(value_parameters, lr=value_lr_schedule(1), **value_kwargs)  # type: ignore[call-arg]

    def _build_mlp_extractor(self) -> None:
        """SB3's ``MlpExtractor``, with ``layer_norm`` a LayerNorm after each of its linear layers (its hidden layers)."""
        super()._build_mlp_extractor()
        if self.layer_norm:
            if not any(isinstance(layer, nn.Linear) for layer in self.mlp_extractor.modules()):
                raise ValueError(
                    f"layer_norm=True normalises the networks' hidden layers, and net_arch={self.net_arch!r} has none (both "
                    "networks are linear in the features): give hidden layers (e.g. net_arch=[64, 64]) or drop layer_norm"
                )
            kwargs = self.layer_norm_kwargs or {}
            for part in ("policy_net", "value_net"):
                # Linear, LayerNorm, activation: the same Linear modules (and weights) as without LayerNorm
                layers = getattr(self.mlp_extractor, part)
                normed = [
                    [layer, nn.LayerNorm(layer.out_features, **kwargs)] if isinstance(layer, nn.Linear) else [layer]
                    for layer in layers
                ]
                setattr(self.mlp_extractor, part, nn.Sequential(*(module for group in normed for module in group)))

    def _check_value_network(self, method: str) -> None:
        """:raises ValueError: for plain REINFORCE (``use_baseline=False``), which has no v̂ for ``method`` to return"""
        if not self.use_baseline:
            raise ValueError(
                f"This policy has no value network (use_baseline=False): v̂ is not defined, and {method} returns it. "
                "For actions and their log-probabilities use policy.get_distribution(obs) (.get_actions(), "
                ".log_prob(actions), .entropy()) or predict(obs); to export the policy (SB3's recipe wraps "
                "policy(obs, deterministic=True)), wrap policy._predict(obs, deterministic=True), which returns the actions"
            )

    def forward(self, obs: th.Tensor, deterministic: bool = False) -> tuple[th.Tensor, th.Tensor, th.Tensor]:
        """
        SB3's ``ActorCriticPolicy.forward``.

        :param obs: observations
        :param deterministic: whether to take the most likely actions
        :return: actions, v̂(obs, w) of shape (batch, 1), and the actions' log-probabilities
        :raises ValueError: for plain REINFORCE (``use_baseline=False``), which has no value network
        """
        self._check_value_network("policy(obs) (forward)")
        return super().forward(obs, deterministic)

    def evaluate_actions(
        self, obs: PyTorchObs, actions: th.Tensor, action_masks: th.Tensor | np.ndarray | None = None
    ) -> tuple[th.Tensor, th.Tensor, th.Tensor | None]:
        """
        SB3's ``ActorCriticPolicy.evaluate_actions``, with sb3-contrib's ``action_masks``.

        :param obs: observations
        :param actions: actions, as SB3's distributions take them
        :param action_masks: the legal actions of each observation, shape (batch, mask_size); None: all legal
        :return: v̂(obs, w) of shape (batch, 1), the actions' log-probabilities and the entropy of the distribution
            (over the legal actions)
        :raises ValueError: for plain REINFORCE (``use_baseline=False``), which has no value network
        """
        self._check_value_network("evaluate_actions")
        if not self._masks_restrict(action_masks):
            return super().evaluate_actions(obs, actions)
        assert action_masks is not None
        features = self.extract_features(obs)
        if self.share_features_extractor:
            latent_pi, latent_vf = self.mlp_extractor(features)
        else:
            pi_features, vf_features = features
            latent_pi = self.mlp_extractor.forward_actor(pi_features)
            latent_vf = self.mlp_extractor.forward_critic(vf_features)
        distribution = self._masked_distribution(self.action_net(latent_pi), action_masks)
        return self.value_net(latent_vf), distribution.log_prob(actions), distribution.entropy()

    def _masks_restrict(self, action_masks: th.Tensor | np.ndarray | None) -> bool:
        """:return: whether there are masks and they make some action illegal"""
        return action_masks is not None and not bool(action_masks.all())

    def _masked_distribution(self, action_logits: th.Tensor, action_masks: th.Tensor | np.ndarray) -> MaskableDistribution:
        """
        :param action_logits: the outputs of ``action_net``, shape (batch, n_logits)
        :param action_masks: the legal actions, shape (batch, mask_size)
        :return: sb3-contrib's masked distribution of them
        """
        if self.masked_action_dist is None:
            raise ValueError(f"action_masks: {self.action_space} actions cannot be masked; pass action_masks=None")
        if isinstance(self.action_space, spaces.MultiBinary):
            # Bernoulli logit l of each dimension as the categorical logits (0, l): soft-max gives 1 − σ(l), σ(l)
            action_logits = th.stack([th.zeros_like(action_logits), action_logits], dim=-1).flatten(1)
        masks = th.as_tensor(action_masks, dtype=th.bool, device=action_logits.device).reshape(action_logits.shape)
        # The illegal logits at sb3-contrib's −1e8 before the distribution is built too: their gradient is then exactly
        # 0 (sb3-contrib masks the normalised logits, whose normaliser leaves a gradient of rounding size)
        action_logits = th.where(masks, action_logits, th.tensor(-1e8, dtype=action_logits.dtype, device=masks.device))
        distribution = self.masked_action_dist.proba_distribution(action_logits)
        distribution.apply_masking(masks)
        return distribution

    def get_distribution(self, obs: PyTorchObs, action_masks: th.Tensor | np.ndarray | None = None) -> Distribution:
        """
        SB3's ``ActorCriticPolicy.get_distribution``, with sb3-contrib's ``action_masks``.

        :param obs: observations
        :param action_masks: the legal actions of each observation, shape (batch, mask_size); None: all legal
        :return: the policy's distribution of the actions in ``obs``, masked
        """
        if not self._masks_restrict(action_masks):
            return super().get_distribution(obs)
        assert action_masks is not None
        features = BaseModel.extract_features(self, obs, self.pi_features_extractor)
        return self._masked_distribution(self.action_net(self.mlp_extractor.forward_actor(features)), action_masks)

    def _predict(
        self, observation: PyTorchObs, deterministic: bool = False, action_masks: np.ndarray | None = None
    ) -> th.Tensor:
        """
        :param observation: observations
        :param deterministic: the most likely actions (among the legal ones) if True, a draw otherwise
        :param action_masks: the legal actions of each observation, shape (batch, mask_size); None: all legal
        :return: the actions, as indices
        """
        return self.get_distribution(observation, action_masks).get_actions(deterministic=deterministic)

    def _predict_masked(self, observation: PyTorchObs, deterministic: bool, action_masks: np.ndarray) -> th.Tensor:
        """``_predict`` with masks (``EnvActionsMixin.predict``'s hook)."""
        return self._predict(observation, deterministic, action_masks)

    def release_distributions(self) -> None:
        """
        Drop the distributions evaluated last, which hold the graph of their step: it is then freed, and the policy
        can be copied (``copy.deepcopy``, pickle) by a callback, as A2C's can during its rollouts.
        """
        self.action_dist.distribution = None  # type: ignore[assignment]
        if self.masked_action_dist is not None:
            for name in ("distribution", "distributions"):
                if hasattr(self.masked_action_dist, name):
                    setattr(self.masked_action_dist, name, None if name == "distribution" else [])

    def predict_values(self, obs: PyTorchObs) -> th.Tensor:
        """
        :param obs: observations
        :return: v̂(obs, w), shape (batch, 1)
        :raises ValueError: for plain REINFORCE (``use_baseline=False``), which has no value network
        """
        self._check_value_network("predict_values")
        return super().predict_values(obs)

    def sample_actions(self, obs: PyTorchObs, action_masks: np.ndarray | None = None) -> th.Tensor:
        """
        ``A ~ π(·|obs, θ)``, the behaviour policy of the rollout loop: the actions of ``forward(obs)`` where a subclass
        overrides it (as SB3's A2C acts with them), else a draw from ``get_distribution(obs)``. For Discrete
        actions, where a subclass overrides none of SB3's hooks of that distribution, this is the draw
        ``CategoricalDistribution.sample()`` makes (the same ``multinomial`` call on the soft-max of the logits),
        without building a ``torch.distributions`` object at every env step, which is most of the per-step cost
        of SB3's ``get_distribution``; otherwise (other action spaces, a subclass that masks actions) SB3's. With masks
        that make some action illegal, a draw from sb3-contrib's masked distribution (``get_distribution``).

        :param obs: the observations of all envs
        :param action_masks: their legal actions, shape (n_envs, mask_size); None: all legal
        :return: one action per env
        """
        if action_masks is not None and self._masks_restrict(action_masks):
            return self.get_distribution(obs, action_masks).get_actions()
        if self._own_forward:
            # A subclass's forward (A2C's rollouts take its actions; its values and log-probabilities are not needed)
            return self(obs)[0]
        if not (isinstance(self.action_dist, CategoricalDistribution) and self._sb3_distribution):
            return self.get_distribution(obs).get_actions()
        features = BaseModel.extract_features(self, obs, self.pi_features_extractor)
        logits = self.action_net(self.mlp_extractor.forward_actor(features))
        # π(a|s, θ) = soft-max of the action preferences h(s, a, θ) (S&B eq. 13.2)
        return th.multinomial(th.softmax(logits, dim=-1), 1, replacement=True).squeeze(-1)

    def action_logits(self, obs: PyTorchObs) -> th.Tensor:
        """
        :param obs: observations
        :return: the action preferences h(s, ·, θ) of Discrete actions (the logits π is the soft-max of, S&B eq. 13.2),
            shape (batch, n_actions)
        """
        features = BaseModel.extract_features(self, obs, self.pi_features_extractor)
        return self.action_net(self.mlp_extractor.forward_actor(features))

    def set_training_mode(self, mode: bool) -> None:
        """
        :param mode: train (True) or evaluation (False) mode of every module; nothing to do if already there (the
            per-step loop switches at every env step, and ``nn.Module.train`` visits every submodule)
        """
        if self.training != mode:
            super().set_training_mode(mode)

    @property
    def value_parameters(self) -> list[nn.Parameter]:
        """The parameters ``value_optimizer`` trains (w; none without a baseline)."""
        if self.value_optimizer is None:
            return []
        return [param for group in self.value_optimizer.param_groups for param in group["params"]]

    @property
    def policy_parameters(self) -> list[nn.Parameter]:
        """The parameters ``optimizer`` trains (θ)."""
        return [param for group in self.optimizer.param_groups for param in group["params"]]

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        for unsupported in ("use_sde", "squash_output", "full_std", "use_expln", "ortho_init"):
            data.pop(unsupported)
        data.update(
            activation_fn=self.activation_fn,
            activation_kwargs=self.activation_kwargs,
            weight_init=self.weight_init,
            with_bias=self.with_bias,
            layer_norm=self.layer_norm,
            layer_norm_kwargs=self.layer_norm_kwargs,
            use_baseline=self.use_baseline,
            value_optimizer_kwargs=self.value_optimizer_kwargs,
            share_features_extractor=self.share_features_extractor,
        )
        return data


class REINFORCECnnPolicy(REINFORCEPolicy):
    """
    ``REINFORCEPolicy`` with SB3's NatureCNN features extractor, for image observations.

    :param observation_space: observation space
    :param action_space: action space
    :param lr_schedule: learning-rate schedule of the policy network (α^θ)
    :param kwargs: the other arguments of ``REINFORCEPolicy``
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Space,
        lr_schedule: Schedule,
        features_extractor_class: type[BaseFeaturesExtractor] = NatureCNN,
        **kwargs: Any,
    ):
        super().__init__(
            observation_space, action_space, lr_schedule, features_extractor_class=features_extractor_class, **kwargs
        )


class REINFORCEMultiInputPolicy(REINFORCEPolicy):
    """
    ``REINFORCEPolicy`` with SB3's CombinedExtractor, for ``Dict`` observations.

    :param observation_space: observation space
    :param action_space: action space
    :param lr_schedule: learning-rate schedule of the policy network (α^θ)
    :param kwargs: the other arguments of ``REINFORCEPolicy``
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Space,
        lr_schedule: Schedule,
        features_extractor_class: type[BaseFeaturesExtractor] = CombinedExtractor,
        **kwargs: Any,
    ):
        super().__init__(
            observation_space, action_space, lr_schedule, features_extractor_class=features_extractor_class, **kwargs
        )


MlpPolicy = REINFORCEPolicy
CnnPolicy = REINFORCECnnPolicy
MultiInputPolicy = REINFORCEMultiInputPolicy
