"""RotorBearingSimulator: the paper's rotor-bearing system, simulated fast."""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import pandas as pd
from joblib import Parallel, delayed
from scipy.optimize import root

from .bearings import bearing_force_py
from .effects import EffectContext, compose_force_kernels
from .integrator import integrate
from .linear import LinearRotorModel, bearing_stiffness
from .matrices import DOF_INDEX, assemble
from .parameters import DOF_NAMES, RotorParameters
from .pedestals import HOUSING_NAMES, bearing_dofs, with_pedestals
from .steady import solve_steady_state
from .sweep_table import SweepStore

__all__ = ["RotorBearingSimulator", "SimulationDivergenceError"]


class SimulationDivergenceError(RuntimeError):
    """The time integration blew up (unstable step or non-physical parameters)."""


@dataclass(frozen=True)
class _Setup:
    minv: np.ndarray
    C: np.ndarray
    G: np.ndarray
    K: np.ndarray
    fg: np.ndarray
    unb: np.ndarray
    brg: np.ndarray
    kernel: object
    kparams: np.ndarray
    # the EffectContext the effects were given (their measure sees it too); it holds the
    # static equilibrium the runs start from (context.q_static)
    context: object


class RotorBearingSimulator:
    """12-DOF rotor with a bolted joint on two nonlinear ball bearings (Jin et al. 2022).

    An effect that mounts the bearings in housings on pedestals
    (:class:`~sknarx.rotor.SupportAnisotropy`) adds the housings' four DOFs
    (:attr:`dof_names`); the recorded columns stay the rotor's.

    Parameters
    ----------
    params : RotorParameters, optional
        Physical parameters; the paper's by default.
    effects : sequence of Effect, optional
        Extra physics (see :mod:`sknarx.rotor.effects`), composed without
        touching the integrator.
    step_factor : float, default=2.0
        Integration step ``h`` is chosen so that ``h * |lambda|_max <= step_factor``,
        with ``lambda_max`` the fastest eigenvalue of the linearised rotor at the
        highest speed simulated (fourth-order RK is stable up to about 2.8; the
        fast modes are stiff bearing and joint modes far above the 1x-3x band, and
        the accuracy of the 1x and 2x amplitudes at the default is verified against
        a tight-tolerance reference in the tests).
    divergence_limit : float, default=0.05
        A displacement beyond this (m) or a non-finite value stops the run with
        :class:`SimulationDivergenceError`.
    seed : int, default=0
        Seed of measurement effects (noise); each speed gets its own stream
        derived from it and the speed, so results do not depend on ``n_jobs``.

    Examples
    --------
    >>> from sknarx.rotor import RotorBearingSimulator
    >>> sim = RotorBearingSimulator()
    >>> run = sim.simulate(144.5, fs=1000.0, n_samples=1000, settle=1.0)
    >>> list(run.columns[:4])
    ['speed', 't', 'u', 'phi']
    >>> bool(0.5e-3 < run["xO1"].max() - run["xO1"].mean() < 2e-3)
    True
    """

    def __init__(self, params=None, effects=(), step_factor=2.0, divergence_limit=0.05,
                 seed=0):
        self.params = RotorParameters() if params is None else params
        if not isinstance(self.params, RotorParameters):
            raise TypeError("params must be a RotorParameters instance.")
        self.effects = tuple(effects)
        self.step_factor = float(step_factor)
        self.divergence_limit = float(divergence_limit)
        self.seed = int(seed)
        if not (0 < self.step_factor <= 2.5):
            raise ValueError("step_factor must be in (0, 2.5]; RK4 is unstable beyond ~2.8.")

    # ------------------------------------------------------------- set-up
    @cached_property
    def effective_params(self) -> RotorParameters:
        p = self.params
        for eff in self.effects:
            p = eff.modify_parameters(p)
        return p

    @cached_property
    def pedestals(self):
        """The bearing housings' pedestals an effect mounts the bearings on, or ``None``
        (bearings held by the frame: 12 DOF)."""
        found = [(e, ped) for e in self.effects if (ped := e.pedestals()) is not None]
        if len(found) > 1:
            raise ValueError("Only one effect may mount the bearings on pedestals; got "
                             + ", ".join(e.name for e, _ in found) + ".")
        return found[0][1] if found else None

    @cached_property
    def matrices(self):
        """Mass, damping, gyroscopic and stiffness matrices (SI), 12 DOF or, with
        pedestals, 16 (``DOF_NAMES`` then ``HOUSING_NAMES``); bearings not included."""
        m = assemble(self.effective_params)
        if self.pedestals is not None:
            m = with_pedestals(m, self.effective_params, self.pedestals)
        return m

    @property
    def dof_names(self):
        """Names of the integrated DOFs, in order."""
        return DOF_NAMES + HOUSING_NAMES[: self.matrices.M.shape[0] - len(DOF_NAMES)]

    def _bearings(self):
        """Per bearing: name, journal ``(x, y)`` DOFs, housing DOFs or ``(-1, -1)``."""
        return [(which, journal, housing) for which, (journal, housing)
                in zip("AB", bearing_dofs(self.matrices.M.shape[0]), strict=True)]

    @staticmethod
    def _relative(q, journal, housing):
        """The journal's displacement in its bearing (relative to the housing, if any)."""
        x, y = q[journal[0]], q[journal[1]]
        if housing[0] >= 0:
            x, y = x - q[housing[0]], y - q[housing[1]]
        return x, y

    def static_equilibrium(self) -> np.ndarray:
        """Displacements (m, rad) at rest under gravity, bearings included."""
        return self._q_static

    @cached_property
    def _q_static(self):
        """The static equilibrium, solved once per simulator."""
        p, m = self.effective_params, self.matrices

        bearings = self._bearings()

        def residual(q):
            f = m.gravity_force - m.K @ q
            for which, journal, housing in bearings:
                fb = bearing_force_py(*self._relative(q, journal, housing), 0.0, p, which)
                f[list(journal)] += fb
                if housing[0] >= 0:
                    f[list(housing)] -= fb
            return f

        guess = np.zeros(m.M.shape[0])
        guess[[1, 3, 7, 11]] = -(max(p.clearance, p.resolved("clearance_B")) + 2e-5)
        if self.pedestals is not None:
            # each pedestal carries half the rotor's weight and its housing's
            load = 0.5 * np.sum(np.abs(m.gravity_force[: len(DOF_NAMES)]))
            sag = -(load + self.pedestals.mass * p.gravity) / self.pedestals.stiffness[1]
            for *_, housing in bearings:
                guess[housing[1]] = sag
            guess[[1, 3, 7, 11]] += sag
        sol = root(residual, guess, method="hybr", options={"xtol": 1e-14})
        scale = max(np.max(np.abs(m.gravity_force)), 1.0)
        if np.max(np.abs(residual(sol.x))) > 1e-8 * scale:
            raise SimulationDivergenceError(
                f"No static equilibrium found ({sol.message}); check the bearing stiffness kB "
                "and clearance."
            )
        return sol.x

    @cached_property
    def _static_bearing_stiffness(self):
        """Each bearing's averaged tangent stiffness (2x2, N/m) at the static
        equilibrium: the effects' context and the linear model share it."""
        q = self._q_static
        return tuple(bearing_stiffness(*self._relative(q, journal, housing),
                                       self.effective_params, which=which)
                     for which, journal, housing in self._bearings())

    @cached_property
    def _setup(self) -> _Setup:
        p, m = self.effective_params, self.matrices
        q_static = self._q_static
        ph = p.unbalance_phase
        unb = np.array([[p.m_O1 * p.e, ph, DOF_INDEX["xO1"], DOF_INDEX["yO1"]],
                        [p.m_O2 * p.resolved("e_O2"), p.beta + ph, DOF_INDEX["xO2"],
                         DOF_INDEX["yO2"]]])
        # bearing A's contact stiffness and clearance first, bearing B's next, then the
        # housings' DOFs (-1: the bearing is held by the frame)
        bearings = self._bearings()
        brg = np.array([p.kB, p.clearance, p.hertz_exponent, p.n_balls, p.cage_ratio,
                        DOF_INDEX["xA"], DOF_INDEX["yA"], DOF_INDEX["xB"], DOF_INDEX["yB"],
                        *p.bearing("B"), *(h for _, _, housing in bearings for h in housing)],
                       dtype=float)
        ctx = EffectContext(q_static=q_static, params=p,
                            bearing_stiffness=self._static_bearing_stiffness)
        kernels = [k for k in (e.force_kernel(ctx) for e in self.effects) if k is not None]
        kernel, kparams = compose_force_kernels(kernels)
        return _Setup(minv=1.0 / np.diag(m.M), C=m.C, G=m.G, K=m.K, fg=m.gravity_force, unb=unb,
                      brg=brg, kernel=kernel, kparams=kparams, context=ctx)

    @cached_property
    def linear_stiffness(self) -> np.ndarray:
        """Stiffness matrix (N/m, N m/rad) of the rotor with its bearings linearised
        about the static equilibrium (:meth:`linear_model`'s ``K``), built once."""
        return self.linear_model().K

    def linear_model(self) -> LinearRotorModel:
        """The rotor with its bearings linearised about the static equilibrium."""
        p, m = self.effective_params, self.matrices
        K = m.K.copy()
        for (_, journal, housing), kb in zip(self._bearings(), self._static_bearing_stiffness,
                                             strict=True):
            jj = list(journal)
            K[np.ix_(jj, jj)] += kb
            if housing[0] >= 0:  # the contact between journal and housing
                hh = list(housing)
                K[np.ix_(hh, hh)] += kb
                K[np.ix_(jj, hh)] -= kb
                K[np.ix_(hh, jj)] -= kb
        unb = np.zeros(m.M.shape[0], dtype=complex)
        for name, me, ph in (("O1", p.m_O1 * p.e, p.unbalance_phase),
                             ("O2", p.m_O2 * p.resolved("e_O2"), p.beta + p.unbalance_phase)):
            unb[DOF_INDEX["x" + name]] = me * np.exp(1j * ph)
            unb[DOF_INDEX["y" + name]] = -1j * me * np.exp(1j * ph)
        return LinearRotorModel(M=m.M, C=m.C, G=m.G, K=K, unbalance=unb)

    #: speeds (rad/s) at which ``|lambda|max`` is sampled: it grows slowly with speed
    #: (gyroscopic stiffening) and is interpolated between them
    LAMBDA_SPEEDS = (0.0, 250.0, 500.0, 1000.0, 2000.0)

    def _lambda_max(self, i: int) -> float:
        """``|lambda|max`` at the ``i``-th of :attr:`LAMBDA_SPEEDS`, computed when first
        needed: a sweep below 500 rad/s needs three of the five eigenproblems, and a
        calibration builds a simulator at every evaluation."""
        cache = self.__dict__.setdefault("_lambda_cache", {})
        if i not in cache:
            cache[i] = self._linear.max_oscillatory_eigenvalue(self.LAMBDA_SPEEDS[i])
        return cache[i]

    @cached_property
    def _linear(self) -> LinearRotorModel:
        return self.linear_model()

    def substeps(self, fs: float, omega_max: float) -> int:
        """RK4 steps per output sample for stability and accuracy (see ``step_factor``)."""
        ws = self.LAMBDA_SPEEDS
        if omega_max > ws[-1]:  # beyond the samples: proportional to speed
            lam_max = self._lambda_max(len(ws) - 1) * omega_max / ws[-1]
        else:  # linear between the two samples around it
            i = min(max(bisect.bisect_right(ws, omega_max) - 1, 0), len(ws) - 2)
            lam_max = float(np.interp(omega_max, ws[i:i + 2],
                                      [self._lambda_max(i), self._lambda_max(i + 1)]))
        return max(1, math.ceil(lam_max / fs / self.step_factor))

    # ---------------------------------------------------------- simulation
    def _check_grid(self, fs, n_samples, settle):
        if not (np.isfinite(fs) and fs > 0):
            raise ValueError(f"fs must be a positive sampling rate in Hz, got {fs!r}.")
        if int(n_samples) != n_samples or n_samples < 1:
            raise ValueError(f"n_samples must be a positive integer, got {n_samples!r}.")
        if not (np.isfinite(settle) and settle >= 0):
            raise ValueError(f"settle must be a non-negative time in s, got {settle!r}.")

    @staticmethod
    def _check_speeds(speeds):
        speeds = np.atleast_1d(np.asarray(speeds, dtype=float))
        bad = ~np.isfinite(speeds) | (speeds < 0)
        if bad.any():
            raise ValueError(
                f"Speeds must be finite and non-negative (rad/s); got {speeds[bad].tolist()}."
            )
        return speeds

    def _run(self, omega_grid, n_settle, fs, speed_label, substeps=None, state=None,
             stop=None):
        """Integrate; an automatically chosen step that proves unstable (stiff contact
        in an effect, say) is halved up to three times before giving up."""
        if substeps is not None:
            return self._run_once(omega_grid, n_settle, fs, speed_label, int(substeps),
                                  state, stop)
        substeps = self.substeps(fs, float(np.max(omega_grid)))
        for attempt in range(4):
            try:
                return self._run_once(omega_grid, n_settle, fs, speed_label, substeps,
                                      state, stop)
            except SimulationDivergenceError:
                if attempt == 3:
                    raise
                substeps *= 2

    def _run_once(self, omega_grid, n_settle, fs, speed_label, substeps, state=None,
                  stop=None):
        """One integration over ``omega_grid`` (sample ``n_settle`` is t = 0), from
        ``state`` (default: rest on the static deflection), up to sample ``stop``
        (default: the end; before t = 0 only the last sample is recorded)."""
        s = self._setup
        dt = 1.0 / fs
        # shaft angle 0 at the first recorded sample (t = 0)
        w = omega_grid
        phi0 = -float(np.sum(0.5 * (w[1 : n_settle + 1] + w[:n_settle])) * dt)
        stop = w.size - 1 if stop is None else stop
        record_from = min(n_settle, stop)
        q_static = s.context.q_static
        q0, v0 = ((q_static.copy(), np.zeros(q_static.size)) if state is None else
                  self._adapt_state(state))
        Q, U, PHI, status, q_end, v_end = integrate(
            q0, v0, np.ascontiguousarray(w[: stop + 1], dtype=float), phi0,
            -n_settle * dt, dt, int(substeps), record_from, s.minv, s.C, s.G, s.K, s.fg,
            s.unb, s.brg, s.kernel, s.kparams, self.divergence_limit,
        )
        if status >= 0:
            t_bad = (status - n_settle) * dt
            raise SimulationDivergenceError(
                f"The simulation diverged at {speed_label} (t = {t_bad:.4g} s, speed "
                f"{w[min(status, len(w) - 1)]:.4g} rad/s): a displacement exceeded "
                f"{self.divergence_limit} m or became NaN. Use a smaller integration step "
                f"(step_factor, now {self.step_factor}; {substeps} substeps per sample) or check "
                "the parameters (e.g. kB, clearance, damping)."
            )
        # columns as arrays: inner loops (calibration) skip the DataFrame entirely
        t = (record_from - n_settle + np.arange(Q.shape[0])) * dt
        columns = {"speed": w[record_from : stop + 1], "t": t, "u": U, "phi": PHI}
        columns.update(zip(self.dof_names, Q.T, strict=True))
        columns["_state"] = (q_end, v_end)
        return columns

    def _adapt_state(self, state):
        """``(q, v)`` for this simulator's DOFs from a state of a rotor with or without
        pedestals (a calibration continues one candidate's settled runs with another's):
        housings a state lacks start at rest on their static deflection."""
        q, v = (np.array(a, dtype=float) for a in state)
        n = self._setup.context.q_static.size
        sizes = (len(DOF_NAMES), len(DOF_NAMES) + len(HOUSING_NAMES))
        if q.shape != v.shape or q.ndim != 1 or q.size not in sizes:
            raise ValueError(f"state must be (q, v) of {sizes[0]} or {sizes[1]} values each; "
                             f"got shapes {q.shape}, {v.shape}.")
        if q.size < n:
            q = np.r_[q, self._setup.context.q_static[q.size:]]
            v = np.r_[v, np.zeros(n - v.size)]
        return q[:n].copy(), v[:n].copy()

    def warm_state(self, omega, fs=1000.0, settle=2.0, lead=0.3, substeps=None):
        """The rotor's state ``lead`` seconds before the record of a run settled for
        ``settle`` seconds from rest: the start of a shorter run (``simulate_columns(...,
        settle=lead, state=...)``) that continues the long one.

        With the parameters the state was computed for, the short run repeats the long
        one's record; with nearby parameters (a calibration's local search) it starts
        close to their steady state, so ``lead`` need only cover the decay of that small
        difference, not of the whole response from rest.

        Parameters
        ----------
        omega : float
            Speed, rad/s.
        fs : float, default=1000.0
            Sampling rate, Hz.
        settle : float, default=2.0
            Seconds of the long run's settling, from rest on the static deflection.
        lead : float, default=0.3
            Seconds before the record (``t = 0``) at which the state is taken; at most
            ``settle``.
        substeps : int, optional
            RK4 steps per sample; chosen from ``step_factor`` by default.

        Returns
        -------
        tuple of ndarray
            ``(q, v)``: displacements (m, rad) and velocities (m/s, rad/s) of the DOFs
            (:attr:`dof_names`: 12, or 16 with pedestals).

        Examples
        --------
        >>> from sknarx.rotor import RotorBearingSimulator
        >>> sim = RotorBearingSimulator()
        >>> state = sim.warm_state(150.0, settle=0.5, lead=0.1)
        >>> short = sim.simulate_columns(150.0, n_samples=200, settle=0.1, state=state)
        >>> long = sim.simulate_columns(150.0, n_samples=200, settle=0.5)
        >>> bool(abs(short["xO1"] - long["xO1"]).max() < 1e-9 * abs(long["xO1"]).max())
        True
        """
        omega = float(self._check_speeds(omega)[0])
        self._check_grid(fs, 1, settle)
        if not (np.isfinite(lead) and 0 <= lead <= settle):
            raise ValueError(f"lead must lie in [0, settle] s, got {lead!r} (settle {settle!r}).")
        n_settle = int(round(settle * fs))
        n_lead = int(round(lead * fs))
        # the long run's first part, up to t = -lead: the shaft angle starts where the
        # long run's does (0 at t = 0)
        grid = self._speed_grid(omega, fs, n_settle, n_settle + 1)
        run = self._run(grid, n_settle, fs, f"speed {omega:g} rad/s (settling)", substeps,
                        stop=n_settle - n_lead)
        q, v = run["_state"]
        return q.copy(), v.copy()

    def _speed_grid(self, omega, fs, n_settle, size):
        """The shaft speed (rad/s) at each sample instant, ``n_settle`` of them before
        t = 0, after the effects that modify it."""
        grid = np.full(size, omega)
        for eff in self.effects:
            t = (np.arange(grid.size) - n_settle) / fs
            grid = np.asarray(eff.modify_speed(t, grid, np.random.default_rng(self.seed)),
                              dtype=float)
        return grid

    def _measure(self, columns, speed, n):
        """The first ``n`` samples of each column, as the measurement effects record them."""
        columns = {name: values[:n] for name, values in columns.items()}
        rng = np.random.default_rng([self.seed, int(round(speed * 1e6))])
        ctx = self._setup.context
        for eff in self.effects:
            columns = eff.measure(columns, rng, context=ctx)
        # the probes have read the housings; the record holds the rotor's DOFs
        for name in HOUSING_NAMES:
            columns.pop(name, None)
        return columns

    def simulate(self, omega, fs=1000.0, n_samples=8192, settle=2.0, substeps=None):
        """Steady run at one speed.

        Parameters
        ----------
        omega : float
            Speed, rad/s.
        fs : float, default=1000.0
            Sampling rate, Hz.
        n_samples : int, default=8192
            Recorded samples (after settling).
        settle : float, default=2.0
            Seconds simulated and discarded first. The dominant first mode
            (damping ratio ~0.27) decays in ~0.03 s; the slowest mode, the lightly
            damped backward conical mode (~264 rad/s, damping ratio ~0.01, time
            constant ~0.4 s), is barely excited by unbalance; 2 s is five of its
            time constants.
        substeps : int, optional
            RK4 steps per sample; chosen from ``step_factor`` by default.

        Returns
        -------
        DataFrame
            Columns ``speed`` (rad/s), ``t`` (s, 0 where disk O1's eccentricity angle
            is 0), ``u`` (disk O1's x unbalance force, N: the paper's input),
            ``phi`` (shaft angle, rad) and one column per DOF (m, rad).
        """
        return pd.DataFrame(self.simulate_columns(omega, fs, n_samples, settle, substeps))

    def simulate_columns(self, omega, fs=1000.0, n_samples=8192, settle=2.0, substeps=None,
                         state=None):
        """Steady run at one speed as arrays: :meth:`simulate` without the DataFrame.

        The same numbers, bit for bit; for inner loops that run thousands of
        simulations (a calibration), where building a DataFrame per speed step held
        the GIL for a third of an evaluation.

        Parameters
        ----------
        omega, fs, n_samples, settle, substeps
            As in :meth:`simulate`.
        state : tuple of ndarray, optional
            ``(q, v)`` at ``t = -settle`` (from :meth:`warm_state`); by default the
            run starts at rest on the static deflection.

        Returns
        -------
        dict
            Column name -> 1-D array, the columns of :meth:`simulate` in its order.
            The arrays may be views of one buffer: copy before writing into them.

        Examples
        --------
        >>> from sknarx.rotor import RotorBearingSimulator
        >>> cols = RotorBearingSimulator().simulate_columns(150.0, n_samples=200, settle=0.1)
        >>> list(cols)[:4], cols["xO1"].shape
        (['speed', 't', 'u', 'phi'], (200,))
        """
        omega = float(self._check_speeds(omega)[0])
        self._check_grid(fs, n_samples, settle)
        n_settle = int(round(settle * fs))
        grid = self._speed_grid(omega, fs, n_settle, n_settle + int(n_samples) + 1)
        columns = self._run(grid, n_settle, fs, f"speed {omega:g} rad/s", substeps, state)
        columns.pop("_state")
        # the nominal speed, not the fluctuating one the integrator saw
        columns["speed"] = np.full(columns["t"].size, omega)
        return self._measure(columns, omega, int(n_samples))

    def steady_state(self, omega, harmonics=8, start=None):
        """The settled shaft-periodic response at ``omega`` rad/s by harmonic balance.

        Solved directly instead of integrated to (see :mod:`sknarx.rotor.steady`: what
        it leaves out, and which effects it declines); raises
        :class:`~sknarx.rotor.steady.HarmonicBalanceError` where it does not converge
        or an effect may make the orbit sub-synchronous.

        Parameters
        ----------
        omega : float
            Speed, rad/s.
        harmonics : int, default=8
            Highest shaft order held.
        start : SteadyState, optional
            A nearby solution to start from.

        Returns
        -------
        SteadyState
            Fourier coefficients per DOF (m, rad), :meth:`SteadyState.order_vector`,
            :meth:`SteadyState.displacements` at any instants.

        Examples
        --------
        >>> from sknarx.rotor import RotorBearingSimulator
        >>> sim = RotorBearingSimulator()
        >>> state = sim.steady_state(150.0)
        >>> run = sim.simulate_columns(150.0, n_samples=1000, settle=2.0)
        >>> x = state.displacements(run["t"])[:, state.dof_names.index("xO1")]
        >>> bool(abs(x - run["xO1"]).max() < 0.01 * abs(run["xO1"]).max())
        True
        """
        return solve_steady_state(self, float(self._check_speeds(omega)[0]),
                                  harmonics=harmonics, start=start)

    def run_up(self, omega, fs=1000.0, duration=None, settle=1.0, substeps=None):
        """Run with a speed profile (run-up or coast-down).

        Parameters
        ----------
        omega : callable or array-like
            ``omega(t)`` in rad/s for ``t`` in seconds (``t = 0`` is the first
            recorded sample; ``t < 0`` is the settling run at ``omega(0)``), or one
            value per recorded sample.
        fs : float
            Sampling rate, Hz.
        duration : float
            Recorded duration, s (needed with a callable).
        settle : float
            Seconds at the initial speed before recording.

        Returns
        -------
        DataFrame
            As :meth:`simulate`, with ``speed`` varying per sample.
        """
        if callable(omega):
            if duration is None:
                raise ValueError("duration (s) is required when omega is a function of time.")
            n = int(round(duration * fs))
            w = np.asarray(omega(np.arange(n + 1) / fs), dtype=float)
        else:
            w = np.asarray(omega, dtype=float)
            if w.ndim != 1 or w.size < 2:
                raise ValueError("omega must be a function of t or a 1-D array of speeds.")
            w = np.r_[w, w[-1]]
            n = w.size - 1
        self._check_speeds(w)
        self._check_grid(fs, n, settle)
        n_settle = int(round(settle * fs))
        grid = np.r_[np.full(n_settle, w[0]), w]
        for eff in self.effects:
            t = (np.arange(grid.size) - n_settle) / fs
            grid = np.asarray(eff.modify_speed(t, grid, np.random.default_rng(self.seed)),
                              dtype=float)
        columns = self._run(grid, n_settle, fs, "the run-up", substeps)
        columns.pop("_state")
        return pd.DataFrame(self._measure(columns, float(w[0]), n))

    def settings(self, **grid) -> dict:
        """Everything that determines a sweep's numbers (stored as metadata)."""
        from .._version import __version__

        return {
            "sknarx_version": __version__,
            "params": self.params.to_dict(),
            "effects": [repr(e) for e in self.effects],
            "step_factor": self.step_factor,
            "seed": self.seed,
            **grid,
        }

    def sweep(self, speeds, fs=1000.0, n_samples=81921, settle=2.0, n_jobs=1, path=None,
              progress=True):
        """Steady runs at many speeds, as one long table.

        Parameters
        ----------
        speeds : array-like
            Speeds, rad/s.
        fs, n_samples, settle :
            As in :meth:`simulate` (defaults: the paper's 81,921 samples).
        n_jobs : int, default=1
            Parallel workers (joblib; threads by default since the integrator
            releases the GIL; ``joblib.parallel_config(backend='dask')`` sends the
            speeds to a dask.distributed cluster). Results do not depend on it.
        path : str or Path, optional
            Directory where each finished speed is written atomically; a rerun
            resumes, simulating only missing speeds.
        progress : bool, default=True
            Show a progress bar.

        Returns
        -------
        DataFrame
            Long table (see :meth:`simulate`) sorted by speed, settings in
            ``df.attrs['settings']``.
        """
        speeds = self._check_speeds(speeds)
        self._check_grid(fs, n_samples, settle)
        settings = self.settings(fs=float(fs), n_samples=int(n_samples), settle=float(settle))
        store = None
        todo = list(speeds)
        if path is not None:
            store = SweepStore(path)
            store.open(settings)
            todo = [w for w in speeds if not store.done(w)]
        _ = self._setup  # compute once, before workers share the simulator

        def one(w):
            table = self.simulate(w, fs=fs, n_samples=n_samples, settle=settle)
            if store is not None:
                store.write(w, table)
            return w, table

        results = {}
        jobs = Parallel(n_jobs=n_jobs, prefer="threads", return_as="generator_unordered")(
            delayed(one)(w) for w in todo
        )
        bar = _progress(len(todo), progress, "sweep")
        for w, table in jobs:
            results[w] = table
            bar.update(1)
        bar.close()
        tables = [results[w] if w in results else store.read(w) for w in speeds]
        order = np.argsort(speeds, kind="stable")
        df = pd.concat([tables[i] for i in order], ignore_index=True)
        df.attrs["settings"] = settings
        return df


def _progress(total, enabled, desc):
    try:
        from tqdm.auto import tqdm
    except ImportError:  # pragma: no cover
        enabled = False
    if not enabled:
        class _Null:
            def update(self, n):
                pass

            def close(self):
                pass

        return _Null()
    return tqdm(total=total, desc=desc, unit="speed")
