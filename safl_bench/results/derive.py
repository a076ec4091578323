"""Records of a new task version derived from those of the version it replaced, without
recomputing them.

The paper and BEVPlace protocols' current task versions (synthetic paper v5, KITTI and top-view
paper v1, BEVPlace v1) differ from their predecessors in one thing only: their first
`TaskSpec.context_queries` queries are context, left out of every measure
(`safl_bench.tasks.builtin.successor` checks that the two definitions are otherwise equal). The
data, the views, the noise, the ground truth and the whole difference matrix are the same, and
so is every match: the matcher sees every query either way, and a query's match depends only
on its own rows of the matrix (its trajectory's rows, all of which exist in both versions). So
each query the new version scores has, in the old record, exactly the outcome a recompute would
give it (confidence, label, true place, candidate, rank), and the new record is the old one's
per-query outcomes with the leading ones dropped, every measure and curve recomputed from them
under this code's metrics version (`safl_bench.evaluation.metrics`). `tools/check_derivation.py`
recomputes sampled cells in full and compares; `tests/test_derive.py` does it on small data.

What is kept as it was: the method, matcher settings, seed, timings (the same method described
the same views), environment (the run that computed the matches) and `seen_in_training`. What
changes: the task (id, version, definition, fingerprint), the measures, `created` (now) and
`derived_from` (the old task id, when the old record was made, and a one-line note).

Which stored queries are dropped. A record holds the outcomes of the queries its evaluation
scored: ``[t, M - t)`` of the ``M`` queries matched (``M``: the task's queries, or
``max_frames`` of them; ``t``: ``trim_queries``). The new version scores
``[max(context, t), M - t)`` (`safl_bench.evaluation.cell.scored_queries`), so the first
``max(context, t) - t`` stored outcomes go. A record whose outcome count is not ``M - 2t`` is
refused, never guessed at.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from safl_bench.errors import DataError
from safl_bench.evaluation.metrics import METRICS_VERSION
from safl_bench.results.records import (
    Derivation,
    ModeResult,
    QueryOutcomes,
    ResultRecord,
    load_records,
    record_path,
    rescore_outcomes,
    task_info,
    utc_now,
    write_record,
)
from safl_bench.tasks.spec import TaskSpec

#: Keys of a record's ``task.spec`` that are the definition, id or fingerprint: the rest
#: (data fingerprint, notes, counts, the method's input) describes the data and is carried over.
_SPEC_KEYS = {"id", "version", "fingerprint"}


class NotDerivableError(DataError):
    """A record that cannot be turned into one of the new task version without recomputing."""


def _slice(queries: QueryOutcomes, drop: int) -> QueryOutcomes:
    """The outcomes without their first `drop` queries: every per-query list field (a field
    added later is sliced too), the optional ones left None."""
    sliced: dict[str, Any] = {f.name: None if (v := getattr(queries, f.name)) is None else v[drop:]
                              for f in dataclasses.fields(queries)}
    return dataclasses.replace(queries, **sliced)


def dropped_queries(record: ResultRecord, new: TaskSpec) -> int:
    """How many of `record`'s stored per-query outcomes the task `new` leaves out (module doc).
    Raises NotDerivableError when the record's outcome count does not fit its settings."""
    evaluation = record.matcher.get("evaluation", {})
    trim = int(evaluation.get("trim_queries") or 0)
    max_frames = evaluation.get("max_frames")
    n_task = int(record.task.spec.get("n_queries", -1))
    if n_task < 0:
        raise NotDerivableError(f"{record.task.id} seed {record.seed}: the record does not say how "
                                "many queries the task has (task.spec.n_queries)")
    matched = n_task if max_frames is None else min(n_task, int(max_frames))
    for name, mode in record.results.items():
        if mode.queries is None:
            raise NotDerivableError(
                f"{record.method.name}@{record.method.version} on {record.task.id} seed "
                f"{record.seed}: metrics version {record.metrics_version}, no per-query outcomes "
                "to derive from; recompute it")
        if len(mode.queries.label) != matched - 2 * trim:
            raise NotDerivableError(
                f"{record.task.id} seed {record.seed}: {len(mode.queries.label)} {name} outcomes, "
                f"expected {matched - 2 * trim} ({matched} queries matched, trim_queries={trim})")
    drop = max(new.context_queries, trim) - trim
    if drop >= matched - 2 * trim:
        raise NotDerivableError(f"{new.id}: its {new.context_queries} context queries leave none of "
                                f"the record's {matched - 2 * trim} scored queries")
    return drop


def derive_record(record: ResultRecord, new: TaskSpec) -> ResultRecord:
    """The record of task `new` that a recompute would give, from `record`, a record of the
    task version `new` replaced (module doc). Raises NotDerivableError when `new` is not that
    task's successor or the record lacks per-query outcomes."""
    from safl_bench.tasks.builtin import successor
    from safl_bench.tasks.registry import registry

    old = registry.get(record.task.id)
    if old is None or successor(record.task.id) != new.id:
        raise NotDerivableError(f"{new.id} does not replace {record.task.id} with the same data and "
                                "matches; its records are computed, not derived")
    if record.task.spec_fingerprint != old.fingerprint:
        raise NotDerivableError(f"{record.task.id} seed {record.seed}: the record was made under "
                                f"another definition (fingerprint {record.task.spec_fingerprint}, "
                                f"registered {old.fingerprint})")
    drop = dropped_queries(record, new)
    results: dict[str, ModeResult] = {}
    for name, mode in record.results.items():
        assert mode.queries is not None  # dropped_queries checked it
        results[name] = rescore_outcomes(_slice(mode.queries, drop))
    extra: dict[str, Any] = {k: v for k, v in record.task.spec.items()
                             if k not in _SPEC_KEYS and k not in old.definition()}
    first = max(new.context_queries, int(record.matcher.get("evaluation", {}).get("trim_queries") or 0))
    note = (f"derived from the record of {record.task.id} (same data, views and matches): its "
            f"outcomes of the first {drop} scored queries dropped, as {new.id} scores queries "
            f"{first} on; every measure recomputed (metrics version {METRICS_VERSION})")
    return dataclasses.replace(
        record,
        task=task_info(new, record.task.source_label, **extra),
        results=results,
        metrics_version=METRICS_VERSION,
        created=utc_now(),
        derived_from=Derivation(task=record.task.id, created=record.created, note=note),
    )


