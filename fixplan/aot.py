"""Kernels compiled ahead of time: numba's own code for the solve path, loaded without numba.

Why. A ``fixplan solve`` of a 2D plate spent about as long starting numba as planning: its
import (0.27 s) and, on the first kernel loaded from the on-disk cache, the set-up of its typing
and lowering registries (0.45 s), in every process (a 3D solve the same, a fifth of its time). ``python -m fixplan.cli.precompile`` (run by
``make install``) therefore also compiles the kernels of :data:`EXPORTS` with ``numba.pycc``
into one extension module beside this file, ``fixplan/_aot<suffix>``, and writes
``fixplan/_aot.json``: for every export, the argument types it was compiled for. Those types are
read from the JIT dispatchers after the precompile workloads ran the real commands, so they are
the signatures the commands use, not a hand-written list.

Same code. The extension is compiled from the same Python source by the same compiler, for the
host CPU like the JIT; ``tests/test_aot.py`` pins every export to its JIT twin, bit for bit.

When it is used. :func:`kernel` hands out the compiled function only when the extension exists,
imports, and was built from this very source: the SHA-256 of every ``.py`` file of the package
and of the Python and NumPy versions (:func:`fingerprint`) must equal the one the build recorded
in the manifest and compiled into the extension. Otherwise, or with ``FIXPLAN_KERNELS=jit`` in
the environment, it hands out numba's dispatcher, imported on first call, as before: editing any
file of the package falls back to JIT until the next precompile. :func:`status` says which and why.

Guarded calls. A compiled function does not check its arguments: a wrong dtype is reinterpreted,
a list crashes the process. Every call therefore compares its arguments with the export's types
(exact scalar types; arrays by dtype, rank, C-contiguity and writability) in one generated
expression per variant (:func:`_checker`, about 0.1 µs per argument); a call that matches no compiled variant goes to the JIT dispatcher instead and is
counted in :data:`fallbacks`.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import json
import os
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

PACKAGE_DIR = Path(__file__).resolve().parent
EXTENSION = "_aot"  # the module fixplan._aot
MANIFEST = PACKAGE_DIR / "_aot.json"
ENV = "FIXPLAN_KERNELS"  # "jit" forces numba's dispatchers

# The kernels the solve paths call from Python (planning: the jamming classifier's NNLS and
# the witness system, its Newton and fixed-point starts; verification: the engine's planar step
# and its compiled loop, the spatial step and the haptic loop's spatial coupling; a mesh part's
# AABB tree and point queries). A 3D solve that reached any of the spatial kernels through numba
# paid its start (about 0.8 s) in every process. A mesh part's engine step, detection included,
# is one kernel too (its pins' closed forms included), and so are the pins' contacts and slots (a
# first simulation of a part on pins compiled them for 40-50 s).
EXPORTS: tuple[tuple[str, str], ...] = (
    ("fixplan.engine.step", "step2"),
    ("fixplan.engine.step", "run2"),
    ("fixplan.jamming._classify_kernels", "nnls"),
    ("fixplan.jamming._witness_kernels", "system"),
    ("fixplan.jamming._witness_kernels", "newton"),
    ("fixplan.jamming._witness_kernels", "fixed_point"),
    ("fixplan.engine.step", "step3_into"),
    ("fixplan.haptics._kernels", "coupling3"),
    ("fixplan.geometry._mesh_kernels", "build_tree"),
    ("fixplan.geometry._mesh_kernels", "contacts"),
    ("fixplan.engine._mesh_slot_kernels", "mesh_step3"),
    ("fixplan.geometry._pin_kernels", "pose_contacts"),
    ("fixplan.engine._pin_slot_kernels", "pin_slots"),
)

fallbacks: dict[str, int] = {}  # "module.name" -> calls that matched no compiled variant

_SCALARS: dict[str, tuple[type, ...]] = {
    "float64": (float, np.float64),
    "int64": (int, np.int64),
    "bool": (bool, np.bool_),
}


def fingerprint() -> str:
    """SHA-256 (hex) of every ``.py`` file of the package, with the Python and NumPy versions."""
    digest = hashlib.sha256(f"python {sys.version_info[:3]} numpy {np.__version__}\n".encode())
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        digest.update(path.relative_to(PACKAGE_DIR).as_posix().encode() + b"\0")
        digest.update(path.read_bytes())
    return digest.hexdigest()


def fingerprint_int(hexdigest: str) -> int:
    """The first 60 bits of a fingerprint, as the int64 the extension's ``fingerprint__()`` returns."""
    return int(hexdigest[:15], 16)


def export_name(module: str, name: str, variant: int) -> str:
    """The extension's name for variant ``variant`` of ``module.name``: ``step__step2__0``."""
    return f"{module.rsplit('.', 1)[-1].lstrip('_')}__{name}__{variant}"


