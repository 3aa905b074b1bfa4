"""The least-loss quartic of docs/spec/MATH.md derived with sympy from the Lagrangian and equal to
the documented formulas (tools/least_loss_quartic.py), and its least loss equal to a search along
the curve on random linear machines. Slow (sympy's expansion takes about a minute); the C++ solver's
quartic is checked against a search along the curve in the default run (tests/cpp/test_least_loss.cpp)."""
from __future__ import annotations

import pytest

sp = pytest.importorskip("sympy")

from tools.least_loss_quartic import check_numeric, check_symbolic  # noqa: E402


@pytest.mark.slow
def test_quartic_derivation_matches_the_documented_formulas():
    lines = check_symbolic()
    assert "degree in lambda of h(i(lambda)) D^2 - T D^2: 4" in lines[0]


@pytest.mark.slow
def test_quartic_least_loss_equals_the_search_along_the_curve():
    check_numeric(seed=3, cases=3)
