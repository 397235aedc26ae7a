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
"""
import ctypes
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
