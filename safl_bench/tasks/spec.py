"""`TaskSpec`: the frozen definition of one benchmark task (what makes two runs comparable).

A task id follows Gymnasium's `[namespace/]name-v{version}` form, e.g. `SAFL/Synth00-T5R1.5-v4`.
Everything that changes a task's data or its ground truth is a field of the spec and enters its
`fingerprint`, which result records store: a record made under a different definition of the
same id can then be detected. A changed definition gets a new version; old versions stay
registered so that old records stay reproducible.

Tasks on the synthetic default also name the version of the synthetic data they were defined on
(`data_version`, the generator's `GENERATOR_VERSION`): a new generator output is a new definition.
This safl-bench generates one version only, so a task on another one can be looked up (its
records resolve) but not materialised or run (`check_data_version`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

from safl_bench.common.fingerprint import fingerprint, to_jsonable
from safl_bench.errors import ConfigError
from safl_bench.views.mapconfig import MapConfig
from safl_bench.views.noise import CLEAN, Condition

#: Bump when the code that turns a spec into data or ground truth changes meaning; it enters every
#: fingerprint, so records made before the change are told apart from those made after it.
DEFINITION_REVISION = 1

SOURCES = ("synth", "kitti", "bev")

#: The synthetic data version of the definitions that predate the `data_version` field (task
#: version v0 of the synthetic tasks): it is left out of their definition, so their fingerprints
#: stay those their records hold.
FIRST_SYNTH_DATA_VERSION = "1"
PROTOCOLS = ("paper", "revisit", "bevplace")
#: Which views of a top-view task come from the second image folder of its sequence (BEVPlace's
#: KITTIRot: each scan yawed by its own random angle before its image was made): the queries
#: only, or the database and the queries (what BEVPlace's own main.py scores).
ROTATED = ("queries", "both")

#: Noise seeds a cell of a task with noisy queries averages, unless the task says otherwise: five
#: draws bound the spread of a cell (issue #25: one seed of Stable-AFL's T1R1 on real 00 ranges
#: 61-96 % recall at 100 % precision) at five times one seed's query work.
DEFAULT_NOISY_SEEDS = 5

#: Gymnasium's id grammar: `[namespace/]name[-v{version}]`.
ID_RE = re.compile(r"^(?:(?P<namespace>[\w:-]+)/)?(?P<name>[\w:.-]+?)(?:-v(?P<version>\d+))?$")


def parse_id(task_id: str) -> tuple[str | None, str, int | None]:
    """Split a task id into (namespace, name, version); version None when the id has none."""
    match = ID_RE.fullmatch(task_id)
    if not match:
        raise ConfigError(f"malformed task id {task_id!r} (expected e.g. 'SAFL/Synth00-T1R1-v4')")
    version = match.group("version")
    return match.group("namespace"), match.group("name"), None if version is None else int(version)


def current_synth_data_version() -> str:
    """The newest version of the synthetic data this safl-bench generates (`synth.GENERATOR_VERSION`)."""
    from safl_bench.synth.config import GENERATOR_VERSION  # lazy: the generator package is heavy

    return GENERATOR_VERSION


def generated_synth_data_versions() -> tuple[str, ...]:
    """Every version of the synthetic data this safl-bench generates (`synth.GENERATOR_VERSIONS`)."""
    from safl_bench.synth.config import GENERATOR_VERSIONS  # lazy: the generator package is heavy

    return GENERATOR_VERSIONS


def make_id(namespace: str | None, name: str, version: int | None) -> str:
    """Inverse of `parse_id`."""
    full = f"{namespace}/{name}" if namespace else name
    return full if version is None else f"{full}-v{version}"


@dataclass(frozen=True)
class TaskSpec:
    """One benchmark task.

    source: "synth" (the embedded default, world `data_seed`), "kitti" (a KITTI odometry root)
        or "bev" (a folder of top-view images, `safl_bench.sources.bev`).
    sequence: the sequence name, e.g. "00".
    protocol: "paper" (database = clean maps, queries = the same frames re-rendered with
        `condition`; true positive within `tp_radius_m`), "revisit" (one sequence, queries =
        database = clean maps; a query may only match frames older than `window_s`; true positive
        within `tp_radius_m`, false positive beyond `fp_radius_m`, the band between excluded) or
        "bevplace" (BEVPlace's: fixed database and query frame ranges of one sequence, clean
        views, a true place within `tp_radius_m`, scored by Recall@1).
    step: every `step`-th frame (0, step, 2*step, ...) is used as database and query frame.
    database_frames, query_frames: [start, stop) frame ranges of the database and the queries
        (protocol "bevplace" only; every `step`-th frame of each range).
    seed: seed of the viewpoint noise (`safl_bench.views.noise.sample_offsets`): the first of the
        task's noise seeds.
    n_seeds: how many noise seeds a cell of the task averages (`seeds`, from `seed` on); None:
        `DEFAULT_NOISY_SEEDS` where the queries are drawn with noise (the paper protocol under a
        condition other than T0R0), 1 where nothing is random (clean queries: the revisit and
        BEVPlace protocols, T0R0). Not part of the definition: it says how many draws of the
        same task a cell takes, not what the task is.
    data_version: the version of the synthetic data the task is defined on (source "synth" only;
        None there means the version this safl-bench generates, `synth.GENERATOR_VERSION`).
    context_queries: how many of the first queries are context only: described and matched (the
        sequence matcher's trajectories of later queries read their rows) but left out of every
        measure, in both matching modes. The paper and BEVPlace protocols from task versions
        synth v5, kitti v1 and bev v1 on set it to the paper's d_s = 10 (`CONTEXT_QUERIES`), so
        that every scored query carries the default matcher's whole trajectory, as the authors'
        code and OpenSeqSLAM score only such queries (issue #37: a shortened trajectory's mean
        over fewer frames spreads wider, and query 0 set recall at 100 % precision in almost
        every cell). 0 (earlier versions): every query is scored.
    map_config: every setting of the top-view maps rendered from scans (None for an image source,
        whose views are its images).
    rotated: source "bev" only: None (every view from the top-view images, `--bev-root`),
        "queries" (the database from them, the queries from the second image folder of the same
        sequence, `--bev-rot-root`: BEVPlace's KITTIRot) or "both" (database and queries from
        the second folder, as BEVPlace's main.py scores). Same frames, poses and ground truth.
    """

    id: str
    source: str
    sequence: str
    protocol: str = "paper"
    condition: Condition = CLEAN
    step: int = 4
    seed: int = 0
    data_seed: int = 0
    n_seeds: int | None = None
    map_config: MapConfig | None = field(default_factory=MapConfig)
    database_frames: tuple[int, int] | None = None
    query_frames: tuple[int, int] | None = None
    tp_radius_m: float = 10.0
    fp_radius_m: float = 10.0
    window_s: float | None = None
    data_version: str | None = None
    context_queries: int = 0
    rotated: str | None = None
    description: str = ""
    namespace: str | None = field(init=False, repr=False, compare=False)
    name: str = field(init=False, repr=False, compare=False)
    version: int = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        ns, name, version = parse_id(self.id)
        if version is None:
            raise ConfigError(f"task id {self.id!r} needs a version suffix such as '-v0'")
        object.__setattr__(self, "namespace", ns)
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "version", version)
        if isinstance(self.condition, str):
            object.__setattr__(self, "condition", Condition.parse(self.condition))
        if self.source not in SOURCES:
            raise ConfigError(
                f"task {self.id}: source must be one of {SOURCES}, got {self.source!r}"
            )
        if self.source != "synth" and self.data_version is not None:
            raise ConfigError(f"task {self.id}: data_version belongs to synthetic tasks only")
        if self.source == "synth":
            object.__setattr__(self, "data_version",
                               current_synth_data_version() if self.data_version is None
                               else str(self.data_version))
        if self.n_seeds is not None and (isinstance(self.n_seeds, bool)
                                         or not isinstance(self.n_seeds, int) or self.n_seeds < 1):
            raise ConfigError(f"task {self.id}: n_seeds must be an integer >= 1, got {self.n_seeds!r}")
        if (isinstance(self.context_queries, bool) or not isinstance(self.context_queries, int)
                or self.context_queries < 0):
            raise ConfigError(f"task {self.id}: context_queries must be an integer >= 0, "
                              f"got {self.context_queries!r}")
        if self.protocol not in PROTOCOLS:
            raise ConfigError(
                f"task {self.id}: protocol must be one of {PROTOCOLS}, got {self.protocol!r}"
            )
        if not isinstance(self.step, int) or self.step < 1:
            raise ConfigError(
                f"task {self.id}: frame step must be an integer >= 1, got {self.step!r}"
            )
        if not 0 <= self.tp_radius_m <= self.fp_radius_m:
            raise ConfigError(
                f"task {self.id}: need 0 <= tp_radius_m <= fp_radius_m, got {self.tp_radius_m}, {self.fp_radius_m}"
            )
        ranges = (self.database_frames, self.query_frames)
        if self.protocol == "bevplace":
            for what, rng in zip(("database", "query"), ranges, strict=True):
                if rng is None or len(rng) != 2 or not 0 <= rng[0] < rng[1]:
                    raise ConfigError(f"task {self.id}: the bevplace protocol needs a {what} frame "
                                      f"range [start, stop) with 0 <= start < stop, got {rng!r}")
                object.__setattr__(self, "database_frames" if what == "database" else "query_frames",
                                   (int(rng[0]), int(rng[1])))
            if not self.condition.is_clean or self.window_s is not None:
                raise ConfigError(f"task {self.id}: the bevplace protocol has clean queries and no time window")
        elif ranges != (None, None):
            raise ConfigError(f"task {self.id}: frame ranges belong to the bevplace protocol only")
        if self.source == "bev" and self.map_config is not None:
            if self.map_config != MapConfig():
                raise ConfigError(f"task {self.id}: an image source's views are its images; it takes no map_config")
            object.__setattr__(self, "map_config", None)
        if self.rotated is not None and (self.source != "bev" or self.rotated not in ROTATED):
            raise ConfigError(f"task {self.id}: rotated is one of {', '.join(ROTATED)} and belongs to "
                              f"top-view image tasks (source bev) only, got {self.rotated!r} on {self.source}")
        if self.source != "bev" and self.map_config is None:
            raise ConfigError(f"task {self.id}: tasks on scans need a map_config")
        if self.protocol in ("paper", "bevplace"):
            if self.window_s is not None or self.fp_radius_m != self.tp_radius_m:
                raise ConfigError(
                    f"task {self.id}: the {self.protocol} protocol has no time window and no excluded band"
                )
        else:
            if not self.condition.is_clean:
                raise ConfigError(
                    f"task {self.id}: revisit queries are the clean frames; condition must be T0R0"
                )
            if self.window_s is None or self.window_s < 0:
                raise ConfigError(
                    f"task {self.id}: the revisit protocol needs a time window >= 0 s"
                )

    @property
    def is_random(self) -> bool:
        """Whether its queries are drawn with noise (the paper protocol, not T0R0)."""
        return self.protocol == "paper" and not self.condition.is_clean

    @property
    def seeds(self) -> tuple[int, ...]:
        """The noise seeds a cell of this task averages: `n_seeds` of them from `seed` on."""
        n = self.n_seeds if self.n_seeds is not None else (DEFAULT_NOISY_SEEDS if self.is_random else 1)
        return tuple(range(self.seed, self.seed + n))

    def definition(self) -> dict[str, Any]:
        """Everything that changes the task's data or ground truth (no id, version or prose)."""
        out = {
            "revision": DEFINITION_REVISION,
            "source": self.source,
            "data_seed": self.data_seed if self.source == "synth" else None,
            "sequence": self.sequence,
            "protocol": self.protocol,
            "condition": self.condition.name,
            "step": self.step,
            "seed": self.seed,
            "map_config": to_jsonable(self.map_config),
            "tp_radius_m": self.tp_radius_m,
            "fp_radius_m": self.fp_radius_m,
            "window_s": self.window_s,
        }
        if self.protocol == "bevplace":  # only where set: older definitions keep their fingerprints
            out["database_frames"] = list(self.database_frames or ())
            out["query_frames"] = list(self.query_frames or ())
        if self.source == "synth" and self.data_version != FIRST_SYNTH_DATA_VERSION:
            out["data_version"] = self.data_version  # likewise: v0's fingerprints stay as they were
        if self.context_queries:  # likewise: the definitions before it keep their fingerprints
            out["context_queries"] = self.context_queries
        if self.rotated is not None:  # likewise
            out["rotated"] = self.rotated
        return out

    @property
    def fingerprint(self) -> str:
        """Stable hex digest of `definition()`; stored in result records."""
        return fingerprint(self.definition())

    def to_dict(self) -> dict[str, Any]:
        """The spec as plain JSON (for result records), fingerprint included."""
        return {
            "id": self.id,
            "version": self.version,
            **self.definition(),
            "fingerprint": self.fingerprint,
        }
