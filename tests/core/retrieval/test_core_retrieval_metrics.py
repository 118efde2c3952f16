"""ADR, MR, LR of a retrieval (seed eqs. 5-15..5-17) on hand-computed rankings."""
import pytest

from bolus_addon.core.errors import BolusError
from bolus_addon.core.retrieval.metrics import query_scores, summarise


def test_ideal_ranking_gives_the_seeds_ideal_row():
    rel = [f"m{i}" for i in range(20)]
    ranking = rel + [f"x{i}" for i in range(80)]
    s = query_scores(ranking, rel)
    assert s == {"ADR": 1.0, "MR": 10.5, "LR": 1.0, "first_rank": 1}  # Table 5-2 "Ideal": 1, 10.5, 1


def test_hand_computed_ranking():
    # library of 6, relevant a and b found at ranks 2 and 5
    s = query_scores(["x", "a", "y", "z", "b", "w"], {"a", "b"})
    # RI(1) = 0, RI(2) = 1 -> ADR = (0/1 + 1/2) / 2
    assert s["ADR"] == pytest.approx(0.25)
    assert s["MR"] == pytest.approx(3.5)
    # rho = 5, n = 2, N = 6 -> LR = 1 - 3/4
    assert s["LR"] == pytest.approx(0.25)
    assert s["first_rank"] == 2


def test_last_place_and_whole_library_relevant():
    assert query_scores(["x", "y", "a"], ["a"])["LR"] == 0.0
    assert query_scores(["a", "b"], ["a", "b"])["LR"] == 1.0


def test_summary_and_refusals():
    out = summarise([query_scores(["a", "x"], ["a"]), query_scores(["x", "a"], ["a"])])
    assert out["top1"] == 0.5 and out["queries"] == 2 and out["MR"] == 1.5
    with pytest.raises(BolusError, match="once"):
        query_scores(["a", "a"], ["a"])
    with pytest.raises(BolusError, match="not in the ranking"):
        query_scores(["a"], ["b"])
    with pytest.raises(BolusError, match="at least one"):
        query_scores(["a"], [])
    with pytest.raises(BolusError, match="no query"):
        summarise([])
