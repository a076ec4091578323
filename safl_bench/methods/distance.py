"""Difference matrices between query and database descriptors.

The paper's difference (Eq. 4) is the squared Euclidean distance between latent codes. Computed
as ``|q|^2 + |b|^2 - 2 q.b`` so that the bulk of the work is one BLAS matrix product; the
descriptors are first centred on the database mean (the distance is translation invariant), which
keeps the norms small and limits the cancellation of the expansion in float32. The result is
clamped at 0. Work is done in query chunks so that temporaries stay small: the only large array
is the (Nq, Ndb) output itself. `euclidean` is its square root: the plain L2 norm that the
paper's authors compare descriptors with (``Euclidean`` in src/util/utils.py lines 72-77 at
commit ``25be0fd`` of CNN-GAN/Top-Mapping), which the evaluation setting ``distance=euclidean``
selects (`safl_bench.evaluation.cell`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from safl_bench.errors import DataError

_DTYPES = {"float32": np.float32, "float64": np.float64}


def _as_descriptors(x: np.ndarray, what: str) -> np.ndarray:
    arr = np.asarray(x)
    if arr.ndim != 2:
        raise DataError(f"{what} descriptors must be a 2-D (N, D) array, got shape {arr.shape}")
    if arr.shape[0] == 0 or arr.shape[1] == 0:
        raise DataError(f"{what} descriptors are empty (shape {arr.shape})")
    if not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr):
        raise DataError(f"{what} descriptors must be real numbers, got dtype {arr.dtype}")
    if not np.isfinite(arr).all():
        raise DataError(f"{what} descriptors contain NaN or infinite values")
    return arr


def sqeuclidean(
    queries: np.ndarray,
    database: np.ndarray,
    *,
    dtype: str = "float32",
    chunk_rows: int = 1024,
) -> np.ndarray:
    """Squared Euclidean distances, shape (Nq, Ndb), lower = more similar (paper Eq. 4).

    ``dtype`` is the precision of the product and the result ("float32" or "float64").
    """
    if dtype not in _DTYPES:
        raise DataError(f"dtype must be one of {sorted(_DTYPES)}, got {dtype!r}")
    if chunk_rows < 1:
        raise DataError(f"chunk_rows must be >= 1, got {chunk_rows}")
    q = _as_descriptors(queries, "query")
    b = _as_descriptors(database, "database")
    if q.shape[1] != b.shape[1]:
        raise DataError(
            f"query and database descriptors differ in length: {q.shape[1]} vs {b.shape[1]}"
        )
    ft: Any = _DTYPES[dtype]
    centre = b.mean(axis=0, dtype=np.float64)
    bc = np.ascontiguousarray((b - centre).astype(ft, copy=False))
    bn = np.einsum("ij,ij->i", bc, bc, dtype=ft)
    bt = bc.T
    out = np.empty((q.shape[0], b.shape[0]), dtype=ft)
    for lo in range(0, q.shape[0], chunk_rows):
        hi = min(lo + chunk_rows, q.shape[0])
        qc = (q[lo:hi] - centre).astype(ft, copy=False)
        qn = np.einsum("ij,ij->i", qc, qc, dtype=ft)
        block = out[lo:hi]
        np.matmul(qc, bt, out=block)
        block *= -2.0
        block += qn[:, None]
        block += bn[None, :]
        np.maximum(block, 0.0, out=block)
    return out


def euclidean(queries: np.ndarray, database: np.ndarray, *, dtype: str = "float32") -> np.ndarray:
    """Euclidean (L2, not squared) distances, shape (Nq, Ndb), lower = more similar, in `dtype`.

    The square root of `sqeuclidean` computed in float64: the root magnifies the expansion's
    cancellation near 0 (a float32 square of 1e-7 would become a distance of 3e-4)."""
    if dtype not in _DTYPES:
        raise DataError(f"dtype must be one of {sorted(_DTYPES)}, got {dtype!r}")
    return np.sqrt(sqeuclidean(queries, database, dtype="float64")).astype(_DTYPES[dtype])
