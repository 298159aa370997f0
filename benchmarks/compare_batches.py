"""Same science? Two batch folders of the same worlds and seeds (`mapqual batch ... -o A` and
`-o B`, made by two checkouts or two settings) compared run by run: the proof issue 21 asks of
a change that alters the numbers.

    python benchmarks/compare_batches.py BATCH_A BATCH_B [--confidence 0.95]

Runs are paired by (world, variant, noise, slam, seed) from each folder's runs.csv. For the
mean A, B and SM errors (translational and rotational), over the pairs where both runs have
the figure: the mean of A - B with its paired-t interval (worker.batch.paired.mean_ci) and the
two-sided p of the Wilcoxon signed-rank test (scipy), and the verdict "no clear difference"
when the interval holds zero; the same for the coverage and the simulated duration (issue 52).
For the outcome: completed and "good" (completed and under the thesis's visually-good
thresholds) counts, and the pairs where only one of the two succeeded, with McNemar's exact
two-sided p (a binomial test on those discordant pairs). Exit 0; 2 on bad input.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from pathlib import Path

from scipy import stats

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from worker.batch.paired import mean_ci  # noqa: E402
from worker.batch.tables import RUN_LABELS  # noqa: E402

METRICS = tuple(
    (f"{kind} {axis}", f"{prefix}_mean_{suffix}", unit)
    for kind, prefix in (("B", "b"), ("A", "a"), ("SM", "sm"))
    for axis, suffix, unit in (("trans.", "t", "m"), ("rot.", "r", "rad"))
) + (("coverage", "coverage", "share"), ("duration", "sim_time_s", "s simulated"))


def _runs(folder: Path) -> dict[tuple, dict[str, str]]:
    path = folder / "runs.csv"
    if not path.is_file():
        raise SystemExit(f"compare_batches: {folder} has no runs.csv (run `mapqual batch` first)")
    with path.open(newline="") as f:
        return {tuple(row[k] for k in RUN_LABELS): row for row in csv.DictReader(f)}


def _float(text: str | None) -> float | None:
    try:
        v = float(text) if text not in (None, "") else None
    except ValueError:
        return None
    return v if v is not None and math.isfinite(v) else None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a", type=Path, help="batch folder A")
    ap.add_argument("b", type=Path, help="batch folder B")
    ap.add_argument("--confidence", type=float, default=0.95)
    args = ap.parse_args()
    if not 0 < args.confidence < 1:
        ap.error("--confidence must be in (0, 1)")
    ra, rb = _runs(args.a), _runs(args.b)
    keys = sorted(set(ra) & set(rb))
    if not keys:
        raise SystemExit("compare_batches: the two batches share no (world, seed) run")
    print(f"{len(keys)} paired runs ({len(ra)} in A, {len(rb)} in B); A = {args.a}, B = {args.b}")
    print(f"{'figure':10} {'n':>3} {'mean A':>9} {'mean B':>9} {'A - B':>9} "
          f"{'interval':>21} {'Wilcoxon p':>10}  verdict")  # fmt: skip
    for name, col, unit in METRICS:
        pairs = [(_float(ra[k][col]), _float(rb[k][col])) for k in keys]
        pairs = [(x, y) for x, y in pairs if x is not None and y is not None]
        if len(pairs) < 2:
            print(f"{name:10} {len(pairs):>3}  too few pairs")
            continue
        d = [x - y for x, y in pairs]
        mean, lo, hi = mean_ci(d, args.confidence)
        p = stats.wilcoxon(d).pvalue if any(v != 0 for v in d) else 1.0
        verdict = "A lower" if hi < 0 else "B lower" if lo > 0 else "no clear difference"
        ma = sum(x for x, _ in pairs) / len(pairs)
        mb = sum(y for _, y in pairs) / len(pairs)
        print(f"{name:10} {len(pairs):>3} {ma:9.4f} {mb:9.4f} {mean:+9.4f} "
              f"[{lo:+.4f}, {hi:+.4f}] {p:10.3f}  {verdict} ({unit})")  # fmt: skip
    for label, test in (
        ("completed", lambda r: r["outcome"] == "completed"),
        ("good", lambda r: r["good"] == "true"),
    ):
        sa = [test(ra[k]) for k in keys]
        sb = [test(rb[k]) for k in keys]
        only_a = sum(x and not y for x, y in zip(sa, sb, strict=True))
        only_b = sum(y and not x for x, y in zip(sa, sb, strict=True))
        n = only_a + only_b
        p = stats.binomtest(only_a, n, 0.5).pvalue if n else 1.0
        print(f"{label:10} A {sum(sa)}/{len(keys)}, B {sum(sb)}/{len(keys)}; only A {only_a}, "
              f"only B {only_b}: McNemar exact p {p:.3f}")  # fmt: skip


if __name__ == "__main__":
    main()
