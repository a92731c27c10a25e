"""
What the populations of both algorithms share (``NStepSARSAPopulation``, ``REINFORCEPopulation``: K models of one
setting trained in lockstep): the checks of their members, each member's generator of action draws, a network of every
member stacked with its Adam state (``StackedPart``), the common part of a stacked gradient step (``Trainer.step``,
``side_by_side``, ``stacked_step``), the loop (``Lockstep``) and the end of ``learn`` for each member.
"""

from collections.abc import Callable, Generator, Iterator, Sequence
from contextlib import contextmanager
from typing import Any, Generic, Literal, TypeVar, cast

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.type_aliases import MaybeCallback
from torch import nn

from sb3_classic.common.arguments import constructor_parameters
from sb3_classic.common.on_policy_algorithm import Update
from sb3_classic.common.stacked import StackedAdam, StackedMLP, clip_grad_norms_per_member, parametrized_layers
from sb3_classic.common.threads import one_thread_unless_chosen
from sb3_classic.common.utils import check_bool, check_positive_int

#: The remaining progress at which two schedules are compared (``same_setting``)
SCHEDULE_PROBES = (1.0, 0.75, 0.5, 0.25, 0.0)
#: The constructor's arguments each member has its own: its seed and env, and what only logs
OWN_ARGUMENTS = frozenset(
    {"self", "policy", "env", "seed", "verbose", "tensorboard_log", "stats_window_size", "_init_setup_model"}
)


def shared_settings(algorithm: type[BaseAlgorithm]) -> tuple[str, ...]:
    """
    :param algorithm: ``NStepSARSA`` or ``REINFORCE``
    :return: the attributes the members of its population share: every argument of its constructor but
        ``OWN_ARGUMENTS`` (``policy`` as ``policy_class``), and the shape of the members' envs
    """
    arguments = [name for name in constructor_parameters(algorithm) if name not in OWN_ARGUMENTS]
    return ("policy_class", *arguments, "n_envs", "observation_space", "action_space")


class MemberError(ValueError):
    """
    Members of a population stopped by an error of their own in an env step (their env's NaN or ±inf, a mask that
    allows no action, a ``ValueError`` of their callback's ``on_step``), the others trained to the end.

    :param message: what happened, naming the members
    :param member_errors: each stopped member's error, by member index
    """

    def __init__(self, message: str, member_errors: dict[int, ValueError]) -> None:
        super().__init__(message)
        self.member_errors = member_errors


def member_rng(seed: int | None) -> np.random.Generator:
    """
    :param seed: a member's seed
    :return: the generator of its behaviour policy's draws, ``default_rng(SeedSequence(seed, spawn_key=(0,)))``: its own,
        not NumPy's global one, so that a member's draws do not depend on the other members (``check_population``
        refuses a member without a seed)
    """
    assert seed is not None, "a population's members have seeds (check_population)"
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0,)))


def same_setting(value: Any, other: Any) -> bool:
    """
    :param value: a member's setting (a number, a string, a dict, a space, an SB3 schedule)
    :param other: another member's
    :return: whether they are the same setting: equal, or two schedules (each member's own object, as rl-zoo3 builds
        them) of the same values at the remaining progress 1, 0.75, 0.5, 0.25 and 0
    """
    if callable(value) and callable(other) and not isinstance(value, type):
        return [float(value(p)) for p in SCHEDULE_PROBES] == [float(other(p)) for p in SCHEDULE_PROBES]
    return bool(value == other)


