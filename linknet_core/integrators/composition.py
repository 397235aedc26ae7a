"""Symmetric compositions of RATTLE: higher order, still symplectic and time-reversible.

A composition is defined only by its step fractions gamma_1..gamma_s (sum 1, palindromic): one step of
size h is RATTLE steps of gamma_i h in turn. Yoshida (1990) and Suzuki (1990) give the coefficients.
"""
from __future__ import annotations


from linknet_core.integrators.rattle import Rattle


def _triple_jump(order_below: int) -> tuple[float, float]:
    p = order_below + 1
    g1 = 1.0 / (2.0 - 2.0 ** (1.0 / p))
    return g1, 1.0 - 2.0 * g1


def _yoshida_symmetric(w: list[float]) -> tuple[float, ...]:
    """Yoshida lists w_1..w_m; the composition is w_m .. w_1 w_0 w_1 .. w_m with w_0 = 1 - 2 sum w."""
    w0 = 1.0 - 2.0 * sum(w)
    return tuple(reversed(w)) + (w0,) + tuple(w)


class Composition(Rattle):
    """A step is RATTLE steps of gamma_i h in turn (the compiled loop takes the same gammas)."""

    def step(self, X, U, h, F_input, t=0.0, t_end=None):
        t_end = t + h if t_end is None else t_end
        fraction = 0.0
        for i, g in enumerate(self.gammas):
            start = t + fraction * h
            fraction += g
            end = t_end if i == len(self.gammas) - 1 else t + fraction * h
            X, U = Rattle.step(self, X, U, g * h, F_input, start, end)
        return X, U


class Yoshida4(Composition):
    """Triple jump (Yoshida 1990 / Creutz-Gocksch): 3 RATTLE stages, order 4."""
    name = "yoshida4"
    order = 4
    _g1, _g0 = _triple_jump(2)
    gammas = (_g1, _g0, _g1)
    guarantees = "order 4 with 3 RATTLE stages; symplectic, time-reversible; constraints as RATTLE"


class Suzuki4(Composition):
    """Suzuki's fractal 5-stage composition: order 4 with a much smaller error constant than the triple jump."""
    name = "suzuki4"
    order = 4
    _p = 1.0 / (4.0 - 4.0 ** (1.0 / 3.0))
    gammas = (_p, _p, 1.0 - 4.0 * _p, _p, _p)
    guarantees = "order 4 with 5 RATTLE stages (smaller error constant); symplectic, time-reversible"


class Yoshida6(Composition):
    """Yoshida (1990) solution A: 7 RATTLE stages, order 6."""
    name = "yoshida6"
    order = 6
    gammas = _yoshida_symmetric([-1.17767998417887, 0.235573213359357, 0.784513610477560])
    guarantees = "order 6 with 7 RATTLE stages; symplectic, time-reversible"


class Yoshida8(Composition):
    """Yoshida (1990) solution D: 15 RATTLE stages, order 8."""
    name = "yoshida8"
    order = 8
    gammas = _yoshida_symmetric([
        0.102799849391985, -1.96061023297549, 1.93813913762276, -0.158240635368243,
        -1.44485223686048, 0.253693336566229, 0.914844246229740])
    guarantees = "order 8 with 15 RATTLE stages; symplectic, time-reversible"
