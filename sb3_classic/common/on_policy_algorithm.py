"""The base class of sb3_classic's algorithms: SB3's on-policy loop around a buffer that keeps whole trajectories."""

import math
import warnings
from abc import abstractmethod
from collections.abc import Callable, Generator, Sequence
from typing import Any, TypeVar

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule
from stable_baselines3.common.utils import check_for_correct_spaces, update_learning_rate
from stable_baselines3.common.vec_env import VecEnv

from sb3_classic.common.arguments import (
    BASE_ARGUMENT_RULES,
    check_arguments,
    check_keywords,
    check_policy_class,
    check_policy_kwargs,
    refuse_policy_kwargs_set_here,
    set_n_envs,
)
from sb3_classic.common.buffers import Observations, TrajectoryBuffer, all_finite, select
from sb3_classic.common.env_checks import (
    check_final_observation,
    raise_non_finite,
    warn_episodes_cut,
    warn_truncation_without_final_observation,
)
from sb3_classic.common.masking import (
    check_action_masks,
    check_some_action_legal,
    get_action_masks,
    is_masking_supported,
    mask_segments,
)
from sb3_classic.common.policies import action_offset
from sb3_classic.common.save_util import SafeSaveLoadMixin, env_id, episodes_not_continued, other_env_message
from sb3_classic.common.schedules import StepDecay
from sb3_classic.common.utils import check_bool, check_positive_int, check_total_timesteps

SelfClassicOnPolicyAlgorithm = TypeVar("SelfClassicOnPolicyAlgorithm", bound="ClassicOnPolicyAlgorithm")

#: An algorithm's update (its ``_update``), read top to bottom, whose gradient steps its caller makes: it yields the
#: arguments of each gradient step and is sent back what the step returned (``run_update`` with the model's own
#: ``_gradient_step``, or a population's stacked step for all its members at once)
Update = Generator[tuple[Any, ...], Any, None]


def run_update(update: Update, gradient_step: Callable[..., Any]) -> None:
    """
    Make the gradient steps of ``update`` one after the other with ``gradient_step``, until the update ends.

    :param update: an algorithm's ``_update()``
    :param gradient_step: its ``_gradient_step``
    """
    arguments = next(update, None)
    while arguments is not None:
        try:
            arguments = update.send(gradient_step(*arguments))
        except StopIteration:
            return