def check_population(
    models: Sequence[Any],
    algorithm: type[BaseAlgorithm],
    check_member: Callable[[int, Any], None],
) -> None:
    """
    :param models: the would-be members of a population of ``algorithm``, which share its ``shared_settings``
        (``same_setting``)
    :param algorithm: ``NStepSARSA`` or ``REINFORCE``
    :param check_member: the algorithm's checks of one member (its index, the model), raising for what is not covered
    :raises ValueError: for no members, a model twice, a member without a seed or an env, or members of different
        settings (and what ``check_member`` raises)
    :raises TypeError: for a member that is not an ``algorithm`` model, or one of observations other than Box (and
        what ``check_member`` raises)
    """
    name = algorithm.__name__
    if len(models) == 0:
        raise ValueError(f"models: a population needs at least one {name} model")
    if len({id(model) for model in models}) != len(models):
        raise ValueError(f"models: a model appears more than once; build one {name} model per seed")
    for k, model in enumerate(models):
        if not isinstance(model, algorithm):
            raise TypeError(f"member {k} is a {type(model).__name__}: a population's members are {name} models")
        model = cast(Any, model)
        if model.seed is None:
            raise ValueError(f"member {k}: seed=None; build each member with a seed of its own ({name}(..., seed=k))")
        if model.env is None:
            raise ValueError(
                f"member {k} (seed {model.seed}) has no env to train on: build it with one, or call model.set_env(env) first"
            )
        check_member(k, model)
        if not isinstance(model.observation_space, spaces.Box):
            raise TypeError(
                f"member {k} (seed {model.seed}): observation_space={model.observation_space}: a population's stacked "
                "networks take flat Box observations; train this setting one model after the other (model.learn), or "
                "wrap the env to give Box observations (e.g. a one-hot of a Discrete observation)"
            )
        for setting in shared_settings(algorithm):
            value, first = getattr(model, setting), getattr(models[0], setting)
            if not same_setting(value, first):
                raise ValueError(
                    f"member {k}'s {setting}={value!r} differs from member 0's ({first!r}): a population's members share "
                    "one setting (every argument but seed and env); train members of other settings in a population of "
                    "their own"
                )


def per_member_callbacks(callback: Sequence[MaybeCallback] | None, n_members: int) -> list[MaybeCallback]:
    """
    :param callback: one callback (or None, or a list of them) per member, or None for none
    :param n_members: the members
    :return: one per member
    :raises ValueError: for another count than one per member
    """
    callbacks: list[MaybeCallback] = [None] * n_members if callback is None else list(callback)
    if len(callbacks) != n_members:
        raise ValueError(f"callback: {len(callbacks)} callbacks for {n_members} members: pass one per member (None for none)")
    return callbacks


def start_learn(
    models: Sequence[Any],
    callback: Sequence[MaybeCallback] | None,
    total_timesteps: int,
    reset_num_timesteps: bool,
    tb_log_name: str,
) -> tuple[list[int], list[BaseCallback]]:
    """
    The start of ``learn`` for each member, as its algorithm's ``learn`` starts it (``_setup_learn``, its callbacks'
    ``on_training_start``).

    :param models: the members
    :param callback: one callback (or None, or a list of them) per member, or None for none
    :param total_timesteps: env steps per member
    :param reset_num_timesteps: the algorithm's ``learn``'s
    :param tb_log_name: the name of each member's run for TensorBoard logging
    :return: each member's env steps to train to, and its callback
    :raises ValueError: for another count of callbacks than one per member
    """
    callbacks = per_member_callbacks(callback, len(models))
    setups = [
        model._setup_learn(total_timesteps, member_callback, reset_num_timesteps, tb_log_name, False)
        for model, member_callback in zip(models, callbacks, strict=True)
    ]
    member_callbacks = [member_callback for _, member_callback in setups]
    for member_callback in member_callbacks:
        member_callback.on_training_start(locals(), globals())
    return [total for total, _ in setups], member_callbacks


