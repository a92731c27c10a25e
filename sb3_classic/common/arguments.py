"""
The rules of the arguments the algorithms share, as a table, and the errors of the policy arguments (``policy``,
``policy_kwargs``): each error names the argument, the value and what to pass instead.
"""

import contextvars
import difflib
import inspect
import numbers
from collections.abc import Callable, Mapping, Sequence
from functools import partial
from typing import Any

from torch import nn

from sb3_classic.common.obgd import ObGD
from sb3_classic.common.utils import check_bool, check_choice, check_learning_rate, check_positive_int, check_range

#: True while ``load()`` builds a model (the rules then accept a learning rate of 0: rl-zoo3's ``enjoy`` loads with
#: ``learning_rate=0.0``, as SB3 allows, to evaluate a model without training it)
LOADING: contextvars.ContextVar[bool] = contextvars.ContextVar("sb3_classic_loading", default=False)

#: A rule: the argument it checks and ``check(name, value)``; or, for a rule that relates arguments, their names and
#: ``check(*values)``
ArgumentRule = tuple[str | tuple[str, ...], Callable[..., None]]


def optional(check: Callable[[str, Any], None]) -> Callable[[str, Any], None]:
    """
    :param check: a check of an argument's value
    :return: the same check, with ``None`` accepted
    """

    def check_unless_none(name: str, value: Any) -> None:
        if value is not None:
            check(name, value)

    return check_unless_none


def check_learning_rate_unless_loading(name: str, value: Any) -> None:
    """
    ``check_learning_rate``, with 0 accepted while ``load()`` builds the model (``LOADING``).

    :param name: the argument's name
    :param value: a positive float, or an SB3 schedule whose values are positive
    """
    check_learning_rate(name, value, allow_zero=LOADING.get())


def check_max_grad_norm(name: str, value: Any) -> None:
    """
    :param name: the argument's name
    :param value: a number > 0 (``math.inf``: no clipping; the constructor stores ``None`` as ``math.inf``)
    """
    # Any real number (NumPy's included), not a bool
    number = isinstance(value, numbers.Real) and not isinstance(value, bool)
    if not number:
        raise TypeError(f"{name}={value!r} must be a number > 0, or None for no clipping")
    if not value > 0:
        raise ValueError(f"{name}={value!r} must be > 0, or None for no clipping")


def check_decay_every_or_milestones(every: int | None, milestones: Sequence[int] | None) -> None:
    """
    A decay is every k counts (``StepLR``) or at milestones (``MultiStepLR``), not both.

    :param every: ``lr_decay_every``
    :param milestones: ``lr_decay_milestones``
    """
    if every is not None and milestones is not None:
        raise ValueError("Pass lr_decay_every or lr_decay_milestones, not both")


def check_milestones(name: str, value: Any) -> None:
    """
    :param name: the argument's name (``lr_decay_milestones``)
    :param value: a non-empty list of counts >= 1
    """
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
        raise TypeError(
            f"{name}={value!r} must be a list of counts, e.g. [300, 500] (one milestone: [300]); for a decay every k, "
            "pass lr_decay_every=k"
        )
    if len(value) == 0:
        raise ValueError(f"{name}=[] has no milestone: pass the counts to decay at, e.g. [300, 500], or None for no decay")
    for milestone in value:
        check_positive_int(f"{name}[...]", milestone)


def check_decay_has_a_step(factor: float, every: int | None, milestones: Sequence[int] | None) -> None:
    """
    A decay factor other than 1 needs the counts to decay at.

    :param factor: ``lr_decay_factor``
    :param every: ``lr_decay_every``
    :param milestones: ``lr_decay_milestones``
    """
    if factor != 1.0 and every is None and milestones is None:
        raise ValueError(
            f"lr_decay_factor={factor!r} has no effect without lr_decay_every (a decay every k episodes or updates, like "
            "StepLR) or lr_decay_milestones (like MultiStepLR): pass one of them"
        )


#: The rules of ``ClassicOnPolicyAlgorithm``'s arguments, in the order they are checked
BASE_ARGUMENT_RULES: tuple[ArgumentRule, ...] = (
    ("learning_rate", check_learning_rate_unless_loading),
    ("gamma", partial(check_range, low=0.0, high=1.0, hint="0.99 is the usual choice")),
    ("max_grad_norm", check_max_grad_norm),
    ("lr_decay_factor", partial(check_range, low=0.0, high=1.0, low_open=True, hint="1.0 means no decay")),
    ("lr_decay_unit", partial(check_choice, choices=("episode", "update"))),
    ("handle_timeout_termination", check_bool),
    ("lr_decay_every", optional(check_positive_int)),
    (("lr_decay_every", "lr_decay_milestones"), check_decay_every_or_milestones),
    ("lr_decay_milestones", optional(check_milestones)),
    (("lr_decay_factor", "lr_decay_every", "lr_decay_milestones"), check_decay_has_a_step),
    ("max_episode_length", optional(partial(check_positive_int, hint="Pass None for no cap"))),
)


