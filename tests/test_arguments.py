"""
Arguments: values a YAML or another library's habit gives, which would be taken silently or fail far from their cause,
are refused at construction with the argument's name, and their valid neighbours are accepted; a constant
initialisation of a CNN and a policy class of another algorithm are named as such; ``learn(0)`` returns the model
unchanged, and a negative count is refused.
"""

import copy
import functools
import math
import re
from typing import Any

import numpy as np
import pytest
import torch as th
from stable_baselines3 import A2C
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.envs import FakeImageEnv
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.dqn.policies import DQNPolicy
from test_contract import MODEL_LIST, make_model, parameters_equal

from sb3_classic import REINFORCE, NStepSARSA, TileCoding

# Values a YAML or a habit from another library gives, which would otherwise be taken silently or fail far from the
# cause: each is refused at construction with the argument's name
REFUSED_INPUTS = [
    (REINFORCE, dict(policy_kwargs=dict(net_arch=dict(qf=[32]))), ValueError, "unknown key(s) 'qf'"),
    (REINFORCE, dict(policy_kwargs=dict(net_arch=dict(pi=[32], vf=[0]))), ValueError, r"net_arch['vf']=[0]"),
    (NStepSARSA, dict(policy_kwargs=dict(net_arch=64)), ValueError, "net_arch=64 must be a list"),
    (NStepSARSA, dict(policy_kwargs=dict(net_arch=[-5])), ValueError, "integer >= 1"),
    (NStepSARSA, dict(policy_kwargs=dict(net_arch=[0])), ValueError, "integer >= 1"),
    (NStepSARSA, dict(policy_kwargs=dict(net_arch=[dict(pi=[32], vf=[32])])), ValueError, "older form; write a list of"),
    # Python's own error named no fix
    (NStepSARSA, dict(n_step=5), TypeError, "unexpected keyword argument 'n_step': did you mean 'n_steps'?"),
    (REINFORCE, dict(value_learning_rates=0.1), TypeError, "did you mean 'value_learning_rate'?"),
    # The other algorithm's argument was taken for a misspelling ("did you mean 'learning_rate'?" alone)
    (NStepSARSA, dict(value_learning_rate=0.1), TypeError, "argument of REINFORCE, not of NStepSARSA; did you mean 'lea"),
    (REINFORCE, dict(td_lambda=0.5), TypeError, "'td_lambda': it is an argument of NStepSARSA, not of REINFORCE; REINFO"),
    # The policy's and ObGD's arguments given to the algorithm say where they belong; PyTorch's and the book's step size
    (NStepSARSA, dict(net_arch=[32]), TypeError, "argument of the policy: pass policy_kwargs=dict(net_arch=...)"),
    (REINFORCE, dict(value_optimizer_kwargs={}), TypeError, "pass policy_kwargs=dict(value_optimizer_kwargs=...)"),
    (NStepSARSA, dict(kappa=2.0), TypeError, "ObGD's: pass policy_kwargs=dict(optimizer_class=ObGD, optimizer_kw"),
    (NStepSARSA, dict(lr=0.1), TypeError, "'lr': did you mean 'learning_rate'?"),
    (REINFORCE, dict(alpha=0.1), TypeError, "'alpha': did you mean 'learning_rate'?"),
    (NStepSARSA, dict(policy_kwargs=dict(optimizer_class="ObGD")), TypeError, "optimizer_class='ObGD'): give the opt"),
    # (A2C's and PPO's rollout length: REINFORCE's own arguments are listed, n_episodes among them)
    (REINFORCE, dict(n_steps=5), TypeError, "not of REINFORCE; REINFORCE takes policy, env, learning_rate, value_learning"),
    # SB3's form before 1.8 with shared layers, which A2C cannot convert either: the error says what to write instead
    (REINFORCE, dict(policy_kwargs=dict(net_arch=[8, dict(pi=[32], vf=[16])])), ValueError, "no shared layers"),
    (NStepSARSA, dict(policy_kwargs=dict(activation_fn="relu")), TypeError, "activation_fn='relu'"),
    (REINFORCE, dict(policy_kwargs=dict(activation_fn=th.nn.ReLU())), TypeError, "activation_fn=ReLU()"),
    (NStepSARSA, dict(tau=0.5), ValueError, "target_update_interval is None"),
    (NStepSARSA, dict(expected_sarsa="False"), TypeError, "expected_sarsa='False'"),
    (NStepSARSA, dict(policy_kwargs=dict(layer_norm="true")), TypeError, "layer_norm='true'"),
    (REINFORCE, dict(gamma_t_factor="no"), TypeError, "gamma_t_factor='no'"),
    (REINFORCE, dict(use_baseline=0), TypeError, "use_baseline=0"),
    (REINFORCE, dict(handle_timeout_termination="yes"), TypeError, "handle_timeout_termination='yes'"),
    (NStepSARSA, dict(policy_kwargs=dict(with_bias="False")), TypeError, "with_bias='False'"),
    (REINFORCE, dict(lr_decay_factor=0.5, lr_decay_milestones=[]), ValueError, "lr_decay_milestones=[] has no milestone"),
    (NStepSARSA, dict(gradient_steps=-1), ValueError, "DQN's -1"),
    # Passed to SB3, which takes their truth: share_features_extractor="False" shared it
    (REINFORCE, dict(policy_kwargs=dict(share_features_extractor="False")), TypeError, "share_features_extractor='False'"),
    (NStepSARSA, dict(policy_kwargs=dict(normalize_images="False")), TypeError, "normalize_images='False'"),
    # Infinity passed the "> 0" checks: NaN weights (SARSA) or a multinomial error deep in the first update (REINFORCE)
    (NStepSARSA, dict(learning_rate=math.inf), ValueError, "learning_rate=inf must be finite and > 0"),
    (REINFORCE, dict(value_learning_rate=math.inf), ValueError, "value_learning_rate=inf must be finite"),
    (REINFORCE, dict(ent_coef=math.inf), ValueError, "ent_coef=inf must be a number in [0.0, inf)"),
    # A constant initialisation of hidden layers: every hidden unit stays identical, only the output biases learn
    (REINFORCE, dict(policy_kwargs=dict(weight_init=0.0)), ValueError, "weight_init=0.0 sets every weight to one number"),
    (NStepSARSA, dict(policy_kwargs=dict(weight_init=0.1)), ValueError, "have 2 hidden layer(s) with weights in all"),
    # The actor's and the critic's: net_arch=[8] was said to have 2 hidden layers, unexplained
    (REINFORCE, dict(policy_kwargs=dict(net_arch=[8], weight_init=0.0)), ValueError, "counts the actor's and the critic's"),
    # The exponential schedule is max(ε_final, ...): it would run at ε_final from the start
    (NStepSARSA, dict(exploration_initial_eps=0.0), ValueError, "exploration_initial_eps=0.0 is below exploration_final_eps"),
    # Set by the algorithm from its own argument (Python's "got multiple values for keyword argument" before)
    (NStepSARSA, dict(policy_kwargs=dict(target_network=True)), TypeError, "pass target_update_interval=... to NStepSARSA"),
    (REINFORCE, dict(policy_kwargs=dict(use_baseline=False)), TypeError, "pass use_baseline=... to REINFORCE"),
    (REINFORCE, dict(max_grad_norm="0.5"), TypeError, "max_grad_norm='0.5' must be a number > 0"),
    # A switch that would do nothing: no hidden layer to normalise
    (NStepSARSA, dict(policy_kwargs=dict(net_arch=[], layer_norm=True)), ValueError, "net_arch=[] has none"),
    # Keyword arguments of the features extractor or the activation: the hint named the policy's arguments
    (
        NStepSARSA,
        dict(policy_kwargs=dict(features_extractor_kwargs=dict(n_tilings=8))),
        TypeError,
        "features_extractor_kwargs go to features_extractor_class, here the default FlattenExtractor",
    ),
    (
        NStepSARSA,
        dict(policy_kwargs=dict(features_extractor_class=TileCoding, features_extractor_kwargs=dict(tilings=8))),
        TypeError,
        "features_extractor_kwargs go to features_extractor_class=TileCoding: give that class's own arguments",
    ),
    (
        REINFORCE,
        dict(policy_kwargs=dict(activation_fn=th.nn.LeakyReLU, activation_kwargs=dict(slope=0.1))),
        TypeError,
        "activation_kwargs go to activation_fn=LeakyReLU",
    ),
    # ... and without activation_fn, to the default one (the hint listed the policy's arguments, activation_kwargs among
    # them); a partial instead names activation_kwargs
    (
        NStepSARSA,
        dict(policy_kwargs=dict(activation_kwargs=dict(negative_slope=0.1))),
        TypeError,
        "activation_kwargs go to activation_fn, here the default ReLU: pass the activation they belong to",
    ),
    (
        REINFORCE,
        dict(policy_kwargs=dict(activation_fn=functools.partial(th.nn.LeakyReLU, negative_slope=0.2))),
        TypeError,
        "(for its arguments: activation_fn=LeakyReLU, activation_kwargs={'negative_slope': 0.2})",
    ),
    (NStepSARSA, dict(policy_kwargs=dict(net_arch=np.array([16, 8]))), ValueError, "write it as a list, net_arch=[16, 8]"),
]


