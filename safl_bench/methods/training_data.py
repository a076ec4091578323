"""Which data a method's weights were trained on, and whether a record's task is among them.

Weights written by `safl-bench train` carry ``trained_on`` in their metadata (`TrainedOn`:
the data set, the source's kind and label, the sequences, the frame step), and `Method.load`
copies it into the method's ``weights`` info, so every record names it. The weights shipped
before that metadata existed are known by their SHA-256 (`SHIPPED`, from their training logs
in leaderboard/training-logs/<name>/train.json), and so are BEVPlace's authors' published
KITTI weights, which trained on KITTI 00 frames 0-2999 only (`BEVPLACE_KITTI`, the evidence in
docs/guides/reproduce-bevplace.md, "What BEVPlace's weights saw"). Weights with neither are
never marked.

A record is SEEN IN TRAINING when its task's sequence is one the weights were trained on, in
the same data set: real KITTI whether read as scans (``kitti``) or as top-view images
(``bev``), since both are the same drive; a synthetic sequence only in the same synthetic data
(its label names the generator's seed). Its scores measure memory, not generalisation:
`seen_note` says so in the record (``seen_in_training``), the run table marks it and the
leaderboard never ranks it beside clean cells.

Weights may have seen only a FRAME RANGE of a sequence (`TrainedOn.frames`, first and last
frame, inclusive; a sequence without a range was seen whole). A task on that sequence is then
judged by its own frames (the record's ``task.spec``: every `step`-th frame of its database and
query ranges, the whole sequence where it names none):

- every database frame and every query among the trained frames: SEEN IN TRAINING, as above;
- none of them: not seen (the weights never saw those frames);
- some but not all: PARTLY SEEN IN TRAINING. Its note begins with `PARTLY_SEEN_PREFIX` and says
  how much of the database and of the queries the weights saw, e.g. BEVPlace's protocol on 00:
  "partly seen in training: the whole database (3000 frames, 0-2999), none of the 1341 queries
  (3200-4540) of KITTI 00 were among the training frames (...)". Tables mark its row
  `PARTLY_SEEN_MARK` and never rank it beside clean cells either: a database the network was
  trained on is one whose descriptors it learned to pull together or apart, so even unseen
  queries are matched against memorised places, and how much that helps is not known.

Which images of the frames the weights saw (plain or rotated top views, scans) does not matter:
the same frames of the same drive (as for scans and top views above).

A record of UNTRAINED networks (random weights, scored only when asked: ``--weights
untrained``) trained on nothing: its ``method.params.weights.source`` is "untrained"
(`record_untrained`), and the run table and every leaderboard table mark it `UNTRAINED_MARK`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any, Protocol


class _Record(Protocol):
    """What `record_seen` reads of a result record (`safl_bench.results.records.ResultRecord`;
    the records come after the methods, so this module names only the fields)."""

    @property
    def seen_in_training(self) -> str | None: ...
    @property
    def method(self) -> Any: ...  # MethodInfo: .params
    @property
    def task(self) -> Any: ...  # TaskInfo: .source_kind, .source_label, .sequence

#: Source kinds that read real KITTI (the same drives, whichever form).
KITTI_KINDS = ("kitti", "bev")


@dataclass(frozen=True)
class TrainedOn:
    """The training data of a set of weights."""

    source_kind: str  # "synth" | "kitti" | "bev"
    source: str  # the source's label, e.g. "KITTI top-view images", "synthetic default (seed 0)"
    sequences: tuple[str, ...]
    step: int = 1
    #: (sequence, first frame, last frame), inclusive, for each sequence of which only a range
    #: was seen; a sequence not named here was seen whole
    frames: tuple[tuple[str, int, int], ...] = ()

    @property
    def dataset(self) -> str:
        """Which data set the sequences name: "KITTI" for scans and top views alike."""
        return "KITTI" if self.source_kind in KITTI_KINDS else self.source

    def frame_range(self, sequence: str) -> tuple[int, int] | None:
        """The first and last frame seen of `sequence` (inclusive); None when seen whole."""
        return next(((first, last) for s, first, last in self.frames if s == sequence), None)

    def describe(self) -> str:
        """The data in words: "KITTI 00 frames 0-2999, 02" (the sequences, with their ranges)."""
        names = []
        for s in self.sequences:
            r = self.frame_range(s)
            names.append(s if r is None else f"{s} frames {r[0]}\u2013{r[1]}")
        return f"{self.dataset} {', '.join(names)}"

    def to_dict(self) -> dict[str, Any]:
        out = {**asdict(self), "sequences": list(self.sequences)}
        del out["frames"]  # written only when there are ranges: older weights' dicts unchanged
        if self.frames:
            out["frames"] = {s: [first, last] for s, first, last in self.frames}
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TrainedOn | None:
        """The `TrainedOn` a weights file or record stores; None when it holds none or garbage."""
        try:
            ranges = data.get("frames") or {}
            frames = tuple((str(s), int(r[0]), int(r[1])) for s, r in ranges.items())
            return cls(str(data["source_kind"]), str(data["source"]),
                       tuple(str(s) for s in data["sequences"]), int(data.get("step", 1)), frames)
        except (KeyError, TypeError, ValueError, AttributeError, IndexError):
            return None


_SYNTH0 = TrainedOn("synth", "synthetic default (seed 0)", ("01", "02", "03", "04"), 1)
_BEV02 = TrainedOn("bev", "KITTI top-view images", ("02",), 4)
#: BEVPlace's authors' published KITTI weights (`zjuluolun/BEVPlace` 56483fd9,
#: checkpoints/checkpoint_paper_kitti.pth.tar; the package ships them converted): trained on
#: KITTI 00 frames 0-2999 by their code's own account (`zjuluolun/BEVPlace2` 2d0636d5,
#: kitti_dataset.py lines 200-202, ``self.poses[:3000]``; the authors in BEVPlace2 issue #32),
#: BEVPlace's own database frames of 00. The evidence, and what stays uncertain: the BEVPlace
#: guide, docs/guides/reproduce-bevplace.md, "What BEVPlace's weights saw".
BEVPLACE_KITTI = TrainedOn("bev", "BEVPlace's authors' KITTI top-view images", ("00",), 1,
                           (("00", 0, 2999),))

#: The shipped weights made before weights recorded their training data, by SHA-256 (their
#: training logs: leaderboard/training-logs/{bigan,stable_afl,bigan-bev,stable_afl-bev}).
SHIPPED: dict[str, TrainedOn] = {
    "2fb62bb38102e5dcbb702c18cd8737ffe3f48617812576a445c9ce20a092512c": _SYNTH0,  # bigan
    "2cb309e7823b0d574cd6997899fd124e6eb88937c791c37e3671147a192ec83c": _SYNTH0,  # stable_afl
    "5aae9d521a8f8f1c0bbfb6f166ebcc7db1874021417fabd4e1699321975fbf78": _BEV02,  # bigan-bev
    "735310183a086408aeaf65779fc26fa2c3e588698f9b94ea7b61e5679cdb7442": _BEV02,  # stable_afl-bev
    # bevplace: the shipped conversion (baselines/weights/bevplace.safetensors), and the authors'
    # checkpoint itself (checkpoint_paper_kitti.pth.tar, read by `bevplace.load_authors_checkpoint`)
    "66a5012eab66f5185414ef4494552f9406326f3ecd133916d58e124c3698add1": BEVPLACE_KITTI,
    "10518d25d05a9484e5e51ebe2e85614514f0732dd1681303cf1ef27004d43f58": BEVPLACE_KITTI,
}


def trained_on(weights: Mapping[str, Any] | None) -> TrainedOn | None:
    """The training data of the weights a method's ``weights`` info describes (its stored
    ``trained_on``, else the shipped file's by SHA-256); None when unknown or untrained."""
    if not isinstance(weights, Mapping):
        return None
    stored = weights.get("trained_on")
    if isinstance(stored, Mapping):
        return TrainedOn.from_dict(stored)
    sha = weights.get("sha256")
    return SHIPPED.get(sha) if isinstance(sha, str) else None


