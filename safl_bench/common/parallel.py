"""Fan-out of independent jobs to local worker processes or a Ray cluster.

The benchmark grid (method × task × seed cells) and map building (chunks of a sequence's frames)
are embarrassingly parallel. `run_jobs(fn, jobs, parallel)` runs `fn(*job)` for every job:

* `Parallel(workers=1)`: in this process, one after the other (the default);
* `Parallel(workers=N)`: N local processes (`concurrent.futures`, "spawn" start method, so the
  method objects and data sources are pickled to the workers; a plug-in's class must be
  importable there);
* `Parallel(ray_address=...)`: tasks on a Ray cluster (`pip install safl-bench[ray]`):
  "auto" joins the cluster this machine belongs to, "ray://host:10001" a remote one, "local"
  starts one on this machine; if Ray is already initialised in this process it is used as is.

A job that raises gets its error back; a worker process that dies (killed, out of memory) loses
only its own job. Ray reports that per task. A local process pool breaks as a whole when one
of its workers dies, so the jobs it was running are rerun one by one in fresh single-worker
pools: the job that kills its worker again fails alone, the others complete.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from safl_bench.errors import ConfigError


@dataclass(frozen=True)
class Parallel:
    """Where jobs run: `workers` local processes, or the Ray cluster at `ray_address`."""

    workers: int = 1
    ray_address: str | None = None

    def __post_init__(self) -> None:
        if isinstance(self.workers, bool) or not isinstance(self.workers, int) or self.workers < 1:
            raise ConfigError(f"--workers must be an integer >= 1, got {self.workers!r}")
        if self.ray_address is not None and self.workers != 1:
            raise ConfigError("give either --workers or --ray, not both")

    @property
    def serial(self) -> bool:
        return self.workers == 1 and self.ray_address is None

    def slots(self) -> int:
        """How many jobs can run at once (Ray: the cluster's CPUs)."""
        if self.ray_address is None:
            return self.workers
        _ray_init(self.ray_address)
        import ray

        return max(1, int(ray.cluster_resources().get("CPU", 1)))

    def describe(self) -> str:
        if self.ray_address is not None:
            return f"Ray cluster ({self.ray_address})"
        return "this process" if self.workers == 1 else f"{self.workers} local worker processes"


@dataclass
class JobResult:
    """The value of one job, or the error that stopped it (value None)."""

    value: Any = None
    error: str | None = None


def run_jobs(
    fn: Callable[..., Any],
    jobs: Sequence[tuple[Any, ...]],
    parallel: Parallel,
    *,
    on_done: Callable[[int, JobResult], None] | None = None,
) -> list[JobResult]:
    """Run `fn(*job)` for each job; results in job order. `on_done(i, result)` is called in
    this process as each job finishes (e.g. for a progress bar)."""
    results: list[JobResult | None] = [None] * len(jobs)

    def done(i: int, result: JobResult) -> None:
        results[i] = result
        if on_done is not None:
            on_done(i, result)

    if not jobs:
        return []
    if parallel.serial:
        for i, job in enumerate(jobs):
            try:
                done(i, JobResult(fn(*job)))
            except Exception as exc:
                done(i, JobResult(error=_message(exc)))
    elif parallel.ray_address is not None:
        _run_ray(fn, jobs, parallel.ray_address, done)
    else:
        _run_local(fn, jobs, parallel.workers, done)
    return [r if r is not None else JobResult(error="not run") for r in results]


def _message(exc: BaseException) -> str:
    text = str(exc).strip()
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _run_local(fn: Callable[..., Any], jobs: Sequence[tuple[Any, ...]], workers: int,
               done: Callable[[int, JobResult], None]) -> None:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    context = multiprocessing.get_context("spawn")
    broken: list[int] = []
    pool = ProcessPoolExecutor(max_workers=min(workers, len(jobs)), mp_context=context)
    try:
        futures = {pool.submit(fn, *job): i for i, job in enumerate(jobs)}
        for future in as_completed(futures):
            i = futures[future]
            exc = future.exception()
            if isinstance(exc, BrokenProcessPool):
                broken.append(i)
            elif exc is not None:
                done(i, JobResult(error=_message(exc)))
            else:
                done(i, JobResult(future.result()))
    except BaseException:  # e.g. Ctrl-C: do not wait for the queued jobs
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()
    for i in sorted(broken):  # alone, so that a job that kills its worker fails by itself
        with ProcessPoolExecutor(max_workers=1, mp_context=context) as pool:
            future = pool.submit(fn, *jobs[i])
            exc = future.exception()
            if isinstance(exc, BrokenProcessPool):
                done(i, JobResult(error="its worker process died (killed or out of memory)"))
            elif exc is not None:
                done(i, JobResult(error=_message(exc)))
            else:
                done(i, JobResult(future.result()))


def _ray_init(address: str) -> None:
    try:
        import ray
    except ImportError:
        raise ConfigError("--ray needs Ray: pip install 'safl-bench[ray]'") from None
    if not ray.is_initialized():
        try:
            ray.init(address=None if address == "local" else address, log_to_driver=False,
                     include_dashboard=False)
        except (ConnectionError, ValueError, RuntimeError, TimeoutError) as exc:
            lines = [line for line in str(exc).splitlines() if line.strip()]
            hint = " (start one with `ray start --head`, or use --ray local)" if address == "auto" else ""
            raise ConfigError(f"--ray {address}: cannot join the Ray cluster{hint}: "
                              f"{lines[0] if lines else type(exc).__name__}") from None


def _run_ray(fn: Callable[..., Any], jobs: Sequence[tuple[Any, ...]], address: str,
             done: Callable[[int, JobResult], None]) -> None:
    _ray_init(address)
    import ray

    remote = ray.remote(num_cpus=1, max_retries=0)(fn)
    pending = {remote.remote(*job): i for i, job in enumerate(jobs)}
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        ref = ready[0]
        i = pending.pop(ref)
        try:
            done(i, JobResult(ray.get(ref)))
        except ray.exceptions.RayTaskError as exc:  # the job raised
            done(i, JobResult(error=_message(getattr(exc, "cause", None) or exc)))
        except (ray.exceptions.WorkerCrashedError, ray.exceptions.NodeDiedError) as exc:
            done(i, JobResult(error=f"its Ray worker died ({type(exc).__name__})"))
        except ray.exceptions.RayError as exc:  # e.g. the job could not be unpickled there
            lines = [line for line in str(exc).splitlines() if line.strip()]
            done(i, JobResult(error=f"{type(exc).__name__}: {lines[-1] if lines else ''}"))
