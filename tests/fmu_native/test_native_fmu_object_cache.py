"""The native FMU's compiled objects are cached by what each translation unit reads (build.unit_digest): the FMI 3.0
FMU, whose sources/ differ from the FMI 2.0 FMU's in the glue only, shares every other object with it; a change to a
file changes the key of the units that include it, directly or through another file, and of no other; an #include
the key cannot follow keys the unit by every source."""
from __future__ import annotations

import sys

import pytest

from native_fmu_support import MODELS, ROOT

sys.path.insert(0, str(ROOT / "fmu_src"))
from native import build as native_build  # noqa: E402
from native import build_fmi3  # noqa: E402


def _digests(sources) -> dict:
    units = sorted(p.name for p in sources.glob("*.c"))
    every = native_build.sources_digest(sources)
    return {u: native_build.unit_digest(sources, u, every) for u in units}


@pytest.fixture(scope="module")
def staged(tmp_path_factory):
    """sources/ of an FMI 2.0 and of an FMI 3.0 native FMU, as their builds lay them out (nothing compiled)."""
    fmi2, fmi3 = tmp_path_factory.mktemp("fmi2_sources"), tmp_path_factory.mktemp("fmi3_sources")
    native_build.stage_sources(fmi2, "cached")
    build_fmi3.stage_fmi3_sources(fmi3, "cached")
    return fmi2, fmi3


def test_the_fmi3_fmu_shares_every_object_but_its_glue_with_the_fmi2_fmu(staged):
    fmi2, fmi3 = (_digests(s) for s in staged)
    shared = set(fmi2) & set(fmi3)
    assert set(fmi2) - shared == {"fmi2Functions.c"} and set(fmi3) - shared == {"fmi3Functions.c"}
    assert len(shared) > 20 and all(fmi2[u] == fmi3[u] for u in shared)
    # the whole sources differ, so the linked binaries are keyed apart
    assert native_build.sources_digest(staged[0]) != native_build.sources_digest(staged[1])


def test_a_changed_file_changes_the_key_of_the_units_that_read_it_and_no_other(staged, tmp_path):
    import shutil
    sources = tmp_path / "sources"
    shutil.copytree(staged[0], sources)
    before = _digests(sources)
    # stages.h is read through "../stages.h" from the stage files that dim2.c and dim3.c include, not by the AMD units
    stages = sources / native_build.CORE_FOLDER / "stages.h"
    assert stages.is_file()
    stages.write_text(stages.read_text() + "\n/* changed */\n")
    after = _digests(sources)
    changed = {u for u in before if before[u] != after[u]}
    assert {"dim2.c", "dim3.c"} <= changed
    assert not any(u.startswith("amd_") for u in changed), changed


def test_an_include_the_key_cannot_follow_keys_the_unit_by_every_source(staged, tmp_path):
    import shutil
    sources = tmp_path / "sources"
    shutil.copytree(staged[0], sources)
    unit = sources / "ln_math.c"
    every = native_build.sources_digest(sources)
    followed = native_build.unit_digest(sources, "ln_math.c", every)
    unit.write_text(unit.read_text() + "#define ELSEWHERE \"elsewhere.h\"\n#include ELSEWHERE\n")
    every_after = native_build.sources_digest(sources)
    by_every_source = native_build.unit_digest(sources, "ln_math.c", every_after)
    assert by_every_source != followed
    # any other change anywhere in sources/ changes it now
    extra = sources / native_build.CORE_FOLDER / "unrelated.h"
    extra.write_text("/* read by no unit */\n")
    assert native_build.unit_digest(sources, "ln_math.c", native_build.sources_digest(sources)) != by_every_source


def test_an_fmi3_build_after_an_fmi2_build_compiles_its_glue_alone(staged, tmp_path, monkeypatch):
    """A cache holding the FMI 2.0 build's objects for this machine and nothing else: the FMI 3.0 build compiles its
    glue, one unit, and links; every other object is the FMI 2.0 build's."""
    import shutil

    import build_fmu
    monkeypatch.setenv(native_build.PLATFORMS_VARIABLE, "host")
    build_fmu.build_scene_fmu(str(MODELS / "pendulum.json"), tmp_path / "fmi2.fmu", quiet=True, native=True)
    every = native_build.sources_digest(staged[0])
    names = [native_build.object_name(staged[0], p.name, every) for p in staged[0].glob("*.c")]
    private = tmp_path / "cache"  # the FMI 2.0 objects copied: other builds keep the shared cache as it is
    for store in native_build.cache_dir().glob("*-objects"):
        if all((store / name).is_file() for name in names):
            (private / store.name).mkdir(parents=True)
            for name in names:
                shutil.copy2(store / name, private / store.name / name)
    assert private.is_dir()
    monkeypatch.setenv("LINKNET_FMU_CACHE", str(private))
    calls = []
    real = native_build._run_compiler
    monkeypatch.setattr(native_build, "_run_compiler", lambda cmd, cwd: (calls.append(cmd), real(cmd, cwd))[1])
    build_fmi3.build_scene_fmi3(str(MODELS / "pendulum.json"), tmp_path / "fmi3.fmu", platforms="host", quiet=True)
    compiled = [cmd[cmd.index("-c") + 1].rsplit("/", 1)[-1] for cmd in calls if "-c" in cmd]
    assert compiled == ["fmi3Functions.c"], calls
    assert sum("-shared" in cmd for cmd in calls) == 1
