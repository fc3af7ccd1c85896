"""Seeing the worlds: matplotlib figures, meshcat 3-D scenes exported as HTML, browser checks.

Everything here loads lazily: ``import coursekit.viz`` imports neither meshcat nor mujoco; a
name below pulls its module (and that module's heavy imports) on first use.

    MeshcatScene, shared_scene          one meshcat server per process, closed cleanly  (meshcat_scene)
    PushTMeshcat, export_pusht_rollout  PushT in 3-D, rollouts as animations            (meshcat_pusht)
    MujocoMeshcat, export_mujoco_rollout  any MuJoCo model in meshcat                   (mujoco_meshcat)
    show_html                           an exported page inline in a notebook          (notebook)
    screenshot_html, find_chromium      headless-chromium screenshots                  (browser)
    MetricsLog, plot_metrics            a training run's metrics.csv and loss.png      (run_log)
    EpisodeRecording, write_replay      evaluated episodes as an HTML replay + frames  (replay)
    TeleopWidget                        push the T with the mouse, recorded            (teleop_widget)
    FigureScrubber                      sliders that redraw one figure in place        (widgets, widgets_chunks, widgets_delay)
"""

from __future__ import annotations

from coursekit.lazy import lazy_loader

_LAZY = {
    "MeshcatScene": "coursekit.viz.meshcat_scene",
    "shared_scene": "coursekit.viz.meshcat_scene",
    "PushTMeshcat": "coursekit.viz.meshcat_pusht",
    "export_pusht_rollout": "coursekit.viz.meshcat_pusht",
    "MujocoMeshcat": "coursekit.viz.mujoco_meshcat",
    "export_mujoco_rollout": "coursekit.viz.mujoco_meshcat",
    "show_html": "coursekit.viz.notebook",
    "screenshot_html": "coursekit.viz.browser",
    "find_chromium": "coursekit.viz.browser",
    "ChromiumNotFoundError": "coursekit.viz.browser",
    "MetricsLog": "coursekit.viz.run_log",
    "plot_metrics": "coursekit.viz.run_log",
    "EpisodeRecording": "coursekit.viz.replay",
    "write_replay": "coursekit.viz.replay",
    "TeleopWidget": "coursekit.viz.teleop_widget",
    "FigureScrubber": "coursekit.viz.widgets",
    "delay_scrubber": "coursekit.viz.widgets_delay",
}
__all__ = sorted(_LAZY)
__getattr__, __dir__ = lazy_loader(__name__, _LAZY, submodules=True)
