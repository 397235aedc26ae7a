"""The Dask scheduler of a study's own local cluster, in a process of its own.

In Dask's LocalCluster the scheduler runs on the client's event loop, in the client's process: its work per task
(transitions, messages to and from every worker) and the client's (fetching results, writing the study file,
submitting the next batches) then share one GIL, and on many workers the client's dispatch waits on the
scheduler's turn and workers idle. Here the scheduler has a process and a core to itself.

Run as ``python -m linknet_core.ensemble.scheduler_process CONFIG_JSON``: it applies the Dask settings given
(the study's LOCAL_CLUSTER_CONFIG), starts a scheduler on 127.0.0.1 on a free port, writes its address as one
line on stdout, and runs until its stdin closes: the client closes it when the cluster closes, and the OS
closes it when the client's process ends in any way (killed included), so a scheduler never outlives its
study. Dask's log messages below ERROR are silenced, as a LocalCluster silences them, and so is the one ERROR a
killed worker brings on a study that goes on (the results lost with it: ``_LostResultNotice``).
"""
from __future__ import annotations

import asyncio
import json
import logging
import sys


class _StdinWatch(asyncio.Protocol):
    """Sets ``closed`` at the end of stdin: the client closed the pipe, or its process ended."""

    def __init__(self, closed: asyncio.Event):
        self.closed = closed

    def connection_lost(self, exc) -> None:
        self.closed.set()


async def _serve(config: dict) -> None:
    import dask
    from distributed import Scheduler

    _silence_dask_logs()  # after distributed's import, which sets its own log levels
    dask.config.set(config)
    # no dashboard: its HTTP server still serves Dask's health routes, on a free port
    async with Scheduler(host="127.0.0.1", port=0, dashboard=False, dashboard_address="127.0.0.1:0") as scheduler:
        sys.stdout.write(scheduler.address + "\n")
        sys.stdout.flush()
        closed = asyncio.Event()
        await asyncio.get_running_loop().connect_read_pipe(lambda: _StdinWatch(closed), sys.stdin)
        stdin_closed = asyncio.ensure_future(closed.wait())
        finished = asyncio.ensure_future(scheduler.finished())
        await asyncio.wait([stdin_closed, finished], return_when=asyncio.FIRST_COMPLETED)
        stdin_closed.cancel()
        finished.cancel()


class _LostResultNotice(logging.Filter):
    """Drops the scheduler's "Couldn't gather keys" ERROR. It comes when a worker died holding finished results
    that the client then asks for: the client that asked reschedules those tasks itself (Dask's client logs that
    as a warning, which the study hears), they run again, and the study records their members as retried, or, if
    they cannot run, as failed with the reason. On a study that succeeds the line was the one thing on stderr, and
    it says nothing the study does not; a failing study says why in its own error."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.msg != LOST_RESULT_MESSAGE


LOST_RESULT_MESSAGE = "Couldn't gather keys: %s"  # distributed.scheduler.Scheduler.gather's format
_LOST_RESULT_FILTER = _LostResultNotice()


def _silence_dask_logs() -> None:
    for name in ("distributed", "tornado"):
        logging.getLogger(name).setLevel(logging.ERROR)
    logging.getLogger("distributed.scheduler").addFilter(_LOST_RESULT_FILTER)  # adding it twice keeps one


def main() -> None:
    config = json.loads(sys.argv[1]) if len(sys.argv) > 1 else {}
    asyncio.run(_serve(config))


if __name__ == "__main__":
    main()
