"""The course's exercises: the registry (every graded piece, in one table), where their files are,
and loading a student's module for one.

An exercise is code written ONCE in the library, inside a module-level function or class,
between ``# BEGIN SOLUTION`` and ``# END SOLUTION`` lines. ``coursekit exercises build`` turns
each entry below into ``exercises/<id>.py`` (stubs) and ``solutions/<id>.py`` (complete), and
``tests/exercises/test_<id>.py`` grades the student's module. Adding an exercise is one
``Exercise(...)`` entry here plus that one test file (see the instructors' section of the README).

How a graded test file is written (the student's code never runs in the test's process):

- set ``EXERCISE = "<id>"`` and take the ``student`` fixture (and ``sandbox`` for modules or
  gradients); ``student.f(x)`` runs the student's ``f`` in a sandboxed worker and returns plain
  data (numpy arrays, plain torch tensors, numbers, strings, lists, dicts); anything else (a
  module, an executor) comes back as a handle you can call and read attributes of;
- compare on the test's side against a trusted reference (closed form, torch, diffusers);
- a plain function of the test passed as an argument (a model, a predictor) stays in the test's
  process: the worker calls back. To test ONE function of an exercise, pass the REFERENCE for
  every other one (``q_sample_fn=reference_q_sample``), so one mistake fails only its own tests;
- modules: ``sandbox.seed(0); layer = student.FiLM(5, 3)``; ``sandbox.parameters(layer)``,
  ``sandbox.load_state_dict(layer, state)``, ``sandbox.grad(layer, h, cond, wrt=(0, layer),
  grad_output=g)``; ``sandbox.new("coursekit.nn.unet1d:ConditionalUnet1D", ..., film_cls=student.FiLM)``
  builds a library object around the student's class inside the worker;
- messages name the failing quantity ("d KL / d logvar differs ...") and the registry's hint says
  what to fix; an optional third entry ``{"shape": ..., "value": ...}`` gives a hint per failure kind.
"""

from __future__ import annotations

import importlib.util
import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType

_ID = re.compile(r"^[a-z][a-z0-9_]*$")
ROOT_ENV = "COURSEKIT_ROOT"
"""Environment variable naming the repository root (optional; found automatically otherwise)."""
FOLDER_ENV = "COURSEKIT_EXERCISES"
"""Environment variable choosing the implementation: "exercises" (default), "solutions" or a path."""


@dataclass(frozen=True)
class Exercise:
    """One graded exercise: where its code lives and how its tests are scored."""

    id: str
    """Short snake_case name; the generated files are exercises/<id>.py and solutions/<id>.py."""
    chapter: int
    """Notebook chapter; exercises are numbered <chapter>.<k> in registry order."""
    title: str
    """One line shown in stubs, check() tables and feedback."""
    source: str
    """Dotted library module that holds the marked code, e.g. "coursekit.data.chunks"."""
    objects: tuple[str, ...]
    """Module-level functions/classes copied (in this order) into the generated module."""
    tests: dict[str, tuple] = field(default_factory=dict)
    """Test function name in tests/exercises/test_<id>.py -> (points, one-line hint) or
    (points, hint, {failure kind: hint}) for kinds "shape", "dtype", "type", "value", "error"."""

    def __post_init__(self) -> None:
        if not _ID.match(self.id):
            raise ValueError(f"exercise id must be snake_case, got {self.id!r}")
        if not isinstance(self.chapter, int) or self.chapter < 0:
            raise ValueError(f"exercise {self.id!r}: chapter must be a non-negative int, got {self.chapter!r}")
        if not self.objects or not all(isinstance(o, str) and o.isidentifier() for o in self.objects):
            raise ValueError(f"exercise {self.id!r}: objects must be identifiers, got {self.objects!r}")
        if not self.tests:
            raise ValueError(f"exercise {self.id!r}: needs at least one graded test")
        for name, spec in self.tests.items():
            if not name.startswith("test_") or not name.isidentifier():
                raise ValueError(f"exercise {self.id!r}: test names must look like test_*, got {name!r}")
            if not (isinstance(spec, tuple) and len(spec) in (2, 3) and spec[0] > 0 and isinstance(spec[1], str) and spec[1]):
                raise ValueError(f"exercise {self.id!r}: test {name!r} needs (points > 0, hint), got {spec!r}")
            if len(spec) == 3 and not (isinstance(spec[2], dict) and all(isinstance(v, str) for v in spec[2].values())):
                raise ValueError(f"exercise {self.id!r}: test {name!r}: the third entry maps a failure kind to a hint, got {spec[2]!r}")

    @property
    def test_module(self) -> str:
        """Path of the graded test file, relative to the repository root."""
        return f"tests/exercises/test_{self.id}.py"

    @property
    def max_points(self) -> float:
        return float(sum(spec[0] for spec in self.tests.values()))


