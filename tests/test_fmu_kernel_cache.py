"""The FMU keeps numba's compiled kernels across processes (fmu_src/linknet_fmu/stable_core.py).

Hosts unpack an FMU into a fresh folder per instantiation; numba's cache is keyed by source path, so
without a stable copy of linknet_core every new process recompiled (~20 s on the first doStep)."""
from __future__ import annotations

import os

from fmu_harness import FMU_CLIENT_LIB, MODELS, build_cached, run_client

CLIENT = FMU_CLIENT_LIB + """
import sys
f = Fmu(FMU_PATH)
f.init()
t = 0.0
for n in range(5):
    f.step(t, 0.01)
    t += 0.01
core = sys.modules["linknet_core"].__file__
save(core=np.array(core), tip=f.get([f.names("X")[-1]]))
"""


def _cache_files(root):
    found = {}
    for folder, _, files in os.walk(root):
        for name in files:
            if name.endswith((".nbi", ".nbc")):
                path = os.path.join(folder, name)
                found[path] = os.stat(path).st_mtime_ns
    return found


def test_second_process_reuses_the_compiled_kernels(tmp_path, tmp_path_factory, monkeypatch):
    cache = tmp_path / "cache"
    monkeypatch.setenv("LINKNET_FMU_CACHE", str(cache))
    fmu = build_cached(tmp_path_factory.getbasetemp(), str(MODELS / "chain_10.json"))
    first = run_client(f"FMU_PATH = {str(fmu)!r}\n" + CLIENT, tmp_path / "first")
    # linknet_core came from the stable copy, not from the unpacked FMU nor the repository
    assert str(first["core"]).startswith(str(cache))
    compiled = _cache_files(cache)
    assert any("rattle" in p for p in compiled), "the first process left no numba cache for the RATTLE loop"
    second = run_client(f"FMU_PATH = {str(fmu)!r}\n" + CLIENT, tmp_path / "second")
    assert str(second["core"]) == str(first["core"])
    # nothing recompiled: the cache files are exactly those of the first process, untouched
    assert _cache_files(cache) == compiled
    assert float(second["tip"][0]) == float(first["tip"][0])
