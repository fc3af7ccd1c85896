"""A real JupyterLab server and a real (headless) chromium driving it, for the browser tests.

``lab_server()`` starts ``jupyter lab`` on a free loopback port with a random token, its
settings, workspaces, runtime and config in a temporary folder (nothing leaks into the user's
~/.jupyter), serving a temporary COPY of the notebooks. It always stops the server again, also
when the test fails: the REST shutdown (which shuts the kernels down), then SIGTERM / SIGKILL to
the server's process group and to every process the server started (kernels run in sessions of
their own, meshcat servers under the kernels). ``leftover()`` lists any that survived.

``LabPage`` wraps a playwright page: open a notebook, Run All, wait until every cell ran (failing within
seconds, with the kernel's fate and the server log, when Run All stops early), save,
and read the executed notebook back from disk (errors are found in the saved file, not guessed
from the DOM).
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.request
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import psutil

ROOT = Path(__file__).resolve().parent.parent


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class LabServer:
    url: str
    token: str
    root: Path
    proc: subprocess.Popen
    started: list[psutil.Process] = field(default_factory=list)

    def api(self, path: str, method: str = "GET") -> object:
        req = urllib.request.Request(f"{self.url}{path}", method=method,
                                     headers={"Authorization": f"token {self.token}"})
        with urllib.request.urlopen(req, timeout=10) as resp:
            body = resp.read()
        return json.loads(body) if body else None

    def shutdown_kernels(self) -> None:
        """Shut down every running kernel (between tests: a closed tab leaves its kernel running)."""
        self.descendants()  # remember them first: leftover() checks them at the end
        for kernel in self.api("/api/kernels") or []:
            with contextlib.suppress(OSError):
                self.api(f"/api/kernels/{kernel['id']}", method="DELETE")

    def descendants(self) -> list[psutil.Process]:
        """Every process the server started so far (remembered: kernels outlive a dead server)."""
        with contextlib.suppress(psutil.Error):
            for p in psutil.Process(self.proc.pid).children(recursive=True):
                if p.pid not in {q.pid for q in self.started}:
                    self.started.append(p)
        return list(self.started)

    def leftover(self) -> list[psutil.Process]:
        """Processes of this server (itself included) that are still alive."""
        alive = []
        for p in [psutil.Process(self.proc.pid) if self.proc.poll() is None else None, *self.started]:
            with contextlib.suppress(psutil.Error):
                if p is not None and p.is_running() and p.status() != psutil.STATUS_ZOMBIE:
                    alive.append(p)
        return alive


def _wait_ready(server: LabServer, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if server.proc.poll() is not None:
            raise RuntimeError(f"jupyter lab exited with code {server.proc.returncode}")
        with contextlib.suppress(OSError, ValueError):
            server.api("/api/status")
            return
        time.sleep(0.3)
    raise RuntimeError(f"jupyter lab did not answer within {timeout} s")


def _stop(server: LabServer) -> None:
    server.descendants()
    with contextlib.suppress(Exception):
        server.api("/api/shutdown", method="POST")  # shuts the kernels down cleanly
    with contextlib.suppress(subprocess.TimeoutExpired):
        server.proc.wait(timeout=10)
    for sig in (signal.SIGTERM, signal.SIGKILL):
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(server.proc.pid, sig)
        for p in server.leftover():
            with contextlib.suppress(psutil.Error):
                p.send_signal(sig)
        psutil.wait_procs(server.leftover(), timeout=5)
        if not server.leftover():
            break
    with contextlib.suppress(subprocess.TimeoutExpired):
        server.proc.wait(timeout=5)


def exercise_mode() -> str:
    """Which exercise code the lab's kernels run: COURSEKIT_EXERCISES, else the worked solutions."""
    return os.environ.get("COURSEKIT_EXERCISES", "solutions")


