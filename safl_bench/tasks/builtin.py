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

Rotated top views (BEVPlace's KITTIRot, a second image folder of the same sequences whose every
scan was yawed by its own random angle before its image was made; `--bev-rot-root`): on 00, 02,
05 and 06, the revisit and BEVPlace protocols with the queries from the rotated folder and the
database from the plain one (`SAFL/BEVKITTI00-Revisit-RotQueries-v0`,
`SAFL/BEVKITTI00-BEVPlace-RotQueries-v1`), and BEVPlace's protocol with both from the rotated
folder (`SAFL/BEVKITTIRot00-BEVPlace-v1`), which is what BEVPlace's own main.py scores. Each is
the current plain task of its protocol (frames, ground truth, context queries, version) with
`TaskSpec.rotated` set; they are in the suite `bev-rotated` (and `all`), not in `revisit`,
`bev-revisit` or `bev-bevplace`, whose commands need one image root only.

Versions (`TASK_VERSION`, per protocol and source). The paper protocol is at v5 on the synthetic
default and v1 on KITTI scans and top-view images, BEVPlace's protocol at v1: these versions
leave the first `CONTEXT_QUERIES` (the paper's d_s = 10) queries out of every measure
(`TaskSpec.context_queries`), so that every scored query carries the default matcher's whole
trajectory (issue #37). Their predecessors (synthetic paper v4, KITTI and top-view paper v0,
BEVPlace v0) scored every query, the first ones on a shortened trajectory; they stay registered
and runnable, in no suite, and `successor` names the version that replaced each. The revisit
protocol kept every query (v0 off the synthetic source): its first queries have no candidate
older than the 30 s window (ten queries at every 4th frame span 3.6 s at 10 Hz), so none of them
is ever answered. The current synthetic tasks (paper and revisit v6) are on synthetic data
version "6" (`SYNTH_DATA_VERSIONS`: routes under a loop rule, `synth.routes`); the paper v4 and
v5 and revisit v4 tasks, on data version "5", stay registered and runnable (this safl-bench
generates versions "5" and "6"), in no suite; the revisit protocol has no v5 (`SYNTH_SKIPPED`).
Their v0-v3, on data versions "1"-"4", stay registered so that their records resolve, but they
cannot be run.

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
#: The top-view tasks on rotated images: `TaskSpec.rotated` -> protocols it is registered for.
ROTATED_PROTOCOLS = {"queries": ("revisit", "bevplace"), "both": ("bevplace",)}
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
#: Leading queries that are context only in the current paper and BEVPlace tasks: the paper's
#: d_s (Table I), the number of earlier queries a causal trajectory of the default matcher reads.
CONTEXT_QUERIES = 10

SUITES = {
    "paper": "the paper's twelve conditions on the default test sequence 00",
    "paper-full": "the paper's twelve conditions on both test sequences 00 and 09",
    "revisit": "loop closure within one sequence (revisit protocol)",
    "sanity": "clean T0R0 re-render tasks (queries equal the database)",
    "bev-revisit": "revisit protocol on the top-view images of KITTI 00, 02, 05, 06 (--bev-root)",
    "bev-bevplace": "BEVPlace's protocol on the top-view images of KITTI 00, 02, 05, 06 (--bev-root)",
    "bev-paper": "the paper's twelve conditions on the top-view images of KITTI 00 (--bev-root)",
    "bev-rotated": "revisit and BEVPlace's protocols with BEVPlace's rotated top views (KITTIRot) of "
                   "KITTI 00, 02, 05, 06 as queries (--bev-root, --bev-rot-root), and BEVPlace's "
                   "protocol on the rotated views alone, as its main.py (--bev-rot-root)",
    "long": "the long drive: the revisit protocol at every frame of a 20 000-frame synthetic drive "
            "(20 000 queries against up to 20 000 database frames; about 14 minutes with --workers 2 "
            "on 2 cores)",
    "all": "every built-in task",
}
#: Suites of one source only: they ignore the source a command's options select.
SOURCE_SUITES = {"bev-revisit": "bev", "bev-bevplace": "bev", "bev-paper": "bev", "bev-rotated": "bev"}

_BUILTIN: dict[str, list[str]] = {name: [] for name in SUITES}
#: Built-in tasks of older versions: registered (their records resolve), in no suite.
_SUPERSEDED: list[str] = []

#: The current version of the built-in tasks per protocol and source: the one the suites hold.
TASK_VERSION = {
    "paper": {"synth": 6, "kitti": 1, "bev": 1},
    "revisit": {"synth": 6, "kitti": 0, "bev": 0},
    "bevplace": {"bev": 1},
}
#: The first version per protocol and source whose leading queries are context only
#: (`CONTEXT_QUERIES`); the versions before it score every query.
CONTEXT_FROM = {"paper": {"synth": 5, "kitti": 1, "bev": 1}, "bevplace": {"bev": 1}}
#: Task version of the synthetic tasks -> the synthetic data version it is defined on
#: (`synth.GENERATOR_VERSION`); versions on another data version than the newest cannot be run.
SYNTH_DATA_VERSIONS = {0: "1", 1: "2", 2: "3", 3: "4", 4: "5", 5: "5", 6: "6"}
#: Versions a protocol skips on the synthetic source: the revisit protocol went from v4 to v6 with
#: data version 6, so that v6 names the tasks on data version 6 in both protocols (its v5 would
#: have been v4 again: the paper protocol's v5 changed only which queries are scored).
SYNTH_SKIPPED = {"revisit": (5,)}


def _version(source: str, version: int | None, protocol: str = "paper") -> int:
    return TASK_VERSION[protocol][source] if version is None else version


def _context(source: str, version: int | None, protocol: str) -> int:
    """The context queries of a built-in task of this protocol, source and version."""
    first = CONTEXT_FROM.get(protocol, {}).get(source)
    return CONTEXT_QUERIES if first is not None and _version(source, version, protocol) >= first else 0


def paper_id(source: str, sequence: str, condition: Condition, version: int | None = None) -> str:
    """Id of a paper-protocol task, e.g. SAFL/KITTI00-T5R1.5-v1 (`version`: default the
    current one, `TASK_VERSION`)."""
    return f"{NAMESPACE}/{SOURCE_LABEL[source]}{sequence}-{condition.name}-v{_version(source, version)}"


def revisit_id(source: str, sequence: str, version: int | None = None) -> str:
    """Id of a revisit-protocol task, e.g. SAFL/KITTI08-Revisit-v0 (default: current version)."""
    return (f"{NAMESPACE}/{SOURCE_LABEL[source]}{sequence}-Revisit-"
            f"v{_version(source, version, 'revisit')}")


def bevplace_id(source: str, sequence: str, version: int | None = None) -> str:
    """Id of a BEVPlace-protocol task, e.g. SAFL/BEVKITTI02-BEVPlace-v1 (default: current version)."""
    return (f"{NAMESPACE}/{SOURCE_LABEL[source]}{sequence}-BEVPlace-"
            f"v{_version(source, version, 'bevplace')}")


def _data_version(source: str, version: int | None, protocol: str = "paper") -> str | None:
    """The synthetic data version of a built-in task (None off the synthetic source)."""
    return SYNTH_DATA_VERSIONS[_version(source, version, protocol)] if source == "synth" else None


def _superseded_note(source: str, version: int | None, protocol: str = "paper") -> str:
    current = TASK_VERSION[protocol][source]
    if _version(source, version, protocol) == current:
        return ""
    data = _data_version(source, version, protocol)
    if data is not None and data != _data_version(source, current, protocol):
        return f" (superseded: defined on synthetic data version {data})"
    return (f" (superseded by v{current}: every query scored, the first {CONTEXT_QUERIES} on a "
            "shortened trajectory)")


def _paper(source: str, sequence: str, condition: Condition, version: int | None = None) -> TaskSpec:
    what = "clean re-render (sanity)" if condition.is_clean else f"viewpoint noise {condition.name}"
    if source == "bev" and not condition.is_clean:
        what += (" (queries: the images resampled to the moved viewpoint, nearest neighbour; "
                 "what lies beyond the image is empty)")
    context = _context(source, version, "paper")
    if context:
        what += f"; queries 0-{context - 1} are context only"
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
        context_queries=context,
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
        data_version=_data_version(source, version, "revisit"),
        description="revisit protocol, loop closure within the sequence"
                    + _superseded_note(source, version, "revisit"),
        map_config=None if source == "bev" else MapConfig(),
    )


