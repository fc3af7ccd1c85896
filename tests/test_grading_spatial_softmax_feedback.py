"""Exercise 12.1 (spatial_softmax): a submission with one typical mistake (x and y swapped, coordinates
in pixels, the softmax over the K maps instead of each map's positions) fails exactly the tests that
see that quantity, and every failing test's message names the mistake; the other tests still pass."""

from __future__ import annotations

import pytest

import coursekit
from coursekit.grading.exercises import repo_root

pytestmark = pytest.mark.slow  # one grading worker (imports torch) per submission

VALUE_TESTS = ("test_peak_gives_its_pixel_centre", "test_two_equal_peaks_give_their_midpoint",
               "test_matches_numpy_on_random_maps", "test_gradients_reach_the_maps", "test_plugs_into_the_encoder_layer")
GRID_X = "torch.linspace(-1, 1, W, device"
GRID_Y = "torch.linspace(-1, 1, H, device"
# mistake -> ({the solution's text: its wrong version}, the failing tests, words every failure message holds)
MISTAKES = {
    "x and y swapped": (
        {"torch.stack([xs.reshape(-1), ys.reshape(-1)], dim=-1)": "torch.stack([ys.reshape(-1), xs.reshape(-1)], dim=-1)"},
        VALUE_TESTS, "x and y are swapped"),
    "coordinates in pixels": (
        {GRID_X: "torch.linspace(0, W - 1, W, device", GRID_Y: "torch.linspace(0, H - 1, H, device"},
        (*VALUE_TESTS, "test_uniform_map_gives_the_centre"), "pixels instead of [-1, 1]"),
    "softmax over the K maps": (
        {"maps.flatten(2).softmax(dim=-1)": "maps.flatten(2).softmax(dim=1)"},
        (*VALUE_TESTS, "test_adding_a_constant_changes_nothing"),
        "softmax taken over the wrong axis (over the K maps): each of the K maps must sum to 1 over its own H*W positions"),
}


@pytest.mark.parametrize("mistake", sorted(MISTAKES))
def test_a_wrong_submission_gets_feedback_naming_the_mistake(tmp_path, mistake):
    edits, failing, words = MISTAKES[mistake]
    source = (repo_root() / "solutions" / "spatial_softmax.py").read_text()
    for right, wrong in edits.items():
        assert source.count(right) == 1, f"the solution no longer holds {right!r}: update this test"
        source = source.replace(right, wrong)
    (tmp_path / "spatial_softmax.py").write_text(source)
    result = coursekit.check("spatial_softmax", tmp_path, show=False)
    failed = {s.name: s for s in result.scores if not s.passed}
    assert sorted(failed) == sorted(failing), {n: s.message for n, s in failed.items()}
    for name, score in failed.items():
        assert score.kind == "value" and score.hint, (name, score.kind, score.hint)
        assert words in score.message, (name, score.message)
    assert 0 < result.points < result.max_points
