"""Make libpython's symbols global before any C extension module is imported.

In a C host (no Python in the process) the FMU binary pulls in libpython through the
DT_NEEDED entry build_fmu.py adds, but hosts dlopen the FMU with RTLD_LOCAL, so libpython's
symbols stay private to the FMU. C extension modules (math, numpy, ...) do not link against
libpython: they expect its symbols in the global scope and fail to import
("undefined symbol: PyFloat_Type"). Re-opening the already loaded libpython with
RTLD_GLOBAL promotes it. CPython's extension loader does exactly one dlopen(path, flags)
with sys.getdlopenflags(); pointing it at libpython (which has no PyInit_ function) performs
the promotion and then fails harmlessly with ImportError. Only builtin modules are used here.

In an ordinary Python process the first `import math` succeeds and nothing is done.
"""
import os
import sys


def _loaded_libpython():
    """Full path of the libpython mapped into this process (the extension loader needs a path)."""
    stem = f"libpython{sys.version_info.major}.{sys.version_info.minor}"
    try:
        with open("/proc/self/maps") as maps:
            for line in maps:
                path = line.rstrip("\n").split(" ")[-1]
                if os.path.basename(path).startswith(stem) and ".so" in path:
                    return path
    except OSError:
        pass
    import sysconfig
    return os.path.join(sysconfig.get_config_var("LIBDIR"), sysconfig.get_config_var("INSTSONAME"))


def ensure_global_libpython():
    try:
        import math  # noqa: F401  (a C extension: importable iff libpython is global)
        return False
    except ImportError:
        pass
    import importlib.machinery
    soname = _loaded_libpython()
    old = sys.getdlopenflags()
    sys.setdlopenflags(os.RTLD_NOW | os.RTLD_GLOBAL)
    try:
        loader = importlib.machinery.ExtensionFileLoader("_linknet_libpython", soname)
        spec = importlib.machinery.ModuleSpec("_linknet_libpython", loader, origin=soname)
        try:
            loader.create_module(spec)
        except ImportError:
            pass  # expected: libpython defines no PyInit__linknet_libpython
    finally:
        sys.setdlopenflags(old)
    import math  # noqa: F401,F811  (raises if the promotion did not work)
    return True


promoted = ensure_global_libpython()
