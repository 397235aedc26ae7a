"""Scene files, the CLI, build_fmu.py and the Python API answer every bad input at once, naming the field or option
and its rule; the general rules: every scene field type-checked, every option parsed by one validated
type (checked over the parsers' actions)."""
import argparse
import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from contract_support import MODELS, ROOT
import build_fmu
import linknet_core as ln
from linknet_core import cli

PENDULUM = {"masses": [{"name": "p", "position": [0, 0, 0], "fixed": True},
                       {"name": "a", "mass": 1.0, "position": [1, 0, 0]}], "links": [{"a": 1, "b": 2}]}


def _scene(**changes):
    data = json.loads(json.dumps(PENDULUM))
    for path, value in changes.items():
        node, keys = data, path.split(".")
        for key in keys[:-1]:
            node = node[int(key)] if isinstance(node, list) else node[key]
        node[int(keys[-1]) if isinstance(node, list) else keys[-1]] = value
    return data


@pytest.mark.parametrize("changes,words", [
    ({"masses.0.fixed": "false"}, "fixed must be a JSON boolean"),
    ({"masses.0.fixed": 0}, "fixed must be a JSON boolean"),
    ({"options": {"project_initial_positions": "no"}}, "must be a JSON boolean"),
    ({"options": {"project_initial_position": True}}, "unknown field(s) ['project_initial_position']"),
    ({"masses.1.position": [1e308, 0, 0]}, "position = [1e+308, 0, 0] is too large"),
    ({"masses.1.mass": 1e308}, "mass = 1e+308 is too large"),
    ({"gravity": [0, 0, -1e308]}, "gravity = [0, 0, -1e+308] is too large"),
    ({"masses.1.position": ["1", 0, 0]}, "must be a list of 3 numbers"),
    ({"masses.1.position": [True, 0, 0]}, "must be a list of 3 numbers"),
    ({"masses.1.name": 5}, "name must be a string"),
    ({"links.0.length": 1e-200}, "too small"),
])
def test_scene_fields_are_type_checked_and_overflow_refused(changes, words):
    with pytest.raises(ln.SceneError) as err:
        ln.Scene.from_dict(_scene(**changes))
    assert words in str(err.value)


def test_top_level_list_is_refused_with_a_message(tmp_path):
    path = tmp_path / "list.json"
    path.write_text("[1, 2]")
    with pytest.raises(ln.SceneError, match="must be a JSON object"):
        ln.load_scene(path)


def test_every_scene_field_is_type_checked():
    """The general rule: any field of a valid scene given a value of the wrong JSON type is refused by name."""
    base = json.loads((MODELS / "double_pendulum.json").read_text())
    wrong = {list: "x", str: [1], bool: "true", int: "1", float: "1.5", dict: [1]}
    checked = 0
    for section in ("masses", "links", "springs"):
        for i, entry in enumerate(base.get(section, [])):
            for key, value in entry.items():
                bad = json.loads(json.dumps(base))
                bad[section][i][key] = wrong[type(value)]
                with pytest.raises(ln.SceneError):
                    ln.Scene.from_dict(bad)
                checked += 1
    for key in ("gravity", "name"):
        bad = json.loads(json.dumps(base))
        bad[key] = wrong[type(base[key])]
        with pytest.raises(ln.SceneError):
            ln.Scene.from_dict(bad)
        checked += 1
    assert checked > 10


def _value_actions(parser):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            continue
        if action.nargs == 0 or isinstance(action, argparse._HelpAction):
            continue
        yield action


@pytest.mark.parametrize("which", ["simulate", "analyze", "check", "animate", "view", "ensemble", "build_fmu"])
def test_every_option_is_parsed_by_one_validated_type(which):
    """The general rule: each option that takes a value has a validated type (one carrying its rule) or choices."""
    if which == "build_fmu":
        parser = _build_fmu_parser()
    else:
        sub = next(a for a in cli.build_parser()._actions if isinstance(a, argparse._SubParsersAction))
        parser = sub.choices[which]
    for action in _value_actions(parser):
        assert action.choices or hasattr(action.type, "rule"), f"{which} {action.option_strings or action.dest}"


def _build_fmu_parser():
    captured = {}
    original = argparse.ArgumentParser.parse_args

    def capture(self, *args, **kwargs):
        captured["parser"] = self
        raise SystemExit(0)
    argparse.ArgumentParser.parse_args = capture
    try:
        with pytest.raises(SystemExit):
            build_fmu.main([])
    finally:
        argparse.ArgumentParser.parse_args = original
    return captured["parser"]


