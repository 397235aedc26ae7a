"""Builds the native core (linknet_core/native/src) into a shared library at install time, editable too.

The library is plain C loaded with ctypes (linknet_core/clib/library.py), not a Python extension module:
it has no Python API in it, so the same sources serve the self-contained FMU. setuptools' extension machinery
is used only to compile and link it with the platform's compiler and put it inside the package. Two things
follow from that, both set here:
  * the file is named without the interpreter's tag (`_linknet.so`, the last of EXTENSION_SUFFIXES, which
    library.py also looks for), since any Python 3 can load it;
  * the wheel is tagged `py3-none-<platform>` (say `py3-none-linux_x86_64`): platform-specific, because it holds
    compiled code, but for any Python 3 and no CPython ABI, rather than setuptools' `cp311-cp311-<platform>`.
"""
import importlib.machinery
import shutil
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext
from setuptools.command.build_py import build_py

try:  # setuptools >= 70.1 carries bdist_wheel; before that it is the `wheel` package's
    from setuptools.command.bdist_wheel import bdist_wheel
except ImportError:  # pragma: no cover - older setuptools
    try:
        from wheel.bdist_wheel import bdist_wheel
    except ImportError:  # no wheel to build here (an in-place build of the library): nothing to tag
        bdist_wheel = None

SOURCE_DIR = Path("linknet_core") / "native" / "src"
LIBRARY = "linknet_core.native._linknet"
# the interpreter-independent suffix (".so" on Linux and macOS, ".pyd" on Windows)
LIBRARY_SUFFIX = importlib.machinery.EXTENSION_SUFFIXES[-1]


def _remove_stale_libraries(folder: Path):
    for stale in folder.glob("_linknet.*"):
        if stale.name != "_linknet" + LIBRARY_SUFFIX and stale.suffix in (".so", ".pyd", ".dylib"):
            stale.unlink()


class BuildNativeLibrary(build_ext):
    def get_export_symbols(self, ext):
        return []  # no PyInit_ function to export: the library is loaded with ctypes

    def get_ext_filename(self, fullname):
        # asked with the full name and (distutils' get_ext_fullpath) with the last part alone
        if fullname in (LIBRARY, LIBRARY.rsplit(".", 1)[-1]):
            return str(Path(*fullname.split("."))) + LIBRARY_SUFFIX
        return super().get_ext_filename(fullname)

    # A library of an earlier build named with the interpreter's tag (_linknet.cpython-311-x86_64-linux-gnu.so)
    # would be found before _linknet.so and loaded stale: removed from the build folder (whence the wheel's files
    # come) before the build and, once the new library is in place (editable installs), from the package folder.
    def run(self):
        _remove_stale_libraries(Path(self.build_lib) / "linknet_core" / "native")
        super().run()

    def copy_extensions_to_source(self):
        super().copy_extensions_to_source()
        _remove_stale_libraries(Path(self.get_finalized_command("build_py").get_package_dir("linknet_core.native")))


class BuildPyWithFmuExport(build_py):
    """The FMU export travels in the wheel: build_fmu.py and fmu_src/, which the design card keeps at the top of the
    checkout, are copied into linknet_core/fmu_export/, where `linknet fmu` finds them in an installed package (an
    editable install finds them in the checkout)."""

    def run(self):
        super().run()
        if getattr(self, "editable_mode", False) or not Path("build_fmu.py").is_file():
            return
        target = Path(self.build_lib) / "linknet_core" / "fmu_export"
        target.mkdir(parents=True, exist_ok=True)
        shutil.copy2("build_fmu.py", target / "build_fmu.py")
        shutil.copytree("fmu_src", target / "fmu_src", dirs_exist_ok=True,
                        ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.o"))


commands = {"build_ext": BuildNativeLibrary, "build_py": BuildPyWithFmuExport}
if bdist_wheel is not None:
    class PlatformWheel(bdist_wheel):
        def finalize_options(self):
            super().finalize_options()
            self.root_is_pure = False  # compiled code inside: the platform tag must say which platform

        def get_tag(self):
            _, _, platform = super().get_tag()
            return "py3", "none", platform

    commands["bdist_wheel"] = PlatformWheel


setup(
    ext_modules=[Extension(
        LIBRARY,
        # AMD (src/amd, vendored): only its int64 entry points, each of which includes its generic source
        sources=sorted(str(p) for p in [*SOURCE_DIR.glob("*.c"), *SOURCE_DIR.glob("amd/amd_l*.c")]),
        include_dirs=[str(SOURCE_DIR)],
        depends=sorted(str(p) for p in SOURCE_DIR.rglob("*.[ch]")),
        extra_compile_args=["-std=c99", "-O3", "-fno-math-errno", "-ffp-contract=off", "-fvisibility=hidden", "-Wall", "-Wextra"],
    )],
    cmdclass=commands,
)
