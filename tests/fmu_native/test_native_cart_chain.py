"""Motion coupling (examples/compositions/cart_chain.py): the cart FMU carries the native chain FMU through its
driven hook (P, V, A in; Freact out), against the monolithic reference written in generalized coordinates
(cart_chain_reference.py, scipy DOP853 at rtol 1e-12, independent of linknet).

* The explicit coupling converges at first order, and the error is that first-order term and nothing else:
  the Richardson combination 2 r(h/2) - r(h) is two orders of magnitude closer to the reference.
* The loop through the FMUs equals the same loop on linknet_core.Simulator(anchors=) to round-off.
* The added-mass limit: the start-up error of the cart's acceleration decays when m_c exceeds the chain's
  added mass at the release, m_chain sin^2(0.7) = 0.415 m_chain, and grows below it.
* fmpy's container FMU (connections in the cart-first order) reproduces the master loop bit for bit; fmpy's
  SSP simulator is the Jacobi scheme the master writes out (scheme="jacobi"), to round-off."""
import sys

import numpy as np

from native_fmu_support import ROOT
from fmu_harness import run_client

EXAMPLES = ROOT / "examples" / "compositions"
sys.path.insert(0, str(EXAMPLES))
import cart_chain as cc  # noqa: E402

T_END = 1.0
STEPS = (0.008, 0.004)


def test_cart_carries_the_chain_at_first_order_stability_limit_and_fmpy_masters(fmu_root):
    out = fmu_root / "cart_chain"
    fmus = cc.build(out, native=True)
    result = run_client(f"""
sys.path.insert(0, {str(EXAMPLES)!r})
from pathlib import Path
import cart_chain as cc
fmus = {{k: Path(v) for k, v in {({k: str(v) for k, v in fmus.items()})!r}.items()}}
out = Path({str(out)!r})
def keep(tag, r):
    save(**{{tag + '_x': r['x'], tag + '_X': r['X'], tag + '_a': r['a_steps'],
              tag + '_failed': np.array(-1.0 if r['failed'] is None else r['failed'])}})
for h in {STEPS!r}:
    keep(f'fmu{{h}}', cc.master(fmus, 1.0, h, {T_END!r}))
keep('lib', cc.library_master(1.0, 0.004, {T_END!r}))
for ratio in (0.45, 0.38):
    keep(f'ratio{{ratio}}', cc.master(fmus, ratio, 0.004, 0.3))
keep('container', cc.run_container(fmus, 1.0, 0.008, {T_END!r}, out))
keep('ssp', cc.ssp_master(fmus, 1.0, 0.008, {T_END!r}, out))
keep('jacobi', cc.master(fmus, 1.0, 0.008, {T_END!r}, scheme='jacobi'))
""", fmu_root / "cart_chain_client", timeout=600)

    def run(tag, h):
        return dict(x=result[tag + "_x"], X=result[tag + "_X"], a_steps=result[tag + "_a"], h=h,
                    failed=None if result[tag + "_failed"] < 0 else float(result[tag + "_failed"]))

    ref = cc.reference(1.0, T_END)
    coarse, fine = run(f"fmu{STEPS[0]}", STEPS[0]), run(f"fmu{STEPS[1]}", STEPS[1])
    e_coarse, e_fine = cc.errors(coarse, ref), cc.errors(fine, ref)
    order = np.log(e_coarse["position"] / e_fine["position"]) / np.log(STEPS[0] / STEPS[1])
    assert 0.95 < order < 1.05, order                      # explicit zero-order-hold coupling: O(h)
    assert 0.95 < np.log2(e_coarse["acceleration"] / e_fine["acceleration"]) < 1.05
    assert e_fine["position"] < 0.01                       # 7.4e-3 m measured (chain swings ~0.3 m)
    # the first-order term is all there is: Richardson removes it (measured 6.5e-5 m, against 7.4e-3 m)
    richardson = dict(x=2 * fine["x"] - coarse["x"], X=2 * fine["X"] - coarse["X"], a_steps=fine["a_steps"],
                      h=STEPS[1])
    assert cc.errors(richardson, ref)["position"] < 0.02 * e_fine["position"]
    # the FMUs are the library's loop
    lib = run("lib", 0.004)
    np.testing.assert_allclose(fine["X"], lib["X"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(fine["a_steps"], lib["a_steps"], rtol=1e-11, atol=1e-11)
    # stability: the added mass at the release is sin^2(0.7) m_chain = 0.415 kg (reference, closed form)
    model, theta0 = cc.chain_model()
    assert abs(model.added_mass(np.r_[0.0, theta0]) - np.sin(0.7) ** 2) < 1e-12
    growth = {r: cc.growth(run(f"ratio{r}", 0.004), cc.reference(r, 0.3, sample=0.004)) for r in (0.45, 0.38)}
    assert growth[0.45] <= 1.0 + 1e-9, growth               # above the limit: the start-up error only decays
    assert growth[0.38] > 1.3, growth                       # below: it grows (1.54 measured over 0.3 s)
    # fmpy's container FMU is the cart-first loop; its SSP simulator the Jacobi loop
    container, master_coarse = run("container", 0.008), coarse
    np.testing.assert_array_equal(container["X"], master_coarse["X"])
    ssp, jacobi = run("ssp", 0.008), run("jacobi", 0.008)
    np.testing.assert_allclose(ssp["X"], jacobi["X"], rtol=0, atol=1e-12)
    assert cc.errors(ssp, ref)["position"] < 10 * e_coarse["position"]
