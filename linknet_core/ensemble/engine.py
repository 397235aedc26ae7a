"""Running a study on Dask: the client, the stream of member batches, retries after a worker dies.

* ``client=None`` starts a ``LocalCluster`` on 127.0.0.1 with one single-threaded worker process per core
  and closes it afterwards; an address (``"tcp://host:8786"``) or a ``distributed.Client`` uses that
  cluster as it is.
* Members go out in batches of consecutive members, at most two batches per worker thread in flight, so
  the scheduler holds a few tasks whatever the study's size. The first batches hold one member each (the
  first result comes as soon as possible); later batches are sized from the measured member time to about
  ``TASK_SECONDS`` each, so that Dask's cost per task (TASK_OVERHEAD_SECONDS of CPU time in the client,
  scheduler and worker) stays about TASK_OVERHEAD_SHARE of the work, and never so large that the last batches
  leave workers idle.
* Results are fetched as they finish and handed to the sink (the study file) at once, then released, so the
  cluster never holds more than the batches in flight. A batch's trajectories are not in its result where its
  worker wrote them into the study's shard folder (members.run_batch): the result is its quantities of
  interest, status and errors, ~100 bytes a member. A fetch that fails (a connection fault) is tried again, and
  after FETCH_ATTEMPTS the batch runs again: a study never waits on a result that cannot come. A sink whose
  write fails (a full disk) goes on in its rescue file, and the study with it.
* When a worker dies, the scheduler reruns the batches it was running and any finished result not yet
  fetched from it (the "remove-worker" event names those tasks; this module listens to it): those members
  are the study's retried members. A batch whose workers keep dying (``KilledWorker``) is split into single
  members, so only a member that itself kills workers fails, with that as its error.
"""
from __future__ import annotations

import contextlib
import functools
import logging
import math
import os
import socket
import struct
import threading
import time
from collections import deque
from concurrent.futures import CancelledError
from dataclasses import dataclass, field

from linknet_core.errors import LinknetError
from linknet_core.output import WriteError
from linknet_core.scene import Scene
from linknet_core.ensemble.members import StudyPayload, StudySpec, error_text, output_values, run_batch
from linknet_core.ensemble.parameters import Plan

# CPU time Dask spends on one task of a study, whatever its size: 3.5-5 ms in the client and scheduler (submit, the
# scheduler's transitions, the result's fetch and release, the batch's record in the file) and 2-2.5 ms in the
# worker (benchmarks/bench_ensemble.py's per-task figures k_c, k_w: studies of trivial members, one per task, on
# this project's 2-core machine; a shard file adds ~1.3 ms on the worker)
TASK_OVERHEAD_SECONDS = 0.006
TASK_OVERHEAD_SHARE = 0.01  # a task holds about 1 / this times its overhead in work
TASK_SECONDS = TASK_OVERHEAD_SECONDS / TASK_OVERHEAD_SHARE  # target work per task once the member time is known
# The client's and scheduler's part, ~5 ms per task, is kept to about a fifth of their core: at most this many
# tasks per second, so on a large cluster tasks grow to threads / MAX_TASKS_PER_SECOND seconds of work
MAX_TASKS_PER_SECOND = 40
# a batch's outputs stay below this: a batch is held whole by its worker until written into its shard (or fetched,
# and then by the client until written)
MAX_TASK_BYTES = 64 << 20
# the last tasks of a study hold at least this share of a full task's work: TASK_SECONDS / 4 leaves a worker
# idle at most ~0.15 s at the end, and keeps Dask's cost per task below 4 % of the work
TAIL_TASK_SHARE = 0.25
WORKER_WAIT_SECONDS = 60.0  # how long a study waits for the first worker of an existing cluster
CONNECT_TIMEOUT = 10.0  # seconds to connect to a scheduler address and see its Dask handshake (connect_timeout=)
SCHEDULER_PORT = 8786  # Dask's default scheduler port (its dashboard's HTTP server: 8787)
_HANDSHAKE_MAX_BYTES = 1 << 20  # a scheduler's handshake is ~100 bytes; a first frame announcing more is not one


@dataclass
class Progress:
    """Where a study stands; handed to the progress callback after every finished batch."""

    total: int
    workers: int
    done: int = 0
    failed: int = 0
    retried: int = 0
    tasks: int = 0  # batches submitted (a batch split after KilledWorker counts its singles too)
    started: float = field(default_factory=time.perf_counter)
    first_result_seconds: float | None = None
    member_cpu_seconds: float = 0.0  # CPU time of the members' own runs, summed over the workers
    write_cpu_seconds: float = 0.0  # CPU time of this thread writing the results into the study file and shards
    worker_write_cpu_seconds: float = 0.0  # CPU time of the workers writing their shards

    @property
    def elapsed(self) -> float:
        return time.perf_counter() - self.started


