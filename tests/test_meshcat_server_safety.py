"""The meshcat server listens on loopback only and dies with its process, whichever thread made the scene."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time
from urllib.parse import urlparse

import pytest

psutil = pytest.importorskip("psutil")
pytest.importorskip("meshcat")

from coursekit.viz.meshcat.scene import MeshcatScene  # noqa: E402


def _gone(pid: int, timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if psutil.Process(pid).status() == psutil.STATUS_ZOMBIE:
                return True
        except psutil.NoSuchProcess:
            return True
        time.sleep(0.05)
    return False


def _non_loopback_addresses() -> list[tuple[int, str]]:
    out = []
    for addrs in psutil.net_if_addrs().values():
        for a in addrs:
            if a.family in (socket.AF_INET, socket.AF_INET6) and not a.address.startswith(("127.", "::1", "fe80")):
                out.append((a.family, a.address.split("%")[0]))
    return out


def test_server_listens_on_loopback_only():
    with MeshcatScene() as scene:
        listening = [c for c in psutil.Process(scene.server_pid).net_connections(kind="inet") if c.status == psutil.CONN_LISTEN]
        web_port, zmq_port = urlparse(scene.web_url).port, urlparse(scene.vis.window.zmq_url).port
        assert {c.laddr.port for c in listening} >= {web_port, zmq_port}
        assert {c.laddr.ip for c in listening} == {"127.0.0.1"}, listening  # not 0.0.0.0, not [::]
        with socket.create_connection(("127.0.0.1", web_port), timeout=5):
            pass  # reachable where it should be
        others = _non_loopback_addresses()
        if not others:
            pytest.skip("this machine has no non-loopback address to try")
        for family, address in others:
            for port in (web_port, zmq_port):
                with socket.socket(family, socket.SOCK_STREAM) as s:
                    s.settimeout(2)
                    assert s.connect_ex((address, port)) != 0, f"meshcat port {port} reachable on {address}"


_THREAD_SCENE = """
import threading, time
from coursekit.viz.meshcat.scene import MeshcatScene
box = []
t = threading.Thread(target=lambda: box.append(MeshcatScene()))
t.start(); t.join()                      # the creating thread has ENDED: the server must still serve
scene = box[0]
scene.clear()                            # raises if the server died with its thread
print(scene.server_pid, flush=True)
time.sleep(120)
"""


def test_a_scene_made_on_a_worker_thread_outlives_the_thread_and_dies_with_the_process():
    parent = subprocess.Popen([sys.executable, "-c", _THREAD_SCENE], stdout=subprocess.PIPE)
    try:
        line = parent.stdout.readline()
        assert line, "the thread-made scene did not come up"
        pid = int(line)
        assert psutil.pid_exists(pid) and psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    finally:
        parent.send_signal(signal.SIGKILL)
        parent.wait()
        parent.stdout.close()
    assert _gone(pid), f"meshcat server {pid} outlived its SIGKILLed parent"
