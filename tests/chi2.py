"""Pearson's chi-square of a sampler's 2-D histogram against the expected counts (style.md).

Shared by the sampler tests: named constants, sparse cells pooled, and on
failure a report with both histograms (top row = +y) so a person can look.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

#: Chi-square significance level. Seeds are fixed, so the outcome is deterministic, not flaky.
SIGNIFICANCE = 1e-3
#: Cells expecting fewer samples than this are pooled into one cell (and dropped if the pool
#: still expects fewer), as the chi-square law needs.
MIN_EXPECTED = 20
#: Histogram resolution: odd, so that edges through the centre (and the symmetric edges of the
#: shapes) do not fall on cell borders.
GRID = 15
#: Independent samples per chi-square test.
N_CHI2 = 200_000


@dataclass
class Chi2Result:
    statistic: float
    dof: int
    p_value: float
    report: str


def pearson_chi2(observed: np.ndarray, expected: np.ndarray, label: str) -> Chi2Result:
    """Chi-square of ``observed`` against ``expected`` counts, both [y bin, x bin]."""
    report = (
        f"{label}: observed counts (rows top = +y):\n{np.array2string(observed[::-1].astype(int), max_line_width=200)}\n"
        f"expected counts:\n{np.array2string(np.round(expected[::-1], 1), max_line_width=250)}"
    )
    obs, exp = observed.ravel(), expected.ravel()
    stray = (exp <= 0.0) & (obs > 0)
    if stray.any():
        return Chi2Result(math.inf, 0, 0.0, f"{int(obs[stray].sum())} samples in cells the shape does not touch\n{report}")
    low = exp < MIN_EXPECTED
    o, e = list(obs[~low]), list(exp[~low])
    if exp[low].sum() >= MIN_EXPECTED:  # pool the sparse cells into one
        o.append(obs[low].sum())
        e.append(exp[low].sum())
    o, e = np.array(o), np.array(e)
    statistic = float(np.sum((o - e) ** 2 / e))
    dof = len(o) - 1
    return Chi2Result(statistic, dof, float(stats.chi2.sf(statistic, dof)), report)
