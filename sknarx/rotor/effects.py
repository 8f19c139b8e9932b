"""Physical effects that extend the nominal simulator without touching the integrator.

An effect acts at one (or more) of four places in the data flow:

1. **parameters** -- it changes the nominal :class:`RotorParameters` (bearing
   clearance);
2. **forces** -- it adds generalised forces through a numba-compiled kernel
   ``kernel(t, phi, omega, alpha, q, v, params, out)`` (rub, misalignment, crack,
   joint looseness); the simulator composes the kernels of all active effects into
   the integrator's single hook (the package's own as one program of one compiled
   dispatcher, see :func:`compose_force_kernels`);
3. **speed** -- it changes the speed profile (speed fluctuation);
4. **measurement** -- it changes what the probes see (runout, noise).

Every effect has a canonical ``name`` (used in reports and JSON), a few physical
parameters with ``bounds`` (and whether they are searched on a log scale), and a
``signature``: what it is expected to do to the response. A new effect subclasses
:class:`Effect` and overrides what it needs; nothing else changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from functools import lru_cache

import numpy as np
from numba import njit

from .parameters import DOF_NAMES
from .pedestals import JOURNAL_OF, Pedestals

__all__ = [
    "Effect",
    "Rub",
    "Misalignment",
    "BreathingCrack",
    "JointLooseness",
    "ClearanceChange",
    "SupportAnisotropy",
    "SupportFlexibility",
    "ProbeRunout",
    "MeasurementNoise",
    "SpeedFluctuation",
    "EFFECTS",
    "compose_force_kernels",
]

_IDX = {n: i for i, n in enumerate(DOF_NAMES)}


@dataclass
class EffectContext:
    """What an effect may need to know about the simulator it joins."""

    q_static: np.ndarray  # static equilibrium, m / rad
    params: object = None  # effective RotorParameters
    bearing_stiffness: tuple = ()  # (K_A, K_B) averaged 2x2 tangent stiffness, N/m
    dof_index: dict = field(default_factory=lambda: dict(_IDX))


class Effect:
    """Base class: an effect that does nothing. Override the hooks you need.

    Class attributes: ``name`` (canonical), ``bounds`` (``{param: (lo, hi, scale)}``
    with scale ``'lin'`` or ``'log'``), ``discrete`` (``{field: choices}``: settings the
    calibration searches over a list, such as where the effect acts), ``signature``
    (expected evidence), ``alike`` (what such data cannot tell it from).
    """

    name = "none"
    bounds: dict = {}
    discrete: dict = {}  # {field: choices} searched over a list (a location, a station)
    units: dict = {}  # {param: SI unit, "-" for a ratio}
    signature = ""
    #: what a stepped sweep shows the same way: the physical causes such data cannot tell
    #: from this effect, and the measurement that would (said beside a verdict naming it)
    alike = ""
    #: the restricted form of this effect that only changes the linear rotor (an
    #: :class:`Effect` class, or None): what that form explains as well is model error,
    #: not this effect (see :meth:`linear_form_of`)
    linear_form = None
    #: whether the settled response stays locked to the shaft revolution whatever the
    #: parameters (harmonic balance may solve it, :mod:`sknarx.rotor.steady`); False for
    #: an effect that can make it sub-synchronous, quasi-periodic or chaotic (a contact,
    #: an impact, a fluctuating speed): its settled records are integrated, unless it
    #: acts through a force alone and that force is nil along the balanced orbit
    shaft_periodic = True

    def linear_form_of(self):
        """This effect's nearest instance of :attr:`linear_form` (None without one)."""
        return None

    def modify_parameters(self, params):
        """The rotor parameters with this effect's static change applied (a new object).

        Parameters
        ----------
        params : RotorParameters

        Returns
        -------
        RotorParameters
        """
        return params

    def force_kernel(self, context: EffectContext):
        """The compiled extra force of this effect, or ``None``.

        Returns ``(kernel, params_array)``: a numba function
        ``kernel(t, phi, omega, alpha, q, v, p, out)`` that adds its generalised
        forces (N, N m) to ``out`` from the state ``q`` (m, rad) and ``v``, and the
        float array ``p`` it reads (DOF indices first).
        """
        return None

    def pedestals(self):
        """The bearing housings this effect mounts on pedestals, or ``None``.

        Returns a :class:`~sknarx.rotor.pedestals.Pedestals`: the simulator adds each
        housing's two DOFs (``HOUSING_NAMES``) and puts the ball contact and the bearing
        damper between journal and housing. At most one effect of a simulator may.
        """
        return None

    def modify_speed(self, t, omega, rng):
        """The shaft speed (rad/s) the rotor actually turns at, given the nominal ``omega``.

        Parameters
        ----------
        t : ndarray
            Time, s.
        omega : ndarray
            Nominal speed, rad/s.
        rng : numpy.random.Generator
            Seeded per speed step.
        """
        return omega

    def measure(self, table, rng, context=None):
        """Change the recorded columns and return them.

        ``table`` maps column names (``speed``, ``t``, ``u``, ``phi`` and the DOFs, as
        in :meth:`RotorBearingSimulator.simulate`; m, rad) to 1-D arrays. Assign new
        arrays rather than writing into the given ones (they may be views of the
        integrator's output). ``rng`` is seeded per speed step; ``context`` is the
        :class:`EffectContext` the force kernels were given (static equilibrium,
        bearing stiffness), for a measurement that depends on the rotor.
        """
        return table

    # -- calibration interface -------------------------------------------------
    @classmethod
    def param_names(cls) -> list[str]:
        """Names of the searched parameters, in ``bounds`` order."""
        return list(cls.bounds)

    def vector(self) -> np.ndarray:
        """The searched parameters in ``bounds`` order (the calibration's vector)."""
        return np.array([getattr(self, n) for n in self.param_names()], dtype=float)

    @classmethod
    def from_vector(cls, x):
        """The effect with its searched parameters from a calibration vector."""
        return cls.from_params({n: float(v) for n, v in zip(cls.param_names(), x,
                                                             strict=True)})

    @classmethod
    def from_params(cls, params: dict):
        """The effect from its searched parameters by name (``bounds``), with any of its
        other fields (a discrete setting such as a crack's station)."""
        return cls(**params)

    def to_dict(self) -> dict:
        """All fields of the effect (parameters, location) as a plain dict."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def __repr__(self):
        body = ", ".join(f"{k}={v!r}" for k, v in self.to_dict().items())
        return f"{type(self).__name__}({body})"


def _check_choice(effect, field_name):
    """A discrete setting must be one of the effect's ``discrete`` choices."""
    choices = type(effect).discrete[field_name]
    value = getattr(effect, field_name)
    if value not in choices:
        raise ValueError(f"{type(effect).__name__}: {field_name}={value!r} is not one of "
                         f"{', '.join(map(str, choices))}.")


