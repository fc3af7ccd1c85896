"""The task records: one home per task fact, and a new task added by registering ONE record.

The new task is a 1-D reach defined here (its env, its expert, its record): registering the
record is all it takes for `coursekit collect`, `train` and `eval`, the gymnasium id and the
delay model to run on it; no other module is touched.
"""

from __future__ import annotations

import ast
import json
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from gymnasium import spaces

from coursekit.cli import main
from coursekit.policies import POLICY_TYPES
from coursekit.tasks import INSERTION, PUSHT, TASKS, TRANSFER_CUBE, Task, get_task, register_task, unregister_task

ROOT = Path(__file__).resolve().parent.parent

SPEED = 0.1
"""Largest move of the reacher per step."""


class Reach1D(gymnasium.Env):
    """A point on a line moves toward the commanded position (at most SPEED per step) to reach a target.

    Observation (2,) [position, target]; action (1,) commanded position in [-1, 1]; reward
    1 - |position - target| / 2; success (and termination) within 0.02 of the target.
    """

    metadata = {"render_modes": [], "render_fps": 20}

    def __init__(self, max_episode_steps: int = 40) -> None:
        self.max_episode_steps = max_episode_steps
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float64)
        self.observation_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float64)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.pos, self.target = self.np_random.uniform(-1.0, 1.0, size=2)
        self.t = 0
        return self.get_state(), {}

    def step(self, action):
        move = float(np.clip(np.asarray(action, dtype=np.float64).reshape(-1)[0], -1, 1)) - self.pos
        self.pos += float(np.clip(move, -SPEED, SPEED))
        self.t += 1
        gap = abs(self.pos - self.target)
        success = gap < 0.02
        return self.get_state(), 1.0 - gap / 2.0, success, self.t >= self.max_episode_steps, {"is_success": success}

    def get_state(self) -> np.ndarray:
        return np.array([self.pos, self.target])


def reach_expert(n_episodes: int, seed: int, progress: bool = True):
    """Demonstrations that command the target itself: episode i from reset seed ``seed + i``."""
    from coursekit.data import EpisodeDataset

    episodes = []
    for i in range(n_episodes):
        env = Reach1D()
        obs, _ = env.reset(seed=seed + i)
        states, actions, done = [], [], False
        while not done:
            action = np.array([env.target])
            states.append(obs)
            actions.append(action)
            obs, _, terminated, truncated, _ = env.step(action)
            done = terminated or truncated
        episodes.append({"state": np.array(states), "action": np.array(actions)})
    return EpisodeDataset.from_episodes(episodes, {"task": "reach1d", "env_id": REACH.gym_id, "seed": seed,
                                                   "n_episodes": n_episodes})


REACH = Task(name="reach1d", aliases=("reach",), gym_id="coursekit-test/Reach1D-v0", env=Reach1D, control_hz=20.0,
             max_steps=30, features="raw_state", expert=reach_expert, demo_episodes=3)


@pytest.fixture
def reach():
    register_task(REACH)
    try:
        yield REACH
    finally:
        unregister_task(REACH.name)


def test_the_course_tasks_and_their_facts():
    assert list(TASKS) == ["pusht", "transfer_cube", "insertion"]
    assert get_task("aloha-cube") is TRANSFER_CUBE and get_task("aloha-insertion") is INSERTION
    assert (PUSHT.control_hz, PUSHT.max_steps, TRANSFER_CUBE.control_hz, TRANSFER_CUBE.max_steps) == (10.0, 300, 50.0, 400)
    with pytest.raises(ValueError, match=r"unknown task 'cube'; expected one of \['aloha-cube'"):
        get_task("cube")
    for task in TASKS.values():  # each env runs at its record's rate, truncates at its record's length
        env = gymnasium.make(task.gym_id).unwrapped
        assert env.metadata["render_fps"] == task.control_hz and env.max_episode_steps == task.max_steps
        env.close()


def test_the_envs_step_at_their_records_rate():
    """The physics behind one control step lasts exactly 1 / control_hz seconds."""
    from coursekit.envs.aloha import AlohaTransferCubeEnv
    from coursekit.envs.pusht import PushTEnv

    pusht = PushTEnv()
    assert pusht.n_substeps * pusht.dt == pytest.approx(1.0 / PUSHT.control_hz)
    arm = AlohaTransferCubeEnv()
    arm.reset(seed=0)
    t0 = arm.data.time
    arm.step(arm.index.qpos14(arm.data))
    assert arm.data.time - t0 == pytest.approx(1.0 / TRANSFER_CUBE.control_hz)
    arm.close()