@contextmanager
def trained_together(
    population: str, models: Sequence[Any], rngs: Sequence[np.random.Generator], use_masking: bool
) -> Iterator[None]:
    """
    While a population trains its members: each draws its behaviour policy's actions from its own generator, reads its
    env's action masks as its ``learn(use_masking=...)`` would, and refuses ``save`` (``refusing_save``); PyTorch
    uses one thread on the CPU unless the user chose a number (``one_thread_unless_chosen``: the stacked networks are
    small too, and threads made a population slower than its members one after another on a busy machine); as before
    when the context ends, however it ends.

    :param population: the population's class name, for the messages
    :param models: the members
    :param rngs: their generators (``member_rng``)
    :param use_masking: the population's ``learn``'s
    """
    try:
        for model, rng in zip(models, rngs, strict=True):
            model._action_rng = rng
            model._setup_masking(use_masking)
            # A member's optimizers are not stepped while the population trains it (the StackedAdams are): a file
            # saved now would hold a stale Adam state, so saving waits until learn returns
            model.__dict__["save"] = refusing_save(population)
        with one_thread_unless_chosen(models[0].device):
            yield
    finally:
        for model in models:
            model._action_rng = None
            model.__dict__.pop("save", None)


def refusing_save(population: str) -> Callable[..., None]:
    """
    :param population: the population's class name, for the message
    :return: a member's ``save`` while its population trains it: a ``RuntimeError`` (its optimizers are not stepped
        then, the population's are, so a file saved then would hold a stale Adam state)
    """

    def refuse_save(*args: Any, **kwargs: Any) -> None:
        raise RuntimeError(
            f"A member of a {population} cannot be saved while the population's learn() runs (its Adam state is the "
            "population's until then): save the members after learn() returns, or train the run alone to save checkpoints"
        )

    return refuse_save


def dump(model: Any, iteration: int, log_interval: int | None) -> None:
    """The algorithm's ``learn``'s dump after an update (every ``log_interval`` rollouts)."""
    if log_interval is not None and iteration % log_interval == 0:
        model.dump_logs(iteration)


def finish_learn(
    population: str,
    models: Sequence[Any],
    callbacks: Sequence[BaseCallback],
    iterations: Sequence[int],
    errors: dict[int, ValueError],
    log_interval: int | None,
) -> None:
    """
    The end of ``learn`` for each member, as its algorithm's ``learn`` ends (the last dump, ``on_training_end``), except
    for the members stopped by an error, which end as a separate run that raised: then the error, naming them.

    :param population: the population's class name, for the message
    :param models: the members
    :param callbacks: their callbacks
    :param iterations: their rollouts
    :param errors: the stopped members' errors, by member
    :param log_interval: ``learn``'s
    :raises MemberError: if a member stopped, with every stopped member's error
    """
    for k, (model, member_callback) in enumerate(zip(models, callbacks, strict=True)):
        if k in errors:
            continue
        if log_interval is not None and model.logger.name_to_value:
            model.dump_logs(iterations[k])
        member_callback.on_training_end()
    if errors:
        first = min(errors)
        names = ", ".join(f"{k} (seed {models[k].seed})" for k in sorted(errors))
        raise MemberError(
            f"{population}.learn: member {names} stopped, each as its last update left it (the others trained to the end); "
            f"member {first}'s error: {errors[first]}",
            errors,
        ) from errors[first]


def layer_parameters(network: nn.Sequential) -> list[th.Tensor]:
    """:return: the parameters of the network's ``nn.Linear`` and ``nn.LayerNorm`` layers, in a stacked MLP's order"""
    return [parameter for layer in parametrized_layers(network) for parameter in layer.parameters()]


def _to_member(stacked_slice: th.Tensor, parameter: th.Tensor) -> th.Tensor:
    # (K, in, out)[k] is the transposed (out, in) weight of nn.Linear; (K, 1, out)[k] a bias or LayerNorm gain, (out,)
    return stacked_slice.T if parameter.dim() == 2 else stacked_slice[0]


def _to_stacked(member_tensor: th.Tensor) -> th.Tensor:
    return member_tensor.T if member_tensor.dim() == 2 else member_tensor.unsqueeze(0)