#: How the note of a partly seen record begins (`seen_note`; `seen_kind` reads it back).
PARTLY_SEEN_PREFIX = "partly seen in training: "
#: What tables append to the method version (or task) of a cell seen in training, or partly.
SEEN_MARK = " (seen in training)"
PARTLY_SEEN_MARK = " (partly seen in training)"


def _task_frames(spec: Mapping[str, Any] | None, role: str) -> range | None:
    """The frames of a task's database or queries (`role`) as its spec (a record's
    ``task.spec``) states them: every `step`-th frame from its range's start (0 when it names
    none), as many as it counts; None when the spec does not say."""
    if not isinstance(spec, Mapping):
        return None
    span = spec.get("database_frames" if role == "database" else "query_frames")
    count = spec.get("n_database" if role == "database" else "n_queries")
    try:
        step = int(spec.get("step", 1))
        start = int(span[0]) if span else 0
        if isinstance(count, int) and step > 0:
            return range(start, start + count * step, step)
        return range(start, int(span[1]), step) if span and step > 0 else None
    except (TypeError, ValueError, IndexError):
        return None


def _part(frames: range, seen: int, role: str, first: int, last: int) -> str:
    """How much of one role's frames ("database" or "queries") the weights saw, in words."""
    span = f"{frames[0]}\u2013{frames[-1]}" if len(frames) else "none"
    noun = "database frames" if role == "database" else "queries"
    if seen == len(frames):
        return (f"the whole database ({len(frames)} frames, {span})" if role == "database"
                else f"all {len(frames)} queries ({span})")
    if seen == 0:
        return f"none of the {len(frames)} {noun} ({span})"
    return f"{seen} of the {len(frames)} {noun} (those in {first}\u2013{last})"


