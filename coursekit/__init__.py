"""coursekit: action-chunk generative policies (Diffusion Policy and ACT), taught on a laptop CPU.

Submodules load lazily: ``import coursekit`` costs almost nothing, and torch, mujoco or meshcat
are imported only when a part that needs them is first touched (``coursekit.policies`` pulls
torch; ``coursekit.envs.aloha`` pulls mujoco; ``coursekit.viz.meshcat_*`` pulls meshcat).

Glossary (paper symbol -> name in code, notebooks and docs alike; see ``coursekit.glossary``):

    To   = n_obs_steps     observation steps the policy sees
    Tp   = horizon         actions predicted per chunk (Diffusion Policy)
    Ta   = n_action_steps  actions executed before re-planning
    k    = chunk_size      actions predicted per chunk (ACT)
    beta = kl_weight       weight of the KL term in the CVAE loss (ACT)
"""

from __future__ import annotations

from coursekit.lazy import lazy_loader

__version__ = "0.1.0"

# Names resolved on first access: "attribute" -> "module:" (the module) or "module:object".
_LAZY = {
    "envs": "coursekit.envs:",
    "experts": "coursekit.experts:",
    "data": "coursekit.data:",
    "diffusion": "coursekit.diffusion:",
    "nn": "coursekit.nn:",
    "policies": "coursekit.policies:",
    "execution": "coursekit.execution:",
    "viz": "coursekit.viz:",
    "grading": "coursekit.grading:",
    "glossary": "coursekit.glossary:",
    "config": "coursekit.config:",
    "checkpoint": "coursekit.checkpoint:",
    "train": "coursekit.train:",
    "evaluate": "coursekit.evaluate:",
    "teleop": "coursekit.teleop:",
    "check": "coursekit.grading.notebook:check",
}

__all__ = sorted(_LAZY) + ["__version__"]
__getattr__, __dir__ = lazy_loader(__name__, _LAZY)


def _register_gym_envs() -> None:
    """Register the gymnasium ids (cheap: entry points are strings, nothing heavy is imported)."""
    try:
        from coursekit.envs.registration import register_all
    except ImportError:  # gymnasium missing: the envs are unusable anyway, the rest still works
        return
    register_all()


_register_gym_envs()
