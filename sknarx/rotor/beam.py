"""A linear finite-element rotor described by a file: shaft, disks, linear bearings.

For rotors other than the paper's (e.g. a Bently Nevada RK-4 kit): Euler-Bernoulli
shaft elements with consistent mass, rigid disks with gyroscopic moments, and
linear, possibly anisotropic, bearings. Being linear, its steady-state order
response (what order tracking of a slow run-up measures) is one complex solve
per speed: ``(K - w^2 M + i w (C + w G)) X = F``.

DOFs per node: ``x, sx, y, sy`` with ``sx = dx/dz`` and ``sy = dy/dz``; phasors
follow ``x(t) = Re(X e^{i w t})``, so ``|X|`` is the 0-peak amplitude and
``angle(X)`` the phase in ``x = A cos(w t + phase)`` -- the convention of the
RK-4 data.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np
import scipy.linalg as sla

__all__ = ["Disk", "Bearing", "BeamRotor", "beam_rotor_from_config"]


@dataclass(frozen=True)
class Disk:
    position: float  # m from the shaft end
    mass: float  # kg
    diameter: float  # m
    thickness: float  # m

    @property
    def polar_inertia(self):
        return 0.5 * self.mass * (self.diameter / 2) ** 2

    @property
    def diametral_inertia(self):
        return self.mass * (3 * (self.diameter / 2) ** 2 + self.thickness**2) / 12.0


@dataclass(frozen=True)
class Bearing:
    position: float  # m
    kxx: float  # N/m
    kyy: float
    cxx: float  # N s/m
    cyy: float


@dataclass(frozen=True)
class BeamRotor:
    """Shaft of ``length`` (m) and ``diameter`` (m) in ``n_elements`` elements."""

    length: float
    diameter: float
    E: float = 2.0e11
    density: float = 7850.0
    n_elements: int = 28
    disks: tuple = ()
    bearings: tuple = ()
    extra_nodes: tuple = field(default=())  # positions that must be nodes (probes)

    def __post_init__(self):
        if self.length <= 0 or self.diameter <= 0 or self.n_elements < 2:
            raise ValueError("length and diameter must be positive and n_elements >= 2.")
        for pos in [o.position for o in (*self.disks, *self.bearings)] + list(self.extra_nodes):
            if not 0 <= pos <= self.length:
                raise ValueError(f"A disk, bearing or probe at {pos} m lies outside the "
                                 f"shaft (0..{self.length} m).")

    @property
    def nodes(self) -> np.ndarray:
        base = np.linspace(0.0, self.length, self.n_elements + 1)
        pts = [d.position for d in self.disks] + [b.position for b in self.bearings]
        pts += list(self.extra_nodes)
        return np.unique(np.round(np.concatenate([base, pts]), 9))

    def node(self, z: float) -> int:
        return int(np.argmin(np.abs(self.nodes - z)))

    def with_bearings(self, **changes) -> BeamRotor:
        """Every bearing with some values changed (e.g. ``kxx=2e6, kyy=3e6``)."""
        return replace(self, bearings=tuple(replace(b, **changes) for b in self.bearings))

    def matrices(self):
        """``M, C, G, K`` (SI) with the bearings; the shaft and disks' part is computed
        once per geometry (a calibration changes only the bearings)."""
        # the key keeps the bearings' positions (mesh nodes), not their values
        where = tuple(Bearing(b.position, 0.0, 0.0, 0.0, 0.0) for b in self.bearings)
        M, C, G, K = (X.copy() for X in _structure(replace(self, bearings=where)))
        for b in self.bearings:
            i = 4 * self.node(b.position)
            K[i, i] += b.kxx
            K[i + 2, i + 2] += b.kyy
            C[i, i] += b.cxx
            C[i + 2, i + 2] += b.cyy
        return M, C, G, K

    def probe_responses(self, speeds, probe: float, n_modes: int | None = 24) -> np.ndarray:
        """Complex x and y response (m) at ``probe`` to a unit unbalance at each disk.

        Returns an array of shape (n_speeds, n_disks, 2). With ``n_modes`` the system
        is first reduced to its lowest undamped modes (damping and gyroscopic terms
        projected), which makes a speed sweep ~10x cheaper; ``None`` solves the full
        model (one factorisation per speed, every disk as a right-hand side).
        """
        return self.responses_at(speeds, (probe,), n_modes)[:, 0]

    def responses_at(self, speeds, probes, n_modes: int | None = 24) -> np.ndarray:
        """:meth:`probe_responses` at several axial positions (m) from one solve per
        speed: shape (n_speeds, n_probes, n_disks, 2)."""
        M, C, G, K = self.matrices()
        nd = len(self.disks)
        F = np.zeros((M.shape[0], nd), dtype=complex)
        for d, disk in enumerate(self.disks):
            i = 4 * self.node(disk.position)
            F[i, d] = 1.0
            F[i + 2, d] = -1j  # forward rotating: y lags x by 90 degrees
        P = np.eye(M.shape[0])
        if n_modes is not None and n_modes < M.shape[0]:
            _, P = sla.eigh(K, M, subset_by_index=[0, n_modes - 1])
        Mr, Cr, Gr, Kr = (P.T @ A @ P for A in (M, C, G, K))
        Fr = P.T @ F
        rows = [P[[j, j + 2]] for j in (4 * self.node(z) for z in probes)]
        out = np.empty((len(speeds), len(rows), nd, 2), dtype=complex)
        for k, w in enumerate(np.asarray(speeds, dtype=float)):
            D = Kr - w * w * Mr + 1j * w * (Cr + w * Gr)
            X = sla.solve(D, w * w * Fr, check_finite=False)
            for r, rw in enumerate(rows):
                out[k, r] = (rw @ X).T
        return out

    def natural_frequencies(self, n=4):
        """Lowest undamped natural frequencies at rest (rad/s); x and y modes both appear."""
        M, C, G, K = self.matrices()
        lam = sla.eigh(K, M, eigvals_only=True, subset_by_index=[0, n - 1])
        return np.sqrt(np.clip(lam, 0, None))


@lru_cache(maxsize=16)
def _structure(rotor):
    """Shaft and disk matrices ``M, C, G, K`` of a rotor without bearings (read-only:
    :meth:`BeamRotor.matrices` copies them). The bearings' positions are nodes of the
    mesh; their values are not used."""
    z = rotor.nodes
    n = z.size
    N = 4 * n
    M = np.zeros((N, N))
    K = np.zeros((N, N))
    C = np.zeros((N, N))
    G = np.zeros((N, N))
    A = np.pi * rotor.diameter**2 / 4
    EI = rotor.E * np.pi * rotor.diameter**4 / 64
    for e in range(n - 1):
        L = z[e + 1] - z[e]
        k = EI / L**3 * np.array([[12, 6 * L, -12, 6 * L],
                                  [6 * L, 4 * L * L, -6 * L, 2 * L * L],
                                  [-12, -6 * L, 12, -6 * L],
                                  [6 * L, 2 * L * L, -6 * L, 4 * L * L]])
        m = rotor.density * A * L / 420 * np.array(
            [[156, 22 * L, 54, -13 * L], [22 * L, 4 * L * L, 13 * L, -3 * L * L],
             [54, 13 * L, 156, -22 * L], [-13 * L, -3 * L * L, -22 * L, 4 * L * L]])
        for plane in (0, 2):
            a, b = 4 * e + plane, 4 * (e + 1) + plane
            idx = [a, a + 1, b, b + 1]
            K[np.ix_(idx, idx)] += k
            M[np.ix_(idx, idx)] += m
    for d in rotor.disks:
        i = 4 * rotor.node(d.position)
        M[i, i] += d.mass
        M[i + 2, i + 2] += d.mass
        M[i + 1, i + 1] += d.diametral_inertia
        M[i + 3, i + 3] += d.diametral_inertia
        G[i + 1, i + 3] += d.polar_inertia
        G[i + 3, i + 1] -= d.polar_inertia
    for X in (M, C, G, K):
        X.setflags(write=False)
    return M, C, G, K


def _entry(section: str, i: int | None, d: dict, *keys: str) -> list[float]:
    """The numbers ``keys`` of one entry of a rotor file's ``section``, or an error that
    names the entry and the key a user left out or mistyped."""
    where = f"[{section}]" if i is None else f"[[{section}]] entry {i + 1}"
    if not isinstance(d, dict):
        raise ValueError(f"The rotor file's {where} must be a table of keys, got {d!r}.")
    missing = [k for k in keys if k not in d]
    if missing:
        raise ValueError(f"The rotor file's {where} lacks {', '.join(missing)} (see "
                         "examples/rk4/rotor.toml for a beam rotor file).")
    try:
        return [float(d[k]) for k in keys]
    except (TypeError, ValueError):
        raise ValueError(f"The rotor file's {where}: {', '.join(keys)} must be numbers, got "
                         f"{[d[k] for k in keys]}.") from None


def beam_rotor_from_config(cfg: dict) -> tuple[BeamRotor, dict]:
    """Build a :class:`BeamRotor` and the probe/measurement settings from a rotor file."""
    if "shaft" not in cfg:
        raise ValueError("A beam rotor file needs a [shaft] section (length, diameter; E, "
                         "density and n_elements optional) with [[disks]], [[bearings]] and "
                         "[[probes]]; see examples/rk4/rotor.toml.")
    sh = cfg["shaft"]
    length, diameter = _entry("shaft", None, sh, "length", "diameter")
    disks = tuple(Disk(*_entry("disks", i, d, "position", "mass", "diameter", "thickness"))
                  for i, d in enumerate(cfg.get("disks", [])))
    bearings = []
    for i, b in enumerate(cfg.get("bearings", [])):
        # an isotropic bearing may give kxx and cxx alone
        b = {"kyy": b.get("kxx"), "cyy": b.get("cxx"), **b} if isinstance(b, dict) else b
        position, kxx, kyy, cxx, cyy = _entry("bearings", i, b, "position", "kxx", "kyy",
                                              "cxx", "cyy")
        bearings.append(Bearing(position=position, kxx=kxx, kyy=kyy, cxx=cxx, cyy=cyy))
    bearings = tuple(bearings)
    probes = cfg.get("probes", [])
    for i, pr in enumerate(probes):
        _entry("probes", i, pr, "position")
    rotor = BeamRotor(length=length, diameter=diameter,
                      E=float(sh.get("E", 2.0e11)), density=float(sh.get("density", 7850.0)),
                      n_elements=int(sh.get("n_elements", 28)), disks=disks, bearings=bearings,
                      extra_nodes=tuple(float(p["position"]) for p in probes))
    if not disks or len(bearings) < 2:
        raise ValueError("A rotor file needs at least one [[disks]] and two [[bearings]].")
    return rotor, {"probes": probes, "measurement": cfg.get("measurement", {}),
                   "calibration": cfg.get("calibration", {})}