# ---------------------------------------------------------------- force kernels
@njit(nogil=True, cache=True)
def _rub_kernel(t, phi, omega, alpha, q, v, p, out):  # pragma: no cover
    ix, iy = int(p[0]), int(p[1])
    x = q[ix] - p[2]
    y = q[iy] - p[3]
    r = math.sqrt(x * x + y * y)
    gap, kr, mu = p[4], p[5], p[6]
    if r > gap:
        fn = kr * (r - gap)
        cx, cy = x / r, y / r
        # normal force inward; Coulomb friction against the surface speed of a
        # forward-spinning shaft (tangent direction (-cy, cx))
        out[ix] += -fn * cx + mu * fn * cy
        out[iy] += -fn * cy - mu * fn * cx


@dataclass(repr=False)
class Rub(Effect):
    """Rotor-stator rub at a disk: radial contact beyond a clearance, with friction.

    ``F_n = k_c (r - c)`` for ``r > c`` (``r``: the disk's radial displacement from
    the stator centre), Coulomb friction ``mu F_n`` against the spin (Muszynska,
    *Rotordynamics*, 2005, ch. 7). The stator centre sits ``(offset_x, offset_y)``
    (m) from the disk's static equilibrium: a seal or casing is aligned with the
    bearings, not with the rotor's gravity sag (about 0.56 mm at the paper rotor's
    disks), and rarely even with those, so a rotor rubs first on one side long before
    its orbit reaches the clearance.

    Parameters: ``clearance`` (m), ``stiffness`` (N/m), ``friction`` (-),
    ``offset_x``, ``offset_y`` (m), ``at`` (``'O1'`` or ``'O2'``, searched as a
    discrete parameter).
    """

    clearance: float = 5e-4
    stiffness: float = 5e6
    friction: float = 0.1
    offset_x: float = 0.0
    offset_y: float = 0.0
    at: str = "O1"
    name = "rub"
    shaft_periodic = False  # a rub can make 1/2x, 1/3x and chaos (Muszynska 2005)
    bounds = {"clearance": (1e-4, 2e-3, "log"), "stiffness": (1e5, 1e8, "log"),
              "friction": (0.0, 0.3, "lin"), "offset_x": (-1e-3, 1e-3, "lin"),
              "offset_y": (-1e-3, 1e-3, "lin")}
    #: where a calibration starts the parameters (the others: a quarter into the range)
    start = {"offset_x": 0.0, "offset_y": 0.0}
    discrete = {"at": ("O1", "O2")}
    units = {"clearance": "m", "stiffness": "N/m", "friction": "-", "offset_x": "m",
             "offset_y": "m", "at": ""}
    signature = ("amplitude clipped near the response peak; 2x, 3x and sub-synchronous "
                 "(1/2x, 1/3x) orders where the orbit exceeds the clearance")

    def __post_init__(self):
        _check_choice(self, "at")

    def force_kernel(self, context):
        ix, iy = context.dof_index["x" + self.at], context.dof_index["y" + self.at]
        p = np.array([ix, iy, context.q_static[ix] + self.offset_x,
                      context.q_static[iy] + self.offset_y, self.clearance,
                      self.stiffness, self.friction], dtype=float)
        return _rub_kernel, p


@njit(nogil=True, cache=True)
def _misalignment_kernel(t, phi, omega, alpha, q, v, p, out):  # pragma: no cover
    ix, iy = int(p[0]), int(p[1])
    kc, par, ang, lc = p[2], p[3], p[4], p[5]
    cd, sd, phase, whirl, phase1 = p[6], p[7], p[8], p[9], p[10]
    jx, jy, lever = int(p[11]), int(p[12]), p[13]
    # parallel offset: a force at twice the shaft angle, (kc par / 2) e^{i direction}
    # (-1 + cos th + i whirl sin th), th = 2 phi + phase: planar along the offset with
    # its static part (whirl 0), an ellipse, or a circle (whirl +-1)
    th = 2.0 * phi + phase
    a = 0.5 * kc * par
    gx = -1.0 + math.cos(th)
    gy = whirl * math.sin(th)
    # angular: a 1x bending moment, seen at the journal as a rotating force
    f1 = kc * lc * ang
    fx = a * (cd * gx - sd * gy) - f1 * math.cos(phi + phase1)
    fy = a * (sd * gx + cd * gy) - f1 * math.sin(phi + phase1)
    out[ix] += fx
    out[iy] += fy
    # the coupling's reaction across its shaft segment: the opposite force, a share
    # ``lever`` of it, where that segment meets the rotor's next station (its disk)
    out[jx] -= lever * fx
    out[jy] -= lever * fy