def available_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


# Dask settings of the LocalCluster a study starts (its scheduler, client, nannies and workers). Dask's defaults
# suit a long-lived cluster watched on its dashboard; here they cost the study's cores (benchmarks/bench_ensemble.py,
# 2 workers: ~30 ms of CPU time per second in the client and scheduler and as much in the workers, ~10 with
# these settings), and the workers' statistical profiler, which samples the running task's stack every 10 ms for
# the dashboard's profile page, cost 0.1-0.3 ms per chain_10 member (up to 5 % of its work).
LOCAL_CLUSTER_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "200ms",  # the event loops' health check (a warning when one blocks 3 s)
    "distributed.admin.system-monitor.interval": "2s",  # CPU and memory samples for the dashboard and heartbeats
}


def local_cluster(workers: int):
    """The local cluster a study starts, and a client of it: its scheduler in a process of its own
    (scheduler_process.py: a LocalCluster's runs in this process, where it shares the GIL with the client's
    fetches, writes and submits), and ``workers`` single-threaded worker processes on 127.0.0.1 (the solver holds
    the GIL in its Python layers, so threads in one process would queue), each under a nanny in this process that
    restarts it if it dies, as a LocalCluster's; Dask's log messages below ERROR silenced, LOCAL_CLUSTER_CONFIG set
    (the nannies pass it to their workers, the scheduler process is given it)."""
    import dask
    from distributed import Client, Nanny, SpecCluster
    from distributed.worker_memory import parse_memory_limit

    with dask.config.set(LOCAL_CLUSTER_CONFIG):
        worker = {"cls": Nanny, "options": {
            "host": "127.0.0.1", "nthreads": 1, "dashboard": False, "silence_logs": logging.ERROR,
            "memory_limit": parse_memory_limit("auto", 1, workers, logger=logging.getLogger("distributed"))}}
        cluster = SpecCluster(workers={i: worker for i in range(workers)}, worker=worker,
                              scheduler={"cls": scheduler_process_class(), "options": {"config": LOCAL_CLUSTER_CONFIG}},
                              silence_logs=logging.ERROR, name="linknet-study")
        try:
            return cluster, Client(cluster)
        except BaseException:
            cluster.close()
            raise


@functools.lru_cache(maxsize=None)
def scheduler_process_class():
    """The SpecCluster scheduler class of a study's local cluster (made when first asked for: it subclasses a Dask
    class, and importing this module does not import distributed)."""
    from distributed.deploy.spec import ProcessInterface

    class SchedulerProcess(ProcessInterface):
        """A Dask scheduler in a child process (``python -m linknet_core.ensemble.scheduler_process``), as a
        SpecCluster's scheduler: started with the given Dask settings, its address read from its first line of
        output; closed by closing its stdin (it also exits if this process ends). Its child finds linknet as this
        process does (this process's import path is its PYTHONPATH): Dask's scheduler unpickles the tasks it is
        sent, whose function is linknet's."""

        def __init__(self, config: dict | None = None, start_timeout: float = 60.0):
            self.config = dict(config or {})
            self.start_timeout = start_timeout
            self.process = None
            super().__init__()

        async def start(self) -> None:
            import asyncio
            import json
            import sys

            env = dict(os.environ)
            env["PYTHONPATH"] = os.pathsep.join([p for p in sys.path if p] +
                                                ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
            self.process = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "linknet_core.ensemble.scheduler_process", json.dumps(self.config),
                stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE, env=env)
            try:
                line = await asyncio.wait_for(self.process.stdout.readline(), self.start_timeout)
            except asyncio.TimeoutError:
                line = b""
            address = line.decode(errors="replace").strip()
            if not address.startswith("tcp://"):
                await self._stop()
                raise RuntimeError(f"the study's Dask scheduler process did not start (exit code "
                                   f"{self.process.returncode}, output {line[:200]!r})")
            self.address = address
            await super().start()

        async def _stop(self) -> None:
            import asyncio

            process = self.process
            if process is None:
                return
            if process.returncode is None:
                process.stdin.close()
                try:
                    await asyncio.wait_for(process.wait(), 10.0)
                except asyncio.TimeoutError:
                    process.kill()
                    await process.wait()
            self.process = None

        async def close(self) -> None:
            await self._stop()
            await super().close()

    return SchedulerProcess


