"""Paper B, sec. 4: joint Levenberg-Marquardt over the camera pose and per-point static weights.

As printed, eq. 7 ``argmin 1/2 phi_i sum ||p_i - pi(R P_i + t)||^2`` is minimised by phi = 0.
We keep its intent (each point's error scaled by its weight, the weights optimised with the
pose, paper eq. 8's derivative ``de/dphi_i = e_i``) and make it well posed with a prior that
pulls each weight back to its initial value phi0_i (eq. 6):

    E(xi, phi) = 1/2 sum_i phi_i^2 chi2_i(xi) + lambda/2 sum_i (phi_i - phi0_i)^2,
    chi2_i = e_i^T Omega_i e_i,    e_i = (u - u_hat, v - v_hat, u_r - u_hat_r),

the residual vector being ``(phi_i Omega_i^1/2 e_i, sqrt(lambda) (phi_i - phi0_i))``. For a fixed
pose the optimal weight is ``phi_i = lambda phi0_i / (lambda + chi2_i)``: in [0, phi0_i], equal
to phi0_i for a perfect fit, halved at chi2_i = lambda, falling toward 0 as a moving point's
error grows. ``lambda`` defaults to the 95 % chi-square gate of a stereo observation (7.815).

LM step: the weights enter block-diagonally, so the normal equations are reduced to the 6x6
pose system by the Schur complement (as g2o does for points), solved, and back-substituted.
Weights are clipped to [0, 1] after each step.

References: paper B (weightedstatic), eqs. 6-8; Nocedal & Wright, Numerical Optimization,
sec. 10.3 (Levenberg-Marquardt).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..features.optimize import CHI2_STEREO, Observations, pose_jacobian, residuals
from ..geometry import PinholeCamera, se3_exp



def initial_weights(mask_seg, mask_geo, eta: float = 0.5, omega: float = 0.5) -> np.ndarray:
    """Eq. 6: ``phi0 = eta * mask_seg + omega * mask_geo`` per point.

    ``mask_seg``, ``mask_geo`` : (N,) bool or scalar, 1 where the semantic masks / the weighted
    geometric test call the point static; eta + omega = 1 (0.5 each in the paper).
    """
    return eta * np.asarray(mask_seg, float) + omega * np.asarray(mask_geo, float)

@dataclass
class JointResult:
    """Result of :func:`joint_pose_and_weights`.

    Attributes
    ----------
    T_c_w : (4, 4) world to camera
    phi : (N,) final weights in [0, 1]
    chi2 : (N,) whitened squared errors at the solution
    cost : costs E, one per accepted LM iteration (the first is the initial cost)
    """

    T_c_w: np.ndarray
    phi: np.ndarray
    chi2: np.ndarray
    cost: list[float] = field(default_factory=list)


def joint_cost(phi: np.ndarray, chi2: np.ndarray, phi0: np.ndarray, lam: float) -> float:
    """E(xi, phi) of the module docstring, for the errors ``chi2`` of a pose."""
    return 0.5 * float(np.sum(phi**2 * chi2) + lam * np.sum((phi - phi0) ** 2))


def joint_pose_and_weights(camera: PinholeCamera, bf: float, T_c_w: np.ndarray, P_w: np.ndarray,
                           obs: Observations, phi0: np.ndarray, lam: float = CHI2_STEREO,
                           iterations: int = 20, mu0: float = 1e-3) -> JointResult:
    """Minimise E(xi, phi) from ``(T_c_w, phi0)`` by Levenberg-Marquardt.

    Parameters
    ----------
    T_c_w : (4, 4) initial pose, world to camera
    P_w : (N, 3) map points, world frame; obs : their N observations
    phi0 : (N,) initial weights (eq. 6), the prior's centre
    lam : weight of the prior (units of chi2)
    """
    T = np.array(T_c_w, float)
    phi = np.clip(np.asarray(phi0, float).copy(), 0.0, 1.0)
    s2 = obs.info

    def chi2_of(T):
        e, P_c = residuals(camera, bf, T[:3, :3], T[:3, 3], P_w, obs)
        return s2 * np.sum(e**2, axis=1), e, P_c

    chi2, e, P_c = chi2_of(T)
    cost = [joint_cost(phi, chi2, phi0, lam)]
    mu = mu0
    for _ in range(iterations):
        J = pose_jacobian(camera, bf, P_c, obs.stereo)  # (N, 3, 6)
        H_xx = np.einsum("n,nij,nik->jk", phi**2 * s2, J, J)
        b_x = np.einsum("n,nij,ni->j", phi**2 * s2, J, e)
        H_xp = np.einsum("n,nij,ni->nj", phi * s2, J, e)  # (N, 6): column i of H_xi,phi
        D = chi2 + lam  # diagonal of H_phi,phi
        b_p = phi * chi2 + lam * (phi - phi0)
        improved = False
        while mu < 1e8:
            Hd = H_xx + mu * np.diag(np.diag(H_xx))
            Dd = D * (1.0 + mu)
            S = Hd - np.einsum("ni,nj,n->ij", H_xp, H_xp, 1.0 / Dd)
            rhs = -b_x + H_xp.T @ (b_p / Dd)
            dx = np.linalg.solve(S + 1e-12 * np.eye(6), rhs)
            dphi = (-b_p - H_xp @ dx) / Dd
            T_new = se3_exp(dx) @ T
            phi_new = np.clip(phi + dphi, 0.0, 1.0)
            chi2_new, e_new, P_c_new = chi2_of(T_new)
            c = joint_cost(phi_new, chi2_new, phi0, lam)
            if c < cost[-1]:
                T, phi, chi2, e, P_c = T_new, phi_new, chi2_new, e_new, P_c_new
                mu = max(mu / 3.0, 1e-9)
                improved = True
                break
            mu *= 4.0
        if not improved:
            break
        rel = (cost[-1] - c) / max(cost[-1], 1e-12)
        cost.append(c)
        if rel < 1e-6:
            break
    return JointResult(T, phi, chi2, cost)
