"""Unbalance identification: the gap between a condition and the balanced rotor, attributed
to an unbalance change per disk through a calibrated model of the rig.

The measured 1x response change ``z`` (one complex vector per probe and speed) relates to
the unbalance ``U`` (one complex number per disk, g mm) through the rig's influence
matrix ``H``: ``z = H U + e``. Three layers build ``H`` and judge ``U``:

1. **The rotor model** (a rotor file, :mod:`sknarx.rotor.beam`): the response of each
   probe to a unit unbalance at each disk at the campaign's speeds. Updated on the
   labelled conditions by least squares (model updating): each bearing's stiffness in x
   and y and its damping, each probe's orientation, one probe sensitivity, and each
   disk's angle offset between its engraved scale and the keyphasor.
2. **A regularised correction** per channel and disk, ``H = H_model (1 + delta)``, with
   ``delta`` pulled toward 0 with a stated prior width: what the data insist on and
   the model cannot express (the report states how large it had to be).
3. **A noise model** fitted to the labelled residuals: independent noise per channel and
   a mount-to-mount unbalance scatter ``tau`` (every mounting leaves a slightly
   different residual unbalance; it reaches every channel through ``H``, and it bounds
   how well any method can know the applied unbalance).

A condition's unbalance is then estimated by generalised least squares for each set of
loaded disks (none, disk 1, disk 2, both), and the set with the lowest penalised
chi-square is chosen; standard errors combine the estimate's covariance and ``tau``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import least_squares, minimize

from ..rotor.beam import beam_rotor_from_config
from ..rotor.runup import RPM
from .campaign import GMM_KGM, MIL_M, Campaign

__all__ = ["RigInfluenceModel", "UnbalanceModel", "scores", "cross_validate_conditions"]

logger = logging.getLogger(__name__)

SUPPORTS = ((), (0,), (1,), (0, 1))


@dataclass
class RigInfluenceModel:
    """Influence of a unit unbalance at each disk on every channel, from a rotor file.

    The file's ``[[probes]]`` name the channels (``name``), their axial ``position`` (m)
    and ``direction`` (``x`` or ``y``: the nominal orientation, refined by calibration).
    The response vectors are taken as the file stores them: phase lags, the conjugate
    of the model's phasor, in ``units_m`` metres (mils: 25.4e-6).
    """

    cfg: dict
    speeds_rpm: dict
    probes: tuple
    units_m: float = MIL_M
    n_starts: int = 4  # the nominal and 3 random starts (a local search per start)
    rotor: object = field(init=False)
    names: tuple = field(init=False)

    def __post_init__(self):
        self.rotor, info = beam_rotor_from_config(self.cfg)
        by_name = {p["name"]: p for p in info["probes"]}
        missing = [p for p in self.probes if p not in by_name]
        if missing:
            raise ValueError(f"The rotor file has no [[probes]] named {missing}; it names "
                             f"{sorted(by_name)}. Add them (name, position, direction).")
        self._probe = [by_name[p] for p in self.probes]
        cal = info["calibration"]
        self._kb = np.log10(cal.get("bearing_stiffness", (1e4, 1e8)))
        self._cb = np.log10(cal.get("bearing_damping", (1.0, 2000.0)))
        nb = len(self.rotor.bearings)
        self.names = (tuple(f"bearing{i + 1}_k{d}" for i in range(nb) for d in "xy")
                      + tuple(f"bearing{i + 1}_c" for i in range(nb))
                      + tuple(f"{p}_angle" for p in self.probes)
                      + ("sensitivity",)
                      + tuple(f"disk{d + 1}_angle_offset" for d in range(len(self.rotor.disks))))

    def nominal(self) -> np.ndarray:
        """The parameter vector of the rotor file as written (log10 of stiffness and
        damping, probe angles from their ``direction``, sensitivity 1, no offsets)."""
        b = self.rotor.bearings
        k = [np.log10(v) for x in b for v in (x.kxx, x.kyy)]
        c = [np.log10(x.cxx) for x in b]
        ang = [0.0 if p.get("direction", "x") == "x" else np.pi / 2 for p in self._probe]
        return np.array(k + c + ang + [1.0] + [0.0] * len(self.rotor.disks))

    def bounds(self):
        """Lower and upper bounds of the calibration (the rotor file's ``[calibration]``
        stiffness and damping ranges; angles within two turns; sensitivity 0.2-5)."""
        nb, nd, npr = len(self.rotor.bearings), len(self.rotor.disks), len(self.probes)
        lo = [self._kb[0]] * 2 * nb + [self._cb[0]] * nb + [-2 * np.pi] * npr + [0.2] \
            + [-4 * np.pi] * nd
        hi = [self._kb[1]] * 2 * nb + [self._cb[1]] * nb + [2 * np.pi] * npr + [5.0] \
            + [4 * np.pi] * nd
        return np.array(lo), np.array(hi)

    def influence(self, p, channels) -> np.ndarray:
        """``H`` (n_channels, n_disks): file units per g mm."""
        nb, nd = len(self.rotor.bearings), len(self.rotor.disks)
        k = 10 ** np.asarray(p[: 2 * nb])
        c = 10 ** np.asarray(p[2 * nb : 3 * nb])
        ang = p[3 * nb : 3 * nb + len(self.probes)]
        sens = p[3 * nb + len(self.probes)]
        psi = np.asarray(p[-nd:])
        bearings = tuple(replace(b, kxx=k[2 * i], kyy=k[2 * i + 1], cxx=c[i], cyy=c[i])
                         for i, b in enumerate(self.rotor.bearings))
        rotor = replace(self.rotor, bearings=bearings)
        speed_ids = list(dict.fromkeys(s for s, _ in channels))
        w = np.array([self.speeds_rpm[s] * RPM for s in speed_ids])
        positions = list(dict.fromkeys(float(pr["position"]) for pr in self._probe))
        both = rotor.responses_at(w, positions, n_modes=24)
        planes = {pos: both[:, i] for i, pos in enumerate(positions)}
        H = np.empty((len(channels), nd), dtype=complex)
        for j, (s, name) in enumerate(channels):
            i = self.probes.index(name)
            XY = planes[float(self._probe[i]["position"])][speed_ids.index(s)]  # (disks, 2)
            along = np.cos(ang[i]) * XY[:, 0] + np.sin(ang[i]) * XY[:, 1]
            H[j] = np.conj(along) * np.exp(-1j * psi) * sens * GMM_KGM / self.units_m
        return H

    def calibrate(self, U, z, channels, starts=None, max_nfev=300):
        """Least-squares model updating on labelled conditions; returns (params, cost)."""
        ok = ~np.isnan(z)
        lo, hi = self.bounds()

        def resid(p):
            r = (z - U @ self.influence(p, channels).T)[ok]
            return np.r_[r.real, r.imag]

        if starts is None:
            rng = np.random.default_rng(0)
            nom = self.nominal()
            starts = [nom]
            nb = len(self.rotor.bearings)
            for _ in range(self.n_starts - 1):  # supports and offsets may be far from nominal
                s = nom.copy()
                s[: 3 * nb] = rng.uniform(lo[: 3 * nb], hi[: 3 * nb]) * 0.5 + nom[: 3 * nb] * 0.5
                s[-len(self.rotor.disks):] = rng.uniform(-np.pi, np.pi)
                starts.append(np.clip(s, lo, hi))
        from .._progress import progress_bar

        best = None
        bar = progress_bar(starts, desc="rotor model starts", unit="fit") if len(starts) > 1 \
            else starts
        for x0 in bar:
            r = least_squares(resid, np.clip(x0, lo, hi), bounds=(lo, hi), max_nfev=max_nfev)
            if best is None or r.cost < best.cost:
                best = r
        return best.x, float(best.cost)


def _correction(H0, U, z, prior_width, sigma2):
    """Per channel: ``delta`` of ``H = H0 (1 + delta)``, ridge toward 0 (MAP estimate)."""
    H = H0.copy()
    delta = np.zeros_like(H0)
    for c in range(H0.shape[0]):
        ok = ~np.isnan(z[:, c])
        A = U[ok] * H0[c][None, :]
        y = z[ok, c] - U[ok] @ H0[c]
        lhs = A.conj().T @ A / sigma2[c] + np.eye(H0.shape[1]) / prior_width**2
        delta[c] = np.linalg.solve(lhs, A.conj().T @ y / sigma2[c])
        H[c] = H0[c] * (1 + delta[c])
    return H, delta


def _noise_model(H, U, z, start=None):
    """Maximum-likelihood channel noise and mount scatter from labelled residuals."""
    R = z - U @ H.T
    n_ch = H.shape[0]

    def nll(theta):
        s2, t2 = np.exp(theta[:n_ch]), np.exp(theta[-1])
        total = 0.0
        for r in R:
            ok = ~np.isnan(r)
            Hk = H[ok]
            S = t2 * (Hk @ Hk.conj().T) + np.diag(s2[ok])
            sign, logdet = np.linalg.slogdet(S)
            total += logdet + np.real(r[ok].conj() @ np.linalg.solve(S, r[ok]))
        return total

    if start is None:
        v = np.nanmean(np.abs(R) ** 2, axis=0)
        x0 = np.r_[np.log(0.5 * v + 1e-12), np.log(1.0)]
    else:
        x0 = np.r_[np.log(start[0]), np.log(start[1])]
    res = minimize(nll, x0, method="L-BFGS-B")
    return np.exp(res.x[:n_ch]), float(np.exp(res.x[-1]))


@dataclass
class UnbalanceModel:
    """Model-based unbalance identification (see the module docstring).

    Parameters
    ----------
    rig : RigInfluenceModel
    prior_width : float, default=0.3
        Prior standard deviation of the relative correction of each influence
        coefficient (0.3: the model is trusted to about 30 %).
    penalty : float, default=2.0
        Chi-square cost of declaring a disk loaded (two real parameters); chosen by
        leave-one-condition-out cross-validation on labelled data only.
    """

    rig: RigInfluenceModel
    prior_width: float = 0.3
    penalty: float = 2.0
    max_nfev: int = 300

    def fit(self, campaign: Campaign, warm: UnbalanceModel | None = None) -> UnbalanceModel:
        """Calibrate the rotor model, its correction and the noise on the labelled
        conditions of ``campaign``; ``warm`` (a model fitted on similar data) starts
        every step from its solution (used by the cross-validation folds)."""
        lab = campaign.subset(campaign.labeled)
        self.channels_ = campaign.channels
        starts = None if warm is None else [warm.params_]
        self.params_, _ = self.rig.calibrate(lab.U, lab.z, self.channels_, starts=starts,
                                             max_nfev=self.max_nfev if warm is None else 5)
        self.H_model_ = self.rig.influence(self.params_, self.channels_)
        R = lab.z - lab.U @ self.H_model_.T
        sigma2 = np.nanmean(np.abs(R) ** 2, axis=0)
        noise = None if warm is None else (warm.sigma2_, warm.tau2_)
        H = self.H_model_
        for _ in range(3 if warm is None else 1):  # correction and noise in turn
            H, delta = _correction(self.H_model_, lab.U, lab.z, self.prior_width, sigma2)
            noise = _noise_model(H, lab.U, lab.z, start=noise)
            # the ridge's per-channel variance: channel noise plus the scatter through H
            sigma2 = noise[0] + noise[1] * np.sum(np.abs(H) ** 2, axis=1)
        self.H_ = H
        self.delta_ = delta
        self.sigma2_, self.tau2_ = noise
        model_only = lab.z - lab.U @ self.H_model_.T
        corrected = lab.z - lab.U @ self.H_.T
        self.relative_residual_ = {
            "rotor model": float(np.sqrt(np.nansum(np.abs(model_only) ** 2)
                                         / np.nansum(np.abs(lab.z) ** 2))),
            "rotor model + correction": float(np.sqrt(np.nansum(np.abs(corrected) ** 2)
                                                      / np.nansum(np.abs(lab.z) ** 2)))}
        return self

    def predict(self, campaign: Campaign):
        """Per condition: unbalance (2 complex, g mm), its covariance, the loaded set."""
        U, cov, supp = [], [], []
        for z in campaign.z:
            u, c, s = self._one(z)
            U.append(u)
            cov.append(c)
            supp.append(s)
        return np.array(U), np.array(cov), supp

    def _one(self, z, penalty=None):
        """Estimate for one condition's channel vector (NaN for channels not recorded)."""
        penalty = self.penalty if penalty is None else penalty
        ok = ~np.isnan(z)
        H = self.H_[ok]
        S = self.tau2_ * (H @ H.conj().T) + np.diag(self.sigma2_[ok])
        Si = np.linalg.inv(S)
        best = None
        for supp in SUPPORTS:
            u = np.zeros(2, dtype=complex)
            cov = np.zeros((2, 2))
            if supp:
                Hs = H[:, supp]
                F = Hs.conj().T @ Si @ Hs
                Fi = np.linalg.inv(F)
                u[list(supp)] = Fi @ (Hs.conj().T @ Si @ z[ok])
                cov[np.ix_(supp, supp)] = np.real(np.diag(np.diag(Fi)))
            r = z[ok] - H @ u
            crit = float(np.real(r.conj() @ Si @ r)) + penalty * len(supp)
            if best is None or crit < best[0]:
                best = (crit, u, cov, supp)
        _, u, cov, supp = best
        # the mount scatter is unbalance the estimate cannot tell from the applied one
        var = np.diag(cov) + self.tau2_
        return u, var, supp