@dataclasses.dataclass(frozen=True)
class Migration:
    """What `migrate` did to one results folder."""

    derived: list[Path]
    removed: list[Path]
    kept: list[str]  # one line each: a superseded record left as it was, and why


def migrate(results_dir: str | Path, *, remove: bool = False, force: bool = False) -> Migration:
    """Derive, in `results_dir`, the record of the current task version for every record of a
    version it replaced (`successor`); an existing new-version record is kept unless `force`.
    `remove`: delete each old record once its derived one is written (the folder then holds
    the new versions only). Records that cannot be derived are kept and named in `kept`."""
    from safl_bench.tasks.builtin import successor
    from safl_bench.tasks.registry import registry

    root = Path(results_dir)
    records, _ = load_records(root)
    derived: list[Path] = []
    removed: list[Path] = []
    kept: list[str] = []
    for record in records:
        new_id = successor(record.task.id)
        if new_id is None:
            continue
        old_path = record_path(root, record.method.name, record.method.version, record.task.id,
                               record.seed)
        target = record_path(root, record.method.name, record.method.version, new_id, record.seed)
        if target.is_file() and not force:
            kept.append(f"{old_path}: {target} exists (--force derives it again)")
        else:
            try:
                new_record_ = derive_record(record, registry[new_id])
            except NotDerivableError as exc:
                kept.append(f"{old_path}: {exc}")
                continue
            derived.append(write_record(root, new_record_))
        if remove and old_path.is_file():
            old_path.unlink()
            removed.append(old_path)
            try:
                old_path.parent.rmdir()
            except OSError:
                pass
    return Migration(derived, removed, kept)


def superseded_note(records: list[ResultRecord], folder: str | Path) -> str | None:
    """One line naming the records of superseded task versions among `records` (read as what
    they are, in tables of their own version, never beside the current versions), and the
    command that derives the current ones; None when there are none."""
    from safl_bench.tasks.builtin import successor

    ids = [r.task.id for r in records if successor(r.task.id) is not None]  # one registry scan each
    if not ids:
        return None
    old, n = sorted(set(ids)), len(ids)
    shown = ", ".join(old[:3]) + (f" and {len(old) - 3} more" if len(old) > 3 else "")
    return (f"{n} records in {folder} are of task versions a newer one replaced ({shown}): they are "
            f"tabled under their own version, never beside the current one; `safl-bench records "
            f"migrate {folder}` derives the current versions' records from them")


def retrieval_settings(matcher: Any) -> dict[str, Any] | None:
    """The settings a retrieval method's answers depend on, from a record's ``matcher`` field:
    the evaluation-level ones and the single-frame matcher's (its score rule, dtype), without
    the preset's name. The sequence matcher does not apply to a retrieval method
    (`safl_bench.methods.retrieval`), so records whose settings differ only there hold the same
    answers. None when the field cannot be read."""
    from safl_bench.errors import ConfigError
    from safl_bench.matching.settings import EvaluationConfig

    try:
        config = EvaluationConfig.from_dict(matcher)
    except (ConfigError, TypeError):
        return None
    single = config.single_frame.to_dict()
    single.pop("preset")
    return {"single_frame": single,
            "evaluation": config.to_dict()["evaluation"]}


def relabel_retrieval(record: ResultRecord, matcher: dict[str, Any]) -> ResultRecord:
    """`record` of a retrieval method under the matcher settings `matcher` (another preset's),
    without recomputing it: its answers depend only on `retrieval_settings`, which must be the
    same in both (else NotDerivableError). Everything else is kept; `created` is now and
    `derived_from` says what was relabelled. This is how a retrieval method's records follow a
    change of the default preset that touches only the sequence matcher (``paper-r10`` ->
    ``paper``: the enhancement window), instead of being run again."""
    from safl_bench.matching.presets import label

    if record.method.kind != "retrieval":
        raise NotDerivableError(f"{record.method.name}@{record.method.version} is not a "
                                "retrieval method: its sequence matches depend on the settings")
    old, new = retrieval_settings(record.matcher), retrieval_settings(matcher)
    if old is None or old != new:
        raise NotDerivableError(f"{record.task.id} seed {record.seed}: the settings differ "
                                "beyond the sequence matcher, which a retrieval method does "
                                "not use; recompute it")
    note = (f"matcher settings relabelled {label(record.matcher)} -> {label(matcher)} without "
            "recomputing: the sequence matcher does not apply to a retrieval method, and the "
            "single-frame and evaluation settings are the same")
    return dataclasses.replace(
        record, matcher=dict(matcher), created=utc_now(),
        derived_from=Derivation(task=record.task.id, created=record.created, note=note))
