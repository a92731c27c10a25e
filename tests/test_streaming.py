"""
The streaming recipe: ObGD's step against its formula, SARSA(λ) along its traces against a tabular transcription of the
book's, REINFORCE's bounded per-step updates against theirs, sparse initialisation, LayerNorm without parameters, the
argument checks, and save/load of the traces.
"""

import math
from pathlib import Path
from typing import Any, cast

import numpy as np
import pytest
import torch as th
import yaml
from chain_env import ShortChain
from recorders import RecordLocal
from stable_baselines3.common.utils import set_random_seed
from stable_baselines3.common.vec_env import DummyVecEnv
from torch import nn

import sb3_classic
from sb3_classic import REINFORCE, NStepSARSA
from sb3_classic.common.obgd import ObGD, td_step
from sb3_classic.common.torch_layers import sparse_init
from sb3_classic.envs import RandomWalkEnv
from sb3_classic.zoo import YAML_NAMES

GAMMA, LAMBDA = 0.9, 0.8


@pytest.mark.parametrize("given", [False, True], ids=["grad", "step_with_gradients"])
@pytest.mark.parametrize(("lr", "kappa", "bounded"), [(0.01, 2.0, False), (1.0, 2.0, True), (1.0, 0.0, False)])
def test_obgd_step_is_its_formula(lr: float, kappa: float, bounded: bool, given: bool) -> None:
    weight = nn.Parameter(th.tensor([0.5, -1.0, 2.0]))
    bias = nn.Parameter(th.tensor(0.25))
    optimizer = ObGD([weight, bias], lr=lr, kappa=kappa)
    w, b = weight.detach().double().numpy().copy(), float(bias.detach())
    e_w, e_b = np.zeros(3), 0.0
    for grad_w, grad_b, td_error, decay in (
        ([0.2, -0.1, 0.3], 0.5, 0.7, 0.0),
        ([-0.4, 0.6, 0.1], -0.2, -1.5, GAMMA * LAMBDA),
    ):
        if given:
            optimizer.step_with_gradients([th.tensor(grad_w), th.tensor(grad_b)], td_error=td_error, trace_decay=decay)
            assert weight.grad is None
            assert bias.grad is None
        else:
            weight.grad, bias.grad = th.tensor(grad_w), th.tensor(grad_b)
            optimizer.step(td_error=td_error, trace_decay=decay)
        # e ← γλe + ∇; δ̄ = max(|δ|, 1); M = ακδ̄‖e‖₁; w ← w + (α / max(M, 1)) δ e
        e_w, e_b = decay * e_w + np.array(grad_w), decay * e_b + grad_b
        bound = lr * kappa * max(abs(td_error), 1.0) * (np.abs(e_w).sum() + abs(e_b))
        assert (bound > 1.0) == bounded
        step = lr / bound if bound > 1.0 else lr
        w, b = w + step * td_error * e_w, b + step * td_error * e_b
        np.testing.assert_allclose(weight.detach().numpy(), w, rtol=1e-6)
        assert float(bias.detach()) == pytest.approx(b, rel=1e-6)
        np.testing.assert_allclose(optimizer.state[weight]["eligibility_trace"].numpy(), e_w, rtol=1e-6)


def test_obgd_refuses_a_loss_step_and_bad_arguments() -> None:
    weight = nn.Parameter(th.ones(2))
    with pytest.raises(ValueError, match=r"kappa=-1.0\): must be a finite number >= 0"):
        ObGD([weight], kappa=-1.0)
    with pytest.raises(ValueError, match="lr=nan"):
        ObGD([weight], lr=math.nan)
    optimizer = ObGD([weight])
    weight.grad = th.ones(2)
    with pytest.raises(ValueError, match=r"ObGD.step\(td_error=δ"):
        optimizer.step()
    with pytest.raises(ValueError, match=r"trace_decay=1\.5"):
        optimizer.step(td_error=1.0, trace_decay=1.5)


