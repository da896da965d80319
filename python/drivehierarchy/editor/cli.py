"""`drivehierarchy editor [FILE_OR_FOLDER] [--map NET] [--port P]`."""

from __future__ import annotations

import argparse
import socket
from pathlib import Path

from drivehierarchy._core import ConfigError

HOST = "127.0.0.1"


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    ed = sub.add_parser(
        "editor",
        help="the interactive scenario editor: a local web page (127.0.0.1 only)",
        description=(
            "Serves the scenario editor on http://127.0.0.1:PORT/ and prints its URL. FILE_OR_FOLDER "
            "is the root folder the editor may write in (a file opens that file, its folder being "
            "the root; default: the current folder). Every route, validation message, actor "
            "position and frame comes from the simulator itself. Needs no internet. Stop it with "
            "Ctrl-C."
        ),
    )
    ed.add_argument("target", nargs="?", type=Path, default=Path("."), metavar="FILE_OR_FOLDER")
    ed.add_argument("--map", help="map for new scenarios (a .net.xml path, sumo:PATH or builtin:NAME)")
    ed.add_argument("--port", type=int, default=8765, help="port on 127.0.0.1 (default 8765; 0 = any free)")
    ed.set_defaults(func=_editor)


def _editor(args: argparse.Namespace) -> int:
    import uvicorn

    from drivehierarchy.editor.app import create_app

    target: Path = args.target
    if not target.exists():
        raise ConfigError(f"{target}: no such file or folder")
    root, open_rel = (target.parent, target.name) if target.is_file() else (target, None)
    default_map = args.map
    if default_map and not default_map.startswith(("sumo:", "builtin:")):
        default_map = str(Path(default_map).resolve())
    app = create_app(root, default_map)
    # Bind first so the printed URL carries the real port (--port 0).
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((HOST, args.port))
    except OSError as exc:
        raise ConfigError(f"--port {args.port}: cannot listen on {HOST}: {exc}") from exc
    # Listening before the URL is printed: a client that connects at once waits in the
    # backlog until uvicorn accepts.
    sock.listen(128)
    port = sock.getsockname()[1]
    url = f"http://{HOST}:{port}/" + (f"#{open_rel}" if open_rel else "")
    print(f"drivehierarchy editor: {url}  (root {root.resolve()}; Ctrl-C stops)", flush=True)
    config = uvicorn.Config(app, log_level="warning")
    uvicorn.Server(config).run(sockets=[sock])
    return 0
