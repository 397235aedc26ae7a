"""One native FMU for every platform (build_fmu.py --native; fmu_src/native/build.py, README.md there).

Every shipped scene is built once with all four binaries: linux64 (x86-64, glibc 2.17 at most), win64 (PE32+ DLL),
darwin64 (one universal Mach-O: x86_64 and arm64) and aarch64-linux (the FMI 3.0 platform tuple FMI 2.0.4 names for
platforms 2.0 does not). Each exports the fmi2 functions and nothing else, and none calls a libm function: the core
computes its sin, cos, pow and hypot itself (linknet_core/native/src/ln_math.c), so that every platform rounds them
alike; the library built by setup.py calls none either. Where an emulator lets them run here (win64 under wine,
driven by native_host.c built for Windows; aarch64-linux under qemu-user, driven by native_host.c built for aarch64)
they give linux64's results bit for bit for a second of simulated time on every scene (models/*.json and
models/degenerate/*.json), dop853 and rattle, with the same inputs and settings, or stop where linux64 stops; macOS
cannot run here, so its slices' CPU types, exports, imports, minimum versions and code signature are read from the
Mach-O.

sources/ builds as a tool builds it: with the plain command `cc -shared -fPIC sources/*.c -lm`, with the
CMakeLists.txt beside them, and with fmpy's own source build as it is (no libm named): each gives a binary that
exports only the fmi2 functions and runs, with linux64's results, in the plain C host and in a host without libm."""
from __future__ import annotations

import importlib.util
import os
import re
import shutil
import struct
import subprocess
import sys
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from native_fmu_support import (AMPLITUDE_X, AMPLITUDE_Z, HERE, MODELS, N_STEPS, SCENES, H, Built, built, compile_host,
                                input_mass, output_names, parse_rows, run_host)
import build_fmu
from native.build import PLATFORMS, PLATFORMS_VARIABLE

ALL = ",".join(PLATFORMS)
COMPARED_METHODS = ("dop853", "rattle")  # the default (error-controlled) and the fixed-step method
SECONDS = 1.0  # of simulated time, compared across platforms: the motions amplify a last bit well within it
COMPARED_STEPS = round(SECONDS / H)
# every shipped scene, the degenerate ones too (they run, or stop with an explanation, on every platform alike),
# but those the library refuses to run, which have no FMU (build_fmu.py names the flexes their links cannot hold)
REFUSED = {"degenerate/braced_panel_net", "degenerate/triangulated_net_4x4_corners"}
DEGENERATE = [f"degenerate/{p.stem}" for p in sorted((MODELS / "degenerate").glob("*.json"))]
EMULATED_SCENES = SCENES + [scene for scene in DEGENERATE if scene not in REFUSED]
# The pushed triangulated net takes ~10 s here for its second with rattle, over 5 min of CPU with dop853 (stopped
# there unfinished), and qemu many times as long (rattle's second: over 10 min): linux64 and wine compare rattle's
# second and dop853's first N_STEPS, qemu rattle's first N_STEPS.
FEWER_STEPS = {("triangulated_net", "dop853"): N_STEPS}
QEMU_STEPS = {("triangulated_net", "rattle"): N_STEPS, ("triangulated_net", "dop853"): 0}
ZIG = [sys.executable, "-m", "ziglang", "cc"]
FMI2_FUNCTIONS = 34  # every function of the FMI 2.0 Co-Simulation interface (fmi2_api.h)
AARCH64_SYSROOT = Path("/usr/aarch64-linux-gnu")  # Debian's libc6-arm64-cross: the loader and libraries qemu runs


def fmu_of(scene: str, fmu_root: Path) -> Built:
    """The FMU of a shipped scene with every platform's binary (built once per session)."""
    return built(fmu_root, scene, platforms=ALL)


def binary(fmu: Built, folder: str) -> Path:
    return fmu.dir / "binaries" / folder / f"{fmu.ident}{PLATFORMS[folder].suffix}"


# ---------------------------------------------------------------------------- what was built
@pytest.mark.slow  # CI's slow step runs it (.ci/run): every platform's binaries, compiled cold on a fresh machine
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


@pytest.mark.slow  # CI's slow step runs it (.ci/run): kept out of make test's 5 minutes
@pytest.mark.skipif(shutil.which("objdump") is None or shutil.which("nm") is None,
                    reason="binutils' objdump and nm not installed (apt-get install binutils)")