@dataclass(repr=False)
class Misalignment(Effect):
    """Coupling misalignment at a bearing end (``at``: ``'A'``, the drive end, or ``'B'``;
    searched as a discrete parameter).

    Phenomenological model after Redmond & Al-Hussain (J. Sound Vib. 2010): a
    flexible coupling of lateral stiffness ``k_c = 1e6 N/m`` and length
    ``L_c = 0.1 m`` transmits, for a parallel offset ``parallel`` (m) in the
    direction ``direction`` (rad from x), a force ``k_c parallel (1 - cos(2 phi +
    phase))/2`` along the offset (static preload + 2x) and, for an angular
    misalignment ``angular`` (rad), a rotating 1x force ``k_c L_c angular`` at
    ``angular_phase`` from the keyphasor. Couplings and their models differ in how
    the 2x reaction turns: ``whirl`` adds the quadrature component (0: planar along
    the offset, as Redmond's; +-1: a circular forward or backward 2x force, as
    Sekhar & Prabhu's coupling reaction), so the 2x force can take any ellipse and
    phase. They also differ in where it acts: Redmond's and Sekhar & Prabhu's reaction
    acts at the bearing (``lever = 0``); a coupling modelled as a flexible element of
    the shaft line (Xia et al., 2019, as ROSS's ``MisalignmentFlex``) pushes its two
    ends apart, an equal and opposite force pair across that element, of which the
    inboard one reaches the rotor between the bearing and the next disk. ``lever``
    (0-1) is the share of the reaction that acts, opposite, at that disk (O1 for
    ``at='A'``, O2 for ``'B'``): a pair across a third of segment A-O1 is, to the
    stations of this model, about ``F/3`` at the journal and ``-F/3`` at the disk
    (``lever = 1`` with a third of the force). Signature: 2x at the drive-end journal
    and the disks, growing with offset but not with speed; a static shift (invisible
    to AC-coupled probes); for angular misalignment a speed-independent 1x vector.

    A calibration searches the offset, its direction and the 2x form (``bounds``),
    not the angular misalignment: a rotating 1x force of free size and phase at a
    journal is what an imperfect nominal model also leaves there (the smooth 1x
    mismatch that nominal model updating owns), so lateral probes cannot credit it
    to the coupling; and coupling models do not agree that angular misalignment
    makes one (ROSS's ``MisalignmentFlex``: none; Sekhar & Prabhu: a 2x reaction).
    """

    parallel: float = 1e-4
    angular: float = 0.0
    direction: float = 0.0
    phase: float = 0.0
    whirl: float = 0.0
    angular_phase: float = 0.0
    lever: float = 0.0
    at: str = "A"
    name = "misalignment"
    #: searched: the offset, the 2x reaction's form and where it acts (not ``angular``:
    #: see above)
    bounds = {"parallel": (0.0, 1e-3, "lin"), "direction": (-math.pi, math.pi, "lin"),
              "phase": (-math.pi, math.pi, "lin"), "whirl": (-1.0, 1.0, "lin"),
              "lever": (0.0, 1.0, "lin")}
    #: where a calibration starts the parameters (the others: a quarter into the range)
    start = {"direction": 0.0, "phase": 0.0, "whirl": 0.0, "lever": 0.0}
    discrete = {"at": ("A", "B")}
    #: the station next to each bearing end, where an inboard reaction reaches the rotor
    INBOARD = {"A": "O1", "B": "O2"}
    units = {"parallel": "m", "angular": "rad", "direction": "rad", "phase": "rad",
             "whirl": "-", "angular_phase": "rad", "lever": "-", "at": ""}
    signature = ("2x at every speed (not growing with speed^2), strongest at the coupled "
                 "bearing; 1x offset")
    K_C = 1e6
    L_C = 0.1

    def __post_init__(self):
        _check_choice(self, "at")
        if not 0.0 <= self.lever <= 1.0:
            raise ValueError(f"Misalignment: lever={self.lever!r} must lie in [0, 1] (the "
                             "share of the coupling reaction acting at the next disk).")

    def force_kernel(self, context):
        p = np.array([context.dof_index["x" + self.at], context.dof_index["y" + self.at],
                      self.K_C, self.parallel, self.angular, self.L_C,
                      # the offset's direction enters as its cosine and sine, computed
                      # here once rather than at every force evaluation
                      math.cos(self.direction), math.sin(self.direction), self.phase,
                      self.whirl, self.angular_phase,
                      context.dof_index["x" + self.INBOARD[self.at]],
                      context.dof_index["y" + self.INBOARD[self.at]], self.lever],
                     dtype=float)
        return _misalignment_kernel, p


@njit(nogil=True, cache=True)
def _crack_kernel(t, phi, omega, alpha, q, v, p, out):  # pragma: no cover
    # p: lost stiffness, crack angle, then the cracked element's deformation in each
    # plane as four (DOF index, coefficient) pairs: x plane from p[2], y plane from p[10],
    # then the element's stiffness change in every direction (p[18]) and the direction
    # the crack's normal points at when it is fully open (p[19])
    dk, psi, ds, opening = p[0], p[1], p[18], p[19]
    dx = 0.0
    dy = 0.0
    for k in range(4):
        dx += p[3 + 2 * k] * q[int(p[2 + 2 * k])]
        dy += p[11 + 2 * k] * q[int(p[10 + 2 * k])]
    nx, ny = math.cos(phi + psi), math.sin(phi + psi)
    xi = nx * dx + ny * dy
    # breathing (Mayes & Davies): fully open when the normal points at ``opening``, the
    # tension side of the static bending at the crack
    h = 0.5 * (1.0 + math.cos(phi + psi - opening))
    f = dk * h * xi  # the cracked direction loses stiffness dk: add back dk*h*xi
    # ... and the element is ds stiffer in every direction (restoring -ds * deformation)
    fx, fy = f * nx - ds * dx, f * ny - ds * dy
    for k in range(4):
        out[int(p[2 + 2 * k])] += fx * p[3 + 2 * k]
        out[int(p[10 + 2 * k])] += fy * p[11 + 2 * k]


