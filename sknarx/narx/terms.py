"""Polynomial NARX candidate terms: enumeration, names, parsing and evaluation.

A term is a monomial in the lagged variables ``y(t-1) .. y(t-ny), u(t-1) .. u(t-nu)``.
It is stored as a row of an integer *exponent matrix* whose columns are those
variables in that order (y lags ascending, then u lags ascending). The printed
name is a faithful, parseable encoding of the row, so a term list can travel
between pipeline stages, JSON files and reports as plain strings.

With several outputs or inputs (a multi-output model) the variables are each
channel's lags, outputs first: ``y1(t-1..ny), y2(t-1..ny), .., u1(t-1..nu), ..``; the
channel's number (from 1) follows the letter in the names. One output and one input
keep the plain names.
"""

from __future__ import annotations

import re
from itertools import combinations_with_replacement
from math import comb

import numpy as np

__all__ = [
    "n_candidate_terms",
    "monomial_exponents",
    "term_names",
    "parse_terms",
    "noise_term_name",
    "split_noise_terms",
    "channel_counts",
    "TermSet",
]

_FACTOR = re.compile(r"^([yu])(\d*)\(t-(\d+)\)(?:\^(\d+))?$")
_NOISE = re.compile(r"^e\(t-(\d+)\)$")


def noise_term_name(lag: int) -> str:
    """Name of the noise (moving-average) term ``e(t-lag)`` of a NARMAX model."""
    return f"e(t-{int(lag)})"


def split_noise_terms(names) -> tuple[list[int], list[int], list[int]]:
    """Positions of the process terms and of the noise terms ``e(t-k)``, and the noise lags.

    Returns ``(process_positions, noise_positions, noise_lags)``.
    """
    process, noise, lags = [], [], []
    for i, name in enumerate(names):
        m = _NOISE.match(str(name).strip())
        if m is None:
            process.append(i)
        else:
            noise.append(i)
            lags.append(int(m.group(1)))
    return process, noise, lags


def n_candidate_terms(ny: int, nu: int, degree: int) -> int:
    """Number of monomials of degree <= ``degree`` in ``ny + nu`` variables.

    This is the paper's ``M = (n + L)! / (n! L!)`` with ``n = ny + nu``.
    """
    return comb(ny + nu + degree, degree)


def monomial_exponents(ny: int, nu: int, degree: int, n_outputs: int = 1,
                       n_inputs: int = 1) -> np.ndarray:
    """Exponent matrix of every candidate term, shape ``(M, ny + nu)`` (with several
    channels ``(M, n_outputs ny + n_inputs nu)``).

    Rows are ordered by total degree, then lexicographically by the variable
    order ``y(t-1..ny), u(t-1..nu)``; row 0 is the constant term.
    """
    n = n_outputs * ny + n_inputs * nu
    rows = [np.zeros(n, dtype=np.int64)]
    for d in range(1, degree + 1):
        for combo in combinations_with_replacement(range(n), d):
            e = np.zeros(n, dtype=np.int64)
            for j in combo:
                e[j] += 1
            rows.append(e)
    return np.vstack(rows) if rows else np.zeros((0, n), dtype=np.int64)


def _channel(letter: str, index: int, count: int) -> str:
    return letter if count == 1 and index == 0 else f"{letter}{index + 1}"


def _variable_names(ny: int, nu: int, n_outputs: int = 1, n_inputs: int = 1) -> list[str]:
    names = [f"{_channel('y', c, n_outputs)}(t-{i})" for c in range(n_outputs)
             for i in range(1, ny + 1)]
    return names + [f"{_channel('u', c, n_inputs)}(t-{i})" for c in range(n_inputs)
                    for i in range(1, nu + 1)]


def term_names(exponents: np.ndarray, ny: int, nu: int, n_outputs: int = 1,
               n_inputs: int = 1) -> list[str]:
    """Printed names, e.g. ``1``, ``y(t-1)``, ``u(t-2)^2``, ``y(t-1)*u(t-3)``; with
    several channels ``y2(t-1)*u1(t-3)``."""
    var = _variable_names(ny, nu, n_outputs, n_inputs)
    names = []
    for row in np.asarray(exponents):
        factors = [var[j] + (f"^{int(p)}" if p > 1 else "") for j, p in enumerate(row) if p > 0]
        names.append("*".join(factors) if factors else "1")
    return names