@functools.cache
def _load() -> tuple[Any, dict[str, Any], str]:
    """(the extension module or None, its manifest, a one-line reason)."""
    if os.environ.get(ENV, "").strip().lower() == "jit":
        return None, {}, f"just-in-time (numba): {ENV}=jit"
    if not MANIFEST.is_file():
        return None, {}, "just-in-time (numba): not built (python -m fixplan.cli.precompile builds it)"
    try:
        manifest = json.loads(MANIFEST.read_text())
        recorded = str(manifest["fingerprint"])
        exports = manifest["exports"]
        if not isinstance(exports, dict):
            raise TypeError("exports is not a table")
    except (OSError, ValueError, KeyError, TypeError) as exc:
        return None, {}, f"just-in-time (numba): {MANIFEST.name} unreadable ({exc})"
    if recorded != fingerprint():
        return None, {}, "just-in-time (numba): the source changed since the build (precompile rebuilds it)"
    try:
        _preload_lapack()
        module = importlib.import_module(f"fixplan.{EXTENSION}")
        built = int(module.fingerprint__())
    except (ImportError, AttributeError, OSError) as exc:
        return None, {}, f"just-in-time (numba): the extension does not load ({exc})"
    if built != fingerprint_int(recorded):
        return None, {}, "just-in-time (numba): the extension and its manifest come from different builds"
    return (
        module,
        manifest,
        f"ahead-of-time: {Path(module.__file__ or EXTENSION).name}, built by numba {manifest.get('numba', '?')}",
    )


# The BLAS and LAPACK the compiled kernels call (numba resolves them from SciPy's Cython
# modules on their first use).
_LAPACK_MODULES = ("cython_blas", "cython_lapack")


def _preload_lapack() -> None:
    """Load ``scipy.linalg.cython_blas`` and ``cython_lapack`` without ``scipy.linalg``'s package init.

    The compiled witness kernels call LAPACK, which numba looks up by importing
    ``scipy.linalg.cython_lapack``; importing that name first runs ``scipy.linalg/__init__``,
    which imports the whole of ``scipy.linalg`` (and parses docstrings): 0.18 s of a 3D solve,
    against 5 ms for the two extension modules alone. Loaded here from their files and
    registered under their full names, the later import finds them in ``sys.modules`` and runs
    no package init. The same LAPACK routines run either way (the same shared objects). A
    later ``import scipy.linalg`` works as usual. Nothing happens if SciPy's layout differs.
    """
    if "scipy.linalg" in sys.modules:
        return
    import importlib.util

    try:
        import scipy
    except ImportError:
        return
    folder = Path(scipy.__file__).resolve().parent / "linalg"
    for name in _LAPACK_MODULES:
        full = f"scipy.linalg.{name}"
        if full in sys.modules:
            continue
        files = sorted(folder.glob(f"{name}.*.so")) + sorted(folder.glob(f"{name}.*.pyd"))
        spec = importlib.util.spec_from_file_location(full, files[0]) if files else None
        if spec is None or spec.loader is None:
            return
        module = importlib.util.module_from_spec(spec)
        sys.modules[full] = module
        try:
            spec.loader.exec_module(module)
        except ImportError:
            del sys.modules[full]
            return


def status() -> str:
    """One line: which kernels run (ahead-of-time or just-in-time) and why."""
    return _load()[2]


def _spec(arg: dict[str, Any]) -> tuple[type, ...] | tuple[np.dtype[Any], int, bool, bool]:
    """A manifest argument as the tuple :func:`_accepts` compares with."""
    if arg["kind"] == "scalar":
        return _SCALARS[arg["dtype"]]
    return (np.dtype(arg["dtype"]), int(arg["ndim"]), bool(arg["contiguous"]), bool(arg["mutable"]))


def _accepts(args: Sequence[Any], specs: Sequence[Any]) -> bool:
    """Whether ``args`` have exactly the types one compiled variant was built for."""
    if len(args) != len(specs):
        return False
    for a, s in zip(args, specs, strict=True):
        if type(s[0]) is type:  # a scalar: its exact Python or NumPy type
            if type(a) not in s:
                return False
        elif (
            type(a) is not np.ndarray
            or a.dtype != s[0]
            or a.ndim != s[1]
            or (s[2] and not a.flags.c_contiguous)
            or (s[3] and not a.flags.writeable)
        ):
            return False
    return True


class _JitKernel:
    """numba's dispatcher for ``module.name``, imported on the first call."""

    __slots__ = ("_function", "_module", "_name")

    def __init__(self, module: str, name: str) -> None:
        self._module, self._name = module, name
        self._function: Callable[..., Any] | None = None

    def resolve(self) -> Callable[..., Any]:
        if self._function is None:
            self._function = getattr(importlib.import_module(self._module), self._name)
        return self._function

    def __call__(self, *args: Any) -> Any:
        return self.resolve()(*args)

    def fixing(self, fixed: Mapping[int, Any]) -> Callable[..., Any]:
        """Itself: numba's dispatcher types every argument anyway (:meth:`_AotKernel.fixing`)."""
        return self


