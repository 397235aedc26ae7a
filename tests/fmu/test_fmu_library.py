"""FMU results equal the library's (linknet_core) for the same scene, inputs and solver settings.

FMU clients run in subprocesses (fmu_harness.run_client); references are computed here with
linknet_core directly, so the two paths share no FMI code.
"""
import numpy as np
import pytest

from fmu_harness import FMU_CLIENT_LIB, MODELS, build_cached, run_client  # first: repo on sys.path
import linknet_core as ln

H, T_END = 0.01, 0.5
TIP = 10  # 0-based index of chain_10's tip mass (F[11,3] in the FMU)


def tip_force(t):
    """A step of 2 N at t = 0.1 s plus a 3 Hz sine of 0.5 N (z component of the tip force)."""
    return (2.0 if t >= 0.1 - 1e-12 else 0.0) + 0.5 * np.sin(2 * np.pi * 3 * t)


@pytest.fixture(scope="module")
def fmu_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("fmus_lib")


def _library_reference(scene, method, **settings):
    """Library run with the same piecewise-constant force (held over each communication step)."""
    times = np.array([n * H for n in range(int(round(T_END / H)) + 1)])

    def forces(t):
        F = np.zeros((scene.K, 3))
        F[TIP, 2] = tip_force(times[int(round(t / H))])
        return F

    res = ln.simulate(scene, T_END, method=method, output_dt=H, forces=forces, **settings)
    # An FMI master reads outputs after doStep, before it sets the next input: the tensions it
    # sees at t_n carry the force held over the step that ended there (direct feedthrough).
    dyn = ln.Dynamics(scene)
    T_held = np.array([dyn.tensions(res.X[n], res.U[n], forces(times[max(n - 1, 0)])) for n in range(len(times))])
    return res, T_held


@pytest.mark.parametrize("method,settings,fmu_opts", [
    ("rattle", dict(dt=1e-3), dict(step=1e-3)),
    ("dop853", dict(rtol=1e-9), dict(integrator="dop853", tolerance=1e-9)),
])
def test_simulate_fmu_with_time_varying_force_matches_library(method, settings, fmu_opts, fmu_dir):
    fmu = build_cached(fmu_dir, str(MODELS / "chain_10.json"), **fmu_opts)
    scene = ln.load_scene(MODELS / "chain_10.json")
    out = run_client(f"""
import fmpy
h, t_end = {H!r}, {T_END!r}
times = np.array([n * h for n in range(int(round(t_end / h)) + 1)])
step_sine = lambda t: (2.0 if t >= 0.1 - 1e-12 else 0.0) + 0.5 * np.sin(2 * np.pi * 3 * t)
signal = np.array([(t, step_sine(t)) for t in times], dtype=[('time', float), ('F[11,3]', float)])
names = [f'X[{{k}},{{i}}]' for k in range(1, 12) for i in (1, 2, 3)] + \\
        [f'U[{{k}},{{i}}]' for k in range(1, 12) for i in (1, 2, 3)] + [f'T[{{l}}]' for l in range(1, 11)] + \\
        ['Freact[1,1]', 'Freact[1,2]', 'Freact[1,3]']
res = fmpy.simulate_fmu({str(fmu)!r}, stop_time=t_end, output_interval=h, input=signal, output=names)
save(t=res['time'], X=np.stack([res[n] for n in names[:33]], 1).reshape(-1, 11, 3),
     U=np.stack([res[n] for n in names[33:66]], 1).reshape(-1, 11, 3),
     T=np.stack([res[n] for n in names[66:76]], 1), Freact=np.stack([res[n] for n in names[76:]], 1))
""", fmu_dir / f"client_lib_{method}")
    ref, T_held = _library_reference(scene, method, **settings)
    np.testing.assert_allclose(out["t"], ref.t, rtol=0, atol=1e-12)
    # same solver, same held inputs, same communication points: agreement to round-off
    np.testing.assert_allclose(out["X"], ref.X, rtol=0, atol=1e-11)
    np.testing.assert_allclose(out["U"], ref.U, rtol=0, atol=1e-10)
    np.testing.assert_allclose(out["T"], T_held, rtol=1e-9, atol=1e-9)
    # the force on the anchor is the link forces' reaction, from the library's own C^T T
    dyn = ln.Dynamics(scene)
    Freact = np.array([dyn.link_forces(ref.X[n], T_held[n])[0] for n in range(len(ref.t))])
    np.testing.assert_allclose(out["Freact"], Freact, rtol=1e-9, atol=1e-9)
    assert np.ptp(out["X"][:, TIP, 2]) > 0.05  # the run is not trivial: the tip moved