class StackedPart:
    """
    One network of every member (q̂, π or v̂) as a ``StackedMLP`` shared with them (each member's parameters views into
    the stacked ones), and, for a trained network, its ``StackedAdam`` loaded from the members' optimizers (each
    member's step count and moments) and handed back to them by ``close``.

    :param networks: the members' networks, ``nn.Sequential`` of their ``nn.Linear`` and ``nn.LayerNorm`` layers and
        activations
    :param optimizers: the members' Adam optimizers of those parameters; None: a network no optimizer trains (a copy of
        q̂), without gradients
    :param name: the network's name in the errors
    :param device: where the stacked network lives
    """

    def __init__(
        self, networks: list[nn.Sequential], optimizers: list[th.optim.Optimizer] | None, name: str, device: th.device
    ) -> None:
        self.networks = networks
        self.optimizers = optimizers
        self.stacked = StackedMLP.from_sequentials(networks, name)
        self.stacked.to(device)
        self.stacked.share_with(networks)
        self.parameters = list(self.stacked.parameters())
        # Member k's own parameters, in the stacked parameters' order
        self.member_parameters = [layer_parameters(network) for network in networks]
        self._optimizer: StackedAdam | None = None
        if optimizers is None:
            self.stacked.requires_grad_(False)
            return
        group = optimizers[0].param_groups[0]
        self._optimizer = StackedAdam(
            self.parameters,
            len(networks),
            betas=group["betas"],
            eps=group["eps"],
            fused=group["fused"],
            foreach=group["foreach"],
            # (separate runs spend most of their Adam steps' time on denormal second moments)
            flush_denormal=True,
        )
        for k, optimizer in enumerate(optimizers):
            state = optimizer.state
            for index, parameter in enumerate(self.member_parameters[k]):
                if parameter not in state:
                    continue
                self._optimizer.set_state(k, int(state[parameter]["step"]))
                self._optimizer.exp_avgs[index][k].copy_(_to_stacked(state[parameter]["exp_avg"]))
                self._optimizer.exp_avg_sqs[index][k].copy_(_to_stacked(state[parameter]["exp_avg_sq"]))

    @property
    def optimizer(self) -> StackedAdam:
        """The ``StackedAdam`` of a trained network (a copy of q̂ has none)."""
        assert self._optimizer is not None, "a network no optimizer trains has no StackedAdam"
        return self._optimizer

    def learning_rates(self) -> np.ndarray:
        """:return: each member's learning rate of this network as its update set it (schedule and decay), shape (K,)"""
        assert self.optimizers is not None, "a network no optimizer trains has no learning rate"
        return np.array([optimizer.param_groups[0]["lr"] for optimizer in self.optimizers], dtype=np.float64)

    def close(self) -> None:
        """Each member's parameters get storage of their own again, and its optimizer its slice's Adam state."""
        StackedMLP.own_storage(self.networks)
        if self._optimizer is None or self.optimizers is None:
            return
        steps = self.optimizer.steps
        for k, optimizer in enumerate(self.optimizers):
            if steps[k] == 0:
                continue
            for index, parameter in enumerate(self.member_parameters[k]):
                exp_avg = _to_member(self.optimizer.exp_avgs[index][k], parameter)
                exp_avg_sq = _to_member(self.optimizer.exp_avg_sqs[index][k], parameter)
                optimizer.state[parameter] = {
                    "step": th.tensor(float(steps[k]), dtype=th.float32, device=parameter.device),
                    "exp_avg": exp_avg.clone(memory_format=th.contiguous_format),
                    "exp_avg_sq": exp_avg_sq.clone(memory_format=th.contiguous_format),
                }


#: The algorithm of a population's members
ModelT = TypeVar("ModelT", bound=BaseAlgorithm)