EXERCISES: tuple[Exercise, ...] = (
    Exercise(
        id="chunk_windows",
        chapter=1,
        title="Diffusion Policy training windows with edge padding",
        source="coursekit.data.chunks",
        objects=("sequence_window_indices",),
        tests={
            "test_shapes_and_dtypes": (1, "Return (indices, episode): int64 arrays of shape (W, Tp) and (W,)."),
            "test_one_episode_matches_definition": (2, "Window w holds clip(w + j, s, t - 1) for j = 0..Tp-1, w from s-(To-1) to t-Tp+(Ta-1)."),
            "test_edge_padding": (2, "Before the episode repeat its first row, after it repeat its last row (clip, don't wrap)."),
            "test_windows_stay_in_their_episode": (2, "Clip every window to its own episode [s, t); episode[w] is that episode's index."),
            "test_window_count": (1, "Each episode of length L gives max(L - Tp + To + Ta - 1, 1) windows."),
            "test_short_episode_gets_one_window": (1, "An episode shorter than a window still gives exactly one (edge-padded) window."),
            "test_matches_library_on_random_datasets": (1, "Episodes in order, window starts increasing; compare with SequenceWindows on small cases."),
        },
    ),
    Exercise(
        id="noise_loss",
        chapter=2,
        title="Forward noising q_sample and the epsilon-prediction loss",
        source="coursekit.diffusion.loss",
        objects=("q_sample", "epsilon_loss"),
        tests={
            "test_q_sample_matches_closed_form": (3, "x_t = sqrt(abar_t) * x0 + sqrt(1 - abar_t) * noise, with abar_t = alphas_cumprod[t] picked per sample."),
            "test_q_sample_endpoints_and_other_shapes": (1, "Reshape abar_t to (B, 1, ..., 1) so it broadcasts over any trailing shape of x0."),
            "test_q_sample_matches_diffusers_add_noise": (1, "Same formula as diffusers' add_noise: index alphas_cumprod by t, take square roots, broadcast."),
            "test_epsilon_loss_is_mse_on_noise": (3, "x_t = q_sample_fn(x0, t, noise, abar); loss = mean((eps_model(x_t, t, cond) - noise)^2), a 0-d tensor."),
            "test_epsilon_loss_uses_q_sample_fn_and_backpropagates": (2, "Build x_t with the q_sample_fn argument and use torch ops only so gradients reach the model."),
        },
    ),
    Exercise(
        id="film",
        chapter=3,
        title="FiLM: per-channel scale and bias from the condition",
        source="coursekit.nn.film",
        objects=("FiLM",),
        tests={
            "test_film_has_one_linear_layer_of_the_right_size": (1, "In __init__ create exactly self.linear = nn.Linear(cond_dim, 2 * channels)."),
            "test_film_matches_closed_form": (3, "e = self.linear(F.mish(cond)); out = e[:, :C, None] * h + e[:, C:, None]."),
            "test_film_scale_first_then_bias": (1, "The first C outputs of the linear layer are the scales, the last C the biases."),
            "test_film_uses_mish_on_the_condition": (1, "Apply Mish to cond BEFORE the linear layer (F.mish)."),
            "test_film_plugs_into_the_unet": (1, "FiLM(cond_dim, channels) must work inside ConditionalUnet1D: h (B, C, L), cond (B, cond_dim)."),
        },
    ),
    Exercise(
        id="ddim_step",
        chapter=4,
        title="One DDIM update (deterministic and stochastic)",
        source="coursekit.diffusion.samplers",
        objects=("ddim_step",),
        tests={
            "test_deterministic_step_closed_form": (2, "x0_hat = (x_t - sqrt(1-abar_t) eps) / sqrt(abar_t); x_prev = sqrt(abar_prev) x0_hat + sqrt(1-abar_prev) eps."),
            "test_clip_sample_clamps_x0_hat": (1, "If clip_sample, clamp x0_hat to [-clip_sample_range, clip_sample_range]; keep the model's eps in the direction term."),
            "test_stochastic_step_closed_form": (2, "sigma = eta*sqrt((1-abar_prev)/(1-abar_t)*(1-abar_t/abar_prev)); direction sqrt(1-abar_prev-sigma^2) eps; add sigma*noise."),
            "test_matches_diffusers_step_for_step": (3, "Match diffusers' DDIMScheduler.step (epsilon prediction, clip_sample, eta) at every step."),
            "test_last_step_returns_clean_estimate": (1, "With abar_prev = 1 the update returns the (clipped) x0 estimate."),
        },
    ),
    Exercise(
        id="receding_horizon",
        chapter=5,
        title="Receding-horizon execution of action chunks",
        source="coursekit.execution.receding",
        objects=("RecedingHorizon",),
        tests={
            "test_first_chunk_executes_pred_to_minus_1_onwards": (2, "Execute chunk[:, To-1 : To-1+Ta] in order; row b of the chunk is environment b's."),
            "test_replans_every_ta_steps": (3, "Call the predictor only when all Ta planned actions are used up (and on the first act after reset)."),
            "test_history_holds_newest_to_observations": (2, "Push each new obs into the history and drop the oldest; pass the newest To, oldest first."),
            "test_reset_repeats_first_observation_and_forgets_plan": (2, "reset(obs): history = [obs] * To, and forget any plan left from the last episode."),
            "test_works_with_torch_tensors": (1, "Only slice and index the chunk (chunk[:, i]); don't convert it to numpy."),
        },
    ),
    Exercise(
        id="kl",
        chapter=7,
        title="The KL of a diagonal Gaussian to N(0, I) (ACT's CVAE regulariser)",
        source="coursekit.nn.kl",
        objects=("gaussian_kl",),
        tests={
            "test_returns_a_scalar": (1, "Return one scalar tensor: sum over latent dims, then mean over the batch."),
            "test_zero_at_the_prior": (1, "mu = 0 and logvar = 0 is the prior itself: the KL is exactly 0."),
            "test_matches_torch_distributions": (3, "KL = 1/2 * sum_j (mu_j^2 + exp(logvar_j) - logvar_j - 1); sigma^2 = exp(logvar)."),
            "test_sum_over_latent_mean_over_batch": (2, "Sum over the latent dimension (dim 1), then average over the batch (dim 0)."),
            "test_gradients_match": (1, "d KL / d mu = mu / B and d KL / d logvar = (exp(logvar) - 1) / (2 B): check the 1/2 and the batch mean.",
                                     {"error": "Your code raised while computing the KL: fix that first (see the traceback).",
                                      "value": "d KL / d mu = mu / B and d KL / d logvar = (exp(logvar) - 1) / (2 B); no gradient at all means .item() or numpy broke the graph."}),
        },
    ),
    Exercise(
        id="temporal_ensembling",
        chapter=8,
        title="Temporal ensembling of overlapping action chunks (ACT)",
        source="coursekit.execution.ensembling",
        objects=("TemporalEnsemble",),
        tests={
            "test_first_step_is_the_first_chunk": (1, "At t = 0 only the first chunk covers t: return chunk[:, start] with shape (B, Da)."),
            "test_plain_mean_when_m_is_zero": (2, "With m = 0 every weight is 1: average chunk_s[t - s] over all stored chunks covering t."),
            "test_oldest_first_weights": (2, "w_i = exp(-m i) with i = 0 the OLDEST chunk covering t; divide by the sum of the weights."),
            "test_newest_first_weights": (2, "With newest_first=True count i from the NEWEST chunk (reverse the order before weighting)."),
            "test_old_chunks_expire": (1, "A chunk of length L made at step s covers s .. s+L-1: drop it once t - s >= L."),
            "test_start_offset_for_diffusion_policy": (1, "Store chunk[:, self.start:] so index 0 of a stored chunk is the step it was made at."),
        },
    ),
    Exercise(
        id="flow_loss",
        chapter=10,
        title="The flow-matching loss: sample t, interpolate, regress the velocity",
        source="coursekit.flow.loss",
        objects=("sample_flow_time", "flow_matching_loss"),
        tests={
            "test_times_in_range_and_shape": (1, "Return n float times in [0.001, 1): t = 0.001 + 0.999 * s."),
            "test_uniform_times_are_uniform": (1, "kind 'uniform': s = u with u = torch.rand(n, generator=generator)."),
            "test_beta_times_follow_beta_1_5_1": (2, "kind 'beta': s = u ** (2/3), the inverse of the Beta(1.5, 1) CDF s^1.5."),
            "test_times_use_the_generator": (1, "Draw u with torch.rand(..., generator=generator, device=device) so a seed repeats the times."),
            "test_model_sees_the_interpolated_chunk": (2, "x_t = t * noise + (1 - t) * a0 with t reshaped to (B, 1, ..., 1); call velocity_model(x_t, t, cond)."),
            "test_loss_matches_closed_form": (2, "target u = noise - a0; loss = mean((velocity_model(x_t, t, cond) - u)^2), a 0-d tensor."),
            "test_loss_backpropagates": (1, "Use torch ops only (no .item(), no numpy) so gradients reach the model."),
        },
    ),
    Exercise(
        id="euler_step",
        chapter=10,
        title="One Euler step of the flow ODE",
        source="coursekit.flow.sampler",
        objects=("euler_step",),
        tests={
            "test_step_closed_form": (2, "x_next = x_t + dt * velocity_model(x_t, t_vec, cond)."),
            "test_model_gets_time_as_a_batch_vector": (2, "Pass t as a (B,) tensor of x_t's dtype and device, every entry t: torch.full((B,), t)."),
            "test_exact_on_a_constant_field": (1, "N steps of dt = -1/N on v = c move x by exactly -c."),
            "test_first_order_on_a_linear_field": (2, "Euler on dx/dt = x gives x1 * (1 - 1/N)^N after N steps."),
        },
    ),
    Exercise(
        id="async_chunking",
        chapter=11,
        title="Naive asynchronous chunk execution under an inference delay of d steps",
        source="coursekit.execution.delay",
        objects=("AsyncChunking",),
        tests={
            "test_zero_delay_is_receding_horizon": (2, "With d = 0 a request arrives at once: request every Ta steps and play the chunk from its start."),
            "test_switch_indices_on_a_hand_built_stream": (3, "Receive first, then request if due, then receive again; play current.action_at(t): index t - request."),
            "test_requests_see_the_newest_observations": (2, "Request at step t after pushing obs_t: next_request = t + self.period (max(Ta, d))."),
            "test_delay_longer_than_ta_holds_the_last_action": (2, "Only one inference at a time; past the chunk's end action_at holds its last action."),
            "test_batch_rows_and_start_offset": (1, "Return self._emit(action, ...) with action (B, Da) = the current chunk's column for step t."),
        },
    ),
    Exercise(
        id="rtc_step",
        chapter=11,
        title="Real-time chunking's step: the soft-mask weights and one guided update",
        source="coursekit.execution.rtc",
        objects=("rtc_weights", "guidance_vjp", "guided_update"),
        tests={
            "test_weights_shape_and_frozen_prefix": (1, "Return W as a float array of shape (n,) with W_j = 1 for the d frozen steps j < d."),
            "test_soft_weights_decay_exponentially": (3, "W_j for d <= j < L decays: W_j = c_j (e^c_j - 1) / (e - 1) with c_j = (L - j) / (L - d + 1), "
                                                         "about 1 at j = d and near 0 at j = L - 1; not a constant, not a straight line."),
            "test_weights_zero_past_the_overlap": (1, "W_j = 0 for j >= L (the previous chunk has ended); with L <= d only the frozen prefix is 1."),
            "test_hard_schedule_freezes_only": (1, "schedule 'hard': W_j = 1 for j < d and 0 everywhere else (no soft region)."),
            "test_vjp_is_jacobian_transpose_times_weighted_error": (3, "g = J^T e with e = W (Y - x0_hat) and J = d x0_hat / d x: "
                                                                       "torch.autograd.grad(x0_hat, x, grad_outputs=e)."),
            "test_vjp_weights_each_step_of_the_error": (1, "Weight the ERROR before the VJP: e[:, j, :] = W_j (Y - x0_hat)[:, j, :] "
                                                          "(weights.view(1, -1, 1)); not g afterwards, not W over the action dimension."),
            "test_vjp_pulls_toward_the_previous_chunk": (2, "g must point where x0_hat gets closer to Y: a small step x + eps g lowers sum_j W_j |Y_j - x0_hat_j|^2; "
                                                           "the error is Y - x0_hat.",
                                                        {"value": "The guidance has the wrong sign (or none): it must pull x0_hat toward the previous "
                                                                  "chunk Y, and yours pushes it away or not at all. The error is Y - x0_hat, not x0_hat - Y."}),
            "test_update_closed_form": (1, "out' = out - scale * g, the same shape as out."),
            "test_update_pulls_toward_the_previous_chunk": (2, "v and eps point toward the noise and the sampler steps against them: "
                                                              "out' = out - scale * g moves the next iterate along +g, toward Y.",
                                                           {"value": "The guided update has the wrong sign: out + scale * g pushes the chunk away "
                                                                     "from the previous chunk Y; take it off: out' = out - scale * g."}),
        },
    ),
    Exercise(
        id="spatial_softmax",
        chapter=12,
        title="The spatial softmax: a keypoint (x, y) from each heat map",
        source="coursekit.nn.vision",
        objects=("spatial_softmax",),
        tests={
            "test_keypoints_shape_and_dtype": (1, "Return (B, K, 2) in the maps' dtype: one (x, y) per map, x first."),
            "test_peak_gives_its_pixel_centre": (3, "A peak at row i, column j gives x = -1 + 2 j / (W - 1), y = -1 + 2 i / (H - 1): "
                                                    "x from the column, y from the row, both in [-1, 1] (torch.linspace(-1, 1, n))."),
            "test_uniform_map_gives_the_centre": (1, "A flat map puts equal weight on every pixel: its mean position is (0, 0)."),
            "test_two_equal_peaks_give_their_midpoint": (1, "The keypoint is the EXPECTED position under the softmax (a weighted mean), not the arg-max."),
            "test_matches_numpy_on_random_maps": (2, "p = softmax of each map over its own H*W positions (flatten(2).softmax(-1)); keypoint = sum p * (x, y)."),
            "test_adding_a_constant_changes_nothing": (1, "A softmax over each map's positions ignores a constant added to that map; normalise per map, not across maps."),
            "test_gradients_reach_the_maps": (1, "Use torch ops only (no .item(), numpy or argmax) so gradients flow back into the maps."),
            "test_plugs_into_the_encoder_layer": (1, "spatial_softmax(maps) must work inside SpatialSoftmax: maps (B, K, H, W) from a 1x1 conv."),
        },
    ),
)


