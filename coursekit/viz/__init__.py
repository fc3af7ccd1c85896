"""Seeing the worlds: matplotlib figures, meshcat 3-D scenes exported as HTML, notebook widgets.

Everything here loads lazily: ``import coursekit.viz`` imports neither meshcat nor mujoco; a
name below pulls its module (and that module's heavy imports) on first use.

    MeshcatScene, shared_scene          one meshcat scene per process, closed cleanly  (meshcat.scene)
    PushTMeshcat, export_pusht_rollout  PushT in 3-D, rollouts as animations            (meshcat.pusht)
    MujocoMeshcat, export_mujoco_rollout  any MuJoCo model in meshcat                   (meshcat.mujoco_model)
    show_html                           an exported page inline in a notebook          (notebook)
    EpisodeRecording, write_replay      evaluated episodes as an HTML replay + frames  (replay)
    TeleopWidget                        push the T with the mouse, recorded            (teleop_widget)
    FigureScrubber, delay_scrubber      sliders that redraw one figure in place        (scrubbers.*)

Figures: ``pusht_plots`` (the PushT scene, trajectories), ``expert_plots`` (the scripted expert),
``measured`` (the results table's rows, with their intervals, for the chapters' measured claims).
A training run's metrics.csv and loss.png are the trainer's (:mod:`coursekit.training_log`).
"""

from __future__ import annotations

from coursekit.lazy import lazy_loader

_LAZY = {
    "MeshcatScene": "coursekit.viz.meshcat.scene",
    "shared_scene": "coursekit.viz.meshcat.scene",
    "PushTMeshcat": "coursekit.viz.meshcat.pusht",
    "export_pusht_rollout": "coursekit.viz.meshcat.pusht",
    "MujocoMeshcat": "coursekit.viz.meshcat.mujoco_model",
    "export_mujoco_rollout": "coursekit.viz.meshcat.mujoco_model",
    "show_html": "coursekit.viz.notebook",
    "EpisodeRecording": "coursekit.viz.replay",
    "write_replay": "coursekit.viz.replay",
    "TeleopWidget": "coursekit.viz.teleop_widget",
    "FigureScrubber": "coursekit.viz.scrubbers.figure",
    "delay_scrubber": "coursekit.viz.scrubbers.delay",
}
__all__ = sorted(_LAZY)
__getattr__, __dir__ = lazy_loader(__name__, _LAZY, submodules=True)