def _joint_lateral_stiffness(params) -> float:
    """The bolted joint's stiffness on the disks' relative lateral displacement
    ``w_O2 - w_O1 - d/2 (slope_O1 + slope_O2)``, N/m: the shaft element through the joint
    (``12 E I / d^3 = k``, ``matrices.py``) in parallel with the contact ``kb``."""
    return params.k + params.kb


def _crack_element(station, params, dof):
    """Stiffness of the cracked element's lateral mode and its deformation per plane.

    The deformations are those of ``matrices.py``: a segment's deflection relative to
    the tangent at its disk, and the joint's relative lateral displacement
    ``w_O2 - w_O1 - d/2 (slope_O1 + slope_O2)``, on which the shaft through the joint
    (12 E I / d^3 = k) and the contact stiffness kb act in parallel. Slopes are ``ty``
    in the x-z plane and ``-tx`` in the y-z plane.
    """
    p = params
    if station == "A-O1":
        k = p.k1
        x = {"xA": -1.0, "xO1": 1.0, "tyO1": -p.a1}
        y = {"yA": -1.0, "yO1": 1.0, "txO1": p.a1}
    elif station == "O2-B":
        k = p.k2
        x = {"xO2": -1.0, "tyO2": -p.b2, "xB": 1.0}
        y = {"yO2": -1.0, "txO2": p.b2, "yB": 1.0}
    elif station == "joint":
        d = p.a2 - p.a1
        k = _joint_lateral_stiffness(p)
        x = {"xO1": -1.0, "tyO1": -d / 2, "xO2": 1.0, "tyO2": -d / 2}
        y = {"yO1": -1.0, "txO1": d / 2, "yO2": 1.0, "txO2": d / 2}
    else:  # BreathingCrack checks its station when it is made
        raise ValueError(f"Unknown crack station {station!r}.")
    pairs = []
    for plane in (x, y):
        items = [(float(dof[n]), c) for n, c in plane.items()]
        items += [(0.0, 0.0)] * (4 - len(items))  # padding: coefficient 0
        pairs += [v for item in items for v in item]
    return k, pairs


@dataclass(repr=False)
class BreathingCrack(Effect):
    """Breathing transverse crack at one station of the shaft.

    The cracked element (shaft segment A-O1, the bolted joint with the shaft through
    it, or segment O2-B: ``station``) loses a fraction ``depth`` of its lateral
    stiffness in the direction normal to the crack, which rotates with the shaft at
    angle ``phi + angle``; the static bending opens and closes it once per revolution
    with the breathing function ``h = (1 + cos(phi + angle - opening))/2`` (Mayes &
    Davies, 1984; Gasch, J. Sound Vib. 1993): fully open when the normal points at
    ``opening`` (rad, in the fixed x-y frame), the tension side of the static bending
    at the crack. Gravity alone bends the shaft in the vertical plane, but which side
    is in tension depends on where along the element the crack sits (the bending
    moment of a span between a bearing and a disk changes sign along it) and static
    loads that are not vertical (a misaligned bearing, a bow) turn it, so it is
    searched; ``pi/2`` (the normal along +y) is the model's gravity-driven default.
    ``(angle, opening)`` and ``(angle + pi, opening + pi)`` are one crack (the
    normal's sign only says which side opens, and that turns with it).
    The station is searched as a discrete parameter (``discrete``). Signature: 2x (and
    3x) rising near half the critical speed; a small 1x change.

    ``element_scale`` is the cracked element's stiffness (closed) relative to the
    model's: a crack's mean loss of stiffness is linear and looks to the 1x like a
    softer element, which nominal model updating may already have taken (a stiffness it
    is allowed to correct). With the element's stiffness fitted with it, a crack is
    credited only with what updating cannot explain -- its breathing. A calibration
    searches the element's *mean* stiffness over a revolution instead (``mean_scale =
    element_scale - depth / 4``: the open share ``h`` averages 1/2 and the crack's
    direction turns through both planes), so that the depth moves the breathing (2x,
    3x) and leaves the 1x to ``mean_scale``: searched as depth and closed stiffness, the
    two trade along a narrow valley that short local runs do not follow.

    Examples
    --------
    >>> from sknarx.rotor import BreathingCrack
    >>> crack = BreathingCrack(depth=0.4, station="O2-B")
    >>> round(crack.mean_scale, 2)
    0.9
    >>> BreathingCrack.from_params({"depth": 0.4, "angle": 0.0, "mean_scale": 1.0,
    ...                             "station": "O2-B"}).element_scale
    1.1
    """

    depth: float = 0.1
    angle: float = 0.0
    station: str = "A-O1"
    element_scale: float = 1.0
    opening: float = 0.5 * math.pi
    name = "crack"
    STATIONS = ("A-O1", "joint", "O2-B")
    bounds = {"depth": (0.0, 0.6, "lin"), "angle": (-math.pi, math.pi, "lin"),
              "mean_scale": (0.7, 1.4, "log"), "opening": (-math.pi, math.pi, "lin")}
    #: where a calibration starts the parameters (the others: a quarter into the range)
    start = {"mean_scale": 1.0, "opening": 0.5 * math.pi}
    #: settings searched over a list rather than a range (the calibration probes each)
    discrete = {"station": STATIONS}
    units = {"depth": "- (stiffness lost, open)", "angle": "rad", "station": "",
             "element_scale": "- (element stiffness, closed / model's)",
             "mean_scale": "- (element stiffness, mean over a revolution / model's)",
             "opening": "rad (the normal's direction when fully open)"}
    signature = "2x and 3x, peaking near 1/2 and 1/3 of the critical speed"

    def __post_init__(self):
        _check_choice(self, "station")

    @property
    def mean_scale(self) -> float:
        """The element's stiffness averaged over a revolution, relative to the model's."""
        return self.element_scale - 0.25 * self.depth

    @classmethod
    def from_params(cls, params: dict):
        """The crack from its searched parameters (``mean_scale`` for the element's
        closed stiffness) and its other fields."""
        p = dict(params)
        mean = p.pop("mean_scale", None)
        if mean is not None:
            p["element_scale"] = mean + 0.25 * p.get("depth", cls.depth)
        return cls(**p)

    def force_kernel(self, context):
        k, pairs = _crack_element(self.station, context.params, context.dof_index)
        return _crack_kernel, np.array([self.depth * k, self.angle, *pairs,
                                        (self.element_scale - 1.0) * k, self.opening])