@pytest.mark.parametrize("folder", ["linux64", "aarch64-linux"])
def test_linux_binaries_need_glibc_2_17_at_most_and_export_only_fmi(folder, fmu_root):
    """The manylinux2014 baseline: no symbol of a glibc newer than 2.17 (the loader refuses a binary that asks for
    one, as RHEL 8's glibc 2.28 did for hypot@GLIBC_2.35); libc only (no libm: ln_math.c); the fmi2 functions
    only."""
    for scene in SCENES:
        so = binary(fmu_of(scene, fmu_root), folder)
        versions = _glibc_versions(so)
        assert versions and max(versions) <= (2, 17), (scene, sorted(versions)[-3:])
        exported = _elf_exports(so)
        assert len(exported) == FMI2_FUNCTIONS and all(n.startswith("fmi2") for n in exported), (scene, exported)
        dynamic = subprocess.run(["objdump", "-p", str(so)], capture_output=True, text=True, check=True).stdout
        assert set(re.findall(r"NEEDED\s+(\S+)", dynamic)) == {"libc.so.6"}, (scene, dynamic)


@pytest.mark.slow  # CI's slow step runs it (.ci/run): every platform's binaries, compiled cold on a fresh machine
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
    """CPU type -> {exports, imports, minimum macOS (major, minor), signed} of every slice of a universal Mach-O."""
    magic, count = struct.unpack_from(">II", data)
    assert magic == 0xCAFEBABE, hex(magic)
    slices = {}
    for i in range(count):
        cputype, _, offset, size, align = struct.unpack_from(">iiIII", data, 8 + 20 * i)
        assert offset % (1 << align) == 0
        s = data[offset:offset + size]
        magic, sliced_cpu, _, filetype, ncmds = struct.unpack_from("<IiiII", s)
        assert magic == 0xFEEDFACF and sliced_cpu == cputype and filetype == 6  # MH_DYLIB
        info = {"exports": set(), "imports": set(), "minos": None, "signed": False}
        at = 32
        for _ in range(ncmds):
            cmd, cmdsize = struct.unpack_from("<II", s, at)
            if cmd == LC_SYMTAB:
                symoff, nsyms, stroff, _ = struct.unpack_from("<IIII", s, at + 8)
                for k in range(nsyms):
                    strx, ntype = struct.unpack_from("<IB", s, symoff + 16 * k)
                    name = s[stroff + strx:s.index(b"\0", stroff + strx)].decode()
                    if ntype & 0x0E == 0x0E and ntype & 0x01 and not ntype & 0x10:  # N_SECT, N_EXT, not N_PEXT
                        info["exports"].add(name)
                    elif ntype & 0x0E == 0 and ntype & 0x01:  # N_UNDF, N_EXT: bound by dyld to a dylib's
                        info["imports"].add(name)
            elif cmd in (LC_BUILD_VERSION, LC_VERSION_MIN_MACOSX):
                version = struct.unpack_from("<I", s, at + (12 if cmd == LC_BUILD_VERSION else 8))[0]
                info["minos"] = (version >> 16, (version >> 8) & 0xFF)
            elif cmd == LC_CODE_SIGNATURE:
                info["signed"] = True
            at += cmdsize
        slices[cputype] = info
    return slices


@pytest.mark.slow  # CI's slow step runs it (.ci/run): every platform's binaries, compiled cold on a fresh machine
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


# ---------------------------------------------------------------------------- no libm
# every function of C99's <math.h> in its double, float and long double forms, and the C libraries' own additions
MATH_FUNCTIONS = frozenset(
    name + suffix
    for name in ("acos asin atan atan2 cos sin tan acosh asinh atanh cosh sinh tanh exp exp2 expm1 exp10 pow10 frexp "
                 "ilogb ldexp log log10 log1p log2 logb modf scalbn scalbln cbrt fabs hypot pow sqrt erf erfc lgamma "
                 "tgamma gamma ceil floor nearbyint rint lrint llrint round lround llround trunc fmod remainder "
                 "remquo drem copysign nan nextafter nexttoward fdim fmax fmin fma sincos significand j0 j1 jn y0 y1 "
                 "yn finite isinf isnan").split()
    for suffix in ("", "f", "l")) | {"__fpclassify", "__signbit", "__isnan", "__isinf", "__finite"}


