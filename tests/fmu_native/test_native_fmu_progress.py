"""A large scene's native FMU build says how far it is: a line on stderr per stage (baking, compiling, the model
description, packing), only above build.PROGRESS_VARIABLES variables, and never when quiet."""
from __future__ import annotations

import native_fmu_support  # noqa: F401  (puts build_fmu and fmu_src on the path)
import build_fmu
from native import build as native_build


def test_a_large_build_prints_its_stages(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(native_build, "PROGRESS_VARIABLES", 0)  # every scene counts as large here
    out = tmp_path / "pendulum.fmu"
    build_fmu.build_scene_fmu("models/pendulum.json", out, native=True, platforms="host")
    err = capsys.readouterr().err.strip().splitlines()
    stages = [line.split(": ", 2)[2].rsplit(" (", 1)[0] for line in err]
    assert stages[0].startswith("baking the scene (") and stages[1:] == [
        f"compiling for {native_build.host_platform()}", "writing the model description", f"packing {out}"]
    assert all(line.startswith("build_fmu: pendulum: ") and line.endswith(" s)") for line in err)


def test_a_small_or_quiet_build_prints_none(tmp_path, capsys, monkeypatch):
    build_fmu.build_scene_fmu("models/pendulum.json", tmp_path / "a.fmu", native=True, platforms="host")
    assert capsys.readouterr().err == ""
    monkeypatch.setattr(native_build, "PROGRESS_VARIABLES", 0)
    build_fmu.build_scene_fmu("models/pendulum.json", tmp_path / "b.fmu", native=True, platforms="host", quiet=True)
    assert capsys.readouterr().err == ""
