"""
The policies' speed paths (fused Adam by default, REINFORCE's sampler of the rollout loop) and policies of the user's:
subclasses' distributions, ``forward``, ``make_q_net`` and ``predict``, features extractors, and layers of their own in
eval mode for ``predict``.
"""

from operator import attrgetter
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from recorders import RecordLocal
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.distributions import Distribution
from stable_baselines3.common.envs import IdentityEnvBox, SimpleMultiObsEnv
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.dqn.policies import QNetwork
from torch import nn

from sb3_classic import REINFORCE, NStepSARSA
from sb3_classic.common.torch_layers import optimizer_kwargs_with_defaults
from sb3_classic.reinforce.policies import REINFORCEPolicy
from sb3_classic.sarsa.policies import SARSAPolicy

MODEL_LIST = [REINFORCE, NStepSARSA]


def observation_batch(space: gym.spaces.Space, n: int) -> np.ndarray | dict[str, np.ndarray]:
    space.seed(0)
    samples = [space.sample() for _ in range(n)]
    if isinstance(space, gym.spaces.Dict):
        return {key: np.stack([sample[key] for sample in samples]) for key in space.spaces}
    return np.stack(samples)


def optimizers(model: REINFORCE | NStepSARSA) -> list[th.optim.Optimizer]:
    """Every optimizer the model saves (the same list save/load relies on)."""
    return [attrgetter(name)(model) for name in model._get_torch_save_params()[0] if name.endswith("optimizer")]


@pytest.mark.parametrize("model_class", MODEL_LIST)
def test_adam_is_fused_unless_the_user_chooses(model_class: type[Any]) -> None:
    model = model_class("MlpPolicy", "CartPole-v1", device="cpu")
    assert [optimizer.defaults["fused"] for optimizer in optimizers(model)] == [True] * len(optimizers(model))
    # The policy keeps (and saves) the arguments as given; the default is applied when building the optimizers
    assert "fused" not in model.policy.optimizer_kwargs

    chosen = model_class("MlpPolicy", "CartPole-v1", device="cpu", policy_kwargs=dict(optimizer_kwargs=dict(foreach=True)))
    for optimizer in optimizers(chosen):
        assert optimizer.defaults["foreach"] is True
        assert not optimizer.defaults["fused"]
    # Choosing the implementation leaves Adam's eps alone (REINFORCE's was SB3's 1e-5 only without optimizer_kwargs)
    default_eps = {optimizer.defaults["eps"] for optimizer in optimizers(model)}
    assert {optimizer.defaults["eps"] for optimizer in optimizers(chosen)} == default_eps
    own_eps = model_class(
        "MlpPolicy", "CartPole-v1", device="cpu", policy_kwargs=dict(optimizer_kwargs=dict(fused=False, eps=1e-3))
    )
    assert {optimizer.defaults["eps"] for optimizer in optimizers(own_eps)} == {1e-3}
    sgd = model_class("MlpPolicy", "CartPole-v1", device="cpu", policy_kwargs=dict(optimizer_class=th.optim.SGD))
    for optimizer in optimizers(sgd):
        assert isinstance(optimizer, th.optim.SGD)
        assert not optimizer.defaults["fused"]


@pytest.mark.parametrize("optimizer_class", [th.optim.Adam, th.optim.AdamW])
def test_fused_adam_takes_the_same_steps(optimizer_class: type[th.optim.Adam]) -> None:
    th.manual_seed(0)
    nets = [th.nn.Linear(6, 3), th.nn.Linear(6, 3)]
    nets[1].load_state_dict(nets[0].state_dict())
    initial = nets[0].weight.detach().clone()
    built = [
        optimizer_class(nets[0].parameters(), lr=1e-2, **optimizer_kwargs_with_defaults(optimizer_class, None)),
        optimizer_class(nets[1].parameters(), lr=1e-2, foreach=False),
    ]
    assert built[0].defaults["fused"] is True
    inputs = th.randn(32, 6)
    for _ in range(20):
        for net, optimizer in zip(nets, built, strict=True):
            optimizer.zero_grad()
            (net(inputs) ** 2).mean().backward()
            optimizer.step()
    for fused, looped in zip(nets[0].parameters(), nets[1].parameters(), strict=True):
        th.testing.assert_close(fused, looped, rtol=1e-5, atol=1e-6)
    # The steps moved the weights (the comparison is not of two untouched networks)
    assert (nets[0].weight - initial).abs().max() > 1e-2


