"""
Where the per-step MLP case of issue 12 loses to the plain PyTorch loop (``benchmarks.per_step_speed``): the same
comparison, with the package's own per-step bookkeeping switched off in one variant, and the time of the torch calls
the two share (forward passes, ``backward``, the optimizer's ``zero_grad`` and ``step``) measured inside both runs.

    python -m benchmarks.diagnostics.per_step_overhead              # writes results/per-step-overhead.md
    python -m benchmarks.diagnostics.per_step_overhead --steps 8000 --repeats 7

The variant without bookkeeping is not the package's behaviour (its log, learning-rate schedule and buffer upkeep are
replaced by nothing, and the buffer is compacted every 32 steps instead of each one); it bounds what making that
bookkeeping cheaper could gain. Every run is timed from scratch, the package's and the loop's back to back with the
order alternating, as in ``per_step_speed``.
"""

import collections
import contextlib
import os
import shlex
import statistics
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import torch as th
from stable_baselines3.common.logger import Logger

from benchmarks.per_step_speed import package_mlp_sarsa, timing_arguments, torch_mlp_sarsa
from sb3_classic import NStepSARSA
from sb3_classic.common.buffers import TrajectoryBuffer

RESULTS = Path(__file__).resolve().parent / "results" / "per-step-overhead.md"


def _lazy_mark_trained(buffer: TrajectoryBuffer, trained: Any) -> None:
    """``mark_trained`` for one env without moving the rows at every step (a bound only: the rows stay 32 steps)."""
    buffer.start += trained
    if buffer.start[0] >= 32:
        buffer._drop_rows(int(buffer.start[0]))


@contextlib.contextmanager
def patched(replacements: list[tuple[type, str, Callable[..., Any]]]) -> Iterator[None]:
    """Class attributes replaced for the duration, then put back (or removed where they were inherited)."""
    saved = [(owner, name, owner.__dict__.get(name)) for owner, name, _ in replacements]
    for owner, name, function in replacements:
        setattr(owner, name, function)
    try:
        yield
    finally:
        for owner, name, original in saved:
            if original is None:
                delattr(owner, name)
            else:
                setattr(owner, name, original)


def without_bookkeeping() -> contextlib.AbstractContextManager[None]:
    """The package's per-step log (``_record_update``, ``Logger.record``), learning-rate upkeep and buffer upkeep off."""
    return patched(
        [
            (NStepSARSA, "_record_update", lambda self, *args: None),
            (NStepSARSA, "_update_learning_rates", lambda self, *args: None),
            (Logger, "record", lambda self, *args, **kwargs: None),
            (TrajectoryBuffer, "mark_trained", _lazy_mark_trained),
        ]
    )


def timing_torch_calls(totals: dict[str, float]) -> contextlib.AbstractContextManager[None]:
    """Adds the seconds spent in the torch calls both loops make to ``totals``, by name (about 0.3 µs a call more)."""

    def timed(label: str, function: Callable[..., Any]) -> Callable[..., Any]:
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            start = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                totals[label] += time.perf_counter() - start

        return wrapper

    targets: list[tuple[type, str]] = [
        (th.Tensor, "backward"),
        (th.optim.Adam, "step"),
        (th.optim.Adam, "zero_grad"),
        (th.nn.Sequential, "forward"),
    ]
    return patched([(owner, name, timed(f"{owner.__name__}.{name}", getattr(owner, name))) for owner, name in targets])


