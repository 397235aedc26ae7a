"""Keep the Python thread state of each host thread that calls into the FMU.

pythonfmu 0.7.0 wraps every FMI call in PyGILState_Ensure / PyGILState_Release. A thread of a C master
(every FMI toolchain) has no Python thread state, so each Ensure creates one and each Release destroys it
again: measured from a plain C host (benchmarks/c_reference/fmi2_timing_host.c, `python
benchmarks/bench_fmu.py`), about 8 us per FMI call for chain_10, more than one compiled RATTLE step of a
100-link chain, and paid twice per communication step by a master that sets inputs and steps.

Taking one extra reference (PyGILState_Ensure without a Release) from inside the first call on a thread
keeps that thread's state alive: pythonfmu's Release then only hands the GIL back
(PyEval_SaveThread) and its next Ensure only takes it (PyEval_RestoreThread). This is what CPython's
documentation of the PyGILState API allows (calls nest; the state is deleted when the count returns to
zero). In a Python host (fmpy) the calling thread already has a thread state and this only raises its
count. The cost is one thread state (a few kB) per host thread that ever calls the FMU, kept until that
thread or the process ends.

A C host that ends with exit() (fmuCheck, any plain C master) must then still end. pythonfmu finalizes Python at
exit from its own thread, and CPython 3.11's threading._shutdown waits there for the thread that first imported
threading (a host thread, here) to drop its thread state, which a kept state never does: the process hung. Beyond
that wait, finalizing an interpreter that loaded numpy and scipy corrupts the heap (SIGSEGV, or "free(): invalid
pointer" with libpython preloaded). So in a host that embeds Python (pythonfmu initialized it: sys.orig_argv is
empty) the host thread is not waited for, and the interpreter is left to the operating system at exit: the first
Python exit handler ends pythonfmu's finalizing thread before any module is torn down, and the host's own exit
carries on with its status, handlers and buffers. Python hosts (fmpy) are left alone.
"""
import atexit
import ctypes
import sys
import threading

_this_thread = threading.local()  # lives in the thread state it keeps alive
_ensure = ctypes.pythonapi.PyGILState_Ensure
_ensure.restype = ctypes.c_int
_ensure.argtypes = []


def keep() -> None:
    """Called at the top of every FMI entry point of the slaves; ~0.1 us after the first call on a thread."""
    if getattr(_this_thread, "kept", False):
        return
    _ensure()  # ctypes.pythonapi keeps the GIL during the call: this only counts one more Ensure
    _this_thread.kept = True


EMBEDDED = not getattr(sys, "orig_argv", [""])  # Python was initialized by the FMU's binary, not by a python program


def _end_finalizing_thread() -> None:
    """Python atexit handler in an embedding host: runs on pythonfmu's finalizing thread, after threading's shutdown
    and before modules are torn down, and ends that thread (pthread_exit) so Py_Finalize never reaches them."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # noqa: BLE001,S110 (a closed stream: nothing to flush)
            pass
    libc = ctypes.CDLL(None)
    libc.pthread_exit.argtypes = [ctypes.c_void_p]
    libc.pthread_exit(None)


if EMBEDDED:
    # the host thread that imported threading is the interpreter's "main thread" only by accident (bpo-1596321:
    # threading._shutdown ignores it when it runs on another thread, but still waits for its lock)
    _main = getattr(threading, "_main_thread", None)
    _locks = getattr(threading, "_shutdown_locks", None)
    if _main is not None and _locks is not None:
        with threading._shutdown_locks_lock:
            _locks.discard(getattr(_main, "_tstate_lock", None))
    atexit.register(_end_finalizing_thread)
