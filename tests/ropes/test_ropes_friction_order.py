"""RATTLE keeps its order through Coulomb friction whose slip direction turns: its second half kick is implicit in
the new velocity, as for drag (the friction -mu N d, d along the tangential velocity, depends on it). Measured
against scipy's solve_ivp of Newton's laws written in the tests: the leaning rod and the dumbbell of
test_ropes_friction_coupled (coupled masses slipping from rest, the slip turning), and a puck pushed across its
motion (a mass alone: m a = P - mu m g v / |v|), for RATTLE (order 2) and the triple jump (order 4), on the numpy
reference and on the native core (stages/rattle.c: the friction a force of the kicks, implicit in the second). With
the friction at the half step's velocity the order was 1."""
from __future__ import annotations

import numpy as np
import pytest
from rope_references import G
from scipy.integrate import solve_ivp
from test_ropes_friction_coupled import DUMBBELL, LEANING

import linknet_core as ln


BACKENDS = ["numpy", "native"]


def observed_order(scene, method, dts, t_end, reference, backend):
    errors = [float(np.abs(ln.simulate(scene, t_end, method, dt=dt, n_out=2, error_estimate=False,
                                       backend=backend).X[-1] - reference).max()) for dt in dts]
    return np.log(errors[0] / errors[1]) / np.log(dts[0] / dts[1]), errors


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("case", [LEANING, DUMBBELL], ids=["leaning rod", "dumbbell"])
def test_rattle_is_second_order_where_the_slip_of_coupled_masses_turns(case, backend):
    t_end = 0.15
    X_ref = case.trajectory(t_end, 2)[0][-1]
    order, errors = observed_order(case.scene(), "rattle", [4e-3, 2e-3], t_end, X_ref, backend)
    assert 1.9 < order < 2.1, errors


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_puck_pushed_across_its_slide_keeps_rattles_and_the_triple_jumps_orders(backend):
    mu, mass, push, v0, t_end = 0.1, 1.0, np.array([0.0, 2.0, 0.0]), np.array([1.5, 0.0, 0.0]), 0.15
    scene = ln.Scene.from_dict({"name": "puck", "gravity": [0, 0, -G],
                                "masses": [{"name": "puck", "position": [0, 0, 0], "mass": mass,
                                            "velocity": v0.tolist(), "force": push.tolist()}],
                                "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": mu}})

    def newton(_, y):
        v = y[3:]
        return np.concatenate([v, push / mass - mu * G * v / np.linalg.norm(v)])
    end = solve_ivp(newton, (0.0, t_end), np.concatenate([np.zeros(3), v0]), method="DOP853", rtol=1e-13,
                    atol=1e-15).y[:3, -1]
    order, errors = observed_order(scene, "rattle", [1e-2, 5e-3], t_end, end[None], backend)
    assert 1.95 < order < 2.05, errors
    order, errors = observed_order(scene, "yoshida4", [1.5e-2, 7.5e-3], t_end, end[None], backend)
    assert 3.9 < order < 4.1, errors