def test_obgd_steps_with_given_gradients_as_with_grad() -> None:
    # The same arithmetic in the same order: equal to the bit on one machine; a None gradient leaves its parameter and
    # trace as they were
    def trained(given: bool) -> tuple[list[th.Tensor], list[th.Tensor]]:
        th.manual_seed(0)
        layer = nn.Linear(4, 2)
        optimizer = ObGD([{"params": [layer.weight]}, {"params": [layer.bias], "kappa": 0.5}], lr=1.0)
        for step in range(5):
            inputs = th.randn(1, 4)
            output = layer(inputs).sum()
            restart = 0.0 if step == 0 else GAMMA * LAMBDA
            if given:
                gradients = th.autograd.grad(output, optimizer.parameter_list())
                optimizer.step_with_gradients(gradients, td_error=2.0 - step, trace_decay=restart)
            else:
                optimizer.zero_grad()
                output.backward()
                optimizer.step(td_error=2.0 - step, trace_decay=restart)
        traces = [optimizer.state[p]["eligibility_trace"] for p in optimizer.parameter_list()]
        return [p.detach().clone() for p in layer.parameters()], traces

    (weights_grad, traces_grad), (weights_given, traces_given) = trained(False), trained(True)
    for a, b in zip([*weights_grad, *traces_grad], [*weights_given, *traces_given], strict=True):
        assert th.equal(a, b), (a, b)

    weight, bias = nn.Parameter(th.ones(2)), nn.Parameter(th.zeros(()))
    optimizer = ObGD([weight, bias], lr=0.1)
    optimizer.step_with_gradients([None, th.tensor(1.0)], td_error=1.0)
    assert th.equal(weight.detach(), th.ones(2))
    assert "eligibility_trace" not in optimizer.state[weight]
    assert float(bias) == pytest.approx(0.1)
    with pytest.raises(ValueError, match=r"1 gradients for the optimizer's 2 parameters"):
        optimizer.step_with_gradients([th.ones(2)], td_error=1.0)


def test_traces_restart_at_an_episode_start() -> None:
    layer = nn.Linear(3, 1)
    optimizer = ObGD(layer.parameters(), lr=0.1)
    for x, restart in (([1.0, 0.0, 2.0], True), ([0.5, 1.0, 0.0], False), ([0.0, 3.0, 1.0], True)):
        observation = th.tensor([x])
        td_step(optimizer, layer(observation).flatten(), th.tensor([1.0]), GAMMA * LAMBDA, restart)
    # After a restart the trace is the gradient of that step alone: x(S_0) for the weight, 1 for the bias (compared
    # exactly: a linear layer's gradient is its input, copied with no arithmetic that could round otherwise on
    # another CPU)
    assert th.equal(optimizer.state[layer.weight]["eligibility_trace"], th.tensor([[0.0, 3.0, 1.0]]))
    assert th.equal(optimizer.state[layer.bias]["eligibility_trace"], th.tensor([1.0]))
    optimizer.reset_traces()
    assert not optimizer.state[layer.weight]["eligibility_trace"].any()
    with pytest.raises(ValueError, match="one transition at a time"):
        td_step(optimizer, layer(th.ones(2, 3)).flatten(), th.ones(2), GAMMA * LAMBDA, False)


def tabular_sarsa_lambda(
    states: list[int], actions: list[int], rewards: list[float], ends: list[bool], n_states: int, n_actions: int, alpha: float
) -> np.ndarray:
    """
    Sutton & Barto's box of §12.7 (Sarsa(λ) with binary features and accumulating traces) with one feature per state
    and action, replaying a recorded trajectory: step t is (S_t, A_t, R_{t+1}), and ``ends[t]`` says that S_{t+1} is
    terminal (the next step starts an episode).

    :return: w, shape (n_actions, n_states)
    """
    w = np.zeros((n_actions, n_states))
    z = np.zeros_like(w)
    for t, (s, a, r) in enumerate(zip(states, actions, rewards, strict=True)):
        if t == 0 or ends[t - 1]:
            z[:] = 0.0  # (a new episode)
        delta = r - w[a, s]
        z[a, s] += 1.0  # accumulating traces
        if ends[t]:
            w += alpha * delta * z
            continue
        if t + 1 == len(states):
            break  # (A_{t+1} not taken: the model has not made this update either)
        delta += GAMMA * w[actions[t + 1], states[t + 1]]
        w += alpha * delta * z
        z *= GAMMA * LAMBDA
    return w