def main(argv: list[str] | None = None) -> int:
    args = timing_arguments(argv, __doc__, steps=8_000, repeats=5, output=RESULTS)
    load_before = os.getloadavg()[0]
    package_mlp_sarsa(500, 0), torch_mlp_sarsa(500, 0)  # warm-up
    rows = []
    for variant, context in (("the package", contextlib.nullcontext), ("without its bookkeeping", without_bookkeeping)):
        ratios, ours, theirs = [], [], []
        for repeat in range(args.repeats):
            runs: dict[str, float] = {}
            order = [package_mlp_sarsa, torch_mlp_sarsa]
            for train in order if repeat % 2 == 0 else order[::-1]:
                with context() if train is package_mlp_sarsa else contextlib.nullcontext():
                    start = time.perf_counter()
                    train(args.steps, repeat)
                    runs[train.__name__] = (time.perf_counter() - start) / args.steps * 1e6
            ours.append(runs["package_mlp_sarsa"])
            theirs.append(runs["torch_mlp_sarsa"])
            ratios.append(runs["torch_mlp_sarsa"] / runs["package_mlp_sarsa"])
        rows.append(
            f"| {variant} | {statistics.median(ours):.0f} | {statistics.median(theirs):.0f} "
            f"| {statistics.median(ratios):.2f}× ({min(ratios):.2f}–{max(ratios):.2f}) |"
        )
        print(rows[-1], flush=True)
    # The torch calls both make, inside one run of each (seed 0)
    shares = []
    for train in (package_mlp_sarsa, torch_mlp_sarsa):
        totals: dict[str, float] = collections.defaultdict(float)
        with timing_torch_calls(totals):
            start = time.perf_counter()
            train(args.steps, 0)
            total = (time.perf_counter() - start) / args.steps * 1e6
        calls = {name: seconds / args.steps * 1e6 for name, seconds in totals.items()}
        shared = sum(calls.values())
        shares.append(
            f"| {'`NStepSARSA` per step' if train is package_mlp_sarsa else 'PyTorch loop'} | {total:.0f} "
            f"| {calls['Sequential.forward']:.0f} | {calls['Tensor.backward']:.0f} | {calls['Adam.zero_grad']:.0f} "
            f"| {calls['Adam.step']:.0f} | {total - shared:.0f} |"
        )
        print(shares[-1], flush=True)
    load = f"load average {load_before:.1f} before, {os.getloadavg()[0]:.1f} after, on {os.cpu_count()} cores"
    command = "python -m benchmarks.diagnostics.per_step_overhead " + shlex.join(sys.argv[1:] if argv is None else argv)
    text = f"""# Issue 12: where the per-step MLP case loses to the PyTorch loop

Produced by:

```
{command.strip()}
```

torch {th.__version__}, 1 thread ({load}); {args.steps:,} env steps of training from scratch per run, {args.repeats}
repeats, the package and the loop back to back (order alternating). The settings are `benchmarks.per_step_speed`'s
(CartPole-v1, a 2 × 128 MLP, Adam, n = 1, ε = 0.1, one update per step). Ratio: the package's steps/s over the loop's
of the same repeat, median (min–max).

| `NStepSARSA` | package (µs per env step) | PyTorch loop (µs per env step) | ratio |
|---|---|---|---|
{chr(10).join(rows)}

"Without its bookkeeping" replaces the package's per-step log (`_record_update`, SB3's `Logger.record`), its
learning-rate upkeep and its buffer's row moves by nothing: what they cost is the difference between the two rows.

The torch calls both make, in one run of each (µs per env step; "the rest" is everything else: the env and SB3's
`DummyVecEnv` and `Monitor`, choosing the action, the callbacks, the buffer, the log, the loss):

| | total | forward passes | `backward` | `zero_grad` | `Adam.step` | the rest |
|---|---|---|---|---|---|---|
{chr(10).join(shares)}

The loop makes three forward passes per step (one to act, one for its bootstrap, one with gradient) and its Adam has
no fused kernel; the package makes two (it bootstraps from the rollout's) with PyTorch's fused Adam. It wins those,
and loses more in the rest: SB3's per-step machinery (the VecEnv and its Monitor, the callbacks' locals, SB3's
`QNetwork` and `preprocess_obs` around the MLP) and its own duties (the buffer, the ε schedule, the log).
"""
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(text)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