_DASK_LOGGERS = ("distributed", "tornado")


@contextlib.contextmanager
def quiet_shutdown(client):
    """While a study's own LocalCluster closes: Dask's messages about the cluster going away (a worker's
    heartbeat meeting a scheduler that closed first, a comm closed under a message) say nothing about the study,
    whose results are written by then, so they are silenced in the workers and, until the cluster is closed,
    here."""
    loggers = [logging.getLogger(name) for name in _DASK_LOGGERS]
    levels = [logger.level for logger in loggers]
    for silence in (client.run, client.run_on_scheduler):  # the workers; the scheduler, in its own process
        try:
            silence(_silence_dask_logs)
        except Exception:  # a worker or scheduler already gone: nothing of it to silence
            pass
    _silence_dask_logs()
    try:
        yield
    finally:
        for logger, level in zip(loggers, levels):
            logger.setLevel(level)


def _silence_dask_logs() -> None:
    for name in _DASK_LOGGERS:
        logging.getLogger(name).setLevel(logging.CRITICAL)


class Engine:
    """A Dask client for one study; closes what it opened (never a cluster it was given)."""

    def __init__(self, client=None, workers: int | None = None, connect_timeout: float = CONNECT_TIMEOUT):
        from distributed import Client

        self._cluster = None
        if client is None:
            n = workers or available_cores()
            try:
                self._cluster, self.client = local_cluster(n)
            except Exception as exc:
                # the usual cause: a script without a main guard, which each spawned worker imports again and
                # which then tries to start a cluster of its own while it is being imported
                raise LinknetError(f"the LocalCluster's worker processes did not start ({error_text(exc)}). Dask "
                                   "starts each worker by importing the main script again, so a script must call "
                                   "ln.ensemble under `if __name__ == \"__main__\":`") from None
            self._owns_client = True
            self.description = f"local cluster on 127.0.0.1: a scheduler process and {n} worker process(es)"
            return
        if workers is not None:
            raise LinknetError("workers= sets the size of the embedded LocalCluster; an existing cluster "
                               "(client=...) keeps the workers it has")
        if isinstance(client, str):
            check_scheduler(client, connect_timeout)  # bounded: distributed's own handshake read has no timeout
            try:
                self.client = Client(client, timeout=connect_timeout)
            except Exception as exc:  # OSError, TimeoutError, a reply that is not Dask's (MemoryError), ...
                raise LinknetError(f"cannot reach the Dask scheduler at {client}: {error_text(exc)}") from None
            self._owns_client = True
        elif isinstance(client, Client):
            self.client = client
            self._owns_client = False
        else:
            raise LinknetError(f"client must be None (a LocalCluster), a scheduler address such as "
                               f"'tcp://127.0.0.1:8786', or a distributed.Client; got {client!r}")
        self.description = f"Dask scheduler {self.client.scheduler.address}"
        try:
            self.client.wait_for_workers(1, timeout=WORKER_WAIT_SECONDS)
        except TimeoutError:
            self.close()
            raise LinknetError(f"no Dask worker joined the scheduler at {self.client.scheduler.address} within "
                               f"{WORKER_WAIT_SECONDS:g} s") from None

    def threads(self) -> int:
        return max(1, sum(self.client.nthreads().values()))

    def close(self) -> None:
        if self._cluster is None:
            if self._owns_client:
                self.client.close()
            return
        with quiet_shutdown(self.client):
            self.client.close()
            self._cluster.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def check_scheduler(address: str, timeout: float = CONNECT_TIMEOUT) -> None:
    """Refuse, in one line naming the address, a scheduler address where no Dask scheduler answers, within
    ``timeout`` seconds in all. ``distributed.Client(address, timeout=)`` bounds the TCP connect but not the
    read of the scheduler's handshake: a server that accepts and never answers hangs it, and an HTTP server's
    answer read as a Dask frame length asks for exabytes (a MemoryError). So a plain socket looks first:

    * the TCP connect (a refused connection is tried again until the timeout, as Dask does: a scheduler that
      is just starting refuses for a moment); refused, unreachable, an unknown host are each said so;
    * a Dask scheduler speaks first (its handshake, one frame whose 8-byte length is small): the probe waits
      up to half the timeout for the peer's first bytes, sending nothing;
    * a peer still silent then gets an HTTP request (``GET /``): an HTTP answer is the dashboard-port slip
      (8787 for 8786); no answer at all within the timeout is a server that never speaks Dask.

    Only tcp:// (or no scheme) addresses are probed this way; tls:// and ws(s):// get the TCP connect check
    (their client speaks first), other schemes are left to Dask.
    """
    from distributed.comm.addressing import parse_address, parse_host_port

    try:
        scheme, location = parse_address(address)
        if scheme not in ("tcp", "tls", "ws", "wss"):
            return
        host, port = parse_host_port(location)
    except (ValueError, TypeError) as exc:
        raise LinknetError(f"{address!r} is not a Dask scheduler address ({exc}); write tcp://HOST:PORT, e.g. "
                           f"tcp://127.0.0.1:{SCHEDULER_PORT}") from None
    if not (isinstance(timeout, (int, float)) and math.isfinite(timeout) and timeout > 0):
        raise LinknetError(f"connect_timeout must be a positive number of seconds, got {timeout!r}")
    start = time.monotonic()
    deadline = start + timeout

    def fail(found: str):
        raise LinknetError(f"cannot reach the Dask scheduler at {address}: {found}")

    sock = _connect(host, port, deadline, timeout, fail)
    with sock:
        if scheme != "tcp":
            return
        first = _receive(sock, start + timeout / 2)
        if first is None:  # silent so far: an HTTP server waits for a request
            try:
                sock.sendall(f"GET / HTTP/1.0\r\nHost: {host}:{port}\r\n\r\n".encode())
                answer = _receive(sock, deadline)
            except OSError:
                answer = b""
            if answer is None:
                fail(f"the server accepted the connection but never answered the Dask handshake within "
                     f"{timeout:g} s (nor an HTTP request)")
            if answer.startswith(b"HTTP/"):
                fail(f"an HTTP server answered ({_first_line(answer)}): is this the dashboard port? the scheduler's default port "
                     f"is {SCHEDULER_PORT}")
            if not answer:
                fail("the server accepted the connection and closed it without the Dask handshake")
            fail(f"the server did not start the Dask handshake and answered an HTTP request with {answer[:40]!r}")
        if not first:
            fail("the server accepted the connection and closed it without the Dask handshake")
        if first.startswith(b"HTTP/"):
            fail(f"an HTTP server spoke ({_first_line(first)}): is this the dashboard port? the scheduler's default "
                 f"port is {SCHEDULER_PORT}")
        if len(first) < 8 or not 0 < struct.unpack("<Q", first[:8])[0] <= _HANDSHAKE_MAX_BYTES:
            length = struct.unpack("<Q", first[:8])[0] if len(first) >= 8 else None
            meaning = "" if length is None else (f"; read as a Dask frame, its first 8 bytes announce "
                                                 f"{_bytes_text(length)}, which is no handshake")
            fail(f"the server speaks another protocol: it sent {first[:40]!r}{meaning}")


