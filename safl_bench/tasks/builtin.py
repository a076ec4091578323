"""The built-in tasks and the named suites.

Paper protocol (Table II): the twelve conditions T{1,5,10,20}R{1,1.5,2} on the test sequences 00
and 09, for the embedded synthetic default (`SAFL/Synth00-T1R1-v4`) and for KITTI
(`SAFL/KITTI00-T1R1-v0`); every 4th frame, as the authors' public code did (the paper is silent),
true positive within 10 m, noise seed 0. A clean T0R0 sanity task per sequence checks that a
method finds the route without noise.

Revisit protocol: loop closure within one sequence (`SAFL/KITTI00-Revisit-v0`); every 4th frame
(so the clean database maps are shared with the paper tasks), a query may only match frames more
than 30 s older, true positive within 3 m, false positive beyond 20 m. On KITTI 00, 05 and 08
(the sequences with many revisits; 08 revisits in the opposite direction) and on the synthetic
test sequences.

Top-view image folders (real KITTI through BEVPlace's published images, `SAFL/BEVKITTI00-...`):
the revisit protocol on 00, 02, 05 and 06; BEVPlace's own protocol (`-BEVPlace-v0`, from its
`dataset.py`: fixed database and query frame ranges per sequence, every frame, a true place
within 5 m, scored by Recall@1); and the paper's twelve conditions on 00, whose noisy queries
are the images resampled to the moved viewpoint (there are no points to re-render: nearest
neighbour, what comes from outside the image is empty; at T20 up to a third of a 60.4 m wide
view along the shift, see `safl_bench.views.resample`).

Synthetic tasks are at task version v4, on synthetic data version "5" (`SYNTH_DATA_VERSIONS`);
their v0, v1, v2 and v3, on data versions "1", "2", "3" and "4", stay registered so that their
records resolve, but in no suite, and they cannot be run (this safl-bench generates version "5"
only). KITTI and top-view image tasks are at v0.

Never edit a registered definition: add a new version (e.g. `-v1`) beside it.
"""

from __future__ import annotations

from safl_bench.errors import RegistryError
from safl_bench.tasks.registry import register
from safl_bench.tasks.spec import TaskSpec
from safl_bench.views.mapconfig import MapConfig
from safl_bench.views.noise import CLEAN, PAPER_CONDITIONS, Condition

NAMESPACE = "SAFL"
PAPER_STEP = 4
PAPER_TP_RADIUS_M = 10.0
REVISIT_STEP = 4
REVISIT_WINDOW_S = 30.0
REVISIT_TP_RADIUS_M = 3.0
REVISIT_FP_RADIUS_M = 20.0

#: Test sequences of the paper protocol; the first is the default test sequence.
PAPER_SEQUENCES = ("00", "09")
REVISIT_SEQUENCES = {"synth": ("00", "09"), "kitti": ("00", "05", "08"), "bev": ("00", "02", "05", "06")}
SOURCE_LABEL = {"synth": "Synth", "kitti": "KITTI", "bev": "BEVKITTI"}
#: Sequences of the paper protocol per source (the top-view images: KITTI 00 only).
PAPER_SOURCE_SEQUENCES = {"synth": PAPER_SEQUENCES, "kitti": PAPER_SEQUENCES, "bev": ("00",)}
#: BEVPlace's protocol (its dataset.py): [start, stop) database and query frames per sequence.
BEVPLACE_RANGES = {
    "00": ((0, 3000), (3200, 4541)),
    "02": ((0, 3400), (3600, 4661)),
    "05": ((0, 1000), (1200, 2751)),
    "06": ((0, 600), (800, 1101)),
}
BEVPLACE_TP_RADIUS_M = 5.0

