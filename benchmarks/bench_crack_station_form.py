"""A crack's 2x and 3x on the second plant and on sknarx's rotor, station by station.

The blind runs place the independent plants' cracks at segment A-O1 right and their
cracks at O2-B mostly wrong (at A-O1 or the joint), with the held-out speeds calling the
wrong place decided. This asks whether the two derivations of the paper rotor answer a
crack at each station alike: both nominal (no mismatch, no noise), the same crack (the
second plant's Mayes & Davies crack of normal loss ``0.8 depth`` and a quarter of it
across; sknarx's ``BreathingCrack`` of ``depth`` 0.8 depth with the same breathing
angle), each plant's response with the crack minus without, its 2x and 3x amplitude at
every probe, and the static deformation of each cracked segment (what the breathing
acts on); and the second plant once more with its disks' tilt damping (``c_O1``,
``c_O2``, which it reads as acting on the tilts where sknarx puts them on the joint)
removed, with both rotors' modes.

    python benchmarks/bench_crack_station_form.py [--speeds 120 200 260] [--depth 0.4]

Prints a table and writes ``results/bench_crack_station_form.json``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import write_json  # noqa: E402

from sknarx.rotor import EFFECTS, RotorBearingSimulator, RotorParameters  # noqa: E402

CHANNELS = ("xO1", "yO1", "xA", "yA", "xB", "yB")
STATIONS = ("A-O1", "O2-B")
FS, N = 1000.0, 1000


def harmonic(t, rec, w, order):
    """Complex amplitude (m) of ``order`` x at every probe of a settled record."""
    ph = np.exp(-1j * order * w * t)
    return np.array([2.0 * np.mean(rec[c] * ph) for c in CHANNELS])


def second_records(w, depth, opening, tilt_damping=1.0):
    """The second plant's records; ``tilt_damping`` scales its ``c_O1``, ``c_O2`` (which
    it reads as damping of the disks' tilt)."""
    import dataclasses

    import plants.second_derivation as sd

    def run(effects):
        r = sd.SecondRotor()
        rotor = dataclasses.replace(r, c_O1=r.c_O1 * tilt_damping, c_O2=r.c_O2 * tilt_damping)
        rotor.effects = effects
        return sd.SecondDerivationPlant(rotor).run(w, fs=FS, n_samples=N, settle=1.5)

    base = run({})
    return base, {st: run({"crack": [i, 0.8 * depth, 0.2 * depth, opening]})
                  for i, st in enumerate(STATIONS)}


def sknarx_records(w, depth, opening):
    def run(effects):
        sim = RotorBearingSimulator(RotorParameters(), effects=effects)
        cols = sim.simulate_columns(w, n_samples=N, settle=2.0)
        return {**cols, "t": np.arange(N) / FS}

    base = run([])
    return base, {st: run([EFFECTS["crack"](depth=0.8 * depth, angle=0.0, opening=opening,
                                            station=st)]) for st in STATIONS}


def static_deformations():
    """Each cracked segment's static y-deformation (m) on both plants at 200 rad/s: the
    deflection at the bearing relative to the tangent at the disk, from the record's
    mean (absolute journal positions and the disks' slopes)."""
    import plants.second_derivation as sd

    extra = {"jyA": (sd.YA, -1), "jyB": (sd.YB, -1), "pyO1": (sd.PYO1, -1),
             "pyO2": (sd.PYO2, -1)}
    saved = dict(sd.PROBES)
    sd.PROBES.update(extra)  # read the state itself, not only the probes
    try:
        r2 = sd.SecondRotor()
        rec = sd.SecondDerivationPlant(r2).run(200.0, fs=FS, n_samples=N, settle=1.5)
    finally:
        sd.PROBES.clear()
        sd.PROBES.update(saved)
    m = {k: float(np.mean(v)) for k, v in rec.items()}
    b2 = r2.span - r2.a2
    second = {"A-O1": m["yO1"] - m["jyA"] - r2.a1 * m["pyO1"],
              "O2-B": m["yO2"] - m["jyB"] + b2 * m["pyO2"]}
    p = RotorParameters()
    c = RotorBearingSimulator(p).simulate_columns(200.0, n_samples=N, settle=2.0)
    m = {k: float(np.mean(v)) for k, v in c.items()}
    # sknarx's y-plane slope is -tx (matrices.py); signs as the second plant's
    own = {"A-O1": m["yO1"] - m["yA"] + p.a1 * m["txO1"],
           "O2-B": -(m["yB"] - m["yO2"] + p.b2 * m["txO2"])}
    return {"second": second, "sknarx": own}


