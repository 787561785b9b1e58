"""Every way a ``--scheduler`` address can be wrong is one line and exit 2 (issue 25, item 8).

Before, ``tls://`` without certificates and ``ucx://`` were tracebacks, a server that is
not a Dask scheduler was a traceback (an HTTP server) or a client waiting for ever (a
listener that accepts and says nothing), and every refused address had already claimed the
run directory. Network only on 127.0.0.1; the listeners are opened here.
"""

from __future__ import annotations

import contextlib
import socket
import threading

import pytest

from rippleb import cli

RUN = ["run", "--methods", "raw", "--scenarios", "static-contact", "--seeds", "1", "--no-progress",
       "--out", "out"]


@contextlib.contextmanager
def listener(answer: bytes | None):
    """A TCP server on 127.0.0.1 that accepts and says nothing (``answer`` None), or reads a
    request and sends ``answer``; yields its port."""
    server = socket.create_server(("127.0.0.1", 0))
    conns = []

    def serve():
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            conns.append(conn)
            if answer is not None:
                with contextlib.suppress(OSError):
                    conn.recv(65536)
                    conn.sendall(answer)
    threading.Thread(target=serve, daemon=True).start()
    try:
        yield server.getsockname()[1]
    finally:
        server.close()
        for conn in conns:
            conn.close()


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


HTTP = b"HTTP/1.1 200 OK\r\nContent-Length: 5\r\nContent-Type: text/plain\r\n\r\nhello"


def refused(tmp_path, monkeypatch, capsys, address: str, *options: str) -> str:
    """Run with ``--scheduler address``; the one stderr line, after checking the exit status
    and that nothing was written."""
    monkeypatch.chdir(tmp_path)
    status = cli.main([*RUN, "--scheduler", address, "--connect-timeout", "1", *options])
    err = capsys.readouterr().err
    assert status == 2 and len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith(f"rippleb: error: --scheduler {address}"), err
    assert not (tmp_path / "out").exists(), "a refused address claimed the run directory"
    return err


@pytest.mark.parametrize("address, says", [
    ("tls://127.0.0.1:1", "tls:// needs a certificate and key in Dask's configuration"),
    ("ucx://127.0.0.1:1", "ucx:// needs UCX"),
    ("foo", "not a Dask address (missing port number"),
    ("http://127.0.0.1:8787", "not a Dask address (unknown address scheme 'http'"),
    ("tcp://127.0.0.1:99999", "not a Dask address (port 99999 is not in 1-65535)"),
    ("inproc://nowhere", "not a Dask address"),
])
def test_a_malformed_or_unusable_address_is_one_line(tmp_path, monkeypatch, capsys, address, says):
    assert says in refused(tmp_path, monkeypatch, capsys, address)


def test_nothing_listening_is_one_line(tmp_path, monkeypatch, capsys):
    address = f"tcp://127.0.0.1:{free_port()}"
    assert "cannot connect (Timed out trying to connect" in refused(tmp_path, monkeypatch, capsys, address)


def test_a_listener_that_says_nothing_is_one_line_after_the_connect_timeout(tmp_path, monkeypatch, capsys):
    with listener(None) as port:
        err = refused(tmp_path, monkeypatch, capsys, f"tcp://127.0.0.1:{port}")
    assert "connected, but no Dask scheduler answered within 3 s (--connect-timeout 1)" in err


def test_an_http_server_is_not_a_scheduler(tmp_path, monkeypatch, capsys):
    with listener(HTTP) as port:
        err = refused(tmp_path, monkeypatch, capsys, f"tcp://127.0.0.1:{port}")
    assert "the server there is not a Dask scheduler" in err


def test_an_empty_address_is_refused(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert cli.main([*RUN, "--scheduler", ""]) == 2
    assert capsys.readouterr().err == ("rippleb: error: --scheduler is empty; give a scheduler's address, "
                                       "e.g. tcp://10.0.0.5:8786\n")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("value", ["0", "-1", "nan"])
def test_a_nonsense_connect_timeout_is_refused(tmp_path, monkeypatch, capsys, value):
    monkeypatch.chdir(tmp_path)
    assert cli.main([*RUN, "--scheduler", "tcp://127.0.0.1:1", "--connect-timeout", value]) == 2
    assert "--connect-timeout must be" in capsys.readouterr().err