def check_arguments(owner: object, rules: Sequence[ArgumentRule]) -> None:
    """
    :param owner: the object whose attributes are the arguments (the algorithm)
    :param rules: the rules, applied in order
    :raises ValueError: or TypeError, from the first rule an argument breaks
    """
    for names, check in rules:
        if isinstance(names, str):
            check(names, getattr(owner, names))
        else:
            check(*(getattr(owner, name) for name in names))


def set_n_envs(model: Any, n_envs: int) -> None:
    """
    Give a model ``n_envs`` envs (``set_env``'s new ones) once its arguments pass their checks with them, else leave
    it as it was: the rules that depend on the number of envs (one stream for ObGD's traces) hold for every env a
    model is given, not only for the constructor's.

    :param model: the algorithm (its ``n_envs`` and ``_check_arguments``)
    :param n_envs: the new number of envs
    :raises ValueError: from the first rule the new number breaks
    """
    before = model.n_envs
    model.n_envs = n_envs
    try:
        model._check_arguments()
    except ValueError:
        model.n_envs = before
        raise


def constructor_parameters(cls: type) -> dict[str, inspect.Parameter]:
    """
    :param cls: a class
    :return: its constructor's parameters by name, with those of the parents' constructors that a subclass's passes on
        through ``**kwargs`` (``def __init__(self, *args, bonus=0.0, **kwargs)``), the subclass's first
    """
    parameters: dict[str, inspect.Parameter] = {}
    for klass in cls.__mro__:
        init = klass.__dict__.get("__init__")
        if init is None:
            continue
        own = inspect.signature(init).parameters
        for name, parameter in own.items():
            if parameter.kind not in (parameter.VAR_POSITIONAL, parameter.VAR_KEYWORD):
                parameters.setdefault(name, parameter)
        if not any(parameter.kind is parameter.VAR_KEYWORD for parameter in own.values()):
            break
    return parameters


def check_keywords(cls: type, kwargs: Mapping[str, Any], family: type | None = None) -> None:
    """
    :param cls: a class about to be constructed
    :param kwargs: the keyword arguments of the call
    :param family: the package's base class of ``cls`` (``ClassicOnPolicyAlgorithm``): its other subclasses in the
        package are the algorithms whose arguments a user may give ``cls`` by mistake
    :raises TypeError: for a keyword its constructor does not take (Python's own error names no fix), naming the other
        algorithm that takes it, if one does, or the policy or ``ObGD`` (to pass in ``policy_kwargs``), else the closest
        argument ``cls`` takes. A constructor that passes ``**kwargs`` on to ``object`` takes any keyword, and nothing is
        checked
    """
    inits = [klass.__dict__["__init__"] for klass in cls.__mro__ if "__init__" in klass.__dict__]
    takes_any = all(
        any(parameter.kind is parameter.VAR_KEYWORD for parameter in inspect.signature(init).parameters.values())
        for init in inits
    )
    if takes_any:
        return
    arguments = [name for name in constructor_parameters(cls) if name != "self"]
    for key in kwargs:
        if key not in arguments:
            public = [name for name in arguments if not name.startswith("_")]
            close = [_ALIASES[key]] if _ALIASES.get(key) in public else difflib.get_close_matches(key, public, n=1)
            hint = f"did you mean {close[0]!r}?" if close else f"{cls.__name__} takes {', '.join(public)}"
            others: list[type] = [] if family is None else family.__subclasses__()
            owners = [
                other.__name__
                for other in others
                if other.__module__.startswith("sb3_classic.")
                and not issubclass(cls, other)
                and key in constructor_parameters(other)
            ]
            if owners:
                hint = f"it is an argument of {' and '.join(owners)}, not of {cls.__name__}; {hint}"
            elif key in constructor_parameters(ObGD).keys() - {"self", "params", "lr"}:
                hint = f"it is ObGD's: pass policy_kwargs=dict(optimizer_class=ObGD, optimizer_kwargs=dict({key}=...))"
            elif any(key in constructor_parameters(policy) for policy in _policy_classes(cls)):
                hint = f"it is an argument of the policy: pass policy_kwargs=dict({key}=...)"
            raise TypeError(f"{cls.__name__}() got an unexpected keyword argument {key!r}: {hint}")


