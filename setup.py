"""Builds the native core (linknet_core/native/src) into a shared library at install time, editable too.

The library is plain C loaded with ctypes (linknet_core/native/library.py), not a Python extension module:
it has no Python API in it, so the same sources serve the self-contained FMU. setuptools' extension machinery
is used only to compile and link it with the platform's compiler and put it inside the package.
"""
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

SOURCE_DIR = Path("linknet_core") / "native" / "src"


class BuildNativeLibrary(build_ext):
    def get_export_symbols(self, ext):
        return []  # no PyInit_ function to export: the library is loaded with ctypes


setup(
    ext_modules=[Extension(
        "linknet_core.native._linknet",
        # AMD (src/amd, vendored): only its int64 entry points, each of which includes its generic source
        sources=sorted(str(p) for p in [*SOURCE_DIR.glob("*.c"), *SOURCE_DIR.glob("amd/amd_l*.c")]),
        include_dirs=[str(SOURCE_DIR)],
        depends=sorted(str(p) for p in SOURCE_DIR.rglob("*.[ch]")),
        extra_compile_args=["-std=c99", "-O3", "-fno-math-errno", "-ffp-contract=off", "-fvisibility=hidden", "-Wall", "-Wextra"],
    )],
    cmdclass={"build_ext": BuildNativeLibrary},
)