def test_direct_feedthrough_is_as_declared(fmu_dir):
    """Setting F changes T at once (B of (26) contains F) and leaves X and U alone, as the
    ModelStructure says; the new T equals the library's tensions for that force."""
    fmu = build_cached(fmu_dir, str(MODELS / "chain_10.json"), step=1e-3)
    out = run_client(f"""
{FMU_CLIENT_LIB}
f = Fmu({str(fmu)!r})
f.init()
t = 0.0
for n in range(20):
    f.step(t, 0.01); t += 0.01
X_names, U_names, T_names = f.names('X'), f.names('U'), f.names('T')
before = f.get(X_names + U_names + T_names)
f.set({{'F[11,3]': 3.0, 'F[5,1]': -1.0}})
after = f.get(X_names + U_names + T_names)
g = Fmu({str(fmu)!r}, 'init_mode')      # initial unknowns in initialization mode follow the parameters
g.slave.setupExperiment(startTime=0.0)
g.slave.enterInitializationMode()
g.set({{'g[1]': 4.0, 'M[11]': 0.5, 'F[11,3]': 1.0}})
T_init = g.get(T_names)
save(before=before, after=after, t=t, T_init=T_init)
""", fmu_dir / "client_feedthrough")
    n_xu = 66
    np.testing.assert_array_equal(out["after"][:n_xu], out["before"][:n_xu])
    assert np.max(np.abs(out["after"][n_xu:] - out["before"][n_xu:])) > 0.1
    scene = ln.load_scene(MODELS / "chain_10.json")
    X = out["after"][:33].reshape(11, 3)
    U = out["after"][33:66].reshape(11, 3)
    F = np.zeros((11, 3))
    F[10, 2], F[4, 0] = 3.0, -1.0
    np.testing.assert_allclose(out["after"][n_xu:], ln.Dynamics(scene).tensions(X, U, F), rtol=1e-12, atol=1e-12)
    mass = np.array(scene.mass, dtype=float)
    mass[10] = 0.5
    changed = scene.with_parameters(mass=mass, gravity=[4.0, 0.0, -9.81])
    F0 = np.zeros((11, 3))
    F0[10, 2] = 1.0
    T0 = ln.Dynamics(changed).tensions(changed.X0, changed.U0, F0)
    assert np.max(np.abs(T0)) > 1.0  # g along the chain: the links are loaded
    np.testing.assert_allclose(out["T_init"], T0, rtol=1e-12, atol=1e-12)


def test_parameters_set_in_the_fmu_give_the_library_scene_with_those_parameters(fmu_dir):
    """M, R-consistent, g set through fmpy start values = Scene.with_parameters in the library."""
    fmu = build_cached(fmu_dir, str(MODELS / "double_pendulum.json"), step=1e-3)
    start = {"M[2]": 2.5, "M[3]": 0.4, "g[1]": 1.0, "g[3]": -1.62}
    out = run_client(f"""
import fmpy
res = fmpy.simulate_fmu({str(fmu)!r}, stop_time=1.0, output_interval=0.05, start_values={start!r},
                        output=['X[3,1]', 'X[3,3]', 'T[2]'])
save(x=res['X[3,1]'], z=res['X[3,3]'], T=res['T[2]'])
""", fmu_dir / "client_params")
    scene = ln.load_scene(MODELS / "double_pendulum.json")
    mass = np.array(scene.mass, dtype=float)
    mass[1], mass[2] = 2.5, 0.4
    changed = scene.with_parameters(mass=mass, gravity=[1.0, 0.0, -1.62])
    ref = ln.simulate(changed, 1.0, method="rattle", dt=1e-3, output_dt=0.05)
    np.testing.assert_allclose(out["x"], ref.X[:, 2, 0], rtol=0, atol=1e-11)
    np.testing.assert_allclose(out["z"], ref.X[:, 2, 2], rtol=0, atol=1e-11)
    np.testing.assert_allclose(out["T"], ref.T[:, 1], rtol=1e-9, atol=1e-10)
    default = ln.simulate(scene, 1.0, method="rattle", dt=1e-3, output_dt=0.05)
    assert np.max(np.abs(default.X[:, 2, 2] - ref.X[:, 2, 2])) > 0.1  # the parameters mattered