@pytest.mark.parametrize(
    ("env", "policy", "policy_kwargs"),
    [
        (lambda: gym.make("Acrobot-v1"), "MlpPolicy", {}),
        (lambda: gym.make("Acrobot-v1"), "MlpPolicy", dict(share_features_extractor=True)),
        (lambda: SimpleMultiObsEnv(random_start=True), "MultiInputPolicy", {}),
        (lambda: IdentityEnvBox(ep_length=20), "MlpPolicy", {}),
    ],
)
def test_reinforce_samples_as_sb3_distributions_do(env: Any, policy: str, policy_kwargs: dict[str, Any]) -> None:
    model = REINFORCE(policy, env(), policy_kwargs=policy_kwargs, seed=0, device="cpu")
    # A trained-looking policy: logits far from uniform, so that a wrong probability shows in the draws
    with th.no_grad():
        for parameter in model.policy.action_net.parameters():
            parameter.mul_(20.0)
    obs, _ = model.policy.obs_to_tensor(observation_batch(model.observation_space, 64))
    draws, differing = set(), 0
    for seed in range(50):
        with th.no_grad():
            th.manual_seed(seed)
            ours = model.policy.sample_actions(obs)
            th.manual_seed(seed)
            sb3 = model.policy.get_distribution(obs).get_actions()
        differing += int((ours != sb3).sum())
        draws.add(ours.numpy().tobytes())
    # The same multinomial draws, of probabilities computed two ways (SB3's soft-max of the normalised logits, up to
    # 6e-8 from ours, by exp and sums that round otherwise on other CPUs): a draw differs only where its uniform falls
    # that close to a boundary (one run in 5,000 would see one); logits 1% off change two of these 3,200
    assert differing <= 1, f"{differing} of {50 * len(ours)} draws differ from SB3's"
    assert len(draws) > 1  # random, not the greedy action


def actions_taken(model: REINFORCE | NStepSARSA, total_timesteps: int) -> list[int]:
    """:return: the actions of the rollout loop (``locals["actions"]``) of ``model.learn(total_timesteps)``"""
    taken: list[int] = []

    class Actions(BaseCallback):
        def _on_step(self) -> bool:
            taken.extend(np.asarray(self.locals["actions"]).ravel().tolist())
            return True

    model.learn(total_timesteps, callback=Actions())
    return taken


class NeverAction1(REINFORCEPolicy):
    """A policy that masks action 1 through SB3's hook of the action distribution (as action masking does)."""

    def _get_action_dist_from_latent(self, latent_pi: th.Tensor) -> Distribution:
        logits = self.action_net(latent_pi)
        mask = th.zeros_like(logits)
        mask[:, 1] = -1e9
        return self.action_dist.proba_distribution(action_logits=logits + mask)


def test_reinforce_rollouts_draw_from_a_subclass_distribution() -> None:
    # The rollout's fast draw rebuilt the logits itself: it took action 1 about half the time, which the policy gives
    # probability e^-1e9 (A2C's rollouts honour the hook)
    model = REINFORCE(NeverAction1, "CartPole-v1", seed=0, device="cpu")
    taken = actions_taken(model, 300)
    assert len(taken) >= 300
    assert set(taken) == {0}
    assert not model.policy._sb3_distribution
    assert REINFORCE("MlpPolicy", "CartPole-v1", device="cpu").policy._sb3_distribution


class PretrainedExtractor(BaseFeaturesExtractor):
    """A features extractor of the user's, built with weights of its own (pretrained ones, say)."""

    def __init__(self, observation_space: gym.spaces.Box) -> None:
        super().__init__(observation_space, features_dim=8)
        self.layer = th.nn.Linear(4, 8)
        with th.no_grad():
            self.layer.weight.fill_(0.01)
            self.layer.bias.fill_(0.5)

    def forward(self, observations: th.Tensor) -> th.Tensor:
        return th.relu(self.layer(observations))


@pytest.mark.parametrize(
    ("model_class", "kwargs"),
    [
        (NStepSARSA, {}),  # the default weight_init="kaiming"
        (NStepSARSA, dict(weight_init="orthogonal")),
        (NStepSARSA, dict(with_bias=False)),
        (REINFORCE, dict(weight_init="kaiming")),
        (REINFORCE, dict(with_bias=False, weight_init="default")),
        (NStepSARSA, dict(net_arch=[], weight_init=0.0)),
        (REINFORCE, dict(net_arch=[], weight_init=0.0)),
    ],
)
def test_a_users_features_extractor_keeps_its_weights(model_class: type[Any], kwargs: dict[str, Any]) -> None:
    # SARSA's default Kaiming scheme re-initialised it (DQN leaves it alone), REINFORCE's with_bias=False removed its
    # biases, and a constant weight_init was refused for its layer
    policy_kwargs = dict(features_extractor_class=PretrainedExtractor, **kwargs)
    model = model_class("MlpPolicy", "CartPole-v1", policy_kwargs=policy_kwargs, device="cpu")
    extractors = [module for module in model.policy.modules() if isinstance(module, PretrainedExtractor)]
    assert extractors
    for extractor in extractors:
        assert th.all(extractor.layer.weight == 0.01)
        assert extractor.layer.bias is not None
        assert th.all(extractor.layer.bias == 0.5)
    # The networks built here do take the scheme: no bias anywhere else, or the constant
    others = [layer for layer in model.policy.modules() if isinstance(layer, th.nn.Linear)]
    others = [layer for layer in others if not any(layer is extractor.layer for extractor in extractors)]
    if kwargs.get("with_bias") is False:
        assert all(layer.bias is None for layer in others)
    if kwargs.get("weight_init") == 0.0:
        assert all(th.all(layer.weight == 0.0) for layer in others)


