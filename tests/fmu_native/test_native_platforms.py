"""One native FMU for every platform (build_fmu.py --native; fmu_src/native/build.py, README.md there).

Every shipped scene is built once with all four binaries: linux64 (x86-64, glibc 2.17 at most), win64 (PE32+ DLL),
darwin64 (one universal Mach-O: x86_64 and arm64) and aarch64-linux (the FMI 3.0 platform tuple FMI 2.0.4 names for
platforms 2.0 does not). Each exports the fmi2 functions and nothing else. Where an emulator lets them run here
(win64 under wine, driven by native_host.c built for Windows; aarch64-linux under qemu-user, driven by native_host.c
built for aarch64) they give linux64's results bit for bit on every scene, with the same inputs and settings; macOS
cannot run here, so its slices' CPU types, exports, minimum versions and code signature are read from the Mach-O.

sources/ builds as a tool builds it: with the plain command `cc -shared -fPIC sources/*.c -lm`, with the CMakeLists.txt
beside them, and with fmpy's own source build; each gives a binary that exports only the fmi2 functions and runs in
the plain C host with linux64's results."""
from __future__ import annotations

import importlib.util
import os
import re
import shutil
import struct
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from native_fmu_support import (AMPLITUDE_X, AMPLITUDE_Z, HERE, MODELS, N_STEPS, SCENES, H, Built, built, input_mass,
                                output_names, parse_rows, run_host)
import build_fmu
from native.build import PLATFORMS, PLATFORMS_VARIABLE

ALL = ",".join(PLATFORMS)
COMPARED_METHODS = ("dop853", "rattle")  # the default (error-controlled) and the fixed-step method
# 5 steps of the pushed triangulated net with dop853 take ~6 s here and ~500 s emulated: qemu runs its rattle only
QEMU_SKIPPED = {("triangulated_net", "dop853")}
ZIG = [sys.executable, "-m", "ziglang", "cc"]
FMI2_FUNCTIONS = 34  # every function of the FMI 2.0 Co-Simulation interface (fmi2_api.h)
AARCH64_SYSROOT = Path("/usr/aarch64-linux-gnu")  # Debian's libc6-arm64-cross: the loader and libraries qemu runs


def fmu_of(scene: str, fmu_root: Path) -> Built:
    """The FMU of a shipped scene with every platform's binary (built once per session)."""
    return built(fmu_root, scene, platforms=ALL)


def binary(fmu: Built, folder: str) -> Path:
    return fmu.dir / "binaries" / folder / f"{fmu.ident}{PLATFORMS[folder].suffix}"