def exercise_number(exercise: Exercise) -> str:
    """'<chapter>.<k>': k counts the chapter's exercises in registry order, from 1."""
    same = [e.id for e in EXERCISES if e.chapter == exercise.chapter]
    k = same.index(exercise.id) + 1 if exercise.id in same else 1
    return f"{exercise.chapter}.{k}"


def get_exercise(exercise_id: str) -> Exercise:
    """The registered exercise called ``exercise_id`` (ValueError listing the known ids)."""
    for exercise in EXERCISES:
        if exercise.id == exercise_id:
            return exercise
    known = ", ".join(e.id for e in EXERCISES)
    raise ValueError(f"unknown exercise {exercise_id!r}; registered exercises: {known}")


def _check_unique() -> None:
    ids = [e.id for e in EXERCISES]
    duplicates = sorted({i for i in ids if ids.count(i) > 1})
    if duplicates:
        raise ValueError(f"duplicate exercise ids in the registry: {duplicates}")


_check_unique()


# ------------------------------------------------------------------------------ the course on disk
def _looks_like_root(path: Path) -> bool:
    return (path / "coursekit" / "grading").is_dir() and (path / "pyproject.toml").is_file()


def repo_root() -> Path:
    """The course repository: $COURSEKIT_ROOT, else the checkout holding this package, else cwd or a parent."""
    env = os.environ.get(ROOT_ENV)
    if env:
        root = Path(env).expanduser().resolve()
        if not _looks_like_root(root):
            raise FileNotFoundError(f"{ROOT_ENV}={env!r} is not a coursekit checkout (no pyproject.toml and coursekit/grading/)")
        return root
    package_parent = Path(__file__).resolve().parents[2]  # coursekit/grading/exercises.py -> repo
    candidates = [package_parent, Path.cwd(), *Path.cwd().parents]
    for candidate in candidates:
        if _looks_like_root(candidate):
            return candidate
    raise FileNotFoundError(
        "could not find the coursekit repository (a folder with pyproject.toml and coursekit/grading/); "
        f"set {ROOT_ENV}=/path/to/the/clone"
    )