#: Other names of an argument: PyTorch's and the book's for the step size
_ALIASES = {"lr": "learning_rate", "alpha": "learning_rate"}


def _policy_classes(cls: type) -> list[type]:
    """:return: the policy classes an algorithm class names (SB3's ``policy_aliases``)"""
    return [policy for policy in getattr(cls, "policy_aliases", {}).values() if isinstance(policy, type)]


#: The policy's arguments the algorithm passes itself (not ``policy_kwargs``)
_POLICY_ARGUMENTS = {
    "self",
    "observation_space",
    "action_space",
    "lr_schedule",
    "value_lr_schedule",
    "use_baseline",
    "target_network",
    "averaged_network",
}


def refuse_policy_kwargs_set_here(algorithm: str, policy_kwargs: Mapping[str, Any], arguments: Mapping[str, str]) -> None:
    """
    :param algorithm: the algorithm's class name
    :param policy_kwargs: the algorithm's ``policy_kwargs``
    :param arguments: the policy's arguments that the algorithm sets itself, each with the algorithm's argument that
        sets it
    :raises TypeError: if ``policy_kwargs`` gives one of them (Python's "got multiple values" otherwise), naming the
        algorithm's argument to pass instead
    """
    for policy_argument, own_argument in arguments.items():
        if policy_argument in policy_kwargs:
            raise TypeError(
                f"policy_kwargs={{{policy_argument!r}: {policy_kwargs[policy_argument]!r}}}: {algorithm} sets the "
                f"policy's {policy_argument} from its own {own_argument}: pass {own_argument}=... to {algorithm} instead"
            )


class PolicyClassError(TypeError, ValueError):
    """
    A policy class the algorithm cannot train: a ``TypeError``, and a ``ValueError`` as sb3-contrib's ``MaskablePPO``
    raises for a policy of another class, so that a script written for either catches it.
    """


def check_policy_class(algorithm: str, policy_class: Any, policy_aliases: Mapping[str, type]) -> None:
    """
    :param algorithm: the algorithm's class name
    :param policy_class: the policy class to build
    :param policy_aliases: the algorithm's policies by name
    :raises PolicyClassError: if it is not one of them or a subclass of one (``foreign_policy_message``)
    """
    own_policies = tuple(policy_aliases.values())
    if own_policies and not (isinstance(policy_class, type) and issubclass(policy_class, own_policies)):
        raise PolicyClassError(foreign_policy_message(algorithm, policy_class, policy_aliases))


def foreign_policy_message(algorithm: str, policy_class: Any, policy_aliases: Mapping[str, type]) -> str:
    """
    :param algorithm: the algorithm's class name
    :param policy_class: a policy class that is not one of the algorithm's (e.g. SB3's ``ActorCriticPolicy`` passed to
        REINFORCE, or a file saved by another algorithm: ``load()`` takes the saved policy class)
    :param policy_aliases: the algorithm's policies by name
    :return: the error, naming the class to load a file of that policy with
    """
    name = getattr(policy_class, "__qualname__", repr(policy_class))
    module = getattr(policy_class, "__module__", "")
    aliases = ", ".join(repr(alias) for alias in policy_aliases)
    base = policy_aliases.get("MlpPolicy")  # the others subclass it
    own = base.__name__ if base is not None else ", ".join(policy.__name__ for policy in policy_aliases.values())
    # The class to load a file with, from its policy's module (stable_baselines3.dqn.policies: DQN)
    package = module.split(".")
    if package[0] in ("stable_baselines3", "sb3_contrib") and len(package) > 1 and package[1] != "common":
        loader = f"{package[0]}.{package[1].upper()}.load"
    elif module.startswith("stable_baselines3.common"):
        loader = "stable_baselines3.A2C.load or PPO.load, whichever saved it"
    else:
        loader = "REINFORCE.load" if algorithm == "NStepSARSA" else "NStepSARSA.load"
    return (
        f"policy={module}.{name} is not one of {algorithm}'s policies: pass {aliases}, or a subclass of {own}. If this "
        f"model was loaded from a file, the file was saved by another algorithm; load it with that algorithm's class "
        f"({loader})"
    )


#: The policy's arguments that take keyword arguments of their own, by the policy argument that holds those, in the
#: order the policy builds them (the features extractor before the layers the activation is built in)
_KWARGS_RECEIVERS = (("features_extractor_class", "features_extractor_kwargs"), ("activation_fn", "activation_kwargs"))


