"""Explicit stability limits computed from the chain, for engines that
integrate part of the loop explicitly (a PID evaluated once per step, or
explicit joint springs and damping).

For a linear mode with mass m, stiffness k and damping c integrated by
semi-implicit (symplectic) Euler, the step must satisfy h < 2/omega for the
spring (omega^2 = k/m) and h < 2m/c for the damper; we take the smaller and a
safety factor, then the largest step from a list that divides the 1 s
protocol period.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

STEP_CHOICES = (1e-3, 8e-4, 5e-4, 4e-4, 2.5e-4, 2e-4, 1e-4, 5e-5, 2.5e-5, 2e-5, 1e-5, 5e-6, 2.5e-6, 2e-6, 1e-6)


def probe_effective_mass(M: np.ndarray, Ju: np.ndarray) -> float:
    """Mass felt along the probe direction: 1 / (u^T J M^-1 J^T u)."""
    return float(1.0 / (Ju @ np.linalg.solve(M, Ju)))


def explicit_limit(M: np.ndarray, K: np.ndarray | None = None, C: np.ndarray | None = None) -> float:
    """Largest stable step (s) of symplectic Euler on M q'' = -K q - C q'."""
    lim = np.inf
    if C is not None and np.any(C):
        lam = sla.eigh(C, M, eigvals_only=True).max()
        lim = min(lim, 2.0 / lam)
    if K is not None and np.any(K):
        w2 = sla.eigh(K, M, eigvals_only=True).max()
        lim = min(lim, 2.0 / np.sqrt(w2))
    return float(lim)


def pid_limit(m_eff: float, kp: float, kd: float) -> float:
    """Stable step for an explicit PD acting on an effective mass."""
    return min(2.0 * m_eff / kd if kd > 0 else np.inf, 2.0 * np.sqrt(m_eff / kp) if kp > 0 else np.inf)


def choose_step(limit: float, ceiling: float = 1e-3, safety: float = 0.5) -> float:
    """Largest step in :data:`STEP_CHOICES` below ``safety * limit`` and ``ceiling``."""
    for h in STEP_CHOICES:
        if h <= ceiling and h <= safety * limit:
            return h
    return STEP_CHOICES[-1]