@njit(nogil=True, cache=True)
def _looseness_kernel(t, phi, omega, alpha, q, v, p, out):  # pragma: no cover
    # p: lost lateral and tilt stiffness, joint length, opening, then the DOF indices
    # of x, y, tx, ty at O1 and at O2
    lkj, lkt, d, gap = p[0], p[1], p[2], p[3]
    x1, y1, tx1, ty1 = int(p[4]), int(p[5]), int(p[6]), int(p[7])
    x2, y2, tx2, ty2 = int(p[8]), int(p[9]), int(p[10]), int(p[11])
    # the joint's relative lateral displacement w_O2 - w_O1 - d/2 (slope_O1 + slope_O2)
    # in each plane (slopes: ty in x-z, -tx in y-z); the interface is a circle, so it
    # opens on the radial displacement, not per plane
    djx = q[x2] - q[x1] - 0.5 * d * (q[ty1] + q[ty2])
    djy = q[y2] - q[y1] + 0.5 * d * (q[tx1] + q[tx2])
    u = math.sqrt(djx * djx + djy * djy)
    if u <= gap:
        return
    # the lost share grows from nothing at the opening (force continuous there): a
    # stiffness switched on whole at u = gap is a step the integrator cannot resolve
    share = (u - gap) / u
    for plane in range(2):
        if plane == 0:
            i1, j1, i2, j2, sg, dj = x1, ty1, x2, ty2, 1.0, djx
        else:
            i1, j1, i2, j2, sg, dj = y1, tx1, y2, tx2, -1.0, djy
        s1, s2 = sg * q[j1], sg * q[j2]
        # the joint's restoring force is -k dj d(dj)/dq; removing the lost share adds
        # +k_lost dj d(dj)/dq, and likewise for the tilt
        fj = lkj * dj * share
        ft = lkt * (s2 - s1) * share
        out[i1] -= fj
        out[i2] += fj
        out[j1] += sg * (-0.5 * d * fj - ft)
        out[j2] += sg * (-0.5 * d * fj + ft)


@dataclass(repr=False)
class JointLooseness(Effect):
    """Bolted-joint loosening: the joint with the shaft through it goes slack once its
    interface opens.

    Beyond a radial opening ``gap`` (m) of the joint's relative lateral displacement
    ``w_O2 - w_O1 - d/2 (slope_O1 + slope_O2)``, only ``residual`` of the joint's
    stiffness is left: of the lateral stiffness ``k + kb`` (the shaft through the joint,
    ``12 E I / d^3 = k``, in parallel with the contact ``kb``) and of the tilt stiffness
    ``k_theta + E I / d`` (the contact's and the shaft's). The loss grows as
    ``(1 - gap / u)`` with the opening ``u``, so the force is continuous there (after
    Qin et al., J. Sound Vib. 2014: piecewise-linear contact). Signature: a lower
    response peak frequency and harmonics (2x, 3x, 1/2x) from the bilinear stiffness.

    Examples
    --------
    >>> from sknarx.rotor import JointLooseness
    >>> JointLooseness(residual=0.01, gap=2e-6).name
    'looseness'
    """

    residual: float = 0.1
    gap: float = 0.0
    name = "looseness"
    shaft_periodic = False  # a loose joint opens and closes: 1/2x (Goldman & Muszynska)
    bounds = {"residual": (1e-4, 1.0, "log"), "gap": (0.0, 2e-5, "lin")}
    units = {"residual": "- (joint stiffness left)", "gap": "m"}
    signature = "shift of the response peak, harmonics and subharmonics from bilinear contact"

    def force_kernel(self, context):
        P = context.params
        loss = 1.0 - self.residual
        d = P.a2 - P.a1
        # the Euler-Bernoulli element through the joint is 12EI/d^3 = k on the relative
        # lateral displacement plus EI/d = k d^2/12 on the relative tilt
        dof = context.dof_index
        return _looseness_kernel, np.array([loss * _joint_lateral_stiffness(P),
                                            loss * (P.k_theta + P.k * d * d / 12.0),
                                            d, self.gap,
                                            *(dof[n + at] for at in ("O1", "O2")
                                              for n in ("x", "y", "tx", "ty"))])


