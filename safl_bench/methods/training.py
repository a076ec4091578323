"""Adversarial feature learning: the shared base class of BiGAN and Stable-AFL and its
deterministic, resumable training loop.

`AdversarialMethod` holds an encoder En (the descriptor), a decoder De and whatever critics a
subclass adds; a subclass implements `build_networks`, `build_optimizers` and `train_step`.
`fit(maps, epochs=, batch_size=, seed=, checkpoint_dir=, callback=)`:

* is deterministic for a seed on the CPU: the networks are initialised from `seed`, and each
  epoch draws its batch order and noise from a `torch.Generator` (and the global torch RNG, for
  dropout) seeded from (seed, epoch), so an epoch does not depend on how the run got there. The
  CPU kernels used (convolutions, matrix products, batch norm) are deterministic for a fixed
  thread count, which the tests check; `torch.use_deterministic_algorithms` is not switched on
  because on this torch it imports the inductor compiler (5 s) and changes nothing on the CPU;
* after every epoch, when `checkpoint_dir` is given, atomically writes `last.safetensors` (all
  networks + flattened optimizer states; scalars as JSON metadata; see `safl_bench.methods.weights`)
  and `log.jsonl` (one JSON object per epoch: mean losses, steps, seconds, and whatever
  `callback(epoch, method)` returns, e.g. a validation AUC);
* resumes from `last.safetensors` when it exists (same parameters and data required), so
  "2 epochs" and "1 epoch, interrupted, then resumed to 2" give identical weights.

An epoch is one pass over the shuffled maps in batches (the last incomplete batch is dropped);
a training step consumes `batches_per_step` batches (WGAN's critic iterations each take a
fresh batch, as in Arjovsky et al.'s reference code).

A method may count its training in steps instead of epochs (an `iterations` parameter, as the
authors' code does): training then runs exactly that many steps, across epochs, and stops
inside an epoch when the count says so. `checkpoint_every=K` also writes the checkpoint every K
steps, with the state of both random streams, so a run interrupted inside an epoch resumes
there and ends with the same weights; `step_callback(step, method)` runs after every step (the
`train` command saves the encoder every K steps with it: the checkpoints the paper's Figure 14
is drawn from).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, ClassVar, Self

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from safl_bench.common.atomic import atomic_write_text
from safl_bench.common.fingerprint import fingerprint
from safl_bench.errors import ConfigError, DataError
from safl_bench.methods.method import Method, Views, as_topview
from safl_bench.methods.weights import (
    load_module_tensors,
    load_optimizer_tensors,
    load_tensors,
    module_tensors,
    optimizer_tensors,
    save_tensors,
)

CHECKPOINT = "last.safetensors"
LOG = "log.jsonl"

Callback = Callable[[int, "AdversarialMethod"], dict[str, Any] | None]
StepCallback = Callable[[int, "AdversarialMethod"], None]


def epoch_seed(seed: int, epoch: int) -> int:
    """The RNG seed of one epoch, derived from the run's seed (independent streams)."""
    return int(np.random.SeedSequence([int(seed), int(epoch)]).generate_state(1, np.uint64)[0] >> 1)


def data_fingerprint(x: np.ndarray) -> str:
    """Fingerprint of a training set (shape + bytes), stored in checkpoints."""
    import hashlib

    digest = hashlib.sha256(np.ascontiguousarray(x).tobytes()).hexdigest()[:16]
    return fingerprint(list(x.shape), str(x.dtype), digest)