@pytest.mark.parametrize("make_env", [lambda: RandomWalkEnv(5), lambda: ShortChain(5)], ids=["random-walk", "chain"])
def test_sarsa_lambda_is_the_books_tabular_sarsa_lambda(make_env: Any) -> None:
    alpha = 0.1
    env = DummyVecEnv([make_env])
    model = NStepSARSA(
        "MlpPolicy",
        env,
        learning_rate=alpha,
        n_steps=1,
        train_freq=1,
        gradient_steps=1,
        update_mode="per_step",
        gamma=GAMMA,
        td_lambda=LAMBDA,
        exploration_initial_eps=0.3,
        exploration_final_eps=0.3,
        # q̂(s, a) = W[a] · onehot(s): the tabular Q; κ = 0: the book's step α, without ObGD's bound
        policy_kwargs=dict(
            net_arch=[], with_bias=False, weight_init=0.0, optimizer_class=ObGD, optimizer_kwargs=dict(kappa=0.0)
        ),
        seed=3,
        device="cpu",
    )
    recorders = [RecordLocal(name) for name in ("actions", "rewards", "dones", "new_obs")]
    model.learn(400, callback=recorders)  # type: ignore[arg-type]
    actions, rewards, dones, new_obs = ([np.asarray(value)[0] for value in recorder.values] for recorder in recorders)
    assert sum(dones) >= 5, "the test needs several episodes"
    first = int(np.argmax(env.envs[0].reset()[0]))
    # S_{t+1} is the observation after step t (after an episode's end, the next episode's first)
    states = [first] + [int(np.argmax(obs)) for obs in new_obs[:-1]]
    n_actions = int(model.action_space.n)
    expected = tabular_sarsa_lambda(states, actions, rewards, dones, len(new_obs[0]), n_actions, alpha)
    # (float32 against float64: to rounding)
    (layer,) = (module for module in model.policy.q_net.q_net if isinstance(module, nn.Linear))
    np.testing.assert_allclose(layer.weight.detach().numpy(), expected, rtol=1e-5, atol=1e-6)


def test_sparse_init_zeroes_90_percent_of_each_units_inputs() -> None:
    layers = [nn.Linear(4, 128), nn.Linear(128, 128), nn.Linear(128, 2)]
    network = nn.Sequential(layers[0], nn.ReLU(), layers[1], nn.ReLU(), layers[2])
    th.manual_seed(0)
    sparse_init([network])
    for layer in layers:
        fan_in = layer.in_features
        zeros = (layer.weight == 0).sum(dim=1)
        assert th.equal(zeros, th.full_like(zeros, math.floor(0.9 * fan_in)))  # 3 of 4, 115 of 128
        assert layer.weight.abs().max() <= math.sqrt(3 / fan_in)
        assert not layer.bias.any()
    # The zeros of each unit are its own draw, not one pattern for all
    assert len({tuple(row.nonzero().flatten().tolist()) for row in layers[1].weight}) > 100
    with pytest.raises(ValueError, match=r"sparsity=1\.0 must be in"):
        sparse_init([network], sparsity=1.0)


def streaming_model(env: Any, **kwargs: Any) -> NStepSARSA:
    policy_kwargs = dict(
        net_arch=[32, 32],
        layer_norm=True,
        layer_norm_kwargs=dict(elementwise_affine=False),
        weight_init="sparse",
        optimizer_class=ObGD,
    )
    settings: dict[str, Any] = dict(
        learning_rate=1.0, n_steps=1, train_freq=1, gradient_steps=1, update_mode="per_step", td_lambda=LAMBDA
    )
    settings.update(kwargs)
    return NStepSARSA("MlpPolicy", env, policy_kwargs=policy_kwargs, seed=0, device="cpu", **settings)