def parse_terms(names, n_outputs: int | None = None,
                n_inputs: int | None = None) -> tuple[np.ndarray, int, int]:
    """Inverse of :func:`term_names`: names to ``(exponents, ny, nu)``.

    ``ny`` and ``nu`` are the largest lags that occur (0 when a variable is
    absent), so the exponent matrix is as narrow as the terms allow. The channel
    counts of a multi-output layout are the largest channel numbers named, or
    ``n_outputs`` / ``n_inputs`` when given (and at least those).
    """
    parsed = []
    ny = nu = 0
    p, q = n_outputs or 1, n_inputs or 1
    for name in names:
        name = str(name).strip()
        factors = {}
        if name != "1":
            for factor in name.split("*"):
                m = _FACTOR.match(factor.strip())
                if m is None:
                    raise ValueError(
                        f"Cannot parse NARX term {name!r}: expected factors like 'y(t-1)', "
                        "'u(t-2)^2' (or 'y2(t-1)' with several channels) joined by '*', or "
                        "'1' for the constant."
                    )
                var, ch = m.group(1), int(m.group(2) or 1)
                lag, power = int(m.group(3)), int(m.group(4) or 1)
                if lag < 1 or power < 1 or ch < 1:
                    raise ValueError(f"Lag, power and channel must be >= 1 in term {name!r}.")
                factors[(var, ch, lag)] = factors.get((var, ch, lag), 0) + power
                if var == "y":
                    ny, p = max(ny, lag), max(p, ch)
                else:
                    nu, q = max(nu, lag), max(q, ch)
        parsed.append(factors)
    exps = np.zeros((len(parsed), p * ny + q * nu), dtype=np.int64)
    for i, factors in enumerate(parsed):
        for (var, ch, lag), power in factors.items():
            col = ((ch - 1) * ny + lag - 1 if var == "y"
                   else p * ny + (ch - 1) * nu + lag - 1)
            exps[i, col] = power
    return exps, ny, nu


def channel_counts(names) -> tuple[int, int]:
    """``(n_outputs, n_inputs)`` that a list of term names refers to (1 each for the
    plain names)."""
    p = q = 1
    for name in names:
        for factor in str(name).split("*"):
            m = _FACTOR.match(factor.strip())
            if m and m.group(2):
                if m.group(1) == "y":
                    p = max(p, int(m.group(2)))
                else:
                    q = max(q, int(m.group(2)))
    return p, q


class TermSet:
    """Evaluates a set of monomials on lagged series.

    Each monomial of degree ``d`` is computed as a monomial of degree ``d - 1``
    (its *parent*, always present in the evaluation plan) times one lagged
    variable, so a full dictionary costs one multiplication per column.

    Parameters
    ----------
    exponents : ndarray of shape (n_terms, n_outputs * ny + n_inputs * nu)
    ny, nu : int
        Output and input lags that the exponent columns refer to.
    n_outputs, n_inputs : int, default=1
        Channels: with more than one, ``y`` and ``u`` are 2-D (samples x channels).
    """

    def __init__(self, exponents, ny: int, nu: int, n_outputs: int = 1, n_inputs: int = 1):
        self.exponents = np.asarray(exponents, dtype=np.int64)
        self.ny, self.nu = int(ny), int(nu)
        self.n_outputs, self.n_inputs = int(n_outputs), int(n_inputs)
        width = self.n_outputs * self.ny + self.n_inputs * self.nu
        if self.exponents.ndim != 2 or self.exponents.shape[1] != width:
            raise ValueError("exponents must have n_outputs * ny + n_inputs * nu columns")
        self.max_lag = max(self.ny, self.nu, 0)
        self._plan = self._make_plan()

    def _make_plan(self):
        # Evaluation plan over the closure of the terms under "drop one factor":
        # each entry is (parent index, variable index) with parent -1 for the constant.
        index = {(): -1}
        plan: list[tuple[int, int]] = []

        def ensure(key):
            if key in index:
                return index[key]
            var = key[-1]
            parent = ensure(key[:-1])
            plan.append((parent, var))
            index[key] = len(plan) - 1
            return index[key]

        out = []
        for row in self.exponents:
            key = tuple(j for j, p in enumerate(row) for _ in range(int(p)))
            out.append(ensure(key))
        return np.array(plan, dtype=np.int64).reshape(-1, 2), np.array(out, dtype=np.int64)

    def lagged(self, u, y, start: int, stop: int) -> list[np.ndarray]:
        """Lagged variables for samples ``start <= t < stop`` as views (no copies)."""
        Y = y.reshape(len(y), -1)
        U = u.reshape(len(u), -1)
        cols = [Y[start - i : stop - i, c] for c in range(self.n_outputs)
                for i in range(1, self.ny + 1)]
        cols += [U[start - i : stop - i, c] for c in range(self.n_inputs)
                 for i in range(1, self.nu + 1)]
        return cols

    def evaluate(self, u, y, start: int, stop: int, out=None) -> np.ndarray:
        """Regressor matrix of shape ``(stop - start, n_terms)`` for samples ``start..stop-1``.

        Needs ``start >= max_lag``. With ``out`` (a Fortran-ordered array of that
        shape) the columns are written in place; column-major storage keeps every
        write contiguous.
        """
        lag = self.lagged(u, y, start, stop)
        plan, order = self._plan
        n = stop - start
        cache = np.empty((n, len(plan)), order="F")
        for i, (parent, var) in enumerate(plan):
            if parent < 0:
                cache[:, i] = lag[var]
            else:
                np.multiply(cache[:, parent], lag[var], out=cache[:, i])
        if out is None:
            out = np.empty((n, len(order)), order="F")
        for j, src in enumerate(order):
            if src < 0:
                out[:, j] = 1.0
            else:
                out[:, j] = cache[:, src]
        return out