def _is_math(name: str) -> bool:
    return name in MATH_FUNCTIONS or re.fullmatch(r"__\w+_finite", name) is not None  # glibc's __sin_finite, ...


def _elf_math_imports(so: Path) -> set[str]:
    nm = subprocess.run(["nm", "-D", "--undefined-only", str(so)], capture_output=True, text=True, check=True).stdout
    names = {line.split()[-1].split("@")[0] for line in nm.splitlines() if line.strip()}
    dynamic = subprocess.run(["objdump", "-p", str(so)], capture_output=True, text=True, check=True).stdout
    needed = {f"{lib} (needed)" for lib in re.findall(r"NEEDED\s+(\S+)", dynamic) if lib.startswith("libm.")}
    return {n for n in names if _is_math(n)} | needed


def _pe_math_imports(dll: Path) -> set[str]:
    text = subprocess.run(["objdump", "-p", str(dll)], capture_output=True, text=True, check=True).stdout
    table = text.split("The Import Tables", 1)[1].split("The Export Tables", 1)[0]
    found = set()
    for block in table.split("DLL Name: ")[1:]:
        library = block.split()[0]
        names = re.findall(r"^\s+[0-9a-fA-F]+\s+\d+\s+(\S+)\s*$", block, re.M)
        assert names or "KERNEL32" in library.upper(), block[:500]  # the parse found the imported names
        found |= {f"{library}: {n}" for n in names if _is_math(n)}
        if "math" in library.lower():  # the Universal C Runtime's math (api-ms-win-crt-math-*), whatever it holds
            found.add(library)
    return found


def _mach_o_math_imports(dylib: Path) -> set[str]:
    return {f"{cpu:#x}: {name}" for cpu, info in mach_o_slices(dylib.read_bytes()).items() for name in info["imports"]
            if _is_math(name[1:])}  # C names carry a leading underscore


@pytest.mark.slow  # CI's slow step runs it (.ci/run): every platform's binaries, compiled cold on a fresh machine
@pytest.mark.skipif(shutil.which("objdump") is None or shutil.which("nm") is None,
                    reason="binutils' objdump and nm not installed (apt-get install binutils)")
def test_no_binary_calls_a_libm_function(fmu_root):
    """The core computes its sin, cos, pow and hypot itself (ln_math.c), the same on every platform; sqrt and fabs are
    instructions; min, max, rounding and the like are its own too. So no binary of any shipped scene, on no platform,
    imports a math function (the Universal C Runtime's math DLL on Windows, libm or a math symbol of libc on Linux,
    libSystem's on macOS)."""
    readers = {"linux64": _elf_math_imports, "aarch64-linux": _elf_math_imports, "win64": _pe_math_imports,
               "darwin64": _mach_o_math_imports}
    assert set(readers) == set(PLATFORMS)
    for scene in SCENES:
        fmu = fmu_of(scene, fmu_root)
        for folder, read in readers.items():
            assert not read(binary(fmu, folder)), (scene, folder, sorted(read(binary(fmu, folder))))


@pytest.mark.skipif(not sys.platform.startswith("linux") or shutil.which("objdump") is None
                    or shutil.which("nm") is None, reason="a Linux library read with binutils' objdump and nm")
def test_the_library_calls_no_libm_function():
    """Nor does the library setup.py builds with gcc (the same core as the FMUs' binaries)."""
    import linknet_core.clib.library as library
    assert not _elf_math_imports(Path(library.lib._name)), library.lib._name


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


@dataclass
class Outcome:
    """A run of the host: its exit status, its CSV (t and every output, %.17g: every bit) and its stderr."""
    rc: int
    rows: str
    stderr: str


STOPPED = re.compile(r"the FMU stays at t=(\S+?):")  # fmi2DoStep's message when a step cannot be taken


def _steps(scene: str, method: str) -> int:
    return FEWER_STEPS.get((scene, method), COMPARED_STEPS)


def _host_args(fmu: Built, method: str, steps: int) -> list:
    return ["run", fmu.ident, fmu.guid, 0.0, steps, H] + run_options(fmu, method)