class Trainer(Generic[ModelT]):
    """
    An algorithm's stacked networks during one ``learn`` of its population (``NStepSARSAPopulation``'s q̂ and its
    copies, ``REINFORCEPopulation``'s π and v̂): what the population's loop (``Lockstep``) asks of them. Each algorithm
    gives ``forward``, ``_gradient_step`` and ``close``; ``step`` is theirs in common.

    :param models: the members
    """

    #: Whether a member whose rollout has nothing to train yet takes its next env step before the next stacked
    #: gradient step (NStepSARSA: the first n − 1 steps of an episode; REINFORCE, whose rollouts are whole episodes:
    #: one env step per stacked step)
    steps_again: bool

    def __init__(self, models: list[ModelT]) -> None:
        self.models = models
        self.device = models[0].device
        #: the length of a flattened observation
        self.features = int(np.prod(models[0].observation_space.shape or (1,)))
        self.max_grad_norm: float | None = cast(Any, models[0]).max_grad_norm

    def forward(self) -> Any:
        """
        :return: what chooses each member's actions at this env step, indexed by member (one stacked forward pass), as
            its model's ``_sample_actions`` takes it (``behaviour``)
        """
        raise NotImplementedError

    def step(self, updates: dict[int, "MemberUpdate"]) -> list[int]:
        """
        One stacked gradient step of the members with an update in progress, each on the arguments of its own next
        gradient step (``MemberUpdate.arguments``: its ``_update``'s (S_t, A_t, …), its whole batch or its next
        transition in time order), each sent back what its model's ``_gradient_step`` would return; the others are not
        stepped.

        :param updates: the members' updates in progress, by member
        :return: the members whose update this step finished
        """
        if not updates:
            return []
        members = sorted(updates)
        chunks = [updates[k].arguments for k in members]
        # (each chunk's length from its A_t, one per transition: S_t may be a dict)
        lengths = np.array([len(chunk[1]) for chunk in chunks])
        results = self._gradient_step(chunks, lengths, np.array(members))
        return [k for k, result in zip(members, results, strict=True) if not updates[k].send(result)]

    def _gradient_step(self, chunks: list[tuple[Any, ...]], lengths: np.ndarray, members: np.ndarray) -> list[Any]:
        """
        One stacked gradient step of the given members, each on the mean loss of its own chunk (its model's
        ``_gradient_step``, the chunks side by side, ``side_by_side``).

        :param chunks: the given members' arguments of their model's ``_gradient_step``, in member order
        :param lengths: each chunk's steps or transitions, shape (M,)
        :param members: the members, ascending, shape (M,)
        :return: what each given member's ``_gradient_step`` would return, in member order
        """
        raise NotImplementedError

    def subset(self, members: np.ndarray) -> th.Tensor | None:
        """:return: the given members as an index of the stacked networks (``StackedMLP.forward``), None for all"""
        return None if len(members) == len(self.models) else th.as_tensor(members, device=self.device)

    def close(self) -> None:
        """Hand each member its own parameters and optimizer states back."""
        raise NotImplementedError


def side_by_side(
    chunks: Sequence[np.ndarray | None], lengths: np.ndarray, shape: tuple[int, ...], dtype: Any, fill: Any = 0
) -> np.ndarray:
    """
    The members' chunks of one kind (S_t, A_t, targets, ...) as one array, a member a row.

    :param chunks: each member's values for its gradient step, its own count n first (an array that reshapes to
        (n, *shape)); None: ``fill`` throughout
    :param lengths: each chunk's count n, shape (M,)
    :param shape: one value's shape, () for a number
    :param dtype: the array's
    :param fill: what the padding holds (0: it weighs nothing in the losses; True: every action legal)
    :return: the chunks as the rows of one array, each padded to the longest, shape (M, max(lengths), *shape)
    """
    rows = np.full((len(chunks), int(lengths.max()), *shape), fill, dtype=dtype)
    for row, (chunk, n) in enumerate(zip(chunks, lengths, strict=True)):
        if chunk is not None:
            rows[row, :n] = np.reshape(chunk, (n, *shape))
    return rows


