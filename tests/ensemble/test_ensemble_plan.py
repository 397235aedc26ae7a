"""Parameter names, values and the plan of members (no Dask here: refusals come before anything runs)."""
import numpy as np
import pytest

import linknet_core as ln
from linknet_core.ensemble import make_plan, parse_name, parse_values
from linknet_core.ensemble.parameters import member_forces, member_scene

from .ensemble_support import MODELS


@pytest.fixture(scope="module")
def chain():
    return ln.load_scene(MODELS / "chain_10.json")


def test_names_resolve_to_fmu_indices(chain):
    assert parse_name("M[3]", chain).targets == ((2,),)
    assert parse_name("R[1..10]", chain).targets == tuple((l,) for l in range(10))
    assert parse_name("F[11, 3]", chain).name == "F[11,3]"
    assert parse_name("F[2..3,1..2]", chain).fmu_variables() == ["F[2,1]", "F[2,2]", "F[3,1]", "F[3,2]"]
    assert parse_name("integrator", chain).targets == ((),)


@pytest.mark.parametrize("name,words", [
    ("Q[1]", "unknown parameter"),
    ("M[1]", "anchored"),  # chain_10's mass 1 is its anchor
    ("M[12]", "outside 1..11"),
    ("R[3..2]", "empty"),
    ("F[11]", "needs 2 index"),
    ("step[1]", "takes no index"),
    ("stiffness[1]", "outside 1..0"),  # chain_10 has no springs
])
def test_bad_names_are_refused_with_the_rule(chain, name, words):
    with pytest.raises(ln.LinknetError, match=words):
        parse_name(name, chain)


def test_value_texts(chain):
    p = parse_name("M[3]", chain)
    np.testing.assert_array_equal(parse_values("0.5:2:4", p), [0.5, 1.0, 1.5, 2.0])  # both ends included
    np.testing.assert_array_equal(parse_values("1,2.5", p), [1.0, 2.5])
    np.testing.assert_array_equal(parse_values("3", p), [3.0])
    with pytest.raises(ln.LinknetError, match="start:stop:count"):
        parse_values("1:2", p)
    with pytest.raises(ln.LinknetError, match="at least 2"):
        parse_values("1:2:1", p)
    assert list(parse_values("rattle,dop853", parse_name("integrator", chain))) == ["rattle", "dop853"]
    with pytest.raises(ln.LinknetError, match="unknown method"):
        parse_values("rk4", parse_name("integrator", chain))


def test_grid_is_c_order_and_samples_run_at_every_grid_point(chain):
    plan = make_plan(chain, vary={"M[3]": [1, 2], "g[3]": [-9.81, -1.62, 0]},
                     samples=[{"U0[11,1]": 0.1}, {"U0[11,1]": 0.2}])
    assert plan.n_members == 12 and plan.grid_shape == (2, 3) and plan.n_samples == 2
    assert plan.setting(0) == {"M[3]": 1.0, "g[3]": -9.81, "U0[11,1]": 0.1}
    assert plan.setting(1) == {"M[3]": 1.0, "g[3]": -9.81, "U0[11,1]": 0.2}
    assert plan.setting(2) == {"M[3]": 1.0, "g[3]": -1.62, "U0[11,1]": 0.1}
    assert plan.setting(11) == {"M[3]": 2.0, "g[3]": 0.0, "U0[11,1]": 0.2}


def test_overlapping_names_and_ragged_samples_are_refused(chain):
    with pytest.raises(ln.LinknetError, match="both set R\\[3\\]"):
        make_plan(chain, vary={"R[1..10]": [0.1], "R[3]": [0.2]})
    with pytest.raises(ln.LinknetError, match="different lengths"):
        make_plan(chain, samples={"M[3]": [1, 2], "M[4]": [1]})


def test_fmu_studies_refuse_what_the_fmu_has_no_parameter_for(chain):
    make_plan(chain, vary={"M[3]": [1], "F[11,3]": [1], "step": [1e-3]}).check_fmu(atol=None)
    with pytest.raises(ln.LinknetError, match="no parameter for X0\\[2,1\\]"):
        make_plan(chain, vary={"X0[2,1]": [0.1]}).check_fmu(atol=None)


