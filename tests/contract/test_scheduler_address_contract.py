"""Scheduler addresses that hang: an address where no Dask scheduler answers is one line naming the
address and what was found there, within the connect timeout (``connect_timeout=``, ``--connect-timeout``, default
10 s), from ``ln.ensemble(client=...)`` (a LinknetError) and from ``linknet ensemble --scheduler`` (exit 2, no
traceback). Every server here is started by the test on 127.0.0.1 and stopped by it; the unreachable case is a
mocked socket error (no traffic leaves this machine). Elapsed times are measured and bounded by 3x the timeout
only so that a hang cannot hang the suite."""
from __future__ import annotations

import errno
import http.server
import socket
import subprocess
import sys
import threading
import time

import pytest

import linknet_core as ln
from linknet_core.ensemble import engine
from linknet_core.ensemble.engine import CONNECT_TIMEOUT, check_scheduler
from linknet_core.errors import LinknetError
from contract_support import MODELS, ROOT

TIMEOUT = 2.0  # connect_timeout of these tests (the default, 10 s, once through the CLI)
SCENE = str(MODELS / "chain_10.json")


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


@pytest.fixture
def http_server():
    """An HTTP server on a free port of 127.0.0.1 (as the Dask dashboard on 8787 would be)."""
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _QuietHandler)
    server.daemon_threads = True
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.1}, daemon=True)
    thread.start()
    yield f"tcp://127.0.0.1:{server.server_address[1]}"
    server.shutdown()
    server.server_close()
    thread.join(5)


def _tcp_server(greeting: bytes | None):
    """A TCP server on 127.0.0.1 that accepts every connection and then sends ``greeting`` (None: nothing,
    ever); it reads nothing. Returns (address, stop)."""
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(16)
    listener.settimeout(0.1)
    stop = threading.Event()
    accepted = []

    def serve():
        while not stop.is_set():
            try:
                conn, _ = listener.accept()
            except OSError:  # timeout: look at stop again
                continue
            accepted.append(conn)
            if greeting is not None:
                conn.sendall(greeting)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()

    def close():
        stop.set()
        thread.join(5)
        for conn in accepted:
            conn.close()
        listener.close()
    return f"tcp://127.0.0.1:{listener.getsockname()[1]}", close


@pytest.fixture
def silent_server():
    address, close = _tcp_server(None)
    yield address
    close()


@pytest.fixture
def banner_server():
    """A server that speaks first, but not Dask (an SSH server's banner)."""
    address, close = _tcp_server(b"SSH-2.0-OpenSSH_9.6\r\n")
    yield address
    close()


@pytest.fixture
def closed_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()  # bound, never listened: connections to it are refused
    return f"tcp://127.0.0.1:{port}"


def _api(address, timeout=TIMEOUT):
    """ln.ensemble on the address: (the LinknetError's message, seconds taken)."""
    started = time.perf_counter()
    with pytest.raises(LinknetError) as err:
        ln.ensemble(SCENE, vary={"M[3]": [1.0, 2.0]}, t_end=0.1, n_out=3, client=address, connect_timeout=timeout)
    return str(err.value), time.perf_counter() - started


def _cli(address, *extra):
    """linknet ensemble --scheduler address: (the completed process, seconds taken)."""
    started = time.perf_counter()
    run = subprocess.run([sys.executable, "-m", "linknet_core.cli", "ensemble", SCENE, "--t-end", "0.1",
                          "--vary", "M[3]=1,2", "--no-progress", "--scheduler", address, *extra],
                         capture_output=True, text=True, cwd=str(ROOT), timeout=120)
    return run, time.perf_counter() - started


def _one_line(run) -> str:
    assert run.returncode == 2, run.stderr
    assert "Traceback" not in run.stderr and run.stdout == ""
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("linknet ensemble: error: "), run.stderr
    return lines[0]


def test_the_default_connect_timeout_is_10_s():
    assert CONNECT_TIMEOUT == 10.0


def test_http_server_is_named_as_the_dashboard_slip(http_server):
    message, seconds = _api(http_server)
    assert message.startswith(f"cannot reach the Dask scheduler at {http_server}: an HTTP server answered (HTTP/1.0 200")
    assert "is this the dashboard port? the scheduler's default port is 8786" in message
    assert seconds < 3 * TIMEOUT, seconds


def test_http_server_from_the_cli_with_the_default_timeout(http_server):
    """The issue's command (hung > 580 s): one line, exit 2, within the default 10 s."""
    run, seconds = _cli(http_server)
    line = _one_line(run)
    assert f"cannot reach the Dask scheduler at {http_server}: an HTTP server answered" in line
    assert "is this the dashboard port? the scheduler's default port is 8786" in line
    assert seconds < 3 * CONNECT_TIMEOUT + 30, seconds  # + 30: the interpreter's start and imports, on 2 busy cores