# ---------------------------------------------------------------------------- what was built
def test_the_default_build_holds_every_platform_and_platforms_chooses(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv(PLATFORMS_VARIABLE, raising=False)
    out = tmp_path / "chain_10.fmu"
    build_fmu.main([str(MODELS / "chain_10.json"), "--native", "-o", str(out)])
    with zipfile.ZipFile(out) as z:
        names = set(z.namelist())
    assert {f"binaries/{p}/chain_10{spec.suffix}" for p, spec in PLATFORMS.items()} <= names
    assert {n for n in names if n.startswith("binaries/")} == {f"binaries/{p}/chain_10{s.suffix}"
                                                               for p, s in PLATFORMS.items()}
    build_fmu.main([str(MODELS / "chain_10.json"), "--native", "--platforms", "win64,darwin64", "-o", str(out)])
    with zipfile.ZipFile(out) as z:
        assert {n for n in z.namelist() if n.startswith("binaries/")} == {"binaries/win64/chain_10.dll",
                                                                         "binaries/darwin64/chain_10.dylib"}
    capsys.readouterr()
    with pytest.raises(SystemExit) as e:  # refused when the options are parsed, as every option's bad value is
        build_fmu.main([str(MODELS / "chain_10.json"), "--native", "--platforms", "linux64,win32", "-o", str(out)])
    error = capsys.readouterr().err.strip().splitlines()[-1]
    assert e.value.code == 2 and "error: argument --platforms: platforms: unknown platform" in error
    assert "'win32'" in error and "aarch64-linux" in error


def test_platforms_need_the_native_fmu(capsys):
    with pytest.raises(SystemExit):
        build_fmu.main([str(MODELS / "chain_10.json"), "--platforms", "host"])
    assert "--platforms chooses the binaries of the native FMU: give --native" in capsys.readouterr().err


def _glibc_versions(so: Path) -> set[tuple[int, ...]]:
    text = subprocess.run(["objdump", "-T", str(so)], capture_output=True, text=True, check=True).stdout
    return {tuple(int(x) for x in v.split(".")) for v in re.findall(r"GLIBC_([0-9.]+)", text)}


def _elf_exports(so: Path) -> set[str]:
    nm = subprocess.run(["nm", "-D", "--defined-only", str(so)], capture_output=True, text=True, check=True).stdout
    return {line.split()[-1] for line in nm.splitlines() if line.strip()}


@pytest.mark.skipif(shutil.which("objdump") is None or shutil.which("nm") is None,
                    reason="binutils' objdump and nm not installed (apt-get install binutils)")
@pytest.mark.parametrize("folder", ["linux64", "aarch64-linux"])
def test_linux_binaries_need_glibc_2_17_at_most_and_export_only_fmi(folder, fmu_root):
    """The manylinux2014 baseline: no symbol of a glibc newer than 2.17 (the loader refuses a binary that asks for
    one, as RHEL 8's glibc 2.28 did for hypot@GLIBC_2.35); libm and libc only; the fmi2 functions only."""
    for scene in SCENES:
        so = binary(fmu_of(scene, fmu_root), folder)
        versions = _glibc_versions(so)
        assert versions and max(versions) <= (2, 17), (scene, sorted(versions)[-3:])
        exported = _elf_exports(so)
        assert len(exported) == FMI2_FUNCTIONS and all(n.startswith("fmi2") for n in exported), (scene, exported)
        dynamic = subprocess.run(["objdump", "-p", str(so)], capture_output=True, text=True, check=True).stdout
        assert set(re.findall(r"NEEDED\s+(\S+)", dynamic)) == {"libc.so.6", "libm.so.6"}, (scene, dynamic)


@pytest.mark.skipif(shutil.which("objdump") is None, reason="binutils' objdump not installed (apt-get install binutils)")
def test_win64_binary_is_a_dll_exporting_only_fmi(fmu_root):
    for scene in SCENES:
        dll = binary(fmu_of(scene, fmu_root), "win64")
        assert dll.read_bytes()[:2] == b"MZ"
        text = subprocess.run(["objdump", "-p", str(dll)], capture_output=True, text=True, check=True).stdout
        assert "Magic\t\t\t020b" in text and "(PE32+)" in text or "pei-x86-64" in text, text[:500]
        table = text.split("[Ordinal/Name Pointer] Table", 1)[1].split("\n\n", 1)[0]
        exported = set(re.findall(r"\]\s+(\S+)", table))
        assert len(exported) == FMI2_FUNCTIONS and all(n.startswith("fmi2") for n in exported), (scene, exported)


# Mach-O, read here: no macOS tool needed (llvm-lipo, where installed, checks the same universal header below)
LC_SYMTAB, LC_VERSION_MIN_MACOSX, LC_CODE_SIGNATURE, LC_BUILD_VERSION = 0x2, 0x24, 0x1D, 0x32
CPU_X86_64, CPU_ARM64 = 0x01000007, 0x0100000C
LINKER_SYMBOLS = {"__mh_dylib_header", "___dso_handle"}  # defined by the linker in the dylib itself


def mach_o_slices(data: bytes) -> dict[int, dict]:
    """CPU type -> {exports, minimum macOS (major, minor), signed} of every slice of a universal Mach-O."""
    magic, count = struct.unpack_from(">II", data)
    assert magic == 0xCAFEBABE, hex(magic)
    slices = {}
    for i in range(count):
        cputype, _, offset, size, align = struct.unpack_from(">iiIII", data, 8 + 20 * i)
        assert offset % (1 << align) == 0
        s = data[offset:offset + size]
        magic, sliced_cpu, _, filetype, ncmds = struct.unpack_from("<IiiII", s)
        assert magic == 0xFEEDFACF and sliced_cpu == cputype and filetype == 6  # MH_DYLIB
        info = {"exports": set(), "minos": None, "signed": False}
        at = 32
        for _ in range(ncmds):
            cmd, cmdsize = struct.unpack_from("<II", s, at)
            if cmd == LC_SYMTAB:
                symoff, nsyms, stroff, _ = struct.unpack_from("<IIII", s, at + 8)
                for k in range(nsyms):
                    strx, ntype = struct.unpack_from("<IB", s, symoff + 16 * k)
                    if ntype & 0x0E == 0x0E and ntype & 0x01 and not ntype & 0x10:  # N_SECT, N_EXT, not N_PEXT
                        info["exports"].add(s[stroff + strx:s.index(b"\0", stroff + strx)].decode())
            elif cmd in (LC_BUILD_VERSION, LC_VERSION_MIN_MACOSX):
                version = struct.unpack_from("<I", s, at + (12 if cmd == LC_BUILD_VERSION else 8))[0]
                info["minos"] = (version >> 16, (version >> 8) & 0xFF)
            elif cmd == LC_CODE_SIGNATURE:
                info["signed"] = True
            at += cmdsize
        slices[cputype] = info
    return slices


def test_darwin64_is_one_universal_binary_for_intel_and_apple_silicon(fmu_root):
    """macOS cannot run here. Both slices are dylibs exporting the fmi2 functions only; arm64 carries the ad-hoc
    code signature Apple silicon refuses to load code without; minimum versions as PLATFORMS says."""
    for scene in SCENES:
        dylib = binary(fmu_of(scene, fmu_root), "darwin64")
        slices = mach_o_slices(dylib.read_bytes())
        assert set(slices) == {CPU_X86_64, CPU_ARM64}
        for cpu, info in slices.items():
            fmi = {n for n in info["exports"] if n.startswith("_fmi2")}
            assert len(fmi) == FMI2_FUNCTIONS and info["exports"] - fmi <= LINKER_SYMBOLS, (scene, cpu, info)
        assert slices[CPU_ARM64]["signed"] and slices[CPU_ARM64]["minos"] == (11, 0)
        assert slices[CPU_X86_64]["minos"] == (10, 13)
    lipo = next((shutil.which(n) for n in ("lipo", "llvm-lipo", "llvm-lipo-16", "llvm-lipo-15", "llvm-lipo-14")
                 if shutil.which(n)), None)
    if lipo:  # an independent reader of the universal header agrees
        info = subprocess.run([lipo, "-info", str(dylib)], capture_output=True, text=True, check=True).stdout
        assert "x86_64" in info and "arm64" in info, info


# ---------------------------------------------------------------------------- runs: linux64 here, others emulated
def run_options(fmu: Built, method: str) -> list[str]:
    """The host's options: a constant push on the last mass with inputs (native_fmu_support's input without its
    cos(W t): the host would compute that with its own platform's cos, and the inputs, not the FMUs, would differ),
    the method, every output."""
    k = input_mass(fmu)
    opts = ["-i", f"{fmu.vr[f'F[{k},1]']}={AMPLITUDE_X!r}", "-i", f"{fmu.vr[f'F[{k},3]']}={AMPLITUDE_Z!r}",
            "-m", f"{fmu.vr['integrator']}={method}"]
    for name in output_names(fmu):
        opts += ["-o", str(fmu.vr[name])]
    return opts


def _runs(fmu: Built, run, skipped=frozenset()) -> dict[str, str]:
    """method -> the host's CSV of N_STEPS steps of H (t and every output; %.17g: every bit)."""
    scene = fmu.path.name.split("_native")[0]
    return {method: run(["run", fmu.ident, fmu.guid, 0.0, N_STEPS, H] + run_options(fmu, method), fmu)
            for method in COMPARED_METHODS if (scene, method) not in skipped}


@pytest.fixture(scope="module")
def linux64_runs(fmu_root, host, no_python_env):
    """The reference: every scene's linux64 binary in the plain C host, here."""
    def run(args, fmu):
        return run_host(host, no_python_env, args[0], fmu, *args[3:])
    return {scene: _runs(fmu_of(scene, fmu_root), run) for scene in SCENES}


def _cross_host(tmp_path_factory, target: str, folder: str, libs: list[str]) -> Path:
    """native_host.c built with Zig for another platform, opening binaries/<folder>/ (cross_host/dlfcn.h)."""
    if importlib.util.find_spec("ziglang") is None:
        pytest.skip("ziglang not installed (pip install ziglang)")
    exe = tmp_path_factory.mktemp(f"host_{folder}") / ("native_host.exe" if "windows" in target else "native_host")
    cmd = ZIG + ["-target", target, "-std=c99", "-O1", "-Wall", "-Wextra", "-Werror", "-I", str(HERE / "cross_host"),
                 f'-DFMU_PLATFORM_FOLDER="{folder}"', f'-DFMU_LIBRARY_SUFFIX="{PLATFORMS[folder].suffix}"',
                 "-o", str(exe), str(HERE / "native_host.c")] + libs
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=exe.parent)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return exe


