import math
from collections.abc import Callable, Sequence
from typing import Any, ClassVar, Literal, NamedTuple, TypeVar

import numpy as np
import torch as th
import torch.nn.functional as F
from gymnasium import spaces
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule
from stable_baselines3.common.utils import LinearSchedule, obs_as_tensor

from sb3_classic.common.arguments import check_arguments
from sb3_classic.common.buffers import Observations, TrainingBatch, select
from sb3_classic.common.masking import uniform_legal_actions
from sb3_classic.common.obgd import ObGD, td_step
from sb3_classic.common.on_policy_algorithm import ClassicOnPolicyAlgorithm, Update, run_update
from sb3_classic.common.returns import (
    CompletedWindows,
    completed_windows,
    epsilon_greedy_expectation,
    greedy_random_ties,
    masked_epsilon_greedy_expectation,
    sarsa_targets,
)
from sb3_classic.common.schedules import ExponentialDecay
from sb3_classic.sarsa.arguments import (
    ARGUMENT_RULES,
    DEFAULT_EXPLORATION_DECAY_RATE,
    DEFAULT_EXPLORATION_FINAL_EPS,
    DEFAULT_EXPLORATION_FRACTION,
    DEFAULT_EXPLORATION_INITIAL_EPS,
)
from sb3_classic.sarsa.policies import CnnPolicy, LinearPolicy, LinearQPolicy, MlpPolicy, MultiInputPolicy, SARSAPolicy

SelfNStepSARSA = TypeVar("SelfNStepSARSA", bound="NStepSARSA")


class RolloutQValues(NamedTuple):
    """q̂(S, ·) of the states the rollout loop last chose actions in, and when it computed them."""

    #: q̂(S, ·), shape (n_envs, n_actions)
    q_values: np.ndarray
    #: ``_n_updates`` then (an update since changes the weights)
    n_updates: int
    #: ``num_timesteps`` then (before the step taken in those states)
    num_timesteps: int


def sarsa_losses(q_predicted: th.Tensor, targets: th.Tensor, huber: bool, sizes: np.ndarray | None = None) -> th.Tensor:
    """
    The loss of semi-gradient n-step SARSA for each member of a member axis (a model alone is the axis of one member),
    each member's mean over its own transitions: w ← w + α [G_{t:t+n} − q̂(S_t, A_t, w)] ∇q̂(S_t, A_t, w) (S&B
    eq. 10.5) is a gradient step on ½(G − q̂)². The members' losses are independent: a gradient of their sum gives
    member k's parameters the gradient of its own loss only.

    :param q_predicted: q̂(S_t, A_t, w) of each member's transitions, shape (K, B), with its gradient
    :param targets: G_{t:t+n}, shape (K, B) (no gradient: semi-gradient)
    :param huber: the Huber loss (the same as ½(G − q̂)² within 1 of the target, linear beyond) instead
    :param sizes: how many of the B transitions are member k's, the rest padding, shape (K,) (0: a member not
        trained, whose loss is 0); None: all B, for every member
    :return: each member's loss, shape (K,)
    """
    if huber:
        losses = F.smooth_l1_loss(q_predicted, targets, reduction="none")
    else:
        losses = 0.5 * F.mse_loss(q_predicted, targets, reduction="none")
    if sizes is None:
        # (with K = 1 the bits of the mean-reduced loss of one batch and of its gradient)
        return losses.mean(dim=1)
    valid = th.as_tensor(np.arange(losses.shape[1]) < sizes[:, None], device=losses.device)
    counts = th.as_tensor(np.maximum(sizes, 1), dtype=losses.dtype, device=losses.device)
    return th.where(valid, losses, 0.0).sum(dim=1) / counts


# Env steps per env between two logger dumps with learn()'s default log_interval ("auto")
LOG_EVERY_STEPS = 128


