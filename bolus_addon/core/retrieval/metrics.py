"""Accuracy of a retrieval: average dynamic recall, mean rank and last rank (seed 5.4, eqs. 5-15..5-17).

For one query, the library's models are ranked best first; ``relevant`` are the models that
count as right answers (the ground truth, q = n of them):

* ADR = 1/q sum_{i=1..q} RI(i) / i, RI(i) the relevant models among the first i (eq. 5-15;
  1 when the q relevant models come first);
* MR = the mean 1-based rank of the relevant models (eq. 5-16; (q + 1) / 2 at best: the seed's
  "ideal 10.5" is q = 20);
* LR = 1 - (rho - n) / (N - n), rho the rank of the last relevant model, n = q, N the library size
  (eq. 5-17; 1 at best, 0 when the last relevant model comes last; 1 when n = N).

`summarise` averages them over queries (the seed's Table 5-2 rows).
"""
from __future__ import annotations

import numpy as np

from ..errors import BolusError

__all__ = ["query_scores", "summarise"]


def query_scores(ranking, relevant) -> dict:
    """ADR, MR, LR (eqs. 5-15..5-17) of one query: ``ranking`` the library's model names (or ids) best
    first, every model once; ``relevant`` the right answers (a non-empty subset of the ranking)."""
    ranking = list(ranking)
    rel = set(relevant)
    N = len(ranking)
    if len(set(ranking)) != N:
        raise BolusError("a ranking must list every model once")
    if not rel:
        raise BolusError("a query needs at least one relevant model")
    missing = rel.difference(ranking)
    if missing:
        raise BolusError(f"relevant models not in the ranking: {sorted(map(str, missing))}")
    hits = np.array([r in rel for r in ranking], dtype=bool)
    q = len(rel)
    ri = np.cumsum(hits)[:q]  # RI(i) for i = 1..q
    adr = float(np.mean(ri / np.arange(1, q + 1)))
    ranks = np.nonzero(hits)[0] + 1
    mr = float(ranks.mean())
    rho = int(ranks.max())
    lr = 1.0 if N == q else float(1.0 - (rho - q) / (N - q))
    return {"ADR": adr, "MR": mr, "LR": lr, "first_rank": int(ranks.min())}


def summarise(scores) -> dict:
    """The mean of each measure over a list of `query_scores` results, plus the share of queries whose
    best answer is relevant (top-1) and the number of queries."""
    scores = list(scores)
    if not scores:
        raise BolusError("no query to summarise")
    out = {k: float(np.mean([s[k] for s in scores])) for k in ("ADR", "MR", "LR")}
    out["top1"] = float(np.mean([s["first_rank"] == 1 for s in scores]))
    out["queries"] = len(scores)
    return out
