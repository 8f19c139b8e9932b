"""Finished steps of one diagnosis kept on disk, so a stopped run resumes.

A time-series diagnosis spends minutes in a few kinds of deterministic step: the nominal
update, the update's prediction spread, each candidate's calibration and each fit's
held-out comparison. :class:`Checkpoint` keeps each finished step's result in a
directory, one file per step written whole or not at all
(:func:`~sknarx.io.write_atomic`), under a key made from everything the step depends on.
A rerun on the same inputs reads the finished steps back and computes only the rest,
so it gives the same diagnosis as an uninterrupted run.

The directory belongs to one set of inputs: the measured data, the rotor, the settings,
the candidates, the readings, the package's own source and its dependencies' versions.
A rerun with anything of these changed starts the directory over rather than mix steps
of two diagnoses. The steps are pickles, read back only from a directory the run itself
stamped: give it a directory of your own, as private as the data.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import pickle
import shutil
from pathlib import Path

import numpy as np
import pandas as pd

from ._atomic import write_atomic, write_text_atomic
from ._report import dependency_versions

__all__ = ["Checkpoint", "fingerprint"]

logger = logging.getLogger(__name__)

_INPUTS = "inputs.json"


def _feed(h, obj) -> None:
    """Feed ``obj`` to the hash ``h`` by value, tagged by kind, so that equal inputs
    hash alike across runs and processes (no ``id``, no set order, no float rounding)."""
    if obj is None or isinstance(obj, (bool, int, str)):
        h.update(f"{type(obj).__name__}:{obj!r};".encode())
    elif isinstance(obj, float):
        h.update(f"float:{obj.hex()};".encode())
    elif isinstance(obj, complex):
        h.update(f"complex:{obj.real.hex()},{obj.imag.hex()};".encode())
    elif isinstance(obj, np.generic):
        _feed(h, obj.item())
    elif isinstance(obj, np.ndarray):
        a = np.ascontiguousarray(obj)
        if a.dtype == object:
            _feed(h, a.tolist())
        else:
            h.update(f"ndarray:{a.dtype.str}:{a.shape};".encode())
            h.update(a.tobytes())
    elif isinstance(obj, pd.DataFrame):
        h.update(f"frame:{list(map(str, obj.columns))};".encode())
        h.update(pd.util.hash_pandas_object(obj, index=True).to_numpy().tobytes())
    elif isinstance(obj, dict):
        h.update(b"dict{")
        for k in sorted(obj, key=repr):
            _feed(h, k)
            _feed(h, obj[k])
        h.update(b"}")
    elif isinstance(obj, (list, tuple)):
        h.update(f"{type(obj).__name__}[".encode())
        for v in obj:
            _feed(h, v)
        h.update(b"]")
    elif isinstance(obj, type):
        h.update(f"type:{obj.__module__}.{obj.__qualname__};".encode())
    elif dataclasses.is_dataclass(obj):
        h.update(f"{type(obj).__qualname__}(".encode())
        for f in dataclasses.fields(obj):
            _feed(h, f.name)
            _feed(h, getattr(obj, f.name))
        h.update(b")")
    else:
        # a key must be a value: an object hashed by identity would never match again
        raise TypeError(f"a checkpoint key cannot hold a {type(obj).__name__}")


def fingerprint(obj) -> str:
    """A hex digest of ``obj`` by value (numbers, strings, arrays, frames, types,
    dataclasses and containers of them).

    Examples
    --------
    >>> import numpy as np
    >>> from sknarx._checkpoint import fingerprint
    >>> fingerprint({"a": np.arange(3.0)}) == fingerprint({"a": np.array([0.0, 1, 2])})
    True
    >>> fingerprint(1.0) == fingerprint(1.0 + 1e-15)
    False
    """
    h = hashlib.sha256()
    _feed(h, obj)
    return h.hexdigest()


def _code_digest() -> str:
    """The package's own source and its dependencies' versions (numerics, compiled
    kernels): a step computed by other code is not reused."""
    root = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    _feed(h, dependency_versions())
    return h.hexdigest()


class Checkpoint:
    """A directory of one diagnosis's finished steps.

    Parameters
    ----------
    path : str or Path
        The directory (created if missing).
    inputs : object
        Everything the diagnosis depends on, hashable by :func:`fingerprint`. With the
        package's source it decides whether the directory's steps are this run's; if
        not, they are removed and the run starts over.

    Examples
    --------
    >>> import tempfile
    >>> from sknarx._checkpoint import Checkpoint
    >>> calls = []
    >>> def slow(x):
    ...     calls.append(x)
    ...     return 2 * x
    >>> with tempfile.TemporaryDirectory() as d:
    ...     first = Checkpoint(d, {"data": 1}).step("double", 21, lambda: slow(21))
    ...     again = Checkpoint(d, {"data": 1}).step("double", 21, lambda: slow(21))
    >>> first, again, calls
    (42, 42, [21])
    """

    def __init__(self, path, inputs):
        self.path = Path(path)
        self.key = fingerprint([inputs, _code_digest()])
        self.reused = 0
        self.computed = 0
        # the directory is stamped when the first step is kept, so a run that fails
        # before any (a user's wrong column) leaves nothing behind
        self._stamped = False
        stamp = self.path / _INPUTS
        if stamp.exists():
            try:
                old = json.loads(stamp.read_text()).get("key")
            except (OSError, ValueError):
                old = None
            if old == self.key:
                self._stamped = True
                n = sum(1 for _ in self.path.glob("*.pkl"))
                logger.info("resuming from %d finished step(s) in %s", n, self.path)
                return
            logger.info("%s holds the steps of another diagnosis (other data, settings "
                        "or code): starting over", self.path)
            shutil.rmtree(self.path)

    def step(self, what: str, key, compute):
        """``compute()``'s result, read back if a step ``what`` with this ``key`` (by
        value, see :func:`fingerprint`) finished before, else computed and kept."""
        file = self.path / f"{what}-{fingerprint(key)[:32]}.pkl"
        if self._stamped and file.exists():
            try:
                value = pickle.loads(file.read_bytes())
            except (OSError, EOFError, pickle.UnpicklingError, AttributeError):
                # written whole, so unreadable means other code; compute it again
                logger.debug("unreadable checkpoint step %s: computing it again", file)
            else:
                self.reused += 1
                return value
        value = compute()
        data = pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
        if not self._stamped:
            write_text_atomic(self.path / _INPUTS, json.dumps({"key": self.key}))
            self._stamped = True
        write_atomic(file, lambda tmp: Path(tmp).write_bytes(data))
        self.computed += 1
        return value


class NoCheckpoint:
    """Every step computed, nothing kept (no checkpoint directory given)."""

    @staticmethod
    def step(what, key, compute):
        return compute()
