"""The Jacobian-corrected master (examples/compositions/cart_chain_implicit.py): a cart of 0.03 times the chain's
mass carries the chain stably, its error converging at first order against the monolithic reference
(cart_chain_reference.py: generalized coordinates, scipy DOP853, independent of linknet), where the explicit loop
of cart_chain.py blows up at the same settings; the loop it solves is the monolithic system's cart equation
(m_c + m_eff) a = F_drive + Freact(A = 0); and the same master on the cart and chain FMUs equals it on the library.

The slaves of the library runs are the cart's own code (fmu_src/cart.py, in this process) and the chain on
linknet_core.Simulator; the FMU run is in a subprocess client (pythonfmu's exit, tests/fmu_harness.py)."""
import sys

import numpy as np
import pytest

from fmu_harness import ROOT, build_cached, run_client  # first: repo on sys.path

EXAMPLES = ROOT / "examples" / "compositions"
sys.path.insert(0, str(EXAMPLES))
import cart_chain as cc  # noqa: E402
import cart_chain_implicit as ci  # noqa: E402

RATIO = 0.03       # m_c / m_chain: 0.03 kg under a 1 kg chain, whose added mass at the release is 0.415 kg
T_END = 0.3        # s
STEPS = (0.004, 0.002, 0.001)


def _release():
    model, theta0 = cc.chain_model(m_c=RATIO)
    return model, np.r_[0.0, theta0]


def test_implicit_master_is_stable_at_a_light_cart_and_converges_where_the_explicit_loop_blows_up():
    ref = cc.reference(RATIO, T_END)
    errors = []
    for h in STEPS:
        run = ci.run_library(RATIO, h, T_END)
        assert run["failed"] is None, (h, run["failed"])
        assert run["defect"] < 1e-11                     # |Freact(A) - F|, |a(F) - A| after the solve: loop closed
        errors.append(cc.errors(run, ref))
        explicit = cc.library_master(RATIO, h, T_END)
        # -m_eff/m_c = -13.8 per step: past A_BLOWN_UP (1000 m/s2) within a few steps, whatever h
        assert explicit["failed"] is not None and explicit["failed"] <= 3 * h, (h, explicit["failed"])
    position = [e["position"] for e in errors]
    orders = np.log2(np.array(position[:-1]) / np.array(position[1:]))
    assert np.all((orders > 0.85) & (orders < 1.15)), (position, orders)   # 0.94, 0.99 measured
    assert position[-1] < 0.01, position                                    # 6.6e-3 m; the chain swings ~0.4 m
    acceleration = [e["acceleration"] for e in errors]
    assert 0.8 < np.log2(acceleration[-2] / acceleration[-1]) < 1.2, acceleration  # 87 -> 44 m/s2 (|a| to 330)


def test_the_solved_loop_is_the_monolithic_cart_equation_and_takes_nothing_from_the_last_step():
    """The first acceleration the master sets is the monolithic system's at the release (the reference's, from
    its mass matrix in generalized coordinates); dFreact/dA is minus the reference's added mass; an error in the
    held hook acceleration A_0 moves the next a by -m_eff/m_c in the explicit loop and by nothing in this one."""
    model, q0 = _release()
    m_eff = model.added_mass(q0)                         # sin^2(0.7) kg
    a_ref = model.accelerations(q0, np.zeros_like(q0))[0]
    run = ci.run_library(RATIO, 0.004, 0.004)
    assert abs(run["a_steps"][0] - a_ref) < 1e-9 * abs(a_ref), (run["a_steps"][0], a_ref)
    assert abs(run["m_eff"][0] - m_eff) < 1e-9, (run["m_eff"][0], m_eff)
    assert abs(ci.loop_gain(RATIO, implicit=False) + m_eff / RATIO) < 1e-9 * m_eff / RATIO
    assert abs(ci.loop_gain(RATIO, implicit=True)) < 1e-12


def test_a_slave_without_derivatives_is_differentiated_by_a_secant_only_where_its_outputs_are_affine():
    cart, chain = ci.library_slaves(RATIO)
    # the cart's a = (F + F_drive)/m_c: its secant is 1/m_c, and the cart's F is left as it was
    cart.set({"F": 2.5})
    np.testing.assert_allclose(cart.directional(["a"], ["F"], [1.0]), [1.0 / RATIO], rtol=1e-12)
    assert cart.get(["F"])[0] == 2.5
    # Freact is quadratic in the hook's velocity (|U - V|^2 / R in (26)): no secant stands for its derivative
    with pytest.raises(ValueError, match=r"not affine.*V\[1,1\]"):
        ci.CouplingSlave.directional(chain, ["Freact[1,1]"], ["V[1,1]"], [1.0])
    with pytest.raises(KeyError, match="not an input-driven anchor"):
        chain.set({"P[2,1]": 0.0})


def test_the_master_on_the_cart_and_chain_fmus_equals_it_on_the_library(tmp_path):
    """Each chain FMU differentiated as it can: through fmi2GetDirectionalDerivative where its modelDescription
    provides it, else by the secant (exact: Freact is affine in A); the same run to round-off either way."""
    fmus = {"cart": build_cached(tmp_path, "cart"),
            "native": build_cached(tmp_path, str(cc.SCENE), integrator="dop853", tolerance=cc.RTOL, native=True),
            "python": build_cached(tmp_path, str(cc.SCENE), integrator="dop853", tolerance=cc.RTOL, native=False)}
    h = 0.004
    out = run_client(f"""
sys.path.insert(0, {str(EXAMPLES)!r})
import cart_chain_implicit as ci
for kind in ("native", "python"):
    cart, chain = ci.fmu_slaves({{"cart": {str(fmus["cart"])!r}, "chain": {{"native": {str(fmus["native"])!r},
                                 "python": {str(fmus["python"])!r}}}[kind]}}, {RATIO!r})
    r = ci.implicit_master(cart, chain, {h!r}, {T_END!r})
    save(**{{kind + "_X": r["X"], kind + "_a": r["a_steps"], kind + "_defect": np.array(r["defect"]),
             kind + "_failed": np.array(-1.0 if r["failed"] is None else r["failed"])}})
""", tmp_path / "client_implicit")
    lib = ci.run_library(RATIO, h, T_END)
    for kind in ("native", "python"):
        assert out[kind + "_failed"] < 0 and out[kind + "_defect"] < 1e-11, kind
        np.testing.assert_allclose(out[kind + "_X"], lib["X"], rtol=0, atol=1e-10, err_msg=kind)
        np.testing.assert_allclose(out[kind + "_a"], lib["a_steps"], rtol=1e-9, atol=1e-9, err_msg=kind)