def test_member_values_reach_the_scene_and_the_input_forces(chain):
    plan = make_plan(chain, vary={"R[1..10]": [0.12], "g[1]": [2.0], "U0[11,3]": [0.5], "F[11,3]": [3.0],
                                  "drag[5]": [0.1]})
    data = member_scene(chain.to_dict(), plan.parameters, plan.setting(0))
    scene = ln.Scene.from_dict(data)
    np.testing.assert_array_equal(scene.length, np.full(10, 0.12))
    np.testing.assert_array_equal(scene.gravity, [2.0, 0.0, -9.81])
    assert scene.U0[10, 2] == 0.5 and scene.drag[4] == 0.1
    forces = member_forces(plan.parameters, plan.setting(0), chain.K)
    assert forces[10, 2] == 3.0 and np.count_nonzero(forces) == 1
    solver_only = make_plan(chain, vary={"step": [1e-3]})
    assert member_scene(chain.to_dict(), solver_only.parameters, solver_only.setting(0)) is None


def test_study_options_are_checked_before_anything_runs():
    scene = MODELS / "chain_10.json"
    with pytest.raises(ln.LinknetError, match="t_end"):
        ln.ensemble(scene, vary={"M[3]": [1]}, t_end=-1)
    with pytest.raises(ln.LinknetError, match="unknown output"):
        ln.ensemble(scene, vary={"M[3]": [1]}, t_end=1, outputs=["Y"])
    with pytest.raises(ln.LinknetError, match="give rtol, not dt"):
        ln.ensemble(scene, vary={"M[3]": [1]}, t_end=1, method="dop853", dt=1e-3)


def test_batch_size_follows_member_time_output_size_and_the_end_of_the_study():
    """Members per task: one until a member's time is known; then TASK_SECONDS of work; on a cluster of more
    threads than TASK_SECONDS * MAX_TASKS_PER_SECOND, threads / MAX_TASKS_PER_SECOND seconds; never more outputs
    than MAX_TASK_BYTES; near the end, the remaining members over the threads, but not below TAIL_TASK_SHARE of a
    full task, unless the whole study is too small to give every thread four tasks that size."""
    from linknet_core.ensemble.engine import MAX_TASK_BYTES, MAX_TASKS_PER_SECOND, TAIL_TASK_SHARE, TASK_SECONDS, \
        _BatchSizer

    chain_member_bytes = 8 * 201 * (33 + 33 + 10) + 100  # chain_10 with X, U, T at 201 times
    sizer = _BatchSizer(None, chain_member_bytes)
    assert sizer.size(remaining=10_000, threads=2) == 1
    sizer.record([0.004, 0.006])  # 5 ms per member
    assert sizer.size(remaining=10_000, threads=2) == int(TASK_SECONDS / 0.005)
    many = 10 * TASK_SECONDS * MAX_TASKS_PER_SECOND
    assert sizer.size(remaining=10**9, threads=int(many)) == MAX_TASK_BYTES // chain_member_bytes
    assert _BatchSizer(None, 100).size(remaining=10**9, threads=1) == 1  # nothing recorded yet
    quantities_only = _BatchSizer(None, 100)
    quantities_only.record([0.005])
    assert quantities_only.size(remaining=10**9, threads=int(many)) == int(many / MAX_TASKS_PER_SECOND / 0.005)
    full = int(TASK_SECONDS / 0.005)
    assert sizer.size(remaining=full, threads=2) == full // 2  # the last members spread over both threads
    floor = int(TAIL_TASK_SHARE * full)
    assert sizer.size(remaining=floor, threads=2) == floor  # not below the floor: one task takes them
    assert sizer.size(remaining=floor // 2, threads=2) == floor // 2  # never more than remain
    small = _BatchSizer(None, chain_member_bytes, total=40)  # 40 members on 2 threads: tasks of 40 // 8 = 5 at least
    small.record([0.005])
    assert small.size(remaining=30, threads=2) == 15
    assert small.size(remaining=6, threads=2) == 5
    assert _BatchSizer(7, chain_member_bytes).size(remaining=10_000, threads=2) == 7  # members_per_task=7