def test_the_recipes_network() -> None:
    model = streaming_model("CartPole-v1")
    norms = [layer for layer in model.policy.q_net.q_net if isinstance(layer, nn.LayerNorm)]
    assert len(norms) == 2
    assert all(norm.weight is None and norm.bias is None for norm in norms)
    assert isinstance(model.policy.optimizer, ObGD)
    with pytest.raises(ValueError, match="pass layer_norm=True as well"):
        NStepSARSA("MlpPolicy", "CartPole-v1", policy_kwargs=dict(layer_norm_kwargs=dict(elementwise_affine=False)))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(update_mode="batch"), "update_mode='batch' with optimizer_class=ObGD.*pass update_mode='per_step'"),
        (dict(n_steps=3), "n_steps=3 with optimizer_class=ObGD.*pass n_steps=1"),
        (dict(gradient_steps=2), "gradient_steps=2 with optimizer_class=ObGD"),
        (dict(loss_function="huber"), "loss_function='huber' with optimizer_class=ObGD"),
        (dict(max_grad_norm=10.0), "max_grad_norm=10.0 with optimizer_class=ObGD"),
    ],
)
def test_settings_obgd_cannot_train_are_refused(kwargs: dict[str, Any], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        streaming_model("CartPole-v1", **kwargs)


def test_every_setting_obgd_cannot_train_is_named_at_once() -> None:
    # The defaults are a batch learner's: one error names the three settings to change, each with its fix
    with pytest.raises(ValueError, match="update_mode='batch' with optimizer_class=ObGD") as refused:
        NStepSARSA("MlpPolicy", "CartPole-v1", policy_kwargs=dict(optimizer_class=ObGD))
    for fix in ("pass update_mode='per_step'", "pass n_steps=1", "pass gradient_steps=1"):
        assert fix in str(refused.value), str(refused.value)
    with pytest.raises(ValueError, match="update_mode='batch' with optimizer_class=ObGD") as refused:
        REINFORCE("MlpPolicy", "CartPole-v1", max_grad_norm=0.5, policy_kwargs=dict(optimizer_class=ObGD))
    for fix in ("pass update_mode='per_step'", "drop max_grad_norm"):
        assert fix in str(refused.value), str(refused.value)


def test_obgds_unknown_arguments_name_where_lambda_and_gamma_go() -> None:
    # The paper's code gives the optimizer λ and γ; here they are the algorithm's
    with pytest.raises(TypeError, match=r"'lamda', 'gamma': it takes lr \(α\) and kappa \(κ\).*td_lambda"):
        ObGD([nn.Parameter(th.ones(2))], lamda=0.8, gamma=0.99)
    assert sb3_classic.ObGD is ObGD


def test_obgd_with_several_envs_is_refused() -> None:
    with pytest.raises(ValueError, match=r"2 envs with optimizer_class=ObGD.*train on one env"):
        streaming_model(DummyVecEnv([lambda: ShortChain(4)] * 2))
    # set_env too, before anything changes: the model keeps its env and trains on as before
    model = streaming_model(DummyVecEnv([lambda: ShortChain(4)]))
    model.learn(20)
    with pytest.raises(ValueError, match=r"2 envs with optimizer_class=ObGD.*train on one env"):
        model.set_env(DummyVecEnv([lambda: ShortChain(4)] * 2))
    env = model.get_env()
    assert env is not None
    assert model.n_envs == env.num_envs == 1
    model.learn(20, reset_num_timesteps=False)
    assert model.num_timesteps == 40


def test_save_load_keeps_the_traces(tmp_path: Path) -> None:
    def env() -> DummyVecEnv:
        vec_env = DummyVecEnv([lambda: ShortChain(6)])
        vec_env.seed(5)
        return vec_env

    model = streaming_model(env(), exploration_initial_eps=0.5, exploration_final_eps=0.5)
    model.learn(300)
    model.save(tmp_path / "model.zip")
    loaded = NStepSARSA.load(tmp_path / "model.zip", env=env(), device="cpu")
    traces = [model.policy.optimizer.state[p]["eligibility_trace"] for p in model.policy.q_net.parameters()]
    loaded_traces = [loaded.policy.optimizer.state[p]["eligibility_trace"] for p in loaded.policy.q_net.parameters()]
    assert any(trace.any() for trace in traces)
    assert all(th.equal(a, b) for a, b in zip(traces, loaded_traces, strict=True))
    assert loaded.policy.optimizer.param_groups[0]["kappa"] == 2.0
    # The loaded model continues as the original does, to the bit (new episodes of envs seeded alike, the same draws)
    model.set_env(env())
    for continued in (model, loaded):
        set_random_seed(7)
        continued.learn(300)
    for a, b in zip(model.policy.parameters(), loaded.policy.parameters(), strict=True):
        assert th.equal(a, b)


def reinforce_streaming_model(env: Any, **kwargs: Any) -> REINFORCE:
    policy_kwargs = dict(
        net_arch=[32, 32],
        activation_fn=nn.LeakyReLU,
        layer_norm=True,
        layer_norm_kwargs=dict(elementwise_affine=False),
        weight_init="sparse",
        optimizer_class=ObGD,
    )
    policy_kwargs.update(kwargs.pop("policy_kwargs", {}))
    settings: dict[str, Any] = dict(learning_rate=1.0, value_learning_rate=1.0, update_mode="per_step", gamma_t_factor=True)
    settings.update(kwargs)
    return REINFORCE("MlpPolicy", env, policy_kwargs=policy_kwargs, seed=0, device="cpu", **settings)


@pytest.mark.parametrize(
    ("learning_rate", "use_baseline", "episode_step", "bounded"),
    [(0.02, True, 3, False), (1.0, True, 3, True), (1.0, False, 0, True), (0.02, False, 5, False)],
    ids=["M<=1", "M>1", "M>1-plain", "M<=1-plain"],
)
def test_reinforce_obgd_step_is_its_formula(
    learning_rate: float, use_baseline: bool, episode_step: int, bounded: bool
) -> None:
    # Linear networks, so that the gradients are by hand: v̂(s) = w·x + b, h(s, ·) = Θx + c, π = soft-max(h)
    model = REINFORCE(
        "MlpPolicy",
        "CartPole-v1",
        learning_rate=learning_rate,
        value_learning_rate=learning_rate,
        update_mode="per_step",
        gamma=GAMMA,
        gamma_t_factor=True,
        use_baseline=use_baseline,
        policy_kwargs=dict(net_arch=[], optimizer_class=ObGD),
        seed=0,
        device="cpu",
    )
    w, b = np.array([0.3, -0.2, 0.1, 0.4]), 0.5
    theta, c = np.array([[0.2, -0.1, 0.3, 0.0], [-0.3, 0.2, 0.1, 0.5]]), np.array([0.1, -0.2])
    action_net, value_net = cast(nn.Linear, model.policy.action_net), cast(nn.Linear, model.policy.value_net)
    with th.no_grad():
        action_net.weight.copy_(th.tensor(theta))
        action_net.bias.copy_(th.tensor(c))
        if use_baseline:
            value_net.weight.copy_(th.tensor(w[None]))
            value_net.bias.copy_(th.tensor([b]))
    x, action, ret = np.array([0.5, -1.0, 2.0, 0.25]), 1, 2.5
    model._gradient_step(x[None].astype(np.float32), np.array([action]), np.array([ret], np.float32), np.array([episode_step]))

    # δ = G − v̂(S); w ← w + (α / max(M, 1)) δ ∇v̂, M = ακ^w max(|δ|, 1) ‖∇v̂‖₁, κ^w = 2
    v = w @ x + b if use_baseline else 0.0
    delta = ret - v
    grad_v = np.append(x, 1.0)
    bound_v = learning_rate * 2.0 * max(abs(delta), 1.0) * np.abs(grad_v).sum()
    step_v = learning_rate / max(bound_v, 1.0)
    # θ ← θ + (α / max(M, 1)) γ^t δ ∇ln π(A|S), M = ακ^θ max(|γ^t δ|, 1) ‖∇ln π‖₁, κ^θ = 3 (S&B §13.4, eq. 13.11)
    h = theta @ x + c
    pi = np.exp(h - h.max()) / np.exp(h - h.max()).sum()
    grad_h = np.eye(2)[action] - pi  # ∇_h ln π(A|S) of the soft-max (S&B eq. 13.2)
    grad_theta, grad_c = np.outer(grad_h, x), grad_h
    weight = GAMMA**episode_step * delta
    bound_pi = learning_rate * 3.0 * max(abs(weight), 1.0) * (np.abs(grad_theta).sum() + np.abs(grad_c).sum())
    step_pi = learning_rate / max(bound_pi, 1.0)
    assert (bound_pi > 1.0) == bounded
    np.testing.assert_allclose(action_net.weight.detach().numpy(), theta + step_pi * weight * grad_theta, rtol=1e-5)
    np.testing.assert_allclose(action_net.bias.detach().numpy(), c + step_pi * weight * grad_c, rtol=1e-5)
    if use_baseline:
        assert (bound_v > 1.0) == bounded
        new_w = np.append(w, b) + step_v * delta * grad_v
        np.testing.assert_allclose(value_net.weight.detach().numpy()[0], new_w[:4], rtol=1e-5)
        np.testing.assert_allclose(value_net.bias.detach().numpy(), new_w[4:], rtol=1e-5)


def test_reinforce_streaming_networks() -> None:
    model = reinforce_streaming_model("CartPole-v1", policy_kwargs=dict(value_optimizer_kwargs=dict(kappa=1.5)))
    policy = model.policy
    networks = [cast(nn.Sequential, network) for network in (policy.mlp_extractor.policy_net, policy.mlp_extractor.value_net)]
    for network in networks:
        norms = [layer for layer in network if isinstance(layer, nn.LayerNorm)]
        assert len(norms) == 2
        assert all(norm.weight is None and norm.bias is None for norm in norms)
        # Linear, LayerNorm, activation
        assert [type(layer) for layer in list(network)[:3]] == [nn.Linear, nn.LayerNorm, nn.LeakyReLU]
    for layer in (networks[1][3], policy.action_net, policy.value_net):
        assert isinstance(layer, nn.Linear)
        zeros = (layer.weight == 0).sum(dim=1)
        assert th.equal(zeros, th.full_like(zeros, math.floor(0.9 * layer.in_features)))
    # κ: the paper's 3 for the policy (an actor), value_optimizer_kwargs' for v̂ (ObGD's own default: 2)
    assert policy.optimizer.param_groups[0]["kappa"] == 3.0
    assert policy.value_optimizer is not None
    assert policy.value_optimizer.param_groups[0]["kappa"] == 1.5
    value_optimizer = reinforce_streaming_model("CartPole-v1").policy.value_optimizer
    assert value_optimizer is not None
    assert value_optimizer.param_groups[0]["kappa"] == 2.0
    with pytest.raises(ValueError, match="pass layer_norm=True as well"):
        REINFORCE("MlpPolicy", "CartPole-v1", policy_kwargs=dict(layer_norm_kwargs=dict(elementwise_affine=False)))
    with pytest.raises(ValueError, match=r"layer_norm=True normalises the networks' hidden layers, and net_arch=\[\]"):
        REINFORCE("MlpPolicy", "CartPole-v1", policy_kwargs=dict(net_arch=[], layer_norm=True))
    # Without the options, the networks are as before: LayerNorm is not built
    plain = REINFORCE("MlpPolicy", "CartPole-v1", seed=0)
    assert not any(isinstance(layer, nn.LayerNorm) for layer in plain.policy.modules())


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(update_mode="batch"), "update_mode='batch' with optimizer_class=ObGD.*pass update_mode='per_step'"),
        (dict(ent_coef=0.01), "ent_coef=0.01 with optimizer_class=ObGD.*drop ent_coef"),
        (dict(max_grad_norm=0.5), "max_grad_norm=0.5 with optimizer_class=ObGD.*drop max_grad_norm"),
        (
            dict(policy_kwargs=dict(share_features_extractor=True)),
            r"policy_kwargs\['share_features_extractor'\]=True with optimizer_class=ObGD.*drop share_features_extractor",
        ),
    ],
)
def test_reinforce_settings_obgd_cannot_train_are_refused(kwargs: dict[str, Any], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        reinforce_streaming_model("CartPole-v1", **kwargs)


def test_reinforce_streaming_trains_on_several_envs() -> None:
    # λ = 0: no trace joins one step's update to the next, so the envs' steps may interleave
    model = reinforce_streaming_model(DummyVecEnv([lambda: ShortChain(4)] * 2), n_episodes=2)
    model.learn(200)
    assert model._n_updates > 0
    assert all(th.isfinite(p).all() for p in model.policy.parameters())


def test_reinforce_streaming_save_load_continues_as_the_original(tmp_path: Path) -> None:
    def env() -> DummyVecEnv:
        vec_env = DummyVecEnv([lambda: ShortChain(6)])
        vec_env.seed(5)
        return vec_env

    model = reinforce_streaming_model(env())
    model.learn(300)
    model.save(tmp_path / "model.zip")
    loaded = REINFORCE.load(tmp_path / "model.zip", env=env(), device="cpu")
    assert isinstance(loaded.policy.optimizer, ObGD)
    assert loaded.policy.optimizer.param_groups[0]["kappa"] == 3.0
    assert loaded.policy.value_optimizer is not None
    assert loaded.policy.value_optimizer.param_groups[0]["kappa"] == 2.0
    assert loaded.policy.layer_norm
    assert loaded.policy.weight_init == "sparse"
    # The loaded model continues as the original does, to the bit (new episodes of envs seeded alike, the same draws)
    model.set_env(env())
    for continued in (model, loaded):
        set_random_seed(7)
        continued.learn(300)
    for a, b in zip(model.policy.parameters(), loaded.policy.parameters(), strict=True):
        assert th.equal(a, b)


@pytest.mark.parametrize(
    ("algorithm", "yaml_name"), [(REINFORCE, "reinforce_streaming.yml"), (NStepSARSA, "nstep_sarsa_streaming.yml")]
)
def test_streaming_yaml_entries_build(algorithm: type[REINFORCE] | type[NStepSARSA], yaml_name: str) -> None:
    # Each entry as rl-zoo3 reads it: the zoo's own keys consumed, policy_kwargs evaluated with the YAML names in scope
    entries = yaml.safe_load((Path(__file__).resolve().parent.parent / "hyperparams" / yaml_name).read_text())
    assert {"CartPole-v1", "Acrobot-v1"} <= set(entries)
    for env_id, entry in entries.items():
        assert entry["normalize"], f"{yaml_name}, {env_id}: the recipe normalises observations and rewards"
        assert "gamma" in entry, f"{yaml_name}, {env_id}: VecNormalize's γ is the entry's gamma (the zoo passes it)"
        kwargs = {key: value for key, value in entry.items() if key not in ("n_timesteps", "n_envs", "normalize")}
        kwargs["policy_kwargs"] = eval(kwargs["policy_kwargs"], {"nn": nn, "th": th, **YAML_NAMES})
        model = algorithm(env=env_id, device="cpu", **kwargs)
        assert isinstance(model.policy.optimizer, ObGD), f"{yaml_name}, {env_id}"
