"""The statistics a study report states: Wilson 95% intervals on success rates (sound at the
few seeds a study flies, unlike the normal approximation) and paired per-seed comparisons of two
controllers flown on the same seeds (McNemar's exact test: a two-sided binomial test on the
discordant seeds, those where exactly one of the two succeeded; Wilcoxon's signed-rank test on a
continuous metric's paired differences)."""
from __future__ import annotations

import math
from dataclasses import dataclass

Z95 = 1.959963984540054            # two-sided 95% normal quantile


def wilson(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (lo, hi); (0, 1) for n = 0."""
    if n <= 0:
        return 0.0, 1.0
    p = successes / n
    d = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / d
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return max(0.0, centre - half), min(1.0, centre + half)


@dataclass(frozen=True)
class Paired:
    """Two controllers on the seeds both flew: counts of each outcome and McNemar's exact p."""

    a: str
    b: str
    seeds: int
    both: int
    only_a: int
    only_b: int
    neither: int

    @property
    def p_value(self) -> float:
        """McNemar's exact two-sided p-value (1.0 with no discordant seed)."""
        k, n = self.only_a, self.only_a + self.only_b
        if n == 0:
            return 1.0
        from scipy.stats import binomtest
        return float(binomtest(k, n, 0.5, alternative="two-sided").pvalue)


def paired(a: str, b: str, outcome_a: dict[int, bool], outcome_b: dict[int, bool]) -> Paired | None:
    """The paired comparison of a and b over the seeds both flew (seed -> success); None when
    they share no seed."""
    seeds = sorted(set(outcome_a) & set(outcome_b))
    if not seeds:
        return None
    pairs = [(outcome_a[s], outcome_b[s]) for s in seeds]
    return Paired(a, b, len(seeds), sum(x and y for x, y in pairs),
                  sum(x and not y for x, y in pairs), sum(y and not x for x, y in pairs),
                  sum(not x and not y for x, y in pairs))


@dataclass(frozen=True)
class SignedRank:
    """A continuous metric of two controllers on the seeds where both have a value: the median
    of the paired differences (b - a) and Wilcoxon's signed-rank two-sided p."""

    n: int
    median_diff: float
    p_value: float


def signed_rank(a: dict[int, float], b: dict[int, float]) -> SignedRank | None:
    """Wilcoxon's signed-rank test of b - a over the seeds both have a finite value of (seed ->
    value); None without such a seed. Zero differences are dropped (Wilcoxon's rule); p is 1.0
    when every difference is zero."""
    seeds = sorted(s for s in set(a) & set(b) if math.isfinite(a[s]) and math.isfinite(b[s]))
    if not seeds:
        return None
    d = [b[s] - a[s] for s in seeds]
    ds = sorted(d)
    n = len(ds)
    med = ds[n // 2] if n % 2 else 0.5 * (ds[n // 2 - 1] + ds[n // 2])
    if not any(x != 0 for x in d):
        return SignedRank(n, med, 1.0)
    from scipy.stats import wilcoxon
    return SignedRank(n, med, float(wilcoxon(d, zero_method="wilcox",
                                              alternative="two-sided").pvalue))