@pytest.mark.parametrize(("model_class", "kwargs", "error", "message"), REFUSED_INPUTS)
def test_inputs_that_would_be_taken_silently_are_refused(
    model_class: type[BaseAlgorithm], kwargs: dict[str, Any], error: type[Exception], message: str
) -> None:
    with pytest.raises(error, match=re.escape(message)):
        make_model(model_class, **kwargs)


@pytest.mark.parametrize(
    ("model_class", "kwargs"),
    [
        (REINFORCE, dict(policy_kwargs=dict(net_arch=dict(pi=[32], vf=[16])))),
        (REINFORCE, dict(policy_kwargs=dict(net_arch=[]), use_baseline=np.bool_(False))),
        (NStepSARSA, dict(policy_kwargs=dict(net_arch=(np.int64(16),), activation_fn=th.nn.Tanh))),
        (NStepSARSA, dict(target_update_interval=10, tau=0.5, expected_sarsa=np.True_)),
        (NStepSARSA, dict(policy_kwargs=dict(net_arch=[], weight_init=np.float32(0.0)))),
        (REINFORCE, dict(policy_kwargs=dict(net_arch=[], weight_init=0.5), max_grad_norm=np.float32(1.0))),
        (NStepSARSA, dict(exploration_initial_eps=0.0, exploration_final_eps=0.0)),
        (NStepSARSA, dict(exploration_initial_eps=0.0, exploration_final_eps=0.5, exploration_schedule="linear")),
    ],
)
def test_their_valid_neighbours_are_accepted(model_class: type[BaseAlgorithm], kwargs: dict[str, Any]) -> None:
    make_model(model_class, **kwargs).learn(32)


