"""The cart component FMU (fmu_src/cart.py) against its law, and the cart-and-chain monolithic reference
(examples/compositions/cart_chain_reference.py) on its own: the textbook cart-pendulum, its small-oscillation
frequency, energy and momentum conservation, and its added mass against the straight chain's closed form."""
import sys

import numpy as np

from fmu_harness import FMU_CLIENT_LIB, ROOT, build_cached, run_client  # first: repo on sys.path

sys.path.insert(0, str(ROOT / "examples" / "compositions"))
import cart_chain_reference as ref  # noqa: E402


def test_cart_fmu_integrates_the_held_force_exactly_restores_its_state_and_refuses_a_bad_mass(tmp_path):
    cart = build_cached(tmp_path, "cart")
    rng = np.random.default_rng(3)
    forces = rng.normal(size=(12, 2)) * 5
    steps = rng.uniform(1e-3, 0.1, 12)
    out = run_client(f"""
{FMU_CLIENT_LIB}
c = Fmu({str(cart)!r}, 'cart')
c.slave.setupExperiment(startTime=0.0)
c.slave.enterInitializationMode()
c.set({{'mass': 2.5, 'x_start': 0.3, 'v_start': -0.7}})
start = c.get(['x', 'v'])
c.slave.exitInitializationMode()
rows, t = [], 0.0
for (F, Fd), h in zip({forces.tolist()!r}, {steps.tolist()!r}):
    c.set({{'F': F, 'F_drive': Fd}})
    a = c.get(['a'])[0]
    c.step(t, h); t += h
    rows.append([a, *c.get(['x', 'v'])])
state = c.slave.getFMUstate()
blob = c.slave.serializeFMUstate(state)
c.set({{'F': 1.0, 'F_drive': 0.0}}); c.step(t, 0.05); after = c.get(['x', 'v'])
c.slave.setFMUstate(c.slave.deSerializeFMUstate(blob)); c.set({{'F': 1.0, 'F_drive': 0.0}}); c.step(t, 0.05)
replay = c.get(['x', 'v'])
try:
    c.set({{'mass': 0.0}})
except FMICallException:
    pass  # refused at once (fmi2Error) or only at the next doStep
try:
    c.step(t, 0.01); status = 0
except FMICallException as e:
    status = e.status
c.set({{'mass': 1.0}}); c.step(t, 0.01)
save(start=start, rows=np.array(rows), after=after, replay=replay, status=status,
     log=np.array(' '.join(m for _, m in LOG)))
""", tmp_path / "client_cart")
    np.testing.assert_array_equal(out["start"], [0.3, -0.7])
    x, v = 0.3, -0.7
    for (F, Fd), h, (a, x_fmu, v_fmu) in zip(forces, steps, out["rows"]):
        acc = (F + Fd) / 2.5  # closed form of a constant force over the step
        x, v = x + v * h + 0.5 * acc * h * h, v + acc * h
        assert abs(a - acc) <= 1e-15 * (1 + abs(acc))
        np.testing.assert_allclose([x_fmu, v_fmu], [x, v], rtol=1e-13, atol=1e-14)
    np.testing.assert_array_equal(out["replay"], out["after"])
    assert out["status"] == 2 and "mass" in str(out["log"]) and "> 0" in str(out["log"])  # fmi2Discard, named


def test_cart_chain_reference_matches_the_cart_pendulum_and_conserves_energy_and_momentum():
    c = ref.checks(verbose=False)
    assert c["cart_pendulum"] < 1e-13        # n = 1: the textbook closed form, 20 random states
    assert c["small_oscillation"] < 1e-6     # eps cos(w t), w^2 = g (M + m)/(M l), eps = 1e-4: O(eps^2) left
    assert c["energy"] < 1e-11 and c["momentum"] < 1e-11


def test_reference_added_mass_of_a_straight_chain_is_its_mass_times_sin_squared():
    model = ref.CartChain(0.5, np.full(5, 0.2), np.full(5, 0.2))
    for theta in (0.0, 0.3, 0.7, 1.2):
        assert abs(model.added_mass(np.r_[0.0, np.full(5, theta)]) - np.sin(theta) ** 2) < 1e-12
    # the hook force at rest, straight chain: the tension along the chain, gravity's share only when vertical
    F = model.hook_force(np.r_[0.0, np.zeros(5)], np.zeros(6))
    np.testing.assert_allclose(F, [0.0, -9.81], atol=1e-12)