def _connect(host, port, deadline, timeout, fail) -> socket.socket:
    """A TCP connection to (host, port) by the deadline; a refused one is tried again until then."""
    delay = 0.05
    while True:
        try:
            return socket.create_connection((host, port), timeout=max(deadline - time.monotonic(), 0.01))
        except ConnectionRefusedError:
            left = deadline - time.monotonic()
            if left <= 0:
                fail(f"the connection was refused (tried again for {timeout:g} s): nothing listens on port {port} "
                     f"of {host}; is the scheduler running, and is this its port? (its default is {SCHEDULER_PORT})")
            time.sleep(min(delay, left))
            delay = min(2 * delay, 1.0)
        except socket.gaierror as exc:
            fail(f"the host name {host!r} cannot be resolved ({exc.strerror or exc})")
        except TimeoutError:
            fail(f"unreachable: no answer to the TCP connection within {timeout:g} s (no such host on the "
                 "network, or a firewall dropping the connection)")
        except OSError as exc:  # EHOSTUNREACH, ENETUNREACH, ...
            fail(f"unreachable ({exc.strerror or exc})")


def _receive(sock: socket.socket, deadline: float) -> bytes | None:
    """The first bytes the peer sends by the deadline; b"" if it closed the connection, None if it stayed
    silent."""
    try:
        sock.settimeout(max(deadline - time.monotonic(), 0.001))
        return sock.recv(4096)
    except TimeoutError:
        return None
    except OSError:  # reset by the peer
        return b""


def _first_line(data: bytes) -> str:
    return data.split(b"\r\n", 1)[0].split(b"\n", 1)[0].decode("latin-1").strip()[:80]