def _linknet(*args, timeout=120):
    return subprocess.run([sys.executable, "-m", "linknet_core.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT)


@pytest.mark.parametrize("args,words", [
    (["--n-out", "1"], "--n-out: '1' must be at least 2"),
    (["--n-out", "0"], "--n-out: '0' must be at least 2"),
    (["--n-out", "-5"], "--n-out: '-5' must be at least 2"),
    (["--method", "rk99"], "invalid choice: 'rk99'"),
    (["--dt", "-1e-3"], "--dt: '-1e-3' must be a positive"),
    (["--rtol", "1"], "--rtol: '1' must lie in [1e-15, 0.1)"),
    (["--out", "/etc/hostname/result.npz"], "--out: '/etc/hostname/result.npz' cannot be created"),
    (["--plot", "/etc/hostname/p.png"], "--plot"),
    (["--plot", "p.txt"], "is written as .png"),
])
def test_cli_refuses_bad_options_before_running(args, words):
    proc = _linknet("simulate", MODELS / "pendulum.json", "--t-end", "0.1", *args)
    assert proc.returncode == 2 and words in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr


PENDULUM_FILE = "models/pendulum.json"  # relative to the repository (the test runs there)


@pytest.mark.parametrize("argv,words", [
    (["check", PENDULUM_FILE, "--samples", "0"], "--samples: '0' must be at least 1"),
    (["check", PENDULUM_FILE, "--seed", "-1"], "--seed: '-1' must lie in [0, 2**64)"),
    (["check", "no_such_scene.json"], "'no_such_scene.json' is not a file"),
    (["animate", "RUN", "-o", "a.gif", "--fps", "0"], "--fps: '0' must be a positive finite number"),
    (["animate", "RUN", "-o", "a.gif", "--elev", "nan"], "--elev: 'nan' must be a finite number"),
    (["animate", "RUN", "-o", "a.gif", "--cmap", "rainbowish"], "--cmap: unknown colour map 'rainbowish'"),
    (["animate", "RUN", "-o", "a.gif", "--size", "5x5"], "--size: 16 to 8000 pixels each way"),
    (["animate", "RUN", "-o", "a.txt"], "-o/--out: a.txt: an animation is written as .gif or .mp4"),
    (["animate", "no_such_run.npz", "-o", "a.gif"], "result: 'no_such_run.npz' is not a file"),
    (["view", "RUN", "-o", "/etc/hostname/v.html"], "-o/--out: '/etc/hostname/v.html' cannot be created"),
    (["view", "RUN", "-o", "v.html", "--max-frames", "0"], "--max-frames: '0' must be at least 1"),
    (["view", "RUN", "-o", "v.png"], "the page is written as .html"),
    (["ensemble", PENDULUM_FILE, "--t-end", "-1"], "--t-end: '-1' must be a positive finite number"),
    (["ensemble", PENDULUM_FILE, "--t-end", "1", "--rtol", "1"], "--rtol: '1' must lie in [1e-15, 0.1)"),
    (["ensemble", PENDULUM_FILE, "--t-end", "1", "--n-samples", "0"], "--n-samples: '0' must be at least 1"),
    (["ensemble", PENDULUM_FILE, "--t-end", "1", "--n-out", "1"], "--n-out: '1' must be at least 2"),
    (["ensemble", PENDULUM_FILE, "--t-end", "1", "--method", "rk99"], "--method: invalid choice: 'rk99'"),
    (["ensemble", PENDULUM_FILE, "--t-end", "1", "--vary", "M3"], "--vary: 'M3' is not NAME=VALUES"),
    (["ensemble", PENDULUM_FILE, "--t-end", "1", "--sample", "M[2]=gauss:1:2"],
     "--sample: 'M[2]=gauss:1:2' is not NAME=uniform:LOW:HIGH or NAME=normal:MEAN:SD"),
    (["ensemble", PENDULUM_FILE, "--t-end", "1", "--outputs", "X;U"], "--outputs: 'X;U' is not a comma-separated"),
    (["ensemble", PENDULUM_FILE, "--t-end", "1", "--workers", "0"], "--workers: '0' must be at least 1"),
    (["ensemble", PENDULUM_FILE, "--t-end", "1", "--scheduler", "nohost"], "--scheduler: 'nohost' is not a Dask"),
    (["ensemble", PENDULUM_FILE, "--t-end", "1", "--fmu", PENDULUM_FILE], "--fmu: 'models/pendulum.json': FMU is a "),
    (["ensemble", PENDULUM_FILE, "--t-end", "1", "--plot", "p.pdf"], "--plot: 'p.pdf': the plot is written as .png"),
])
def test_check_animate_view_ensemble_refuse_bad_options_in_one_line(argv, words, tmp_path, monkeypatch, capsys):
    """Each bad value of the commands' options is refused while parsing, before anything runs: one line naming the
    option and its rule, exit status 2, no traceback."""
    monkeypatch.chdir(ROOT)
    run = tmp_path / "run.npz"
    run.write_bytes(b"")
    argv = [str(run) if a == "RUN" else a for a in argv]
    with pytest.raises(SystemExit) as stop:
        cli.main(argv)
    err = capsys.readouterr().err
    assert stop.value.code == 2 and words in err, err
    assert err.count("\n") == 1 and "Traceback" not in err, err


def test_ctrl_c_writes_what_was_computed_and_exits_130(tmp_path):
    out = tmp_path / "partial.npz"
    # Ctrl-C as a terminal gives it: SIGINT at its default in the command, whatever this process inherited (a runner
    # started in the background by a non-interactive shell ignores SIGINT, and an ignored signal stays ignored
    # across exec: Python then installs no KeyboardInterrupt handler)
    proc = subprocess.Popen([sys.executable, "-m", "linknet_core.cli", "simulate", MODELS / "chain_100.json",
                             "--t-end", "1000", "--dt", "1e-4", "--out", out], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=ROOT,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:   # interrupt once the run has started computing
        time.sleep(0.5)
        if proc.poll() is not None:
            break
        if time.monotonic() > deadline - 56:
            proc.send_signal(signal.SIGINT)
            break
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr
    assert "interrupted at t =" in stderr and "Traceback" not in stderr
    with np.load(out) as z:
        assert 1 <= z["t"].size < 201 and z["X"].shape[0] == z["t"].size


def _on_a_terminal(command: str, seconds: float, until: str | None = None) -> str:
    """What ``command`` writes to a terminal (script(1)) in its first ``seconds`` of running, or until it writes
    ``until``; then it is stopped (its process group killed)."""
    import os
    import select

    proc = subprocess.Popen(["script", "-qc", command, "/dev/null"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            cwd=ROOT, start_new_session=True)
    text, stop = b"", time.monotonic() + seconds
    try:
        while time.monotonic() < stop and (until is None or until.encode() not in text):
            ready, _, _ = select.select([proc.stdout], [], [], max(0.0, stop - time.monotonic()))
            chunk = os.read(proc.stdout.fileno(), 65536) if ready else b""
            if ready and not chunk:
                break  # the run ended
            text += chunk
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        proc.stdout.close()
    return text.decode(errors="replace")


def test_progress_shown_on_a_terminal_and_never_with_no_progress():
    """A run of a few seconds on a terminal draws its bar once it has taken a second; with --no-progress, none in
    its first three seconds (two past the bar's second). The runs are stopped there: what is tested is over."""
    if subprocess.run(["which", "script"], capture_output=True).returncode:
        pytest.skip("no script(1) for a terminal")
    base = f"{sys.executable} -m linknet_core.cli simulate {MODELS / 'chain_100.json'} --t-end 20 --dt 1e-4"
    assert "elapsed" in _on_a_terminal(base, 60.0, until="elapsed")
    hidden = _on_a_terminal(base + " --no-progress", 3.0)
    assert "elapsed" not in hidden and "Traceback" not in hidden


def test_progress_true_draws_on_stderr(capsys):
    ln.simulate(ln.load_scene(MODELS / "pendulum.json"), 0.05, dt=1e-3, n_out=3, progress=True)
    assert "100.0%" in capsys.readouterr().err


def test_set_state_refuses_another_scenes_snapshot():
    a = ln.Simulator(ln.builders.chain(3), dt=1e-3)
    b = ln.Simulator(ln.builders.chain(3).with_parameters(gravity=[0.0, 0.0, -1.0]), dt=1e-3)  # same masses
    with pytest.raises(ln.LinknetError, match="another scene"):
        b.set_state(a.get_state())
    with pytest.raises(ln.LinknetError, match="not a Simulator snapshot"):
        b.set_state({"state": None})
    b.set_state(b.get_state())


def test_huge_input_force_is_named():
    scene = ln.load_scene(MODELS / "double_pendulum.json")
    F = np.zeros((scene.K, 3))
    F[2, 2] = 1e12
    with pytest.raises(ln.SolverError, match=r"largest input force was F\[3,3\] = 1e\+12 N"):
        ln.Simulator(scene, dt=1e-3).advance(0.1, F)
    F[2, 2] = 1e120
    with pytest.raises(ln.SolverError, match=r"F\[3,3\] .* is 1e\+120"):
        ln.Simulator(scene, dt=1e-3).advance(0.1, F)


@pytest.mark.parametrize("t", [np.float32(0.1), np.float64(0.1), np.array(0.1), 0.1])
def test_numpy_scalars_are_times(t):
    scene = ln.load_scene(MODELS / "pendulum.json")
    sim = ln.Simulator(scene, dt=1e-3)
    sim.advance(t)
    assert sim.state.t == pytest.approx(0.1, rel=1e-7)
    assert ln.simulate(scene, t, dt=1e-3, n_out=3).t[-1] == pytest.approx(0.1, rel=1e-7)


@pytest.mark.parametrize("options,words", [
    ({"tolerance": 5}, "--tolerance = 5 must be < 0.1"), ({"step": 0}, "--step = 0 must be > 0"),
    ({"step": -1e-3}, "--step"), ({"integrator": "rk99"}, "--integrator"),
])
@pytest.mark.parametrize("native", [False, True])
def test_build_fmu_checks_options_for_both_kinds_in_one_line(options, words, native, tmp_path):
    with pytest.raises(SystemExit) as err:
        build_fmu.build_scene_fmu(MODELS / "pendulum.json", tmp_path / "p.fmu", native=native, **options)
    assert words in str(err.value) and "\n" not in str(err.value)


def test_build_fmu_refuses_an_unwritable_output_in_one_line():
    proc = subprocess.run([sys.executable, "build_fmu.py", "models/pendulum.json", "-o", "/etc/hostname/p.fmu"],
                          capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert proc.returncode == 2 and "cannot be created" in proc.stderr and "Traceback" not in proc.stderr
