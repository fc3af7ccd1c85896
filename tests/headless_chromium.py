"""Test helper: screenshots of exported HTML in a real (headless) chromium, proof that a page draws.

meshcat's exported pages draw with WebGL. Headless chromium on a machine without a GPU renders
them through SwiftShader (the CPU WebGL backend) when given the flags below (a few seconds a
page; ``pytest tests/test_browser.py --durations=0`` times them on your machine).
``--virtual-time-budget`` lets the page's scripts and animation frames run for that many
milliseconds of *virtual* time before the picture is taken.

Debian's package is ``chromium`` (``/usr/bin/chromium``); ``make test`` installs it when missing
(``make browser``). Only the tests use this module (``from headless_chromium import ...``: pytest
puts ``tests/`` on the path).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

# Where the Debian/Ubuntu packages put the browser, first match wins.
_CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


class ChromiumNotFoundError(RuntimeError):
    """No headless-capable chromium on this machine (install it: ``apt-get install chromium``)."""


def find_chromium() -> str | None:
    """Path of a chromium executable (``/usr/bin/chromium`` first), or None when there is none."""
    if os.access("/usr/bin/chromium", os.X_OK):
        return "/usr/bin/chromium"
    for name in _CANDIDATES:
        found = shutil.which(name)
        if found:
            return found
    return None


def chromium_command(chromium: str, html_path: Path, png_path: Path, user_data_dir: Path,
                     window_size: tuple[int, int], budget_ms: int) -> list[str]:
    """The command line that renders WebGL headless on a CPU-only machine (SwiftShader)."""
    width, height = window_size
    return [
        chromium,
        "--headless",
        "--no-sandbox",  # we run as root in CI; chromium refuses to start sandboxed as root
        "--disable-gpu",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        "--disable-quic",
        "--enable-unsafe-swiftshader",  # WebGL on the CPU
        f"--user-data-dir={user_data_dir}",
        f"--window-size={width},{height}",
        f"--virtual-time-budget={budget_ms}",
        f"--screenshot={png_path}",
        html_path.resolve().as_uri(),
    ]


def screenshot_html(html_path: str | os.PathLike, png_path: str | os.PathLike,
                    window_size: tuple[int, int] = (800, 600), budget_ms: int = 5000,
                    timeout_s: float = 120.0) -> Path:
    """Open ``html_path`` in headless chromium and save a PNG screenshot to ``png_path``.

    Args:
        html_path: a local HTML file (for example a meshcat export).
        png_path: where the (width, height) RGB PNG goes.
        window_size: (width, height) of the browser window in pixels.
        budget_ms: virtual milliseconds the page may run (scripts, animation) before the shot.
        timeout_s: wall-clock limit for chromium; a hung browser is killed.

    Returns:
        ``png_path`` as a Path.

    Raises:
        ChromiumNotFoundError: no chromium installed.
        FileNotFoundError: ``html_path`` does not exist.
        RuntimeError: chromium failed or wrote no image (its stderr tail is in the message).
    """
    html_path, png_path = Path(html_path), Path(png_path)
    if not html_path.is_file():
        raise FileNotFoundError(f"no HTML file to screenshot at {html_path}")
    width, height = window_size
    if width < 16 or height < 16:
        raise ValueError(f"window_size must be at least 16x16 pixels, got {window_size}")
    if budget_ms < 0:
        raise ValueError(f"budget_ms must be >= 0, got {budget_ms}")
    chromium = find_chromium()
    if chromium is None:
        raise ChromiumNotFoundError(
            "headless chromium not found (looked for /usr/bin/chromium and "
            f"{', '.join(_CANDIDATES)} on PATH); install it with `apt-get install -y chromium` "
            "(as root `make browser` does it)")
    png_path.parent.mkdir(parents=True, exist_ok=True)
    if png_path.exists():
        png_path.unlink()  # so a stale picture can never pass for a new one
    with tempfile.TemporaryDirectory(prefix="coursekit-chromium-") as profile:
        cmd = chromium_command(chromium, html_path, png_path.resolve(), Path(profile), (width, height), budget_ms)
        try:
            result = subprocess.run(cmd, capture_output=True, timeout=timeout_s, stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired as exc:
            raise RuntimeError(f"chromium did not finish within {timeout_s} s on {html_path}") from exc
    if result.returncode != 0 or not png_path.is_file():
        tail = result.stderr.decode("utf-8", "replace")[-2000:]
        raise RuntimeError(f"chromium exited with code {result.returncode} and "
                           f"{'an' if png_path.is_file() else 'no'} image for {html_path}:\n{tail}")
    return png_path

