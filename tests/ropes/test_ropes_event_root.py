"""The events' bracketing root find (linknet_core.dynamics.roots.bracketed_root, and the core's copy in
stages/ropes.c that the engines' agreement tests hold to it) where regula falsi lands on the root: a force or slip
speed linear in the step's length (a block decelerated at mu g stops at v / (mu g); a seabed slide's eight stops)
has its root found by the first secant, f there 0 to round-off. One more value just past it closes the bracket; the
bracket then holds the exact root and is no wider than the tolerance."""
from __future__ import annotations

import pytest

from linknet_core.dynamics.roots import bracketed_root


@pytest.mark.parametrize("root, slope", [(0.25, 1.0), (0.375, 3.0), (0.1, 0.5)])
def test_a_secant_that_lands_on_the_root_closes_the_bracket_in_one_more_value(root, slope):
    calls = []

    def f(x):
        calls.append(x)
        return slope * (root - x)
    lo, hi = bracketed_root(f, 0.0, 1.0, f(0.0), f(1.0), xtol=1e-13)
    n_values = len(calls)
    assert lo <= root <= hi and f(lo) >= 0 > f(hi)
    assert hi - lo <= 1e-13
    assert n_values == 4  # the two ends, the secant, the value just past it: not a run of bisections
