"""The streaming Gymnasium environment: API conformance, rewards and ground truth in `info`, and
an agent (descriptor + shared matcher) that answers exactly as the batch evaluation."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from test_groundtruth import loop_twice

import safl_bench  # noqa: F401  (registers the tasks with Gymnasium)
from safl_bench import tasks
from safl_bench.errors import ConfigError
from safl_bench.mapconfig import MapConfig
from safl_bench.matching import MatcherConfig, seqslam
from safl_bench.tasks import TaskSpec
from safl_bench.tasks.agent import MatcherAgent
from safl_bench.tasks.env import TaskEnv
from safl_bench.tasks.task import Task

REVISIT = TaskSpec(
    id="Test/Loop-Revisit-v0",
    source="synth",
    sequence="00",
    protocol="revisit",
    step=1,
    tp_radius_m=3.0,
    fp_radius_m=20.0,
    window_s=5.0,
)


def place_maps(positions: np.ndarray, seed: int = 0) -> np.ndarray:
    """(n, 8, 8) maps in [0, 1] that depend on the place only (plus a little noise)."""
    rng = np.random.default_rng(seed)
    u, v = np.meshgrid(np.arange(8), np.arange(8), indexing="ij")
    x, y = positions[:, 0, None, None], positions[:, 1, None, None]
    maps = 0.5 + 0.45 * np.sin(0.37 * x * (u + 1) / 8 + 0.23 * y * (v + 1) / 8 + u * v)
    return np.clip(maps + rng.normal(0, 0.02, maps.shape), 0, 1).astype(np.float32)


class FlatDescriptor:
    """The simplest descriptor: the map itself, squared Euclidean distance."""

    def describe(self, maps: np.ndarray) -> np.ndarray:
        return np.asarray(maps, dtype=np.float32).reshape(len(maps), -1)

    def distance(self, queries: np.ndarray, database: np.ndarray) -> np.ndarray:
        return ((queries[:, None, :] - database[None, :, :]) ** 2).sum(-1)


@pytest.fixture(scope="module")
def loop_task() -> Task:
    pos = loop_twice()
    times = np.arange(len(pos)) / 10.0
    maps = place_maps(pos)
    return Task.from_arrays(REVISIT, positions=pos, times=times, database=maps, queries=maps)


@pytest.fixture
def tiny_id(kitti_root: Path, safl_home: Path) -> Iterator[str]:
    spec = tasks.register(
        "Test/TinyEnv-T1R1-v0",
        source="kitti",
        sequence="00",
        condition="T1R1",
        step=1,
        map_config=MapConfig(size=32),
    )
    yield spec.id
    tasks.unregister(spec.id)


def test_gymnasium_make_gives_a_conforming_env(tiny_id: str, kitti_root: Path) -> None:
    env = gymnasium.make(tiny_id, kitti_root=str(kitti_root))
    check_env(env.unwrapped, skip_render_check=True)
    obs, info = env.reset(seed=0)
    assert env.observation_space == gymnasium.spaces.Box(0, 1, (32, 32), np.float32)
    assert env.action_space == gymnasium.spaces.Discrete(13)
    assert obs.shape == (32, 32) and obs.dtype == np.float32
    assert info["database"].shape == (12, 32, 32) and info["database_positions"].shape == (12, 2)
    assert info["query_index"] == 0 and info["candidates"].all()


def test_revisit_env_passes_the_checker(loop_task: Task) -> None:
    check_env(TaskEnv(task=loop_task), skip_render_check=True)


def test_rewards_and_ground_truth_in_info(loop_task: Task) -> None:
    env = TaskEnv(task=loop_task)
    obs, info = env.reset()
    np.testing.assert_array_equal(obs, loop_task.queries()[0])
    assert env.no_match == 320 and not info["candidates"].any()  # nothing is 5 s older yet
    for _ in range(200):  # walk to query 200: (0, 40), where frame 120 stood 8 s earlier
        obs, reward, done, _, info = env.step(env.no_match)
        assert reward == 0.0 and info["label"] == "no_match" and not done
    assert info["query_index"] == 200 and info["candidates"].sum() == 150
    _, reward, _, _, info = env.step(120)
    assert (reward, info["label"], info["answered_index"]) == (1.0, "tp", 200)
    assert info["distance_m"] == pytest.approx(0.0, abs=1e-9)
    assert 120 in info["true_matches"] and np.allclose(info["answered_position"], [0, 40])
    # lap 2 then runs along y = 40 towards x = 40: query 200 + k stands at (k, 40)
    _, reward, _, _, info = env.step(95)  # query 201; frame 95 at (25, 40): FP
    assert (reward, info["label"]) == (-1.0, "fp") and info["distance_m"] == pytest.approx(24.0)
    _, reward, _, _, info = env.step(116)  # query 202; frame 116 at (4, 40): TP
    assert (reward, info["label"]) == (1.0, "tp")
    _, reward, _, _, info = env.step(112)  # query 203; frame 112 at (8, 40): in the band
    assert (reward, info["label"]) == (0.0, "excluded")
    _, reward, _, _, info = env.step(204)  # query 204 itself: same place, not a candidate
    assert (reward, info["label"]) == (-1.0, "fp") and info["distance_m"] == 0.0
    with pytest.raises(ConfigError, match="action"):
        env.step(321)
    for _ in range(205, 320):
        _, _, done, _, _ = env.step(env.no_match)
    assert done
    with pytest.raises(ConfigError, match="reset"):
        env.step(0)


def run_agent(env: gymnasium.Env, agent: MatcherAgent) -> tuple[list[int], float]:
    obs, info = env.reset(seed=0)
    agent.reset(info)
    answers, total = [], 0.0
    done = False
    while not done:
        action = agent.act(obs, info)
        answers.append(action)
        obs, reward, done, _, info = env.step(action)
        total += float(reward)
    return answers, total


def batch_matches(task: Task, method: FlatDescriptor, config: MatcherConfig) -> np.ndarray:
    d = method.distance(method.describe(task.queries()), method.describe(task.database()))
    return seqslam(d, ds=config.ds, db_limit=task.truth.db_limit()).index


def test_streaming_agent_matches_the_batch_evaluation_revisit() -> None:
    """A 10 m square driven twice forwards (40 frames a lap), 2 s window (20 frames)."""
    k = np.arange(80.0)
    side, t = (k % 40) // 10, k % 10
    pos = np.stack(
        [
            np.select([side == 0, side == 1, side == 2], [t, 10 + 0 * t, 10 - t], 0 * t),
            np.select([side == 0, side == 1, side == 2], [0 * t, t, 10 + 0 * t], 10 - t),
        ],
        1,
    )
    spec = TaskSpec(
        id="Test/Small-Revisit-v0",
        source="synth",
        sequence="00",
        protocol="revisit",
        step=1,
        tp_radius_m=3.0,
        fp_radius_m=20.0,
        window_s=2.0,
    )
    maps = place_maps(pos)
    task = Task.from_arrays(spec, positions=pos, times=k / 10, database=maps, queries=maps)
    method, config = FlatDescriptor(), MatcherConfig(ds=5)
    batch = batch_matches(task, method, config)
    answers, total = run_agent(TaskEnv(task=task), MatcherAgent(method, config))
    no_match = len(task.database_frames)
    assert answers == [no_match if j < 0 else int(j) for j in batch]
    answered = batch >= 0
    labels = task.truth.label_of(np.flatnonzero(answered), batch[answered])
    assert total == float(labels.sum())
    # the descriptor finds the second lap's places in the first lap (once its look-back
    # trajectory no longer straddles the start of the lap)
    lap2 = labels[answered[:40].sum() :]
    assert answered[40:].all() and (lap2 != -1).all() and (lap2[5:] == 1).all()


def test_streaming_agent_matches_the_batch_evaluation_paper(tiny_id: str, kitti_root: Path) -> None:
    env = gymnasium.make(tiny_id, kitti_root=str(kitti_root))
    task = env.unwrapped.task
    method, config = FlatDescriptor(), MatcherConfig(ds=3)
    batch = batch_matches(task, method, config)
    answers, total = run_agent(env, MatcherAgent(method, config))
    assert answers == batch.tolist()
    assert total == float(task.truth.labels(batch).sum())


def test_agent_refuses_a_centred_trajectory() -> None:
    with pytest.raises(ConfigError, match="causal"):
        MatcherAgent(FlatDescriptor(), MatcherConfig(trajectory="centred"))


def test_context_queries_are_shown_but_not_rewarded(loop_task: Task) -> None:
    """A task whose first queries are context: the same observations and labels, reward 0 and
    `scored` False for them, the usual reward after."""
    spec = TaskSpec(id="Test/Loop-T0R0-v1", source="synth", sequence="00", step=1,
                    context_queries=10)
    pos, maps = loop_task.query_positions, loop_task.queries()
    task = Task.from_arrays(spec, positions=pos, times=np.arange(len(pos)) / 10.0,
                            database=maps, queries=maps)
    env = TaskEnv(task=task)
    env.reset()
    for t in range(12):
        _, reward, _, _, info = env.step(t)  # its own frame: a true positive
        assert info["label"] == "tp" and info["scored"] == (t >= 10)
        assert reward == (1.0 if t >= 10 else 0.0)