@dataclass(repr=False)
class SupportAnisotropy(Effect):
    """Flexible, anisotropic foundation: each bearing's housing, of ``mass`` (kg), on a
    pedestal of stiffness ``kx``, ``ky`` (N/m) and ``damping`` (N s/m, both directions).

    The simulator adds the two housings' DOFs (:mod:`sknarx.rotor.pedestals`): the
    Hertzian ball contact and the bearing damper (``c_a``, ``c_b``) act between journal
    and housing, the pedestal between housing and frame. The contact stays nonlinear:
    a journal orbiting about its static sag unloads and stiffens the contact every
    revolution, and what a soft pedestal takes depends on that orbit -- a linear series
    spring about the static sag overstated it up to sevenfold at a bearing whose orbit
    exceeds its sag. The housing's mass gives the support a resonance
    of its own, near ``sqrt((k_H + k_p) / mass)``.

    Where the journal probes are fixed matters as soon as the housing moves:
    ``probes='housing'`` (proximity probes mounted in the bearing housing, the usual
    arrangement) read the journal minus its housing; ``probes='frame'`` read it against
    the frame. The disk probes always read against the frame. The housings' own
    displacements are not recorded columns.

    Signature: the critical speed splits into a horizontal and a vertical one;
    elliptical orbits, x and y 1x amplitudes peak at different speeds.

    Examples
    --------
    >>> from sknarx.rotor import RotorBearingSimulator, SupportAnisotropy
    >>> soft_x = SupportAnisotropy(kx=5e6, ky=1e9, mass=15.0, damping=900.0)
    >>> sim = RotorBearingSimulator(effects=[soft_x])
    >>> sim.dof_names[-4:]
    ('xHA', 'yHA', 'xHB', 'yHB')
    >>> cols = sim.simulate_columns(150.0, n_samples=200, settle=0.2)
    >>> "xHA" in cols, cols["xA"].shape
    (False, (200,))
    """

    kx: float = 5e6
    ky: float = 2e7
    mass: float = 10.0
    damping: float = 0.0
    probes: str = "housing"
    name = "anisotropy"
    # a housing has mass: the lower bound keeps its mode within a few times the
    # rotor's fastest one (the integration step follows it)
    bounds = {"kx": (1e6, 1e9, "log"), "ky": (1e6, 1e9, "log"), "mass": (2.0, 40.0, "lin"),
              "damping": (0.0, 2e4, "lin")}
    #: a calibration starts from an undamped pedestal under a housing of middling mass
    start = {"mass": 10.0, "damping": 0.0}
    #: where the journal probes are fixed (a rig fact, not searched)
    PROBES = ("housing", "frame")
    units = {"kx": "N/m", "ky": "N/m", "mass": "kg", "damping": "N s/m", "probes": ""}
    signature = "split critical speed: x and y 1x peaks at different speeds, elliptic orbits"

    def __post_init__(self):
        if self.probes not in self.PROBES:
            raise ValueError(f"SupportAnisotropy: probes={self.probes!r} is not one of "
                             f"{', '.join(self.PROBES)}.")
        self.pedestals()  # the values' checks, named

    def pedestals(self):
        return Pedestals(mass=float(self.mass), stiffness=(float(self.kx), float(self.ky)),
                         damping=(float(self.damping), float(self.damping)))

    def measure(self, table, rng, context=None):
        return _read_journals(table, self.probes)

    def linear_form_of(self):
        """The isotropic support of the same housing mass and damping, its stiffness the
        geometric mean of ``kx`` and ``ky``."""
        return SupportFlexibility(k=float(np.sqrt(self.kx * self.ky)), mass=self.mass,
                                  damping=self.damping, probes=self.probes)


def _read_journals(table, probes):
    """The journal columns as probes fixed in the housing (``'housing'``) or the frame
    read them."""
    if probes == "housing":
        for housing, journal in JOURNAL_OF.items():
            if housing in table and journal in table:
                # the journal read from its own housing
                table[journal] = np.asarray(table[journal]) - np.asarray(table[housing])
    return table


@dataclass(repr=False)
class SupportFlexibility(Effect):
    """Flexible, isotropic foundation: each bearing's housing, of ``mass`` (kg), on a
    pedestal of stiffness ``k`` (N/m) and ``damping`` (N s/m), the same in x and y.

    Not a candidate effect: it is :class:`SupportAnisotropy` with ``kx == ky``, a change
    of the linear rotor only (the housings' resonance shifts the rotor's), which the gap
    diagnosis counts as model error. It tests a fitted anisotropy: where this form
    explains the measurement as well, the support was flexible, not anisotropic
    (:attr:`Effect.linear_form`). The contact acts between journal and housing and the
    journal probes read as ``probes`` says, as for :class:`SupportAnisotropy`.

    Examples
    --------
    >>> from sknarx.rotor import SupportAnisotropy
    >>> SupportAnisotropy(kx=4e6, ky=9e6, mass=15.0).linear_form_of().k
    6000000.0
    """

    k: float = 1e7
    mass: float = 10.0
    damping: float = 0.0
    probes: str = "housing"
    name = "support-flexibility"
    bounds = {"k": (1e6, 1e9, "log"), "mass": (2.0, 40.0, "lin"), "damping": (0.0, 2e4, "lin")}
    start = {"mass": 10.0, "damping": 0.0}
    units = {"k": "N/m", "mass": "kg", "damping": "N s/m", "probes": ""}
    signature = "a shifted critical speed and support resonance, the same in x and y"

    def __post_init__(self):
        if self.probes not in SupportAnisotropy.PROBES:
            raise ValueError(f"SupportFlexibility: probes={self.probes!r} is not one of "
                             f"{', '.join(SupportAnisotropy.PROBES)}.")
        self.pedestals()

    def pedestals(self):
        return Pedestals(mass=float(self.mass), stiffness=(float(self.k), float(self.k)),
                         damping=(float(self.damping), float(self.damping)))

    def measure(self, table, rng, context=None):
        return _read_journals(table, self.probes)


# set here, the restricted class being defined after the effect
SupportAnisotropy.linear_form = SupportFlexibility


