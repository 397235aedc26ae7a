"""The casadi derivation of the tension system, and the checker that compares the solver with it.

Physics first (analytic tensions from the symbolic path alone), then the checker: it passes on every
shipped scene, and it catches deliberately wrong numeric assemblies injected through a test double of
the numeric side (the core is not edited).
"""
import argparse
from pathlib import Path

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.symbolic import check as checks
from linknet_core.symbolic.derivation import SymbolicTensionSystem, sign_pattern

MODELS = Path(__file__).resolve().parents[2] / "models"
SCENES = sorted(MODELS.glob("*.json"))


def _scene(masses, links, gravity=(0, 0, 0), **extra):
    return ln.Scene.from_dict({"name": "t", "gravity": list(gravity), "masses": masses, "links": links, **extra})


# ---------------------------------------------------------------------------------------------
# the derivation itself
# ---------------------------------------------------------------------------------------------

def test_hanging_chain_tensions_are_the_weight_below():
    """Static vertical chain: T_l = g * (mass below link l), from the AD-derived system alone."""
    masses = [{"name": "top", "position": [0, 0, 0], "fixed": True}]
    weights = [0.5, 1.0, 2.0, 0.25]
    for i, m in enumerate(weights):
        masses.append({"name": f"m{i}", "mass": m, "position": [0, 0, -(i + 1) * 0.7]})
    scene = _scene(masses, [{"a": i + 1, "b": i + 2} for i in range(4)], gravity=(0, 0, -9.81))
    sym = SymbolicTensionSystem(scene)
    F = sym.forces(sym.forces_function(), scene.X0, np.zeros((5, 3)), np.zeros((5, 3)))
    acc, T = sym.solve(scene.X0, np.zeros((5, 3)), F)
    below = np.cumsum(weights[::-1])[::-1]
    np.testing.assert_allclose(T, 9.81 * below, rtol=1e-13)
    np.testing.assert_allclose(acc, 0.0, atol=1e-13)


def test_whirling_pendulum_tension_is_centripetal():
    """A mass on a link, moving perpendicular to it with speed v, no gravity: T = m v^2 / R."""
    m, R, v = 1.7, 0.8, 2.3
    scene = _scene([{"name": "o", "position": [0, 0, 0], "fixed": True},
                    {"name": "b", "mass": m, "position": [R, 0, 0], "velocity": [0, v, 0]}],
                   [{"a": "o", "b": "b"}])
    sym = SymbolicTensionSystem(scene)
    acc, T = sym.solve(scene.X0, scene.U0, np.zeros((2, 3)))
    assert T[0] == pytest.approx(m * v ** 2 / R, rel=1e-14)
    np.testing.assert_allclose(acc[1], [-v ** 2 / R, 0, 0], rtol=1e-14)


def test_AD_system_is_the_seeds_25_26_on_the_manifold_and_GMG_off_it():
    """A from differentiating (11) twice equals the literal (25) where |E_l| = 1; off (11) the diagonals
    differ by exactly (|E_l|^2 - 1)(1/M_k1 + 1/M_k2), and the AD matrix is G M^-1 G^T."""
    scene = ln.load_scene(MODELS / "four_bar.json") if (MODELS / "four_bar.json").exists() else None
    if scene is None:
        pytest.skip("four_bar scene not shipped")
    sym = SymbolicTensionSystem(scene)
    X = np.array(scene.X0)
    np.testing.assert_allclose(sym.A(X).toarray(), sym.A25(X).toarray(), atol=1e-14)
    rng = np.random.default_rng(3)
    Xoff = X + 0.05 * rng.standard_normal(X.shape) * (scene.inv_mass > 0)[:, None]
    E = (Xoff[scene.k2] - Xoff[scene.k1]) / scene.length[:, None]
    gap = np.diag(sym.A(Xoff).toarray()) - np.diag(sym.A25(Xoff).toarray())
    expected = ((E ** 2).sum(1) - 1) * (scene.inv_mass[scene.k1] + scene.inv_mass[scene.k2])
    np.testing.assert_allclose(gap, expected, atol=1e-14)
    G = sym.G(Xoff).toarray()
    W = np.repeat(scene.inv_mass[sym.free], 3)
    np.testing.assert_allclose(sym.A(Xoff).toarray(), (G * W) @ G.T, atol=1e-14)
    # B of the derivation is (26) at any X
    U = rng.standard_normal(X.shape) * (scene.inv_mass > 0)[:, None]
    F = rng.standard_normal(X.shape)
    dU = U[scene.k2] - U[scene.k1]
    a = F * scene.inv_mass[:, None]
    B26 = (dU ** 2).sum(1) / scene.length + (E * (a[scene.k2] - a[scene.k1])).sum(1)
    np.testing.assert_allclose(sym.B(Xoff, U, F), B26, rtol=1e-13, atol=1e-13)


