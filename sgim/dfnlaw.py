"""The radius laws of a fracture network's joint sets (sgim/dfn.py): constant, power, lognormal and
exponential, truncated to [min, max]; their moments, exact inverse-CDF sampling of the moment-weighted
laws f(r) r^j and maximum-likelihood fits."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .portable import each, each2

# scipy (special functions, optimisers) is imported inside the laws that need it: start-up time of every command

# ---------------------------------------------------------------------------
# radius laws

def _phi_diff(a, b):
    """P(a < Z < b) for a standard normal Z, accurate in both tails."""
    from scipy.special import ndtr  # scipy, here and below, loaded only when a law needs it (start-up time)

    if a > 0:
        return float(ndtr(-a) - ndtr(-b))
    return float(ndtr(b) - ndtr(a))


@dataclass
class RadiusLaw:
    law: str
    value: float = math.nan  # constant
    exponent: float = math.nan  # power
    mean: float = math.nan  # exponential scale
    mu: float = math.nan  # lognormal (of ln r)
    sigma: float = math.nan
    min: float = 0.0
    max: float = math.inf

    def params(self):
        out = {"law": self.law}
        if self.law == "constant":
            out["value"] = self.value
            return out
        if self.law == "power":
            out["exponent"] = self.exponent
        elif self.law == "exponential":
            out["mean"] = self.mean
        else:
            out["mu"], out["sigma"] = self.mu, self.sigma
        out["min"] = self.min
        out["max"] = None if math.isinf(self.max) else self.max
        return out

    # -- power law helpers, in x = r / min
    def _J(self, k):
        """Integral of x^k over [1, max/min]."""
        X = self.max / self.min
        if math.isinf(X):
            return -1.0 / (k + 1.0)  # k < -1 here
        lx = math.log(X)
        if abs(k + 1.0) * lx < 1e-12:
            return lx
        return math.expm1((k + 1.0) * lx) / (k + 1.0)

    def _lognormal_ab(self, mu):
        a = -math.inf if self.min <= 0 else (math.log(self.min) - mu) / self.sigma
        b = math.inf if math.isinf(self.max) else (math.log(self.max) - mu) / self.sigma
        return a, b

    def mass(self):
        """Probability mass of the untruncated law inside [min, max] (power: 1)."""
        if self.law == "exponential":
            m, M = self.min / self.mean, self.max / self.mean
            return math.exp(-m) - (0.0 if math.isinf(M) else math.exp(-M))
        if self.law == "lognormal":
            return _phi_diff(*self._lognormal_ab(self.mu))
        return 1.0

    def moment(self, j):
        """E[R^j] under the (truncated) law."""
        from scipy.special import gammaincc

        if self.law == "constant":
            return self.value ** j
        if j == 0:
            return 1.0
        if self.law == "power":
            return self.min ** j * self._J(j - self.exponent) / self._J(-self.exponent)
        if self.law == "exponential":
            mu, m, M = self.mean, self.min / self.mean, self.max / self.mean
            num = math.gamma(j + 1) * (gammaincc(j + 1, m) - (0.0 if math.isinf(M) else gammaincc(j + 1, M)))
            return mu ** j * float(num) / self.mass()
        a, b = self._lognormal_ab(self.mu)
        s = self.sigma
        return math.exp(j * self.mu + 0.5 * (j * s) ** 2) * _phi_diff(a - j * s, b - j * s) / self.mass()

    def ppf(self, j, u):
        """Inverse cumulative distribution of the density f(r) r^j (normalised), at u in [0, 1)."""
        from scipy.special import gammaincc, gammainccinv, ndtr, ndtri

        u = np.asarray(u, float)
        if self.law == "constant":
            return np.full(u.shape, self.value)
        if self.law == "power":
            b = self.exponent - j
            e = 1.0 - b
            X = self.max / self.min
            if math.isinf(X):  # e < 0
                x = each2(math.pow, 1.0 - u, 1.0 / e)
            else:
                lx = math.log(X)
                if abs(e) * lx < 1e-12:
                    x = each(math.exp, u * lx)
                else:
                    x = each(math.exp, each(math.log1p, u * math.expm1(e * lx)) / e)
            r = self.min * x
        elif self.law == "exponential":
            m, M = self.min / self.mean, self.max / self.mean
            q0 = float(gammaincc(j + 1, m))
            q1 = 0.0 if math.isinf(M) else float(gammaincc(j + 1, M))
            r = self.mean * gammainccinv(j + 1, q0 - u * (q0 - q1))
        else:
            muj = self.mu + j * self.sigma ** 2
            a, b = self._lognormal_ab(muj)
            if a > 0:
                pa, pb = float(ndtr(-a)), float(ndtr(-b))
                z = -ndtri(pa - u * (pa - pb))
            else:
                pa, pb = float(ndtr(a)), float(ndtr(b))
                z = ndtri(pa + u * (pb - pa))
            r = each(math.exp, muj + self.sigma * z)
        return np.clip(r, self.min, self.max)

    def sample_biased(self, u, extent):
        """Radii with density f(r) V(r) / E[V(R)], V(r) = prod(extent + 2r); u is (n, 2) uniforms."""
        Lx, Ly, Lz = (float(v) for v in extent)
        c = (Lx * Ly * Lz, 2.0 * (Lx * Ly + Ly * Lz + Lz * Lx), 4.0 * (Lx + Ly + Lz), 8.0)
        w = np.array([c[j] * self.moment(j) for j in range(4)])
        cum = np.cumsum(w) / w.sum()
        comp = np.minimum(np.searchsorted(cum, u[:, 0], side="right"), 3)
        r = np.empty(len(u))
        for j in range(4):
            sel = comp == j
            if sel.any():
                r[sel] = self.ppf(j, u[sel, 1])
        return r

    # -- maximum-likelihood fit with the bounds held
    def fit(self, r):
        """MLE of the law's free parameters from radii r (sampled from this law's family)."""
        from scipy.optimize import minimize, minimize_scalar

        r = np.asarray(r, float)
        n = len(r)
        if n == 0:
            return {}
        if self.law == "constant":
            return {"value": float(r.mean())}
        if self.law == "power":
            slx = float(np.log(r / self.min).sum())
            if math.isinf(self.max):
                return {"exponent": 1.0 + n / slx if slx > 0 else math.inf}
            res = minimize_scalar(lambda a: a * slx + n * math.log(self._J(-a)), bounds=(-20.0, 40.0),
                                  method="bounded", options={"xatol": 1e-10})
            return {"exponent": float(res.x)}
        if self.law == "exponential":
            excess = float((r - self.min).sum())
            if math.isinf(self.max):
                return {"mean": excess / n}
            w = self.max - self.min

            def nll(lm):
                mu = math.exp(lm)
                return excess / mu + n * lm + n * math.log(-math.expm1(-w / mu))

            scale = max(excess / n, 1e-12 * w)
            res = minimize_scalar(nll, bounds=(math.log(scale) - 12.0, math.log(scale) + 12.0), method="bounded",
                                  options={"xatol": 1e-12})
            return {"mean": float(math.exp(res.x))}
        lr = np.log(r)
        mu0, s0 = float(lr.mean()), float(lr.std())
        if self.min <= 0 and math.isinf(self.max):
            return {"mu": mu0, "sigma": s0}

        def nll2(p):
            mu, ls = p
            s = math.exp(ls)
            a = -math.inf if self.min <= 0 else (math.log(self.min) - mu) / s
            b = math.inf if math.isinf(self.max) else (math.log(self.max) - mu) / s
            mass = _phi_diff(a, b)
            if not mass > 0:
                return 1e300
            return n * ls + float(((lr - mu) ** 2).sum()) / (2 * s * s) + n * math.log(mass)

        res = minimize(nll2, [mu0, math.log(max(s0, 1e-6))], method="Nelder-Mead",
                       options={"xatol": 1e-10, "fatol": 1e-10, "maxiter": 4000})
        return {"mu": float(res.x[0]), "sigma": float(math.exp(res.x[1]))}
