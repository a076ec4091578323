"""`MatcherAgent`: a streaming agent from a descriptor method and the shared matcher.

It is the batch evaluation run online: at step T it has seen queries 0..T only, and the shared
matcher's trajectory for query T looks back over queries T-ds..T (causal), so the answers equal
the batch matcher's `index` on the whole difference matrix with the same `db_limit`:

    env = gymnasium.make("SAFL/Synth00-T1R1-v4")
    agent = MatcherAgent(method)              # anything with describe() and distance()
    obs, info = env.reset(); agent.reset(info)
    while True:
        obs, reward, done, _, info = env.step(agent.act(obs, info))
        if done: break

Only the matcher's score differs from the batch one: the matcher shifts the enhanced matrix by
its minimum, which online is the minimum of the rows seen so far, so scores are not comparable
with batch scores (matches are).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from safl_bench.errors import ConfigError
from safl_bench.matching.matcher import MatcherConfig, match


class Descriptor(Protocol):
    """What the agent needs of a method (`safl_bench.methods.method.Method` has both)."""

    def describe(self, maps: Any) -> np.ndarray: ...

    def distance(self, queries: np.ndarray, database: np.ndarray) -> np.ndarray: ...


class MatcherAgent:
    """Answers each query with the shared matcher's match, or "no match" when it has none."""

    def __init__(self, method: Descriptor, config: MatcherConfig | None = None) -> None:
        self.method = method
        self.config = config or MatcherConfig()
        if self.config.u_range()[1] > 0:
            raise ConfigError("a streaming agent needs the causal trajectory (trajectory='causal')")
        self._database: np.ndarray | None = None
        self._rows: list[np.ndarray] = []
        self._limits: list[int] = []
        self.no_match = -1
        self.last_score = float("inf")

    def _input(self, maps: np.ndarray) -> Any:
        """Maps at the method's input size (`method_input`) when it is a `Method`."""
        from safl_bench.methods.method import Method, method_input

        return method_input(self.method, maps) if isinstance(self.method, Method) else maps

    def reset(self, info: dict[str, Any]) -> None:
        """Describe the database given by `env.reset()`'s info."""
        database = info["database"]
        self._database = self.method.describe(self._input(database))
        self.no_match = len(database)
        self._rows, self._limits = [], []

    def act(self, observation: np.ndarray, info: dict[str, Any]) -> int:
        """The database index matched to `observation`, or `no_match` (Ndb)."""
        if self._database is None:
            raise RuntimeError("call reset(info) with the environment's reset info first")
        query = self.method.describe(self._input(observation[None]))
        self._rows.append(np.asarray(self.method.distance(query, self._database))[0])
        candidates = np.asarray(info["candidates"], dtype=bool)
        self._limits.append(int(candidates.sum()))  # candidates are a prefix (time order)
        # query T's trajectory uses rows T - ds .. T only: keep just those
        span = -self.config.u_range()[0] + 1
        self._rows, self._limits = self._rows[-span:], self._limits[-span:]
        result = match(
            np.stack(self._rows), self.config, db_limit=np.array(self._limits, dtype=np.int64)
        )
        index = int(result.index[-1])
        self.last_score = float(result.score[-1])
        return self.no_match if index < 0 else index
