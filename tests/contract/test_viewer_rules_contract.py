"""What the viewers answer: a still's time outside the run, --at given to an animation, a
run whose mass ran away (1e300 m) that makes every frame a dot, and positions beyond the float32 the HTML view
stores. Each a one-line error (exit 2) or a note, naming the file, the time or the mass."""
from __future__ import annotations

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.cli import main

from contract_support import MODELS


@pytest.fixture(scope="module")
def result_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("viewers") / "dp.npz"
    ln.simulate(str(MODELS / "double_pendulum.json"), t_end=0.5).save_npz(path)
    return path


@pytest.fixture(scope="module")
def runaway_file(result_file):
    data = dict(np.load(result_file))
    X = data["X"].copy()
    X[-5:, 2, 0] = 1e300  # the last bob leaves for 1e300 m in the last five samples
    data["X"] = X
    path = result_file.with_name("runaway.npz")
    np.savez(path, **data)
    return path


@pytest.mark.parametrize("at", ["-1", "1e9"])
def test_a_still_outside_the_run_is_refused(result_file, tmp_path, capsys, at):
    out = tmp_path / "still.png"
    assert main(["animate", str(result_file), "-o", str(out), "--at", at]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"linknet animate: error: {out}: the frame's time at = {float(at):g} s is outside the run, which "
                   "has samples from t = 0 to 0.5 s")
    assert not out.exists()


def test_a_still_inside_the_run_shows_the_nearest_sample(result_file, tmp_path, capsys):
    out = tmp_path / "still.png"
    assert main(["animate", str(result_file), "-o", str(out), "--at", "0.2501"]) == 0
    assert "t = 0.25 s" in capsys.readouterr().out and out.stat().st_size > 0


@pytest.mark.parametrize("suffix", [".gif", ".mp4"])
def test_at_with_an_animation_is_refused(result_file, tmp_path, capsys, suffix):
    out = tmp_path / f"run{suffix}"
    assert main(["animate", str(result_file), "-o", str(out), "--at", "0.2"]) == 2
    assert "--at picks the one frame of a still (OUT.png)" in capsys.readouterr().err
    assert not out.exists()


def test_a_runaway_mass_gets_a_note_naming_it(runaway_file, tmp_path, capsys):
    out = tmp_path / "still.png"
    assert main(["animate", str(runaway_file), "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert ('note: the frames span 1e+300 m' in printed and 'mass 3 ("b") is 1e+300 m from the others along an '
            'axis at t = 0.49 s, so the network is a dot in every frame' in printed), printed


def test_an_ordinary_run_gets_no_scale_note(result_file, tmp_path, capsys):
    assert main(["animate", str(result_file), "-o", str(tmp_path / "still.png")]) == 0
    assert "note:" not in capsys.readouterr().out


def test_the_html_view_refuses_positions_beyond_float32(runaway_file, tmp_path, capsys):
    out = tmp_path / "view.html"
    assert main(["view", str(runaway_file), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{out}: positions reach 1e+300 m, beyond the float32 range the HTML view stores" in err
    assert not out.exists()


def test_a_long_animation_write_says_how_far_it_is(result_file, tmp_path, capsys, monkeypatch):
    from linknet_core import visual

    monkeypatch.setattr(visual, "PROGRESS_EVERY", 0.0)  # every frame counts as long here
    out = tmp_path / "run.gif"
    assert main(["animate", str(result_file), "-o", str(out), "--max-frames", "4"]) == 0
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    # a line per frame but the last (the 'wrote' line on stdout says the end)
    assert [line.split(",")[0] for line in lines] == [f"writing {out}: frame {i} of 4" for i in (1, 2, 3)]
    assert captured.out.strip().splitlines()[-1].startswith(f"wrote {out}: 4 frames")