def test_server_that_accepts_and_never_answers(silent_server):
    message, seconds = _api(silent_server)
    assert message == (f"cannot reach the Dask scheduler at {silent_server}: the server accepted the connection but "
                       f"never answered the Dask handshake within 2 s (nor an HTTP request)")
    assert TIMEOUT * 0.9 < seconds < 3 * TIMEOUT, seconds


def test_server_that_accepts_and_never_answers_from_the_cli(silent_server):
    run, seconds = _cli(silent_server, "--connect-timeout", "2")
    assert "accepted the connection but never answered the Dask handshake within 2 s" in _one_line(run)
    assert seconds < 3 * TIMEOUT + 30, seconds


def test_refused_port(closed_port):
    message, seconds = _api(closed_port)
    assert message.startswith(f"cannot reach the Dask scheduler at {closed_port}: the connection was refused "
                              "(tried again for 2 s): nothing listens on port")
    assert "its default is 8786" in message
    assert seconds < 3 * TIMEOUT, seconds


def test_refused_port_from_the_cli(closed_port):
    run, _ = _cli(closed_port, "--connect-timeout", "1")
    assert f"{closed_port}: the connection was refused (tried again for 1 s)" in _one_line(run)


def test_server_speaking_another_protocol_is_not_read_as_a_dask_frame(banner_server):
    """What ended in `MemoryError: Unable to allocate 3.07 EiB`: a peer's bytes read as a Dask frame length."""
    message, seconds = _api(banner_server)
    assert message.startswith(f"cannot reach the Dask scheduler at {banner_server}: the server speaks another "
                              "protocol: it sent b'SSH-2.0-OpenSSH_9.6\\r\\n'; read as a Dask frame, its first 8 "
                              "bytes announce")
    assert "EiB, which is no handshake" in message
    assert seconds < 3 * TIMEOUT, seconds


@pytest.mark.parametrize("error,words", [
    (TimeoutError("timed out"), "unreachable: no answer to the TCP connection within 2 s"),
    (OSError(errno.EHOSTUNREACH, "No route to host"), "unreachable (No route to host)"),
    (OSError(errno.ENETUNREACH, "Network is unreachable"), "unreachable (Network is unreachable)"),
])
def test_unreachable_address_mocked(monkeypatch, error, words):
    """Unreachable hosts are not tested on the network (no traffic leaves 127.0.0.1): the socket's own error is
    mocked, and the message must say what it means."""
    calls = []

    def create_connection(address, timeout=None):
        calls.append((address, timeout))
        raise error

    monkeypatch.setattr(engine.socket, "create_connection", create_connection)
    with pytest.raises(LinknetError) as err:
        check_scheduler("tcp://192.0.2.1:8786", TIMEOUT)
    assert str(err.value) == f"cannot reach the Dask scheduler at tcp://192.0.2.1:8786: {words}" + (
        " (no such host on the network, or a firewall dropping the connection)" if words.endswith("2 s") else "")
    assert calls and calls[0][0] == ("192.0.2.1", 8786) and 0 < calls[0][1] <= TIMEOUT


def test_a_real_scheduler_passes_and_its_dashboard_is_named():
    """A Dask scheduler (in this process, tcp on 127.0.0.1) passes the probe at once; its own dashboard's HTTP
    port is the slip the probe names."""
    from distributed import LocalCluster

    with LocalCluster(n_workers=0, processes=False, protocol="tcp", host="127.0.0.1",
                      dashboard_address="127.0.0.1:0") as cluster:
        started = time.perf_counter()
        check_scheduler(cluster.scheduler_address, TIMEOUT)
        assert time.perf_counter() - started < TIMEOUT
        dashboard = f"tcp://127.0.0.1:{cluster.scheduler.http_server.port}"
        with pytest.raises(LinknetError, match=r"an HTTP server answered \(HTTP/1.1 \d+ .*\): is this the "
                                               r"dashboard port\? the scheduler's default port is 8786"):
            check_scheduler(dashboard, TIMEOUT)


@pytest.mark.parametrize("kwargs,words", [
    (dict(client=None, connect_timeout=5), "bounds the connection to a scheduler address"),
    (dict(client="tcp://127.0.0.1:1", connect_timeout=0), "connect_timeout must be a positive finite number"),
    (dict(client="tcp://127.0.0.1:1", connect_timeout=float("nan")), "connect_timeout must be a positive finite"),
    (dict(client="tcp://127.0.0.1"), "is not a Dask scheduler address"),
])
def test_bad_connect_settings_are_refused(kwargs, words):
    with pytest.raises(LinknetError, match=words):
        ln.ensemble(SCENE, vary={"M[3]": [1.0, 2.0]}, t_end=0.1, n_out=3, **kwargs)