class SmallTanhQ(SARSAPolicy):
    """A Q-network of the user's through DQN's hook: 4-7-2 with Tanh."""

    def make_q_net(self) -> QNetwork:
        extractor = self.make_features_extractor()
        return QNetwork(self.observation_space, self.action_space, extractor, extractor.features_dim, [7], th.nn.Tanh)


def test_sarsa_builds_the_network_of_a_subclass_make_q_net() -> None:
    # SARSA built its default 64-64 network whatever make_q_net returned (DQN builds the subclass's)
    model = NStepSARSA(SmallTanhQ, "CartPole-v1", seed=0, device="cpu")
    linears = [layer for layer in model.policy.q_net.modules() if isinstance(layer, th.nn.Linear)]
    assert [layer.out_features for layer in linears] == [7, 2]
    assert any(isinstance(layer, th.nn.Tanh) for layer in model.policy.q_net.modules())
    before = [param.clone() for param in model.policy.q_net.parameters()]
    model.learn(200)
    trained = {id(param) for group in model.policy.optimizer.param_groups for param in group["params"]}
    assert trained == {id(param) for param in model.policy.q_net.parameters()}
    assert any(not th.equal(a, b) for a, b in zip(before, model.policy.q_net.parameters(), strict=True))


class TrunkAndHeads(th.nn.Module):
    """An mlp_extractor of SB3's custom-policy shape, with its parts named otherwise (actor, critic)."""

    def __init__(self, features_dim: int) -> None:
        super().__init__()
        self.latent_dim_pi = self.latent_dim_vf = 8
        self.actor, self.critic = th.nn.Linear(features_dim, 8), th.nn.Linear(features_dim, 8)

    def forward(self, features: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        return self.forward_actor(features), self.forward_critic(features)

    def forward_actor(self, features: th.Tensor) -> th.Tensor:
        return self.actor(features)

    def forward_critic(self, features: th.Tensor) -> th.Tensor:
        return self.critic(features)


class OtherNames(REINFORCEPolicy):
    def _build_mlp_extractor(self) -> None:
        self.mlp_extractor = TrunkAndHeads(self.features_dim)  # type: ignore[assignment]


def test_an_mlp_extractor_without_sb3s_names_is_named() -> None:
    # AttributeError: 'TrunkAndHeads' object has no attribute 'value_net', from deep in the policy's constructor
    with pytest.raises(TypeError, match=r"mlp_extractor=TrunkAndHeads .* has no policy_net: .* name its two parts so"):
        REINFORCE(OtherNames, "CartPole-v1", device="cpu")


class AlwaysAction1(SARSAPolicy):
    """A greedy policy of the user's: action 1 whatever q̂ says (as action masking overrides _predict in DQN)."""

    def _predict(self, observation: Any, deterministic: bool = True) -> th.Tensor:
        return th.ones(len(observation), dtype=th.int64)


def test_sarsa_behaviour_policy_is_greedy_in_a_subclass_predict() -> None:
    # The rollout took q̂'s argmax whatever the subclass said (with ε = 0); DQN's ε-greedy takes the policy's _predict
    model = NStepSARSA(
        AlwaysAction1, "CartPole-v1", exploration_initial_eps=0.0, exploration_final_eps=0.0, seed=0, device="cpu"
    )
    taken = actions_taken(model, 300)
    assert len(taken) >= 300
    assert set(taken) == {1}


class NoisyLinear(nn.Linear):
    """A NoisyNet-like output layer: noisy weights in train mode only (it reads ``self.training``)."""

    def forward(self, x: th.Tensor) -> th.Tensor:
        weight = self.weight + 0.5 * th.randn_like(self.weight) if self.training else self.weight
        return nn.functional.linear(x, weight, self.bias)


class NoisySARSAPolicy(SARSAPolicy):
    def make_q_net(self) -> QNetwork:
        q_net = super().make_q_net()
        output = q_net.q_net[-1]
        assert isinstance(output, nn.Linear)
        q_net.q_net[-1] = NoisyLinear(output.in_features, output.out_features)
        return q_net


def test_a_layer_of_the_users_is_put_in_eval_mode_for_predict() -> None:
    # set_training_mode flips every module's flag, not only where dropout or batch norm is found: otherwise the
    # NoisyNet layer would stay in train mode, and predict(deterministic=True) would be random (DQN's is not)
    model = NStepSARSA(NoisySARSAPolicy, "CartPole-v1", seed=0, device="cpu")
    model.learn(100)
    obs = np.array([0.01, 0.0, 0.01, 0.0], dtype=np.float32)
    assert len({int(model.predict(obs, deterministic=True)[0]) for _ in range(30)}) == 1
    assert not model.policy.q_net.q_net[-1].training
    model.policy.set_training_mode(True)
    assert model.policy.q_net.q_net[-1].training
    # SB3's plain layers keep the shortcut; RReLU's slopes are random in train mode
    assert not NStepSARSA("MlpPolicy", "CartPole-v1", device="cpu").policy.mode_dependent
    rrelu = NStepSARSA("MlpPolicy", "CartPole-v1", policy_kwargs=dict(activation_fn=nn.RReLU), device="cpu")
    assert rrelu.policy.mode_dependent


def test_make_q_net_must_return_a_qnetwork() -> None:
    class Plain(SARSAPolicy):
        def make_q_net(self) -> Any:
            return nn.Sequential(nn.Linear(4, 2))

    # (AttributeError: 'Sequential' object has no attribute 'features_extractor')
    with pytest.raises(TypeError, match="make_q_net returned a Sequential: Plain needs an SB3 QNetwork"):
        NStepSARSA(Plain, "CartPole-v1", device="cpu")


def test_reinforce_acts_with_a_subclass_forward() -> None:
    # A2C's rollouts act with policy(obs)'s actions; REINFORCE drew from the distribution, ignoring the override
    class AlwaysOne(REINFORCEPolicy):
        def forward(self, obs: th.Tensor, deterministic: bool = False) -> tuple[th.Tensor, th.Tensor, th.Tensor]:
            actions, values, log_prob = super().forward(obs, deterministic)
            return th.ones_like(actions), values, log_prob

    actions = RecordLocal("actions")
    REINFORCE(AlwaysOne, "CartPole-v1", seed=0, device="cpu").learn(300, callback=actions)
    assert set(np.concatenate(actions.values).tolist()) == {1}


class ModeRecordingExtractor(BaseFeaturesExtractor):
    """A features extractor with BatchNorm that records, for each forward pass, its mode and whether autograd was on."""

    def __init__(self, observation_space: gym.spaces.Box) -> None:
        super().__init__(observation_space, features_dim=8)
        self.net = nn.Sequential(nn.Linear(int(np.prod(observation_space.shape)), 8), nn.BatchNorm1d(8), nn.ReLU())
        self.calls: list[tuple[bool, bool, int]] = []

    def forward(self, observations: th.Tensor) -> th.Tensor:
        self.calls.append((self.training, th.is_grad_enabled(), len(observations)))
        return self.net(observations)


@pytest.mark.parametrize("model_class", MODEL_LIST)
@pytest.mark.parametrize("truncations_per_update", [1, 3])
def test_values_that_are_no_loss_are_computed_in_eval_mode(model_class: type[Any], truncations_per_update: int) -> None:
    # The bootstrap values of time-limit truncations (v̂(S_T), q̂ at the final state) are no training batch: with one
    # truncation a BatchNorm in training mode raises "Expected more than 1 value per channel when training", with
    # several its running statistics move on them. A2C/PPO and DQN compute such values in eval mode.
    env = gym.make("CartPole-v1", max_episode_steps=5)  # (CartPole's first 5 steps never terminate)
    k = truncations_per_update
    kwargs: dict[str, Any] = dict(n_episodes=k) if model_class is REINFORCE else dict(n_steps=1, train_freq=5 * k)
    model = model_class(
        "MlpPolicy", env, policy_kwargs=dict(features_extractor_class=ModeRecordingExtractor), seed=0, device="cpu", **kwargs
    )
    model.learn(40)
    extractors = {id(module): module for module in model.policy.modules() if isinstance(module, ModeRecordingExtractor)}
    calls = [call for extractor in extractors.values() for call in extractor.calls]
    assert any(grad for _, grad, _ in calls), "no gradient step ran"
    assert any(not grad for _, grad, _ in calls)
    for training, grad, size in calls:
        # Training mode exactly for the loss's own forward passes (autograd on)
        assert training == grad, f"a forward pass of {size} states with autograd {grad} ran in training mode {training}"
