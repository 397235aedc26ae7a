"""The wheel route: `pip wheel` of the project holds every package of linknet_core, the compiled
library and the C sources, is tagged py3-none-<platform> (the library is plain C loaded with ctypes, not a
CPython extension), and imports and simulates from its own files outside the checkout.

Built offline (`--no-deps --no-build-isolation`) from a copy of what the build reads, so the checkout's build/
and in-place library are never touched nor shipped; skipped, naming what is missing, where that cannot run.
.ci/run checks the same route end to end: sdist, wheel from the sdist, a fresh venv with the dependencies.
"""
from __future__ import annotations

import email.parser
import importlib.machinery
import importlib.util
import math
import os
import shlex
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "linknet_core"
LIBRARY = "linknet_core/native/_linknet" + importlib.machinery.EXTENSION_SUFFIXES[-1]
BUILD_INPUTS = ["pyproject.toml", "setup.py", "MANIFEST.in", "README.md", "build_fmu.py"]


_PROBE = """
import importlib.util
import math
try:
    import setuptools
except ImportError:
    print("setuptools is not installed (needed to build without isolation)"); raise SystemExit
if int(setuptools.__version__.split(".")[0]) < 64:
    print(f"setuptools {setuptools.__version__} < 64 (pyproject.toml's build requirement)"); raise SystemExit
if importlib.util.find_spec("setuptools.command.bdist_wheel") is None and importlib.util.find_spec("wheel") is None:
    print(f"setuptools {setuptools.__version__} has no bdist_wheel (70.1+ has) and the wheel package is not installed "
          "(pip install '.[test]' installs it)")
"""


def _cannot_build() -> str | None:
    """Why `pip wheel --no-deps --no-build-isolation` cannot run here (None if it can)."""
    if importlib.util.find_spec("pip") is None:
        return "pip is not installed"
    # asked in a fresh interpreter: importing setuptools here, after distutils, would trip its distutils shim
    probe = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, timeout=120)
    if probe.returncode != 0 or probe.stdout.strip():
        return probe.stdout.strip() or f"setuptools does not import: {probe.stderr.strip()[-300:]}"
    compiler = shlex.split(sysconfig.get_config_var("CC") or "cc")
    if not compiler or shutil.which(compiler[0]) is None:
        return f"no C compiler ({compiler[0] if compiler else 'CC unset'}) to build the native core"
    return None


def _package_folders() -> list[str]:
    """Every package of linknet_core as a wheel path: each folder holding Python modules (native/ has no __init__)."""
    return sorted({p.parent.relative_to(ROOT).as_posix() for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts})


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    reason = _cannot_build()
    if reason:
        pytest.skip(f"cannot build the wheel offline: {reason}")
    work = tmp_path_factory.mktemp("wheel")
    source = work / "source"
    source.mkdir()
    for name in BUILD_INPUTS:
        shutil.copy2(ROOT / name, source / name)
    for folder in (PACKAGE, ROOT / "fmu_src"):  # the package, and the FMU export setup.py puts into it
        shutil.copytree(folder, source / folder.name,
                        ignore=shutil.ignore_patterns("__pycache__", "*.so", "*.pyd", "*.dylib", "*.o"))
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                           "-w", str(work / "dist"), str(source)], capture_output=True, text=True, timeout=600,
                          cwd=work)
    assert proc.returncode == 0, f"pip wheel failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    wheels = list((work / "dist").glob("linknet-*.whl"))
    assert len(wheels) == 1, wheels
    return wheels[0]


@pytest.mark.slow  # CI's slow step runs it (.ci/run): kept out of make test's 5 minutes
def test_wheel_tag_is_any_python3_on_this_platform(wheel):
    platform = sysconfig.get_platform().replace("-", "_").replace(".", "_")
    name, version, python, abi, plat = wheel.stem.split("-")
    assert (name, python, abi) == ("linknet", "py3", "none"), wheel.name
    from linknet_core.version import __version__
    assert version == __version__
    if not platform.startswith("macosx"):  # macOS tags carry the deployment target the build chose
        assert plat == platform, wheel.name
    assert plat != "any", "a wheel with a compiled library must be platform-specific"
    with zipfile.ZipFile(wheel) as z:
        meta = email.parser.Parser().parsestr(z.read(f"linknet-{version}.dist-info/WHEEL").decode())
    assert meta.get_all("Tag") == [f"py3-none-{plat}"]
    assert meta["Root-Is-Purelib"] == "false"