@contextlib.contextmanager
def lab_server(tmp: Path, notebooks: list[Path], env_extra: dict[str, str] | None = None, timeout: float = 90.0):
    """Yield a running :class:`LabServer` serving copies of ``notebooks``; always stop it."""
    root = tmp / "lab"
    root.mkdir(parents=True)
    for nb in notebooks:
        shutil.copy(nb, root / nb.name)
    home = tmp / "jupyter"
    env = dict(os.environ)
    env.update({
        "JUPYTER_CONFIG_DIR": str(home / "config"), "JUPYTER_RUNTIME_DIR": str(home / "runtime"),
        "JUPYTERLAB_SETTINGS_DIR": str(home / "settings"), "JUPYTERLAB_WORKSPACES_DIR": str(home / "workspaces"),
        "IPYTHONDIR": str(home / "ipython"), "JUPYTER_DATA_DIR": str(home / "data"), "COURSEKIT_FAST": "1",
        "COURSEKIT_EXERCISES": exercise_mode(),
        "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
        "PYTHONPATH": os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]),
    })
    env.update(env_extra or {})
    # Every cell in the DOM (no virtual scrolling), so prompts, widgets and outputs can be found;
    # no autosave (the test saves when it wants the executed notebook).
    settings = home / "settings" / "@jupyterlab"
    for ext, values in (("notebook-extension/tracker", {"windowingMode": "none"}),
                        ("docmanager-extension/plugin", {"autosave": False}),
                        ("apputils-extension/notification", {"fetchNews": "false", "checkForUpdates": False})):
        (settings / ext).parent.mkdir(parents=True, exist_ok=True)
        (settings / f"{ext}.jupyterlab-settings").write_text(json.dumps(values))
    token = secrets.token_hex(16)
    port = free_port()
    cmd = [sys.executable, "-m", "jupyterlab", "--no-browser", f"--port={port}", "--ip=127.0.0.1",
           f"--IdentityProvider.token={token}", f"--ServerApp.root_dir={root}", "--ServerApp.port_retries=0",
           "--LabApp.news_url=", "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate",
           # window.jupyterapp: LabPage.open() reads the notebook's real kernel state from it (see there)
           "--LabApp.expose_app_in_browser=True"]
    if os.geteuid() == 0:
        cmd.append("--allow-root")
    log = open(tmp / "lab.log", "wb")  # noqa: SIM115  (closed in finally)
    proc = subprocess.Popen(cmd, env=env, cwd=root, stdout=log, stderr=subprocess.STDOUT,
                            stdin=subprocess.DEVNULL, start_new_session=True)
    server = LabServer(url=f"http://127.0.0.1:{port}", token=token, root=root, proc=proc)
    try:
        _wait_ready(server, timeout)
        yield server
    finally:
        _stop(server)
        log.close()


STOPPED_GRACE_S = 5.0  # nothing running for this long while cells wait unrun: Run All has stopped


class RunAllStopped(RuntimeError):
    """Run All ended with cells that never ran (a cell raised, or the kernel died)."""


KERNEL_STATE_JS = """() => {
    const context = window.jupyterapp?.shell?.currentWidget?.sessionContext;
    const kernel = context?.session?.kernel;
    return context ? {status: context.kernelDisplayStatus, connection: kernel?.connectionStatus ?? null,
                      ready: context.isReady, name: kernel?.name ?? null} : null;
}"""
"""The open notebook's kernel as JupyterLab's session context sees it (None before the notebook opens)."""

KERNEL_READY_JS = f"""() => {{
    const state = ({KERNEL_STATE_JS})();
    return state !== null && state.ready && state.connection === 'connected' && state.status === 'idle';
}}"""


def _log_tail(server: LabServer, chars: int = 3000) -> str:
    log = server.root.parent / "lab.log"
    return log.read_text(errors="replace")[-chars:] if log.exists() else "(no server log)"