def _compare(scene: str, got: dict[str, str], reference: dict[str, str], platform: str):
    assert got
    for method, text in got.items():
        ours, theirs = parse_rows(text), parse_rows(reference[method])
        np.testing.assert_array_equal(ours, theirs, err_msg=f"{platform} vs linux64: {scene}, {method}")


@pytest.fixture(scope="module")
def wine(tmp_path_factory):
    """wine with a fresh prefix of its own, made here (~10 s), and its wineserver and services kept running between
    the runs (a run then starts in ~0.2 s instead of ~2.5 s), stopped at the end. The services are started with no
    pipe of ours open: a service holding a run's stdout would keep that run from ever reaching end of file."""
    exe, server = shutil.which("wine64") or shutil.which("wine"), shutil.which("wineserver")
    if exe is None or server is None:
        pytest.skip("wine not installed (apt-get install wine64): the win64 binary is not run here")
    prefix = tmp_path_factory.mktemp("wineprefix")
    env = dict(os.environ, WINEPREFIX=str(prefix), WINEDEBUG="-all", WINEDLLOVERRIDES="mscoree,mshtml=")
    persistent = subprocess.Popen([server, "-p"], env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                  stderr=subprocess.DEVNULL)
    subprocess.run([exe, "wineboot", "--init"], env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL, timeout=300)
    yield exe, env
    subprocess.run([server, "-k"], env=env, timeout=60)
    persistent.wait(timeout=60)


