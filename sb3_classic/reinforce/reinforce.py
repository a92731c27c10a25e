from collections.abc import Callable, Sequence
from typing import Any, ClassVar, NamedTuple, TypeVar

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule
from stable_baselines3.common.utils import FloatSchedule, explained_variance, obs_as_tensor

from sb3_classic.common.arguments import LOADING
from sb3_classic.common.buffers import TrainingBatch, select
from sb3_classic.common.obgd import ObGD
from sb3_classic.common.on_policy_algorithm import ClassicOnPolicyAlgorithm, Update, run_update
from sb3_classic.common.returns import discounted_returns
from sb3_classic.common.utils import check_bool, check_choice, check_learning_rate, check_positive_int, check_range
from sb3_classic.reinforce.policies import CnnPolicy, MlpPolicy, MultiInputPolicy, REINFORCEPolicy
from sb3_classic.reinforce.streaming import check_streaming_settings, reinforce_obgd_step

SelfREINFORCE = TypeVar("SelfREINFORCE", bound="REINFORCE")


def softmax_cdf(logits: np.ndarray) -> np.ndarray:
    """
    :param logits: action preferences h(s, ·, θ), shape (..., n_actions)
    :return: the cumulative probabilities of their soft-max π(·|s) (S&B eq. 13.2), unnormalised (the last one is the
        normaliser Σ_a e^{h(s, a) − max_b h(s, b)}), float64, the same shape
    """
    logits = np.asarray(logits, dtype=np.float64)
    return np.cumsum(np.exp(logits - logits.max(axis=-1, keepdims=True)), axis=-1)


