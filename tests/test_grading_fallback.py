"""exercise_or_reference: the student's objects where written, the library's where still a stub."""

from __future__ import annotations

import re

import pytest

import coursekit.grading
from coursekit.grading import EXERCISES, exercise_or_reference
from coursekit.grading.exercises import repo_root
from coursekit.grading.notebook import BANNER_PREFIX, is_stub


@pytest.mark.parametrize("exercise", EXERCISES, ids=[e.id for e in EXERCISES])
def test_stubs_fall_back_and_solutions_are_used(exercise):
    """Every object of every generated stub is detected; every solution object is used as is."""
    import importlib

    reference = importlib.import_module(exercise.source)
    stub = exercise_or_reference(exercise.id, repo_root() / "exercises", show=False)
    assert stub.missing == exercise.objects and not stub.implemented
    for name in exercise.objects:
        assert getattr(stub, name) is getattr(reference, name)
        assert is_stub(getattr(stub.module, name), exercise)
    solved = exercise_or_reference(exercise.id, repo_root() / "solutions", show=False)
    assert solved.implemented and solved.missing == ()
    for name in exercise.objects:
        assert getattr(solved, name) is getattr(solved.module, name)
        assert getattr(solved, name) is not getattr(reference, name)


def test_half_finished_exercise_mixes_and_banner_names_the_rest(tmp_path, capsys):
    text = (repo_root() / "exercises" / "noise_loss.py").read_text()
    solved = (repo_root() / "solutions" / "noise_loss.py").read_text()
    # take q_sample from the solution, leave epsilon_loss a stub
    q_solved = re.search(r"def q_sample\(.*?\n(?=\n\ndef )", solved, re.S).group(0)
    q_stub = re.search(r"def q_sample\(.*?\n(?=\n\ndef )", text, re.S).group(0)
    (tmp_path / "noise_loss.py").write_text(text.replace(q_stub, q_solved))
    parts = exercise_or_reference("noise_loss", tmp_path)
    from coursekit.diffusion import loss as reference

    assert parts.missing == ("epsilon_loss",)
    assert parts.q_sample is parts.module.q_sample and parts.q_sample is not reference.q_sample
    assert parts.epsilon_loss is reference.epsilon_loss
    out = capsys.readouterr().out
    assert "exercise 2.1 (noise_loss) " + BANNER_PREFIX in out and "epsilon_loss" in out
    assert 'coursekit.check("noise_loss")' in out and "q_sample," not in out
    # the same call, once the file is finished, says so and uses the student's code
    (tmp_path / "noise_loss.py").write_text(solved)
    parts = exercise_or_reference("noise_loss", tmp_path)
    assert parts.implemented and "using your q_sample, epsilon_loss" in capsys.readouterr().out
    assert parts.__file__ == str(tmp_path / "noise_loss.py")


def test_written_but_wrong_code_is_used_as_written(tmp_path):
    (tmp_path / "kl.py").write_text("def gaussian_kl(mu, logvar):\n    raise ValueError('my bug')\n")
    parts = exercise_or_reference("kl", tmp_path, show=False)
    assert parts.implemented
    with pytest.raises(ValueError, match="my bug"):
        parts.gaussian_kl(None, None)


def test_clear_errors(tmp_path):
    (tmp_path / "film.py").write_text("class Film:\n    pass\n")
    with pytest.raises(AttributeError, match="defines no 'FiLM'"):
        exercise_or_reference("film", tmp_path, show=False)
    parts = exercise_or_reference("kl", repo_root() / "solutions", show=False)
    with pytest.raises(AttributeError, match="has no object 'nope'"):
        parts.nope  # noqa: B018
    assert "exercise_or_reference" in coursekit.grading.__all__


def test_banner_html_for_notebooks():
    parts = exercise_or_reference("film", repo_root() / "exercises", show=False)
    assert BANNER_PREFIX in parts._repr_html_() and repr(parts).startswith("⚠")