def stacked_step(
    parts: Sequence["StackedPart"],
    loss: th.Tensor,
    members: np.ndarray,
    max_grad_norm: float | None,
) -> None:
    """
    The end of a stacked gradient step (each model's ``_gradient_step``'s): the backward pass of the sum of the members'
    losses (member k's parameters get its own loss's gradient only), each network's gradient clipped to each member's
    own norm where ``max_grad_norm`` is finite, then each network's Adam step of the given members, each at the
    learning rate its update set (``StackedPart.learning_rates``).

    :param parts: the networks trained
    :param loss: the given members' losses summed
    :param members: the members to step, shape (M,)
    :param max_grad_norm: the members' ``max_grad_norm``
    """
    for part in parts:
        part.optimizer.zero_grad()
    loss.backward()
    for part in parts:
        if max_grad_norm is not None and np.isfinite(max_grad_norm):
            clip_grad_norms_per_member(part.parameters, max_grad_norm)
        part.optimizer.step(members, part.learning_rates())


def check_adam(name: str, optimizer: th.optim.Optimizer, label: str = "optimizer") -> None:
    """
    :param name: the member, for the message
    :param optimizer: one of its optimizers
    :param label: the optimizer's name, for the message
    :raises TypeError: for another optimizer than Adam without weight decay, AMSGrad or ``maximize`` (``StackedAdam``)
    """
    group = optimizer.param_groups[0]
    if type(optimizer) is not th.optim.Adam:
        found = type(optimizer).__name__
    elif group["weight_decay"] or group["amsgrad"] or group["maximize"]:
        options = ", ".join(f"{key}={group[key]!r}" for key in ("weight_decay", "amsgrad", "maximize"))
        found = f"Adam with {options}"
    else:
        return
    raise TypeError(
        f"{name}: {label} {found}: a population's optimizers are Adam without weight decay, AMSGrad or maximize "
        "(StackedAdam); to train seeds together, leave optimizer_class and those kwargs out"
    )


class MemberUpdate:
    """
    A member's update in progress: its model's own ``_update()``, whose gradient steps the population makes one stacked
    step at a time while the other members go on with their env steps and updates.

    :param update: the member's ``_update()``
    :param arguments: the arguments of its first gradient step (what it yielded first)
    """

    def __init__(self, update: Update, arguments: tuple[Any, ...]) -> None:
        self.update = update
        #: the arguments of the member's next gradient step (those of its ``_gradient_step``)
        self.arguments = arguments

    @classmethod
    def start(cls, model: Any) -> "MemberUpdate | None":
        """:return: the update of ``model``'s complete rollout, or None if it has nothing to train (its log made)"""
        update = model._update()
        arguments = next(update, None)
        return None if arguments is None else cls(update, arguments)

    def send(self, result: Any) -> bool:
        """
        :param result: what the member's gradient step gave (as its ``_gradient_step`` returns it)
        :return: whether its update goes on (False: it ended, its transitions marked trained and its log made)
        """
        try:
            self.arguments = self.update.send(result)
        except StopIteration:
            return False
        return True


