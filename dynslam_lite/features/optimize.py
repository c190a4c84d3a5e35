"""Reprojection errors of RGB-D keypoints and the two optimisations of the frontend:
pose-only (tracking) and local bundle adjustment (keyframe window).

The error of a map point ``P_w`` seen at keypoint ``(u, v)`` with depth ``d`` is ORB-SLAM2's
stereo error ``e = (u - u_hat, v - v_hat, u_r - u_hat_r)`` with ``u_r = u - b_f / d`` and
``u_hat_r = u_hat - b_f / Z``; a keypoint without depth has the first two rows only. Each row
is whitened by ``1 / scale_factor ** octave``.

References: ORB-SLAM2 (Mur-Artal & Tardos 2017), Optimizer::PoseOptimization and
LocalBundleAdjustment; Barfoot, State Estimation for Robotics (2017), sec. 7.1 (left perturbation).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import coo_matrix

from ..geometry import PinholeCamera, hat, se3_exp

CHI2_MONO = 5.991  # 95 % of chi-square, 2 degrees of freedom
CHI2_STEREO = 7.815  # 95 % of chi-square, 3 degrees of freedom


@dataclass
class Observations:
    """Keypoint measurements of map points, one row per observation.

    Attributes
    ----------
    uvr : (N, 3) float, (u, v, u_r) pixels; u_r = u - b_f / d, unused where ``stereo`` is False
    stereo : (N,) bool, the keypoint has depth
    info : (N,) float, 1 / sigma^2 of the keypoint's pyramid level
    """

    uvr: np.ndarray
    stereo: np.ndarray
    info: np.ndarray

    @classmethod
    def of(cls, uv: np.ndarray, z: np.ndarray, info: np.ndarray, bf: float) -> "Observations":
        stereo = z > 0
        ur = np.where(stereo, uv[:, 0] - bf / np.where(stereo, z, 1.0), 0.0)
        return cls(np.column_stack([uv, ur]), stereo, np.asarray(info, float))

    @classmethod
    def concat(cls, parts: list["Observations"]) -> "Observations":
        return cls(np.concatenate([o.uvr for o in parts]), np.concatenate([o.stereo for o in parts]),
                   np.concatenate([o.info for o in parts]))

    def __getitem__(self, idx) -> "Observations":
        return Observations(self.uvr[idx], self.stereo[idx], self.info[idx])

    @property
    def chi2_gate(self) -> np.ndarray:
        return np.where(self.stereo, CHI2_STEREO, CHI2_MONO)


def residuals(camera: PinholeCamera, bf: float, R: np.ndarray, t: np.ndarray, P_w: np.ndarray,
              obs: Observations) -> tuple[np.ndarray, np.ndarray]:
    """Stereo reprojection errors.

    Parameters
    ----------
    R, t : rotation (3, 3) and translation (3,) of ``T_c_w`` (world to camera), or one per
        observation, (N, 3, 3) and (N, 3)
    P_w : (N, 3) map points, world frame, metres
    obs : the N observations
    Returns
    -------
    e : (N, 3) pixels, ``obs - projection``, third row 0 where there is no depth
    P_c : (N, 3) the points in the camera frame
    """
    P_c = (P_w @ R.T if R.ndim == 2 else np.einsum("nij,nj->ni", R, P_w)) + t
    Z = np.where(P_c[:, 2] > 1e-6, P_c[:, 2], 1e-6)
    u = camera.fx * P_c[:, 0] / Z + camera.cx
    v = camera.fy * P_c[:, 1] / Z + camera.cy
    e = obs.uvr - np.column_stack([u, v, u - bf / Z])
    e[~obs.stereo, 2] = 0.0
    return e, P_c


def point_jacobian(camera: PinholeCamera, bf: float, P_c: np.ndarray, stereo: np.ndarray) -> np.ndarray:
    """(N, 3, 3) derivative of the error with respect to the camera-frame point."""
    X, Y, Z = P_c.T
    Z = np.where(Z > 1e-6, Z, 1e-6)
    J = np.zeros((len(P_c), 3, 3))
    J[:, 0, 0] = -camera.fx / Z
    J[:, 0, 2] = camera.fx * X / Z**2
    J[:, 1, 1] = -camera.fy / Z
    J[:, 1, 2] = camera.fy * Y / Z**2
    J[:, 2, 0] = J[:, 0, 0]
    J[:, 2, 2] = (camera.fx * X - bf) / Z**2
    J[~stereo, 2] = 0.0
    return J


def pose_jacobian(camera: PinholeCamera, bf: float, P_c: np.ndarray, stereo: np.ndarray,
                  row_scale: np.ndarray | None = None) -> np.ndarray:
    """(N, 3, 6) derivative of the error w.r.t. a left perturbation ``T_c_w <- exp(xi) T_c_w``,
    ``xi = (rho, phi)``: dP_c = rho + phi x P_c. ``row_scale`` (N,) whitens each observation."""
    J_p = point_jacobian(camera, bf, P_c, stereo)
    if row_scale is not None:
        J_p = J_p * row_scale[:, None, None]
    dP = np.zeros((len(P_c), 3, 6))
    dP[:, :, :3] = np.eye(3)
    dP[:, :, 3:] = -hat(P_c)
    return J_p @ dP


@dataclass
class PoseResult:
    """Result of :func:`optimize_pose`.

    Attributes
    ----------
    T_c_w : (4, 4) world to camera
    inliers : (N,) bool, chi2 below the 95 % gate after the last round
    chi2 : (N,) whitened squared errors at the solution
    """

    T_c_w: np.ndarray
    inliers: np.ndarray
    chi2: np.ndarray


def optimize_pose(camera: PinholeCamera, bf: float, T_c_w: np.ndarray, P_w: np.ndarray,
                  obs: Observations, weights: np.ndarray | None = None, rounds: int = 4,
                  iterations: int = 10) -> PoseResult:
    """Pose-only optimisation with outlier rounds (ORB-SLAM2's PoseOptimization).

    Each round runs Gauss-Newton on the inliers of the previous round, with a Huber kernel
    (threshold = sqrt of the chi2 gate) in the first two rounds; then every observation is
    re-classified by its chi2 against the gate.

    Parameters
    ----------
    T_c_w : (4, 4) initial pose (world to camera)
    P_w : (N, 3) map points, world frame
    obs : their N observations in this frame
    weights : (N,) or None, fixed multipliers of each squared error (1 = ORB-SLAM2)
    """
    T = np.array(T_c_w, float)
    w_fixed = np.ones(len(P_w)) if weights is None else np.asarray(weights, float)
    gate = obs.chi2_gate
    inl = np.ones(len(P_w), bool)
    chi2 = np.zeros(len(P_w))
    for rnd in range(rounds):
        for _ in range(iterations):
            e, P_c = residuals(camera, bf, T[:3, :3], T[:3, 3], P_w, obs)
            chi2 = obs.info * np.sum(e**2, axis=1)
            w = w_fixed * obs.info * inl
            if rnd < 2:  # Huber: weight sqrt(gate / chi2) beyond the threshold
                w = w * np.where(chi2 > gate, np.sqrt(gate / np.maximum(chi2, 1e-12)), 1.0)
            if w.sum() == 0:
                break
            J = pose_jacobian(camera, bf, P_c, obs.stereo)
            H = np.einsum("n,nij,nik->jk", w, J, J)
            g = np.einsum("n,nij,ni->j", w, J, e)
            dx = np.linalg.solve(H + 1e-9 * np.eye(6), -g)
            T = se3_exp(dx) @ T
            if np.linalg.norm(dx) < 1e-7:
                break
        e, _ = residuals(camera, bf, T[:3, :3], T[:3, 3], P_w, obs)
        chi2 = obs.info * np.sum(e**2, axis=1)
        inl = chi2 < gate
        if inl.sum() < 10:
            break
    return PoseResult(T, inl, chi2)


def local_bundle_adjustment(camera: PinholeCamera, bf: float, T_c_w: np.ndarray, fixed: np.ndarray,
                            P_w: np.ndarray, kf_of_obs: np.ndarray, pt_of_obs: np.ndarray,
                            obs: Observations, weights: np.ndarray | None = None,
                            max_nfev: int = 10) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bundle adjustment of a keyframe window: poses (except the fixed ones) and points.

    Solved with scipy's trust-region least squares (``least_squares``, analytic sparse
    Jacobian) in ORB-SLAM2's two phases: Huber-weighted, then the inliers alone. Poses are
    updated as ``exp(xi_k) T_k``.

    Parameters
    ----------
    T_c_w : (K, 4, 4) keyframe poses, world to camera
    fixed : (K,) bool, poses held constant (the gauge)
    P_w : (M, 3) points
    kf_of_obs, pt_of_obs : (N,) int, keyframe and point of each observation
    obs : the N observations; weights : (N,) or None, fixed multipliers of the squared errors
    Returns
    -------
    T_c_w (K, 4, 4), P_w (M, 3), chi2 (N,) of each observation after the adjustment
    """
    K, M = len(T_c_w), len(P_w)
    free = np.flatnonzero(~np.asarray(fixed))
    slot = -np.ones(K, int)
    slot[free] = np.arange(len(free))
    sw = np.sqrt(obs.info * (np.ones(len(obs.info)) if weights is None else weights))
    nP = 6 * len(free)
    T0 = np.asarray(T_c_w, float)

    def unpack(x):
        T = T0.copy()
        for k in free:
            T[k] = se3_exp(x[6 * slot[k]: 6 * slot[k] + 6]) @ T0[k]
        return T, x[nP:].reshape(M, 3)

    n = len(pt_of_obs)
    has = slot[kf_of_obs] >= 0

    def errors(x):
        T, P = unpack(x)
        R = T[kf_of_obs, :3, :3]
        e, P_c = residuals(camera, bf, R, T[kf_of_obs, :3, 3], P[pt_of_obs], obs)
        return e, P_c, R

    def fun(x):
        return (errors(x)[0] * sw[:, None]).ravel()

    def jac(x):
        # analytic: d e / d P_w = J_p R; d e / d xi_k = J_p [I | -P_c^]. The pose derivative is
        # taken at xi = 0 (exact at the start, a close approximation for the small steps of BA).
        _, P_c, R = errors(x)
        J_pt = (point_jacobian(camera, bf, P_c, obs.stereo) * sw[:, None, None]) @ R  # (n, 3, 3)
        J_kf = pose_jacobian(camera, bf, P_c[has], obs.stereo[has], sw[has])  # (n_has, 3, 6)
        rows = np.arange(3 * n).reshape(n, 3)
        r_pt = np.repeat(rows, 3, axis=1).ravel()
        c_pt = (nP + 3 * pt_of_obs[:, None, None] + np.zeros((1, 3, 1), int) + np.arange(3)).ravel()
        r_kf = np.repeat(rows[has], 6, axis=1).ravel()
        c_kf = (6 * slot[kf_of_obs[has]][:, None, None] + np.zeros((1, 3, 1), int) + np.arange(6)).ravel()
        return coo_matrix((np.concatenate([J_pt.ravel(), J_kf.ravel()]),
                           (np.concatenate([r_pt, r_kf]), np.concatenate([c_pt, c_kf]))),
                          shape=(3 * n, nP + 3 * M)).tocsr()

    # ORB-SLAM2's two phases: robust (Huber weights, here as one IRLS reweighting of a plain
    # least-squares solve, which scipy's trust region converges on in a few steps), then the
    # chi2 outliers leave and the inliers are solved without a kernel.
    x = np.concatenate([np.zeros(nP), np.asarray(P_w, float).ravel()])
    base = sw.copy()
    gate = obs.chi2_gate
    for phase in ("huber", "inliers"):
        chi2 = obs.info * np.sum(errors(x)[0] ** 2, axis=1)
        if phase == "huber":
            sw = base * np.where(chi2 > gate, (gate / np.maximum(chi2, 1e-12)) ** 0.25, 1.0)
        else:
            sw = base * (chi2 <= gate)
        x = least_squares(fun, x, jac=jac, max_nfev=max_nfev, method="trf", tr_solver="lsmr").x
    T, P = unpack(x)
    chi2 = obs.info * np.sum(errors(x)[0] ** 2, axis=1)
    return T, P, chi2


__all__ = ["CHI2_MONO", "CHI2_STEREO", "Observations", "residuals", "point_jacobian",
           "pose_jacobian", "PoseResult", "optimize_pose", "local_bundle_adjustment"]
