"""The meshcat server process: started and owned by :class:`MeshcatServer`, run as this very script.

meshcat 0.3.2 has no in-process mode: ``meshcat.Visualizer()`` starts a server SUBPROCESS (zmq on
127.0.0.1:6000+, http on 7000+). Its own ``python -m meshcat.servers.zmqserver`` has two flaws
this module removes:

- it lets tornado listen for http/websocket on EVERY interface (0.0.0.0 and [::]), so anyone on
  the network could watch (and, through the websocket, talk to) a student's scene. The bridge run
  here (:func:`main`) listens on 127.0.0.1 only;
- meshcat kills it at a normal interpreter exit, but after a SIGTERM/SIGKILL of the parent (a
  killed notebook kernel, a timed-out test) it is orphaned and keeps its ports. Here the parent
  keeps the write end of a pipe (the *lifeline*) whose read end the server watches
  (``--parent-pipe FD``); the kernel closes the write end when the parent process goes, however
  and from whichever thread the server was started, the read then returns end-of-file, and the
  server exits. On Linux a server started from the main thread also gets a parent-death SIGKILL
  (that signal fires when the starting *thread* ends, so it is not asked for from other threads).

Parent side: ``MeshcatServer()`` starts ``python -u server.py --parent-pipe FD`` and reads the
``zmq_url=...`` and ``web_url=...`` lines it prints; :meth:`MeshcatServer.close` kills it.
Child side: run as a script, this file imports no coursekit (only the standard library here, and
meshcat inside :func:`main`).
"""

from __future__ import annotations

import argparse
import ctypes
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

LOOPBACK = "127.0.0.1"
"""The only address the server listens on (zmq and http/websocket)."""
SCRIPT = Path(__file__).resolve()
"""This file: what the server process runs (its command line names it)."""
START_TIMEOUT_S = 30.0
"""Seconds to wait for the server to print its URLs before giving up."""
_PR_SET_PDEATHSIG = 1  # from <linux/prctl.h>


def _die_with_parent() -> None:
    """Run in the child between fork and exec: SIGKILL me when my parent dies (Linux only)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):  # not Linux: fall back to close()/atexit only
        pass


class MeshcatServer:
    """One running server process; :meth:`close` (or the death of this process) ends it.

    Attributes:
        pid: the server's process id (to check that it is gone after close).
        zmq_url: where a ``meshcat.Visualizer(zmq_url=...)`` connects.
        web_url: the live viewer's URL (only while the process lives).

    Raises RuntimeError when the server exits at start-up or does not print its URLs within
    :data:`START_TIMEOUT_S`; the process is then already killed.
    """

    def __init__(self) -> None:
        import meshcat

        env = dict(os.environ)
        # meshcat passes its own location on PYTHONPATH (robust when it was added by sys.path hacks).
        env["PYTHONPATH"] = os.path.dirname(os.path.dirname(meshcat.__file__))
        in_main_thread = threading.current_thread() is threading.main_thread()
        read_end, self._lifeline = os.pipe()  # both non-inheritable (PEP 446): only the server gets read_end
        try:
            self._proc: subprocess.Popen | None = subprocess.Popen(
                [sys.executable, "-u", str(SCRIPT), "--parent-pipe", str(read_end)],
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,  # the server logs each websocket; nobody reads it, never let it block
                env=env,
                pass_fds=(read_end,),
                start_new_session=True,  # a Ctrl-C in a notebook cell must not take the server down
                # the parent-death signal fires when the STARTING THREAD ends: only ask for it from the
                # main thread (the pipe covers every thread)
                preexec_fn=_die_with_parent if sys.platform.startswith("linux") and in_main_thread else None,
            )
        except BaseException:
            os.close(self._lifeline)
            raise
        finally:
            os.close(read_end)
        self.pid: int = self._proc.pid
        try:
            self.zmq_url, self.web_url = self._read_urls()
        except BaseException:
            self.close()
            raise

    def _read_urls(self) -> tuple[str, str]:
        """The (zmq_url, web_url) the server prints at start-up."""
        deadline = time.monotonic() + START_TIMEOUT_S
        zmq_url = web_url = None
        while web_url is None:
            line = self._proc.stdout.readline().decode("utf-8", "replace").strip()
            if line.startswith("zmq_url="):
                zmq_url = line.split("=", 1)[1]
            elif line.startswith("web_url="):
                web_url = line.split("=", 1)[1]
            elif not line and self._proc.poll() is not None:
                raise RuntimeError(f"the meshcat server exited at start-up with code {self._proc.returncode}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"the meshcat server did not start within {START_TIMEOUT_S:.0f} s")
        if zmq_url is None:
            raise RuntimeError("the meshcat server printed a web URL but no zmq URL")
        return zmq_url, web_url

    @property
    def closed(self) -> bool:
        """True once :meth:`close` ran (the process is dead and reaped)."""
        return self._proc is None

    def close(self) -> None:
        """Kill the process, reap it and drop the lifeline. Safe to call twice."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=10)
        os.close(self._lifeline)
        if proc.stdout is not None:
            proc.stdout.close()


# -- the child: what runs in the server process ---------------------------------------------------
def _exit_when_parent_dies(fd: int) -> None:
    """Block on the pipe; end-of-file (or an error) means the parent is gone: exit at once."""
    try:
        while os.read(fd, 1):
            pass
    finally:
        os._exit(0)


def main() -> None:
    """Serve meshcat's zmq <-> websocket bridge on 127.0.0.1 until the parent's lifeline closes."""
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