def modes(speeds):
    """Frequencies (rad/s) of each rotor's oscillatory modes below 1,000 rad/s at
    ``speeds``: sknarx's linearised rotor (with damping ratio and whirl), and the second
    plant's own linear matrices with its journals grounded by the stiffness sknarx's
    linearisation gives its bearings (a crude stand-in: the second plant's bearings are
    only in its nonlinear kernel, and its housings are left on their pedestals)."""
    import plants.second_derivation as sd
    import scipy.linalg as sla

    p = RotorParameters()
    sim = RotorBearingSimulator(p)
    lm = sim.linear_model()
    idx = {n: i for i, n in enumerate(sim.dof_names)}
    r2 = sd.SecondRotor()
    M, C, K, G, _ = r2.matrices()
    K = K.copy()
    for name in ("xA", "yA", "xB", "yB"):
        i = idx[name]
        # the journal's diagonal less its segment's spring: the linearised bearing
        bearing = lm.K[i, i] - (p.k1 if name.endswith("A") else p.k2)
        K[getattr(sd, name.upper()), getattr(sd, name.upper())] += bearing
    out = {"sknarx": {}, "second_crude": {}}
    n = M.shape[0]
    for w in speeds:
        m = lm.modes(w)
        m = m[m["frequency"] < 1000.0]
        out["sknarx"][w] = [{"frequency_rad_s": float(f), "damping_ratio": float(z),
                             "whirl": str(wh)}
                            for f, z, wh in zip(m["frequency"], m["damping_ratio"],
                                                m["whirl"], strict=True)]
        A = np.block([[np.zeros((n, n)), np.eye(n)],
                      [-np.linalg.solve(M, K), -np.linalg.solve(M, C + w * G)]])
        lam = sla.eigvals(A)
        lam = lam[lam.imag > 1e-6]
        keep = np.abs(lam.imag) < 1000.0
        out["second_crude"][w] = [{"frequency_rad_s": float(abs(v.imag)),
                                   "damping_ratio": float(-v.real / abs(v))}
                                  for v in sorted(lam[keep], key=lambda v: v.imag)]
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--speeds", type=float, nargs="+", default=[120.0, 200.0, 260.0],
                    help="rad/s")
    ap.add_argument("--depth", type=float, default=0.4,
                    help="the second plant's crack depth ratio (its draw's meaning)")
    ap.add_argument("--opening", type=float, default=np.pi / 2,
                    help="breathing angle, rad (pi/2: open at the top of a gravity sag)")
    args = ap.parse_args(argv)
    rows = []
    for w in args.speeds:
        plants = (("second", second_records),
                  ("second, c_O x0", lambda *a: second_records(*a, tilt_damping=0.0)),
                  ("sknarx", sknarx_records))
        for plant, records in plants:
            base, cracked = records(w, args.depth, args.opening)
            for st in STATIONS:
                diff = {c: cracked[st][c] - base[c] for c in CHANNELS}
                for order in (2, 3):
                    amp = np.abs(harmonic(base["t"], diff, w, order))
                    rows.append({"speed_rad_s": w, "plant": plant, "station": st,
                                 "order": order,
                                 "amplitude_um": dict(zip(CHANNELS, (amp * 1e6).round(3).tolist(),
                                                          strict=True))})
    print(f"crack depth {args.depth} (second plant's ratio), opening {args.opening:.2f} rad; "
          "amplitude of the crack's response, um")
    print(f"{'rad/s':>6s} {'order':>5s} {'station':>7s} {'plant':>14s} "
          + " ".join(f"{c:>7s}" for c in CHANNELS))
    for r in sorted(rows, key=lambda r: (r["speed_rad_s"], r["order"], r["station"])):
        print(f"{r['speed_rad_s']:6.1f} {r['order']:5d} {r['station']:>7s} {r['plant']:>14s} "
              + " ".join(f"{r['amplitude_um'][c]:7.3f}" for c in CHANNELS))
    md = modes(args.speeds)
    for w in args.speeds:
        print(f"modes at {w:.0f} rad/s, sknarx:",
              ", ".join(f"{m['frequency_rad_s']:.0f} ({m['damping_ratio']:.3f}, {m['whirl']})"
                        for m in md["sknarx"][w]))
        print(f"modes at {w:.0f} rad/s, second (crude):",
              ", ".join(f"{m['frequency_rad_s']:.0f} ({m['damping_ratio']:.3f})"
                        for m in md["second_crude"][w]))
    static = static_deformations()
    print("static y-deformation of the cracked segment, um:",
          {p: {k: round(v * 1e6, 1) for k, v in d.items()} for p, d in static.items()})
    write_json("bench_crack_station_form",
               {"depth": args.depth, "opening_rad": args.opening, "rows": rows,
                "static_deformation_m": static, "modes": md})


if __name__ == "__main__":
    main()
