"""coursekit: action-chunk generative policies taught on a laptop CPU.

Diffusion Policy (Chi et al. 2023, RSS), ACT (Zhao et al. 2023, RSS), a flow-matching head on
Diffusion Policy's network (Lipman et al. 2023; pi0's convention, Black et al. 2024) and a
regression baseline; every policy type is registered in ``coursekit.policies.POLICY_TYPES``.

Submodules load lazily: ``import coursekit`` costs almost nothing, and torch, mujoco or meshcat
are imported only when a part that needs them is first touched (``coursekit.policies`` pulls
torch; ``coursekit.envs.aloha`` pulls mujoco; ``coursekit.viz.meshcat.scene`` pulls meshcat).

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
    "flow": "coursekit.flow:",
    "nn": "coursekit.nn:",
    "policies": "coursekit.policies:",
    "execution": "coursekit.execution:",
    "viz": "coursekit.viz:",
    "grading": "coursekit.grading:",
    "glossary": "coursekit.glossary:",
    "config": "coursekit.config:",
    "checkpoint": "coursekit.checkpoint:",
    "train": "coursekit.train:",
    "training_log": "coursekit.training_log:",
    "evaluate": "coursekit.evaluate:",
    "teleop": "coursekit.teleop:",
    "tasks": "coursekit.tasks:",
    "check": "coursekit.grading.notebook:check",
}

__all__ = sorted(_LAZY) + ["__version__"]
__getattr__, __dir__ = lazy_loader(__name__, _LAZY)


def _register_gym_envs() -> None:
    """Register every task's gymnasium id (cheap: entry points are strings, nothing heavy is imported)."""
    from coursekit.tasks.registry import register_gym_envs

    try:
        register_gym_envs()
    except ImportError:  # gymnasium missing: the envs are unusable anyway, the rest still works
        return


_register_gym_envs()