@pytest.mark.parametrize("model_class", [A2C, REINFORCE])
def test_sb3s_older_net_arch_is_converted_with_its_warning_as_a2c_converts_it(model_class: type[Any]) -> None:
    # REINFORCE refused [dict(pi=..., vf=...)], which A2C and PPO take with SB3's deprecation warning
    sb3_warning = "net_arch=dict(pi=..., vf=...) instead of net_arch=[dict(pi=..., vf=...)]"
    with pytest.warns(UserWarning, match=re.escape(sb3_warning)):
        model = model_class("MlpPolicy", "CartPole-v1", policy_kwargs=dict(net_arch=[dict(pi=[32], vf=[16])]), device="cpu")
    assert model.policy.net_arch == dict(pi=[32], vf=[16])
    assert [layer.out_features for layer in model.policy.mlp_extractor.policy_net if isinstance(layer, th.nn.Linear)] == [32]
    assert [layer.out_features for layer in model.policy.mlp_extractor.value_net if isinstance(layer, th.nn.Linear)] == [16]
    model.learn(32)


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_a_constant_init_of_a_cnn_names_its_features_extractor(model_class: type[BaseAlgorithm]) -> None:
    # CnnPolicy with net_arch=[] was told to pass net_arch=[]: the hidden layers are NatureCNN's
    env = FakeImageEnv(screen_height=36, screen_width=36, n_channels=1, discrete=True)
    # REINFORCE's actor and critic have a NatureCNN each (the count said 4 of 8, one overwriting the other)
    count = 8 if model_class is REINFORCE else 4
    expected = rf"have {count} hidden layer\(s\) .* {count} of them are in the features extractor \(NatureCNN's {count}\)"
    with pytest.raises(ValueError, match=expected):
        model_class("CnnPolicy", env, policy_kwargs=dict(net_arch=[], weight_init=0.0), device="cpu")  # type: ignore[call-arg]


