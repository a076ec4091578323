"""`safl-bench train`: train a learned descriptor (BiGAN or Stable-AFL) on the training sequences.

Data: the clean top-view maps of the training sequences (KITTI 01-08 with --kitti-root; KITTI 02
with --bev-root, the top-view images, whose other sequences 00, 05 and 06 are for testing and
evaluation only; else the synthetic default's training sequences), every `--step`-th frame, from
the map cache, resampled to the method's input size.

Writes into --out (default <home>/weights/<method>-v<version>-<source>-seed<seed>, so two
versions of one method never share a run folder):
  last.safetensors     checkpoint after the last completed epoch (all networks + optimizers)
  log.jsonl            per-epoch losses, seconds and the validation AUC per condition (--val-task):
                       the data of the training-stability figure (the paper's Figure 14)
  model.safetensors    the trained encoder and decoder (+ constructor parameters)
  <method>.safetensors the encoder alone: what `describe` needs, the file to ship (<= 25 MB)
  reconstructions.png  a few training maps and their reconstructions De(En(x))
  train.json           the command, parameters, data and environment of the run
An interrupted run continues from last.safetensors with --resume.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path
from typing import Any

import numpy as np

from safl_bench.cli.options import add_bev_arguments, parse_key_values, seed, source_kind
from safl_bench.errors import ConfigError

HELP = "train a learned descriptor (bigan, stable_afl) on the training sequences"

KITTI_TRAIN_SEQUENCES = ("01", "02", "03", "04", "05", "06", "07", "08")
#: Top-view images (BEVPlace publishes 00, 02, 05, 06): 00 is the test sequence, 05 and 06 are for
#: evaluation only, so training takes 02.
BEV_TRAIN_SEQUENCES = ("02",)
BEV_HELD_OUT = ("00", "05", "06")
#: The paper protocol's test sequence (KITTI 00): training on it is warned about, never refused.
TEST_SEQUENCE = "00"

#: Validation tasks logged per epoch by default (the second test sequence, not the headline one).
DEFAULT_VAL_CONDITIONS = ("T1R1", "T10R1.5")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """--method, data, training and output options."""
    parser.add_argument("--method", required=True, help="a trainable method, e.g. stable_afl or bigan")
    parser.add_argument("--kitti-root", help="train on KITTI odometry 01-08 at this root (default: the synthetic data)")
    add_bev_arguments(parser)
    parser.add_argument("--synth-seed", type=int, default=None, help="seed of the synthetic data (default 0)")
    parser.add_argument("--sequences", help="comma-separated training sequences (default: KITTI 01-08 or the synthetic training ones)")
    parser.add_argument("--step", type=int, default=1, help="use every STEP-th frame (default 1: all)")
    parser.add_argument("--epochs", type=int, help="number of epochs (default: the method's, 20)")
    parser.add_argument("--batch-size", type=int, help="batch size (default: the method's, 64)")
    parser.add_argument("--seed", type=seed, default=0, help="training seed (default 0)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="a constructor parameter (value parsed as JSON, else a string); repeatable")
    parser.add_argument("--out", help="output directory")
    parser.add_argument("--resume", action="store_true", help="continue from the checkpoint in --out")
    parser.add_argument("--snapshot-every", type=int, metavar="K",
                        help="every K training steps also write the checkpoint (resumable there) and the "
                             "encoder as snapshots/<method>-step<N>.safetensors: the checkpoints to draw "
                             "the training-stability figure from (`safl-bench train-curve`)")
    parser.add_argument("--threads", type=int, help="torch CPU threads (default: torch's)")
    parser.add_argument("--device", help="torch device to train on, e.g. cuda (default cpu; only the CPU run is bit-reproducible)")
    parser.add_argument("--val-task", action="append", default=None, metavar="ID",
                        help="task whose AUC (sequence matcher) is logged after every epoch; repeatable; "
                             "'none' for no validation (default: sequence 09 at T1R1 and T10R1.5)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def default_val_tasks(source: str) -> list[str]:
    """Sequence 09 (KITTI or synthetic; 00 for the top-view images, which have no 09) at the
    default validation conditions."""
    from safl_bench.tasks.builtin import paper_id
    from safl_bench.views.noise import Condition

    sequence = "00" if source == "bev" else "09"
    return [paper_id(source, sequence, Condition.parse(c)) for c in DEFAULT_VAL_CONDITIONS]


def validation_callback(task_ids: list[str], source_label: str, kitti_root: str | None, progress: bool,
                        bev_root: str | None = None, bev_resolution_m: float | None = None) -> Any:
    """A `fit` callback logging, per epoch, the AUC of the sequence matcher on each task.

    The task views are rendered (or read from the map cache) once, before training starts.
    The log keys are what the leaderboard's training-stability figure reads.
    """
    from safl_bench.evaluation.cell import evaluate_method
    from safl_bench.methods.method import method_input
    from safl_bench.tasks.task import make

    tasks = []
    for task_id in task_ids:
        task = make(task_id, kitti_root=kitti_root, bev_root=bev_root, bev_resolution_m=bev_resolution_m,
                    progress=progress)
        task.prepare(["topview"])
        tasks.append(task)

    def callback(epoch: int, method: Any) -> dict[str, Any]:
        aucs: dict[str, float | None] = {}
        for task in tasks:
            result = evaluate_method(method, method_input(method, task.queries("topview")),
                                     method_input(method, task.database("topview")), task.truth,
                                     context=task.spec.context_queries)
            aucs[task.spec.condition.name] = result.metrics["sequence"].roc_auc
        return {"val_auc": aucs, "val_tasks": [t.id for t in tasks], "source": source_label}

    return callback


def load_training_maps(source: Any, sequences: list[str], step: int, progress: bool) -> tuple[np.ndarray, dict[str, int]]:
    """Clean top-view maps of every `step`-th frame of `sequences`, concatenated (an image
    source's images as they are: the caller resamples them to the method's input size)."""
    from safl_bench.views import mapcache
    from safl_bench.views.mapconfig import MapConfig
    from safl_bench.views.noise import CLEAN

    config = None if source.kind == "bev" else MapConfig()
    parts, counts = [], {}
    for name in sequences:
        frames = np.arange(0, len(source.sequence(name)), step, dtype=np.int64)
        views = mapcache.load_views(source, name, config, frames=frames, condition=CLEAN, seed=0,
                                    kind="topview", progress=progress)
        parts.append(np.asarray(views))
        counts[name] = len(frames)
    return np.concatenate(parts), counts


def main(args: argparse.Namespace) -> int:
    """Train, then write the weights, the encoder-only file, reconstructions and train.json."""
    import torch

    from safl_bench import paths
    from safl_bench.methods.method import SOURCE_WORDS, method_class, method_input, resolve_method
    from safl_bench.methods.training import CHECKPOINT, AdversarialMethod, save_reconstructions
    from safl_bench.results import provenance
    from safl_bench.sources import DataSource, bev_source, kitti_source, synth_source

    # a bare name is the version `run` runs on this data (`resolve_method`), as in every command
    picked = resolve_method(args.method, source_kind(args))
    cls = method_class(picked)
    if "@" not in args.method and cls.trainable:
        where = SOURCE_WORDS.get(source_kind(args), (source_kind(args), ""))[0]
        print(f"training {picked}: a bare {args.method!r} is the version `run` runs on {where} "
              f"(the newest with weights for it); name another as {cls.name}@VERSION", flush=True)
    if not (cls.trainable and issubclass(cls, AdversarialMethod)):
        raise ConfigError(f"method {args.method!r} has nothing to train")
    if args.step < 1:
        raise ConfigError(f"--step must be >= 1, got {args.step}")
    if args.snapshot_every is not None and args.snapshot_every < 1:
        raise ConfigError(f"--snapshot-every must be >= 1 step, got {args.snapshot_every}")
    if args.threads is not None:
        if args.threads < 1:
            raise ConfigError(f"--threads must be >= 1, got {args.threads}")
        torch.set_num_threads(args.threads)
    progress = not args.no_progress

    params = parse_key_values(args.set, "--set")
    if args.device is not None:
        params["device"] = args.device
    for key, value in (("epochs", args.epochs), ("batch_size", args.batch_size), ("seed", args.seed)):
        if value is not None:
            params[key] = value
    unknown = sorted(set(params) - set(cls._param_names()))
    if unknown:
        raise ConfigError(f"method {cls.name!r} has no parameter(s) {unknown}; valid: {cls._param_names()}")
    method = cls(**params)

    kind = source_kind(args)
    if kind != "synth" and args.synth_seed is not None:
        raise ConfigError("--synth-seed applies to the synthetic data only, not with --kitti-root or --bev-root")
    if kind == "kitti":
        sequences = args.sequences.split(",") if args.sequences else list(KITTI_TRAIN_SEQUENCES)
        if TEST_SEQUENCE in sequences:
            print(f"safl-bench: warning: training on {TEST_SEQUENCE}, the paper protocol's test "
                  "sequence: the weights record it, and their scores on it are marked as seen in "
                  "training", file=sys.stderr)
        source: DataSource = kitti_source(args.kitti_root)
        tag = "kitti"
    elif kind == "bev":
        sequences = args.sequences.split(",") if args.sequences else list(BEV_TRAIN_SEQUENCES)
        held_out = sorted(set(sequences) & set(BEV_HELD_OUT))
        if held_out:
            print(f"safl-bench: warning: training on {', '.join(held_out)}: KITTI 00 is the test "
                  "sequence and 05, 06 are for evaluation only; the weights record it, and their "
                  "scores there are marked as seen in training", file=sys.stderr)
        source = bev_source(args.bev_root, args.bev_resolution)
        tag = "bev"
    else:
        from safl_bench import synth

        seed = synth.DEFAULT_SEED if args.synth_seed is None else args.synth_seed
        sequences = args.sequences.split(",") if args.sequences else list(synth.TRAIN_SEQUENCES)
        source = synth_source(seed, sequences, progress=progress)
        tag = f"synth{seed}"

    out = Path(args.out) if args.out else paths.home() / "weights" / f"{cls.name}-v{cls.version}-{tag}-seed{method.seed}"
    if (out / CHECKPOINT).exists() and not args.resume:
        raise ConfigError(f"{out} already holds a training run; pass --resume to continue it or choose another --out")
    out.mkdir(parents=True, exist_ok=True)

    raw, counts = load_training_maps(source, sequences, args.step, progress)
    maps = method_input(method, raw)
    val_tasks = args.val_task if args.val_task is not None else default_val_tasks(kind)
    if [t.lower() for t in val_tasks] == ["none"]:
        val_tasks = []
    callback = (validation_callback(val_tasks, source.label, args.kitti_root, progress, args.bev_root,
                                    args.bev_resolution) if val_tasks else None)
    from safl_bench.methods.training_data import TrainedOn

    trained_on = TrainedOn(source.kind, source.label, tuple(sequences), args.step).to_dict()
    step_callback = None
    if args.snapshot_every is not None:
        every = args.snapshot_every

        def step_callback(done: int, trained: AdversarialMethod) -> None:
            if done % every == 0:
                snapshot_dir = out / "snapshots"
                snapshot_dir.mkdir(exist_ok=True)
                trained.save(snapshot_dir / f"{cls.name}-step{done:06d}.safetensors", parts=("encoder",),
                             trained_on={**trained_on, "steps": done})

    print(f"training {cls.name}@{cls.version} on {len(maps)} maps of {source.label} {', '.join(sequences)} -> {out}",
          file=sys.stderr)
    method.fit(maps, checkpoint_dir=out, callback=callback, progress=progress,
               checkpoint_every=args.snapshot_every, step_callback=step_callback)
    if method.iterations is not None:  # the training steps the weights hold (Table II's Weights column)
        trained_on = {**trained_on, "steps": method.iterations}
    method.save(out / "model.safetensors", parts=("encoder", "decoder"), trained_on=trained_on)
    method.save(out / f"{cls.name}.safetensors", parts=("encoder",), trained_on=trained_on)
    save_reconstructions(method, maps, out / "reconstructions.png")

    from safl_bench.common.atomic import atomic_write_json
    from safl_bench.methods.training import data_fingerprint

    env = provenance.collect_environment()
    atomic_write_json(out / "train.json", {
        "command": "safl-bench " + " ".join(shlex.quote(a) for a in sys.argv[1:]),
        "method": method.config(),
        "data": {"source": source.label, "kind": source.kind, "sequences": counts, "step": args.step,
                 "maps": len(maps), "fingerprint": data_fingerprint(maps),
                 "input": f"{raw.shape[1]}x{raw.shape[2]} views as {maps.shape[1]}x{maps.shape[2]}"},
        "environment": {"python": env.python, "libraries": env.libraries, "cpu": env.cpu_model,
                        "torch_threads": env.torch_threads, "git": env.git_revision},
    })
    print(f"wrote {out / (cls.name + '.safetensors')} (encoder, ship this), {out / 'model.safetensors'}, "
          f"{out / 'log.jsonl'}, {out / 'reconstructions.png'}")
    return 0
