"""`linknet animate`, `linknet view` and `simulate --animate` from the command line: what they write, what
they report, and one clear error line (never a traceback) for bad input."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

import linknet_core as ln
from linknet_core import cli


def run_cli(*args, cwd=None):
    """The real executable path: python -m linknet_core.cli, as a user's shell runs it."""
    return subprocess.run([sys.executable, "-m", "linknet_core.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd)


def test_animate_writes_the_gif_and_reports_its_frames_and_time(chain_npz, tmp_path, capsys):
    out = tmp_path / "chain.gif"
    assert cli.main(["animate", str(chain_npz), "-o", str(out), "--max-frames", "7", "--size", "400x300"]) == 0
    report = capsys.readouterr().out
    assert report.startswith(f"wrote {out}: 7 frames of 41 samples, 400x300 px, xz view") and " s\n" in report
    with Image.open(out) as gif:
        assert (gif.n_frames, gif.size) == (7, (400, 300))


def test_animate_png_writes_one_frame(chain_npz, tmp_path, capsys):
    out = tmp_path / "still.png"
    assert cli.main(["animate", str(chain_npz), "-o", str(out), "--at", "0.5", "--view", "3d"]) == 0
    assert "t = 0.5 s, 800x600 px, 3d view" in capsys.readouterr().out
    with Image.open(out) as png:
        assert png.size == (800, 600)


def test_view_writes_one_self_contained_html(net_npz, tmp_path, capsys):
    out = tmp_path / "net.html"
    assert cli.main(["view", str(net_npz), "-o", str(out), "--max-frames", "5"]) == 0
    assert capsys.readouterr().out.startswith(f"wrote {out}: 5 frames of 31 samples")
    html = out.read_text()
    assert "<script src=" not in html.replace("<script src=\"data:", "")  # plotly.js is inline: no network needed
    assert "plotly.js v" in html and html.count("Plotly.newPlot") == 1


def test_simulate_animate_writes_the_run(tmp_path, capsys):
    scene_path = tmp_path / "chain_3.json"
    ln.builders.chain(3, name="chain_3").save(scene_path)
    out = tmp_path / "run.gif"
    assert cli.main(["simulate", str(scene_path), "--t-end", "0.4", "--dt", "1e-3", "--n-out", "11",
                     "--no-progress", "--animate", str(out)]) == 0
    assert f"wrote {out}: 11 frames of 11 samples" in capsys.readouterr().out
    with Image.open(out) as gif:
        assert gif.n_frames == 11


def test_old_result_without_anchors_is_drawn_with_a_note(chain_npz, tmp_path, capsys):
    old = tmp_path / "old.npz"
    with np.load(chain_npz) as data:
        np.savez(old, **{key: data[key] for key in data.files if key != "fixed"})
    assert cli.main(["animate", str(old), "-o", str(tmp_path / "old.gif"), "--max-frames", "2"]) == 0
    assert "note: old.npz does not say which masses are anchored" in capsys.readouterr().out


@pytest.fixture
def bad_inputs(tmp_path, chain_npz):
    text = tmp_path / "notes.npz"
    text.write_text("not an archive")
    plain = tmp_path / "plain.npy"
    np.save(plain, np.zeros(3))
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, a=np.zeros(2))
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(chain_npz.read_bytes()[:200])
    return {"missing": tmp_path / "nothing.npz", "text": text, "plain": plain, "foreign": foreign,
            "truncated": truncated, "good": chain_npz, "dir": tmp_path}


def exit_code(argv):
    try:
        return cli.main(argv)
    except SystemExit as exc:  # argparse's errors, printed before it exits
        return exc.code


@pytest.mark.parametrize("args, says", [
    (["animate", "{missing}", "-o", "{dir}/a.gif"], "nothing.npz' is not a file (it does not exist)"),
    (["animate", "{text}", "-o", "{dir}/a.gif"], "not a result file written by `linknet simulate --out`"),
    (["animate", "{dir}", "-o", "{dir}/a.gif"], "is not a file"),
    (["view", "{plain}", "-o", "{dir}/a.html"], "it holds one array"),
    (["animate", "{foreign}", "-o", "{dir}/a.gif"], "it has no t, X, T, k1, k2, mass_names"),
    (["animate", "{truncated}", "-o", "{dir}/a.gif"], "not a result file"),
    (["animate", "{good}", "-o", "{dir}/a.avi"], "written as .gif or .mp4"),
    (["animate", "{good}", "-o", "{dir}/a.gif", "--fps", "100"], "at most 50 frames per second"),
    (["view", "{good}", "-o", "{dir}/a.png"], "written as .html"),
    (["animate", "{good}", "-o", "/proc/nowhere/a.gif"], "'/proc/nowhere/a.gif' cannot be created in /proc"),
    (["animate", "{good}", "-o", "{dir}/a.gif", "--max-frames", "0"], "--max-frames: '0' must be at least 1"),
    (["animate", "{good}", "-o", "{dir}/a.gif", "--view", "side"], "--view: invalid choice: 'side'"),
    (["animate", "{good}", "-o", "{dir}/a.gif", "--size", "big"], "--size: WIDTHxHEIGHT"),
    (["animate", "{good}", "-o", "{dir}/a.gif", "--cmap", "nosuchmap"], "unknown colour map 'nosuchmap'"),
    (["view", "{good}"], "the following arguments are required: -o/--out"),
])
def test_bad_input_gets_one_error_line(bad_inputs, args, says, capsys):
    argv = [arg.format(**bad_inputs) for arg in args]
    assert exit_code(argv) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"linknet {argv[0]}: error: ") and says in lines[0], lines[0]


def test_mp4_without_ffmpeg_is_one_error_line_naming_it(chain_npz, tmp_path):
    """A fresh process with no ffmpeg on PATH: the message names ffmpeg, no traceback, nothing written."""
    out = tmp_path / "a.mp4"
    empty = tmp_path / "bin"
    empty.mkdir()
    result = subprocess.run([sys.executable, "-m", "linknet_core.cli", "animate", str(chain_npz), "-o", str(out)],
                            capture_output=True, text=True, env={"PATH": str(empty), "HOME": str(tmp_path),
                                                                 "MPLCONFIGDIR": str(tmp_path)})
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr
    assert "writing MP4 needs ffmpeg" in result.stderr and not out.exists()


def test_the_real_command_reports_errors_in_one_line(tmp_path):
    result = run_cli("view", tmp_path / "absent.npz", "-o", tmp_path / "a.html")
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr == (f"linknet view: error: argument result: '{tmp_path / 'absent.npz'}' is not a file (it "
                             "does not exist) (see linknet view --help)\n")
