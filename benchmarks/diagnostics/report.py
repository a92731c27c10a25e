"""
The tables of the diagnostic studies, from their cache, into ``benchmarks/diagnostics/results/``:

    python -m benchmarks.diagnostics.report

``sarsa.md``: the issue's metrics of every NStepSARSA variant, then per variant the probes of its evaluations (mean
over seeds, every 20k steps). ``reinforce.md``: the same for REINFORCE, each variant's first successes, and the seed
scan (30k steps, no evaluations).
"""

import json
from pathlib import Path

from benchmarks.diagnostics import reinforce_acrobot, sarsa_acrobot
from benchmarks.diagnostics.common import DIAGNOSTICS_CACHE, collect, metrics_table, probe_table, variant_metrics

RESULTS_DIR = Path(__file__).resolve().parent / "results"


def seed_scan_table(folder: Path) -> str:
    """:return: per seed of the scan, its training episodes in 30k steps and the final evaluation"""
    lines = ["| Seed | Training episodes in 30k steps | Successful (< 500 steps) | Final eval |", "|---|---|---|---|"]
    runs = sorted(folder.glob("seed_*-30000-eval1000000"), key=lambda path: int(path.name.split("-")[0][5:]))
    for path in runs:
        summary = json.loads((path / "run.json").read_text())
        episodes = summary["n_episodes"]
        # Every unsuccessful episode is 500 steps: episodes beyond 30000/500 = 60 come from successful ones
        lines.append(
            f"| {summary['seed']} | {episodes} | {'none' if episodes <= 60 else '≥ 1'} | {summary['final_return']:.1f} |"
        )
    return "\n".join(lines)


def main() -> None:
    """Write the two studies' tables."""
    RESULTS_DIR.mkdir(exist_ok=True)
    for module, study, algo in ((sarsa_acrobot, "sarsa", "nstep_sarsa"), (reinforce_acrobot, "reinforce", "reinforce")):
        found = collect(study, algo, "Acrobot-v1", module.VARIANTS, 200_000)
        sections = [
            f"# {study}: Acrobot-v1, 200k steps (written by `python -m benchmarks.diagnostics.report`)",
            metrics_table([variant_metrics(name, runs) for name, runs in found.items()]),
        ]
        for name, runs in found.items():
            sections.append(f"## {name} (seeds {', '.join(map(str, runs))})\n\n{probe_table(runs, module.PROBE_COLUMNS)}")
            if module is reinforce_acrobot:
                sections.append(reinforce_acrobot.first_success_table(runs))
        if module is reinforce_acrobot:
            scan = DIAGNOSTICS_CACHE / study / "Acrobot-v1" / "yaml"
            sections.append(f"## Seed scan (YAML settings, 30k steps)\n\n{seed_scan_table(scan)}")
        (RESULTS_DIR / f"{study}.md").write_text("\n\n".join(sections) + "\n")
        print(RESULTS_DIR / f"{study}.md")


if __name__ == "__main__":
    main()