def _bevplace(source: str, sequence: str, version: int | None = None) -> TaskSpec:
    database, queries = BEVPLACE_RANGES[sequence]
    context = _context(source, version, "bevplace")
    scored = (f"; queries {queries[0]}-{queries[0] + context - 1} are context only" if context
              else "")
    return TaskSpec(
        id=bevplace_id(source, sequence, version),
        source=source,
        sequence=sequence,
        protocol="bevplace",
        step=1,
        database_frames=database,
        query_frames=queries,
        tp_radius_m=BEVPLACE_TP_RADIUS_M,
        fp_radius_m=BEVPLACE_TP_RADIUS_M,
        context_queries=context,
        description=(f"BEVPlace's protocol: database frames {database[0]}-{database[1] - 1}, queries "
                     f"{queries[0]}-{queries[1] - 1}, a true place within 5 m, Recall@1{scored}"
                     + _superseded_note(source, version, "bevplace")),
        map_config=None if source == "bev" else MapConfig(),
    )


#: The long drive (`synth.STREAMED_SEQUENCES`): its sequence and the frame step of its task.
LONG_SEQUENCE = "L0"
LONG_STEP = 1


def _long_drive() -> TaskSpec:
    """The revisit protocol on the long drive at every frame, not every 4th: the matcher at the
    scale of a city run (20 000 queries, each against the frames more than 30 s older), the
    ground truth and window as on the other revisit tasks."""
    import dataclasses

    plain = _revisit("synth", LONG_SEQUENCE)
    return dataclasses.replace(
        plain, step=LONG_STEP,
        description=("revisit protocol on the long drive (20 000 frames over a 14 x 14 town, scans "
                     "cast on demand), every frame"))