@dataclass
class Reference:
    """linux64's run of a scene and method: `steps` steps of H, or, when the scene cannot go on for SECONDS, as far
    as it goes (the FMU stops at `stopped_at`, fmi2DoStep says why; `rows` are those of the steps before)."""
    steps: int
    rows: str
    stopped_at: float | None


def _reference(scene: str, fmu: Built, method: str, run) -> Reference:
    steps = _steps(scene, method)
    out = run(_host_args(fmu, method, steps), fmu)
    if out.rc == 0:
        return Reference(steps, out.rows, None)
    stop = STOPPED.search(out.stderr)
    assert stop, f"{fmu.ident}, {method}: exited {out.rc}\n{out.stderr[-3000:]}"
    stopped_at = float(stop.group(1))
    done = round(stopped_at / H)  # the steps before it are compared
    assert 0 < done < steps, stopped_at
    before = run(_host_args(fmu, method, done), fmu)
    assert before.rc == 0, before.stderr[-3000:]
    return Reference(done, before.rows, stopped_at)


@pytest.fixture(scope="module")
def linux64_runs(fmu_root, host, no_python_env):
    """The reference: every scene's linux64 binary in the plain C host, here, for SECONDS or as far as it goes."""
    def run(args, fmu):
        cmd = [str(host), args[0], str(fmu.dir)] + [str(a) for a in args[1:]]
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=1200, env=no_python_env)
        return Outcome(proc.returncode, proc.stdout, proc.stderr)
    return {(scene, method): _reference(scene, fmu_of(scene, fmu_root), method, run)
            for scene in EMULATED_SCENES for method in COMPARED_METHODS}


def _compare_with_linux64(scene: str, fmu: Built, run, reference: dict, platform: str, limits=None) -> int:
    """Every method's run on the platform against linux64's: every row equal, bit for bit; a run linux64 cannot take
    to its end stops at the same step, and the steps before are equal. limits: (scene, method) -> at most that many
    steps on this platform (its first rows against linux64's; 0: not run). Returns the runs compared."""
    compared = 0
    for method in COMPARED_METHODS:
        ref = reference[scene, method]
        steps = min(ref.steps, (limits or {}).get((scene, method), ref.steps))
        if steps == 0:
            continue
        what = f"{platform} vs linux64: {scene}, {method}"
        if ref.stopped_at is not None and steps == ref.steps:
            out = run(_host_args(fmu, method, _steps(scene, method)), fmu)
            stop = STOPPED.search(out.stderr)
            assert out.rc != 0 and stop and float(stop.group(1)) == ref.stopped_at, f"{what}: {out.stderr[-2000:]}"
        out = run(_host_args(fmu, method, steps), fmu)
        assert out.rc == 0, f"{what}: exited {out.rc}\n{out.stderr[-3000:]}"
        np.testing.assert_array_equal(parse_rows(out.rows), parse_rows(ref.rows)[:steps + 1], err_msg=what)
        compared += 1
    return compared