class NStepSARSA(ClassicOnPolicyAlgorithm):
    r"""
    Episodic semi-gradient n-step SARSA (Sutton & Barto, Reinforcement Learning: An Introduction, 2nd ed., §10.2)
    with a neural network :math:`\hat q(s, a, \mathbf w)` and an ε-greedy behaviour policy.

    Each transition :math:`(S_t, A_t)` is trained once towards its n-step return (eq. 10.4)

    .. math::

        G_{t:t+n} = R_{t+1} + \gamma R_{t+2} + \dots + \gamma^{n-1} R_{t+n} + \gamma^n \hat q(S_{t+n}, A_{t+n}),

    where :math:`A_{t+n}` is the action the agent actually took, with no bootstrap past a termination (eq. 10.5):

    .. math::

        \mathbf w \leftarrow \mathbf w + \alpha [G_{t:t+n} - \hat q(S_t, A_t, \mathbf w)] \nabla \hat q(S_t, A_t, \mathbf w).

    The gradient does not flow through the target (semi-gradient).

    Every ``train_freq`` steps per env, an update trains on every transition whose target has become known (a
    transition waits until its n steps are taken: every target is a full n-step return), with the weights at the
    update's start. ``update_mode`` says how:

    - ``"batch"`` (the default, what the tuned settings were found with): ``gradient_steps`` gradient steps on the
      *mean* loss of the transitions, as DQN does with a minibatch;
    - ``"per_step"``: each transition's own update with the full step size α, in time order (episode ends included),
      ``gradient_steps`` passes. With ``train_freq=1``, one env and plain SGD this is the box of §10.2 to the last bit;
      ``policy="LinearPolicy"`` (``LinearQPolicy``) is the book's linear q̂ with its own SGD update.

    Options that are not in §10.2's algorithm (all off by default): a slowly-moving bootstrap network
    (``target_update_interval``, ``tau``: SB3's DQN names), truncated λ-returns (``td_lambda``, §12.3, as CleanRL's PQN)
    or SARSA(λ) with eligibility traces under the ``ObGD`` optimizer (§12.7, the streaming recipe), LayerNorm
    (``policy_kwargs=dict(layer_norm=True)``), and a greedy policy from a Polyak average of q̂'s weights
    (``averaging_tau``), which keeps a q̂ that passes through a bad state for an update or two out of evaluations.

    The greedy action breaks ties at random (the book's ``argmax``), except in ``predict(deterministic=True)``, which
    takes the first so that it stays reproducible. At a time-limit truncation the target bootstraps from the final
    state with the ε-greedy expectation :math:`(1 - \varepsilon) \max_a \hat q + \varepsilon \operatorname{mean}_a \hat q`
    (eq. 7.8: no action is taken there); with ``expected_sarsa=True`` every bootstrap does (n-step Expected SARSA,
    eq. 7.7).

    Invalid-action masking works as in sb3-contrib's MaskablePPO: when the env supports it (an ``action_masks()``
    method, or sb3-contrib's ``ActionMasker`` wrapper) and ``learn(use_masking=True)`` (the default), the ε-greedy
    policy is over the legal actions :math:`L(s)`: :math:`\operatorname{argmax}_{a \in L(s)} \hat q(s, a)`, and with
    probability ε an action drawn uniformly from :math:`L(s)`. The mask of every :math:`S_t` is stored with it, so
    :math:`G_{t:t+n}`'s bootstrap follows the mask of :math:`S_{t+n}`, and the ε-greedy expectation is the masked
    policy's, :math:`(1 - \varepsilon) \max_{a \in L} \hat q + \varepsilon \operatorname{mean}_{a \in L} \hat q`: an
    illegal action's q̂ is never a target. The final state of a truncation takes the mask its env reports in
    ``info["action_mask"]`` (a VecEnv resets a finished env before ``action_masks()`` can be read again), and allows
    every action if it reports none.
    ``predict(obs, action_masks=...)`` takes masks as MaskablePPO's does. Unlike MaskablePPO, an env without masks
    trains unmasked.

    :param policy: the policy model to use (``"MlpPolicy"``, ``"CnnPolicy"``, ``"MultiInputPolicy"``, or
        ``"LinearPolicy"``: the book's linear q̂ with its own SGD update, ``LinearQPolicy``)
    :param env: the environment to learn from (if registered in Gymnasium, can be str)
    :param learning_rate: learning rate α (a float or an SB3 schedule of the remaining progress)
    :param n_steps: the n of n-step returns (as DQN's ``n_steps``); the seed report's best: 10 on CartPole-v1,
        5 on Acrobot-v1
    :param train_freq: env steps per env between two updates
    :param gradient_steps: gradient steps per update, on the same batch and targets (``update_mode="per_step"``:
        passes over the transitions)
    :param update_mode: ``"batch"`` (gradient steps on the mean loss of an update's transitions) or ``"per_step"``
        (each transition's own update with the full step size, in time order: the book's), see above
    :param gamma: discount factor γ
    :param expected_sarsa: bootstrap from the ε-greedy expectation of q̂ instead of q̂ of the action taken
    :param td_lambda: λ of the truncated λ-return :math:`G^\lambda_{t:t+n}` (S&B §12.3, eq. 12.9), the target of each
        transition: the k-step returns :math:`G_{t:t+k}` of its window (k = 1, …, n) weighted :math:`(1 - \lambda)
        \lambda^{k-1}`, :math:`\lambda^{n-1}` the n-step one; 1 (the default) is §10.2's :math:`G_{t:t+n}`, 0 the
        one-step return (the forward view of n-step-truncated SARSA(λ), as CleanRL's PQN; each update computes q̂ of every
        stored step once more). With ``policy_kwargs=dict(optimizer_class=ObGD)`` (``update_mode="per_step"``,
        ``n_steps=1``), the backward view: the decay of the eligibility traces, e ← γλe + ∇q̂ (SARSA(λ), §12.7)
    :param exploration_schedule: ``"exponential"``: :math:`\varepsilon \leftarrow \max(\varepsilon_\text{final},
        \varepsilon \rho)` with ρ = ``exploration_decay_rate``, at the end of every episode (the seed report's);
        ``"linear"``: from initial to final over ``exploration_fraction`` of
        each ``learn()`` call (SB3's DQN); or a schedule: a callable of the progress remaining (1 at the start of each
        ``learn()`` call, 0 at its end) returning ε in [0, 1], such as SB3's ``LinearSchedule`` or
        ``ConstantSchedule`` (SB3's DQN keeps its schedule under this name: one assigned to ``model.exploration_schedule``
        later applies from the next update, as there); the other ``exploration_`` arguments are then refused if given
        (the schedule gives every ε)
    :param exploration_initial_eps: initial ε
    :param exploration_final_eps: final ε (the floor of the exponential decay)
    :param exploration_fraction: fraction of training over which the linear decay runs (``"linear"`` only; None:
        0.1, SB3's DQN's). Passing it with the exponential schedule is an error, not silently ignored: a DQN user's
        ``exploration_fraction=0.2`` alone would otherwise get the per-episode decay
    :param exploration_decay_rate: per-episode factor of the exponential decay (``"exponential"`` only)
    :param target_update_interval: bootstrap from a copy of q̂ (``policy.q_net_target``) moved towards q̂ every this
        many env steps (all envs together), by ``tau``; None bootstraps from q̂ itself, as the book does
    :param tau: the soft update coefficient of the copy ("Polyak update", between 0 and 1; 1 copies q̂)
    :param averaging_tau: the greedy policy of ``predict`` (and so of every evaluation) from a Polyak average of q̂'s
        weights, :math:`\bar{\mathbf w} \leftarrow \tau \mathbf w + (1 - \tau) \bar{\mathbf w}` after every update,
        with this τ (``policy.q_net_average``; weight averaging as in Nikishin et al. 2018, "Improving Stability in Deep
        Reinforcement Learning with Weight Averaging"); training and the ε-greedy behaviour policy are unchanged. None
        (the default, the book's): the greedy policy is q̂'s
    :param loss_function: ``"mse"`` (:math:`\tfrac12 (G - \hat q)^2`, the book's update) or ``"huber"`` (the same
        within 1 of the target, linear beyond)
    :param max_grad_norm: clip the gradient norm to this; None for no clipping
    :param lr_decay_factor: multiply the learning rate by this at each decay (1.0: no decay)
    :param lr_decay_every: decay every this many ``lr_decay_unit`` (like PyTorch's ``StepLR``)
    :param lr_decay_milestones: decay when the count of ``lr_decay_unit`` reaches each of these (like ``MultiStepLR``;
        the seed report's Acrobot setting decays at 300 and 500 episodes)
    :param lr_decay_unit: ``"episode"`` (completed episodes) or ``"update"`` (gradient steps, as ``train/n_updates``
        counts them)
    :param handle_timeout_termination: at a time-limit truncation, bootstrap from the final state (the time limit is
        not part of the task: SB3's choice, and the default); if False, the return ends there as at a termination
    :param stats_window_size: window size for the rollout logging, in episodes
    :param tensorboard_log: the log location for TensorBoard (if None, no logging)
    :param policy_kwargs: additional arguments to be passed to the policy on creation (see ``SARSAPolicy``:
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
        "LinearPolicy": LinearPolicy,
    }
    _network_arguments: ClassVar[dict[str, Callable[[Any], bool]]] = {
        "target_update_interval": lambda value: value is not None,
        "averaging_tau": lambda value: value is not None,
    }
    policy: SARSAPolicy
    action_space: spaces.Discrete
    exploration_schedule_fn: ExponentialDecay | Schedule

    def __init__(
        self,
        policy: str | type[SARSAPolicy],
        env: GymEnv | str,
        learning_rate: float | Schedule = 1e-3,
        n_steps: int = 3,
        train_freq: int = 16,
        gradient_steps: int = 8,
        update_mode: str = "batch",
        gamma: float = 0.99,
        expected_sarsa: bool = False,
        td_lambda: float = 1.0,
        exploration_schedule: str | Schedule = "exponential",
        exploration_initial_eps: float = DEFAULT_EXPLORATION_INITIAL_EPS,
        exploration_final_eps: float = DEFAULT_EXPLORATION_FINAL_EPS,
        exploration_fraction: float | None = None,
        exploration_decay_rate: float = DEFAULT_EXPLORATION_DECAY_RATE,
        target_update_interval: int | None = None,
        tau: float = 1.0,
        averaging_tau: float | None = None,
        loss_function: str = "mse",
        max_grad_norm: float | None = None,
        lr_decay_factor: float = 1.0,
        lr_decay_every: int | None = None,
        lr_decay_milestones: Sequence[int] | None = None,
        lr_decay_unit: str = "episode",
        handle_timeout_termination: bool = True,
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
            n_steps=n_steps,
            gamma=gamma,
            max_grad_norm=max_grad_norm,
            lr_decay_factor=lr_decay_factor,
            lr_decay_every=lr_decay_every,
            lr_decay_milestones=lr_decay_milestones,
            lr_decay_unit=lr_decay_unit,
            handle_timeout_termination=handle_timeout_termination,
            # SARSA holds at most n_steps + train_freq steps per env, however long the episodes
            max_episode_length=None,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            policy_kwargs=policy_kwargs,
            verbose=verbose,
            seed=seed,
            device=device,
            supported_action_spaces=(spaces.Discrete,),
            _init_setup_model=False,
        )
        self.train_freq = train_freq
        self.gradient_steps = gradient_steps
        self.update_mode = update_mode
        self.expected_sarsa = expected_sarsa
        self.td_lambda = td_lambda
        self.exploration_schedule = exploration_schedule
        self.exploration_initial_eps = exploration_initial_eps
        self.exploration_final_eps = exploration_final_eps
        self.exploration_fraction = exploration_fraction
        self.exploration_decay_rate = exploration_decay_rate
        self.target_update_interval = target_update_interval
        self.tau = tau
        self.averaging_tau = averaging_tau
        # Env steps at the last move of the bootstrap network towards q̂
        self._target_updated_at = 0
        self.loss_function = loss_function
        # ε of the ε-greedy behaviour policy (SB3's DQN name); follows exploration_schedule
        self.exploration_rate = exploration_initial_eps
        # q̂(S, ·) of the rollout loop's last step, the update count and the env steps when it was computed
        self._rollout_q_values = RolloutQValues(np.zeros(0), -1, -1)
        # The generator of the behaviour policy's draws (ε and ties); None: NumPy's global one, seeded by SB3
        self._action_rng: np.random.Generator | None = None
        if _init_setup_model:
            self._setup_model()  # (which checks the arguments first)

    def _unsupported_action_space_message(self, supported: tuple[type[spaces.Space], ...]) -> str:
        return (
            f"NStepSARSA needs a Discrete action space (q̂ has one output per action), not {self.action_space}: "
            "use REINFORCE for Box, MultiDiscrete or MultiBinary actions, or wrap the env to discretize its actions"
        )

    def _check_arguments(self) -> None:
        super()._check_arguments()
        check_arguments(self, ARGUMENT_RULES)

    def _initial_buffer_size(self) -> int:
        # At most n_steps transitions per env wait for their targets between updates
        return self.n_steps + self.train_freq

    def _setup_model(self) -> None:
        super()._setup_model()
        if callable(self.exploration_schedule):
            self.exploration_schedule_fn = self.exploration_schedule
        elif self.exploration_schedule == "exponential":
            self.exploration_schedule_fn = ExponentialDecay(
                self.exploration_initial_eps, self.exploration_final_eps, self.exploration_decay_rate
            )
        else:
            self.exploration_schedule_fn = LinearSchedule(
                self.exploration_initial_eps,
                self.exploration_final_eps,
                DEFAULT_EXPLORATION_FRACTION if self.exploration_fraction is None else self.exploration_fraction,
            )
        self._update_exploration_rate()

    def _make_policy(self) -> BasePolicy:
        self._refuse_policy_kwargs_set_here(target_network="target_update_interval", averaged_network="averaging_tau")
        target_network = self.target_update_interval is not None
        return self.policy_class(
            self.observation_space,
            self.action_space,
            self.lr_schedule,
            target_network=target_network,
            averaged_network=self.averaging_tau is not None,
            **self.policy_kwargs,
        )

    def _update_exploration_rate(self) -> None:
        if callable(self.exploration_schedule):
            # A schedule of the user's, read here so that one assigned after construction applies (SB3's DQN's idiom)
            epsilon = self.exploration_schedule(self._current_progress_remaining)
            if not 0.0 <= epsilon <= 1.0:
                raise ValueError(
                    f"exploration_schedule={self.exploration_schedule!r} gave ε = {epsilon!r} at progress remaining "
                    f"{self._current_progress_remaining:.3g}: ε is a probability, in [0, 1]"
                )
            self.exploration_rate = float(epsilon)
        elif isinstance(self.exploration_schedule_fn, ExponentialDecay):
            self.exploration_rate = self.exploration_schedule_fn(self._completed_episodes)
        else:
            self.exploration_rate = self.exploration_schedule_fn(self._current_progress_remaining)

    def _on_episodes_end(self, n_episodes: int) -> None:
        super()._on_episodes_end(n_episodes)
        self._update_exploration_rate()

    def _epsilon_greedy(
        self, greedy_actions: np.ndarray, first_action: int = 0, action_masks: np.ndarray | None = None
    ) -> np.ndarray:
        """
        :param greedy_actions: the greedy actions, one per observation
        :param first_action: the value of the first action (0 for indices, the space's ``start`` for env values)
        :param action_masks: the legal actions of each observation, shape (batch, n_actions); None: all legal
        :return: ε-greedy actions: with probability ε an action drawn uniformly from all (legal) actions (S&B §2.2),
            for each observation independently
        """
        rng, shape, stop = self._action_rng, greedy_actions.shape, first_action + self.action_space.n
        if shape == (1,) and action_masks is None:
            # One env (the book's loop, at every env step): scalar draws, the same numbers from the generator as arrays
            # of one, at a third of their cost
            if (np.random.random() if rng is None else rng.random()) >= self.exploration_rate:
                return greedy_actions
            uniform_action = np.random.randint(first_action, stop) if rng is None else rng.integers(first_action, stop)
            return np.full(1, uniform_action, dtype=np.result_type(greedy_actions, np.int64))
        explore = (np.random.random(shape) if rng is None else rng.random(shape)) < self.exploration_rate
        if not explore.any():
            return greedy_actions
        if action_masks is not None:
            return np.where(explore, first_action + uniform_legal_actions(action_masks, rng), greedy_actions)
        uniform = np.random.randint(first_action, stop, size=shape) if rng is None else rng.integers(first_action, stop, shape)
        return np.where(explore, uniform, greedy_actions)

    def _sample_actions(
        self,
        obs: np.ndarray | dict[str, np.ndarray],
        action_masks: np.ndarray | None = None,
        behaviour: np.ndarray | None = None,
    ) -> np.ndarray:
        if action_masks is not None:
            # argmax over the legal actions: the illegal ones at −∞ (a policy's own _predict is not asked: the env's
            # masks say what is legal)
            q_masked = np.where(action_masks, self._behaviour_q_values(obs, behaviour), -np.inf)
            return self._epsilon_greedy(greedy_random_ties(q_masked, self._action_rng), action_masks=action_masks)
        if self.policy.own_predict:
            # A subclass's greedy policy (action masking, say), as SB3's DQN's ε-greedy takes its policy's predict
            greedy = self.policy._predict(obs_as_tensor(obs, self.device), deterministic=False)
            return self._epsilon_greedy(greedy.cpu().numpy().reshape(-1))
        return self._epsilon_greedy(greedy_random_ties(self._behaviour_q_values(obs, behaviour), self._action_rng))

    def _behaviour_q_values(self, obs: np.ndarray | dict[str, np.ndarray], q_values: np.ndarray | None) -> np.ndarray:
        """
        :param obs: the current observations of all envs
        :param q_values: q̂(S, ·) of them computed outside the model (a population's stacked forward pass), or None
        :return: q̂(S, ·) of them, shape (n_envs, n_actions): ``q_values``, else q̂'s forward pass; kept in the
            per-step mode for the bootstrap of the next update, if no update comes in between (see ``_values_at``)
        """
        if q_values is None:
            q_values = self.policy.q_values(obs)
        if self.update_mode == "per_step":
            self._rollout_q_values = RolloutQValues(q_values, self._n_updates, self.num_timesteps)
        return q_values

    def _rollout_complete(self, n_steps: int, n_episodes: int) -> bool:
        return n_steps >= self.train_freq

    def predict(
        self,
        observation: np.ndarray | dict[str, np.ndarray],
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
        action_masks: np.ndarray | None = None,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """
        The greedy action (``deterministic=True``: the first of tied ones), or the ε-greedy one with the current
        ``exploration_rate``, whose greedy action breaks ties at random as the behaviour policy does; as the env takes
        it (an index plus the ``start`` of a ``Discrete(n, start=...)`` space). Greedy in the weight average
        ``policy.q_net_average`` with ``averaging_tau``, else in q̂. With ``action_masks`` (sb3-contrib's MaskablePPO's
        argument), greedy and ε-greedy over the legal actions.

        :param observation: the input observation (one, or a batch)
        :param state: unused (no recurrent policy)
        :param episode_start: unused (no recurrent policy)
        :param deterministic: greedy if True, ε-greedy otherwise
        :param action_masks: the legal actions of each observation, shape (batch, n_actions) or (n_actions,) for one
            (sb3-contrib's ``get_action_masks(env)``); None: every action is legal
        :return: the actions, and the unchanged state
        """
        # In the env's action values (the space's start added), as the ε-greedy draw
        actions, state = self.policy.predict(observation, state, episode_start, deterministic, action_masks=action_masks)
        if deterministic:
            return actions, state
        if action_masks is None:
            return self._epsilon_greedy(actions, int(self.action_space.start)), state
        masks = np.asarray(action_masks, dtype=bool).reshape(-1, int(self.action_space.n))
        explored = self._epsilon_greedy(np.reshape(actions, -1), int(self.action_space.start), masks)
        return explored.reshape(np.shape(actions)), state

    def _training_batch(self) -> TrainingBatch | None:
        """
        :return: every transition not trained on yet whose target G_{t:t+n} is known, with that target, in time order
            (None if there is none yet)
        """
        buffer = self.rollout_buffer
        pos = buffer.pos
        windows = completed_windows(buffer.rewards[:pos], buffer.dones[:pos], buffer.start, self.gamma, self.n_steps)
        if len(windows.rows) == 0:
            return None
        # λ-returns need the value after every step of each window: of every stored step, from one forward pass
        step_values = self._stored_values() if self.td_lambda < 1.0 and self.n_steps > 1 else None
        bootstrap = self._window_bootstrap_values(windows, step_values)
        targets = sarsa_targets(windows, bootstrap, buffer.rewards[:pos], step_values, self.gamma, self.td_lambda)
        rows, envs = windows.rows, windows.envs
        return TrainingBatch(
            observations=select(buffer.observations, (rows, envs)),
            actions=buffer.actions[rows, envs],
            targets=targets,
            episode_steps=buffer.episode_steps[rows, envs],
            n_trained=np.bincount(envs, minlength=self.n_envs),
        )

    def _window_bootstrap_values(self, windows: CompletedWindows, step_values: np.ndarray | None) -> np.ndarray:
        """
        Semi-gradient: the values come from the bootstrap network's current weights, without gradient, and only where
        a target needs one.

        :param windows: the windows of an update's transitions
        :param step_values: ``_stored_values()``, if computed already (λ-returns)
        :return: the value each window bootstraps from after its last reward (S&B eq. 10.4), shape (B,), float32: that
            of the next step while the episode goes on (``_values_at``), none after a termination (0), the ε-greedy
            expectation of q̂ in the final state after a time-limit truncation
        """
        buffer = self.rollout_buffer
        envs, stop_rows = windows.envs, windows.stop_rows
        ended = buffer.dones[stop_rows, envs]
        if not np.count_nonzero(ended):  # (every episode goes on: all but the updates at an episode's end)
            return self._values_at(stop_rows + 1, envs, step_values)
        bootstrap = np.zeros(len(stop_rows), dtype=np.float32)
        continuing = ~ended
        if continuing.any():
            bootstrap[continuing] = self._values_at(stop_rows[continuing] + 1, envs[continuing], step_values)
        truncated = buffer.truncated[stop_rows, envs]
        if truncated.any():
            # Every truncation in the buffer in one forward pass, as the rollout stored them (a batch of other rows
            # could round q̂ differently in the last bit: seeded runs would not repeat)
            truncations = buffer.truncated[: buffer.pos]
            final_obs = select(select(buffer.final_observations, slice(0, buffer.pos)), truncations)
            final_values = np.zeros(truncations.shape, dtype=np.float32)
            final_q = self._bootstrap_q_values(final_obs)
            if buffer.final_action_masks is None:
                final_values[truncations] = epsilon_greedy_expectation(final_q, self.exploration_rate)
            else:
                # Under the masked ε-greedy policy of the final state (its env's info["action_mask"], else all legal)
                final_masks = buffer.final_action_masks[: buffer.pos][truncations]
                final_values[truncations] = masked_epsilon_greedy_expectation(final_q, final_masks, self.exploration_rate)
            bootstrap[truncated] = final_values[stop_rows[truncated], envs[truncated]]
        return bootstrap

    def _values_at(self, rows: np.ndarray, envs: np.ndarray, step_values: np.ndarray | None) -> np.ndarray:
        """
        :param rows: the buffer rows to bootstrap from
        :param envs: their envs
        :param step_values: ``_stored_values()``, if computed already
        :return: ``_action_values`` there, float32: from the rollout's forward pass of the last step's states when it
            holds them with the weights of now (the per-step mode's every bootstrap with ``train_freq=1``, which then
            needs no forward pass of its own), else from ``_stored_values``
        """
        if step_values is not None:
            return step_values[rows, envs]
        last = self._rollout_q_values
        if (
            last.n_updates == self._n_updates
            and last.num_timesteps + self.n_envs == self.num_timesteps
            and int(rows[0]) == self.rollout_buffer.pos - 1  # (rows in time order: all of them the last step's)
            and self.update_mode == "per_step"  # (the batch mode's values are those of one pass over every stored step)
            and self.policy.q_net_target is None
        ):
            masks = self.rollout_buffer.action_masks
            return self._action_values(
                last.q_values, envs, self.rollout_buffer.actions[rows, envs], None if masks is None else masks[rows, envs]
            )
        return self._stored_values()[rows, envs]

    def _stored_values(self) -> np.ndarray:
        """
        :return: ``_action_values`` of every stored step, with the bootstrap network, shape (n_steps_stored, n_envs),
            float32. One forward pass over the whole buffer, whatever rows are needed, so that a seeded run repeats to
            the last bit
        """
        data = self.rollout_buffer.get()
        n_rows, n_envs = data.rewards.shape
        q_values = self._bootstrap_q_values(select(data.observations, np.ones((n_rows, n_envs), dtype=bool)))
        masks = None if data.action_masks is None else data.action_masks.reshape(n_rows * n_envs, -1)
        rows = np.arange(len(q_values))
        return self._action_values(q_values, rows, data.actions.reshape(-1), masks).reshape(n_rows, n_envs)

    def _bootstrap_q_values(self, observations: np.ndarray | dict[str, np.ndarray]) -> np.ndarray:
        """:return: q̂(S, ·) of a batch of observations from the bootstrap network, shape (B, n_actions), no gradient"""
        with th.no_grad():
            return self.policy.bootstrap_net(obs_as_tensor(observations, self.device)).cpu().numpy()

    def _action_values(
        self, q_values: np.ndarray, rows: np.ndarray, actions: np.ndarray, action_masks: np.ndarray | None = None
    ) -> np.ndarray:
        """
        :param q_values: q̂(S, ·) of states, shape (N, n_actions)
        :param rows: the states to bootstrap from, indices into ``q_values``, shape (B,)
        :param actions: the actions taken there, shape (B,)
        :param action_masks: the legal actions there, shape (B, n_actions), if masking is on
        :return: q̂(S, A) of the action taken (SARSA; a legal one), or Σ_a π(a|S) q̂(S, a) (Expected SARSA, S&B
            eq. 7.8, under the ε-greedy policy over the legal actions), float32, shape (B,)
        """
        if self.expected_sarsa and action_masks is not None:
            expectation = masked_epsilon_greedy_expectation(q_values[rows], action_masks, self.exploration_rate)
            return expectation.astype(np.float32)
        if self.expected_sarsa:
            return epsilon_greedy_expectation(q_values[rows], self.exploration_rate).astype(np.float32)
        return q_values[rows, actions].astype(np.float32, copy=False)

    def train(self) -> None:
        """Update q̂ towards the n-step targets of every transition whose target is known and not trained on yet."""
        run_update(self._update(), self._gradient_step)

    def _update(self) -> Update:
        """
        The update of ``train``, its gradient steps made by the caller: it yields the transitions of each gradient step,
        (S_t, A_t, G_{t:t+n}, t) (S&B eq. 10.4), and is sent back what the step gave (``_gradient_step``'s q̂(S_t, A_t)
        before the step and loss). ``train`` makes them with ``_gradient_step``; a population with its stacked step.
        """
        self._update_learning_rates([(self.policy.optimizer, self.lr_schedule, "train/learning_rate")])
        self._update_exploration_rate()
        self.logger.record("rollout/exploration_rate", self.exploration_rate)
        # The targets' bootstrap values are no training batch: evaluation mode (dropout off, BatchNorm's running
        # statistics unmoved), as SB3's DQN computes its targets; training mode for the gradient steps only
        self.policy.set_training_mode(False)
        batch = self._training_batch()
        self.policy.set_training_mode(True)
        if batch is None:
            return

        # Batch: gradient steps on the mean loss of all; per step: each transition's own update, in time order
        chunks = self._update_slices(len(batch.targets))
        q_first: list[np.ndarray] = []  # q̂(S_t, A_t) before the update's first pass, for the log
        losses: list[float] = []  # every gradient step's, for the log's mean (SB3's DQN logs the mean)
        for gradient_step in range(self.gradient_steps):
            for chunk in chunks:
                q_predicted, loss = yield batch.step_arguments(chunk)
                losses.append(loss)
                if gradient_step == 0:
                    q_first.append(q_predicted)

        self.rollout_buffer.mark_trained(batch.n_trained)
        self._move_copies()
        self._n_updates += self.gradient_steps * len(chunks)
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        # (the mean of float32 losses in float32, as th.stack(losses).mean() of SB3's DQN)
        self.logger.record("train/loss", losses[0] if len(losses) == 1 else th.tensor(losses).mean().item())
        q_predicted = q_first[0] if len(q_first) == 1 else np.concatenate(q_first)
        self.logger.record("train/q_mean", math.fsum(q_predicted.tolist()) / len(batch.targets))
        self.logger.record("train/target_mean", math.fsum(batch.targets.tolist()) / len(batch.targets))
        self.logger.record("train/n_transitions", len(batch.targets))

    def _gradient_step(
        self, observations: Observations, actions: np.ndarray, targets: np.ndarray, episode_steps: np.ndarray
    ) -> tuple[np.ndarray, float]:
        """
        One gradient step of q̂ on the mean loss of the given transitions: ``LinearQPolicy``'s own SGD step, autograd and
        the policy's optimizer, or with ``ObGD`` one transition's step of SARSA(λ) along its traces (``td_step``).

        :param observations: S_t, a batch of B
        :param actions: A_t as indices, shape (B,)
        :param targets: G_{t:t+n}, shape (B,), float32
        :param episode_steps: t, the step of each S_t within its episode, shape (B,)
        :return: q̂(S_t, A_t) before the step, shape (B,), float32, and the loss
        """
        if isinstance(self.policy, LinearQPolicy):
            return self.policy.sgd_step(observations, actions, targets)
        index = th.as_tensor(actions, device=self.device).reshape(-1, 1)
        q_predicted = self.policy.q_net(obs_as_tensor(observations, self.device)).gather(1, index).flatten()
        target = th.as_tensor(targets, device=self.device)
        if isinstance(self.policy.optimizer, ObGD):  # SARSA(λ): td_lambda's backward view, with traces (S&B §12.7)
            return td_step(self.policy.optimizer, q_predicted, target, self.gamma * self.td_lambda, episode_steps[0] == 0)
        # (a model alone is a member axis of one)
        loss = sarsa_losses(q_predicted.unsqueeze(0), target.unsqueeze(0), self.loss_function == "huber").squeeze(0)
        self.policy.optimizer.zero_grad()
        loss.backward()
        self._clip_gradients(self.policy.q_net.parameters())
        self.policy.optimizer.step()
        return q_predicted.detach().cpu().numpy(), loss.item()

    def _move_copies(self) -> None:
        """
        After an update, the copies of q̂ move towards it (neither is in the book): the bootstrap network,
        w⁻ ← τw + (1 − τ)w⁻ every ``target_update_interval`` env steps (SB3's DQN), and the greedy policy's average,
        w̄ ← τw + (1 − τ)w̄ with τ = ``averaging_tau`` after every update.
        """
        target, average = self.policy.q_net_target, self.policy.q_net_average
        if target is not None and self.num_timesteps - self._target_updated_at >= (self.target_update_interval or 0):
            self.policy.polyak_update(target, self.tau)
            self._target_updated_at = self.num_timesteps
        if average is not None and self.averaging_tau is not None:
            self.policy.polyak_update(average, self.averaging_tau)

    def _on_learn_start(self) -> None:
        if isinstance(self.policy, LinearQPolicy):
            self.policy.check_layers()
        # num_timesteps may have been reset: the bootstrap network's next copy counts from here
        self._target_updated_at = min(self._target_updated_at, self.num_timesteps)
        # A linear ε restarts with this learn() call from its first step (SB3's DQN), not after the first rollout
        self._update_exploration_rate()

    def _log_interval_choices(self) -> str:
        return ', "auto" (every 128 env steps per env)'

    def _excluded_save_params(self) -> list[str]:
        # Caches of the rollout loop's forward passes, and a population's generator (it is the population's): not training
        # state
        return [*super()._excluded_save_params(), "_rollout_q_values", "_action_rng"]

    def learn(
        self: SelfNStepSARSA,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int | Literal["auto"] | None = "auto",
        tb_log_name: str = "NStepSARSA",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
        use_masking: bool = True,
    ) -> SelfNStepSARSA:
        """
        Train for ``total_timesteps`` env steps (rounded up to whole rollouts).

        :param total_timesteps: env steps to train for, all envs together
        :param callback: callback(s) called at every step with the state of the algorithm
        :param log_interval: updates between two logger dumps; ``"auto"`` (the default): every 128 env steps per env,
            ⌈128 / ``train_freq``⌉ updates (8 with the default ``train_freq=16``: a curve in TensorBoard from the first
            thousand steps on; 128 in the book's per-step mode, ``train_freq=1``, which would otherwise write a table
            every few env steps); None: no dumps. Whatever was recorded since the last dump is dumped when
            ``learn()`` returns
        :param tb_log_name: the name of the run for TensorBoard logging
        :param reset_num_timesteps: whether to reset ``num_timesteps`` (and the envs); the exponential ε decay and the
            learning-rate decay counts keep going either way; a linear ε decay follows this call's progress, as in
            SB3's DQN: from ``exploration_initial_eps`` again if True, from where the steps so far put it if False
        :param progress_bar: display a progress bar using tqdm and rich
        :param use_masking: use the env's invalid-action masks if it has them (``action_masks()``, sb3-contrib's
            ``ActionMasker``), as MaskablePPO does; an env without them trains unmasked
        :return: the trained model
        """
        if log_interval == "auto":
            log_interval = -(-LOG_EVERY_STEPS // self.train_freq)
        return super().learn(
            total_timesteps=total_timesteps,
            callback=callback,
            log_interval=log_interval,  # type: ignore[arg-type]
            tb_log_name=tb_log_name,
            reset_num_timesteps=reset_num_timesteps,
            progress_bar=progress_bar,
            use_masking=use_masking,
        )
