"""Reaching a Dask scheduler (``--scheduler ADDRESS``), and noticing when it is gone.

Every way an address can be wrong is one line naming the option and the address, before
the run claims its directory (:func:`check_scheduler`): no scheme or port, a scheme Dask
does not know or cannot use here (``tls://`` without certificates, ``ucx://`` without UCX),
nothing listening, a host that does not resolve, and a server that is not a Dask scheduler.
The last one needs a bound of rippleb's own: Dask's ``connect`` waits for the other side's
handshake without a timeout, so a plain TCP listener that accepts and says nothing kept
``Client`` waiting for ever (issue 25, item 8). A scheduler lost mid-run is
:class:`~rippleb.errors.EnvironmentLost`: one line with the resume command (exit 2).
"""

from __future__ import annotations

from rippleb.errors import InputError

#: Seconds a scheduler has to accept the connection and answer Dask's handshake
#: (``--connect-timeout``); also the time a client waits for a lost scheduler to come back.
CONNECT_TIMEOUT_S = 10.0
#: Seconds beyond that for Dask's handshake once the connection is made.
HANDSHAKE_S = 2.0


def check_scheduler(address: str, timeout: float = CONNECT_TIMEOUT_S) -> None:
    """Raise :class:`InputError` (one line) unless a Dask scheduler answers at ``address``:
    Dask tries to connect for ``timeout`` seconds, and the scheduler then has
    :data:`HANDSHAKE_S` more to answer its handshake."""
    import asyncio  # here: the CLI imports this module for its defaults

    if not address.strip():
        raise InputError("--scheduler is empty; give a scheduler's address, e.g. tcp://10.0.0.5:8786")
    try:
        asyncio.run(_handshake(address, timeout))
    except (asyncio.TimeoutError, TimeoutError):
        raise InputError(f"--scheduler {address}: connected, but no Dask scheduler answered within "
                         f"{timeout + HANDSHAKE_S:g} s (--connect-timeout {timeout:g}); is that the address "
                         "'dask scheduler' printed?") from None
    except Exception as exc:  # noqa: BLE001 - whatever the address does wrong, it is one line
        raise InputError(f"--scheduler {address}: {_why(exc)}") from None


async def _handshake(address: str, timeout: float) -> None:
    """Connect as a client would and exchange Dask's handshake (see :func:`check_scheduler`)."""
    import asyncio

    from distributed.comm import connect
    from distributed.security import Security

    _check_port(address)   # also an unknown scheme or a missing port: ValueError
    args = Security().get_connection_args("client")
    # Dask retries the connection itself for `timeout`; the bound around it is for the
    # handshake, which Dask awaits without one (a server that accepts and says nothing).
    comm = await asyncio.wait_for(connect(address, timeout=timeout, **args), timeout + HANDSHAKE_S)
    await comm.close()


def _check_port(address: str) -> None:
    """A port outside 1-65535 (Dask would retry it until its timeout)."""
    from distributed.comm.addressing import parse_address, parse_host_port

    scheme, location = parse_address(address)
    if scheme in ("tcp", "tls", "ws", "wss"):
        _, port = parse_host_port(location)
        if not 0 < int(port) < 65536:
            raise ValueError(f"port {port} is not in 1-65535")


def _why(exc: BaseException) -> str:
    """What went wrong with an address, in words a user can act on."""
    text = " ".join(str(exc).split())
    if isinstance(exc, TypeError) and "ssl_context" in text:
        return ("tls:// needs a certificate and key in Dask's configuration "
                "(distributed.comm.tls; see Dask's security docs)")
    if isinstance(exc, TypeError) and "UCX" in text:
        return "ucx:// needs UCX (ucx-py), which is not installed here"
    if isinstance(exc, OSError):
        return f"cannot connect ({text or type(exc).__name__})"
    if isinstance(exc, ValueError):
        return f"not a Dask address ({text}); give one like tcp://10.0.0.5:8786"
    # The connection was made, but what came back was no Dask handshake (an HTTP server's
    # reply, read as a message header, asks for exabytes: a MemoryError).
    return (f"the server there is not a Dask scheduler (what it sent is not Dask's handshake; reading "
            f"it failed with {type(exc).__name__})")


def lost(client) -> bool:
    """True once the client has lost its scheduler (it then tries to reconnect for its
    timeout, having cancelled every future, and closes)."""
    return client.status not in ("running", "newly-created")