@pytest.mark.parametrize(("model_class", "policy"), [(REINFORCE, ActorCriticPolicy), (NStepSARSA, DQNPolicy)])
def test_a_policy_class_of_another_algorithm_is_named_as_such(model_class: type[BaseAlgorithm], policy: type) -> None:
    # It failed on this package's own policy_kwargs ("policy_kwargs: ... unexpected keyword argument 'weight_init'"),
    # which the user had not passed
    with pytest.raises(TypeError, match=rf"policy=.*{policy.__name__} is not one of {model_class.__name__}'s policies: "):
        model_class(policy, "CartPole-v1", device="cpu")  # type: ignore[call-arg]
    # ... and a ValueError too, as sb3-contrib's MaskablePPO raises for a policy of another class: a script written
    # for it and catching ValueError runs with the class name changed
    with pytest.raises(ValueError, match="is not one of"):
        model_class(policy, "CartPole-v1", device="cpu")  # type: ignore[call-arg]


@pytest.mark.parametrize("model_class", MODEL_LIST)
@pytest.mark.parametrize("reset_num_timesteps", [True, False])
def test_learn_zero_steps_returns_the_model_unchanged(model_class: type[BaseAlgorithm], reset_num_timesteps: bool) -> None:
    # SB3's A2C and DQN return from learn(0), with no division by zero in the progress of a 0-step call
    model = make_model(model_class, seed=0)
    if not reset_num_timesteps:
        model.learn(64)
    before = copy.deepcopy(model.get_parameters())
    steps = model.num_timesteps
    assert model.learn(0, reset_num_timesteps=reset_num_timesteps) is model
    assert model.num_timesteps == (steps if not reset_num_timesteps else 0)
    assert parameters_equal(model.get_parameters(), before)
    model.learn(64, reset_num_timesteps=False)  # and it goes on training


@pytest.mark.parametrize("model_class", MODEL_LIST)
@pytest.mark.parametrize("reset_num_timesteps", [True, False])
def test_learn_refuses_a_negative_step_count(model_class: type[BaseAlgorithm], reset_num_timesteps: bool) -> None:
    # SB3's loop returned at once and silently; 0 stays allowed (above), and so does a float count such as 1e5
    model = make_model(model_class, seed=0)
    model.learn(64)
    before = copy.deepcopy(model.get_parameters())
    steps = model.num_timesteps
    with pytest.raises(ValueError, match=r"total_timesteps=-5 must be >= 0"):
        model.learn(-5, reset_num_timesteps=reset_num_timesteps)
    with pytest.raises(TypeError, match=r"total_timesteps='100' must be a number"):
        model.learn("100")
    # Nothing was reset: the model goes on where it was
    assert model.num_timesteps == steps
    assert parameters_equal(model.get_parameters(), before)
    model.learn(64.0, reset_num_timesteps=False)
    assert model.num_timesteps >= steps + 64