class AdversarialMethod(Method):
    """Base class of encoder-based adversarial feature learners (see the module docstring).

    Subclasses set `self.code_size`, `self.image_size`, `self.width`, `self.seed`, `self.epochs`,
    `self.batch_size`, `self.prior`, `self.describe_batch` in their constructor and call
    `self._init_networks()` at its end.
    """

    trainable = True
    runtime_params: ClassVar[tuple[str, ...]] = ("describe_batch", "device")
    #: networks that make up a saved inference model (the encoder alone suffices to describe)
    inference_parts: ClassVar[tuple[str, ...]] = ("encoder", "decoder")

    code_size: int
    image_size: int
    width: int
    encoder_width: int
    seed: int
    epochs: int
    batch_size: int
    prior: str
    describe_batch: int
    device: str
    #: training length in steps, for methods that count it so (None: `epochs` epochs)
    iterations: int | None = None

    # -- to implement --------------------------------------------------------------------------
    def build_networks(self) -> dict[str, nn.Module]:
        """All networks, freshly initialised (the global torch RNG is seeded by the caller)."""
        raise NotImplementedError

    def build_optimizers(self) -> dict[str, torch.optim.Optimizer]:
        """The optimizers over `self.nets`."""
        raise NotImplementedError

    def train_step(self, batches: Sequence[torch.Tensor], gen: torch.Generator) -> dict[str, float]:
        """One training step on `batches_per_step` batches of (B,1,S,S) maps in [-1,1]."""
        raise NotImplementedError

    @property
    def batches_per_step(self) -> int:
        return 1

    # -- networks ------------------------------------------------------------------------------
    def _init_networks(self) -> None:
        if self.prior not in ("uniform", "normal"):
            raise ConfigError(f"{self.name}: prior must be 'uniform' or 'normal', got {self.prior!r}")
        counted = ("iterations",) if self.iterations is not None else ("epochs",)
        for key in ("code_size", "width", "encoder_width", *counted, "batch_size", "describe_batch"):
            value = getattr(self, key)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ConfigError(f"{self.name}: {key} must be a positive integer, got {value!r}")
        try:
            self._device = torch.device(self.device)
        except (RuntimeError, TypeError) as exc:
            raise ConfigError(f"{self.name}: not a torch device: {self.device!r}") from exc
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(int(self.seed))
            self.nets: dict[str, nn.Module] = self._on_device(self.build_networks())
        self.optims: dict[str, torch.optim.Optimizer] | None = None
        self._loaded_parts: tuple[str, ...] = tuple(self.nets)
        for net in self.nets.values():
            net.eval()

    def _on_device(self, nets: dict[str, nn.Module]) -> dict[str, nn.Module]:
        """Networks are built on the CPU (seeded, device-independent) and then moved."""
        return {k: v.to(self._device) for k, v in nets.items()}

    @property
    def encoder(self) -> nn.Module:
        return self.nets["encoder"]

    @property
    def decoder(self) -> nn.Module:
        return self.nets["decoder"]

    def sample_prior(self, n: int, gen: torch.Generator) -> torch.Tensor:
        """z ~ P_z: uniform on [-1, 1]^d (BiGAN's choice; default) or standard normal."""
        if self.prior == "uniform":
            z = torch.rand(n, self.code_size, generator=gen) * 2.0 - 1.0
        else:
            z = torch.randn(n, self.code_size, generator=gen)
        return z.to(self._device)

    def to_input(self, maps: Views) -> torch.Tensor:
        """Maps (N,H,W) in [0,1] -> (N,1,S,S) in [-1,1], resized to image_size if needed."""
        arr = as_topview(maps)
        x = torch.from_numpy(np.ascontiguousarray(arr))[:, None]
        if x.shape[-2:] != (self.image_size, self.image_size) and len(x):
            x = F.interpolate(x, size=(self.image_size, self.image_size), mode="bilinear",
                              antialias=True, align_corners=False)
        return x * 2.0 - 1.0

    # -- inference -----------------------------------------------------------------------------
    def describe(self, maps: Views) -> np.ndarray:
        """En(x): (N, code_size) float32, eval mode, no gradients, in chunks of describe_batch."""
        x = self.to_input(maps)
        enc = self.encoder
        if enc.training:
            enc.eval()
        out = np.empty((len(x), self.code_size), np.float32)
        with torch.inference_mode():
            for lo in range(0, len(x), self.describe_batch):
                chunk = x[lo : lo + self.describe_batch].to(self._device)
                out[lo : lo + self.describe_batch] = enc(chunk).cpu().numpy()
        return out

    def reconstruct(self, maps: Views) -> np.ndarray:
        """De(En(x)) as maps in [0, 1], (N, S, S) float32."""
        if "decoder" not in self._loaded_parts:
            raise ConfigError(f"{self.name}: these weights hold no decoder, so nothing can be reconstructed")
        x = self.to_input(maps)
        with torch.inference_mode():
            self.encoder.eval()
            self.decoder.eval()
            rec = self.decoder(self.encoder(x.to(self._device)))[:, 0].cpu()
        return ((rec + 1.0) / 2.0).clamp(0.0, 1.0).numpy().astype(np.float32)

    # -- state ---------------------------------------------------------------------------------
    def state_tensors(self, parts: Sequence[str] | None = None) -> dict[str, torch.Tensor]:
        names = tuple(parts) if parts else self.inference_parts
        unknown = [p for p in names if p not in self.nets]
        if unknown:
            raise ConfigError(f"{self.name}: no network(s) {unknown}; have {sorted(self.nets)}")
        missing = [p for p in names if p not in self._loaded_parts]
        if missing:
            raise ConfigError(f"{self.name}: network(s) {missing} were not loaded, so cannot be saved")
        return module_tensors({p: self.nets[p] for p in names})

    def load_state_tensors(self, tensors: dict[str, torch.Tensor], *, source: str) -> None:
        present = tuple(p for p in self.nets if any(k.startswith(f"net/{p}/") for k in tensors))
        if "encoder" not in present:
            raise DataError(f"{source} holds no encoder weights for {self.name}")
        load_module_tensors({p: self.nets[p] for p in present}, tensors, source=source)
        self._loaded_parts = present
        for net in self.nets.values():
            net.eval()

    # -- training ------------------------------------------------------------------------------
    def fit(
        self,
        maps: Views,
        *,
        epochs: int | None = None,
        batch_size: int | None = None,
        seed: int | None = None,
        checkpoint_dir: str | Path | None = None,
        callback: Callback | None = None,
        progress: bool = False,
        checkpoint_every: int | None = None,
        step_callback: StepCallback | None = None,
    ) -> Self:
        """Train from scratch (or resume from `checkpoint_dir`); see the module docstring.

        `epochs`, `batch_size` and `seed` default to the constructor's values and, when given,
        replace them (so `config()` and saved weights record what was actually run)."""
        self.set_params(**{k: v for k, v in (("epochs", epochs), ("batch_size", batch_size), ("seed", seed)) if v is not None})
        train(self, maps, checkpoint_dir=checkpoint_dir, callback=callback, progress=progress,
              checkpoint_every=checkpoint_every, step_callback=step_callback)
        return self