def test_sign_pattern_of_21_on_a_triangle():
    # links (1,2), (2,3), (1,3): l1,l2 meet at k2(l1)=k1(l2) -> -1; l1,l3 at k1=k1 -> +1; l2,l3 at k2=k2 -> +1
    S, shared = sign_pattern(np.array([0, 1, 0]), np.array([1, 2, 2]))
    np.testing.assert_array_equal(S, [[0, -1, 1], [-1, 0, 1], [1, 1, 0]])
    np.testing.assert_array_equal(shared, [[-1, 1, 0], [1, -1, 2], [0, 2, -1]])


def test_anchored_masses_are_eliminated_and_sparsity_is_the_scenes():
    scene = ln.load_scene(MODELS / "chain_10.json")
    sym = SymbolicTensionSystem(scene)
    n_free = int(np.count_nonzero(~scene.fixed))
    assert sym.n == 3 * n_free                              # no symbols for anchored masses
    # chain: A is tridiagonal -- links sharing a free mass, nothing else
    rows, cols = np.array(sym.sparsity.row()), np.array(sym.sparsity.get_col())
    assert np.all(np.abs(rows - cols) <= 1)
    assert sym.sparsity.nnz() == scene.L + 2 * (scene.L - 1)


# ---------------------------------------------------------------------------------------------
# the checker on the shipped scenes
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_every_check_passes_on_every_shipped_scene(path):
    scene = ln.load_scene(path)
    results = checks.run_checks(scene, samples=3, seed=1)
    failed = [r.line() for r in results if not r.passed]
    assert not failed, "\n".join(failed)
    assert len(results) == 9 or (scene.driven.any() and len(results) > 9)   # driven scenes get their own lines


@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_linknet_check_passes_on_every_shipped_scene_as_a_user_runs_it(path, capsys):
    """`linknet check models/<scene>.json` with its defaults (5 states on and 5 off the manifold, seed 0) exits 0.
    On triangulated_net its states lie near flat folds of the net, where A has eigenvalues from round-off up to
    1e-12 lambda_max next to the solver's rank cut (1e-10): the reference must cut where the solver does."""
    parser = argparse.ArgumentParser()
    checks.add_arguments(parser)
    status = checks.main(parser.parse_args([str(path)]))
    out = capsys.readouterr().out
    assert status == 0, out
    assert "FAIL" not in out and "all checks passed" in out


def test_a_solver_that_cuts_the_rank_finer_than_its_contract_is_caught():
    """A minimum-norm solve that keeps eigenvalues of A down to 1e-13 lambda_max (the solver's contract drops them
    below 1e-10) resolves near-self-stresses of triangulated_net's sampled states into large tensions: the
    accelerations line reports it. The same solve cut at the contract passes."""
    scene = ln.load_scene(MODELS / "triangulated_net.json")

    def solver(rcond):
        dyn = CorruptedDynamics(scene, lambda A, X: A)
        dyn.rcond = rcond
        return dyn

    def line(dyn):
        results = checks.run_checks(scene, samples=5, seed=0, dynamics=dyn)
        return next(r for r in results if r.name.startswith("accelerations"))

    assert line(solver(1e-10)).passed
    fine = line(solver(1e-13))
    assert not fine.passed and fine.discrepancy > 1e3 * fine.tolerance, fine.line()


def test_cli_main_prints_one_line_per_check_and_exits_zero(capsys):
    parser = argparse.ArgumentParser()
    checks.add_arguments(parser)
    status = checks.main(parser.parse_args([str(MODELS / "double_pendulum.json"), "--samples", "2", "--seed", "4"]))
    out = capsys.readouterr().out
    assert status == 0
    assert out.count("PASS") == 9 and "FAIL" not in out


