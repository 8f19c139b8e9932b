"""A Jacobian for least squares on expensive residuals: forward differences now and
then, Broyden's rank-one updates in between.

Each forward-difference Jacobian of a calibration's residual costs one simulated sweep
per parameter, two thirds of a 19-speed diagnosis's time. A trust-region step already
evaluates the residual at the new point; Broyden's update (Dennis & Schnabel,
*Numerical Methods for Unconstrained Optimization*, ch. 8) turns that one evaluation
into a secant correction of the last Jacobian, and a fresh difference Jacobian every
``refresh`` steps keeps the secant drift in check.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SecantJacobian", "SettledStop", "forward_difference"]


def forward_difference(fun, x, f0, lo, hi, rel_step, many=None):
    """Forward-difference Jacobian of ``fun`` at ``x`` (``f0 = fun(x)``), each step
    ``rel_step * max(1, |x_j|)`` and turned back where it would leave the bounds (the
    step scipy's ``'2-point'`` takes). ``many(points)``, if given, evaluates all the
    columns' points in one call (``fun`` of each, in order)."""
    points, steps = [], []
    for j in range(x.size):
        h = rel_step * (1.0 if x[j] >= 0 else -1.0) * max(1.0, abs(x[j]))
        if not lo[j] <= x[j] + h <= hi[j]:
            h = -h
        xj = x.copy()
        xj[j] += h
        points.append(xj)
        steps.append(xj[j] - x[j])  # the step actually taken, after rounding
    values = many(points) if many is not None else [fun(xj) for xj in points]
    J = np.empty((f0.size, x.size))
    for j, (fj, h) in enumerate(zip(values, steps, strict=True)):
        J[:, j] = (fj - f0) / h
    return J


class SecantJacobian:
    """Residual and Jacobian callables for ``scipy.optimize.least_squares``.

    ``fun`` is the residual to minimise; pass ``self.residual`` as the function and
    ``self`` as ``jac``. The trust-region method asks for the Jacobian only at accepted
    points, where it has just evaluated the residual: that value (remembered here) and
    the last Jacobian's point give Broyden's update ``J += (df - J dx) dx^T / dx^T dx``.
    Every ``refresh``-th request (the first included) is answered by forward
    differences instead, and so is any request after a rejected step (the residual
    was evaluated more than once since the last request: the secant model
    mispredicted); ``refresh=1`` is forward differences throughout. ``many(points)``,
    if given, returns ``fun`` at several points in one call: a difference Jacobian's
    columns are independent points, evaluated together.
    """

    def __init__(self, fun, lo, hi, rel_step=1e-3, refresh=4, many=None):
        if refresh < 1:
            raise ValueError(f"refresh must be a positive number of steps, got {refresh!r}.")
        self.fun, self.lo, self.hi = fun, np.asarray(lo), np.asarray(hi)
        self.many = many
        self.rel_step, self.refresh = rel_step, int(refresh)
        self._seen = {}  # x bytes -> residual, the latest few evaluations
        self._J = self._x = self._f = None
        self._calls = 0
        self._evaluated = 0  # residual evaluations since the last Jacobian request
        self.n_differenced = 0  # Jacobians computed by forward differences

    @property
    def jacobian(self):
        """The Jacobian last answered (None before the first request)."""
        return self._J

    def residual(self, x):
        return self._remember(x, self.fun(x))

    def residuals(self, xs):
        """:meth:`residual` of each point, through ``many`` when given."""
        if self.many is None:
            return [self.residual(x) for x in xs]
        return [self._remember(x, f) for x, f in zip(xs, self.many(xs), strict=True)]

    def _remember(self, x, f):
        f = np.asarray(f, dtype=float)
        self._evaluated += 1
        if len(self._seen) > 8:
            self._seen.pop(next(iter(self._seen)))
        self._seen[np.asarray(x, dtype=float).tobytes()] = f
        return f

    def __call__(self, x, *args):
        x = np.asarray(x, dtype=float)
        f = self._seen.get(x.tobytes())
        if f is None:
            f = self.residual(x)
        rejected = self._evaluated > 1
        if self._J is None or self._calls % self.refresh == 0 or rejected:
            self._J = forward_difference(self.residual, x, f, self.lo, self.hi,
                                         self.rel_step, many=self.residuals)
            self.n_differenced += 1
        else:
            dx, df = x - self._x, f - self._f
            dd = float(dx @ dx)
            if dd > 0:
                self._J = self._J + np.outer(df - self._J @ dx, dx / dd)
        self._calls += 1
        self._evaluated = 0
        self._x, self._f = x.copy(), f
        return self._J


class SettledStop:
    """``least_squares`` callback: stop once a step moved no parameter by more than
    ``tol`` of its standard error.

    A calibration's converged run spends its last steps creeping along directions the
    data hardly determine (the cost changing in the fourth digit, a parameter by a
    small share of what its uncertainty allows), one difference Jacobian per step.
    The standard errors are the least-squares covariance ``s^2 (J^T J)^-1`` with
    ``s^2 = 2 cost / (m - n)`` at the new point, from ``jac`` (a
    :class:`SecantJacobian`, asked at every accepted point before the callback);
    a parameter the data barely determine has a large error, so its creeping does not
    hold the run.
    """

    def __init__(self, jac: SecantJacobian, tol: float):
        if not tol > 0:
            raise ValueError(f"tol must be a positive share of a standard error, got {tol!r}.")
        self.jac, self.tol = jac, float(tol)
        self._x = None
        self.stopped = False

    def __call__(self, intermediate_result):
        x = np.asarray(intermediate_result.x, dtype=float)
        J = self.jac.jacobian
        if self._x is not None and J is not None and J.shape[1] == x.size:
            m, n = J.shape
            s2 = 2.0 * float(intermediate_result.cost) / max(m - n, 1)
            sd = np.sqrt(np.clip(np.diag(np.linalg.pinv(J.T @ J)), 0.0, None) * s2)
            if np.all(np.abs(x - self._x) <= self.tol * sd):
                self.stopped = True
                raise StopIteration
        self._x = x.copy()