def rotated_id(sequence: str, protocol: str, rotated: str) -> str:
    """Id of a top-view task on rotated images, e.g. SAFL/BEVKITTI02-BEVPlace-RotQueries-v1
    (queries rotated) or SAFL/BEVKITTIRot02-BEVPlace-v1 (database and queries rotated). Its
    version is the plain task's it copies (`TASK_VERSION`), so that equal versions of a protocol
    mean equal rules (BEVPlace's v1: the first 10 queries are context)."""
    name = "BEVPlace" if protocol == "bevplace" else "Revisit"
    version = TASK_VERSION[protocol]["bev"]
    if rotated == "both":
        return f"{NAMESPACE}/{SOURCE_LABEL['bev']}Rot{sequence}-{name}-v{version}"
    return f"{NAMESPACE}/{SOURCE_LABEL['bev']}{sequence}-{name}-RotQueries-v{version}"


def _rotated(sequence: str, protocol: str, rotated: str) -> TaskSpec:
    """The current plain top-view task of `protocol` on `sequence` with its queries (or its
    database and queries) from the rotated images."""
    import dataclasses

    plain = _bevplace("bev", sequence) if protocol == "bevplace" else _revisit("bev", sequence)
    which = "queries" if rotated == "queries" else "database and queries"
    return dataclasses.replace(
        plain, id=rotated_id(sequence, protocol, rotated), rotated=rotated,
        description=(f"{plain.description}; {which} from the rotated top views (BEVPlace's "
                     "KITTIRot, --bev-rot-root: each scan yawed by its own random angle)"
                     + (", as BEVPlace's main.py scores" if rotated == "both" else "")))


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
    _add(("long",), _long_drive())
    for sequence in BEVPLACE_RANGES:
        _add(("bev-bevplace",), _bevplace("bev", sequence))
    for rotated, protocols in ROTATED_PROTOCOLS.items():
        for protocol in protocols:
            for sequence in REVISIT_SEQUENCES["bev"]:
                _add(("bev-rotated",), _rotated(sequence, protocol, rotated))
    old: list[TaskSpec] = []  # superseded versions: registered, in no suite
    for version in SYNTH_DATA_VERSIONS:
        if version < TASK_VERSION["paper"]["synth"]:
            old += [_paper("synth", sequence, condition, version) for sequence
                    in PAPER_SOURCE_SEQUENCES["synth"] for condition in (*PAPER_CONDITIONS, CLEAN)]
        if version < TASK_VERSION["revisit"]["synth"] and version not in SYNTH_SKIPPED["revisit"]:
            old += [_revisit("synth", sequence, version) for sequence in REVISIT_SEQUENCES["synth"]]
    for source in ("kitti", "bev"):
        old += [_paper(source, sequence, condition, version)
                for version in range(TASK_VERSION["paper"][source])
                for sequence in PAPER_SOURCE_SEQUENCES[source]
                for condition in (*PAPER_CONDITIONS, CLEAN)]
    old += [_bevplace("bev", sequence, version)
            for version in range(TASK_VERSION["bevplace"]["bev"]) for sequence in BEVPLACE_RANGES]
    for task in old:
        register(task)
        _SUPERSEDED.append(task.id)