class LabPage:
    """A notebook open in JupyterLab, driven by playwright."""

    def __init__(self, page, server: LabServer, name: str):
        self.page, self.server, self.name = page, server, name

    def open(self, timeout_ms: int = 120_000) -> None:
        self.page.goto(f"{self.server.url}/lab/tree/{self.name}?token={self.server.token}&reset",
                       timeout=timeout_ms)
        self.page.wait_for_selector(".jp-Notebook .jp-Cell", timeout=timeout_ms)
        # The kernel is up when the notebook's session context says so. The toolbar's execution
        # indicator is no witness: it reads 'idle' from the moment it is drawn, before the session
        # has even asked for a kernel, and a Run All issued then (kernel specs not loaded yet on a
        # busy machine) opens JupyterLab's "Select Kernel" dialog instead of running anything.
        # A dialog instead (no such kernel, a kernel that failed to start) ends the wait at once.
        self.page.wait_for_function(f"() => ({KERNEL_READY_JS})() || document.querySelector('.jp-Dialog') !== null",
                                    timeout=timeout_ms)
        self.fail_on_dialog("after opening")

    def fail_on_dialog(self, when: str) -> None:
        """Raise, naming it, if a JupyterLab dialog is open (it would swallow every click)."""
        dialogs = self.page.locator(".jp-Dialog").all_inner_texts()
        if dialogs:
            self.page.screenshot(path=str(self.server.root / f"dialog-{self.name}.png"))
            raise RuntimeError(f"{self.name}: a JupyterLab dialog is open {when}: {dialogs}; kernel "
                               f"{self.page.evaluate(KERNEL_STATE_JS)}\n--- jupyter lab log (tail) ---\n"
                               f"{_log_tail(self.server)}")

    def command(self, menu: str, item: str) -> None:
        self.page.locator(".lm-MenuBar-itemLabel", has_text=menu).first.click()
        self.page.locator(".lm-Menu-itemLabel", has_text=item).first.click()

    def prompts(self) -> list[str]:
        return self.page.locator(".jp-CodeCell .jp-InputPrompt").all_inner_texts()

    def run_all(self, timeout_s: float) -> None:
        """Run > Run All Cells, then wait until no cell is queued or running.

        The menu command is issued again (up to three times) when no cell has started 30 s
        later: a click can land while the page is still busy settling. Each repeat is a warning in
        pytest's summary (the one known cause, Run All before the kernel existed, is fixed in
        :meth:`open`; a repeat is a new one to find), and a dialog fails at once.
        """
        deadline = time.monotonic() + timeout_s
        # Exported meshcat pages (iframes with a srcdoc) redraw WebGL on the CPU every frame; while
        # the kernel runs they would compete with it for the two cores, so they stay hidden (not
        # laid out, not drawn) until the last cell has run. Widget views are left alone.
        hidden = self.page.add_style_tag(content=".jp-OutputArea-output iframe[srcdoc] { display: none !important; }")
        try:
            self._run_all(deadline, timeout_s)
        finally:
            hidden.evaluate("element => element.remove()")

    def _run_all(self, deadline: float, timeout_s: float) -> None:
        for attempt in range(3):
            self.fail_on_dialog(f"before Run All (attempt {attempt + 1})")
            if attempt:
                warnings.warn(f"{self.name}: Run All started no cell within 30 s; issued again (attempt "
                              f"{attempt + 1}); kernel {self.page.evaluate(KERNEL_STATE_JS)}", stacklevel=2)
            self.page.locator(".jp-Notebook").first.click()
            self.command("Run", "Run All Cells")
            started = time.monotonic() + 30
            while time.monotonic() < started and all(p.strip() in ("[ ]:", "") for p in self.prompts()):
                time.sleep(0.5)
            if not all(p.strip() in ("[ ]:", "") for p in self.prompts()):
                break
        stopped_since = None
        while time.monotonic() < deadline:
            prompts = self.prompts()
            if prompts and not any("*" in p for p in prompts):
                if all(p.strip() not in ("[ ]:", "") for p in prompts):
                    return
                # Nothing queued or running, yet cells never ran: JupyterLab drops the queue when a
                # cell raises or the kernel dies. Waiting for the deadline would only hide that.
                stopped_since = stopped_since or time.monotonic()
                if time.monotonic() - stopped_since > STOPPED_GRACE_S:
                    raise RunAllStopped(self._stopped_report(prompts))
            else:
                stopped_since = None
            time.sleep(1.0)
        self.page.screenshot(path=str(self.server.root / f"timeout-{self.name}.png"))
        raise TimeoutError(f"{self.name}: cells still running after {timeout_s} s; prompts {self.prompts()}")

    def _stopped_report(self, prompts: list[str]) -> str:
        """Why Run All stopped early: prompts, kernel status, visible errors and dialogs, server log."""
        self.page.screenshot(path=str(self.server.root / f"stopped-{self.name}.png"))
        status = self.page.locator(".jp-Notebook-ExecutionIndicator").first.get_attribute("data-status")
        errors = self.page.locator(".jp-OutputArea-output[data-mime-type='application/vnd.jupyter.stderr']")
        dialogs = self.page.locator(".jp-Dialog-content").all_inner_texts()
        tail = _log_tail(self.server)
        memory = psutil.virtual_memory()
        return (f"{self.name}: Run All stopped before every cell ran; prompts {prompts}; kernel status "
                f"{status!r}; dialogs {dialogs}; stderr outputs {errors.all_inner_texts()[-3:]}; memory "
                f"available {memory.available / 2**30:.1f} of {memory.total / 2**30:.1f} GiB\n"
                f"--- jupyter lab log (tail) ---\n{tail}\n--- kernel log lines about killed processes ---\n"
                f"{_oom_lines()}")

    def save_and_read(self) -> dict:
        """Save the notebook from the browser and return the executed notebook JSON from disk."""
        path = self.server.root / self.name
        before = path.stat().st_mtime_ns
        self.fail_on_dialog("before saving")
        self.page.locator(".jp-Notebook").first.click()
        self.page.keyboard.press("Control+s")
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if path.stat().st_mtime_ns != before:
                with contextlib.suppress(ValueError):  # still being written: try again
                    return json.loads(path.read_text())
            time.sleep(0.5)
        raise TimeoutError(f"{self.name} was not saved within 60 s")


def _oom_lines() -> str:
    """The kernel log's last lines about killed processes (a dead kernel's usual cause), if readable."""
    try:
        out = subprocess.run(["dmesg"], capture_output=True, text=True, timeout=10).stdout
    except (OSError, subprocess.TimeoutExpired):
        return "(dmesg not available)"
    lines = [ln for ln in out.splitlines() if "killed process" in ln.lower() or "out of memory" in ln.lower()]
    return "\n".join(lines[-5:]) or "(none, or dmesg not readable)"


def error_outputs(nb: dict) -> list[str]:
    """'cell i: Ename: value' for every error output of an executed notebook."""
    errors = []
    for i, cell in enumerate(nb["cells"]):
        for out in cell.get("outputs", []):
            if out.get("output_type") == "error":
                errors.append(f"cell {i}: {out.get('ename')}: {out.get('evalue')}")
    return errors


def not_run(nb: dict) -> list[int]:
    return [i for i, c in enumerate(nb["cells"]) if c["cell_type"] == "code" and "".join(c["source"]).strip()
            and not c.get("execution_count")]