@pytest.mark.slow  # CI's slow step runs it (.ci/run): kept out of make test's 5 minutes
def test_wheel_holds_every_package_the_library_and_the_c_sources(wheel):
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
    folders = {n.rsplit("/", 1)[0] for n in names if n.endswith(".py")}
    assert set(_package_folders()) <= folders, sorted(set(_package_folders()) - folders)
    modules = {p.relative_to(ROOT).as_posix() for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts}
    assert modules <= names, sorted(modules - names)
    assert LIBRARY in names
    # one library, named for any Python 3 (library.py finds it by the interpreter-independent suffix)
    assert [n for n in names if n.startswith("linknet_core/native/_linknet")] == [LIBRARY]
    sources = {p.relative_to(ROOT).as_posix() for p in (PACKAGE / "native" / "src").rglob("*") if p.is_file()}
    assert sources <= names, sorted(sources - names)  # the self-contained FMU compiles them
    outside = {n for n in names if not n.startswith(("linknet_core/", "linknet-"))}
    assert not outside, sorted(outside)  # nothing else of the checkout
    assert not {n for n in names if "__pycache__" in n or n.endswith((".pyc", ".o"))}


@pytest.mark.slow  # CI's slow step runs it (.ci/run): kept out of make test's 5 minutes
def test_wheel_imports_and_simulates_from_its_own_files(wheel, tmp_path):
    """The wheel's files alone (on PYTHONPATH, the dependencies from this environment), from outside the checkout."""
    unpacked = tmp_path / "site"
    with zipfile.ZipFile(wheel) as z:
        z.extractall(unpacked)
    script = ("import linknet_core as ln, linknet_core.clib.library as lib; "
              "print(ln.__file__); print(lib.lib._name); "
              f"r = ln.simulate({str(ROOT / 'models' / 'chain_10.json')!r}, t_end=0.05, error_estimate=False); "
              "print(r.summary())")
    env = {**os.environ, "PYTHONPATH": str(unpacked)}
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300, cwd=tmp_path,
                          env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    module, library = proc.stdout.splitlines()[:2]
    assert Path(module).is_relative_to(unpacked) and Path(library).is_relative_to(unpacked), proc.stdout
    assert "chain_10" in proc.stdout


@pytest.mark.slow  # CI's slow step runs it (.ci/run): kept out of make test's 5 minutes
def test_wheel_carries_the_fmu_export_and_linknet_fmu_builds_from_it(wheel, tmp_path):
    """`linknet fmu` from the wheel's files alone, outside the checkout: build_fmu.py and fmu_src/ travel in
    linknet_core/fmu_export/ (setup.py), and the FMU it builds simulates in fmpy."""
    unpacked = tmp_path / "site"
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        z.extractall(unpacked)
    assert "linknet_core/fmu_export/build_fmu.py" in names
    assert "linknet_core/fmu_export/fmu_src/native/fmi2Functions.c" in names
    assert not {n for n in names if "fmu_export" in n and ("__pycache__" in n or n.endswith(".pyc"))}
    out = tmp_path / "chain_10.fmu"
    env = {**os.environ, "PYTHONPATH": str(unpacked), "LINKNET_FMU_PLATFORMS": "host"}
    proc = subprocess.run([sys.executable, "-m", "linknet_core.cli", "fmu", str(ROOT / "models" / "chain_10.json"),
                           "--native", "-o", str(out)], capture_output=True, text=True, timeout=600, cwd=tmp_path,
                          env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.startswith(f"built {out}"), proc.stdout
    import fmpy
    result = fmpy.simulate_fmu(str(out), stop_time=0.1)
    assert len(result) > 2 and all(math.isfinite(v) for v in result["T[1]"])