def test_cli_refuses_a_missing_file_and_handles_a_scene_without_links(capsys, tmp_path):
    parser = argparse.ArgumentParser()
    checks.add_arguments(parser)
    with pytest.raises(SystemExit) as stop:  # refused by the scene argument's type, before anything runs
        parser.parse_args([str(tmp_path / "missing.json")])
    assert stop.value.code == 2 and "missing.json' is not a file" in capsys.readouterr().err
    free = tmp_path / "free.json"
    free.write_text('{"name": "free", "gravity": [0, 0, -9.81], "masses": ['
                    '{"name": "a", "mass": 1.0, "position": [0, 0, 0]}, {"name": "b", "mass": 2.0, '
                    '"position": [1, 0, 0]}], "springs": [{"a": 1, "b": 2, "stiffness": 3.0, "damping": 0.5}]}')
    assert checks.main(parser.parse_args([str(free), "--samples", "2"])) == 0


def test_kernel_line_of_the_checker(tmp_path, monkeypatch):
    from linknet_core.symbolic import codegen

    monkeypatch.setenv("LINKNET_CACHE_DIR", str(tmp_path))
    scene = ln.load_scene(MODELS / "pendulum.json")
    line = checks.run_checks(scene, samples=2, seed=0, kernel=True)[-1]
    assert line.name == "generated kernel = numeric accelerations" and line.passed
    assert line.skipped == (codegen.compiler() is None)


def test_blas_is_single_threaded_during_the_checks_and_restored_after():
    import scipy.linalg  # noqa: F401 - loads scipy's own OpenBLAS too

    ctx = checks.single_threaded_blas()
    with ctx:
        during = ctx.thread_counts()
        before = [previous for _, _, previous in ctx._restore]
    assert all(n == 1 for n in during)
    assert ctx.thread_counts() == before


def test_taut_string_violation_of_35_is_reported():
    """The seed's acknowledgment: velocities satisfying (12) with no consistent accelerations (35)."""
    scene = checks.taut_string_scene()
    results = {r.name: r for r in checks.run_checks(scene, samples=2, seed=0)}
    r = results["existence (32)-(36) and hypothesis (35)"]
    assert r.passed, r.line()
    assert "violation REPORTED" in r.detail and "taut_string at its initial positions" in r.detail
    assert "refuses it with ConsistencyError" in r.detail


# ---------------------------------------------------------------------------------------------
# the checker catches wrong assemblies (test doubles of the numeric side)
# ---------------------------------------------------------------------------------------------

class CorruptedDynamics:
    """The real Dynamics with its tension matrix replaced by ``corrupt(A, X)``; tensions and accelerations
    are then solved from the corrupted matrix, as a wrong assembly inside the solver would do."""

    rcond = 1e-10  # the minimum-norm solve's cut (an eigenvalue cut: lstsq on the symmetric A)

    def __init__(self, scene, corrupt, accept_everything=False):
        self.real = ln.Dynamics(scene)
        self.scene = scene
        self.corrupt = corrupt
        if accept_everything:
            self.check_consistent_velocities = lambda X, U, rtol=1e-8: None

    def forces(self, X, U, F_input=None):
        return self.real.forces(X, U, F_input)

    def tension_matrix(self, X):
        return self.corrupt(self.real.tension_matrix(X).toarray(), X)

    def tension_rhs(self, X, U, F):
        return self.real.tension_rhs(X, U, F)

    def tensions(self, X, U, F_input=None):
        B = self.tension_rhs(X, U, self.forces(X, U, F_input))
        return np.linalg.lstsq(self.tension_matrix(X), B, rcond=self.rcond)[0]

    def link_forces(self, X, T):
        return self.real.link_forces(X, T)

    def accelerations(self, X, U, F_input=None):
        T = self.tensions(X, U, F_input)
        acc = (self.forces(X, U, F_input) + self.link_forces(X, T)) * self.scene.inv_mass[:, None]
        return acc, T

    def check_consistent_velocities(self, X, U, rtol=1e-8):
        return self.real.check_consistent_velocities(X, U, rtol)


def flip_one_sign_of_S(A, X):
    """S(l,l') -> -S(l,l') for the first coupled pair (kept symmetric, as a wrong S table would be)."""
    A = A.copy()
    l, lp = np.argwhere(np.triu(A, 1) != 0)[0]
    A[l, lp] *= -1
    A[lp, l] *= -1
    return A


