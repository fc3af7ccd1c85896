"""The meshcat server process, started by :mod:`coursekit.viz.meshcat_scene` as a script (imports no coursekit).

meshcat's own ``python -m meshcat.servers.zmqserver`` binds zmq to 127.0.0.1 but lets tornado
listen for http/websocket on EVERY interface (0.0.0.0 and [::]), so anyone on the network could
watch (and, through the websocket, talk to) a student's scene. Here the same bridge listens on
127.0.0.1 only.

It also exits when the process that started it dies, however it dies and from whichever thread
it was started: the parent keeps the write end of a pipe whose read end is ``--parent-pipe FD``;
the kernel closes the write end when the parent process goes (SIGKILL included), the read below
then returns end-of-file, and the server exits. (Linux's parent-death signal cannot do this: it
fires when the starting *thread* ends.)

Usage (what MeshcatScene runs): ``python -u meshcat_server.py --parent-pipe FD``; prints
``zmq_url=...`` and ``web_url=...`` lines like meshcat's server.
"""

from __future__ import annotations

import argparse
import os
import threading

LOOPBACK = "127.0.0.1"


def _exit_when_parent_dies(fd: int) -> None:
    """Block on the pipe; end-of-file (or an error) means the parent is gone: exit at once."""
    try:
        while os.read(fd, 1):
            pass
    finally:
        os._exit(0)


def main() -> None:
    parser = argparse.ArgumentParser(description="meshcat server bound to 127.0.0.1, dying with its parent")
    parser.add_argument("--parent-pipe", type=int, required=True, help="read end of a pipe the parent holds open")
    args = parser.parse_args()
    threading.Thread(target=_exit_when_parent_dies, args=(args.parent_pipe,), daemon=True).start()

    from meshcat.servers import zmqserver

    class LoopbackBridge(zmqserver.ZMQWebSocketBridge):
        """meshcat's bridge with its web app listening on 127.0.0.1 only (zmq already is)."""

        def make_app(self):
            app = super().make_app()
            listen = app.listen
            app.listen = lambda port, **kwargs: listen(port, address=LOOPBACK, **kwargs)
            return app

    bridge = LoopbackBridge(host=LOOPBACK)
    print(f"zmq_url={bridge.zmq_url}")
    print(f"web_url={bridge.web_url}")
    try:
        bridge.run()
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":
    main()