@pytest.mark.slow
def test_win64_under_wine_equals_linux64_on_every_scene(fmu_root, tmp_path_factory, wine, linux64_runs):
    exe, env = wine
    host = _cross_host(tmp_path_factory, "x86_64-windows-gnu", "win64", [])

    def run(args, fmu):  # output through files: the wait is for the run alone, not for whoever holds a pipe
        cmd = [exe, str(host), args[0], "Z:" + str(fmu.dir)] + [str(a) for a in args[1:]]
        out, err = host.parent / "stdout.txt", host.parent / "stderr.txt"
        with open(out, "wb") as o, open(err, "wb") as e:
            rc = subprocess.run(cmd, stdin=subprocess.DEVNULL, stdout=o, stderr=e, env=env, timeout=600).returncode
        assert rc == 0, f"{' '.join(cmd[:5])} ... exited {rc}\n{err.read_text(errors='replace')[-3000:]}"
        return out.read_text().replace("\r\n", "\n")

    for scene in SCENES:
        _compare(scene, _runs(fmu_of(scene, fmu_root), run), linux64_runs[scene], "win64 (wine)")


@pytest.fixture(scope="module")
def qemu():
    exe = shutil.which("qemu-aarch64-static") or shutil.which("qemu-aarch64")
    if exe is None:
        pytest.skip("qemu-user not installed (apt-get install qemu-user-static): the aarch64 binary is not run here")
    if not (AARCH64_SYSROOT / "lib" / "ld-linux-aarch64.so.1").exists():
        pytest.skip(f"no aarch64 C library at {AARCH64_SYSROOT} (apt-get install libc6-arm64-cross): the aarch64 "
                    "binary is not run here")
    return exe