def _checker(specs: Sequence[Any], fixed: Mapping[int, Any] | None = None) -> Callable[[Sequence[Any]], bool]:
    """:func:`_accepts` for one variant's ``specs``, written out as one expression (the same tests).

    The generic loop spends most of its time on the loop itself (a 3D step has 35 arguments):
    one straight-line expression per variant checks them about twice as fast. The code is
    generated from the manifest's types only (indices, ranks and flags; the dtypes and scalar
    type tuples are bound as names, never printed into the source). ``fixed``: positions whose
    argument must be that very object (already checked against ``specs`` by the caller).
    """
    names: dict[str, Any] = {"ndarray": np.ndarray}
    terms = []
    for i, s in enumerate(specs):
        if fixed is not None and i in fixed:
            names[f"F{i}"] = fixed[i]
            terms.append(f"a{i} is F{i}")
            continue
        if type(s[0]) is type:
            names[f"S{i}"] = s
            terms.append(f"type(a{i}) in S{i}")
            continue
        names[f"D{i}"] = s[0]
        term = f"type(a{i}) is ndarray and a{i}.ndim == {int(s[1])} and a{i}.dtype == D{i}"
        if s[2] and s[3]:
            term += f" and (f{i} := a{i}.flags).c_contiguous and f{i}.writeable"
        elif s[2]:
            term += f" and a{i}.flags.c_contiguous"
        elif s[3]:
            term += f" and a{i}.flags.writeable"
        terms.append(f"({term})")
    n = len(specs)
    unpack = ", ".join(f"a{i}" for i in range(n)) + ("," if n == 1 else "")
    body = " and ".join(terms) if terms else "True"
    source = (
        "def check(args):\n"
        f"    if len(args) != {n}:\n"
        "        return False\n" + (f"    {unpack} = args\n" if n else "") + f"    return bool({body})\n"
    )
    exec(compile(source, f"<fixplan.aot checker, {n} arguments>", "exec"), names)  # noqa: S102 - our own manifest
    check: Callable[[Sequence[Any]], bool] = names["check"]
    return check


class _AotKernel:
    """The compiled variants of one kernel, each behind its argument check; JIT when none fits."""

    __slots__ = ("_checks", "_jit", "_key", "_variants")

    def __init__(self, key: str, variants: list[tuple[tuple[Any, ...], Callable[..., Any]]], jit: _JitKernel) -> None:
        self._key, self._variants, self._jit = key, variants, jit
        self._checks = [(_checker(specs), function) for specs, function in variants]

    def __call__(self, *args: Any) -> Any:
        for check, function in self._checks:
            if check(args):
                return function(*args)
        fallbacks[self._key] = fallbacks.get(self._key, 0) + 1
        return self._jit(*args)

    def fixing(self, fixed: Mapping[int, Any]) -> Callable[..., Any]:
        """The kernel for a caller that passes the same objects at the positions of ``fixed`` every call.

        Their types are checked here, once, against each variant; a call then checks that they are
        those very objects (``is``: an array's dtype, rank and layout cannot change) and checks the
        other arguments as :meth:`__call__` does. A mesh part's step passes 48 arguments, 38 of them
        arrays that stay the same objects from step to step: their checks were most of the wrapper's
        time. Another object at a fixed position fails the identity test, and the call is checked in
        full as :meth:`__call__` checks it (then the JIT, as an unmatched call).
        """
        checks = []
        for specs, function in self._variants:
            if all(i < len(specs) and _accepts((value,), (specs[i],)) for i, value in fixed.items()):
                checks.append((_checker(specs, fixed), function))
        bound = _AotKernel.__new__(_AotKernel)
        bound._key, bound._variants, bound._jit = self._key, self._variants, self._jit
        bound._checks = checks + self._checks
        return bound


@functools.cache
def kernel(module: str, name: str) -> Callable[..., Any]:
    """``module.name`` compiled ahead of time when usable (see the module's text), else numba's JIT.

    Never imports numba itself: the JIT dispatcher is imported on its first call.
    """
    jit = _JitKernel(module, name)
    extension, manifest, _ = _load()
    entries = manifest.get("exports", {}).get(f"{module}.{name}") if extension is not None else None
    if not entries:
        return jit
    try:
        variants = [(tuple(_spec(a) for a in e["args"]), getattr(extension, e["export"])) for e in entries]
    except (KeyError, TypeError, AttributeError):
        return jit
    return _AotKernel(f"{module}.{name}", variants, jit)