def scores(pred: np.ndarray, truth: np.ndarray, threshold: float, phase_from: float,
           decide_at=None) -> dict:
    """The source's metrics on disk-points: MAE of |U| (g mm), detection accuracy (a disk
    is loaded when ``|U| >= threshold``), mean phase error (deg) where ``|U| >=
    phase_from``, and localisation (share of conditions whose set of loaded disks is
    right). ``decide_at``: the estimate's threshold for calling a disk loaded
    (default ``threshold``)."""
    decide_at = threshold if decide_at is None else decide_at
    pa, ta = np.abs(pred), np.abs(truth)
    ph = []
    for p, t in zip(pred.ravel(), truth.ravel(), strict=True):
        if abs(t) >= phase_from:
            ph.append(abs(np.degrees(np.angle(p * np.conj(t)))))
    return {"mae_gmm": float(np.mean(np.abs(pa - ta))),
            "detection": float(np.mean((pa >= decide_at) == (ta >= threshold))),
            "phase_error_deg": float(np.mean(ph)) if ph else float("nan"),
            "localisation": float(np.mean(np.all((pa >= decide_at) == (ta >= threshold),
                                                 axis=1)))}


def _fold(model, campaign, condition, z, penalties):
    """One leave-one-condition-out fold: refit without ``condition``, predict it."""
    mask = np.array([x != condition for x in campaign.conditions])
    fold = UnbalanceModel(model.rig, prior_width=model.prior_width).fit(
        campaign.subset(mask), warm=model)
    out = {}
    for p in penalties:
        u, v, _ = fold._one(z, penalty=p)
        out[p] = (u, v)
    return out