@njit(nogil=True, cache=True)
def builtin_forces(t, phi, omega, alpha, q, v, p, out):  # pragma: no cover
    # p is a force program: the number of kernels, then (code, size, parameters) of
    # each, the code indexing _BUILTIN_KERNELS
    i = 1
    for _ in range(int(p[0])):
        code, size = int(p[i]), int(p[i + 1])
        kp = p[i + 2 : i + 2 + size]
        if code == 0:
            _rub_kernel(t, phi, omega, alpha, q, v, kp, out)
        elif code == 1:
            _misalignment_kernel(t, phi, omega, alpha, q, v, kp, out)
        elif code == 2:
            _crack_kernel(t, phi, omega, alpha, q, v, kp, out)
        elif code == 3:
            _looseness_kernel(t, phi, omega, alpha, q, v, kp, out)
        i += 2 + size


#: the kernels :func:`builtin_forces` dispatches to, in the order of their codes
_BUILTIN_KERNELS = (_rub_kernel, _misalignment_kernel, _crack_kernel, _looseness_kernel)


def compose_force_kernels(kernels):
    """One kernel that adds the forces of every ``(kernel, params)``; its parameters.

    The package's own kernels become one program of :func:`builtin_forces`, the same
    compiled function whatever the effects: numba compiles the integrator anew for
    each distinct kernel it is handed (about 5 s a time), so a search over effects and
    their pairs would otherwise compile once per combination. Other kernels (an
    :class:`Effect` of the user's) are chained after it.
    """
    program = [0.0]
    custom = []
    for kernel, p in kernels:
        p = np.asarray(p, dtype=float).ravel()
        if kernel in _BUILTIN_KERNELS:
            program[0] += 1
            program += [_BUILTIN_KERNELS.index(kernel), p.size, *p]
        else:
            custom.append((kernel, p))
    if not custom:
        return builtin_forces, np.array(program)
    funcs = (builtin_forces, *(k for k, _ in custom))
    sizes = (len(program), *(p.size for _, p in custom))
    return _chain(funcs, sizes), np.concatenate([program, *(p for _, p in custom)])


@lru_cache(maxsize=64)
def _chain(funcs, sizes):
    if len(funcs) == 1:
        return funcs[0]
    first, n1 = funcs[0], sizes[0]
    rest = _chain(funcs[1:], sizes[1:])

    @njit(nogil=True)
    def chained(t, phi, omega, alpha, q, v, p, out):  # pragma: no cover
        first(t, phi, omega, alpha, q, v, p[:n1], out)
        rest(t, phi, omega, alpha, q, v, p[n1:], out)

    return chained


# ----------------------------------------------------------------- parameters
@dataclass(repr=False)
class ClearanceChange(Effect):
    """Bearing radial clearance changed to ``clearance`` (m), e.g. by wear, with the
    balls' contact stiffness scaled by ``contact_scale`` (-) at both bearings.

    Signature: softer, more nonlinear bearings: stronger 2x and ball-pass
    components at the journals, a slightly lower response peak.

    Why the contact stiffness moves with it: a larger clearance softens a bearing's
    1x stiffness as a lower contact stiffness does, so a nominal update made without
    the clearance in the model lowers the contact stiffness to follow that 1x (by
    30-50 % on rotors derived apart from this one). The clearance alone, fitted on top
    of that
    update, then needs less clearance than the truth and leaves the harmonics half
    explained. ``contact_scale`` lets the candidate hand the softening back: the
    two are estimated together, as one change of the bearings.
    """

    clearance: float = 5e-6
    contact_scale: float = 1.0
    name = "clearance"
    shaft_periodic = False  # a clearance bearing bifurcates to 1/2x and chaos (Tiwari 2000)
    bounds = {"clearance": (5e-7, 5e-5, "log"), "contact_scale": (0.5, 2.0, "log")}
    units = {"clearance": "m", "contact_scale": "- (of the model's contact stiffness)"}
    start = {"contact_scale": 1.0}
    signature = "2x and ball-pass (3.08x) growth at the journals; response peak shift"

    def modify_parameters(self, params):
        # both bearings: the candidate is a change of the rig's bearings, not of one
        return params.replace(clearance=self.clearance, clearance_B=None,
                              kB=params.kB * self.contact_scale,
                              kB_B=params.resolved("kB_B") * self.contact_scale)


# ---------------------------------------------------------------------- speed
@dataclass(repr=False)
class SpeedFluctuation(Effect):
    """Sinusoidal speed ripple ``omega (1 + amplitude sin(2 pi frequency t + phase))``.

    ``t`` is each record's own time (0 at its first sample), so ``phase`` (rad) is where
    the ripple stands when a record starts. It is searched with the amplitude and the
    frequency: with a ripple of a cycle or a few per record the 1x smear and the
    sidebands depend on it as much as on the frequency, and a fit held at a wrong phase
    moves the frequency to make up for it (a 5.8 Hz ripple fitted at 2.9 Hz) and leaves
    a residual that any flexible partner then takes. One phase serves every record:
    exact where the records start at the same point of the ripple (a ripple locked to
    the trigger); where each record starts at its own point, one phase fits the
    sidebands of a ripple that runs many cycles per record and is an average below that.

    Signature: sidebands around 1x at +-``frequency`` (non-synchronous energy),
    smeared 1x amplitude.

    Examples
    --------
    >>> from sknarx.rotor import SpeedFluctuation
    >>> SpeedFluctuation.param_names()
    ['amplitude', 'frequency', 'phase']
    >>> ripple = SpeedFluctuation.from_vector([0.02, 3.0, 1.0])
    >>> round(ripple.phase, 3), ripple.units["phase"]
    (1.0, 'rad')
    """

    amplitude: float = 0.01
    frequency: float = 1.0
    phase: float = 0.0
    name = "speed-fluctuation"
    shaft_periodic = False  # the speed itself is not constant
    bounds = {"amplitude": (0.0, 0.05, "lin"), "frequency": (0.2, 20.0, "log"),
              "phase": (-math.pi, math.pi, "lin")}
    start = {"phase": 0.0}
    units = {"amplitude": "- (of the speed)", "frequency": "Hz", "phase": "rad"}
    signature = "non-synchronous sidebands around 1x; 1x amplitude reduced"

    def modify_speed(self, t, omega, rng):
        return omega * (1.0 + self.amplitude * np.sin(2 * np.pi * self.frequency * t + self.phase))


