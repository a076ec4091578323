"""Hand-made result records for the records and leaderboard tests (small, realistic curves)."""

from __future__ import annotations

import numpy as np

from safl_bench import metrics
from safl_bench.matching.presets import default_config
from safl_bench.provenance import Environment
from safl_bench.records import (
    MethodInfo,
    Metrics,
    ResultRecord,
    TaskInfo,
    Timings,
    make_mode_result,
    mode_result_from_evaluation,
)

SYNTH_LABEL = "synthetic default (seed 0)"


def curves(strength: float, n: int = 50) -> dict[str, np.ndarray]:
    """A plausible PR and ROC curve pair; larger `strength` gives a better detector."""
    recall = np.linspace(0.0, 1.0, n)
    precision = 1.0 / (1.0 + np.exp(-strength * (0.8 - recall)))
    precision = np.maximum.accumulate(precision[::-1])[::-1]  # non-increasing in recall
    fpr = np.linspace(0.0, 1.0, n)
    tpr = fpr ** (1.0 / (1.0 + strength))
    return {"precision": precision, "recall": recall, "fpr": fpr, "tpr": tpr}


def make_record(
    method: str = "stable_afl",
    *,
    method_version: str = "1",
    sequence: str = "00",
    condition: str | None = "T1R1",
    protocol: str = "paper",
    task_version: int = 0,
    seed: int = 0,
    source_kind: str = "synth",
    source_label: str = SYNTH_LABEL,
    recall: float = 0.5,
    auc: float = 0.9,
    f1: float = 0.7,
    single_recall: float | None = None,
    recall_at_1: float | None = None,
    ms: float = 10.0,
    modes: tuple[str, ...] = ("sequence", "single_frame"),
    spec_fingerprint: str = "abcd1234",
    created: str = "2025-01-01T00:00:00Z",
    deterministic: bool = True,
) -> ResultRecord:
    """A complete record; the single-frame mode scores lower than the sequence mode by default."""
    prefix = {"synth": "Synth", "kitti": "KITTI", "bev": "BEVKITTI"}[source_kind]
    suffix = {"paper": condition, "revisit": "Revisit", "bevplace": "BEVPlace"}[protocol]
    task_id = f"SAFL/{prefix}{sequence}-{suffix}-v{task_version}"
    results = {}
    for mode in modes:
        scale = 1.0 if mode == "sequence" else 0.5
        r = recall * scale if (mode == "sequence" or single_recall is None) else single_recall
        results[mode] = make_mode_result(
            Metrics(
                recall_at_100_precision=r,
                auc=auc * (1.0 if mode == "sequence" else 0.9),
                f1_max=f1 * scale,
                extended_precision=0.5 + r / 2,
                n_queries=100,
                n_positives=80,
                recall_at_1=None if recall_at_1 is None else recall_at_1 * scale,
                recall_at_n=(None if recall_at_1 is None or mode == "sequence"
                             else {"1": recall_at_1 * scale, "5": min(1.0, recall_at_1 * scale + 0.1)}),
            ),
            **curves(10.0 * auc * scale),
        )
    return ResultRecord(
        method=MethodInfo(name=method, version=method_version, params={"latent": 1024},
                          deterministic=deterministic),
        task=TaskInfo(
            id=task_id,
            version=task_version,
            protocol=protocol,
            sequence=sequence,
            condition=condition if protocol == "paper" else None,
            source_kind=source_kind,
            source_label=source_label,
            spec={"sequence": sequence, "condition": condition, "frame_step": 4},
            spec_fingerprint=spec_fingerprint,
        ),
        seed=seed,
        matcher=default_config().to_dict(),  # what a run under the default preset records
        results=results,
        timings=Timings(
            describe_ms_per_frame=ms,
            describe_frames_per_s=1000.0 / ms * 2,
            matcher_s=1.5,
            peak_memory_mb=512.0,
            repeats=5,
            how_run="sequential, pinned",
        ),
        environment=Environment(
            python="3.11.9",
            libraries={"numpy": "2.4.0", "torch": "2.13.0"},
            platform="Linux",
            cpu_model="Test CPU",
            cpu_cores=2,
            torch_threads=2,
            git_revision="0123abcd",
        ),
        created=created,
    )


def random_outcomes(seed: int, n: int = 200, skill: float = 0.7) -> metrics.Outcomes:
    """A method that answers a share `skill` of its queries correctly, more confidently."""
    rng = np.random.default_rng(seed)
    has_true = rng.random(n) < 0.9
    correct = has_true & (rng.random(n) < skill)
    band = ~correct & (rng.random(n) < 0.1)
    conf = np.where(correct, rng.normal(1.0, 1.0, n), rng.normal(0.0, 1.0, n))
    conf[rng.random(n) < 0.05] = -np.inf
    correct &= np.isfinite(conf)
    band &= np.isfinite(conf)
    rank = np.where(has_true, np.where(correct, 1, rng.integers(2, 20, n)), 0)
    return metrics.outcomes(conf, correct, has_true, ambiguous=band, true_rank=rank)


def task_outcomes(seed: int, skill: float, variant: int = 0, n: int = 200) -> metrics.Outcomes:
    """A method's answers (of `skill`; `variant` draws another method of the same skill) on the
    queries of seed `seed` of one task: every method gets the same positives and candidates."""
    truth = random_outcomes(seed, n, skill=0.9)
    o = random_outcomes(1000 * seed + 17 * variant + int(1000 * skill), n, skill=skill)
    return metrics.Outcomes(o.confidence, np.where(truth.has_true_place, o.label, -1).astype(np.int8),
                            truth.has_true_place, truth.has_candidate,
                            np.where(truth.has_true_place, np.maximum(o.true_rank, 1), 0))


def scored_record(method: str, *, seed: int = 0, skill: float = 0.7, variant: int = 0,
                  **fields: object) -> ResultRecord:
    """A `make_record` whose metrics and per-query outcomes are those of `task_outcomes` (both
    matching modes the same): a record intervals and paired differences can be computed from."""
    import dataclasses

    o = task_outcomes(seed, skill, variant)
    mode = mode_result_from_evaluation(metrics.evaluate_outcomes(o), o)
    record = make_record(method, seed=seed, **fields)  # type: ignore[arg-type]
    return dataclasses.replace(record, results={"sequence": mode, "single_frame": mode})
