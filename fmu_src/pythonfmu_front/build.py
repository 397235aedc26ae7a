"""Compile the pythonfmu FMU's front layer (front.c, see its header) with the system C compiler.

build_fmu.py ships pythonfmu's binary as binaries/linux64/<model>_pythonfmu.so and this layer as
binaries/linux64/<model>.so, the file a host loads: every pythonfmu FMU (scenes and components) gets it.
"""
from __future__ import annotations

import hashlib
import os
import shlex
import shutil
import subprocess
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "front.c"
FMI_HEADERS = HERE.parent / "native"  # fmi2_api.h: the FMI 2.0 declarations, written once for both FMU kinds
CFLAGS = ["-std=c99", "-O2", "-fPIC", "-shared", "-Wall", "-Wextra"]
# never unloaded (hosts such as fmpy dlclose the binary after each fmi2FreeInstance): the parked instances and the
# live states outlive a dlclose, and pythonfmu's binary, with the interpreter in it, cannot be unloaded anyway
LDFLAGS = ["-Wl,-z,nodelete", "-ldl", "-lpthread"]


class FrontBuildError(RuntimeError):
    """The front layer cannot be compiled (the message says why)."""


def inner_library_name(model_identifier: str) -> str:
    """File name of pythonfmu's own binary inside the FMU, beside the front layer."""
    return f"{model_identifier}_pythonfmu.so"


def compiler() -> str:
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if not cc:
        raise FrontBuildError("no C compiler found (cc, gcc or clang on PATH, or CC): the pythonfmu FMU's front "
                              "layer (fmu_src/pythonfmu_front/front.c) is compiled when the FMU is built")
    return cc


def compile_front(model_identifier: str, derivative_vr_base: int | None = None) -> bytes:
    """The front layer's shared library for this model identifier. With derivative_vr_base, input derivatives reach
    the slave as fmi2SetReal of the value reference order * derivative_vr_base + vr.

    Kept in the per-user FMU cache (native.build.cache_dir), keyed by the compiler (its path and its --version), the
    command and what it reads (front.c and the FMI headers): a scene's FMU built again, or another scene's with the
    same model identifier, compiles nothing."""
    from native.build import cache_dir, store_by_rename

    cc = compiler()
    defines = [f'-DFRONT_INNER_LIBRARY="{inner_library_name(model_identifier)}"',
               *([f"-DFRONT_DERIVATIVE_VR_BASE={int(derivative_vr_base)}u"] if derivative_vr_base else [])]
    key = hashlib.sha256("\0".join([cc, _compiler_version(cc), *CFLAGS, *LDFLAGS, *defines]).encode())
    for read in [SOURCE, *sorted(FMI_HEADERS.glob("*.h"))]:
        key.update(b"\0" + read.name.encode() + b"\0" + read.read_bytes())
    kept = cache_dir() / "pythonfmu-front" / f"{model_identifier}.{key.hexdigest()[:32]}.so"
    if kept.is_file():
        return kept.read_bytes()
    with tempfile.TemporaryDirectory(prefix="linknet_front_") as tmp:
        out = Path(tmp) / kept.name
        cmd = [*shlex.split(cc), *CFLAGS, f"-I{FMI_HEADERS}", *defines, "-o", str(out), str(SOURCE), *LDFLAGS]
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        except (OSError, subprocess.SubprocessError) as e:
            raise FrontBuildError(f"the C compiler {cc!r} could not be run: {e}") from e
        if proc.returncode != 0:
            raise FrontBuildError(f"compiling {SOURCE.name} failed ({' '.join(cmd)}):\n{proc.stderr.strip()}")
        data = out.read_bytes()
        try:
            store_by_rename(out, kept.parent)
        except OSError:
            pass  # a cache that cannot be written (read-only home, full disk) costs the next build a compile only
        return data


_compiler_versions: dict = {}


def _compiler_version(cc: str) -> str:
    """What ``cc --version`` prints (once per process): part of the cache key, so that a new compiler compiles anew."""
    if cc not in _compiler_versions:
        try:
            _compiler_versions[cc] = subprocess.run([*shlex.split(cc), "--version"], capture_output=True, text=True,
                                                    timeout=60).stdout
        except (OSError, subprocess.SubprocessError) as e:
            raise FrontBuildError(f"the C compiler {cc!r} could not be run: {e}") from e
    return _compiler_versions[cc]