def _rejected_keyword(receiver: Any, kwargs: Any) -> tuple[str, str] | None:
    """
    :param receiver: a class that is called with ``kwargs``
    :param kwargs: its keyword arguments
    :return: the first keyword argument its constructor does not take, with the name of the constructor that refuses
        it (where the ``**kwargs`` passed on end), as the ``TypeError`` of the call would name them; ``None`` if it takes
        them all, or if only the call can say (a constructor of the user's that takes ``**kwargs`` may use them itself)
    """
    if not (isinstance(receiver, type) and isinstance(kwargs, Mapping)):
        return None
    for klass in receiver.__mro__:
        init = klass.__dict__.get("__init__")
        if init is None:
            continue
        if klass is nn.Module:
            # (its *args, **kwargs: it refuses any keyword argument, naming the class called)
            refused_by = f"{receiver.__name__}.__init__"
            break
        if all(parameter.kind is not parameter.VAR_KEYWORD for parameter in inspect.signature(init).parameters.values()):
            refused_by = init.__qualname__
            break
        # A constructor of the user's that takes **kwargs may use them itself (this package's pass them on to their
        # parent's): only the call can say
        if not klass.__module__.startswith("sb3_classic."):
            return None
    else:
        return None
    accepted = constructor_parameters(receiver)
    key = next((key for key in kwargs if key not in accepted), None)
    return None if key is None else (key, refused_by)


def _policy_kwargs_hint(algorithm: str, policy_class: type, receiver: str, receiver_class: type, default: bool) -> str:
    """
    :param algorithm: the algorithm's class name
    :param policy_class: the policy class
    :param receiver: what does not take a keyword argument it is given: ``"policy"``, or the policy's argument
        ``"features_extractor_class"`` or ``"activation_fn"``
    :param receiver_class: that class
    :param default: whether it is the policy's default (not given in ``policy_kwargs``)
    :return: what takes the keyword argument
    """
    name = receiver_class.__name__
    if receiver == "features_extractor_class":
        if default:
            return (
                f"features_extractor_kwargs go to features_extractor_class, here the default {name}: pass the class they "
                "belong to (e.g. features_extractor_class=TileCoding for n_tilings and tiles_per_dim), or drop them"
            )
        return f"features_extractor_kwargs go to features_extractor_class={name}: give that class's own arguments"
    if receiver == "activation_fn":
        if default:
            return (
                f"activation_kwargs go to activation_fn, here the default {name}: pass the activation they belong to "
                "(e.g. activation_fn=nn.LeakyReLU for negative_slope), or drop them"
            )
        return f"activation_kwargs go to activation_fn={name}: give that class's own arguments"
    parameters = [name for name in inspect.signature(policy_class).parameters if name not in _POLICY_ARGUMENTS]
    return (
        f"{algorithm}'s policy takes {', '.join(parameters)} "
        "(A2C/PPO's ortho_init is weight_init='orthogonal' here, or weight_init='default' for PyTorch's)"
    )


def check_policy_kwargs(algorithm: str, policy_class: type, policy_kwargs: Mapping[str, Any]) -> None:
    """
    Check the keyword arguments of the policy, of its features extractor and of its activation against their
    constructors' signatures, in the order the policy takes them: its own when it is called, the others' when it builds
    its networks.

    :param algorithm: the algorithm's class name
    :param policy_class: the policy class
    :param policy_kwargs: the policy's keyword arguments
    :raises TypeError: with Python's error for the first keyword argument a constructor does not take, and what takes
        it: the features extractor's or the activation's kwargs, or what ``policy_kwargs`` takes
    """
    defaults = constructor_parameters(policy_class)
    # Each receiver, its class, the keyword arguments it is given, and whether it is the policy's default
    receivers: list[tuple[str, Any, Any, bool]] = [("policy", policy_class, policy_kwargs, False)]
    for receiver, kwargs in _KWARGS_RECEIVERS:
        given = policy_kwargs.get(receiver)
        default = defaults[receiver].default if receiver in defaults else None
        receivers.append((receiver, default if given is None else given, policy_kwargs.get(kwargs), given is None))
    for receiver, receiver_class, kwargs, is_default in receivers:
        rejected = _rejected_keyword(receiver_class, kwargs)
        if rejected is not None:
            key, refused_by = rejected
            hint = _policy_kwargs_hint(algorithm, policy_class, receiver, receiver_class, is_default)
            raise TypeError(f"policy_kwargs: {refused_by}() got an unexpected keyword argument '{key}'. {hint}")
