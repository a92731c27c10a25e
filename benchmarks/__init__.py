"""
Benchmarks of sb3_classic: learning curves of REINFORCE and NStepSARSA against SB3's A2C, PPO and DQN on the
rl-zoo3 harness, and the throughput of ``learn()``. Run ``python -m benchmarks.run`` (see benchmarks/README.md).
"""
