"""How the measured experiment is simulated: speeds, sampling, channels, windows.

:class:`SweepModel` runs the nonlinear simulator at every speed step of a sweep and
takes the same order features as the measurement's. With ``solver="harmonic-balance"``
a settled record of a rotor whose response is locked to the shaft revolution is solved
for directly (:mod:`sknarx.rotor.steady`, each speed started from the local search's
start); any other record -- one that starts from rest, an effect that can make a
sub-synchronous or aperiodic orbit, a balance that does not converge -- is integrated.
The speeds of one evaluation run on threads (the compiled kernels release the GIL);
several parameter points share the threads' queue.
"""

from __future__ import annotations

import dataclasses
import logging
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import pandas as pd
from joblib import cpu_count

from .._progress import evaluated
from ..orders import record_features, stack_features
from ..rotor import RotorBearingSimulator, RotorParameters
from ..rotor.steady import (
    HarmonicBalanceError,
    SteadyState,
    solve_steady_state,
    steady_columns,
    supports_harmonic_balance,
)

__all__ = ["NUISANCE", "NUISANCE_UNITS", "SweepModel"]

#: name -> (lower, upper, scale, start)
NUISANCE = {
    "unbalance_scale": (0.7, 1.4, "lin", 1.0),
    "unbalance_phase": (-np.pi, np.pi, "lin", 0.0),
    "stiffness_scale": (0.85, 1.15, "lin", 1.0),
    "damping_scale": (0.6, 1.6, "lin", 1.0),
}
NUISANCE_UNITS = {"unbalance_scale": "-", "unbalance_phase": "rad", "stiffness_scale": "-",
                  "damping_scale": "-"}

logger = logging.getLogger(__name__)

_POOLS: dict = {}


def _pool(threads: int | None = None) -> ThreadPoolExecutor:
    """The process's thread pool of ``threads`` workers (None: one per CPU this process
    may use, as joblib counts them), made once."""
    n = max(1, int(threads or cpu_count()))
    pool = _POOLS.get(n)
    if pool is None:
        pool = _POOLS[n] = ThreadPoolExecutor(max_workers=n)
    return pool