SUITES = {
    "paper": "the paper's twelve conditions on the default test sequence 00",
    "paper-full": "the paper's twelve conditions on both test sequences 00 and 09",
    "revisit": "loop closure within one sequence (revisit protocol)",
    "sanity": "clean T0R0 re-render tasks (queries equal the database)",
    "bev-revisit": "revisit protocol on the top-view images of KITTI 00, 02, 05, 06 (--bev-root)",
    "bev-bevplace": "BEVPlace's protocol on the top-view images of KITTI 00, 02, 05, 06 (--bev-root)",
    "bev-paper": "the paper's twelve conditions on the top-view images of KITTI 00 (--bev-root)",
    "all": "every built-in task",
}
#: Suites of one source only: they ignore the source a command's options select.
SOURCE_SUITES = {"bev-revisit": "bev", "bev-bevplace": "bev", "bev-paper": "bev"}

_BUILTIN: dict[str, list[str]] = {name: [] for name in SUITES}
#: Built-in tasks of older versions: registered (their records resolve), in no suite.
_SUPERSEDED: list[str] = []

#: The current version of the built-in tasks per source: the one the suites hold.
TASK_VERSION = {"synth": 4, "kitti": 0, "bev": 0}
#: Task version of the synthetic tasks -> the synthetic data version it is defined on
#: (`synth.GENERATOR_VERSION`); the versions before `TASK_VERSION["synth"]` are superseded.
SYNTH_DATA_VERSIONS = {0: "1", 1: "2", 2: "3", 3: "4", 4: "5"}


def _version(source: str, version: int | None) -> int:
    return TASK_VERSION[source] if version is None else version


def paper_id(source: str, sequence: str, condition: Condition, version: int | None = None) -> str:
    """Id of a paper-protocol task, e.g. SAFL/KITTI00-T5R1.5-v0 (`version`: default the
    source's current one, `TASK_VERSION`)."""
    return f"{NAMESPACE}/{SOURCE_LABEL[source]}{sequence}-{condition.name}-v{_version(source, version)}"


def revisit_id(source: str, sequence: str, version: int | None = None) -> str:
    """Id of a revisit-protocol task, e.g. SAFL/KITTI08-Revisit-v0 (default: current version)."""
    return f"{NAMESPACE}/{SOURCE_LABEL[source]}{sequence}-Revisit-v{_version(source, version)}"


def bevplace_id(source: str, sequence: str, version: int | None = None) -> str:
    """Id of a BEVPlace-protocol task, e.g. SAFL/BEVKITTI02-BEVPlace-v0 (default: current version)."""
    return f"{NAMESPACE}/{SOURCE_LABEL[source]}{sequence}-BEVPlace-v{_version(source, version)}"


def _data_version(source: str, version: int | None) -> str | None:
    """The synthetic data version of a built-in task (None off the synthetic source)."""
    return SYNTH_DATA_VERSIONS[_version(source, version)] if source == "synth" else None


def _superseded_note(source: str, version: int | None) -> str:
    if _version(source, version) == TASK_VERSION[source]:
        return ""
    return f" (superseded: defined on synthetic data version {_data_version(source, version)})"


def _paper(source: str, sequence: str, condition: Condition, version: int | None = None) -> TaskSpec:
    what = "clean re-render (sanity)" if condition.is_clean else f"viewpoint noise {condition.name}"
    if source == "bev" and not condition.is_clean:
        what += (" (queries: the images resampled to the moved viewpoint, nearest neighbour; "
                 "what lies beyond the image is empty)")
    return TaskSpec(
        id=paper_id(source, sequence, condition, version),
        source=source,
        sequence=sequence,
        protocol="paper",
        condition=condition,
        step=PAPER_STEP,
        tp_radius_m=PAPER_TP_RADIUS_M,
        fp_radius_m=PAPER_TP_RADIUS_M,
        data_version=_data_version(source, version),
        description=f"paper protocol, {what}{_superseded_note(source, version)}",
        map_config=None if source == "bev" else MapConfig(),
    )


