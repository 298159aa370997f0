"""Error bars of a batch: each algorithm's mean B error over seeds, with its 95 % interval.

    python examples/plot_compare.py cmp/runs.csv -o compare.png

Reads the batch's runs.csv (one row per run) and, per world and algorithm, averages the runs'
mean B translational error over the seeds; the error bar is the t-based 95 % confidence
interval of that average (seed to seed spread, not the spread of one run's relations).
"""

from __future__ import annotations

import argparse
import csv
import math
from collections import defaultdict
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from scipy import stats  # noqa: E402


def by_algorithm(rows: list[dict[str, str]], column: str) -> dict[tuple[str, str], list[float]]:
    """(world, slam) -> the runs' values of `column` (runs without one are left out)."""
    out: dict[tuple[str, str], list[float]] = defaultdict(list)
    for row in rows:
        if row.get(column):
            out[(row["world"], row["slam"])].append(float(row[column]))
    return out


def mean_ci95(values: list[float]) -> tuple[float, float]:
    """The mean and the t-based 95 % half-width (0 for a single value)."""
    n = len(values)
    mean = sum(values) / n
    if n < 2:
        return mean, 0.0
    sd = math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1))
    return mean, float(stats.t.ppf(0.975, n - 1)) * sd / math.sqrt(n)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs_csv", type=Path)
    parser.add_argument("-o", "--out", type=Path, default=Path("compare.png"))
    parser.add_argument("--column", default="b_mean_t", help="runs.csv column (b_mean_r, ...)")
    args = parser.parse_args()
    with args.runs_csv.open(newline="") as f:
        groups = by_algorithm(list(csv.DictReader(f)), args.column)
    if not groups:
        raise SystemExit(f"no run in {args.runs_csv} has a value in {args.column}")
    labels, means, halves = [], [], []
    for (world, slam), values in sorted(groups.items()):
        mean, half = mean_ci95(values)
        labels.append(f"{world}\n{slam}")
        means.append(mean)
        halves.append(half)
        print(f"{world:24s} {slam:28s} {mean:.4f} +- {half:.4f}  ({len(values)} runs)")
    fig, ax = plt.subplots(figsize=(1.6 + 1.4 * len(labels), 4))
    ax.bar(range(len(labels)), means, yerr=halves, capsize=6, color="#6a8caf")
    ax.set_xticks(range(len(labels)), labels)
    ax.set_ylabel(f"{args.column} (mean over seeds, 95 % CI)")
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