def draw_from_cdf(cdf: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """
    A ~ π(·|s) for each row by the inverse CDF: the first action whose cumulative probability exceeds one uniform draw
    u ~ U[0, 1) of ``rng`` scaled by the row's total (so that rounding leaves no gap at the top).

    :param cdf: ``softmax_cdf``'s, shape (B, n_actions)
    :param rng: the generator of the draws (one ``rng.random((B, 1))`` call: B draws, in row order)
    :return: the action indices, shape (B,), int64
    """
    u = rng.random((len(cdf), 1)) * cdf[:, -1:]
    # (the count over all but the last action: at most the last index, even where rounding puts u at the total)
    return (cdf[:, :-1] <= u).sum(axis=-1)


def categorical_inverse_cdf(logits: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """
    :param logits: the action preferences h(s, ·, θ), shape (B, n_actions)
    :param rng: the generator of the draws (B draws, in row order)
    :return: A ~ π(·|s) of each row (``draw_from_cdf`` of ``softmax_cdf``), shape (B,), int64
    """
    return draw_from_cdf(softmax_cdf(logits), rng)


class REINFORCELosses(NamedTuple):
    """The losses of a REINFORCE gradient step, each member's, shape (K,)."""

    policy: th.Tensor
    value: th.Tensor
    entropy: th.Tensor
    #: what the gradient step descends: policy + ent_coef · entropy (+ value with a baseline)
    total: th.Tensor


def reinforce_losses(
    log_prob: th.Tensor,
    entropy: th.Tensor,
    values: th.Tensor,
    returns: th.Tensor,
    episode_steps: th.Tensor,
    gamma: float,
    gamma_t_factor: bool,
    normalize_advantage: bool,
    ent_coef: float,
    use_baseline: bool,
    lengths: th.Tensor | None = None,
) -> REINFORCELosses:
    """
    The losses of REINFORCE (with baseline) for each member of a member axis (a model alone is the axis of one member),
    each member's mean over its own steps. The members' losses are independent: a gradient of their sum gives member
    k's parameters the gradient of its own losses only.

    :param log_prob: ln π(A_t|S_t, θ), shape (K, B), with its gradient
    :param entropy: the entropy of π(·|S_t, θ), shape (K, B)
    :param values: v̂(S_t, w) before the step, shape (K, B), with its gradient (zeros without a baseline)
    :param returns: G_t, shape (K, B)
    :param episode_steps: t, the step of each within its episode, shape (K, B)
    :param gamma: γ
    :param gamma_t_factor: weight each step's policy gradient by γ^t (S&B eq. 13.8)
    :param normalize_advantage: standardise δ_t over each member's steps (where it has more than one)
    :param ent_coef: the entropy bonus's coefficient
    :param use_baseline: whether v̂ is trained (its loss in ``total``)
    :param lengths: how many of the B steps are member k's, the rest padding, shape (K,); None: all B, for every member
    :return: the losses, each shape (K,)
    """
    # δ_t = G_t − v̂(S_t, w) (S&B §13.4), from w before this step's update; the baseline is a constant for the policy
    # gradient. Plain REINFORCE: δ_t = G_t (§13.3)
    advantages = returns - values.detach()
    if lengths is None:
        # (with K = 1 the bits of a batch's mean-reduced losses and their gradients)
        def member_mean(x: th.Tensor) -> th.Tensor:
            return x.mean(dim=1)

        def standardised(a: th.Tensor) -> th.Tensor:
            return (a - a.mean(dim=1, keepdim=True)) / (a.std(dim=1, keepdim=True) + 1e-8)

        several = advantages.shape[1] > 1
    else:
        # Each member's over its own steps: weight 1/T_k on its steps, 0 on the padding
        valid = th.arange(advantages.shape[1], device=advantages.device) < lengths[:, None]
        weights = valid / lengths[:, None]

        def member_mean(x: th.Tensor) -> th.Tensor:
            return (x * weights).sum(1)

        def standardised(a: th.Tensor) -> th.Tensor:
            # (torch's unbiased std; a member with one step keeps its δ_t)
            mean = (a * weights).sum(1, keepdim=True)
            spread = ((a - mean) ** 2 * valid).sum(1, keepdim=True) / (lengths[:, None] - 1).clamp(min=1)
            return th.where(lengths[:, None] > 1, (a - mean) / (spread.sqrt() + 1e-8), a)

        several = True
    # Standardised over each member's own steps, where it has more than one
    policy_weights = standardised(advantages) if normalize_advantage and several else advantages
    if gamma_t_factor:
        policy_weights = policy_weights * gamma**episode_steps
    # θ ← θ + α^θ γ^t δ_t ∇ln π(A_t|S_t, θ) (S&B §13.4, eq. 13.11 with b(S_t) = v̂(S_t, w); eq. 13.8 with b = 0)
    policy_loss = -member_mean(policy_weights * log_prob)
    # w ← w + α^w δ_t ∇v̂(S_t, w) (S&B §13.4): the gradient of ½ δ_t²
    value_loss = 0.5 * member_mean((returns - values) ** 2)
    entropy_loss = -member_mean(entropy)
    total = policy_loss + ent_coef * entropy_loss
    if use_baseline:
        total = total + value_loss
    return REINFORCELosses(policy_loss, value_loss, entropy_loss, total)


class REINFORCE(ClassicOnPolicyAlgorithm):
    r"""
    REINFORCE with baseline: Monte-Carlo policy gradient with a learned state-value baseline
    (Williams 1992; Sutton & Barto, Reinforcement Learning: An Introduction, 2nd ed., §13.4).

    Each update uses ``n_episodes`` complete episodes. For every step t of them, with the Monte-Carlo return and its
    difference from the baseline

    .. math::

        G_t = \sum_{k=t+1}^{T} \gamma^{k-t-1} R_k, \qquad \delta_t = G_t - \hat v(S_t, \mathbf w),

    - the value network follows :math:`\mathbf w \leftarrow \mathbf w + \alpha^{\mathbf w} \delta_t \nabla \hat v(S_t,
      \mathbf w)`;
    - the policy network follows :math:`\boldsymbol\theta \leftarrow \boldsymbol\theta + \alpha^{\boldsymbol\theta}
      \delta_t \nabla \ln \pi(A_t \mid S_t, \boldsymbol\theta)`,

    ``update_mode`` says how an update applies them:

    - ``"batch"`` (the default): one gradient step of each network on the *mean* over the batch's steps, as A2C and
      most implementations do. Each step t then moves the weights by α/T of its own update for an episode of T
      steps, and T changes during training;
    - ``"per_step"``: the book's loop over the episode, t = 0, …, T − 1 (§13.4's box): :math:`\delta_t` from the
      current :math:`\mathbf w`, the value update with :math:`\alpha^{\mathbf w}`, then the policy update with
      :math:`\alpha^{\boldsymbol\theta}`, each with the full step size. With plain SGD
      (``policy_kwargs=dict(optimizer_class=th.optim.SGD)``), one env, ``n_episodes=1`` and ``gamma_t_factor=True``
      (the box's :math:`\gamma^t`; or γ = 1) it is the book's algorithm to the last bit. With
      ``policy_kwargs=dict(optimizer_class=ObGD)`` each update is bounded as in the streaming recipe (Elsayed, Vasan &
      Mahmood 2024, arXiv 2410.14606): a network's step cut to α/M where :math:`M = \alpha\kappa \max(|\delta|, 1)
      \lVert \nabla \rVert_1 > 1`, κ = 3 for the policy and 2 for v̂ (``reinforce_obgd_step``), with
      ``weight_init="sparse"`` and ``layer_norm`` as its networks.

    Why batch by default: the settings of ``hyperparams/reinforce.yml`` (Adam, the seed report's learning rates)
    were found and benchmarked with it; the per-step mode makes T optimizer steps per episode instead of one
    (hundreds on Acrobot-v1), so the same learning rates are not comparable between the modes.

    The book's update also has a factor :math:`\gamma^t` (``gamma_t_factor=True``). It is off by default, as in most
    implementations and in the seed report's results: it makes the gradient the exact gradient of the discounted
    return from the start state, but it scales the updates of late steps down to nothing (:math:`\gamma^{500} \approx
    0.007` for γ = 0.99), which slows learning on long episodes.

    ``use_baseline=False`` is plain REINFORCE (§13.3, eq. 13.8): no value network is built, :math:`\delta_t` is
    :math:`G_t`, and ``value_learning_rate`` is unused. Without v̂ there is nothing to bootstrap a time-limit
    truncation from: the return ends there, as with ``handle_timeout_termination=False``.

    With several envs, an update takes every episode that has ended, and an env whose episode is still running
    keeps it for a later update: nothing is thrown away, and long episodes are not dropped in favour of short
    ones. (The steps of such an episode taken before an update were sampled by the policy before it; with one
    env, every update is exactly on-policy.)

    Invalid-action masking (Discrete, MultiDiscrete, MultiBinary actions) works as in sb3-contrib's MaskablePPO: when
    the env supports it (an ``action_masks()`` method, or sb3-contrib's ``ActionMasker`` wrapper) and
    ``learn(use_masking=True)`` (the default), π is sb3-contrib's masked distribution in the rollouts and in the
    update: :math:`\ln \pi(A_t \mid S_t, \boldsymbol\theta)` is over the legal actions of :math:`S_t` (its mask,
    stored with the step), an illegal action's logit gets no gradient, and the entropy bonus is over the legal
    actions. ``predict(obs, action_masks=...)`` takes masks as MaskablePPO's does (sb3-contrib's
    ``MaskableEvalCallback`` and ``evaluate_policy`` pass them). Unlike MaskablePPO, an env without masks trains
    unmasked. The baseline :math:`\hat v(S_T)` of a truncation's final state does not depend on masks.

    :param policy: the policy model to use (``"MlpPolicy"``, ``"CnnPolicy"``, ``"MultiInputPolicy"``)
    :param env: the environment to learn from (if registered in Gymnasium, can be str)
    :param learning_rate: learning rate :math:`\alpha^{\boldsymbol\theta}` of the policy network (a float or an SB3
        schedule of the remaining progress); the seed report's best: 0.003 on CartPole-v1, 0.001 on Acrobot-v1
    :param value_learning_rate: learning rate :math:`\alpha^{\mathbf w}` of the value network (float or SB3
        schedule); the seed report's best: 0.01 on CartPole-v1, 0.1 on Acrobot-v1
    :param n_episodes: complete episodes per update (all envs together; an update takes every episode that has
        ended, so it may use more)
    :param update_mode: ``"batch"`` (one gradient step of each network on the batch mean) or ``"per_step"`` (the
        book's T updates per episode with the full step sizes), see above
    :param use_baseline: learn :math:`\hat v(s, \mathbf w)` and use :math:`\delta_t = G_t - \hat v(S_t, \mathbf w)`
        (§13.4); False: plain REINFORCE (§13.3)
    :param gamma: discount factor γ
    :param gamma_t_factor: multiply the policy gradient of step t by :math:`\gamma^t` as in the book (see above)
    :param normalize_advantage: standardise δ over the batch before the policy gradient (the value network still
        regresses on the raw returns)
    :param ent_coef: entropy bonus coefficient of the policy loss
    :param max_grad_norm: clip the gradient norm of each network to this; None for no clipping
    :param lr_decay_factor: multiply both learning rates by this at each decay (1.0: no decay)
    :param lr_decay_every: decay every this many ``lr_decay_unit`` (like PyTorch's ``StepLR``)
    :param lr_decay_milestones: decay when the count of ``lr_decay_unit`` reaches each of these (like ``MultiStepLR``)
    :param lr_decay_unit: ``"episode"`` (completed episodes) or ``"update"`` (gradient steps, as ``train/n_updates``
        counts them)
    :param handle_timeout_termination: at a time-limit truncation, bootstrap the return from v̂ of the final state
        (the time limit is not part of the task: SB3's choice, and the default); if False, the return ends there
        as at a termination
    :param max_episode_length: REINFORCE needs episodes that end: one that reaches this many steps is cut there for
        training (with a warning), so a never-ending env cannot grow the buffer without bound. Its return ends there,
        bootstrapped as at a time limit, but the env is not reset: the next episode trained on starts from the state
        reached, and the Monitor and callbacks do not count the cut (``gymnasium.wrappers.TimeLimit`` resets it)
    :param stats_window_size: window size for the rollout logging, in episodes
    :param tensorboard_log: the log location for TensorBoard (if None, no logging)
    :param policy_kwargs: additional arguments to be passed to the policy on creation (see ``REINFORCEPolicy``:
        ``net_arch``, ``activation_fn``, ``activation_kwargs``, ``weight_init``, ...)
    :param verbose: verbosity level: 0 no output, 1 info, 2 debug
    :param seed: seed for the pseudo random generators
    :param device: device (cpu, cuda, ...) on which the code should be run
    :param _init_setup_model: whether or not to build the network at the creation of the instance
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {
        "MlpPolicy": MlpPolicy,
        "CnnPolicy": CnnPolicy,
        "MultiInputPolicy": MultiInputPolicy,
    }
    _network_arguments: ClassVar[dict[str, Callable[[Any], bool]]] = {"use_baseline": bool}
    policy: REINFORCEPolicy
    value_lr_schedule: Schedule

    def __init__(
        self,
        policy: str | type[REINFORCEPolicy],
        env: GymEnv | str,
        learning_rate: float | Schedule = 3e-3,
        value_learning_rate: float | Schedule = 1e-2,
        n_episodes: int = 1,
        update_mode: str = "batch",
        use_baseline: bool = True,
        gamma: float = 0.99,
        gamma_t_factor: bool = False,
        normalize_advantage: bool = False,
        ent_coef: float = 0.0,
        max_grad_norm: float | None = None,
        lr_decay_factor: float = 1.0,
        lr_decay_every: int | None = None,
        lr_decay_milestones: Sequence[int] | None = None,
        lr_decay_unit: str = "episode",
        handle_timeout_termination: bool = True,
        max_episode_length: int = 100_000,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        policy_kwargs: dict[str, Any] | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: th.device | str = "auto",
        _init_setup_model: bool = True,
    ):
        super().__init__(
            policy,
            env,
            learning_rate=learning_rate,
            # Unused: a rollout is n_episodes whole episodes, not a fixed number of steps
            n_steps=1,
            gamma=gamma,
            max_grad_norm=max_grad_norm,
            lr_decay_factor=lr_decay_factor,
            lr_decay_every=lr_decay_every,
            lr_decay_milestones=lr_decay_milestones,
            lr_decay_unit=lr_decay_unit,
            handle_timeout_termination=handle_timeout_termination,
            max_episode_length=max_episode_length,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            policy_kwargs=policy_kwargs,
            verbose=verbose,
            seed=seed,
            device=device,
            supported_action_spaces=(spaces.Discrete, spaces.Box, spaces.MultiDiscrete, spaces.MultiBinary),
            _init_setup_model=False,
        )
        self.value_learning_rate = value_learning_rate
        self.n_episodes = n_episodes
        self.update_mode = update_mode
        self.use_baseline = use_baseline
        self.gamma_t_factor = gamma_t_factor
        self.normalize_advantage = normalize_advantage
        self.ent_coef = ent_coef
        # The generator of the rollouts' action draws; None: torch's global one (``multinomial``), seeded by SB3
        self._action_rng: np.random.Generator | None = None
        if _init_setup_model:
            self._setup_model()  # (which checks the arguments first)

    def _check_arguments(self) -> None:
        super()._check_arguments()
        check_learning_rate("value_learning_rate", self.value_learning_rate, allow_zero=LOADING.get())
        check_positive_int("n_episodes", self.n_episodes, hint="1 is the book's algorithm")
        # (use_baseline: checked by the policy, which takes it)
        for name in ("gamma_t_factor", "normalize_advantage"):
            check_bool(name, getattr(self, name))
        check_choice("update_mode", self.update_mode, ("batch", "per_step"))
        if self.normalize_advantage and self.update_mode == "per_step":
            raise ValueError(
                "normalize_advantage=True standardises δ over a batch, but update_mode='per_step' updates one step at a "
                "time: pass update_mode='batch', or normalize_advantage=False"
            )
        check_range("ent_coef", self.ent_coef, 0.0, float("inf"), hint="0.0 disables the entropy bonus")
        check_streaming_settings(self.policy_kwargs, self.update_mode, self.ent_coef, self.max_grad_norm)

    def _make_policy(self) -> BasePolicy:
        self._refuse_policy_kwargs_set_here(use_baseline="use_baseline", value_lr_schedule="value_learning_rate")
        self.value_lr_schedule = FloatSchedule(self.value_learning_rate)
        return self.policy_class(
            self.observation_space,
            self.action_space,
            self.lr_schedule,
            value_lr_schedule=self.value_lr_schedule,
            use_baseline=self.use_baseline,
            **self.policy_kwargs,
        )

    def _sample_actions(
        self,
        obs: np.ndarray | dict[str, np.ndarray],
        action_masks: np.ndarray | None = None,
        behaviour: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> np.ndarray:
        if self._action_rng is not None:
            return self._draw_actions(obs, action_masks, behaviour)
        # A ~ π(·|S, θ) over the legal actions; the baseline v̂ is only needed at update time
        actions = self.policy.sample_actions(obs_as_tensor(obs, self.device), action_masks).cpu().numpy()
        if isinstance(self.action_space, spaces.Box):
            # SB3's Gaussian draws flat actions (n_envs, action_dim); the env and the buffer take the space's shape
            # (as SB3's ActorCriticPolicy.forward reshapes them), e.g. (n_envs, 2, 3) for Box(shape=(2, 3))
            actions = actions.reshape((-1, *self.action_space.shape))
        return actions

    def _draw_actions(
        self,
        obs: np.ndarray | dict[str, np.ndarray],
        action_masks: np.ndarray | None,
        behaviour: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> np.ndarray:
        """
        ``_sample_actions`` with ``_action_rng`` set: A ~ π(·|S, θ) by the inverse CDF of the soft-max of the logits
        (``categorical_inverse_cdf``), one uniform draw of ``_action_rng`` per env, an illegal action (masks) at
        probability 0.

        :param obs: the current observations of all envs
        :param action_masks: the legal actions of each env, shape (n_envs, n_actions); None: all legal
        :param behaviour: the logits of ``obs`` and their cumulative probabilities (``softmax_cdf``), computed outside
            the model (a population's stacked forward pass); None: the policy's forward pass
        :return: one action index per env, shape (n_envs,)
        :raises ValueError: for actions other than Discrete, or a policy with its own forward or distribution
        """
        if not isinstance(self.action_space, spaces.Discrete) or self.policy._own_forward or not self.policy._sb3_distribution:
            raise ValueError(
                f"_action_rng draws Discrete actions from the soft-max of REINFORCEPolicy's logits, not {self.action_space} "
                f"actions of a {type(self.policy).__name__}: set model._action_rng = None"
            )
        if behaviour is None:
            logits, cdf = self.policy.action_logits(obs_as_tensor(obs, self.device)).cpu().numpy(), None
        else:
            logits, cdf = behaviour
        if action_masks is not None and not action_masks.all():
            # h(s, a) = −∞ for an illegal a: e^{h} = 0 in the soft-max (S&B eq. 13.2)
            cdf = softmax_cdf(np.where(action_masks, logits, -np.inf))
        elif cdf is None:
            cdf = softmax_cdf(logits)
        assert self._action_rng is not None
        return draw_from_cdf(cdf, self._action_rng)

    def _rollout_complete(self, n_steps: int, n_episodes: int) -> bool:
        return n_episodes >= self.n_episodes

    def _training_batch(self) -> TrainingBatch | None:
        """
        :return: every step of the complete episodes not trained on yet, with its Monte-Carlo return G_t
            (None if no episode has ended)
        """
        data = self.rollout_buffer.get()
        if len(data.dones) == 0:  # (train() called with nothing stored)
            return None
        # An env's pending steps up to its last episode end form complete episodes; the rest is still running
        steps = np.arange(len(data.dones))[:, None]
        last_end = np.where(data.dones, steps, -1).max(axis=0)
        trained = data.pending & (steps <= last_end)
        if not trained.any():
            return None
        # v̂(S_T, w) of the final states of time-limit truncations, to bootstrap their returns from
        next_values = np.zeros_like(data.rewards)
        if data.truncated.any() and self.use_baseline:
            with th.no_grad():
                final_obs = obs_as_tensor(select(data.final_observations, data.truncated), self.device)
                next_values[data.truncated] = self.policy.predict_values(final_obs).flatten().cpu().numpy()
        returns = discounted_returns(data.rewards, data.dones, next_values, self.gamma)
        return TrainingBatch(
            observations=select(data.observations, trained),
            actions=self._distribution_actions(data.actions[trained]),
            targets=returns[trained],
            episode_steps=data.episode_steps[trained],
            n_trained=np.count_nonzero(trained, axis=0),
            action_masks=None if data.action_masks is None else data.action_masks[trained],
        )

    def _distribution_actions(self, actions: np.ndarray) -> np.ndarray:
        """
        :param actions: A_t as the buffer stores them, shape (B, *action_space.shape)
        :return: the same, as SB3's distributions take them: Box actions flattened to (B, action_dim) (SB3's
            ``RolloutBuffer`` stores them so), other spaces unchanged
        """
        if isinstance(self.action_space, spaces.Box):
            return actions.reshape(len(actions), -1)
        return actions

    def _gradient_step(
        self,
        observations: np.ndarray | dict[str, np.ndarray],
        actions: np.ndarray,
        returns: np.ndarray,
        episode_steps: np.ndarray,
        action_masks: np.ndarray | None = None,
    ) -> dict[str, th.Tensor]:
        """
        One gradient step of each network on the mean over the given steps (one step: the book's per-step update).

        :param observations: S_t, a batch of B
        :param actions: A_t, as the buffer stores them
        :param returns: G_t, shape (B,)
        :param episode_steps: t, the step of each within its episode, shape (B,)
        :param action_masks: the legal actions of each S_t, shape (B, mask_size), if masking is on
        :return: the losses, and v̂(S_t) before the step (detached; zeros without a baseline)
        """
        obs = obs_as_tensor(observations, self.device)
        actions_t = th.as_tensor(actions, device=self.device)
        returns_t = th.as_tensor(returns, device=self.device)
        masks = None if action_masks is None else th.as_tensor(action_masks, device=self.device)
        if self.use_baseline:
            values, log_prob, entropy = self.policy.evaluate_actions(obs, actions_t, masks)
            values = values.flatten()
        else:
            distribution = self.policy.get_distribution(obs, masks)
            log_prob, entropy = distribution.log_prob(actions_t), distribution.entropy()
            values = th.zeros_like(returns_t)
        assert entropy is not None, "the action distributions REINFORCE supports have an entropy"
        if isinstance(self.policy.optimizer, ObGD):  # the same updates, each bounded by ObGD (the streaming recipe)
            return reinforce_obgd_step(
                self.policy, log_prob, entropy, values, returns_t, episode_steps, self.gamma, self.gamma_t_factor
            )

        # (a model alone is a member axis of one)
        losses = reinforce_losses(
            log_prob.unsqueeze(0),
            entropy.unsqueeze(0),
            values.unsqueeze(0),
            returns_t.unsqueeze(0),
            th.as_tensor(episode_steps, device=self.device).unsqueeze(0),
            self.gamma,
            self.gamma_t_factor,
            self.normalize_advantage,
            self.ent_coef,
            self.use_baseline,
        )
        loss = losses.total.squeeze(0)

        # The two networks have their own parameters: one backward pass, then each optimizer's step, is the value
        # update followed by the policy update of the book's loop
        optimizers = [self.policy.optimizer] + ([self.policy.value_optimizer] if self.policy.value_optimizer else [])
        for optimizer in optimizers:
            optimizer.zero_grad()
        loss.backward()
        self._clip_gradients(self.policy.policy_parameters)
        self._clip_gradients(self.policy.value_parameters)
        for optimizer in optimizers:
            optimizer.step()
        # The distribution evaluated here holds this step's graph: dropped, so that the graph is freed and the policy
        # can be copied (copy.deepcopy, pickle) by a callback, as A2C's can during its rollouts
        self.policy.release_distributions()
        return dict(
            policy_loss=losses.policy.detach().squeeze(0),
            value_loss=losses.value.detach().squeeze(0),
            entropy_loss=losses.entropy.detach().squeeze(0),
            values=values.detach(),
        )

    def train(self) -> None:
        """Update both networks on every complete episode in the buffer (``update_mode``: batch mean or per step)."""
        run_update(self._update(), self._gradient_step)

    def _update(self) -> Update:
        """
        The update of ``train``, its gradient steps made by the caller: it yields the steps of each gradient step,
        (S_t, A_t, G_t, t, masks), and is sent back what the step gave (``_gradient_step``'s losses and v̂(S_t) before
        the step). ``train`` makes them with ``_gradient_step``; a population with its stacked step.
        """
        # The learning rates α^θ and α^w of this update (schedule and decay)
        schedules = [(self.policy.optimizer, self.lr_schedule, "train/learning_rate")]
        if self.policy.value_optimizer is not None:
            schedules.append((self.policy.value_optimizer, self.value_lr_schedule, "train/value_learning_rate"))
        self._update_learning_rates(schedules)
        # v̂(S_T) of the truncations is no training batch: evaluation mode (dropout off, BatchNorm's running statistics
        # unmoved), as A2C/PPO compute their bootstrap values; training mode for the gradient steps only
        self.policy.set_training_mode(False)
        batch = self._training_batch()
        self.policy.set_training_mode(True)
        if batch is None:
            return

        # Per step: the book's loop over each episode's steps t = 0, …, T − 1, in the order they were taken (with
        # several envs, the episodes' steps interleave in time order)
        steps = []
        masks = batch.action_masks
        for chunk in self._update_slices(len(batch.targets)):
            chunk_masks = None if masks is None else masks[chunk]
            chunk_steps = batch.actions[chunk], batch.targets[chunk], batch.episode_steps[chunk], chunk_masks
            steps.append((yield select(batch.observations, chunk), *chunk_steps))

        self.rollout_buffer.mark_trained(batch.n_trained)
        self._n_updates += len(steps)
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        # Every episode in the buffer is held from its first step (t = 0)
        self.logger.record("train/n_episodes", int((batch.episode_steps == 0).sum()))
        self.logger.record("train/policy_loss", th.stack([step["policy_loss"] for step in steps]).mean().item())
        self.logger.record("train/entropy_loss", th.stack([step["entropy_loss"] for step in steps]).mean().item())
        if self.use_baseline:
            values = th.cat([step["values"] for step in steps]).cpu().numpy()
            self.logger.record("train/value_loss", th.stack([step["value_loss"] for step in steps]).mean().item())
            self.logger.record("train/explained_variance", explained_variance(values, batch.targets))
        if hasattr(self.policy, "log_std"):
            self.logger.record("train/std", th.exp(self.policy.log_std).mean().item())

    def learn(
        self: SelfREINFORCE,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 4,
        tb_log_name: str = "REINFORCE",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
        use_masking: bool = True,
    ) -> SelfREINFORCE:
        """
        Train for at least ``total_timesteps`` env steps (the last update waits for its episodes to end).

        :param total_timesteps: env steps to train for, all envs together
        :param callback: callback(s) called at every step with the state of the algorithm
        :param log_interval: updates between two logger dumps (each update takes at least ``n_episodes`` episodes;
            the default, 4, is SB3's DQN's 4 episodes); whatever was recorded since the last dump is dumped when
            ``learn()`` returns; None: no dumps
        :param tb_log_name: the name of the run for TensorBoard logging
        :param reset_num_timesteps: whether to reset ``num_timesteps`` (and the envs); the learning-rate decay
            counts keep going either way
        :param progress_bar: display a progress bar using tqdm and rich
        :param use_masking: use the env's invalid-action masks if it has them (``action_masks()``, sb3-contrib's
            ``ActionMasker``), as MaskablePPO does; an env without them trains unmasked
        :return: the trained model
        """
        return super().learn(
            total_timesteps=total_timesteps,
            callback=callback,
            log_interval=log_interval,
            tb_log_name=tb_log_name,
            reset_num_timesteps=reset_num_timesteps,
            progress_bar=progress_bar,
            use_masking=use_masking,
        )

    def predict(
        self,
        observation: np.ndarray | dict[str, np.ndarray],
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
        action_masks: np.ndarray | None = None,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """
        An action of π (the most likely with ``deterministic=True``), as the env takes it, among the legal actions
        of ``action_masks`` (sb3-contrib's MaskablePPO's argument).

        :param observation: the input observation (one, or a batch)
        :param state: unused (no recurrent policy)
        :param episode_start: unused (no recurrent policy)
        :param deterministic: the most likely action if True, a draw otherwise
        :param action_masks: the legal actions of each observation, shape (batch, mask_size) or (mask_size,) for one
            (sb3-contrib's ``get_action_masks(env)``); None: every action is legal
        :return: the actions, and the unchanged state
        """
        return self.policy.predict(observation, state, episode_start, deterministic, action_masks=action_masks)

    def _excluded_save_params(self) -> list[str]:
        # A population's generator and probabilities (they are the population's): not training state
        return [*super()._excluded_save_params(), "_action_rng"]

    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        optimizers = ["policy.optimizer"] + (["policy.value_optimizer"] if self.use_baseline else [])
        return ["policy", *optimizers], []
