"""Exercise 11.2 (rtc_step): a submission with one deliberate mistake (wrong soft weights, the wrong
sign in the guidance or in the update) fails exactly the tests of that quantity, and its feedback
(the registry's hint and the test's message) names the mistake; every other test still passes."""

from __future__ import annotations

import pytest

import coursekit
from coursekit.grading.exercises import repo_root

pytestmark = pytest.mark.slow  # one grading worker (imports torch) per submission

VJP_TESTS = ("test_vjp_is_jacobian_transpose_times_weighted_error", "test_vjp_weights_each_step_of_the_error",
             "test_vjp_pulls_toward_the_previous_chunk")
# mistake -> (the solution's line, its wrong version, {failing test: (words in its hint, words in its message)})
MISTAKES = {
    "constant soft weights": (
        "w[soft] = c * np.expm1(c) / (math.e - 1.0)", "w[soft] = 0.5",
        {"test_soft_weights_decay_exponentially": ("decays", "yours is constant")}),
    "error with the wrong sign": (
        "err = (target - x0_hat.detach())", "err = (x0_hat.detach() - target)",
        {"test_vjp_is_jacobian_transpose_times_weighted_error": ("J^T e", "g has the wrong sign"),
         "test_vjp_weights_each_step_of_the_error": ("Weight the ERROR", "g has the wrong sign"),
         "test_vjp_pulls_toward_the_previous_chunk": ("wrong sign", "pushes x0_hat away from the previous chunk")}),
    "update with the wrong sign": (
        "return out - scale * g", "return out + scale * g",
        {"test_update_closed_form": ("out - scale * g", "out' = out - scale * g"),
         "test_update_pulls_toward_the_previous_chunk": ("wrong sign", "moves the iterate against g")}),
}


@pytest.mark.parametrize("mistake", sorted(MISTAKES))
def test_a_wrong_submission_gets_feedback_naming_the_mistake(tmp_path, mistake):
    right, wrong, expected = MISTAKES[mistake]
    source = (repo_root() / "solutions" / "rtc_step.py").read_text()
    assert source.count(right) == 1, f"the solution no longer holds {right!r}: update this test"
    (tmp_path / "rtc_step.py").write_text(source.replace(right, wrong))
    result = coursekit.check("rtc_step", tmp_path, show=False)
    failed = {s.name: s for s in result.scores if not s.passed}
    assert sorted(failed) == sorted(expected), {n: s.message for n, s in failed.items()}
    for name, (hint_words, message_words) in expected.items():
        assert hint_words in failed[name].hint, (name, failed[name].hint)
        assert message_words in failed[name].message, (name, failed[name].message)
    assert 0 < result.points < result.max_points
