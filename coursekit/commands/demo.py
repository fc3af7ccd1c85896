"""``coursekit demo``: the end-to-end tour (what ``make demo`` runs), a few minutes on a laptop CPU.

1. generate a handful of PushT demonstrations with the scripted expert and save them;
2. replay one of them in a fresh environment (same reset seed, same actions: the same states bit
   for bit, the physics is deterministic) and check that it ends in success;
3. write the replay as a 3-D meshcat animation (one self-contained HTML file) and a matplotlib
   figure (the replayed pusher path; every demonstration's coverage over time) under ``--out``;
4. print where everything is and how to open the course.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from coursekit.commands._args import MAX_SEED, int_in, nonnegative_int, output_path, seed_int

HELP = "the end-to-end tour: PushT demonstrations, a replay, a meshcat HTML animation and a figure"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--episodes", type=int_in(1, 1000), default=6, help="number of scripted demonstrations (default 6)")
    parser.add_argument("--seed", type=seed_int, default=0, help="seed of the first demonstration (episode i uses seed + i)")
    parser.add_argument("--out", type=output_path, default=Path("outputs"),
                        help="output folder (default outputs/); the tour replaces only the three files it wrote there")
    parser.add_argument("--replay", type=nonnegative_int, default=0, help="which demonstration to replay and animate (default 0)")
    parser.add_argument("--no-progress", action="store_true", help="hide progress bars")


def replay_episode(states, actions, seed: int | None = None):
    """Replay ``actions`` (T, 2) in a fresh PushTEnv.

    With the episode's reset ``seed`` the env is reset exactly as when it was recorded and the
    replay reproduces every state bit for bit. Without one, the T is placed at ``states[0]``
    with ``set_state``, which is close but not exact: the reset's physics substep can leave
    hidden solver state (see ``PushTEnv.set_state``), and pushing is chaotic.

    Returns (replayed states (T, 7) [ax, ay, bx, by, angle, vx, vy], coverage (T,) after each
    action, largest |position difference| (px) to the recorded states (T, 5)).
    """
    import numpy as np

    from coursekit.envs.pusht import PushTEnv

    env = PushTEnv()
    if seed is not None:
        env.reset(seed=int(seed))
    else:
        env.reset()
        # set_state puts the T exactly at the recorded pose (angle set before position); the
        # reset option "reset_to_state" would apply the reference's LEGACY order and shift the T.
        env.set_state(np.asarray(states[0][:5], dtype=np.float64))
    replayed, coverage = [env.get_state()], []
    for action in actions:
        _, _, _, _, info = env.step(action)  # the raw env keeps stepping after success: the rest steps
        replayed.append(env.get_state())
        coverage.append(info["coverage"])
    env.close()
    replayed = np.array(replayed[:-1])  # (T, 7): the state each action was taken in, like the dataset
    drift = float(np.abs(replayed[:, :4] - np.asarray(states)[:, :4]).max())
    return replayed, np.array(coverage), drift


PAGE_MARK = "<!-- written by `coursekit demo`: a PushT demonstration replayed in meshcat -->"
"""Appended to the tour's HTML page (after </html>, where it changes nothing): what proves the page is the tour's."""
FIGURE_SOFTWARE = "coursekit demo"
"""The ``Software`` text of the tour's PNG figure: what proves the figure is the tour's."""


def save_figure(dataset, replay: int, path: Path, lock: Any = None) -> Path:
    """The replayed demonstration's pusher path over its start, and every demonstration's coverage."""
    from matplotlib.figure import Figure

    from coursekit.atomic import atomic_path
    from coursekit.viz.pusht_plots import plot_coverage, plot_trajectories

    episodes = [dataset.episode(i) for i in range(dataset.n_episodes)]
    states = episodes[replay]["state"]
    fig = Figure(figsize=(10.0, 4.6), layout="constrained")
    left, right = fig.subplots(1, 2, width_ratios=[1.0, 1.15])
    plot_trajectories([states], ax=left, end_states=[states[-1]], labels=["pusher path"],
                      title=f"demonstration {replay}: start, pusher path, end (dotted)")
    plot_coverage([ep["coverage"] for ep in episodes], labels=[f"demonstration {i}" for i in range(len(episodes))],
                  ax=right)
    right.set_title(f"{len(episodes)} scripted demonstrations: coverage of the goal T")
    with atomic_path(path, suffix=".png", lock=lock) as tmp:
        fig.savefig(tmp, dpi=110, format="png", metadata={"Software": FIGURE_SOFTWARE})
    return path


def _outputs(out: Path, args: argparse.Namespace) -> tuple[Path, Path, Path]:
    """The three files the tour writes under ``--out`` (dataset, 3-D replay page, figure)."""
    return (out / "data" / f"demo_pusht_{args.episodes}ep_seed{args.seed}.npz", out / "demo_pusht_replay.html",
            out / "demo_pusht.png")


def _png_software(path: Path) -> str:
    """The ``Software`` tEXt entry of the PNG ``path`` ('' if none, or not a PNG); reads at most 1 MB."""
    with open(path, "rb") as fh:
        data = fh.read(1 << 20)
    if not data.startswith(b"\x89PNG\r\n\x1a\n"):
        return ""
    pos = 8
    while pos + 8 <= len(data):
        size, kind = int.from_bytes(data[pos:pos + 4], "big"), data[pos + 4:pos + 8]
        if kind == b"IDAT":
            break
        if kind == b"tEXt" and data[pos + 8:pos + 8 + size].startswith(b"Software\x00"):
            return data[pos + 17:pos + 8 + size].decode("latin-1")
        pos += 12 + size
    return ""


def _page_foreign(path: Path) -> str | None:
    with open(path, "rb") as fh:
        fh.seek(max(0, path.stat().st_size - 4096))
        tail = fh.read()
    return None if PAGE_MARK.encode() in tail else "it does not end with the tour's mark"


def _figure_foreign(path: Path) -> str | None:
    return None if _png_software(path) == FIGURE_SOFTWARE else f"it is not a PNG with Software '{FIGURE_SOFTWARE}'"



def _check_demo_outputs(out: Path, args: argparse.Namespace) -> None:
    """Before any work: --out must be a (possibly new) folder; the tour replaces only its own three files there.

    Nothing else in the folder is touched. A file of one of those names is replaced only if it is
    provably the tour's: a coursekit dataset, a page ending with :data:`PAGE_MARK`, a PNG whose
    ``Software`` is :data:`FIGURE_SOFTWARE`.
    """
    from coursekit.data.episodes import dataset_foreign
    from coursekit.outputs import check_output

    check_output(out, what="folder", foreign=lambda p: None, directory=True, overwrite=True)
    data, page, figure = _outputs(out, args)
    check_output(data, what="coursekit dataset", foreign=dataset_foreign, directory=False, overwrite=True)
    check_output(page, what="coursekit demo page", foreign=_page_foreign, directory=False, overwrite=True)
    check_output(figure, what="coursekit demo figure", foreign=_figure_foreign, directory=False, overwrite=True)


def _write_page(replayed, actions, path: Path, lock: Any) -> Path:
    """The replay as a 3-D meshcat animation, one self-contained HTML page (marked as the tour's)."""
    from coursekit.atomic import atomic_write_text
    from coursekit.viz.meshcat.pusht import PushTMeshcat
    from coursekit.viz.meshcat.scene import MeshcatScene

    with MeshcatScene() as scene:  # its server is killed as soon as the page is drawn
        viewer = PushTMeshcat(scene, show_target=True)
        viewer.animate(replayed, actions=actions, fps=10.0, play=True)
        page = viewer.html()
    atomic_write_text(path, f"{page}\n{PAGE_MARK}\n", lock=lock)
    return path


def run(args: argparse.Namespace) -> int:
    from coursekit.outputs import claim_output

    if not 0 <= args.replay < args.episodes:
        raise ValueError(f"--replay must index one of the {args.episodes} episodes, got {args.replay}")
    if args.seed > MAX_SEED - (args.episodes - 1):
        raise ValueError(f"--seed must be at most {MAX_SEED - (args.episodes - 1)} (episode i uses seed + i), got {args.seed}")
    out: Path = args.out
    _check_demo_outputs(out, args)
    with claim_output(out, what="folder", foreign=lambda p: None, directory=True, overwrite=True) as lock:
        _check_demo_outputs(out, args)  # again, now that no other tour can write here
        return _tour(args, out, lock)


def _tour(args: argparse.Namespace, out: Path, lock: Any) -> int:
    """The four steps, every file written under the lock on ``out``."""
    from coursekit.experts.pusht_planner import collect_dataset

    start = time.perf_counter()
    data_path, page_path, figure_path = _outputs(out, args)
    print(f"[1/4] generating {args.episodes} PushT demonstrations with the scripted expert (seed {args.seed}) ...")
    t0 = time.perf_counter()
    dataset = collect_dataset(args.episodes, args.seed, progress=not args.no_progress)
    dataset.save(data_path, lock=lock)
    lengths = dataset.episode_lengths
    print(f"      {dataset.n_episodes} episodes, {dataset.n_steps} steps (mean {lengths.mean():.0f} per episode) "
          f"in {time.perf_counter() - t0:.1f} s")

    print(f"[2/4] replaying demonstration {args.replay} in a fresh environment ...")
    episode = dataset.episode(args.replay)
    replayed, coverage, drift = replay_episode(episode["state"], episode["action"],
                                               seed=dataset.meta["episode_seeds"][args.replay])
    print(f"      {len(replayed)} steps, final coverage {coverage[-1]:.3f} "
          f"({'success' if coverage.max() > 0.95 else 'NOT a success'}); "
          f"largest drift from the recorded states {drift:.2e} px")

    print("[3/4] writing the replay as a 3-D meshcat animation ...")
    t0 = time.perf_counter()
    _write_page(replayed, episode["action"], page_path, lock)
    print(f"      {page_path.stat().st_size / 1e6:.2f} MB in {time.perf_counter() - t0:.1f} s")

    print("[4/4] drawing the demonstrations with matplotlib ...")
    save_figure(dataset, args.replay, figure_path, lock)

    print(f"\nDone in {time.perf_counter() - start:.0f} s. Open these:")
    print(f"  demonstrations   {data_path}")
    print(f"  3-D replay       {page_path.resolve().as_uri()}   (any browser, works offline)")
    print(f"  figure           {figure_path}")
    print("\nNext: `make lab` opens the course in JupyterLab; start with notebooks/00_setup_and_tour.ipynb.")
    return 0
