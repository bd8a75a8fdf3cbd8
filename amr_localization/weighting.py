"""The measurement update's weights: likelihoods times prior, flattened while searching.

While the filter searches (not localized), the particles are far sparser than the likelihood is
narrow: the full likelihood would keep only the few luckiest particles, and in a symmetric maze
the luckiest may sit at a rotated copy of the true pose. So the likelihood is raised to the power
beta in (0, 1] that keeps the effective sample size of the new weights at a given share of the
particles: every hypothesis that roughly fits stays alive until later scans decide. No rclpy
import.
"""
from __future__ import annotations

import numpy as np


def tempering_exponent(scores: np.ndarray, prior: np.ndarray, ess_share: float) -> float:
    """The exponent beta in (0, 1] keeping the effective sample size at `ess_share` of N.

    scores: log-likelihoods relative to the best (<= 0, -inf for impossible particles); prior:
    the weights before the update. 1 if the full likelihood already keeps that share.
    """
    target = ess_share * len(scores)
    finite = np.isfinite(scores)
    safe = np.where(finite, scores, 0.0)

    def ess(beta: float) -> float:
        w = np.where(finite, prior * np.exp(beta * safe), 0.0)
        total = w.sum()
        return float(total * total / np.dot(w, w)) if total > 0 else 0.0

    if ess(1.0) >= target:
        return 1.0
    low, high = 0.0, 1.0
    for _ in range(10):
        mid = 0.5 * (low + high)
        if ess(mid) >= target:
            low = mid
        else:
            high = mid
    return max(low, 1e-3)


def updated_weights(prior: np.ndarray, scores: np.ndarray,
                    ess_share: float | None) -> np.ndarray | None:
    """Normalised posterior weights from the prior and the particles' log-likelihoods.

    ess_share: flatten the likelihood to keep this effective sample size share (while
    searching), or None for the full likelihood. None if no particle is possible (every score
    -inf: all in walls or off the map).
    """
    best = scores.max()
    if not np.isfinite(best):
        return None
    scores = scores - best
    if ess_share is not None:
        scores *= tempering_exponent(scores, prior, ess_share)
    weights = prior * np.exp(scores)
    total = weights.sum()
    if not total > 0.0:  # the old weights underflowed against the new scores
        weights = np.exp(scores)
        total = weights.sum()
    return weights / total
