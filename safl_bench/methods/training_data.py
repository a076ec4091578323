"""Which data a method's weights were trained on, and whether a record's task is among them.

Weights written by `safl-bench train` carry ``trained_on`` in their metadata (`TrainedOn`:
the data set, the source's kind and label, the sequences, the frame step), and `Method.load`
copies it into the method's ``weights`` info, so every record names it. The weights shipped
before that metadata existed are known by their SHA-256 (`SHIPPED`, from their training logs
in leaderboard/training-logs/<name>/train.json). Weights with neither (BEVPlace's authors'
checkpoint, whose training data the file does not say) are never marked.

A record is SEEN IN TRAINING when its task's sequence is one the weights were trained on, in
the same data set: real KITTI whether read as scans (``kitti``) or as top-view images
(``bev``), since both are the same drive; a synthetic sequence only in the same synthetic data
(its label names the generator's seed). Its scores measure memory, not generalisation:
`seen_note` says so in the record (``seen_in_training``), the run table marks it and the
leaderboard never ranks it beside clean cells.

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

    @property
    def dataset(self) -> str:
        """Which data set the sequences name: "KITTI" for scans and top views alike."""
        return "KITTI" if self.source_kind in KITTI_KINDS else self.source

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "sequences": list(self.sequences)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TrainedOn | None:
        """The `TrainedOn` a weights file or record stores; None when it holds none or garbage."""
        try:
            return cls(str(data["source_kind"]), str(data["source"]),
                       tuple(str(s) for s in data["sequences"]), int(data.get("step", 1)))
        except (KeyError, TypeError, ValueError):
            return None


_SYNTH0 = TrainedOn("synth", "synthetic default (seed 0)", ("01", "02", "03", "04"), 1)
_BEV02 = TrainedOn("bev", "KITTI top-view images", ("02",), 4)

#: The shipped weights made before weights recorded their training data, by SHA-256 (their
#: training logs: leaderboard/training-logs/{bigan,stable_afl,bigan-bev,stable_afl-bev}).
SHIPPED: dict[str, TrainedOn] = {
    "2fb62bb38102e5dcbb702c18cd8737ffe3f48617812576a445c9ce20a092512c": _SYNTH0,  # bigan
    "2cb309e7823b0d574cd6997899fd124e6eb88937c791c37e3671147a192ec83c": _SYNTH0,  # stable_afl
    "5aae9d521a8f8f1c0bbfb6f166ebcc7db1874021417fabd4e1699321975fbf78": _BEV02,  # bigan-bev
    "735310183a086408aeaf65779fc26fa2c3e588698f9b94ea7b61e5679cdb7442": _BEV02,  # stable_afl-bev
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


def seen_note(method_params: Mapping[str, Any], source_kind: str, source_label: str,
              sequence: str) -> str | None:
    """One line when the task (its source kind and label, its sequence) is one the method's
    weights were trained on (`method_params`: a record's ``method.params``, whose ``weights``
    entry describes them); None when it is not, or the training data are unknown."""
    data = trained_on(method_params.get("weights"))
    if data is None or sequence not in data.sequences:
        return None
    same = (source_kind in KITTI_KINDS) if data.source_kind in KITTI_KINDS else (
        source_kind == data.source_kind and source_label == data.source)
    if not same:
        return None
    return (f"the weights were trained on {data.dataset} {', '.join(data.sequences)} "
            f"({data.source}, frame step {data.step}), this task's sequence {sequence}")


def record_seen(record: _Record) -> str | None:
    """`seen_note` of a record: the one it stores, else worked out from its method's weights
    (records made before the field existed)."""
    if record.seen_in_training:
        return record.seen_in_training
    return seen_note(record.method.params, record.task.source_kind, record.task.source_label,
                     record.task.sequence)


#: What tables append to the method version (or task) of a cell scored with untrained networks.
UNTRAINED_MARK = " (untrained)"


def record_untrained(record: _Record) -> bool:
    """Whether the record's method ran its untrained (random) networks: only when asked for
    (``--weights untrained``; `make_method`), and its ``method.params.weights.source`` says so."""
    weights = record.method.params.get("weights") if isinstance(record.method.params, Mapping) else None
    return isinstance(weights, Mapping) and weights.get("source") == "untrained"
