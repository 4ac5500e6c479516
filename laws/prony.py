"""Prony series for measured tissue: the LBMC power laws of porcine organs and their fits.

Nicolle's rheometer data (thesis, section 7.7, Table 7.7) give each organ's linear shear relaxation
modulus as a power law, G(t) = K t^(-n) / Gamma(1 - n); at a constant shear rate r the stress is
then r K t^(1-n) / Gamma(2 - n). A power law has no long-term modulus and a singular start: a
Prony series G_inf (1 + sum_i beta_i exp(-t / tau_i)) matches it over a window of times only.
prony_fit picks the relaxation times (log-spaced over the window) and fits the moduli by
non-negative least squares on the relative error, with G_inf the power law's value at the window's
end: a [[material]] then takes E = 2 G_inf (1 + nu) and viscous = the branches (laws/viscous.py).
"""
from __future__ import annotations

import math

import numpy as np

# Table 7.7: K (Pa s^n) and n of the power law (the strain-hardening gamma_lim and p of the thesis'
# spring law are not used here: the Prony series is linear viscoelasticity on top of a hyperelastic law).
LBMC = {"spleen": (758.0, 0.1043), "liver": (861.0, 0.1138), "kidney": (1818.0, 0.0892)}
RATES = (0.0151, 0.133, 0.67)        # s^-1: the strain rates of the rheometer tests


def relaxation_modulus(t, K: float, n: float):
    """G(t) = K t^(-n) / Gamma(1 - n) (Pa)."""
    return K * np.asarray(t, dtype=float) ** (-n) / math.gamma(1 - n)


def constant_rate_stress(t, rate: float, K: float, n: float):
    """The shear stress of the power law at a constant shear rate from t = 0: rate K t^(1-n) / Gamma(2 - n)."""
    return rate * K * np.asarray(t, dtype=float) ** (1 - n) / math.gamma(2 - n)


def prony_fit(K: float, n: float, t_min: float = 1e-3, t_max: float = 10.0, per_decade: int = 2) -> tuple:
    """(G_inf, ((tau, beta), ...)) with G_inf (1 + sum beta exp(-t / tau)) close to the power law on
    [t_min, t_max] (relative error; see prony_error); deterministic (no random start)."""
    from scipy.optimize import nnls
    if not (0 < t_min < t_max and 0 < n < 1 and K > 0 and per_decade >= 1):
        raise ValueError("prony_fit: needs 0 < t_min < t_max, 0 < n < 1, K > 0, per_decade >= 1")
    decades = math.log10(t_max / t_min)
    taus = t_min * 10.0 ** (np.arange(int(math.ceil(decades * per_decade)) + 1) / per_decade)
    t = np.geomspace(t_min, t_max, 40 * len(taus))
    G = relaxation_modulus(t, K, n)
    G_inf = float(relaxation_modulus(t_max, K, n))
    A = np.exp(-t[:, None] / taus[None, :]) / G[:, None]        # rows weighted by 1 / G: relative error
    moduli, _ = nnls(A, (G - G_inf) / G)
    keep = moduli > 0
    return G_inf, tuple((float(tau), float(g / G_inf)) for tau, g in zip(taus[keep], moduli[keep]))


def prony_modulus(t, G_inf: float, branches) -> np.ndarray:
    t = np.asarray(t, dtype=float)
    return G_inf * (1 + sum(beta * np.exp(-t / tau) for tau, beta in branches))


def prony_constant_rate_stress(t, rate: float, G_inf: float, branches) -> np.ndarray:
    """The shear stress of the Prony series at a constant shear rate from t = 0 (its closed form)."""
    t = np.asarray(t, dtype=float)
    return rate * G_inf * (t + sum(beta * tau * (1 - np.exp(-t / tau)) for tau, beta in branches))