def _checkpoint_key(method: AdversarialMethod, data_fp: str) -> dict[str, Any]:
    params = {k: v for k, v in method.get_params().items()
              if k not in ("epochs", "iterations", *method.runtime_params)}
    return {"name": method.name, "version": method.version, "params": params, "data": data_fp}


def save_checkpoint(method: AdversarialMethod, directory: Path, epoch: int, key: dict[str, Any],
                    step: int = 0, rng: dict[str, torch.Tensor] | None = None) -> None:
    """Write every network and optimizer state after `epoch` completed epochs and `step` steps
    of the next one (atomic); `rng` holds the random streams' states when `step` > 0."""
    assert method.optims is not None
    tensors = module_tensors(method.nets)
    opt_tensors, opt_scalars = optimizer_tensors(method.optims)
    tensors.update(opt_tensors)
    tensors.update({f"rng/{k}": v for k, v in (rng or {}).items()})
    save_tensors(directory / CHECKPOINT, tensors, {"kind": "checkpoint", "epoch": epoch, "step": step,
                                                   "key": key, "optimizers": opt_scalars})


def load_checkpoint(method: AdversarialMethod, directory: Path, key: dict[str, Any]) -> tuple[int, int, dict[str, torch.Tensor]]:
    """Restore networks and optimizers from `directory`; returns the completed epochs, the
    steps done in the next one and the random streams' states saved with them."""
    path = directory / CHECKPOINT
    tensors, meta = load_tensors(path)
    if meta.get("kind") != "checkpoint":
        raise DataError(f"{path} is not a training checkpoint")
    if meta.get("key") != json.loads(json.dumps(key)):
        raise ConfigError(
            f"the checkpoint {path} was made with other settings or data "
            f"({meta.get('key')} vs {key}); use another output directory or remove it"
        )
    assert method.optims is not None
    rng = {k.removeprefix("rng/"): tensors.pop(k) for k in [k for k in tensors if k.startswith("rng/")]}
    load_module_tensors(method.nets, tensors, source=path)
    load_optimizer_tensors(method.optims, tensors, meta["optimizers"], source=path)
    return int(meta["epoch"]), int(meta.get("step", 0)), rng


def read_log(directory: Path, upto: int) -> list[dict[str, Any]]:
    """The per-epoch log records of epochs 1..upto."""
    path = directory / LOG
    if not path.is_file():
        return []
    records = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    return [r for r in records if r.get("epoch", 0) <= upto]


def write_log(directory: Path, records: list[dict[str, Any]]) -> None:
    atomic_write_text(directory / LOG, "".join(json.dumps(r, sort_keys=True) + "\n" for r in records))


