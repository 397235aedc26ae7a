"""FMU state save/restore/serialize (bit-identical replay), reset and reuse, independence of
instances and of different scenes' FMUs sharing one interpreter."""

import numpy as np
import pytest

from fmu_harness import FMU_CLIENT_LIB, MODELS, ROOT, build_cached, run_client  # first: repo on sys.path
import linknet_core as ln


@pytest.fixture(scope="module")
def fmu_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("fmus_state")


@pytest.mark.parametrize("opts", [dict(integrator="dop853", tolerance=1e-8), dict(step=1e-3)],
                         ids=["dop853", "rattle"])
def test_state_restore_and_deserialize_replay_bit_identically_and_reset_reuses(opts, fmu_dir):
    fmu = build_cached(fmu_dir, str(MODELS / "chain_10.json"), **opts)
    out = run_client(f"""
{FMU_CLIENT_LIB}
names = None
def run(f, t, n, h=0.013):
    rows = []
    for j in range(n):
        f.set({{'F[11,3]': np.sin(7 * t), 'F[4,1]': 0.3}})
        f.step(t, h); t += h
        rows.append(f.get(names))
    return t, np.array(rows)

f = Fmu({str(fmu)!r}, 'a')
f.init()
names = f.names('X') + f.names('U') + f.names('T') + ['error_estimate']
t, first = run(f, 0.0, 15)
state = f.slave.getFMUstate()
blob = f.slave.serializeFMUstate(state)
t_save = t
_, cont = run(f, t, 15)
f.slave.setFMUstate(state)
_, replay = run(f, t_save, 15)

g = Fmu({str(fmu)!r}, 'b')          # a fresh instance continues from the serialized state
g.init()
g.slave.setFMUstate(g.slave.deSerializeFMUstate(blob))
_, replay_g = run(g, t_save, 15)
f.slave.freeFMUstate(state)

f.slave.terminate()                    # terminate, reset and reuse: same run again from t = 0
f.slave.reset()
f.init()
_, again = run(f, 0.0, 15)
g.slave.terminate()
g.slave.freeInstance()                 # freeing one instance leaves the other working
_, after_free = run(f, 15 * 0.013, 3)
save(first=first, cont=cont, replay=replay, replay_g=replay_g, again=again, after_free=after_free,
     nbytes=len(blob))
""", fmu_dir / f"client_state_{'_'.join(opts)}")
    assert np.ptp(out["cont"][:, 32]) > 1e-3  # the tip moves during the replayed span
    np.testing.assert_array_equal(out["replay"], out["cont"])
    np.testing.assert_array_equal(out["replay_g"], out["cont"])
    np.testing.assert_array_equal(out["again"], out["first"])
    assert np.all(np.isfinite(out["after_free"]))


def test_two_instances_and_two_scenes_in_one_process_are_independent(fmu_dir):
    chain = build_cached(fmu_dir, str(MODELS / "chain_10.json"), step=1e-3)
    four_bar = build_cached(fmu_dir, str(MODELS / "four_bar.json"), step=1e-3)
    # FMUs load first here, so the client's later `import linknet_core` gets the copy bundled
    # in the first FMU's resources (sys.modules is shared): results must not change
    out = run_client(f"""
{FMU_CLIENT_LIB}
a, b = Fmu({str(chain)!r}, 'a'), Fmu({str(chain)!r}, 'b')
c = Fmu({str(four_bar)!r}, 'c')
for f in (a, b, c):
    f.init()
t, h = 0.0, 0.01
for n in range(30):                     # interleaved, with different inputs
    a.set({{'F[11,3]': 1.0}})
    b.set({{'F[11,3]': -2.0}})
    for f in (a, b, c):
        f.step(t, h)
    t += h
import linknet_core
save(xa=a.get(a.names('X')), xb=b.get(b.names('X')), xc=c.get(c.names('X')),
     core_from=np.array(linknet_core.__file__))
""", fmu_dir / "client_instances")
    # the FMU's own linknet_core (in its resources, with its native library) was in use, not the repository's
    assert "resources" in str(out["core_from"]) and not str(out["core_from"]).startswith(str(ROOT))
    for key, path, force in (("xa", "chain_10", 1.0), ("xb", "chain_10", -2.0), ("xc", "four_bar", None)):
        scene = ln.load_scene(MODELS / f"{path}.json")
        sim = ln.Simulator(scene, method="rattle", dt=1e-3)
        F = np.zeros((scene.K, 3))
        if force is not None:
            F[10, 2] = force
        t = 0.0
        for n in range(30):
            sim.advance(t + 0.01, F)
            t += 0.01
        np.testing.assert_allclose(out[key], sim.state.X.ravel(), rtol=0, atol=1e-12, err_msg=key)
