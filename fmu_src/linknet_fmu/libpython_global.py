"""Make libpython's symbols global before any C extension module is imported.

In a C host (no Python in the process) the FMU binary pulls in libpython through the
DT_NEEDED entry build_fmu.py adds, but hosts dlopen the FMU with RTLD_LOCAL, so libpython's
symbols stay private to the FMU. C extension modules (math, numpy, ...) do not link against
libpython: they expect its symbols in the global scope and fail to import
("undefined symbol: PyFloat_Type"). Re-opening the already loaded libpython with
RTLD_GLOBAL promotes it. CPython's extension loader does exactly one dlopen(path, flags)
with sys.getdlopenflags(); pointing it at libpython (which has no PyInit_ function) performs
the promotion and then fails harmlessly with ImportError. Only builtin modules are used here.

Whether to promote is decided by what is mapped, not by importing a module: a libpython shared library
mapped into the process is re-opened with RTLD_GLOBAL (a no-op where it is global already: a Python host
linked against it); a process with no libpython mapped (a python executable with the interpreter built in)
has its symbols global already. (Testing `import math` missed Debian's libpython, which has math built in
while numpy's extensions still need the symbols.)
"""
import os
import sys


def _loaded_libpython():
    """Full path of the libpython mapped into this process (the extension loader needs a path), or None."""
    stem = f"libpython{sys.version_info.major}.{sys.version_info.minor}"
    try:
        with open("/proc/self/maps") as maps:
            for line in maps:
                path = line.rstrip("\n").split(" ")[-1]
                if os.path.basename(path).startswith(stem) and ".so" in path:
                    return path
    except OSError:
        pass
    return None


def ensure_global_libpython():
    """Promote the mapped libpython to the global scope; True if one was mapped (and so promoted)."""
    import importlib.machinery
    soname = _loaded_libpython()
    if soname is None:
        return False
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