def superseded() -> list[str]:
    """Ids of the built-in tasks of older versions: registered, so that their records resolve,
    but in no suite. The synthetic tasks on synthetic data the generator no longer makes (v0-v3)
    cannot be run (`registry.check_data_version`); those on data version 5 (paper v4, v5,
    revisit v4) and the paper and BEVPlace tasks that scored every query (KITTI and top-view paper
    v0, BEVPlace v0) still can."""
    return list(_SUPERSEDED)


def predecessor(task_id: str) -> str | None:
    """The registered task whose `successor` is `task_id` (None when there is none)."""
    from safl_bench.tasks.registry import registry

    new = registry.get(task_id)
    if new is None or not new.context_queries:
        return None
    return next((old.id for old in registry.values() if old.namespace == new.namespace
                 and old.name == new.name and old.version < new.version
                 and successor(old.id) == task_id), None)


def successor(task_id: str) -> str | None:
    """The task (a later version of the same name) that replaced `task_id` with the same data,
    views and ground truth and only its leading queries made context (`TaskSpec.context_queries`), e.g.
    SAFL/BEVKITTI00-T1R1-v0 -> SAFL/BEVKITTI00-T1R1-v1; None for any other id. A record of the
    old task holds every per-query outcome the new one scores
    (`safl_bench.results.derive.derive_record`)."""
    import dataclasses

    from safl_bench.tasks.registry import registry
    from safl_bench.tasks.spec import make_id

    old = registry.get(task_id)
    if old is None or old.context_queries:
        return None
    newer = sorted((s for s in registry.values() if s.namespace == old.namespace
                    and s.name == old.name and s.version > old.version), key=lambda s: s.version)
    for new in newer:
        if new.context_queries and dataclasses.replace(new, id=old.id, context_queries=0,
                                                       description=old.description) == old:
            return make_id(new.namespace, new.name, new.version)
    return None


def suite(name: str, source: str | None = None) -> list[str]:
    """Ids of a named suite ('paper', 'paper-full', 'revisit', 'sanity', 'all', 'bev-...').

    `source` keeps only the tasks on "synth" (the embedded default), "kitti" or "bev" (top-view
    images); None keeps all. The 'bev-...' suites hold top-view image tasks whatever `source`.
    """
    import difflib

    from safl_bench.tasks.registry import registry

    if name not in SUITES:
        tasks = _namespaced(name)
        close = tasks or difflib.get_close_matches(name, SUITES, n=1)
        what = "task or suite" if tasks else "suite"
        hint = f" Did you mean: {', '.join(close)}?" if close else ""
        why = " (task ids carry their namespace)" if tasks else ""
        raise RegistryError(f"unknown {what} {name!r}{why}; suites: {', '.join(SUITES)}.{hint}")
    if source not in (None, *SOURCE_LABEL):
        raise RegistryError(f"unknown source {source!r}; sources: {', '.join(SOURCE_LABEL)}")
    source = SOURCE_SUITES.get(name, source)
    return [i for i in _BUILTIN[name] if source is None or registry[i].source == source]


def _namespaced(name: str) -> list[str]:
    """The registered task ids that `name` is once their namespace is prefixed (e.g.
    'BEVKITTI00-BEVPlace-RotQueries-v1' -> SAFL/BEVKITTI00-BEVPlace-RotQueries-v1), else those
    of the closest such names (at most 3): what a namespace-less task id given where a task id
    or suite is read (`safl-bench run --task`) meant. Ids stay explicit, as Gymnasium keeps
    them: this only suggests, it resolves nothing."""
    import difflib

    from safl_bench.tasks.registry import registry
    from safl_bench.tasks.spec import make_id

    full: dict[str, list[str]] = {}  # namespace-less id or versionless name -> full ids
    for spec_ in registry.values():
        if spec_.namespace:
            for version in (spec_.version, None):
                full.setdefault(make_id(None, spec_.name, version), []).append(
                    make_id(spec_.namespace, spec_.name, version))
    if name in full:
        return sorted(set(full[name]))
    close = difflib.get_close_matches(name, list(full), n=3, cutoff=0.8)
    return list(dict.fromkeys(i for c in close for i in sorted(set(full[c]))))[:3]
