"""Statistics shared by training, evaluation and the label reports: AUROC, error summaries and binomial
confidence intervals."""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def auroc(scores: Sequence[float] | np.ndarray, labels: Sequence[bool] | np.ndarray) -> float | None:
    """Area under the ROC curve of ``scores`` for binary ``labels`` (Mann-Whitney U, tied scores share their
    average rank); None when only one class is present."""
    s = np.asarray(scores, dtype=float).reshape(-1)
    y = np.asarray(labels, dtype=float).reshape(-1) > 0.5
    n_pos, n_neg = int(y.sum()), int((~y).sum())
    if not n_pos or not n_neg:
        return None
    _, inv, counts = np.unique(s, return_inverse=True, return_counts=True)
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])  # rank - 1 of each distinct score's first copy
    ranks = (first + (counts + 1) / 2)[inv]
    return float((ranks[y].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


def error_stats(err: np.ndarray, *, scale: float = 1.0, digits: int = 4, empty: float | None = None) -> dict:
    """Summary of the finite entries of ``err * scale``: n, missing (non-finite entries), median, p90, mean, max
    (rounded to ``digits``); the four figures are ``empty`` when no entry is finite."""
    e = np.asarray(err, dtype=float).reshape(-1)
    finite = np.isfinite(e)
    e = e[finite] * scale
    out = {"n": int(e.size), "missing": int((~finite).sum())}
    if not e.size:
        return {**out, "median": empty, "p90": empty, "mean": empty, "max": empty}
    return {**out, "median": round(float(np.median(e)), digits), "p90": round(float(np.percentile(e, 90)), digits),
            "mean": round(float(e.mean()), digits), "max": round(float(e.max()), digits)}


def wilson_interval(successes: int, n: int, *, z: float = 1.959963984540054) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion (95 % by default): (low, high). (0, 1) when n = 0.

    Unlike the normal approximation p ± z·s.e. it does not collapse to a point at 0/n or n/n: 5/5 gives
    (0.57, 1.00), 20/20 gives (0.84, 1.00)."""
    if n <= 0:
        return 0.0, 1.0
    if not 0 <= successes <= n:
        raise ValueError(f"successes must be in [0, n = {n}], got {successes}")
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)