def _bytes_text(n: int) -> str:
    for unit, size in (("EiB", 1 << 60), ("PiB", 1 << 50), ("TiB", 1 << 40), ("GiB", 1 << 30), ("MiB", 1 << 20)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n} bytes"


class _BatchSizer:
    """Members per task: 1 until a member time is known, then about TASK_SECONDS of work (longer on clusters
    with more than TASK_SECONDS * MAX_TASKS_PER_SECOND threads), at most MAX_TASK_BYTES of outputs. Near the end,
    when the remaining members no longer fill a task per worker thread, a task takes the remaining members over
    the threads (so the last wave ends about together on every worker), but never less than
    TAIL_TASK_SHARE of the full task's work, so that the end of a study does not break into tasks whose Dask cost
    approaches their work; nor more than a quarter of the study's members per thread (``total``), so that a study
    smaller than a wave of full tasks still spreads over every thread. ``fixed`` (members_per_task=) overrides it."""

    def __init__(self, fixed: int | None, member_bytes: int = 0, total: int | None = None):
        self.fixed = fixed
        self.member_bytes = member_bytes
        self.total = total
        self._seconds = 0.0
        self._members = 0

    def record(self, run_seconds) -> None:
        self._seconds += float(sum(run_seconds))
        self._members += len(run_seconds)

    def size(self, remaining: int, threads: int) -> int:
        if self.fixed:
            return self.fixed
        if not self._members:
            return 1
        per_member = max(self._seconds / self._members, 1e-6)
        task_seconds = max(TASK_SECONDS, threads / MAX_TASKS_PER_SECOND)
        largest = MAX_TASK_BYTES // self.member_bytes if self.member_bytes else remaining
        full = max(1, min(int(task_seconds / per_member), largest))
        smallest = max(1, int(TAIL_TASK_SHARE * full))
        if self.total is not None:
            smallest = max(1, min(smallest, self.total // (4 * threads)))
        return max(1, min(full, max(smallest, math.ceil(remaining / threads)), remaining))


def run_study(engine: Engine, spec: StudySpec, plan: Plan, sink, on_progress=None,
              members_per_task: int | None = None) -> Progress:
    """Run every member of ``plan`` on ``engine``'s cluster, handing each finished batch to ``sink.write``;
    returns the final progress (``sink.mark_retried`` has been told the retried members)."""
    from distributed import as_completed
    from distributed.scheduler import KilledWorker

    client = engine.client
    payload = StudyPayload(spec)
    try:
        client.register_plugin(payload, name=payload.name)
    except Exception as exc:  # e.g. a worker without linknet (or fmpy) installed
        raise LinknetError(f"the Dask workers cannot take the study ({error_text(exc)}); every worker needs "
                           "linknet, and fmpy for an FMU study, installed in its Python") from None

    threads = engine.threads()
    progress = Progress(total=plan.n_members, workers=threads)
    # a batch's outputs in bytes, per member: 8 per number kept, ~100 for its quantities of interest and status
    member_bytes = 8 * output_values(Scene.from_dict(spec.scene), spec.outputs, spec.times.size) + 100
    sizer = _BatchSizer(members_per_task, member_bytes, plan.n_members)
    lock = threading.Lock()  # the event handler runs on the client's event-loop thread
    in_flight: dict[str, tuple[int, int]] = {}  # task key -> (first member, count)
    retried: set[int] = set()
    # batches to run again: single members of a batch that kept killing workers, a batch whose result could
    # not be fetched
    again: deque[tuple[int, int]] = deque()
    cursor = 0
    last_thread_check = time.perf_counter()

    def on_event(event):
        _, message = event
        if not isinstance(message, dict) or message.get("action") != "remove-worker":
            return
        keys = set(message.get("processing-tasks", ())) | set(message.get("lost-computed-tasks", ()))
        with lock:  # a batch stays in flight until its result is written: none of its members is written yet
            for key in keys:
                if key in in_flight:
                    first, count = in_flight[key]
                    retried.update(range(first, first + count))

    def submit(ac) -> None:
        nonlocal cursor
        if again:
            (first, count), suffix = again.popleft(), f"-again{progress.tasks}"
        else:
            first, suffix = cursor, ""
            count = min(sizer.size(plan.n_members - cursor, threads), plan.n_members - cursor)
            cursor += count
        key = f"linknet-ensemble-{spec.study_id}-{first}-{count}{suffix}"
        settings = [plan.setting(m) for m in range(first, first + count)]
        future = client.submit(run_batch, spec.study_id, first, settings, key=key)
        progress.tasks += 1
        with lock:
            in_flight[key] = (first, count)
        ac.add(future)

    def deliver(batch: dict) -> None:
        """Hand a batch to the sink. A failed write raises once, and the sink goes on in its rescue file: the study
        goes on with it (the sink's close says where its members are), unless the rescue failed too."""
        try:
            sink.write(batch)
        except WriteError:
            if not sink.continues():
                raise

    def record_failure(first: int, count: int, message: str) -> None:
        deliver({"first": first, "count": count, "outputs": {}, "error": [message] * count,
                 "run_seconds": [math.nan] * count, "worker": ""})
        progress.failed += count

    client.subscribe_topic("all", on_event)
    # without with_results: as_completed fetching in the background would leave the study waiting forever if
    # a fetch failed (seen once under load: an AssertionError inside tornado's stream); here it is retried
    ac = as_completed()
    try:
        while len(in_flight) < 2 * threads and cursor < plan.n_members:
            submit(ac)
        for future in ac:
            with lock:
                first, count = in_flight[future.key]
            result, failure = _fetch(future)
            # off the batches in flight only once fetched: a result lost with its worker after the task finished
            # (not yet fetched) is fetched once the scheduler has run the task again, and the worker's removal,
            # which says so, may come while the fetch waits
            with lock:
                del in_flight[future.key]
            future.release()
            if result is not None:
                cpu = time.thread_time()
                deliver(result)
                progress.write_cpu_seconds += time.thread_time() - cpu
                progress.member_cpu_seconds += float(sum(result["cpu_seconds"]))
                progress.worker_write_cpu_seconds += result.get("write_cpu_seconds", 0.0)
                sizer.record([s for s, e in zip(result["run_seconds"], result["error"]) if not e])
                progress.failed += sum(1 for e in result["error"] if e)
                progress.done += count
            elif isinstance(failure, KilledWorker) and count > 1:
                again.extend((m, 1) for m in range(first, first + count))  # find the member that kills workers
            elif isinstance(failure, KilledWorker):
                record_failure(first, count, f"KilledWorker: every worker that ran this member died "
                                             f"({failure}); it may crash its process (e.g. a fault in an FMU)")
                progress.done += count
            elif isinstance(failure, CancelledError):
                raise LinknetError("the Dask scheduler cancelled the study (connection to it lost?)")
            elif isinstance(failure, _FetchFailed):
                with lock:
                    retried.update(range(first, first + count))
                again.append((first, count))
            else:  # the task itself failed, not a member (members record their own errors)
                record_failure(first, count, error_text(failure))
                progress.done += count
            with lock:
                progress.retried = len(retried)
            if progress.first_result_seconds is None and progress.done:
                progress.first_result_seconds = progress.elapsed
            if time.perf_counter() - last_thread_check > 2.0:  # workers may join or leave an existing cluster
                threads, last_thread_check = engine.threads(), time.perf_counter()
                progress.workers = threads
            while len(in_flight) < 2 * threads and (again or cursor < plan.n_members):
                submit(ac)
            if on_progress is not None:
                on_progress(progress)
    finally:
        if in_flight:  # interrupted: nothing more should run for this study
            client.cancel(list(ac.futures), force=True)
        client.unsubscribe_topic("all")
        try:
            client.unregister_worker_plugin(payload.name)
        except Exception:  # the cluster may be gone already (interrupted, scheduler lost)
            pass
    sink.mark_retried(retried)
    return progress


class _FetchFailed(Exception):
    """A finished batch whose result could not be brought to the client."""


FETCH_ATTEMPTS = 3
FETCH_TIMEOUT = 120.0  # seconds for one fetch of a finished batch's result


def _fetch(future):
    """(result, None) for a finished batch, (None, exception) for a task that failed or was cancelled, and
    (None, _FetchFailed) when fetching the result failed FETCH_ATTEMPTS times (the batch then runs again).
    A task's own failure is read with ``exception()``, so whatever ``result()`` raises here is the fetch."""
    last = None
    for attempt in range(FETCH_ATTEMPTS):
        try:
            if future.status == "error":
                return None, future.exception(timeout=FETCH_TIMEOUT)
            if future.status == "cancelled":
                return None, CancelledError(future.key)
            return future.result(timeout=FETCH_TIMEOUT), None
        except Exception as exc:  # a connection fault, a timeout: try again
            last = exc
            time.sleep(0.2 * 2 ** attempt)
    return None, _FetchFailed(error_text(last))
