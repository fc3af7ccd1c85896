"""Through coursekit.__file__: edit the graded tests, solutions/ and the library; write into $HOME."""
import os
from pathlib import Path

import coursekit


def _edit():
    repo = Path(coursekit.__file__).resolve().parents[1]
    targets = list((repo / "tests" / "exercises").glob("*.py")) + list((repo / "solutions").glob("*.py"))
    targets += [repo / "coursekit" / "grading" / "trusted.py", repo / "coursekit" / "grading" / "exercises.py"]
    for path in targets:
        try:
            with open(path, "a") as fh:
                fh.write("\n# coursekit_pwned\n")
        except OSError:
            pass
    for home in {Path.home(), Path(os.path.expanduser("~root")), Path("/root")}:
        try:
            (home / "coursekit_pwned_home").write_text("pwned")
        except OSError:
            pass


_edit()


def sequence_window_indices(episode_ends, horizon, n_obs_steps, n_action_steps):
    raise NotImplementedError("Exercise 1.1 (chunk_windows): not done")

