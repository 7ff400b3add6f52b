"""``mjx-pick gui``: a web GUI with the paper's four tabs and its parameter-sweep tab.

The GUI is an interface layer like the CLI. Its web framework (NiceGUI, the ``gui``
extra) is imported only when the app starts: ``import mjx_pick`` or
``import mjx_pick.gui`` never imports it.
"""

from __future__ import annotations

import ipaddress
import socket
import webbrowser
from pathlib import Path

LOOPBACK = "127.0.0.1"


def free_port(host: str = LOOPBACK) -> int:
    """A TCP port nothing listens on now (the OS picks it)."""
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def port_problem(host: str, port: int) -> str | None:
    """Why the app cannot listen on host:port (in use, no such interface), or None."""
    try:
        with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.bind((host, port))
    except OSError as err:
        return f"cannot listen on {host}:{port} ({err.strerror or err})"
    return None


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def has_browser() -> bool:
    """A browser the standard library can open (none on a headless server)."""
    try:
        webbrowser.get()
    except webbrowser.Error:
        return False
    return True


def missing_framework() -> str | None:
    """Why the GUI cannot start (its extra is not installed), or None."""
    import importlib.util

    if importlib.util.find_spec("nicegui") is None:
        return 'the GUI needs its extra: pip install "mjx-pick[gui]" (or ".[gui]" in a checkout)'
    return None


def serve(host: str, port: int, workdir: str | Path, show: bool) -> None:
    """Start the app (blocks until Ctrl-C); see :func:`mjx_pick.gui.app.serve`."""
    from mjx_pick.gui.app import serve as _serve

    _serve(host, port, Path(workdir), show)
