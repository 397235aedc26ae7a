"""Native FMU == library on every shipped scene and every integrator, and pythonfmu FMU == library on every scene with
a fixed-step and an adaptive integrator, with a force input.

The native FMU runs in the plain C host (tests/fmu_native/native_host.c) with no Python in its process or its
environment; the pythonfmu FMU runs in fmpy (one client process for all scenes); the library is
linknet_core's Simulator in this process. A few communication steps each, every output compared."""
import numpy as np
import pytest

from native_fmu_support import (METHODS, MODELS, N_STEPS, SCENES, H, assert_round_off, built, host_options,
                                input_force, input_mass, library_rows, output_names, parse_rows, run_host)
from fmu_harness import FMU_CLIENT_LIB, run_client
import linknet_core as ln


# Every shipped scene, the triangulated net included: the force input pushes its flat braced cells out of their
# plane, to a near-self-stress that the position projection's Gauss-Newton retry (RETRY_SINGULAR_RCOND) gets
# through with every method on both backends (test_the_pushed_triangulated_net_goes_through_on_both_backends).
FORCED = list(SCENES)
# The pushed net costs more with every communication step (dop853: 0.26, 0.79, 1.29, 1.73, 2.13 s of CPU for steps 1
# to 5 on the native core, in each of the three runs compared; the fixed-step methods ~0.1 s a step each), so its runs
# compare two steps, in which the position projection already stops at its floor and takes its retry (68 times with
# dopri5, 129 with dop853); the other scenes compare N_STEPS. And one fixed-step and one adaptive method: the
# projection and its retry are the same code under every method, which the other scenes compare one by one.
FEW_STEPS = {("triangulated_net", method): 2 for method in METHODS}
FEW_METHODS = {"triangulated_net": ("rattle", "dop853")}


# The pythonfmu FMU passes its integrator parameter to the library, whose every method the native FMU's comparison
# below covers: its glue is the same for every method, so one fixed-step and one adaptive method compare it.
PYTHONFMU_METHODS = ("rattle", "dop853")


def steps(scene: str, method: str) -> int:
    """How many communication steps of H the runs of ``scene`` with ``method`` compare."""
    return FEW_STEPS.get((scene, method), N_STEPS)


@pytest.fixture(scope="module")
def pythonfmu_rows(fmu_root):
    """Every scene and integrator through the pythonfmu FMUs, in one fmpy client process."""
    fmus = {scene: built(fmu_root, scene, native=False) for scene in FORCED}
    jobs = {scene: (str(f.path), output_names(f), input_mass(f), {m: steps(scene, m) for m in PYTHONFMU_METHODS})
            for scene, f in fmus.items()}
    code = f"""
{FMU_CLIENT_LIB}
import math
jobs = {jobs!r}
for scene, (path, names, k, n_steps) in jobs.items():
    for method in {PYTHONFMU_METHODS!r}:
        f = Fmu(path, scene + '_' + method)
        f.init(strings={{'integrator': method}})
        rows = []
        for n in range(n_steps[method] + 1):
            t = n * {H!r}
            f.set({{f'F[{{k}},1]': {0.5!r}, f'F[{{k}},3]': {2.0!r} * math.cos({20.0!r} * t)}})
            rows.append([t] + list(f.get(names)))
            if n < n_steps[method]:
                f.step(t, {H!r})
        f.slave.terminate()
        f.slave.freeInstance()
        save(**{{scene + '__' + method: np.array(rows)}})
"""
    return run_client(code, fmu_root / "pythonfmu_client", timeout=900), fmus


def test_the_pushed_triangulated_net_goes_through_on_both_backends():
    """A push on a node of the triangulated net's flat braced cells: the position projection's Gauss-Newton stalls
    with the minimum-norm cut SINGULAR_RCOND (the pushed cell's near-self-stress lies below it) and goes through on
    its retry with RETRY_SINGULAR_RCOND, in the reference and in the native core alike."""
    scene = ln.load_scene(MODELS / "triangulated_net.json")
    final = {}
    for backend in ("numpy", "native"):
        sim = ln.Simulator(scene, method="rattle", dt=1e-3, backend=backend)
        for n in range(N_STEPS):
            sim.advance((n + 1) * H, input_force(scene.K, scene.K, n * H))
        X, U = sim.state.X, sim.state.U
        # on (11) within the cap of the projection's floor (1e-10 relative), and (12) to round-off of that
        assert sim.dyn.constraint_residual(X) <= 1e-10, backend
        assert sim.dyn.velocity_residual(X, U) <= 1e-6, backend
        stops, reached = sim.integrator.projection_floor()
        assert reached <= 1e-9, backend
        final[backend] = X
    # the two paths agree to the positions a residual at the floor leaves undetermined (~sqrt(2e-10) R) ...
    R = float(scene.length.min())
    assert np.abs(final["native"] - final["numpy"]).max() <= 1e-4 * R
    # ... and the push moved the net by far more than that
    assert np.abs(final["numpy"] - scene.X0).max() > 1e-3 * R


@pytest.mark.parametrize("scene", FORCED)
def test_native_fmu_equals_library_and_pythonfmu_fmu(scene, fmu_root, host, no_python_env, pythonfmu_rows):
    rows, py_fmus = pythonfmu_rows
    fmu = built(fmu_root, scene)
    assert output_names(fmu) == output_names(py_fmus[scene])  # one Layout: the same variables
    sc = ln.load_scene(MODELS / f"{scene}.json")
    k = input_mass(fmu)
    assert np.any(input_force(k, sc.K, 0.0) != 0.0)
    for method in FEW_METHODS.get(scene, METHODS):
        n = steps(scene, method)
        native = parse_rows(run_host(host, no_python_env, "run", fmu, 0.0, n, H, *host_options(fmu, method)))
        library = library_rows(sc, fmu, method, n=n)
        names = output_names(fmu)
        assert_round_off(native, library, f"{scene}, {method}: native FMU vs library", names)
        if method in PYTHONFMU_METHODS:
            assert_round_off(rows[f"{scene}__{method}"], library, f"{scene}, {method}: pythonfmu FMU vs library",
                             names)
        assert np.ptp(native[:, 1:], axis=0).max() > 0.0  # something responds over the run


def test_native_fmu_is_bit_identical_to_the_library_at_default_parameters(fmu_root, host, no_python_env):
    """The FMU runs the library's ln_model and ln_method (read from the library's own structs) through the same
    core compiled with the same flags: not just round-off, every bit, including the 2-D planar path (chain_10),
    the general sparse LDL^T (net_10x10), the minimum-norm static truss and the rigid-body path."""
    for scene, method in (("chain_10", "rattle"), ("net_10x10", "dop853"), ("redundant_truss", "rattle"),
                          ("spinning_tetrahedron", "yoshida4"), ("spinning_tetrahedron", "dop853")):
        fmu = built(fmu_root, scene)
        native = parse_rows(run_host(host, no_python_env, "run", fmu, 0.0, N_STEPS, H, *host_options(fmu, method)))
        library = library_rows(ln.load_scene(MODELS / f"{scene}.json"), fmu, method)
        np.testing.assert_array_equal(native, library, err_msg=f"{scene}, {method}")