def exercise_dir(directory: str | os.PathLike | None = None) -> Path:
    """The folder holding the student's modules.

    ``directory`` if given; else $COURSEKIT_EXERCISES: "exercises" (or unset) -> <root>/exercises,
    "solutions" -> <root>/solutions, anything else is taken as a path.
    """
    if directory is None:
        choice = os.environ.get(FOLDER_ENV, "").strip() or "exercises"
        directory = repo_root() / choice if choice in ("exercises", "solutions") else Path(choice)
    path = Path(directory).expanduser()
    if not path.is_dir():
        raise FileNotFoundError(f"exercise folder {str(path)!r} does not exist (run `coursekit exercises build`?)")
    return path.resolve()


def read_test_sources(exercises: list[Exercise], root: Path | None = None) -> dict[str, bytes]:
    """The graded test files (and their conftest) as bytes, read once at the start of a grading run."""
    root = Path(root) if root is not None else repo_root()
    folder = root / "tests" / "exercises"
    sources = {"conftest.py": (folder / "conftest.py").read_bytes()}
    for exercise in exercises:
        path = root / exercise.test_module
        if not path.is_file():
            raise FileNotFoundError(f"graded tests of exercise {exercise.id!r} not found at {path}")
        sources[path.name] = path.read_bytes()
    return sources


def load_exercise(exercise_id: str, directory: str | os.PathLike | None = None) -> ModuleType:
    """Import ``<folder>/<exercise_id>.py`` afresh and return it.

    The folder is ``directory`` if given, else chosen by $COURSEKIT_EXERCISES ("exercises",
    the default, "solutions", or a path; see :func:`exercise_dir`).
    Every call re-executes the file, so edits show up without restarting the notebook kernel.
    Notebooks pass the functions/classes of the returned module explicitly into the library.
    """
    exercise = get_exercise(exercise_id)
    folder = exercise_dir(directory)
    path = folder / f"{exercise.id}.py"
    if not path.is_file():
        raise FileNotFoundError(f"{path} not found: expected the module for exercise {exercise.id!r} there")
    # a readable, folder-specific name: tracebacks say e.g. "exercises_chunk_windows"
    tag = "".join(c if c.isalnum() else "_" for c in folder.name) or "student"
    name = f"{tag}_{exercise.id}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise FileNotFoundError(f"cannot import {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses and pickling look classes up by module name
    try:
        spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(name, None)
        raise
    return module