@pytest.mark.slow
def test_aarch64_linux_under_qemu_equals_linux64_on_every_scene(fmu_root, tmp_path_factory, qemu, linux64_runs):
    host = _cross_host(tmp_path_factory, "aarch64-linux-gnu.2.17", "aarch64-linux", ["-ldl", "-lpthread", "-lm"])

    def run(args, fmu):
        cmd = [qemu, "-L", str(AARCH64_SYSROOT), str(host), args[0], str(fmu.dir)] + [str(a) for a in args[1:]]
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, f"{' '.join(cmd[:6])} ... exited {proc.returncode}\n{proc.stderr[-3000:]}"
        return proc.stdout

    for scene in SCENES:
        _compare(scene, _runs(fmu_of(scene, fmu_root), run, QEMU_SKIPPED), linux64_runs[scene], "aarch64-linux (qemu)")


# ---------------------------------------------------------------------------- sources/ as tools build them
def _rebuilt(fmu: Built, where: Path, library: Path) -> Built:
    """A copy of the unzipped FMU whose linux64 binary is ``library``."""
    copy = where / "fmu"
    shutil.copytree(fmu.dir, copy)
    shutil.copy2(library, copy / "binaries" / "linux64" / f"{fmu.ident}.so")
    return Built(fmu.path, copy, fmu.ident, fmu.guid, fmu.vr, fmu.md)


def _same_results_as_shipped(rebuilt: Built, fmu: Built, host, env, what: str):
    for method in COMPARED_METHODS:
        opts = run_options(fmu, method)
        shipped = run_host(host, env, "run", fmu, 0.0, N_STEPS, H, *opts)
        again = run_host(host, env, "run", rebuilt, 0.0, N_STEPS, H, *opts)
        np.testing.assert_array_equal(parse_rows(again), parse_rows(shipped), err_msg=f"{what}, {method}")


GCC = shutil.which("gcc") or shutil.which("cc")


@pytest.mark.skipif(GCC is None, reason="no C compiler (apt-get install gcc)")
@pytest.mark.parametrize("scene", ["net_10x10", "spinning_tetrahedron"])
def test_sources_build_with_the_plain_command(scene, fmu_root, host, bare_host, no_python_env, tmp_path):
    """`cc -shared -fPIC sources/*.c -lm`, run from the unzipped FMU: AMD included, nothing but the fmi2 functions
    exported, libm recorded (the host without libm runs it), the shipped results."""
    fmu = fmu_of(scene, fmu_root)
    sources = sorted(str(p.relative_to(fmu.dir)) for p in (fmu.dir / "sources").glob("*.c"))
    library = tmp_path / f"{fmu.ident}.so"
    proc = subprocess.run([GCC, "-shared", "-fPIC", *sources, "-lm", "-o", str(library)], cwd=fmu.dir,
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    exported = _elf_exports(library)
    assert len(exported) == FMI2_FUNCTIONS and all(n.startswith("fmi2") for n in exported), sorted(exported)
    _same_results_as_shipped(_rebuilt(fmu, tmp_path, library), fmu, host, no_python_env, f"{scene}: cc sources/*.c")
    assert _bare_run(bare_host, library, fmu) == _bare_run(bare_host, binary(fmu, "linux64"), fmu)  # libm needed


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("cmake") is None, reason="cmake not installed (apt-get install cmake)")
def test_sources_build_with_their_cmakelists(fmu_root, host, no_python_env, tmp_path):
    fmu = fmu_of("net_10x10", fmu_root)
    build = tmp_path / "build"
    for cmd in (["cmake", "-S", str(fmu.dir / "sources"), "-B", str(build)], ["cmake", "--build", str(build)]):
        proc = subprocess.run(cmd, capture_output=True, text=True)
        assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    library = build / f"{fmu.ident}.so"
    exported = _elf_exports(library)
    assert len(exported) == FMI2_FUNCTIONS and all(n.startswith("fmi2") for n in exported), sorted(exported)
    _same_results_as_shipped(_rebuilt(fmu, tmp_path, library), fmu, host, no_python_env, "net_10x10: CMakeLists.txt")