class Population(Generic[ModelT]):
    """
    K models of one algorithm and setting, each built as usual with its own seed and env, trained in lockstep: each
    member steps its own envs with its own schedules, episode boundaries, logger, callback and buffer (its own
    ``_training_batch``), as if it ran alone; what the members share is the networks' arithmetic (``_trainer``:
    ``StackedMLP`` networks, one ``torch.baddbmm`` per layer for all members, and a ``StackedAdam`` of each, with each
    member's own Adam step count and learning rate). One stacked forward pass chooses every member's actions at each
    env step, and one stacked gradient step trains every member with an update in progress, each on the mean loss of
    its own transitions (members' chunks of other lengths padded to the longest) and, where ``max_grad_norm`` is set,
    with its gradient clipped to its own norm. This class is the ``learn`` of ``NStepSARSAPopulation`` and
    ``REINFORCEPopulation``, which say what their members share and what they cover (``_check``).

    Member k starts from its own model's weights (those of the separate run with seed k) and Adam states. While
    ``learn`` runs, its parameters are views into the stacked tensors (the same ``Parameter`` objects, with shared
    storage): its own code paths (its targets' bootstrap values, its ``predict`` in a callback) read the current weights
    with no copying. When ``learn`` returns (or raises), each member's parameters get storage of their own again and its
    optimizers the Adam states of its slices: the members are K ordinary models that save, load, predict and ``learn``
    on their own as any other.

    Member k's behaviour policy draws from a NumPy generator of its own (``member_rng``), kept by the population across
    ``learn`` calls, not from the global generator a separate run draws from: its draws do not depend on the other
    members, and a population of the same seeds repeats itself to the bit on the CPU. A separate run with the same seed
    sees the same transitions only where it draws the same (``model._action_rng`` set to that generator, as the tests
    do).

    :param models: the members, models of one setting (every argument but ``seed`` and ``env``), each with its own
        seed (not None) and env
    :raises ValueError: for members of different settings, without a seed or an env, or of a setting not covered
    :raises TypeError: for networks or optimizers not covered
    """

    def __init__(self, models: Sequence[ModelT]) -> None:
        self._check(models)
        self.models = list(models)
        #: each member's generator of its behaviour policy's draws
        self.action_rngs = [member_rng(model.seed) for model in self.models]

    def _check(self, models: Sequence[Any]) -> None:
        """:raises ValueError, TypeError: for members the population does not cover (its module's ``check_members``)"""
        raise NotImplementedError

    def _trainer(self) -> Trainer:
        """:return: the members' stacked networks for one ``learn``, sharing the members' weights until ``close``"""
        raise NotImplementedError

    def _log_interval(self) -> int:
        """:return: ``log_interval="auto"``: the updates between two logger dumps of the algorithm's ``learn``"""
        raise NotImplementedError

    def learn(
        self,
        total_timesteps: int,
        callback: Sequence[MaybeCallback] | None = None,
        log_interval: int | Literal["auto"] | None = "auto",
        tb_log_name: str | None = None,
        reset_num_timesteps: bool = True,
        use_masking: bool = True,
    ) -> list[ModelT]:
        """
        Train every member for ``total_timesteps`` env steps (its envs together), as its algorithm's ``learn`` would
        (REINFORCE's last update waits for its episodes to end).

        :param total_timesteps: env steps per member
        :param callback: one callback (or None, or a list of them) per member, in member order; None: none
        :param log_interval: the updates between two dumps of each member's logger, as the algorithm's ``learn``;
            ``"auto"``: its default (NStepSARSA's about every 1,000 env steps, REINFORCE's 4); None: no dumps
        :param tb_log_name: the name of each member's run for TensorBoard logging (default: the algorithm's name)
        :param reset_num_timesteps: the algorithm's ``learn``'s, for every member
        :param use_masking: the algorithm's ``learn``'s: each member whose env has action masks (``action_masks()``,
            as sb3-contrib's ``ActionMasker`` gives) chooses among its legal actions
        :return: the members, trained
        :raises MemberError: if a member's env step raised its usual ``ValueError`` (its env's NaN or ±inf, a mask
            that allows no action), with the member named: that member stops as its last update left it, the others
            train to the end first
        :raises TypeError: for a ``use_masking`` that is not a bool, before anything is trained
        """
        models, name = self.models, type(self).__name__
        check_bool("use_masking", use_masking)
        if log_interval == "auto":
            log_interval = self._log_interval()
        if log_interval is not None:
            hint = 'Pass the updates between two logger dumps, "auto" or None'
            check_positive_int("log_interval", log_interval, hint=hint)
        tb_log_name = type(models[0]).__name__ if tb_log_name is None else tb_log_name
        totals, member_callbacks = start_learn(models, callback, total_timesteps, reset_num_timesteps, tb_log_name)
        with trained_together(name, models, self.action_rngs, use_masking):
            run = Lockstep(models, member_callbacks, totals, log_interval, self._trainer())
            try:
                run.run()
            finally:
                run.trainer.close()
        finish_learn(name, models, member_callbacks, run.iterations, run.errors, log_interval)
        return models