def cross_validate_conditions(model: UnbalanceModel, campaign: Campaign, penalties,
                              thresholds, *, loaded_gmm: float, phase_from_gmm: float,
                              progress=None, n_jobs: int = 2) -> dict:
    """Leave-one-condition-out predictions of every labelled condition.

    Each fold recalibrates the whole model (rotor, correction, noise) without the held-out
    condition (its repeats and both speeds leave together), warm-started from ``model``.
    The penalty and the detection threshold act only at prediction, so every pair of the
    grids is scored on the same folds, by :func:`scores` with the campaign's definitions
    (``loaded_gmm``: a disk is loaded from this unbalance; ``phase_from_gmm``: the phase
    error counts from this one; both g mm). ``n_jobs`` worker processes run the folds.

    Returns
    -------
    dict
        ``predictions[penalty]`` (n_labelled, 2) complex, ``variance[penalty]``,
        ``truth``, ``conditions`` and ``scores[(penalty, threshold)]``.
    """
    from joblib import Parallel, delayed

    from .._progress import progress_bar

    keep = campaign.labeled & (np.asarray(campaign.block) != "baseline")
    lab = campaign.subset(keep)
    preds = {p: [] for p in penalties}
    var = {p: [] for p in penalties}
    # the folds are independent: two worker processes (the fits hold the GIL), results
    # in condition order whatever finishes first
    jobs = (delayed(_fold)(model, campaign, c, lab.z[lab.conditions.index(c)], penalties)
            for c in lab.conditions)
    results = Parallel(n_jobs=n_jobs, return_as="generator")(jobs)
    for c, per_penalty in zip(lab.conditions, progress_bar(
            results, total=len(lab.conditions), desc="leave-one-condition-out",
            unit="fold"), strict=True):
        for p, (u, v) in per_penalty.items():
            preds[p].append(u)
            var[p].append(v)
        if progress is not None:
            progress(c)
    preds = {p: np.array(v) for p, v in preds.items()}
    out = {"conditions": lab.conditions, "truth": lab.U, "predictions": preds,
           "variance": {p: np.array(v) for p, v in var.items()}, "scores": {}}
    for p in penalties:
        for t in thresholds:
            out["scores"][(p, t)] = scores(preds[p], lab.U, loaded_gmm, phase_from_gmm,
                                           decide_at=t)
    return out
