"""Import linknet_core from a stable per-user copy, so numba's compiled-kernel cache survives.

An FMI host unpacks the FMU into a fresh temporary folder for every instantiation (fmpy, most tools).
numba keys its on-disk cache by the source file's path and time stamp, so a kernel compiled from
`<tmp>/resources/linknet_core` is never found again: every new process paid ~20 s of compilation on
its first doStep (measured: `fmpy simulate chain_10.fmu` 20.8 s, then 22.0 s again).

Here the bundled linknet_core is copied once to `<cache>/core-<content hash>/linknet_core` and imported
from there; its `__pycache__` then holds numba's cache for every later process. The hash covers every
bundled source file, so FMUs built from other linknet versions never share a copy. Cache root:
$LINKNET_FMU_CACHE, else $XDG_CACHE_HOME/linknet, else ~/.cache/linknet. When the copy cannot be made
(read-only home, ...) the bundled copy is used as before and `reason` says why; when linknet_core is
already imported in the process (another linknet FMU, or a Python master that imported it) nothing
changes.

Importing this module has the effect; `location` and `reason` tell the slave what happened.
"""
import hashlib
import os
import shutil
import sys
import tempfile

location = None  # directory linknet_core is imported from, when this module chose it
reason = ""  # why the bundled copy is used instead (empty when the stable copy is used)


def _bundled_core():
    return os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "linknet_core")


def _content_hash(root):
    digest = hashlib.sha256()
    for folder, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        for name in sorted(files):
            if not name.endswith(".py"):
                continue
            path = os.path.join(folder, name)
            digest.update(os.path.relpath(path, root).encode())
            with open(path, "rb") as f:
                digest.update(f.read())
    return digest.hexdigest()[:20]


def _cache_root():
    if os.environ.get("LINKNET_FMU_CACHE"):
        return os.environ["LINKNET_FMU_CACHE"]
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "linknet")


def _install():
    global location, reason
    if "linknet_core" in sys.modules:
        reason = "linknet_core was already imported in this process"
        return
    bundled = _bundled_core()
    if not os.path.isdir(bundled):
        reason = f"no bundled linknet_core at {bundled}"
        return
    try:
        root = _cache_root()
        target = os.path.join(root, "core-" + _content_hash(bundled))
        if not os.path.isfile(os.path.join(target, "linknet_core", "__init__.py")):
            os.makedirs(root, exist_ok=True)
            # copy beside the target and rename: concurrent instantiations never see a half-written copy
            staging = tempfile.mkdtemp(prefix="staging-", dir=root)
            shutil.copytree(bundled, os.path.join(staging, "linknet_core"),
                            ignore=shutil.ignore_patterns("__pycache__"))
            try:
                os.rename(staging, target)
            except OSError:  # another process installed it first
                shutil.rmtree(staging, ignore_errors=True)
        sys.path.insert(0, target)
        location = target
    except OSError as e:
        reason = f"could not prepare the stable copy ({e}); numba recompiles in every new process"


_install()