def diagonal_of_one_end_only(A, X, scene):
    """Diagonal 1/M_k1 |E|^2 instead of (1/M_k1 + 1/M_k2) |E|^2: a dropped term of (18)."""
    A = A.copy()
    E = (X[scene.k2] - X[scene.k1]) / scene.length[:, None]
    np.fill_diagonal(A, (E ** 2).sum(1) * scene.inv_mass[scene.k1])
    return A


def seeds_diagonal_everywhere(A, X, scene):
    """The literal (25) diagonal 1/M_k1 + 1/M_k2 also off the manifold."""
    A = A.copy()
    np.fill_diagonal(A, scene.inv_mass[scene.k1] + scene.inv_mass[scene.k2])
    return A


def _failed(results):
    return {r.name for r in results if not r.passed}


@pytest.fixture(scope="module")
def net():
    return ln.load_scene(MODELS / "four_bar.json")


def test_flipped_sign_in_S_is_caught(net):
    results = checks.run_checks(net, samples=2, seed=0, dynamics=CorruptedDynamics(net, flip_one_sign_of_S))
    failed = _failed(results)
    assert "A and B numeric = symbolic on the manifold" in failed
    assert "symmetry (23)-(24) and sign pattern S (21)" in failed
    assert "accelerations (9) and tensions: solver = symbolic" in failed
    sign_line = next(r for r in results if r.name.startswith("symmetry"))
    assert "wrong sign" in sign_line.detail and "entries with the wrong sign: 0" not in sign_line.detail


def test_wrong_diagonal_is_caught(net):
    dyn = CorruptedDynamics(net, lambda A, X: diagonal_of_one_end_only(A, X, net))
    failed = _failed(checks.run_checks(net, samples=2, seed=0, dynamics=dyn))
    assert {"A and B numeric = symbolic on the manifold", "A = G M^-1 G^T and A positive semidefinite",
            "accelerations (9) and tensions: solver = symbolic"} <= failed


def test_seeds_diagonal_off_the_manifold_is_reported_as_such(net):
    """A solver using (25) literally passes on the manifold but the off-manifold line names the choice."""
    dyn = CorruptedDynamics(net, lambda A, X: seeds_diagonal_everywhere(A, X, net))
    results = {r.name: r for r in checks.run_checks(net, samples=2, seed=0, dynamics=dyn)}
    assert results["A and B numeric = symbolic on the manifold"].passed
    off = results["off the manifold: solver's A is G M^-1 G^T"]
    assert not off.passed and off.extra["uses"] == "25"
    assert "seed's (25) diagonal" in off.detail


def test_solver_that_accepts_a_35_violation_is_caught():
    taut = checks.taut_string_scene()

    def factory(scene):
        return CorruptedDynamics(scene, lambda A, X: A, accept_everything=True)

    results = {r.name: r for r in checks.run_checks(taut, samples=2, seed=0, dynamics=factory(taut),
                                                      dynamics_factory=factory)}
    r = results["existence (32)-(36) and hypothesis (35)"]
    assert not r.passed and "ACCEPTS" in r.detail


def _force_element_scene():
    """A small anchored net with every force element: springs (one to an anchor), drag, constant forces."""
    masses = [{"name": "a0", "position": [0, 0, 0], "fixed": True},
              {"name": "a1", "position": [2, 0, 0], "fixed": True}]
    for i, p in enumerate([[0, 1, 0], [1, 1, 0.2], [2, 1, 0], [1, 2, -0.1]]):
        masses.append({"name": f"m{i}", "mass": 0.5 + 0.25 * i, "position": p, "drag": 0.1 * i,
                       "force": [0.2 * i, -0.1, 0.3]})
    links = [{"a": "a0", "b": "m0"}, {"a": "m0", "b": "m1"}, {"a": "m1", "b": "m2"}, {"a": "m2", "b": "a1"},
             {"a": "m1", "b": "m3"}]
    springs = [{"a": "a0", "b": "m3", "stiffness": 20.0, "damping": 0.5, "rest_length": 1.5},
               {"a": "m0", "b": "m2", "stiffness": 5.0, "damping": 0.2}]
    return _scene(masses, links, gravity=(0, 0, -9.81), springs=springs)


def test_every_check_passes_with_springs_drag_and_constant_forces():
    scene = _force_element_scene()
    results = checks.run_checks(scene, samples=3, seed=2)
    assert all(r.passed for r in results), "\n".join(r.line() for r in results if not r.passed)
    forces = next(r for r in results if r.name.startswith("external forces"))
    assert forces.discrepancy < 1e-13
