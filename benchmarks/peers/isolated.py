"""Run benchmark settings in a worker process with a hard per-run timeout.

A peer can hang (Exudyn's Newton iterating for minutes at a tiny step) and a fine setting of any method can
run far longer than its predecessor predicted; a timeout inside the same process cannot interrupt a C++
library. So every run goes to one long-lived worker process (spawned once, reused by every method and scene,
so imports, numba compilation and model caches are paid once as they were in-process); when a run exceeds
its timeout the worker is killed, the run is recorded as a timeout, and the next run starts a fresh worker.

Timing is unchanged by the isolation: `Method.run` times the integration only, inside the worker, exactly as
it did in the driver process; the driver additionally records the wall time of the whole request
(model construction, warm-up, repeats, inter-process transfer) for the budget.
"""
from __future__ import annotations

import multiprocessing as mp
import os
import time
import traceback

from .base import OverBudget, RunResult, Unsupported

# the worker integrates on one core, as the benchmark always has (the 2 cores are shared)
STARTUP_TIMEOUT = 120.0
_SINGLE_THREAD_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def measure(method, spec, t_end, knob, repeat_below: float) -> RunResult:
    """One setting; runs shorter than `repeat_below` seconds are repeated (up to 5 in all), fastest kept."""
    best = method.run(spec, t_end, knob)
    total = best.seconds
    for _ in range(4):
        if total >= repeat_below or best.seconds >= repeat_below / 5:
            break
        r = method.run(spec, t_end, knob)
        total += r.seconds
        if r.seconds < best.seconds:
            best = r
    return best


def _worker_main(conn, quiet: bool):
    if quiet:   # peers (Exudyn) print pages of solver chatter to stdout from C++: keep the driver's log readable
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
    import numpy  # noqa: F401  (the common imports before "ready": process start-up is not part of a run's timeout)
    import scipy.integrate  # noqa: F401
    conn.send(("ready", None))
    while True:
        try:
            msg = conn.recv()
        except EOFError:
            return
        if msg is None:
            return
        method, spec, t_end, knob, repeat_below = msg
        try:
            conn.send(("ok", measure(method, spec, t_end, knob, repeat_below)))
        except Unsupported as e:
            conn.send(("unsupported", str(e)))
        except OverBudget as e:
            conn.send(("skipped", str(e)))
        except BaseException as e:   # a failing run is a result; say what failed
            msg = f"{type(e).__name__}: {e}"
            if not str(e):
                msg += " | " + traceback.format_exc(limit=3).replace("\n", " ")
            conn.send(("failed", msg))


class IsolatedRunner:
    """One worker process, restarted after a timeout or a crash. Use as a context manager."""

    def __init__(self, quiet: bool = True):
        self.quiet = quiet
        self._ctx = mp.get_context("spawn")
        self._proc = None
        self._conn = None
        self.restarts = 0

    def _start(self):
        saved = {k: os.environ.get(k) for k in _SINGLE_THREAD_ENV}
        for k, v in _SINGLE_THREAD_ENV.items():
            os.environ.setdefault(k, v)
        try:
            parent, child = self._ctx.Pipe()
            self._proc = self._ctx.Process(target=_worker_main, args=(child, self.quiet), daemon=True)
            self._proc.start()
        finally:
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
        child.close()
        self._conn = parent
        if not parent.poll(STARTUP_TIMEOUT) or parent.recv()[0] != "ready":
            self._kill()
            raise RuntimeError(f"benchmark worker process did not start within {STARTUP_TIMEOUT} s")

    def _kill(self):
        if self._proc is not None:
            if self._proc.is_alive():
                self._proc.kill()
            self._proc.join(5)
        if self._conn is not None:
            self._conn.close()
        self._proc = self._conn = None
        self.restarts += 1

    def run(self, method, spec, t_end, knob, repeat_below: float, timeout: float):
        """-> (status, payload, wall_seconds): status 'ok' (payload RunResult), 'failed' / 'unsupported' /
        'skipped' (payload a message) or 'timeout' (the worker was killed after `timeout` seconds)."""
        if self._proc is None or not self._proc.is_alive():
            self._start()
        t0 = time.perf_counter()
        try:
            self._conn.send((method, spec, t_end, knob, repeat_below))
            if not self._conn.poll(timeout):
                self._kill()
                return "timeout", f"no result after {timeout:.0f} s: worker process killed", time.perf_counter() - t0
            status, payload = self._conn.recv()
        except (EOFError, BrokenPipeError, ConnectionResetError, OSError) as e:
            code = self._proc.exitcode if self._proc is not None else None
            self._kill()
            return "failed", f"worker process died (exit code {code}): {type(e).__name__}", time.perf_counter() - t0
        return status, payload, time.perf_counter() - t0

    def close(self):
        if self._proc is not None and self._proc.is_alive():
            try:
                self._conn.send(None)
                self._proc.join(10)
            except (BrokenPipeError, OSError):
                pass
            if self._proc.is_alive():
                self._proc.kill()
                self._proc.join(5)
        self._proc = self._conn = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


class InProcessRunner:
    """The same interface without isolation (no timeout possible): for debugging with --in-process."""
    restarts = 0

    def run(self, method, spec, t_end, knob, repeat_below: float, timeout: float):
        t0 = time.perf_counter()
        try:
            return "ok", measure(method, spec, t_end, knob, repeat_below), time.perf_counter() - t0
        except Unsupported as e:
            return "unsupported", str(e), time.perf_counter() - t0
        except OverBudget as e:
            return "skipped", str(e), time.perf_counter() - t0
        except Exception as e:
            return "failed", f"{type(e).__name__}: {e}", time.perf_counter() - t0

    def close(self):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False