def test_a_bad_record_is_refused_naming_the_value():
    with pytest.raises(ValueError, match="control_hz must be a positive finite number, got 0"):
        Task(name="x", gym_id="x/X-v0", env=Reach1D, control_hz=0, max_steps=10, features="raw_state")
    with pytest.raises(ValueError, match="max_steps must be an int >= 1, got 2.5"):
        Task(name="x", gym_id="x/X-v0", env=Reach1D, control_hz=5.0, max_steps=2.5, features="raw_state")
    with pytest.raises(ValueError, match="'module:Class' entry point, got 'nowhere'"):
        Task(name="x", gym_id="x/X-v0", env="nowhere", control_hz=5.0, max_steps=10, features="raw_state")
    with pytest.raises(ValueError, match=r"task name\(s\) \['pusht'\] are already registered"):
        register_task(Task(name="pusht", gym_id="x/X-v0", env=Reach1D, control_hz=5.0, max_steps=10,
                           features="raw_state"))
    assert list(TASKS) == ["pusht", "transfer_cube", "insertion"]


def test_registering_a_task_registers_its_gym_id(reach):
    assert get_task("reach") is reach and reach.gym_id in gymnasium.registry
    env = gymnasium.make(reach.gym_id).unwrapped
    assert isinstance(env, Reach1D)
    with pytest.raises(ValueError, match="already registered"):
        register_task(REACH)
    from coursekit.evaluate.latency import latency_delay

    assert latency_delay(120.0, "reach1d") == 3  # ceil(0.120 s x 20 Hz - 1e-9): the record's control rate
    assert latency_delay(120.0, "pusht") == 2 and latency_delay(120.0, "transfer_cube") == 6


def test_unregistering_removes_the_task_and_its_gym_id():
    register_task(REACH)
    unregister_task("reach")
    assert "reach1d" not in TASKS and REACH.gym_id not in gymnasium.registry
    with pytest.raises(ValueError, match="unknown task 'reach1d'"):
        get_task("reach1d")


@pytest.mark.parametrize("policy", sorted(POLICY_TYPES))
def test_collect_train_and_eval_run_on_a_registered_task(policy, reach, tmp_path, train_then_eval, capsys):
    data = tmp_path / "reach.npz"
    assert main(["collect", "reach", "--episodes", "3", "--out", str(data), "--no-progress"]) == 0
    info, summary = train_then_eval(policy, data, tmp_path, max_steps=6)
    assert info["config"]["features"] == "raw_state" and info["dataset"]["task"] == "reach1d"
    assert summary["task"] == "reach1d" and summary["max_steps"] == 6 and 0.0 < summary["score"] <= 1.0
    assert main(["eval", str(tmp_path / "run"), "--episodes", "1", "--no-progress", "--json",
                 str(tmp_path / "full.json")]) == 0
    assert json.loads((tmp_path / "full.json").read_text())["max_steps"] == reach.max_steps  # the record's protocol
    assert main(["eval", str(tmp_path / "run"), "--episodes", "1", "--no-progress",  # no replay drawing: refused first
                 "--record", str(tmp_path / "replay")]) == 2
    assert "task 'reach1d' has no replay drawing" in capsys.readouterr().err and not (tmp_path / "replay").exists()


def _code_strings(path: Path) -> list[str]:
    """The string constants of a module's code (docstrings and other bare string statements left out)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    prose = {id(n.value) for n in ast.walk(tree) if isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant)}
    return [n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str)
            and id(n) not in prose]


def test_each_task_name_and_gym_id_is_written_once():
    """Every gym id, alias and arm-pair task name is spelt in the library's code exactly once: in its record.
    ('pusht' also names PushT's world in the feature table and its replay viewer.)"""
    strings = {p: _code_strings(p) for p in (ROOT / "coursekit").rglob("*.py")}
    for task in TASKS.values():
        for fact in (task.gym_id, *task.aliases, *([task.name] if task.name != "pusht" else [])):
            where = [str(p.relative_to(ROOT)) for p, found in strings.items() if fact in found]
            assert len(where) == 1 and where[0].startswith("coursekit/tasks/"), (fact, where)