class ClassicOnPolicyAlgorithm(SafeSaveLoadMixin, OnPolicyAlgorithm):
    """
    Base of REINFORCE and n-step SARSA. What they share:

    - a ``TrajectoryBuffer`` that keeps each transition until its target is known, so an episode (REINFORCE) or an
      n-step window (SARSA) may span several rollouts and envs may end their episodes at different times;
    - the rollout loop, which stops when the algorithm says its update has what it needs
      (``_rollout_complete``); the time-limit bootstrap; an optional cap on episode length;
    - learning rates given as SB3 schedules (of the training progress) times a step decay (of the completed
      episodes or updates, like PyTorch's ``StepLR``), and that training state kept across ``learn()``
      calls and ``save``/``load``;
    - ``set_env`` with another number of envs;
    - invalid-action masking through sb3-contrib's interface (``learn(use_masking=...)``, see ``_setup_masking``):
      the masks of each S_t travel with it in the buffer, and the final state of a time-limit truncation takes the
      mask its env reports in ``info["action_mask"]`` (the VecEnv has reset the env when the masks are next read, so
      ``action_masks()`` then gives the next episode's), or allows every action if it reports none;
    - ``save``, ``load`` and ``set_parameters`` that leave no file or model half-changed (``SafeSaveLoadMixin``).

    :param policy: the policy model to use (``"MlpPolicy"``, ``"CnnPolicy"``, ``"MultiInputPolicy"`` or a class)
    :param env: the environment to learn from (if registered in Gymnasium, can be str)
    :param learning_rate: learning rate (a float or an SB3 schedule of the remaining progress)
    :param n_steps: passed to ``OnPolicyAlgorithm``; its meaning is the subclass's
    :param gamma: discount factor γ
    :param max_grad_norm: gradient-norm clipping threshold; ``None`` for no clipping
    :param lr_decay_factor: multiply the learning rate(s) by this at each decay (1.0: no decay)
    :param lr_decay_every: decay every this many ``lr_decay_unit`` (like PyTorch's ``StepLR(step_size=...)``)
    :param lr_decay_milestones: decay when the count of ``lr_decay_unit`` reaches each of these instead
        (like ``MultiStepLR``)
    :param lr_decay_unit: what the decay counts: ``"episode"`` (completed episodes, all envs together)
        or ``"update"`` (gradient steps, as SB3's ``train/n_updates`` counts them: a SARSA update of ``gradient_steps``
        steps counts ``gradient_steps``). The rate is set at the start of each update (``train()``, as SB3 sets its
        learning rates) from the count so far: every gradient step of one update uses the same rate, and the decays
        whose boundaries an update's steps pass apply together at the next update (REINFORCE's per-step mode: an
        episode's T updates are one ``train()``)
    :param handle_timeout_termination: bootstrap from the value of the final state when an episode is cut by a time
        limit (``TimeLimit.truncated``), treating the limit as not part of the task (SB3's default); if False,
        a truncation ends the return like a termination
    :param max_episode_length: cut any episode that reaches this many steps for training (with a warning), so an env
        that never ends cannot grow the buffer without bound: its return ends there, bootstrapped as at a time limit;
        the env is not reset (a VecEnv resets an env only when it ends), so the next episode trained on starts from
        the state reached, and the Monitor and callbacks do not count the cut; ``None`` for no cap
    :param stats_window_size: window size for the rollout logging, in episodes
    :param tensorboard_log: the log location for TensorBoard (if None, no logging)
    :param policy_kwargs: additional arguments to be passed to the policy on creation
    :param verbose: verbosity level: 0 no output, 1 info, 2 debug
    :param seed: seed for the pseudo random generators
    :param device: device (cpu, cuda, ...) on which the code should be run
    :param supported_action_spaces: the action spaces the subclass supports
    :param _init_setup_model: whether or not to build the network at the creation of the instance
    """

    rollout_buffer: TrajectoryBuffer  # type: ignore[assignment]
    policy: BasePolicy  # type: ignore[assignment]
    lr_decay: StepDecay
    #: ``"batch"`` or ``"per_step"``: how an update applies its transitions (set by each algorithm)
    update_mode: str

    def __new__(cls, *args: Any, **kwargs: Any) -> Any:
        # A misspelt argument (n_step=5) gets the closest one (n_steps), in Python and through rl-zoo3's -params
        # (and REINFORCE's argument given to NStepSARSA, or the other way round, says so)
        check_keywords(cls, kwargs, ClassicOnPolicyAlgorithm)
        return super().__new__(cls)

    def __init__(
        self,
        policy: str | type[BasePolicy],
        env: GymEnv | str,
        learning_rate: float | Schedule,
        n_steps: int,
        gamma: float,
        max_grad_norm: float | None,
        lr_decay_factor: float,
        lr_decay_every: int | None,
        lr_decay_milestones: Sequence[int] | None,
        lr_decay_unit: str,
        handle_timeout_termination: bool,
        max_episode_length: int | None,
        stats_window_size: int,
        tensorboard_log: str | None,
        policy_kwargs: dict[str, Any] | None,
        verbose: int,
        seed: int | None,
        device: th.device | str,
        supported_action_spaces: tuple[type[spaces.Space], ...],
        _init_setup_model: bool,
    ):
        super().__init__(
            policy,  # type: ignore[arg-type]
            env,
            learning_rate=learning_rate,
            n_steps=n_steps,
            gamma=gamma,
            # Unused: returns are Monte-Carlo (REINFORCE) or n-step (SARSA), not GAE
            gae_lambda=1.0,
            # Set by REINFORCE; a Q-network has no policy entropy
            ent_coef=0.0,
            # Unused: REINFORCE's value network has its own optimizer and learning rate, SARSA has no value network
            vf_coef=0.0,
            max_grad_norm=math.inf if max_grad_norm is None else max_grad_norm,
            # gSDE is for continuous actions of actor-critic methods
            use_sde=False,
            sde_sample_freq=-1,
            # Unused: the algorithms build their own TrajectoryBuffer
            rollout_buffer_class=None,
            rollout_buffer_kwargs=None,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            policy_kwargs=policy_kwargs,
            verbose=verbose,
            seed=seed,
            device=device,
            _init_setup_model=False,
            # Checked below with an error that says what to do (SB3 asserts)
            supported_action_spaces=None,
        )
        self.lr_decay_factor = lr_decay_factor
        self.lr_decay_every = lr_decay_every
        self.lr_decay_milestones = lr_decay_milestones
        self.lr_decay_unit = lr_decay_unit
        self.handle_timeout_termination = handle_timeout_termination
        self.max_episode_length = max_episode_length
        # Training state the count-driven schedules follow; unlike num_timesteps, learn() never resets it
        self._completed_episodes = 0
        # The episodes completed before the current rollout: an update's learning-rate decay counts those, as PyTorch's
        # StepLR does when stepped after each episode's updates (the episodes ending in the rollout decay the next one)
        self._episodes_before_rollout = 0
        # Whether the rollouts read the envs' action masks: decided by each learn() call
        self._use_masking = False
        if self.env is not None and not isinstance(self.action_space, supported_action_spaces):
            raise ValueError(self._unsupported_action_space_message(supported_action_spaces))

    def _unsupported_action_space_message(self, supported: tuple[type[spaces.Space], ...]) -> str:
        names = ", ".join(space.__name__ for space in supported)
        return f"{type(self).__name__} supports {names} action spaces, not {self.action_space}"

    def _check_arguments(self) -> None:
        """
        Raise a ValueError naming the argument for anything invalid (the rules of ``BASE_ARGUMENT_RULES``); subclasses
        extend it. ``_setup_model`` calls it, so that ``load(..., **kwargs)`` (rl-zoo3's ``-i``) checks what it changes
        as the constructor does; a learning rate of 0 is accepted there (rl-zoo3's ``enjoy`` loads with
        ``learning_rate=0.0``, as SB3 allows).
        """
        check_arguments(self, BASE_ARGUMENT_RULES)

    @abstractmethod
    def _make_policy(self) -> BasePolicy:
        """Build the policy (networks and optimizers) for the current spaces and arguments."""

    def _initial_buffer_size(self) -> int:
        """:return: the buffer's initial capacity in steps per env (it grows when needed)"""
        return 1024

    def _setup_model(self) -> None:
        # First: with a file saved by another algorithm (load() takes its policy class), the argument checks would fail
        # on the first of that algorithm's values this one reads differently (DQN's train_freq tuple, say), misleadingly
        check_policy_class(type(self).__name__, self.policy_class, self.policy_aliases)
        if self.max_grad_norm is None:
            # No clipping, as the constructor stores it (load(..., max_grad_norm=None) sets None: rl-zoo3's -i)
            self.max_grad_norm = math.inf
        self._check_arguments()
        self._setup_lr_schedule()
        self.lr_decay = StepDecay(self.lr_decay_factor, self.lr_decay_every, self.lr_decay_milestones)
        # The env's value of action index 0 (Discrete/MultiDiscrete `start`), added to what the envs are sent
        self._action_offset = action_offset(self.action_space)
        self.set_random_seed(self.seed)
        self._make_buffer()
        check_policy_kwargs(type(self).__name__, self.policy_class, self.policy_kwargs)
        self.policy = self._make_policy().to(self.device)

    def _refuse_policy_kwargs_set_here(self, **arguments: str) -> None:
        """
        :param arguments: the policy's arguments that ``_make_policy`` sets itself, each with the argument of the
            algorithm that sets it
        :raises TypeError: if ``policy_kwargs`` gives one of them (Python's "got multiple values" otherwise), naming
            the algorithm's argument to pass instead
        """
        refuse_policy_kwargs_set_here(type(self).__name__, self.policy_kwargs, arguments)

    def _make_buffer(self) -> None:
        self.rollout_buffer = TrajectoryBuffer(
            self._initial_buffer_size(), self.observation_space, self.action_space, device=self.device, n_envs=self.n_envs
        )
        # Reused when no env is truncated (the common case of the per-step loop)
        self._no_truncation = np.zeros(self.n_envs, dtype=bool)

    def _update_current_progress_remaining(self, num_timesteps: int, total_timesteps: int) -> None:
        """
        SB3's remaining progress (1 at the start of ``learn()``, 0 at ``total_timesteps``), clamped to [0, 1]: a rollout
        can end past ``total_timesteps`` (REINFORCE waits for its episodes to end, SARSA collects ``train_freq`` steps
        of every env), and a schedule must never be evaluated outside its range (``lin_`` would give a negative
        learning rate).

        :param num_timesteps: env steps taken so far
        :param total_timesteps: env steps of this ``learn()`` call (``learn(0)``: 0, nothing to do, all of it remaining)
        """
        if total_timesteps <= 0:
            self._current_progress_remaining = 1.0
            return
        self._current_progress_remaining = min(1.0, max(0.0, 1.0 - float(num_timesteps) / float(total_timesteps)))

    def _lr_decay_count(self) -> int:
        # (a state that holds only _completed_episodes counts those)
        episodes = getattr(self, "_episodes_before_rollout", self._completed_episodes)
        return episodes if self.lr_decay_unit == "episode" else self._n_updates

    def _update_learning_rates(self, schedules: Sequence[tuple[th.optim.Optimizer, Schedule, str]]) -> None:
        """
        Set each optimizer's learning rate to its schedule's value at the current progress, times the step decay,
        and log it.

        :param schedules: (optimizer, learning-rate schedule, logger key) triples
        """
        decay = self.lr_decay(self._lr_decay_count())
        for optimizer, schedule, key in schedules:
            learning_rate = schedule(self._current_progress_remaining) * decay
            update_learning_rate(optimizer, learning_rate)
            self.logger.record(key, learning_rate)

    def _update_slices(self, n_transitions: int) -> list[slice]:
        """
        :param n_transitions: the transitions of an update, in time order
        :return: what each gradient step of the update takes: all of them at once (``update_mode="batch"``: one step on
            their mean), or one at a time in time order (``"per_step"``: the book's updates, each with the full step size)
        """
        if self.update_mode == "batch":
            return [slice(None)]
        return [slice(index, index + 1) for index in range(n_transitions)]

    def _clip_gradients(self, parameters: Any) -> None:
        # None (e.g. passed to load()) means no clipping, as inf does
        if self.max_grad_norm is not None and math.isfinite(self.max_grad_norm):
            th.nn.utils.clip_grad_norm_(parameters, self.max_grad_norm)

    @abstractmethod
    def _sample_actions(
        self, obs: np.ndarray | dict[str, np.ndarray], action_masks: np.ndarray | None = None, behaviour: Any = None
    ) -> np.ndarray:
        """
        The behaviour policy of the per-step loop: one action per env, as a NumPy array the env accepts. Called
        without gradient (``th.no_grad``).

        :param obs: the current observations of all envs, as the VecEnv returned them
        :param action_masks: their action masks, shape (n_envs, mask_size), boolean, each allowing some action;
            None when masking is off
        :param behaviour: what the behaviour policy's forward pass gives for ``obs``, computed outside the model (a
            population's stacked pass: NStepSARSA's q̂(S, ·), REINFORCE's logits and their soft-max); None: the
            model's own forward pass
        """

    def _read_action_masks(self, env: VecEnv) -> np.ndarray:
        """
        :param env: the training environment
        :return: the masks of the envs' current observations (sb3-contrib's ``get_action_masks``), shape
            (n_envs, mask_size), boolean
        :raises ValueError: if they have another shape, or one allows no action (naming the env and the step)
        """
        masks = check_action_masks(get_action_masks(env), env.num_envs, self.action_space, "action_masks()")
        check_some_action_legal(masks, self.action_space, self.rollout_buffer.episode_length)
        return masks

    def _final_action_masks(self, infos: list[dict[str, Any]], final_observations: dict[int, Any]) -> dict[int, np.ndarray]:
        """
        :param infos: the step's infos
        :param final_observations: the final observations bootstrapped from, by env
        :return: the masks of those final states that their envs report in ``info["action_mask"]``, by env (the
            others allow every action)
        :raises ValueError: if one has the wrong shape or allows no action
        """
        masks: dict[int, np.ndarray] = {}
        for idx in final_observations:
            if infos[idx].get("action_mask") is not None:
                name = f'info["action_mask"] of env {idx}'
                mask = check_action_masks(infos[idx]["action_mask"], 1, self.action_space, name)
                where = f"the final state of its episode (step {int(self.rollout_buffer.episode_length[idx]) + 1})"
                check_some_action_legal(mask, self.action_space, np.zeros(1, dtype=np.int64), where)
                masks[idx] = mask[0]
        return masks

    @abstractmethod
    def _rollout_complete(self, n_steps: int, n_episodes: int) -> bool:
        """
        Whether the next update has what it needs.

        :param n_steps: steps taken per env in this rollout
        :param n_episodes: episodes that ended in this rollout (all envs together)
        """

    def _on_episodes_end(self, n_episodes: int) -> None:
        """
        Called after each step in which episodes ended.

        :param n_episodes: how many ended (all envs together)
        """
        self._completed_episodes += n_episodes

    def _episode_ends(
        self, new_obs: Observations, dones: np.ndarray, infos: list[dict[str, Any]]
    ) -> tuple[np.ndarray, np.ndarray, dict[int, Any]]:
        """
        :return: which episodes ended with this step, which of those to bootstrap from (time-limit truncations,
            and episodes cut at ``max_episode_length``), and the final observations to bootstrap from, by env
        :raises ValueError: if a final observation bootstrapped from (a truncation's) holds NaN or ±inf, or has another
            shape than the observation space's
        """
        ends, truncated = dones, self._no_truncation
        final_observations: dict[int, Any] = {}
        if self.handle_timeout_termination and dones.any():
            truncated = np.zeros_like(dones)
            for idx in np.flatnonzero(dones):
                # The VecEnv sets TimeLimit.truncated = truncated and not terminated
                if not infos[idx].get("TimeLimit.truncated", False):
                    continue  # a termination: nothing is bootstrapped from its final observation
                final_obs = infos[idx].get("terminal_observation")
                if final_obs is None:
                    warn_truncation_without_final_observation(self, int(idx))
                    continue
                # Bootstrapped from: checked as the observations are (A2C refuses a wrong shape in predict)
                check_final_observation(self, self.rollout_buffer.episode_length, final_obs, int(idx))
                truncated[idx] = True
                final_observations[int(idx)] = final_obs
        episode_length = self.rollout_buffer.episode_length
        # (the longest episode first: one reduction at every env step, REINFORCE's cap of 100,000 steps seldom reached)
        if self.max_episode_length is not None and int(episode_length.max()) + 1 >= self.max_episode_length:
            overlong = ~dones & (episode_length + 1 >= self.max_episode_length)
            if overlong.any():
                warn_episodes_cut(self, np.flatnonzero(overlong).tolist(), self.max_episode_length)
                ends = dones | overlong
                truncated = truncated | (overlong & self.handle_timeout_termination)
                if self.handle_timeout_termination:
                    final_observations.update({int(idx): select(new_obs, idx) for idx in np.flatnonzero(overlong)})
        return ends, truncated, final_observations

    def collect_rollouts(  # type: ignore[override]
        self,
        env: VecEnv,
        callback: BaseCallback,
        rollout_buffer: TrajectoryBuffer,
        n_rollout_steps: int | None = None,
    ) -> bool:
        """
        Step the envs with the behaviour policy and append the transitions to ``rollout_buffer``, which keeps
        those of earlier rollouts not trained on yet.

        :param env: the training environment
        :param callback: callback called at each step (and at the beginning and end of the rollout)
        :param rollout_buffer: buffer to fill
        :param n_rollout_steps: steps per env to collect; ``None`` (what ``learn`` passes) stops when the
            algorithm's update has what it needs (``n_episodes`` episodes for REINFORCE, ``train_freq`` steps for
            SARSA)
        :return: False if the callback stopped training
        """
        rollout = self._rollout(env, callback, rollout_buffer, n_rollout_steps)
        try:
            next(rollout)
            while True:
                rollout.send(None)
        except StopIteration as end:
            return bool(end.value)

    def _rollout(
        self,
        env: VecEnv,
        callback: BaseCallback,
        rollout_buffer: TrajectoryBuffer,
        n_rollout_steps: int | None = None,
    ) -> Generator[None, Any, bool]:
        """
        ``collect_rollouts``, one env step per ``send``: before each step it waits to be sent what the behaviour
        policy's forward pass gives for the current observations (a population's stacked pass; None: the model makes
        its own, as ``collect_rollouts`` does), and it returns ``collect_rollouts``' value.
        """
        assert self._last_obs is not None, "No previous observation was provided"
        self._start_rollout(callback)
        n_steps, n_episodes = 0, 0
        while True:
            if n_rollout_steps is None:
                if self._rollout_complete(n_steps, n_episodes):
                    break
            elif n_steps >= n_rollout_steps:
                break
            behaviour = yield
            continue_training, n_ended = self._rollout_step(env, callback, rollout_buffer, n_steps, n_episodes, behaviour)
            n_steps += 1
            n_episodes += n_ended
            if not continue_training:
                return False

        callback.update_locals(locals())
        callback.on_rollout_end()
        return True

    def _start_rollout(self, callback: BaseCallback) -> None:
        """
        The start of a rollout (``collect_rollouts``): evaluation mode, the episodes counted so far kept for this
        rollout's update, the callback's ``on_rollout_start``.

        :param callback: the rollout's callback
        """
        self.policy.set_training_mode(False)
        self._episodes_before_rollout = self._completed_episodes
        callback.on_rollout_start()

    def _rollout_step(
        self,
        env: VecEnv,
        callback: BaseCallback,
        rollout_buffer: TrajectoryBuffer,
        n_steps: int,
        n_episodes: int,
        behaviour: Any = None,
    ) -> tuple[bool, int]:
        """
        One step of ``collect_rollouts``: an action per env from the behaviour policy, the envs' step, the callback's
        ``on_step``, the transitions stored.

        :param env: the training environment
        :param callback: callback called at the step
        :param rollout_buffer: buffer to fill
        :param n_steps: steps per env taken in this rollout before this one (the callback's ``locals``, as SB3's)
        :param n_episodes: episodes ended in this rollout before this step (the callback's ``locals``)
        :param behaviour: what the behaviour policy's forward pass gives for the current observations, computed outside
            the model (a population's stacked pass); None: the model's own forward pass
        :return: False if the callback stopped training, and the episodes this step ended (all envs together)
        :raises ValueError: if the envs returned NaN or ±inf (nothing of the step is stored)
        """
        use_masking, action_masks, final_action_masks = self._use_masking, None, None
        if use_masking:
            # Read before the action is chosen, as sb3-contrib's MaskablePPO reads them
            action_masks = self._read_action_masks(env)
        with th.no_grad():
            actions = self._sample_actions(self._last_obs, action_masks, behaviour)  # type: ignore[arg-type]
        env_actions = actions
        if self._action_offset is not None:
            # The buffer and the networks use indices 0..n-1, the env its own values start..start+n-1
            env_actions = actions + self._action_offset
        elif isinstance(self.action_space, spaces.Box):
            # The Gaussian is unbounded: clip what the env sees, store what was sampled
            env_actions = np.clip(actions, self.action_space.low, self.action_space.high)
        new_obs, rewards, dones, infos = env.step(env_actions)
        # A VecEnv of the user's may return 0/1 integers or floats: as an index, [1, 0] would select envs 1 and 0
        dones = np.asarray(dones, dtype=bool)
        self.num_timesteps += env.num_envs
        n_steps += 1

        # The callback runs before the step is stored, as in SB3's loops: one that changes rewards (or
        # observations) in place in _on_step, to shape or rescale them, changes what is trained on
        callback.update_locals(locals())
        continue_training = callback.on_step()

        # Nothing is stored or trained on if a value is NaN or ±inf: the model stays as its last update left it.
        # Checked after the callback, on the values that would be stored; final observations in _episode_ends
        if not (np.isfinite(rewards).all() and all_finite(new_obs)):  # type: ignore[arg-type]
            episode_length = self.rollout_buffer.episode_length
            if not np.isfinite(rewards).all():
                raise_non_finite(self, episode_length, rewards, "reward")
            raise_non_finite(self, episode_length, new_obs, "observation", after_reset=dones)  # type: ignore[arg-type]
        ends, truncated, final_observations = self._episode_ends(new_obs, dones, infos)  # type: ignore[arg-type]
        if use_masking and final_observations:
            final_action_masks = self._final_action_masks(infos, final_observations)
        # Stored even when the callback stops training, so that the buffer and the envs stay in step: the next
        # learn() goes on from the step the envs are at
        rollout_buffer.add(
            self._last_obs,  # type: ignore[arg-type]
            actions,
            rewards,
            ends,
            truncated,
            final_observations,
            action_masks,
            final_action_masks,
        )
        self._last_obs = new_obs  # type: ignore[assignment]
        # The training episodes' starts: an episode cut at max_episode_length starts a new one where the env goes on
        # (with the env's dones, the next learn() would take the cut for the start of an episode missing from the buffer)
        self._last_episode_starts = ends
        self._update_info_buffer(infos, dones)
        n_ended = 0
        if ends.any():
            n_ended = int(ends.sum())
            self._on_episodes_end(n_ended)
        return continue_training, n_ended

    def learn(
        self: SelfClassicOnPolicyAlgorithm,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 1,
        tb_log_name: str = "ClassicOnPolicyAlgorithm",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
        use_masking: bool = True,
    ) -> SelfClassicOnPolicyAlgorithm:
        if log_interval is not None:
            # Before anything is set up: SB3's loop would divide by it after the first rollout
            check_positive_int(
                "log_interval",
                log_interval,
                hint=f"Pass the updates between two logger dumps{self._log_interval_choices()} or None (no dumps)",
            )
        if self.env is None:
            # (SB3 asserts, with no message)
            raise ValueError(
                f"{type(self).__name__}.learn: this model has no env to train on (it was loaded without one): pass env=... "
                f"to {type(self).__name__}.load, or call model.set_env(env) first"
            )
        self._setup_masking(use_masking)
        iteration = 0
        total_timesteps, callback = self._setup_learn(
            total_timesteps, callback, reset_num_timesteps, tb_log_name, progress_bar
        )
        callback.on_training_start(locals(), globals())
        assert self.env is not None

        while self.num_timesteps < total_timesteps:
            if not self.collect_rollouts(self.env, callback, self.rollout_buffer):
                break
            iteration += 1
            self._update_current_progress_remaining(self.num_timesteps, total_timesteps)
            self.train()
            # After the update (SB3's on-policy algorithms dump before it): a dump's train/ values are those of the
            # rollout it reports, and no step is dumped twice
            if log_interval is not None and iteration % log_interval == 0:
                self.dump_logs(iteration)

        if log_interval is not None and self.logger.name_to_value:
            # What was recorded since the last dump is in the logs when learn() returns, however short the run
            # (log_interval=None: no dumps at all, as in SB3)
            self.dump_logs(iteration)
        callback.on_training_end()
        return self

    def _setup_masking(self, use_masking: bool) -> None:
        """
        Decide whether this ``learn()`` call reads action masks: when asked to and the env supports them (it, or a
        wrapper of it such as sb3-contrib's ``ActionMasker``, has ``action_masks()``), as MaskablePPO decides.

        :param use_masking: ``learn``'s argument
        :raises ValueError: if the env has masks for an action space that cannot be masked (``Box``)
        """
        check_bool("use_masking", use_masking)
        assert self.env is not None
        self._use_masking = bool(use_masking) and is_masking_supported(self.env)
        segments = mask_segments(self.action_space) if self._use_masking else None
        if self._use_masking and segments is None:
            raise ValueError(
                f"The env has action_masks(), but {self.action_space} actions cannot be masked (sb3-contrib masks "
                "Discrete, MultiDiscrete and MultiBinary actions): pass learn(..., use_masking=False)"
            )
        self.rollout_buffer.set_mask_size(None if segments is None else sum(segments))

    def dump_logs(self, iteration: int = 0) -> None:
        """
        SB3's ``OnPolicyAlgorithm.dump_logs``, with ``time/episodes``: the episodes completed so far, all envs
        together, as SB3's DQN logs it (the count the episode-based decays use).

        :param iteration: the rollouts so far in this ``learn()`` call (``time/iterations``)
        """
        self.logger.record("time/episodes", self._completed_episodes, exclude="tensorboard")
        super().dump_logs(iteration)

    def _excluded_save_params(self) -> list[str]:
        # Decided by each learn() call from its env: a loaded model predicts with masks or without. "predict" and
        # "save": an instance's own wrappers (the zoo's enjoy, which predicts with its env's masks; a population's
        # learn), not training state
        return [*super()._excluded_save_params(), "_use_masking", "predict", "save"]

    def _log_interval_choices(self) -> str:
        """:return: the values of ``learn(log_interval=...)`` beyond a count and None, for its error message"""
        return ""

    def _setup_learn(
        self,
        total_timesteps: int,
        callback: MaybeCallback = None,
        reset_num_timesteps: bool = True,
        tb_log_name: str = "run",
        progress_bar: bool = False,
    ) -> tuple[int, BaseCallback]:
        # Before anything is reset (a population's members start here too): SB3's loop would return at once, silently
        check_total_timesteps("total_timesteps", total_timesteps)
        if not reset_num_timesteps and self._last_obs is not None:
            reason = episodes_not_continued(self, self.rollout_buffer.episode_length)
            if reason is not None:
                warnings.warn(reason, stacklevel=3)
                self._last_obs = None
        if reset_num_timesteps or self._last_obs is None:
            # The envs are about to be reset: the episodes in progress in the buffer cannot be continued
            self.rollout_buffer.reset()
        total_timesteps, callback = super()._setup_learn(
            total_timesteps, callback, reset_num_timesteps, tb_log_name, progress_bar
        )
        if not all_finite(self._last_obs):  # type: ignore[arg-type]
            where = "the first observation after the reset"
            raise_non_finite(self, self.rollout_buffer.episode_length, self._last_obs, "observation", where)  # type: ignore[arg-type]
        # The progress of this learn() call from its first step (the schedules the rollout reads: a linear ε)
        self._update_current_progress_remaining(self.num_timesteps, total_timesteps)
        self._on_learn_start()
        return total_timesteps, callback

    def _on_learn_start(self) -> None:
        """Called by ``learn()`` once set up (``num_timesteps`` reset or not, the progress of this call at its start)."""

    def set_env(self, env: GymEnv, force_reset: bool = True) -> None:
        """
        Set the environment to learn from. Unlike SB3's on-policy algorithms, the number of envs may change:
        the buffer is rebuilt for it (the episodes in progress are dropped with the old envs).

        :param env: the new environment (same observation and action spaces)
        :param force_reset: reset the envs before training (required when the number of envs changes)
        """
        env = self._wrap_env(env, self.verbose)
        # Before anything changes: a model whose env was refused keeps its envs and buffer
        try:
            check_for_correct_spaces(env, self.observation_space, self.action_space)
        except ValueError as error:
            trained_on = env_id(self.env) or getattr(self, "_trained_env_id", None)
            raise ValueError(other_env_message(type(self).__name__, trained_on, env, error)) from error
        if env.num_envs != self.n_envs:
            if not force_reset:
                raise ValueError(
                    f"set_env(force_reset=False) needs the same number of envs ({self.n_envs}), got {env.num_envs}: "
                    "pass force_reset=True to start new episodes in the new envs"
                )
            set_n_envs(self, env.num_envs)
            self._make_buffer()
        super().set_env(env, force_reset=force_reset)