def test_fmu_equals_linknet_simulate_cli(fmu_dir, tmp_path):
    """The FMU run through fmpy equals `linknet simulate` (the CLI) with the same settings."""
    import subprocess
    import sys
    from fmu_harness import ROOT
    fmu = build_cached(fmu_dir, str(MODELS / "four_bar.json"), integrator="dop853", tolerance=1e-9)
    npz = tmp_path / "cli.npz"
    cli = subprocess.run([sys.executable, "-m", "linknet_core.cli", "simulate", str(MODELS / "four_bar.json"),
                          "--t-end", "1.0", "--method", "dop853", "--rtol", "1e-9", "--n-out", "101",
                          "--out", str(npz), "--no-progress"], capture_output=True, text=True, cwd=str(ROOT))
    assert cli.returncode == 0, cli.stderr
    scene = ln.load_scene(MODELS / "four_bar.json")
    names = [f"X[{k + 1},{i + 1}]" for k in range(scene.K) for i in range(3)] + [f"T[{l + 1}]" for l in range(scene.L)]
    out = run_client(f"""
import fmpy
res = fmpy.simulate_fmu({str(fmu)!r}, stop_time=1.0, output_interval=0.01, output={names!r})
save(t=res['time'], values=np.stack([res[n] for n in {names!r}], 1))
""", fmu_dir / "client_cli")
    with np.load(npz) as ref:
        X, T, t = ref["X"], ref["T"], ref["t"]
    np.testing.assert_allclose(out["t"], t, atol=1e-12)
    assert np.ptp(X[:, :, :]) > 0.1
    # same method and tolerance; the output times differ in the last bit (linspace vs n*h), so
    # the adaptive step sequences may differ at round-off: agreement far below the tolerance
    np.testing.assert_allclose(out["values"][:, :3 * scene.K], X.reshape(len(t), -1), rtol=0, atol=1e-9)
    np.testing.assert_allclose(out["values"][:, 3 * scene.K:], T, rtol=1e-7, atol=1e-8)


def test_scene_with_spring_dampers_as_fmu_matches_library(fmu_dir, tmp_path):
    """Force elements travel with the scene: the monolithic coupled scene (two networks and a
    damped spring, examples/compositions/coupling.py) as one FMU equals the library run."""
    import json
    import sys
    from fmu_harness import ROOT
    sys.path.insert(0, str(ROOT / "examples" / "compositions"))
    import coupling
    scene = coupling.monolithic_scene()
    path = tmp_path / "coupled_monolithic.json"
    path.write_text(json.dumps(scene.to_dict()))
    fmu = build_cached(fmu_dir, str(path), integrator="dop853", tolerance=1e-10)
    out = run_client(f"""
import fmpy
res = fmpy.simulate_fmu({str(fmu)!r}, stop_time=1.0, output_interval=0.02, output=['X[3,1]', 'X[3,3]', 'X[5,2]'])
save(x=np.stack([res['X[3,1]'], res['X[3,3]'], res['X[5,2]']], 1))
""", fmu_dir / "client_springs")
    ref = ln.simulate(scene, 1.0, method="dop853", rtol=1e-10, output_dt=0.02)
    np.testing.assert_allclose(out["x"], np.stack([ref.X[:, 2, 0], ref.X[:, 2, 2], ref.X[:, 4, 1]], 1),
                               rtol=0, atol=1e-9)
    assert np.ptp(ref.X[:, 4, 1]) > 0.05  # the spring pulls B's bob sideways