# ---------------------------------------------------------------- measurement
@dataclass(repr=False)
class ProbeRunout(Effect):
    """Slow-roll runout: what each probe reads of its track, the same at every speed.

    Mechanical and electrical runout of a probe track is fixed to the shaft, so it adds
    to that probe's signal a 1x (and, for an out-of-round or scratched track, a 2x)
    vector constant in amplitude and phase at every speed -- and each probe sees its
    own track. Two forms:

    * per probe, as the diagnosis fits it: ``vectors`` maps a channel (DOF name) to its
      ``(v1, v2)`` complex vectors, m, adding ``Re(v1 e^{i phi}) + Re(v2 e^{2 i phi})``;
      these enter the order features linearly and are solved in closed form for given
      other parameters (``projected_orders``), not searched;
    * one shared 1x vector (``amplitude``, ``phase``) on the probes at ``planes``:
      ``amplitude cos(phi + phase)`` on x, ``amplitude sin(phi + phase)`` on y.

    Both apply when given. Signature: a constant 1x (or 2x) vector per probe, dominant
    at low speed where the response is small.
    """

    amplitude: float = 0.0
    phase: float = 0.0
    planes: tuple = ("O1", "A", "O2", "B")
    vectors: dict = field(default_factory=dict)
    name = "runout"
    bounds = {}  # nothing searched: the per-probe vectors are solved in closed form
    #: orders whose constant per-channel vectors the calibration solves in closed form
    projected_orders = (1.0, 2.0)
    units = {"amplitude": "m", "phase": "rad", "vectors": "m"}
    signature = "a constant 1x (or 2x) vector per probe, dominant at low speed"
    # a bow fixed over the sweep is this runout plus a change of the disks' unbalance
    # (to 2-3 % of its 1x on rotors derived apart from this one: docs/decisions.md);
    # a relaxing one adds a smooth drift of 1x over a sweep whose speeds only rise
    alike = ("a bent shaft: a bow fixed over the sweep is such a runout plus a change of the "
             "disks' unbalance, and a bow relaxing as the rotor warms or cools adds a slow "
             "drift of 1x over the sweep, which the nominal update can follow; a speed "
             "measured again after the sweep, at another thermal state, tells them apart "
             "(a probe's runout does not change, a relaxing bow does)")

    @classmethod
    def from_vector(cls, x):
        """No searched parameters: the per-probe vectors come from the projection."""
        return cls()

    @classmethod
    def from_projection(cls, vectors):
        """The effect with per-channel vectors ``{channel: {order: complex}}`` (m)."""
        return cls(vectors={ch: (complex(v.get(1.0, 0.0)), complex(v.get(2.0, 0.0)))
                            for ch, v in vectors.items()})

    def order_vectors(self) -> dict:
        """The per-probe vectors as ``{channel: {order: complex}}`` (m), the form
        :meth:`from_projection` takes: what this runout adds to each probe's order
        features. The shared vector (``amplitude``) is not included."""
        return {ch: {1.0: complex(v1), 2.0: complex(v2)}
                for ch, (v1, v2) in self.vectors.items()}

    def measure(self, table, rng, context=None):
        phi = np.asarray(table["phi"])
        if self.amplitude:
            for plane in self.planes:
                if "x" + plane in table:
                    table["x" + plane] = table["x" + plane] + self.amplitude * np.cos(
                        phi + self.phase)
                if "y" + plane in table:
                    table["y" + plane] = table["y" + plane] + self.amplitude * np.sin(
                        phi + self.phase)
        for ch, (v1, v2) in self.vectors.items():
            if ch in table:
                table[ch] = table[ch] + np.real(v1 * np.exp(1j * phi)
                                                + v2 * np.exp(2j * phi))
        return table

    def to_dict(self) -> dict:
        """Plain values: per-probe vectors as amplitude (m) and phase (deg) pairs."""
        out = {}
        if self.amplitude:
            out.update(amplitude=self.amplitude, phase=self.phase)
        for ch, (v1, v2) in self.vectors.items():
            out[ch] = {"1x_m": abs(v1), "1x_deg": math.degrees(np.angle(v1)),
                       "2x_m": abs(v2), "2x_deg": math.degrees(np.angle(v2))}
        return out


@dataclass(repr=False)
class MeasurementNoise(Effect):
    """White Gaussian noise on every displacement channel at a signal-to-noise ratio (dB).

    The ratio is of each channel's AC power to the noise power. Signature: a flat
    non-synchronous floor; no structured order gap.
    """

    snr_db: float = 30.0
    name = "noise"
    bounds = {"snr_db": (0.0, 60.0, "lin")}
    units = {"snr_db": "dB"}
    signature = "broadband non-synchronous floor"

    def measure(self, table, rng, context=None):
        for col in DOF_NAMES:
            if col in table:
                x = np.asarray(table[col])
                ac = x - x.mean()
                sigma = math.sqrt(np.mean(ac**2) / 10 ** (self.snr_db / 10.0))
                table[col] = x + sigma * rng.standard_normal(x.shape)
        return table


#: Canonical name -> effect class.
EFFECTS = {cls.name: cls for cls in (Rub, Misalignment, BreathingCrack, JointLooseness,
                                     ClearanceChange, SupportAnisotropy, ProbeRunout,
                                     MeasurementNoise, SpeedFluctuation)}
