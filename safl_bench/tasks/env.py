"""The streaming environment: one query top-view map per step, answered with a database index.

After `import safl_bench`, `gymnasium.make("SAFL/Synth00-T5R1.5-v4")` returns it (KITTI tasks
take `kitti_root=...` as a make keyword, or $SAFL_KITTI_ROOT, and top-view image tasks `bev_root=...`
or $SAFL_BEV_ROOT, their rotated tasks also `bev_rot_root=...` or $SAFL_BEV_ROT_ROOT;
`progress=False` silences the
progress bars of a first run, which generates the synthetic data and renders the maps).

- observation: the current query map, Box(0, 1, (H, W), float32).
- action: Discrete(Ndb + 1): a database index, or Ndb (= `env.unwrapped.no_match`) for "no match".
- reward: +1 for a true positive, -1 for a false positive (including a database frame the query
  may not match, e.g. one inside the revisit time window), 0 for an answer in the excluded band
  and 0 for "no match" (misses are counted by recall in the batch metrics, not here); 0 for
  any answer to one of the task's context queries (`TaskSpec.context_queries`: the first ten of
  the paper and BEVPlace tasks, shown so that a sequence matcher has their rows, never scored).
- `reset()` info: `database` (Ndb, H, W) maps, `database_positions` (Ndb, 2) m,
  `database_times` (Ndb,) s, plus the per-query keys below for query 0. The same arrays are
  attributes of `env.unwrapped` (`database`, `task`).
- per-query info keys (for the query the returned observation shows): `query_index`,
  `query_time`, `candidates` (Ndb,) bool, the database frames it may match.
- `step()` info also carries the ground truth of the query just answered: `answered_index`,
  `label` ("tp", "fp", "excluded", "no_match"), `distance_m` of the answered match (nan for no
  match), `true_matches` (database indices within the true-positive radius among its
  candidates), `true_positions` (their positions), `answered_position` (the query's position),
  `scored` (False for a context query: its label is the truth, its reward 0).
- the episode terminates after the last query; the final observation repeats the last query.
- observations and infos are fresh copies (Gymnasium's rule: callers keep what they get);
  `env.unwrapped.database` is the read-only original, for agents that want no copy.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from safl_bench.errors import ConfigError
from safl_bench.evaluation.groundtruth import EXCLUDED, TP
from safl_bench.tasks.task import Task

LABELS = {TP: "tp", EXCLUDED: "excluded", -1: "fp"}


class TaskEnv(gymnasium.Env):
    """A benchmark task as a Gymnasium environment (see the module doc for the protocol)."""

    metadata = {"render_modes": []}  # noqa: RUF012 (Gymnasium declares it an instance attribute)

    def __init__(
        self,
        task_id: str | None = None,
        *,
        task: Task | None = None,
        kitti_root: str | None = None,
        bev_root: str | None = None,
        progress: bool = True,
        bev_rot_root: str | None = None,
    ) -> None:
        if task is None:
            if task_id is None:
                raise ConfigError("TaskEnv needs a task id or a Task")
            from safl_bench.tasks.task import make

            task = make(task_id, kitti_root=kitti_root, bev_root=bev_root, progress=progress,
                        bev_rot_root=bev_rot_root)
        self.task = task
        # private read-only copies: `info["database"]` is shared with the agent, not copied per reset
        self.database = np.array(task.database("topview"), dtype=np.float32)
        self.queries = np.array(task.queries("topview"), dtype=np.float32)
        self.database.flags.writeable = False
        self.queries.flags.writeable = False
        if self.database.ndim != 3 or self.queries.shape[1:] != self.database.shape[1:]:
            raise ConfigError(f"task {task.id}: top views must be (F, H, W) of one shape")
        if len(self.queries) == 0 or len(self.database) == 0:
            raise ConfigError(f"task {task.id} has no queries or no database frames")
        self.n_database = len(self.database)
        self.no_match = self.n_database
        height, width = self.database.shape[1:]
        self.observation_space = spaces.Box(0.0, 1.0, (height, width), np.float32)
        self.action_space = spaces.Discrete(self.n_database + 1)
        self._candidates = task.truth.candidate_mask()
        self._t = 0

    def _query_info(self, t: int) -> dict[str, Any]:
        return {
            "query_index": t,
            "query_time": float(self.task.query_times[t]),
            "candidates": self._candidates[t].copy(),
        }

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start at the first query; info holds the database (see the module doc)."""
        super().reset(seed=seed)
        self._t = 0
        info = {
            "database": self.database.copy(),
            "database_positions": self.task.database_positions.copy(),
            "database_times": self.task.database_times.copy(),
            **self._query_info(0),
        }
        return self.queries[0].copy(), info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Answer the current query; get the next one and the ground truth of this answer."""
        if self._t >= len(self.queries):
            raise ConfigError("the episode is over; call reset()")
        answer = int(action)
        if not 0 <= answer <= self.no_match:
            raise ConfigError(
                f"action must be a database index 0..{self.n_database - 1} or {self.no_match} (no match), got {action!r}"
            )
        t = self._t
        truth = self.task.truth
        if answer == self.no_match:
            label, reward, distance = "no_match", 0.0, float("nan")
        else:
            code = int(truth.label_of(t, answer))
            label, reward = LABELS[code], float(code)
            distance = float(truth.distances(t, answer))
        scored = t >= self.task.spec.context_queries
        if not scored:
            reward = 0.0
        true = truth.true_matches(t)
        info: dict[str, Any] = {
            "scored": scored,
            "answered_index": t,
            "label": label,
            "distance_m": distance,
            "true_matches": true.copy(),
            "true_positions": self.task.database_positions[true],
            "answered_position": self.task.query_positions[t],
        }
        self._t += 1
        terminated = self._t >= len(self.queries)
        shown = min(self._t, len(self.queries) - 1)
        info.update(self._query_info(shown))
        return self.queries[shown].copy(), reward, terminated, False, info