@pytest.fixture(scope="module")
def bare_host(tmp_path_factory) -> Path:
    """bare_host.c: a C host with no libm in its process (linked with libc and libdl only)."""
    if GCC is None:
        pytest.skip("no C compiler (apt-get install gcc)")
    exe = tmp_path_factory.mktemp("bare_host") / "bare_host"
    subprocess.run([GCC, "-std=c99", "-O1", "-Wall", "-Wextra", "-Werror", "-o", str(exe), str(HERE / "bare_host.c"),
                    "-ldl"], check=True)
    assert "libm" not in subprocess.run(["ldd", str(exe)], capture_output=True, text=True, check=True).stdout
    return exe


def _bare_run(bare_host: Path, library: Path, fmu: Built) -> str:
    """Five doSteps in the host without libm; T[1], a tension, after each (hexadecimal: every bit)."""
    cmd = [str(bare_host), str(library), fmu.ident, fmu.guid, "5", repr(H), str(fmu.vr["T[1]"])]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env={"PATH": ""})
    assert proc.returncode == 0, f"{library}: exit {proc.returncode}\n{proc.stderr[-2000:]}"
    return proc.stdout


@pytest.mark.slow
def test_fmpy_source_build_with_libm_named(fmu_root, host, bare_host, no_python_env, tmp_path):
    """fmpy's own source build (fmpy.build.build_platform_binary: CMake with fmpy's CMakeLists.txt over the
    <SourceFiles>, sources/ the include folder) compiles the sources as they are, into a binary that exports only the
    fmi2 functions and gives the shipped results. fmpy's CMakeLists.txt links no libm, so that binary loads only into
    a process that already has libm (fmpy's Python, a host linked with -lm; a host without it fails with `undefined
    symbol: sincos`); cmake_options={"CMAKE_C_STANDARD_LIBRARIES": "-lm"} links it, and the host without libm runs it."""
    if shutil.which("cmake") is None:
        pytest.skip("cmake not installed (apt-get install cmake): fmpy's source build needs it")
    fmpy_build = pytest.importorskip("fmpy.build")
    fmu = fmu_of("chain_10", fmu_root)
    copy = tmp_path / "fmu"
    shutil.copytree(fmu.dir, copy, ignore=shutil.ignore_patterns("binaries"))
    (tmp_path / "build").mkdir()
    fmpy_build.build_platform_binary(copy, build_dir=tmp_path / "build",
                                     cmake_options={"CMAKE_C_STANDARD_LIBRARIES": "-lm"})
    library = copy / "binaries" / "linux64" / f"{fmu.ident}.so"
    exported = _elf_exports(library)
    assert len(exported) == FMI2_FUNCTIONS and all(n.startswith("fmi2") for n in exported), sorted(exported)
    assert _bare_run(bare_host, library, fmu) == _bare_run(bare_host, binary(fmu, "linux64"), fmu)
    _same_results_as_shipped(Built(fmu.path, copy, fmu.ident, fmu.guid, fmu.vr, fmu.md), fmu, host, no_python_env,
                             "chain_10: fmpy's build")