@dataclass
class SweepModel:
    """How to simulate the measured experiment: speeds, sampling, channels, windows."""

    base: RotorParameters
    fs: float
    n_samples: int
    channels: tuple
    transient_s: float = 0.5
    seed: int = 0
    settle_s: float = 0.0  # simulated and discarded before each record (0: from rest)
    # speed (rad/s) -> (q, v): each speed's run continues a settled run from ``lead_s``
    # before its record instead of settling from rest; or -> SteadyState: each speed's
    # balance starts from it (see ``warmed``; None: never)
    warm: dict | None = None
    lead_s: float | None = 0.3
    # the integration step: h |lambda|max <= step_factor (see RotorBearingSimulator)
    step_factor: float = 2.0
    # threads the speed steps run on (None: one per CPU this process may use)
    threads: int | None = None
    # how a settled record is computed: "integrate" always, or "harmonic-balance"
    # where the rotor allows it (else integrated)
    solver: str = "integrate"

    def params(self, nuis) -> RotorParameters:
        su, ph, sk, sc = nuis
        b = self.base
        return b.with_unbalance_scaled(su).replace(
            unbalance_phase=b.unbalance_phase + ph, k1=b.k1 * sk, k2=b.k2 * sk,
            c_a=b.c_a * sc, c_b=b.c_b * sc, c_d1=b.c_d1 * sc, c_d2=b.c_d2 * sc,
            c_O1=b.c_O1 * sc, c_O2=b.c_O2 * sc,
        )

    def warmed(self, speeds, nuis, effects=()) -> SweepModel:
        """This model with every speed's run continuing the settled run of the rotor
        ``(nuis, effects)``: ``lead_s`` seconds of settling instead of ``settle_s``.

        A local search moves the parameters a little: its runs start near their own
        steady state and the short lead lets the small difference decay (the slow
        modes are the least excited ones). Every run of one warmed model starts from
        the same states, so its residual is a smooth function of the parameters.
        Where the records are balanced, not integrated, the balance at each speed
        starts from the start point's solution there instead (two or three chord steps
        rather than five Newton iterations), and every evaluation from the same one, so
        that its result does not depend on the order the threads take the points in; an
        evaluation whose balance fails is integrated over ``lead_s`` from the start's
        orbit, and a speed where the start's own balance fails (a contact acts) keeps
        the start's settled run.
        Records that start with a transient (``settle_s`` 0) are not warmed: their
        start from rest is part of what is compared.
        """
        if self.lead_s is None or self.settle_s <= self.lead_s:
            return self
        sim = self._simulator(nuis, effects, speeds)
        balances = self._balances(sim)

        def one(w):
            # the start's balanced orbit; where it has none (a contact acts), its
            # settled run from ``lead_s`` before the record
            if balances:
                try:
                    return float(w), solve_steady_state(sim, float(w), keep_jacobian=True)
                except HarmonicBalanceError:
                    sim.substeps(self.fs, float(w))
            return float(w), sim.warm_state(float(w), fs=self.fs, settle=self.settle_s,
                                            lead=self.lead_s)

        return dataclasses.replace(self, warm=dict(_pool(self.threads).map(one, speeds)))

    def _balances(self, sim) -> bool:
        """Whether the settled records of ``sim`` are solved by harmonic balance."""
        return (self.solver == "harmonic-balance" and self.settle_s > 0
                and supports_harmonic_balance(sim))

    def _simulator(self, nuis, effects, speeds):
        sim = RotorBearingSimulator(self.params(nuis), effects=effects, seed=self.seed,
                                    step_factor=self.step_factor)
        # build once, before the threads share it: the setup and each speed's step
        _ = sim._setup
        if not self._balances(sim):
            for w in speeds:
                sim.substeps(self.fs, float(w))
        return sim

    def _balanced_record(self, sim, w, start):
        """The settled record at ``w`` by harmonic balance from ``start`` (a
        SteadyState or None), or None where the balance fails or the start's own did
        (a warm ``(q, v)``: a contact acted there) -- the caller integrates."""
        if isinstance(start, tuple):
            return None
        try:
            state = solve_steady_state(sim, w, start=start,
                                       max_iter=10 if start is not None else 25)
        except HarmonicBalanceError as exc:
            logger.debug("%s; integrated instead", exc)
            return None
        return steady_columns(sim, state, self.fs, self.n_samples)

    def records(self, speeds, nuis, effects=()):
        """Simulated records at ``speeds``; the speeds run concurrently (the integrator
        releases the GIL), which halves an evaluation on two cores."""
        return _only(self._per_speed(speeds, [(nuis, effects)], lambda record: record))

    def _per_speed(self, speeds, points, then):
        """``then(record)`` of each speed's simulated record for each ``(nuis,
        effects)`` point, computed in the thread that simulated it (so one thread's
        post-processing overlaps the other's integration), in the order of ``speeds``.
        Every point's speeds share the two threads' queue, so a thread that finishes
        its last speed of one point starts on the next point instead of waiting for the
        other's last speed (and a point's simulator is built while the last one runs).
        Each point gets its list of results, or the first exception one of its speeds
        raised."""
        warm = self.warm or {}

        def jobs():
            # lazily: the pool starts on a point's speeds while the next is built
            for nuis, effects in points:
                try:
                    sim = self._simulator(nuis, effects, speeds)
                except Exception as exc:  # noqa: BLE001 -- handed to the point's caller
                    sim = exc
                for w in speeds:
                    yield sim, float(w)

        def one(job):
            sim, w = job
            if isinstance(sim, Exception):
                return sim
            try:
                state = warm.get(w)
                run = (self._balanced_record(sim, w, state) if self._balances(sim)
                       else None)
                if run is None:
                    if isinstance(state, SteadyState):  # on the start's orbit
                        state = state.state_at(-self.lead_s)
                    # automatic step: halved if an effect's stiff contact makes it unstable
                    run = sim.simulate_columns(w, fs=self.fs, n_samples=self.n_samples,
                                               settle=self.settle_s if state is None
                                               else self.lead_s, state=state)
                Y = np.column_stack([run[c] for c in self.channels])
                evaluated()
                return then((w, run["t"], Y))
            except Exception as exc:  # noqa: BLE001 -- handed to the point's caller
                return exc

        done = list(_pool(self.threads).map(one, jobs()))
        n = len(speeds)
        out = []
        for i in range(len(points)):
            part = done[i * n:(i + 1) * n]
            out.append(next((r for r in part if isinstance(r, Exception)), part))
        return out

    def features(self, speeds, nuis, effects=()):
        """Order features of the simulated experiment as a DataFrame."""
        keys, vals, ses, _ = self.feature_arrays(speeds, nuis, effects)
        df = pd.DataFrame(keys, columns=["speed", "window", "channel", "feature"])
        df["re"], df["im"], df["se"] = vals.real, vals.imag, ses
        return df

    def feature_arrays(self, speeds, nuis, effects=()):
        return _only(self.feature_arrays_many(speeds, [(nuis, effects)]))

    def feature_arrays_many(self, speeds, points):
        """:meth:`feature_arrays` of several ``(nuis, effects)`` points, run together
        (see :meth:`_per_speed`); a point whose simulation failed gets its exception
        instead."""
        channels = list(self.channels)
        parts = self._per_speed(
            speeds, points, lambda record: record_features(record, channels,
                                                           self.transient_s))
        return [p if isinstance(p, Exception) else stack_features(p) for p in parts]


def _only(results):
    """The one point's result of a batched call, or its exception raised."""
    (out,) = results
    if isinstance(out, Exception):
        raise out
    return out
