"""A bracketing root find of a scalar function, without scipy.optimize (whose import would cost every run a tenth
of a second): the events' times (linknet_core.integrators.events) and a slip's starting direction
(linknet_core.dynamics.unilateral)."""
from __future__ import annotations


def bracketed_root(f, lo, hi, f_lo, f_hi, xtol=4e-16, guess=None):
    """(lo, hi): the bracket of a sign change of f, f(lo) >= 0 > f(hi), shrunk to xtol (relative) by the Illinois
    variant of regula falsi, with a bisection wherever the last three iterations did not halve it; ``guess``: the
    first point tried. A regula falsi point within a sixteenth of the tolerance of an end (that end at the root to
    round-off, f there 0 or nearly) is moved that far inside it: one more value closes the bracket, where regula
    falsi would stay at that end and the bracket close from the far one by bisections."""
    last = 0
    widths = []  # the bracket's width after each iteration
    m = guess
    for _ in range(200):
        if hi - lo <= xtol * max(1.0, abs(lo), abs(hi)):
            break
        if m is None:
            if len(widths) >= 3 and hi - lo > 0.5 * widths[-3]:
                m = 0.5 * (lo + hi)
            else:
                m = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
                close = xtol / 16 * max(1.0, abs(lo), abs(hi))
                m = max(min(m, hi - close), lo + close)
        if not lo < m < hi:
            m = 0.5 * (lo + hi)
            if not lo < m < hi:
                break
        fm = f(m)
        if fm >= 0:
            lo, f_lo = m, fm
            if last == 1:  # the same end moved twice: halve the other's value (Illinois)
                f_hi *= 0.5
            last = 1
        else:
            hi, f_hi = m, fm
            if last == -1:
                f_lo *= 0.5
            last = -1
        widths.append(hi - lo)
        m = None
    return lo, hi
