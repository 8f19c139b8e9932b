"""Physical parameters of the paper's rotor-bearing system (SI units throughout)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace

__all__ = ["RotorParameters", "DOF_NAMES"]

#: per-bearing and per-disk parameters -> the shared one they default to
_SHARED = {"kB_B": "kB", "clearance_B": "clearance", "e_O2": "e"}

#: Generalised coordinates, in matrix order (t = tilt; x horizontal, y vertical up).
DOF_NAMES = (
    "xA", "yA", "xO1", "yO1", "txO1", "tyO1", "xO2", "yO2", "txO2", "tyO2", "xB", "yB",
)


@dataclass(frozen=True)
class RotorParameters:
    """Parameters of the 12-DOF rotor with a bolted joint and two ball bearings.

    Defaults are the paper's Table 1 and Table 2 (Jin et al., Processes 2022),
    read as documented in ``docs/rotor_model.md``. Every value is overridable:
    ``RotorParameters(k1=9e5)`` or ``params.replace(clearance=5e-6)``.

    Parameters
    ----------
    m_A, m_B : float
        Lumped masses at bearings A and B, kg (20).
    m_O1, m_O2 : float
        Disk masses, kg (40).
    J_polar1, J_polar2 : float
        Polar moments of inertia of the disks, kg m^2 (1.6059; the paper's "Jp",
        which it calls equatorial: the polar one is the larger).
    J_diam1, J_diam2 : float
        Diametral moments of inertia, kg m^2 (0.803; the paper's "Jd").
    a1, b1 : float
        Distances from disk O1 to bearings A and B, m (0.29, 0.61).
    a2, b2 : float
        Distances from disk O2 to bearings A and B, m (0.31, 0.59).
    k : float
        Bending stiffness of the shaft section through the bolted joint, N/m (2.5e8).
    k1, k2 : float
        Lateral stiffness of shaft segments A-O1 and O2-B, N/m (8e5).
    kb : float
        Disk-to-disk contact stiffness of the bolted joint, N/m (2.5e7).
    k_theta : float
        Bending (tilt) stiffness between the disks, N m/rad (2.5e7).
    c_a, c_b : float
        Bearing damping at A and B, N s/m (3000).
    c_d1, c_d2 : float
        Shaft (bending) damping of segments A-O1 and O2-B, N s/m (3000): on the
        relative lateral displacement of each disk and its bearing, except the share
        ``frame_share_d1`` (``frame_share_d2``) that acts from the disk to the frame.
    c_O1, c_O2 : float
        Damping of the two faces of the bolted joint, N s/m (3000); they act in
        parallel on the disks' relative lateral displacement.
    e : float
        Disk eccentricity, m (0.6e-3): disk O1's, and disk O2's unless ``e_O2``.
    beta : float
        Eccentric phase of disk O2 relative to O1, rad (pi/4).
    unbalance_phase : float
        Angle of disk O1's eccentricity at the once-per-revolution reference, rad
        (0: the paper's convention; a rig's is unknown and calibrated).
    kB : float
        Hertzian contact stiffness of a ball, N/m^1.5 (13.34e9; the paper prints
        13.34e6, a misprint: see docs); bearing A's, and bearing B's unless ``kB_B``.
    clearance : float
        Radial clearance gamma, m (0.5e-6: Table 2 gives 2 r0 = 1 um); bearing A's,
        and bearing B's unless ``clearance_B``.
    kB_B, clearance_B : float or None
        Bearing B's contact stiffness (N/m^1.5) and clearance (m) where they differ
        from bearing A's (None: ``kB`` and ``clearance`` hold for both). A rig's two
        bearings are rarely alike; model updating fits each.
    e_O2 : float or None
        Disk O2's eccentricity, m, where it differs from disk O1's ``e`` (None: ``e``
        for both); with ``beta`` it makes O2's unbalance a vector of its own.
    frame_share_d1, frame_share_d2 : float
        Share (0-1) of ``c_d1`` (``c_d2``) acting from disk O1 (O2) to the frame
        rather than across its shaft segment (0). The paper does not say where its
        disk dampers act: 0 is the reading of ``docs/rotor_model.md``, 1 an absolute
        damper at the disk (external damping, as other readings of the paper take
        it). Where it acts moves the journals' 1x phase by tens of
        per cent, so model updating fits it.
    tilt_share_O : float
        Share (0-1) of ``c_O1`` (``c_O2``) acting on disk O1's (O2's) tilt to the frame,
        read there as N m s/rad, rather than on the joint (0). The paper's "damping
        introduced by the rotation of the disks" can be read either way
        (``docs/rotor_model.md``). On the tilts it damps out the disks' gyroscopic
        tilting pair, which on the joint keeps under 1 % damping -- the pair a crack's
        2x and 3x excite -- so model updating fits it.
    n_balls : int
        Number of balls Nb (8).
    R_outer, r_inner : float
        Outer and inner race radii, m (63.9e-3, 40.1e-3).
    hertz_exponent : float
        Contact exponent m (1.5 for ball bearings).
    gravity : float
        Gravitational acceleration along -y, m/s^2 (9.81; 0 switches it off).
    """

    m_A: float = 20.0
    m_B: float = 20.0
    m_O1: float = 40.0
    m_O2: float = 40.0
    J_polar1: float = 1.6059
    J_polar2: float = 1.6059
    J_diam1: float = 0.803
    J_diam2: float = 0.803
    a1: float = 0.29
    b1: float = 0.61
    a2: float = 0.31
    b2: float = 0.59
    k: float = 2.5e8
    k1: float = 8e5
    k2: float = 8e5
    kb: float = 2.5e7
    k_theta: float = 2.5e7
    c_a: float = 3000.0
    c_b: float = 3000.0
    c_d1: float = 3000.0
    c_d2: float = 3000.0
    c_O1: float = 3000.0
    c_O2: float = 3000.0
    e: float = 0.6e-3
    beta: float = math.pi / 4
    unbalance_phase: float = 0.0
    kB: float = 13.34e9
    clearance: float = 0.5e-6
    n_balls: int = 8
    R_outer: float = 63.9e-3
    r_inner: float = 40.1e-3
    hertz_exponent: float = 1.5
    gravity: float = 9.81
    kB_B: float | None = None
    clearance_B: float | None = None
    e_O2: float | None = None
    frame_share_d1: float = 0.0
    frame_share_d2: float = 0.0
    tilt_share_O: float = 0.0

    def __post_init__(self):
        self.validate()

    def validate(self):
        """Raise ``ValueError`` naming every non-physical value."""
        problems = []
        positive = [
            "m_A", "m_B", "m_O1", "m_O2", "J_polar1", "J_polar2", "J_diam1", "J_diam2",
            "a1", "b1", "a2", "b2", "k", "k1", "k2", "kb", "k_theta", "kB", "R_outer",
            "r_inner", "hertz_exponent",
        ]
        non_negative = ["c_a", "c_b", "c_d1", "c_d2", "c_O1", "c_O2", "e", "clearance", "gravity"]
        for name in positive:
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                problems.append(f"{name}={v!r} must be a finite positive number")
        for name in non_negative:
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                problems.append(f"{name}={v!r} must be finite and >= 0")
        for name, positive_only in (("kB_B", True), ("clearance_B", False), ("e_O2", False)):
            v = getattr(self, name)
            if v is not None and not (isinstance(v, (int, float)) and math.isfinite(v)
                                      and (v > 0 if positive_only else v >= 0)):
                problems.append(f"{name}={v!r} must be None (same as "
                                f"{_SHARED[name]}) or a finite "
                                f"{'positive number' if positive_only else 'value >= 0'}")
        for name in ("frame_share_d1", "frame_share_d2", "tilt_share_O"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0.0 <= v <= 1.0):
                problems.append(f"{name}={v!r} must be a share between 0 and 1")
        for name in ("beta", "unbalance_phase"):
            if not math.isfinite(getattr(self, name)):
                problems.append(f"{name}={getattr(self, name)!r} must be finite (rad)")
        if int(self.n_balls) != self.n_balls or self.n_balls < 3:
            problems.append(f"n_balls={self.n_balls!r} must be an integer >= 3")
        if not problems:
            for side in ("1", "2"):
                if abs(getattr(self, "a" + side) + getattr(self, "b" + side) - self.span) > 1e-9:
                    problems.append(
                        f"a{side} + b{side} must equal the bearing span a1 + b1 = {self.span} m"
                    )
            if self.a2 <= self.a1:
                problems.append("disk O2 must lie beyond O1 from bearing A (a2 > a1)")
            if self.J_polar1 < self.J_diam1 or self.J_polar2 < self.J_diam2:
                problems.append(
                    "a disk's polar inertia must not be smaller than its diametral one "
                    "(swap J_polar and J_diam?)"
                )
        if problems:
            raise ValueError("Non-physical rotor parameters: " + "; ".join(problems) + ".")

    @property
    def span(self) -> float:
        """Bearing span A-B, m."""
        return self.a1 + self.b1

    @property
    def cage_ratio(self) -> float:
        """Cage speed over shaft speed, ``r / (R + r)``."""
        return self.r_inner / (self.R_outer + self.r_inner)

    @property
    def ball_pass_ratio(self) -> float:
        """Varying-compliance frequency over shaft frequency, ``BN = Nb r / (R + r)``."""
        return self.n_balls * self.cage_ratio

    def resolved(self, name: str) -> float:
        """The value ``name`` takes in the model: a per-bearing or per-disk parameter
        (``kB_B``, ``clearance_B``, ``e_O2``) left at None falls back to the shared one
        (``kB``, ``clearance``, ``e``)."""
        v = getattr(self, name)
        return getattr(self, _SHARED[name]) if v is None and name in _SHARED else v

    def with_unbalance_scaled(self, factor: float) -> RotorParameters:
        """A copy with both disks' eccentricity multiplied by ``factor`` (O2's own
        ``e_O2`` too where it is set)."""
        return self.replace(e=self.e * factor,
                            e_O2=None if self.e_O2 is None else self.e_O2 * factor)

    def bearing(self, which: str) -> tuple[float, float]:
        """``(kB, clearance)`` of bearing ``'A'`` or ``'B'`` (N/m^1.5, m)."""
        if which == "A":
            return self.kB, self.clearance
        if which == "B":
            return self.resolved("kB_B"), self.resolved("clearance_B")
        raise ValueError(f"A bearing is 'A' or 'B', not {which!r}.")

    def replace(self, **changes) -> RotorParameters:
        """A copy with some values changed (validated)."""
        return replace(self, **changes)

    def to_dict(self) -> dict:
        """All parameters as a plain dict (SI units), the inverse of ``from_dict``."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> RotorParameters:
        known = {f.name for f in fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"Unknown rotor parameter(s): {sorted(unknown)}.")
        return cls(**d)
