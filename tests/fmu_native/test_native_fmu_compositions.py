"""The compositions of examples/compositions/ with native network FMUs in place of the pythonfmu ones.

The example scripts build pythonfmu FMUs on their command line, but their masters take FMU paths:
pd_feedback.run(chain_fmu, pd_fmu, h, t_end) and coupling.master(fmus, h, t_end). They are driven here with
native network FMUs (built with the same options as the scripts' own build()) next to the helper FMUs (PD
controller, spring-damper, which exist as pythonfmu FMUs only), and give the pythonfmu compositions' results."""
import numpy as np

from native_fmu_support import ROOT
from fmu_harness import run_client
import build_fmu

HERE = ROOT / "examples" / "compositions"


def test_pd_loop_and_spring_coupling_with_native_network_fmus(fmu_root):
    out = fmu_root / "compositions"
    out.mkdir(exist_ok=True)
    chain = {native: build_fmu.build_scene_fmu(HERE / "hanging_chain.json",
                                               out / f"hanging_chain{'_native' if native else ''}.fmu",
                                               integrator="dop853", tolerance=1e-10, inputs="1", outputs="1,5",
                                               quiet=True, native=native) for native in (True, False)}
    nets = {native: {name: build_fmu.build_scene_fmu(HERE / f"net_{name}.json",
                                                      out / f"{name}{'_native' if native else ''}.fmu",
                                                      inputs=str(tip), integrator="dop853", tolerance=1e-11,
                                                      quiet=True, native=native)
                     for name, tip in (("a", 3), ("b", 2))} for native in (True, False)}
    pd = build_fmu.build_component_fmu("pd_controller", out / "pd_controller.fmu", quiet=True)
    spring = build_fmu.build_component_fmu("spring_damper", out / "spring_damper.fmu", quiet=True)
    result = run_client(f"""
sys.path.insert(0, {str(HERE)!r})
import pd_feedback, coupling
for native in (True, False):
    tag = 'native' if native else 'python'
    chain = {{True: {str(chain[True])!r}, False: {str(chain[False])!r}}}[native]
    r = pd_feedback.run(chain, {str(pd)!r}, 0.004, 3.0)
    save(**{{'pd_top_' + tag: r['top'], 'pd_error_' + tag: np.array(r['max_error'])}})
    nets = {{True: {({k: str(v) for k, v in nets[True].items()})!r},
             False: {({k: str(v) for k, v in nets[False].items()})!r}}}[native]
    m = coupling.master(dict(nets, spring={str(spring)!r}), 0.02, 1.0)
    save(**{{'xa_' + tag: m['xa'], 'xb_' + tag: m['xb'],
              'coupling_error_' + tag: np.array(coupling.errors(m, coupling.monolithic_reference(1.0)))}})
""", fmu_root / "compositions_client", timeout=600)
    # the PD loop: the same trajectory, and the documented coupling error (docs/fmu.md: 1.215e-3 m at h = 0.004)
    np.testing.assert_allclose(result["pd_top_native"], result["pd_top_python"], rtol=1e-9, atol=1e-12)
    assert abs(float(result["pd_error_native"]) - 1.215e-3) < 0.005e-3
    # the spring coupling: the same positions, and the documented error against the monolithic scene (1.597e-2 m)
    np.testing.assert_allclose(result["xa_native"], result["xa_python"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(result["xb_native"], result["xb_python"], rtol=1e-9, atol=1e-12)
    assert abs(float(result["coupling_error_native"]) - 1.597e-2) < 0.005e-2