def _cross_host(tmp_path_factory, target: str, folder: str, libs: list[str]) -> Path:
    """native_host.c built with Zig for another platform, opening binaries/<folder>/ (tests/c_host/fmi2_host_api.h)."""
    if importlib.util.find_spec("ziglang") is None:
        pytest.skip("ziglang not installed (pip install ziglang)")
    exe = tmp_path_factory.mktemp(f"host_{folder}") / ("native_host.exe" if "windows" in target else "native_host")
    cmd = ZIG + ["-target", target, "-std=c99", "-O1", "-Wall", "-Wextra", "-Werror",
                 f'-DFMU_PLATFORM_FOLDER="{folder}"', f'-DFMU_LIBRARY_SUFFIX="{PLATFORMS[folder].suffix}"',
                 "-o", str(exe), str(HERE / "native_host.c")] + libs
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=exe.parent)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return exe


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
        # the host writes its rows or its error on every run it makes; an exit with nothing written at all is wine
        # failing to start the process, not the FMU's answer: that launch is retried once
        for _ in range(2):
            with open(out, "wb") as o, open(err, "wb") as e:
                rc = subprocess.run(cmd, stdin=subprocess.DEVNULL, stdout=o, stderr=e, env=env,
                                    timeout=1200).returncode
            if rc == 0 or out.stat().st_size or err.stat().st_size:
                break
        return Outcome(rc, out.read_text().replace("\r\n", "\n"), err.read_text(errors="replace"))

    compared = sum(_compare_with_linux64(scene, fmu_of(scene, fmu_root), run, linux64_runs, "win64 (wine)")
                   for scene in EMULATED_SCENES)
    assert compared == len(EMULATED_SCENES) * len(COMPARED_METHODS)


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
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=1200)
        return Outcome(proc.returncode, proc.stdout, proc.stderr)

    compared = sum(_compare_with_linux64(scene, fmu_of(scene, fmu_root), run, linux64_runs, "aarch64-linux (qemu)",
                                         QEMU_STEPS) for scene in EMULATED_SCENES)
    assert compared == len(EMULATED_SCENES) * len(COMPARED_METHODS) - list(QEMU_STEPS.values()).count(0)


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
    fmu = built(fmu_root, scene, platforms="linux64")  # the shipped binary it is compared with: no other platform
    sources = sorted(str(p.relative_to(fmu.dir)) for p in (fmu.dir / "sources").glob("*.c"))
    library = tmp_path / f"{fmu.ident}.so"
    proc = subprocess.run([GCC, "-shared", "-fPIC", *sources, "-lm", "-o", str(library)], cwd=fmu.dir,
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    exported = _elf_exports(library)
    assert len(exported) == FMI2_FUNCTIONS and all(n.startswith("fmi2") for n in exported), sorted(exported)
    _same_results_as_shipped(_rebuilt(fmu, tmp_path, library), fmu, host, no_python_env, f"{scene}: cc sources/*.c")
    assert _bare_run(bare_host, library, fmu) == _bare_run(bare_host, binary(fmu, "linux64"), fmu)


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
    exe = compile_host(tmp_path_factory, "bare_host.c", "-ldl")
    assert "libm" not in subprocess.run(["ldd", str(exe)], capture_output=True, text=True, check=True).stdout
    return exe


def _bare_run(bare_host: Path, library: Path, fmu: Built) -> str:
    """Five doSteps in the host without libm; T[1], a tension, after each (hexadecimal: every bit). The library
    reads the scene from the FMU's resources folder, wherever the library itself lies."""
    cmd = [str(bare_host), str(library), fmu.ident, fmu.guid, "5", repr(H), str(fmu.vr["T[1]"]),
           (fmu.dir / "resources").as_uri()]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env={"PATH": ""})
    assert proc.returncode == 0, f"{library}: exit {proc.returncode}\n{proc.stderr[-2000:]}"
    return proc.stdout


@pytest.mark.slow
def test_fmpy_source_build_as_it_is(fmu_root, host, bare_host, no_python_env, tmp_path):
    """fmpy's own source build (fmpy.build.build_platform_binary: CMake with fmpy's CMakeLists.txt over the
    <SourceFiles>, sources/ the include folder, no libm linked, no -fno-math-errno), called as a user calls it: its
    binary calls no libm function (the core's math is its own, sqrt the instruction), so it loads in a C host without
    libm, exports only the fmi2 functions and gives the shipped results."""
    if shutil.which("cmake") is None:
        pytest.skip("cmake not installed (apt-get install cmake): fmpy's source build needs it")
    fmpy_build = pytest.importorskip("fmpy.build")
    fmu = fmu_of("chain_10", fmu_root)
    copy = tmp_path / "fmu"
    shutil.copytree(fmu.dir, copy, ignore=shutil.ignore_patterns("binaries"))
    (tmp_path / "build").mkdir()
    fmpy_build.build_platform_binary(copy, build_dir=tmp_path / "build")
    library = copy / "binaries" / "linux64" / f"{fmu.ident}.so"
    exported = _elf_exports(library)
    assert len(exported) == FMI2_FUNCTIONS and all(n.startswith("fmi2") for n in exported), sorted(exported)
    assert not _elf_math_imports(library)
    assert _bare_run(bare_host, library, fmu) == _bare_run(bare_host, binary(fmu, "linux64"), fmu)
    _same_results_as_shipped(Built(fmu.path, copy, fmu.ident, fmu.guid, fmu.vr, fmu.md), fmu, host, no_python_env,
                             "chain_10: fmpy's build")
