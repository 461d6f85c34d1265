"""``beastbt studio [FOLDER]``: serve the mission studio for the missions, worlds and robots under FOLDER.

It prints the page's address and serves until Ctrl-C or SIGTERM (it ends
within 2 s of either, its checks, tries and their temporary folders with it).
It binds loopback (127.0.0.1:8070) unless ``--listen`` says otherwise; off
loopback (or with ``--token always``) the page needs the token printed in its
address, as the operator console does. Exit status: 0 after Ctrl-C, 2 for a bad option or
folder (nothing served).
"""

from __future__ import annotations

import argparse
import sys


def _listen(text: str) -> tuple[str, int]:
    from beastbt.live.endpoint import parse_endpoint
    try:
        return parse_endpoint(text, "--listen")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc))


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The arguments of ``beastbt studio``."""
    p.add_argument("folder", nargs="?", default=".",
                   help="the folder whose missions, worlds and robots the studio shows and saves (default: here)")
    p.add_argument("--listen", metavar="[HOST:]PORT", type=_listen, default=("127.0.0.1", 8070),
                   help="where the studio listens (default 127.0.0.1:8070; loopback only unless a host is given, "
                        "and then the page needs the token printed with its address)")
    p.add_argument("--token", choices=("auto", "always"), default="auto",
                   help="auto (default): the page needs its token off loopback only; always: on loopback too, for "
                        "a studio reached through a reverse proxy or an SSH tunnel")


def command(args: argparse.Namespace) -> int:
    """Serve the studio until Ctrl-C; 2 when the folder or the address is unusable."""
    from pathlib import Path
    folder = Path(args.folder)
    if not folder.is_dir():
        print(f"beastbt studio: error: '{args.folder}' is not a folder: give the folder that holds your missions "
              f"(or nothing, for this one)", file=sys.stderr)
        return 2
    from beastbt.core.errors import plain_reason
    from beastbt.studio.server import StudioServer
    host, port = args.listen
    server = StudioServer(folder, host, port, require_token=True if args.token == "always" else None)

    def ready() -> None:
        print(f"beastbt studio: {server.folder.root}", flush=True)
        print(f"open {server.url}", flush=True)
        print("(Ctrl-C stops the studio)", flush=True)

    try:
        server.serve_forever(ready)
    except OSError as exc:
        print(f"beastbt studio: error: cannot listen on {host}:{port}: {plain_reason(exc)}; choose another port "
              f"with --listen PORT", file=sys.stderr)
        return 2
    return 0
