"""Batch classification over worker processes (the machine's cores), in input order.

Each worker rebuilds its own :class:`~fixplan.jamming.classify.Classifier` from the contact set
(solver objects are not shared between processes) and classifies a contiguous chunk. Small
batches run in-process: starting workers costs more than it saves below a few hundred wrenches.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from numpy.typing import NDArray

from fixplan.jamming.classify import Classifier
from fixplan.kinematics import ContactSet
from fixplan.settings import DEFAULT, Tolerances, WitnessSettings

FloatArray = NDArray[np.float64]
PARALLEL_MIN = 400  # wrenches below which one process is faster


def _encode(r: dict) -> str | dict:
    """One result as compact strict JSON text (its dictionary if a number is not finite: the caller reports it)."""
    try:
        return json.dumps(r, separators=(",", ":"), allow_nan=False)
    except (ValueError, TypeError):
        return r


def _finish(out: list, as_json: bool | str) -> list:
    if not as_json:
        return out
    dicts = [r.to_json() for r in out]
    return [_encode(d) for d in dicts] if as_json == "text" else dicts


def _chunk(args: tuple) -> list:
    cs, gravity, tol, backend, W_com, W_given, as_json, witness = args
    clf = Classifier(cs, gravity, tolerances=tol, backend=backend, witness=witness)
    out = [clf.classify(w, g) for w, g in zip(W_com, W_given, strict=True)]
    return _finish(out, as_json)


def default_jobs() -> int:
    """Worker count: the CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def classify_batch(
    cs: ContactSet,
    gravity: FloatArray,
    tol: Tolerances,
    backend: str,
    W_com: FloatArray,
    W_given: FloatArray,
    *,
    jobs: int | None = None,
    progress: Callable[[int], None] | None = None,
    as_json: bool | str = False,
    witness: WitnessSettings = DEFAULT.witness,
) -> list:
    """Classify every row of ``W_com`` (about the centre of mass); results in input order.

    With ``as_json`` the results come back as their JSON dictionaries, built in the workers;
    with ``as_json="text"`` as compact strict JSON text, also encoded in the workers (a result
    with a non-finite number stays a dictionary, for the caller to report).
    """
    n = W_com.shape[0]
    jobs = default_jobs() if jobs is None else max(1, jobs)
    if jobs == 1 or n < PARALLEL_MIN or backend != "clarabel":
        clf = Classifier(cs, gravity, tolerances=tol, backend=backend, witness=witness)
        out = []
        for i in range(n):
            out.append(clf.classify(W_com[i], W_given[i]))
            if progress is not None and (i + 1) % 100 == 0:
                progress(100)
        if progress is not None and n % 100:
            progress(n % 100)
        return _finish(out, as_json)
    n_chunks = max(jobs * 4, 1)
    bounds = np.linspace(0, n, n_chunks + 1).astype(int)
    tasks = [
        (cs, gravity, tol, backend, W_com[a:b], W_given[a:b], as_json, witness)
        for a, b in zip(bounds[:-1], bounds[1:], strict=True)
        if b > a
    ]
    results: list[list] = [[] for _ in tasks]
    ctx = mp.get_context("fork") if "fork" in mp.get_all_start_methods() else mp.get_context()
    with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx) as pool:
        futures = {pool.submit(_chunk, t): i for i, t in enumerate(tasks)}
        from concurrent.futures import as_completed

        for fut in as_completed(futures):
            i = futures[fut]
            results[i] = fut.result()
            if progress is not None:
                progress(len(results[i]))
    return [r for chunk in results for r in chunk]
