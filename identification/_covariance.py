"""Standard errors from the Jacobian of the residuals at the optimum."""

from __future__ import annotations

import numpy as np
from scipy.linalg import null_space

#: Eigenvalues of the normalised J^T J below this fraction of the largest count as zero.
RCOND = 1e-10


def standard_errors(J: np.ndarray, r: np.ndarray, A_eq: np.ndarray | None = None,
                    active: np.ndarray | None = None) -> tuple[np.ndarray, bool]:
    """``sqrt(diag(sigma^2 (J^T J)^-1))`` over the columns of ``J``.

    Parameters
    ----------
    J : (n, k) array
        Jacobian of the residuals with respect to the k estimated quantities.
    r : (n,) array
        Residuals at the optimum; ``sigma^2 = r.r / (n - dof)``.
    A_eq : (m, k) array, optional
        Jacobian of equality constraints (Preisach weights summing to 1): the
        covariance lives in their null space.
    active : (k,) bool array, optional
        Estimates at a bound: held there, their error is NaN.

    Returns
    -------
    se : (k,) array
        Standard errors; ``inf`` for quantities the data do not determine
        (a zero eigenvalue of ``J^T J`` involves them), NaN at an active bound
        and everywhere when they cannot be computed (a non-finite Jacobian or
        residual, an eigen-decomposition that fails): unavailable, not a crash.
    singular : bool
        True when ``J^T J`` (restricted as above) is singular, or the errors are unavailable.
    """
    n, k = J.shape
    active = np.zeros(k, bool) if active is None else np.asarray(active, bool)
    keep = ~active
    se = np.full(k, np.nan)
    if not keep.any():
        return se, False
    Jk = J[:, keep]
    if not (np.all(np.isfinite(Jk)) and np.all(np.isfinite(r))):
        return se, True
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        try:
            se[keep], singular = _kept(Jk, r, n, None if A_eq is None else A_eq[:, keep])
        except (np.linalg.LinAlgError, ValueError):  # e.g. "Eigenvalues did not converge"
            return se, True
    return se, singular


def _kept(Jk: np.ndarray, r: np.ndarray, n: int, A_eq: np.ndarray | None) -> tuple[np.ndarray, bool]:
    norms = np.linalg.norm(Jk, axis=0)
    if not np.all(np.isfinite(norms)):
        raise ValueError("the Jacobian overflows")
    norms[norms == 0] = 1.0
    Jn = Jk / norms
    if A_eq is not None and A_eq.size:
        Z = null_space(A_eq / norms)
    else:
        Z = np.eye(Jn.shape[1])
    H = Z.T @ Jn.T @ Jn @ Z
    dof = max(n - Z.shape[1], 1)
    sigma2 = float(r @ r) / dof
    eig, V = np.linalg.eigh(H)
    zero = eig <= RCOND * max(eig.max(initial=0.0), np.finfo(float).tiny)
    inv = (V[:, ~zero] / eig[~zero]) @ V[:, ~zero].T
    cov = sigma2 * Z @ inv @ Z.T
    se_keep = np.sqrt(np.clip(np.diag(cov), 0, None)) / norms
    if zero.any():
        null = Z @ V[:, zero]
        se_keep[np.linalg.norm(null, axis=1) > 1e-6] = np.inf
    return se_keep, bool(zero.any())