class Lockstep:
    """
    The loop of one population's ``learn``: at each tick, the members free to step take their env steps (each
    member's actions from one stacked forward pass of all of them, ``Trainer.forward``), a member whose rollout is
    complete starts its update, and one stacked gradient step trains every member with an update in progress. A
    member's update trains its transitions one stacked step at a time while the others go on with their env steps and
    updates: each member makes the updates of its separate run, in the same order.

    :param models: the members
    :param callbacks: their callbacks (``_setup_learn``'s)
    :param totals: their ``total_timesteps`` (``_setup_learn``'s)
    :param log_interval: ``learn``'s
    :param trainer: their stacked networks
    """

    def __init__(
        self, models: list[Any], callbacks: list[BaseCallback], totals: list[int], log_interval: int | None, trainer: Trainer
    ) -> None:
        self.models, self.totals, self.log_interval, self.trainer = models, totals, log_interval, trainer
        self.errors: dict[int, ValueError] = {}
        self.stopped: set[int] = set()
        #: each member's rollouts so far (``time/iterations``)
        self.iterations = [0] * len(models)
        self.callbacks = callbacks
        #: each member's rollout under way (its ``_rollout()``), None between two
        self.rollouts: list[Generator[None, Any, bool] | None] = [None] * len(models)
        #: the updates in progress, by member
        self.updates: dict[int, MemberUpdate] = {}

    def run(self) -> None:
        """Train until every member has taken its env steps (or stopped)."""
        while True:
            stepping = [
                k
                for k, model in enumerate(self.models)
                if k not in self.stopped
                and k not in self.updates
                and (self.rollouts[k] is not None or model.num_timesteps < self.totals[k])
            ]
            if not stepping and not self.updates:
                return
            while stepping:
                outputs = self.trainer.forward()
                stepping = [k for k in stepping if self._step(k, outputs)]
            for k in self.trainer.step(self.updates):
                del self.updates[k]
                dump(self.models[k], self.iterations[k], self.log_interval)

    def _step(self, k: int, outputs: Any) -> bool:
        """
        Member k's env step (its own ``_rollout``: ``collect_rollouts`` one step at a time, its actions chosen from
        ``outputs[k]``), and the end of its rollout and the start of its update when the rollout is complete (the
        algorithm's ``learn`` loop after ``collect_rollouts``).

        :param k: the member
        :param outputs: ``Trainer.forward``'s
        :return: whether it takes another env step before the next stacked gradient step (``Trainer.steps_again``)
        """
        model, rollout = self.models[k], self.rollouts[k]
        try:
            if rollout is None:
                rollout = self.rollouts[k] = model._rollout(model.env, self.callbacks[k], model.rollout_buffer)
                next(rollout)
            rollout.send(outputs[k])
        except StopIteration as end:
            self.rollouts[k] = None
            if not end.value:  # (the callback stopped training)
                self.stopped.add(k)
                return False
        except ValueError as error:
            self.rollouts[k] = None
            self.errors[k] = error
            self.stopped.add(k)
            return False
        else:
            return self.trainer.steps_again
        self.iterations[k] += 1
        model._update_current_progress_remaining(model.num_timesteps, self.totals[k])
        update = MemberUpdate.start(model)
        if update is not None:
            self.updates[k] = update
            return False
        dump(model, self.iterations[k], self.log_interval)
        return self.trainer.steps_again and model.num_timesteps < self.totals[k]