def seen_note(method_params: Mapping[str, Any], source_kind: str, source_label: str,
              sequence: str, spec: Mapping[str, Any] | None = None) -> str | None:
    """One line when the task (its source kind and label, its sequence; `spec`, its
    ``task.spec``, for its frames) is one the method's weights were trained on, wholly or partly
    (`method_params`: a record's ``method.params``, whose ``weights`` entry describes them); None
    when it is not, or the training data are unknown. Where the weights saw only a frame range
    of the sequence, the task's own frames decide (the module's docstring): a partly seen
    task's note begins with `PARTLY_SEEN_PREFIX`; one whose frames the spec does not state is
    taken as partly seen."""
    data = trained_on(method_params.get("weights"))
    if data is None or sequence not in data.sequences:
        return None
    same = (source_kind in KITTI_KINDS) if data.source_kind in KITTI_KINDS else (
        source_kind == data.source_kind and source_label == data.source)
    if not same:
        return None
    trained = f"{data.describe()}: {data.source}, frame step {data.step}"
    window = data.frame_range(sequence)
    if window is None:  # the whole sequence was seen (the text of records made before ranges)
        return (f"the weights were trained on {data.dataset} {', '.join(data.sequences)} "
                f"({data.source}, frame step {data.step}), this task's sequence {sequence}")
    first, last = window
    roles = [(role, _task_frames(spec, role)) for role in ("database", "queries")]
    known = [(role, frames) for role, frames in roles if frames is not None]
    if len(known) < len(roles):
        return (f"{PARTLY_SEEN_PREFIX}the weights were trained on {trained}; which frames of "
                f"{sequence} this task uses its record does not say")
    counts = [sum(first <= f <= last for f in frames) for _, frames in known]
    if all(c == len(frames) for c, (_, frames) in zip(counts, known, strict=True)):
        return (f"the weights were trained on {trained}; every frame this task uses of "
                f"{data.dataset} {sequence} is among them")
    if not any(counts):
        return None
    parts = [_part(frames, c, role, first, last)
             for c, (role, frames) in zip(counts, known, strict=True)]
    return (f"{PARTLY_SEEN_PREFIX}{' and '.join(parts)} of {data.dataset} {sequence} were among "
            f"the frames the weights were trained on ({trained})")


def seen_kind(note: str | None) -> str | None:
    """"seen", "partly" or None: what a record's seen note (`record_seen`) says."""
    if not note:
        return None
    return "partly" if note.startswith(PARTLY_SEEN_PREFIX) else "seen"


def seen_mark(note: str | None) -> str:
    """`SEEN_MARK`, `PARTLY_SEEN_MARK` or "", for a record's seen note (`record_seen`)."""
    kind = seen_kind(note)
    return SEEN_MARK if kind == "seen" else PARTLY_SEEN_MARK if kind == "partly" else ""


def record_seen(record: _Record) -> str | None:
    """`seen_note` of a record: the one it stores, else worked out from its method's weights
    (records made before the field existed)."""
    if record.seen_in_training:
        return record.seen_in_training
    return seen_note(record.method.params, record.task.source_kind, record.task.source_label,
                     record.task.sequence, record.task.spec)


#: What tables append to the method version (or task) of a cell scored with untrained networks.
UNTRAINED_MARK = " (untrained)"


def record_untrained(record: _Record) -> bool:
    """Whether the record's method ran its untrained (random) networks: only when asked for
    (``--weights untrained``; `make_method`), and its ``method.params.weights.source`` says so."""
    weights = record.method.params.get("weights") if isinstance(record.method.params, Mapping) else None
    return isinstance(weights, Mapping) and weights.get("source") == "untrained"