def _revisit(source: str, sequence: str, version: int | None = None) -> TaskSpec:
    return TaskSpec(
        id=revisit_id(source, sequence, version),
        source=source,
        sequence=sequence,
        protocol="revisit",
        step=REVISIT_STEP,
        tp_radius_m=REVISIT_TP_RADIUS_M,
        fp_radius_m=REVISIT_FP_RADIUS_M,
        window_s=REVISIT_WINDOW_S,
        data_version=_data_version(source, version),
        description="revisit protocol, loop closure within the sequence"
                    + _superseded_note(source, version),
        map_config=None if source == "bev" else MapConfig(),
    )


def _bevplace(source: str, sequence: str) -> TaskSpec:
    database, queries = BEVPLACE_RANGES[sequence]
    return TaskSpec(
        id=bevplace_id(source, sequence),
        source=source,
        sequence=sequence,
        protocol="bevplace",
        step=1,
        database_frames=database,
        query_frames=queries,
        tp_radius_m=BEVPLACE_TP_RADIUS_M,
        fp_radius_m=BEVPLACE_TP_RADIUS_M,
        description=(f"BEVPlace's protocol: database frames {database[0]}-{database[1] - 1}, queries "
                     f"{queries[0]}-{queries[1] - 1}, a true place within 5 m, Recall@1"),
        map_config=None if source == "bev" else MapConfig(),
    )


def _add(suites: tuple[str, ...], task: TaskSpec) -> None:
    register(task)
    for name in (*suites, "all"):
        _BUILTIN[name].append(task.id)


def register_builtin() -> None:
    """Register every built-in task (once; `import safl_bench` does it)."""
    if _BUILTIN["all"]:
        return
    for source in ("synth", "kitti", "bev"):
        bev = ("bev-paper",) if source == "bev" else ()
        sequences = PAPER_SOURCE_SEQUENCES[source]
        for sequence in sequences:
            for condition in PAPER_CONDITIONS:
                default = ("paper",) if sequence == sequences[0] else ()
                _add((*default, "paper-full", *bev), _paper(source, sequence, condition))
        for sequence in sequences:
            _add(("sanity",), _paper(source, sequence, CLEAN))
        for sequence in REVISIT_SEQUENCES[source]:
            _add(("revisit", *(("bev-revisit",) if source == "bev" else ())), _revisit(source, sequence))
    for sequence in BEVPLACE_RANGES:
        _add(("bev-bevplace",), _bevplace("bev", sequence))
    for version in SYNTH_DATA_VERSIONS:  # superseded synthetic versions: registered, in no suite
        if version == TASK_VERSION["synth"]:
            continue
        old = [_paper("synth", sequence, condition, version)
               for sequence in PAPER_SOURCE_SEQUENCES["synth"] for condition in (*PAPER_CONDITIONS, CLEAN)]
        old += [_revisit("synth", sequence, version) for sequence in REVISIT_SEQUENCES["synth"]]
        for task in old:
            register(task)
            _SUPERSEDED.append(task.id)


def superseded() -> list[str]:
    """Ids of the built-in tasks of older versions (the synthetic tasks' v0, v1, v2 and v3):
    registered, so that their records resolve, but in no suite; a synthetic one cannot be run
    (`registry.check_data_version`)."""
    return list(_SUPERSEDED)


def suite(name: str, source: str | None = None) -> list[str]:
    """Ids of a named suite ('paper', 'paper-full', 'revisit', 'sanity', 'all', 'bev-...').

    `source` keeps only the tasks on "synth" (the embedded default), "kitti" or "bev" (top-view
    images); None keeps all. The 'bev-...' suites hold top-view image tasks whatever `source`.
    """
    import difflib

    from safl_bench.tasks.registry import registry

    if name not in SUITES:
        close = difflib.get_close_matches(name, SUITES, n=1)
        hint = f" Did you mean: {close[0]}?" if close else ""
        raise RegistryError(f"unknown suite {name!r}; suites: {', '.join(SUITES)}.{hint}")
    if source not in (None, *SOURCE_LABEL):
        raise RegistryError(f"unknown source {source!r}; sources: {', '.join(SOURCE_LABEL)}")
    source = SOURCE_SUITES.get(name, source)
    return [i for i in _BUILTIN[name] if source is None or registry[i].source == source]