def train(
    method: AdversarialMethod,
    maps: Views,
    *,
    checkpoint_dir: str | Path | None = None,
    callback: Callback | None = None,
    progress: bool = False,
    checkpoint_every: int | None = None,
    step_callback: StepCallback | None = None,
) -> list[dict[str, Any]]:
    """The training loop behind `AdversarialMethod.fit`; returns the per-epoch log."""
    x_all = method.to_input(maps)
    n, batch, k = len(x_all), method.batch_size, method.batches_per_step
    steps = (n // batch) // k
    if steps < 1:
        raise ConfigError(
            f"{method.name}: {n} training maps are too few for batch_size={batch} with {k} "
            f"batch(es) per step; need at least {batch * k}"
        )
    if checkpoint_every is not None and checkpoint_every < 1:
        raise ConfigError(f"checkpoint_every must be a positive number of steps, got {checkpoint_every!r}")
    directory = Path(checkpoint_dir) if checkpoint_dir is not None else None
    key = _checkpoint_key(method, data_fingerprint(x_all.numpy()))
    total = method.iterations if method.iterations is not None else method.epochs * steps

    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(method.seed))
        method.nets = method._on_device(method.build_networks())
        method.optims = method.build_optimizers()
        method._loaded_parts = tuple(method.nets)
        done, done_steps = 0, 0
        rng: dict[str, torch.Tensor] = {}
        log: list[dict[str, Any]] = []
        if directory is not None and (directory / CHECKPOINT).is_file():
            done, done_steps, rng = load_checkpoint(method, directory, key)
            log = read_log(directory, done)
            if done * steps + done_steps > total:
                raise ConfigError(
                    f"the checkpoint in {directory} holds {done * steps + done_steps} training steps, more "
                    f"than the {total} asked for; ask for at least that many or use another output directory")

        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=max(total - done * steps - done_steps, 0), desc=f"train {method.name}", unit="step")
        epoch = done
        while epoch * steps < total:
            started = time.perf_counter()
            gen = torch.Generator().manual_seed(epoch_seed(method.seed, epoch))
            torch.manual_seed(epoch_seed(method.seed, epoch) ^ 0x5EED)
            for net in method.nets.values():
                net.train()
            order = torch.randperm(n, generator=gen)
            first, done_steps = done_steps, 0
            if first:  # resuming inside this epoch: the streams continue where they were
                gen.set_state(rng["gen"])
                torch.set_rng_state(rng["torch"])
            last = min(steps, total - epoch * steps)
            sums: dict[str, float] = {}
            for s in range(first, last):
                batches = [x_all[order[(s * k + j) * batch : (s * k + j + 1) * batch]].to(method._device)
                           for j in range(k)]
                for name, value in method.train_step(batches, gen).items():
                    sums[name] = sums.get(name, 0.0) + float(value)
                done_now = epoch * steps + s + 1
                if step_callback is not None:
                    step_callback(done_now, method)
                if (directory is not None and checkpoint_every is not None and s + 1 < last
                        and done_now % checkpoint_every == 0):
                    save_checkpoint(method, directory, epoch, key, step=s + 1,
                                    rng={"gen": gen.get_state(), "torch": torch.get_rng_state()})
                if bar is not None:
                    bar.update(1)
                    bar.set_postfix({name: f"{v / (s + 1 - first):.3g}" for name, v in list(sums.items())[:3]})
            for net in method.nets.values():
                net.eval()
            ran = last - first
            record: dict[str, Any] = {"epoch": epoch + 1, "steps": last}
            record.update({name: v / max(ran, 1) for name, v in sums.items()})
            record["seconds"] = round(time.perf_counter() - started, 3)
            if first:
                record["resumed_at_step"] = first
            if callback is not None:
                record.update(callback(epoch + 1, method) or {})
            log.append(record)
            if directory is not None:
                if last == steps:
                    save_checkpoint(method, directory, epoch + 1, key)
                else:  # the run ends inside this epoch
                    save_checkpoint(method, directory, epoch, key, step=last,
                                    rng={"gen": gen.get_state(), "torch": torch.get_rng_state()})
                write_log(directory, log)
            if last < steps:
                break
            epoch += 1
        if bar is not None:
            bar.close()
    for net in method.nets.values():
        net.eval()
    return log


def save_reconstructions(method: AdversarialMethod, maps: Views, path: str | Path, n: int = 8) -> Path:
    """A PNG of `n` maps (top row) and their reconstructions De(En(x)) (bottom row)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from safl_bench.common.atomic import atomic_path

    arr = as_topview(maps)
    if len(arr) == 0:
        raise DataError("no maps to reconstruct")
    idx = np.linspace(0, len(arr) - 1, min(n, len(arr))).round().astype(int)
    originals = method.to_input(arr[idx])[:, 0].numpy() * 0.5 + 0.5
    recs = method.reconstruct(arr[idx])
    fig = Figure(figsize=(1.6 * len(idx), 3.4))
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, len(idx), squeeze=False)
    for col in range(len(idx)):
        for row, (img, label) in enumerate(((originals[col], "x"), (recs[col], "De(En(x))"))):
            ax = axes[row][col]
            ax.imshow(img, cmap="gray", vmin=0.0, vmax=1.0, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if col == 0:
                ax.set_ylabel(label)
    fig.suptitle(f"{method.name}: maps (top) and reconstructions (bottom)")
    fig.tight_layout()
    out = Path(path)
    with atomic_path(out) as tmp:
        fig.savefig(tmp, format="png", dpi=100)
    return out
