"""The parameter digest of ``benchmarks/digest.py``: it sees a change of one ulp, and a seeded run repeats it."""

import json
from pathlib import Path

import numpy as np
import pytest
import torch as th

from benchmarks import digest as digest_tool
from benchmarks.lockstep import population_of
from sb3_classic import NStepSARSA
from sb3_classic.common.obgd import ObGD


def one_ulp_up(value: float) -> float:
    return float(np.nextafter(np.float32(value), np.float32(np.inf)))


def test_a_one_ulp_change_of_one_parameter_changes_the_digest() -> None:
    model = NStepSARSA("MlpPolicy", "CartPole-v1", policy_kwargs=dict(net_arch=[8]), seed=0, device="cpu")
    before = digest_tool.digest(model)
    weight = next(model.policy.parameters())
    with th.no_grad():
        original = float(weight[0, 0])
        weight[0, 0] = one_ulp_up(original)
        assert float(weight[0, 0]) != original
        changed = digest_tool.digest(model)
        weight[0, 0] = original
    assert changed != before
    assert digest_tool.digest(model) == before
    # ... and of the optimizer's state
    model.policy.optimizer.param_groups[0]["lr"] = np.nextafter(model.policy.optimizer.param_groups[0]["lr"], 1.0)
    assert digest_tool.digest(model) != before


def test_a_one_ulp_change_of_a_logged_value_changes_the_digest() -> None:
    model = NStepSARSA("MlpPolicy", "CartPole-v1", policy_kwargs=dict(net_arch=[8]), seed=0, device="cpu")
    log = digest_tool.TrainLog()
    log.write({"train/loss": 0.125, "rollout/ep_rew_mean": 9.0}, {})
    changed = digest_tool.TrainLog()
    changed.write({"train/loss": np.nextafter(0.125, 1.0), "rollout/ep_rew_mean": 9.0}, {})
    assert log.dumps == [{"train/loss": (0.125).hex()}]  # (train/ keys only: rollout/ values are the envs')
    assert digest_tool.digest(model, log.dumps) != digest_tool.digest(model, changed.dumps)


def test_a_seeded_configuration_repeats_its_digest_and_check_finds_a_difference(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    name = "reinforce-per-step"
    saved = tmp_path / "digests.json"
    assert digest_tool.main(["--only", name, "--save", str(saved)]) == 0
    assert digest_tool.main(["--only", name, "--check", str(saved)]) == 0
    assert "1 of 1 digests as in" in capsys.readouterr().out
    digests = json.loads(saved.read_text())
    digests[name] = "0" * 64
    saved.write_text(json.dumps(digests))
    assert digest_tool.main(["--only", name, "--check", str(saved)]) == 1
    out = capsys.readouterr().out
    assert f"{name}: " in out
    # Written on this machine: a difference is the code's, and nothing is said of machines
    assert digests[digest_tool.MACHINE] == digest_tool.machine()
    assert "was written on" not in out
    # Written on another CPU: the check says so, naming both
    digests[digest_tool.MACHINE] = "Another CPU (x86_64), torch 0.0, numpy 0.0"
    saved.write_text(json.dumps(digests))
    assert digest_tool.main(["--only", name, "--check", str(saved)]) == 1
    out = capsys.readouterr().out
    assert f"was written on Another CPU (x86_64), torch 0.0, numpy 0.0; this is {digest_tool.machine()}" in out


def test_the_configurations_cover_both_algorithms_and_both_update_modes() -> None:
    built = {name: make()[0] for name, make in digest_tool.CONFIGURATIONS.items()}
    modes = {(type(model).__name__, model.update_mode) for model in built.values()}
    assert modes == {("NStepSARSA", "batch"), ("NStepSARSA", "per_step"), ("REINFORCE", "batch"), ("REINFORCE", "per_step")}
    assert {model.n_envs for model in built.values()} == {1, 8}
    # ... and the streaming recipe's ObGD steps of both (SARSA(λ)'s traces, REINFORCE's bounded per-step updates)
    assert {type(model).__name__ for model in built.values() if isinstance(model.policy.optimizer, ObGD)} == {
        "NStepSARSA",
        "REINFORCE",
    }


def test_the_populations_cover_both_algorithms_and_both_update_modes_in_lockstep() -> None:
    modes = set()
    for name, make in digest_tool.POPULATIONS.items():
        models = [make(seed)[0] for seed in digest_tool.POPULATION_SEEDS]
        # (a population's own check: a setting it does not cover would train alone, not in lockstep)
        population_of(models)
        assert [model.seed for model in models] == list(digest_tool.POPULATION_SEEDS), name
        modes.add((type(models[0]).__name__, models[0].update_mode))
    assert modes == {("NStepSARSA", "batch"), ("NStepSARSA", "per_step"), ("REINFORCE", "batch"), ("REINFORCE", "per_step")}


def test_a_population_digest_repeats_and_depends_on_every_member(monkeypatch: pytest.MonkeyPatch) -> None:
    name = "population-reinforce-per-step"
    first = digest_tool.population_digest(name)
    assert digest_tool.population_digest(name) == first
    # Another seed for the last member only: its training differs, so the digest does
    monkeypatch.setattr(digest_tool, "POPULATION_SEEDS", (0, 1, 3))
    assert digest_tool.population_digest(name) != first
