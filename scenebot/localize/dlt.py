"""Camera pose from 2D-3D matches: the paper's method (section IV.B, eqs. 2-3).

On each RANSAC iteration the DLT algorithm (Hartley & Zisserman, section 4.1, with the
data normalisation of section 4.4.4) estimates a 3x4 camera matrix P from 6 random matches;
the hypothesis with the most matches reprojecting within the threshold wins. P is then
re-estimated from all its inliers and split by an RQ decomposition (H&Z section 6.2.4) into
``K [R | T]``. Because P is noisy and the upper-triangular factor is not of the form of eq. 3,

    K = [[f, 0, w/2], [0, f, h/2], [0, 0, 1]],

f, R and T are refined by non-linear least squares on the reprojection error of the inliers
(with the principal point fixed at the camera's), the inliers are re-selected with the refined
camera and the refinement is repeated once. RANSAC only counts hypotheses whose K is close to
the form of eq. 3 (:func:`plausible_cameras`), which rejects the degenerate P of samples that
lie on one plane.

A 3x4 camera matrix is not determined by matches that all lie on one plane (a robot facing a
wall), and matches on a few nearly planar surfaces leave it poorly conditioned, so that the
refinement can settle in a wrong local minimum (tens of cm off in the simulated office). When
the focal length is known, a second pose comes from the dominant plane (:func:`planar_pose`):
a RANSAC DLT homography from the plane to the image (H&Z section 4.1 again), decomposed with
the known K into R and T, then refined with f fixed; the pose with more inliers (then the
lower RMSE) is returned. This addition to the paper's method is what makes it as accurate as
pycolmap's P3P in benchmarks/bench_localize.py.

All pixel coordinates here are of an ideal pinhole camera (undistorted), COLMAP convention.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy import linalg, optimize

MIN_SAMPLE = 6


@dataclass(frozen=True)
class DltPose:
    """Result of :func:`ransac_dlt_pose`.

    Attributes:
        R: (3, 3) rotation cam_from_world.
        t: (3,) translation cam_from_world (m): ``x_cam = R @ X + t``.
        focal_px: refined focal length (pixels).
        inliers: (M,) bool inlier mask over the matches.
        iterations: RANSAC hypotheses evaluated.
        rmse_px: reprojection RMSE over the inliers (pixels).
    """

    R: np.ndarray
    t: np.ndarray
    focal_px: float
    inliers: np.ndarray
    iterations: int
    rmse_px: float
    planar: bool = False


def _normalizing_transforms(x: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Similarities that centre the points and scale them to mean distance sqrt(2) / sqrt(3).

    Args:
        x: (B, n, 2) image points.
        X: (B, n, 3) world points.

    Returns:
        T (B, 3, 3) for the image points, U (B, 4, 4) for the world points.
    """
    b = x.shape[0]
    cx = x.mean(axis=1)
    sx = math.sqrt(2.0) / np.maximum(np.linalg.norm(x - cx[:, None], axis=2).mean(axis=1), 1e-12)
    cX = X.mean(axis=1)
    sX = math.sqrt(3.0) / np.maximum(np.linalg.norm(X - cX[:, None], axis=2).mean(axis=1), 1e-12)
    T = np.zeros((b, 3, 3))
    T[:, 0, 0] = T[:, 1, 1] = sx
    T[:, :2, 2] = -sx[:, None] * cx
    T[:, 2, 2] = 1.0
    U = np.zeros((b, 4, 4))
    U[:, 0, 0] = U[:, 1, 1] = U[:, 2, 2] = sX
    U[:, :3, 3] = -sX[:, None] * cX
    U[:, 3, 3] = 1.0
    return T, U


def dlt_batch(x: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Normalised DLT for a batch of correspondence sets.

    Args:
        x: (B, n, 2) image points (pixels), n >= 6.
        X: (B, n, 3) world points (m).

    Returns:
        (B, 3, 4) camera matrices, scaled so that ``det(P[:, :3]) > 0`` (points in front of
        the camera then have positive depth ``(P @ [X, 1])[2]``).
    """
    x = np.asarray(x, float)
    X = np.asarray(X, float)
    b, n, _ = x.shape
    T, U = _normalizing_transforms(x, X)
    xn = np.einsum("bij,bnj->bni", T[:, :2, :2], x) + T[:, None, :2, 2]
    Xh = np.concatenate([X, np.ones((b, n, 1))], axis=2)
    Xn = np.einsum("bij,bnj->bni", U, Xh)
    # Two rows per match (H&Z eq. 7.2): [0, -X, y X; X, 0, -x X] p = 0.
    A = np.zeros((b, 2 * n, 12))
    A[:, 0::2, 4:8] = -Xn
    A[:, 0::2, 8:12] = xn[:, :, 1:2] * Xn
    A[:, 1::2, 0:4] = Xn
    A[:, 1::2, 8:12] = -xn[:, :, 0:1] * Xn
    # Null vector of A: the eigenvector of A^T A with the smallest eigenvalue (with the
    # normalised data this is as accurate as the SVD of A, and faster for batches).
    _, vecs = np.linalg.eigh(np.einsum("bij,bik->bjk", A, A))
    Pn = vecs[:, :, 0].reshape(b, 3, 4)
    P = np.linalg.solve(T, Pn) @ U  # T^-1 Pn U
    sign = np.sign(np.linalg.det(P[:, :, :3]))
    sign[sign == 0] = 1.0
    return P * sign[:, None, None]


def dlt(x: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Normalised DLT camera matrix from n >= 6 matches: (n, 2), (n, 3) -> (3, 4)."""
    if len(x) < MIN_SAMPLE:
        raise ValueError(f"dlt: need at least {MIN_SAMPLE} matches, got {len(x)}")
    return dlt_batch(np.asarray(x)[None], np.asarray(X)[None])[0]


def decompose_camera_matrix(P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """RQ decomposition ``P = K [R | T]`` (eq. 2) with a positive diagonal of K.

    Args:
        P: (3, 4) camera matrix.

    Returns:
        K (3, 3) upper triangular with ``K[2, 2] = 1``, R (3, 3) rotation (det +1), T (3,).
    """
    P = np.asarray(P, float)
    if np.linalg.det(P[:, :3]) < 0:
        P = -P
    Kr, Q = linalg.rq(P[:, :3])
    s = np.sign(np.diag(Kr))
    s[s == 0] = 1.0
    D = np.diag(s)
    K = Kr @ D
    R = D @ Q
    T = np.linalg.solve(K, P[:, 3])
    return K / K[2, 2], R, T


def project(P: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Project world points with camera matrices.

    Args:
        P: (..., 3, 4) camera matrices.
        X: (n, 3) world points.

    Returns:
        pixels (..., n, 2) and depths (..., n) (positive in front for det(P[:3]) > 0).
    """
    h = P[..., :3] @ X.T + P[..., 3:4]
    z = h[..., 2, :]
    zs = np.where(np.abs(z) < 1e-12, 1e-12, z)
    return np.stack([h[..., 0, :] / zs, h[..., 1, :] / zs], axis=-1), z


def plausible_cameras(
    P: np.ndarray,
    cx: float,
    cy: float,
    f_init: float | None = None,
    max_aspect_dev: float = 0.1,
    max_skew: float = 0.05,
    max_pp_dev: float = 0.25,
) -> np.ndarray:
    """Which camera matrices have an intrinsic matrix close to the form of eq. 3.

    ``M M^T / |m3|^2 = K K^T`` for ``P = [M | p4] ~ K [R | T]``, from which the principal
    point, the focal lengths along x and y and the skew follow without an RQ decomposition.
    Degenerate DLT solutions (e.g. from matches on one plane) give arbitrary K and fail this.

    Args:
        P: (B, 3, 4) camera matrices.
        cx, cy: expected principal point (pixels).
        f_init: expected focal length (pixels); accept 0.5x..2x of it. None: any.
        max_aspect_dev: allowed |fx / fy - 1|.
        max_skew: allowed |skew| / f.
        max_pp_dev: allowed principal point offset as a fraction of ``max(cx, cy)``.

    Returns:
        (B,) bool.
    """
    M = P[:, :, :3]
    n3 = np.maximum((M[:, 2] ** 2).sum(axis=1), 1e-300)
    A = M @ np.transpose(M, (0, 2, 1)) / n3[:, None, None]
    px, py = A[:, 0, 2], A[:, 1, 2]
    fx2 = A[:, 0, 0] - px**2
    fy2 = A[:, 1, 1] - py**2
    ok = (fx2 > 0) & (fy2 > 0)
    fx = np.sqrt(np.where(ok, fx2, 1.0))
    fy = np.sqrt(np.where(ok, fy2, 1.0))
    tol = max_pp_dev * max(cx, cy)
    ok &= (np.abs(px - cx) < tol) & (np.abs(py - cy) < tol)
    ok &= np.abs(fx / fy - 1.0) < max_aspect_dev
    ok &= np.abs(A[:, 0, 1] - px * py) / (fx * fy) < max_skew
    if f_init is not None:
        f = 0.5 * (fx + fy)
        ok &= (f > 0.5 * f_init) & (f < 2.0 * f_init)
    return ok


def _camera_matrix(f: float, cx: float, cy: float, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    K = np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])
    return K @ np.hstack([R, t[:, None]])


def _pinhole_residuals(c: np.ndarray, x: np.ndarray, f: float, cx: float, cy: float) -> np.ndarray:
    """(2n,) reprojection residuals (u..., v...) in pixels of camera-frame points ``c``
    (n, 3) against pixels ``x`` (n, 2)."""
    z = np.where(np.abs(c[:, 2]) < 1e-9, 1e-9, c[:, 2])
    return np.concatenate([f * c[:, 0] / z + cx - x[:, 0], f * c[:, 1] / z + cy - x[:, 1]])


def refine_f_r_t(
    x: np.ndarray,
    X: np.ndarray,
    f: float,
    R: np.ndarray,
    t: np.ndarray,
    cx: float,
    cy: float,
    refine_focal: bool = True,
) -> tuple[float, np.ndarray, np.ndarray]:
    """Non-linear least squares on the reprojection error over f, R (axis-angle), T.

    Args:
        x: (n, 2) image points (pixels).
        X: (n, 3) world points (m).
        f: initial focal length (pixels).
        R: (3, 3) initial rotation.
        t: (3,) initial translation.
        cx, cy: fixed principal point (pixels).
        refine_focal: keep ``f`` fixed when False.

    Returns:
        refined f, R (3, 3), t (3,).
    """
    rvec0 = cv2.Rodrigues(np.asarray(R, float))[0].ravel()

    def residuals(p: np.ndarray) -> np.ndarray:
        ff = p[6] if refine_focal else f
        return _pinhole_residuals(X @ cv2.Rodrigues(p[:3])[0].T + p[3:6], x, ff, cx, cy)

    p0 = np.concatenate([rvec0, t, [f] if refine_focal else []])
    sol = optimize.least_squares(residuals, p0, method="lm", x_scale="jac", max_nfev=200)
    p = sol.x
    return (float(p[6]) if refine_focal else f), cv2.Rodrigues(p[:3])[0], p[3:6].copy()


def position_std_m(
    x: np.ndarray,
    X: np.ndarray,
    f: float,
    cx: float,
    cy: float,
    R: np.ndarray,
    t: np.ndarray,
    sigma_px: float,
) -> float:
    """How well the inliers fix the camera centre in the plane: the 1-sigma length (m) of the
    longer axis of the horizontal (x, y) covariance of the centre.

    First-order propagation of an image noise of ``sigma_px`` through the reprojection
    error's Jacobian in (rotation, centre) with f fixed: ``cov = sigma^2 (J^T J)^-1``. Matches
    that are few, far, or bunched on one small patch leave the centre poorly determined along
    some direction (a wrong fix tens of cm off can have dozens of inliers and a small RMSE);
    this says so before the fix is used.

    Args:
        x: (n, 2) inlier pixels; X: (n, 3) their 3D points (m).
        f, cx, cy: pinhole intrinsics (pixels).
        R, t: the pose (cam_from_world).
        sigma_px: image noise (pixels), e.g. the inliers' reprojection RMSE.

    Returns:
        The standard deviation (m); ``inf`` when the centre is not determined.
    """
    if len(x) < 4:
        return math.inf
    rvec0 = cv2.Rodrigues(np.asarray(R, float))[0].ravel()
    c0 = -np.asarray(R, float).T @ np.asarray(t, float)

    def residuals(p: np.ndarray) -> np.ndarray:
        return _pinhole_residuals((X - p[3:6]) @ cv2.Rodrigues(p[:3])[0].T, x, f, cx, cy)

    p0 = np.concatenate([rvec0, c0])
    r0 = residuals(p0)
    J = np.empty((len(r0), 6))
    for k, h in enumerate((1e-6, 1e-6, 1e-6, 1e-5, 1e-5, 1e-5)):
        dp = np.zeros(6)
        dp[k] = h
        J[:, k] = (residuals(p0 + dp) - r0) / h
    try:
        cov = np.linalg.inv(J.T @ J) * float(sigma_px) ** 2
    except np.linalg.LinAlgError:
        return math.inf
    w = np.linalg.eigvalsh(cov[3:5, 3:5])
    return float(np.sqrt(max(w[-1], 0.0))) if np.all(np.isfinite(w)) else math.inf


def _sample_indices(rng: np.random.Generator, n: int, batch: int) -> np.ndarray:
    """(batch, 6) distinct random indices per row."""
    return np.argpartition(rng.random((batch, n)), MIN_SAMPLE - 1, axis=1)[:, :MIN_SAMPLE]


def _iterations_needed(inliers: int, n: int, confidence: float) -> int:
    """RANSAC hypotheses needed to draw one all-inlier sample with ``confidence`` when
    ``inliers`` of the ``n`` matches are inliers."""
    w = inliers / n
    fail = 1.0 - w**MIN_SAMPLE
    return 0 if fail <= 0 else math.ceil(math.log(1 - confidence) / math.log(max(fail, 1e-12)))


def _ransac_camera(
    x: np.ndarray,
    X: np.ndarray,
    cx: float,
    cy: float,
    f_init: float | None,
    thr2: float,
    confidence: float,
    max_iterations: int,
    rng: np.random.Generator,
    batch: int,
) -> tuple[int, np.ndarray | None, np.ndarray | None, int]:
    """RANSAC over batches of DLT camera matrices of 6-match samples.

    Returns:
        The best plausible hypothesis's inlier count, inlier mask and (3, 4) camera matrix
        (mask and matrix None when no hypothesis had an inlier), and the hypotheses drawn.
    """
    n = len(x)
    best_count, best_mask, best_P = 0, None, None
    needed = max_iterations
    done = 0
    while done < min(needed, max_iterations):
        b = min(batch, max_iterations - done)
        idx = _sample_indices(rng, n, b)
        P = dlt_batch(x[idx], X[idx])
        uv, z = project(P, X)
        err2 = ((uv - x[None]) ** 2).sum(axis=2)
        mask = (z > 0) & (err2 < thr2) & np.isfinite(err2)
        counts = mask.sum(axis=1) * plausible_cameras(P, cx, cy, f_init)
        j = int(np.argmax(counts))
        done += b
        if counts[j] > best_count:
            best_count, best_mask, best_P = int(counts[j]), mask[j], P[j]
            needed = _iterations_needed(best_count, n, confidence)
    return best_count, best_mask, best_P, done


def _refine_on_inliers(
    x: np.ndarray,
    X: np.ndarray,
    mask: np.ndarray,
    P_init: np.ndarray,
    cx: float,
    cy: float,
    f_init: float | None,
    refine_focal: bool,
    thr2: float,
    iterations: int,
) -> DltPose | None:
    """The pose from RANSAC's best hypothesis (see :func:`ransac_dlt_pose`); None when
    fewer than 6 inliers remain. ``iterations``: the hypotheses RANSAC drew."""
    # Re-estimate P from all inliers (if that camera is plausible; matches on one plane make
    # it degenerate, then the best hypothesis is kept), split P = K [R | T] (eq. 2), refine
    # f, R, T (eq. 3), re-select the inliers with the refined camera; repeat once.
    for _ in range(2):
        if mask.sum() < MIN_SAMPLE:
            return None
        P_all = dlt(x[mask], X[mask])
        if plausible_cameras(P_all[None], cx, cy, f_init)[0]:
            P_init = P_all
        K, R, t = decompose_camera_matrix(P_init)
        f = 0.5 * (K[0, 0] + K[1, 1])
        if f_init is not None and not refine_focal:
            f = f_init
        f, R, t = refine_f_r_t(x[mask], X[mask], f, R, t, cx, cy, refine_focal)
        P_init = _camera_matrix(f, cx, cy, R, t)
        uv, z = project(P_init, X)
        err2 = ((uv - x) ** 2).sum(axis=1)
        new_mask = (z > 0) & (err2 < thr2)
        if np.array_equal(new_mask, mask):
            break
        mask = new_mask
    if mask.sum() < MIN_SAMPLE:
        return None
    rmse = float(np.sqrt(err2[mask].mean()))
    return DltPose(R, t, f, mask, iterations, rmse)


def _better_of_planar(
    pose: DltPose,
    x: np.ndarray,
    X: np.ndarray,
    cx: float,
    cy: float,
    f_init: float,
    refine_focal: bool,
    max_error_px: float,
    seed: int,
) -> DltPose:
    """``pose``, or the dominant plane's pose when that has more inliers (or as many and a
    lower RMSE)."""
    # Matches on few, nearly planar surfaces (a wall, a bookcase) leave the DLT poorly
    # conditioned and its refinement can settle in a local minimum; a second start from
    # the dominant plane's homography often finds the better one. Keep the better pose.
    f = pose.focal_px if not refine_focal else f_init
    alt = planar_pose(x, X, f, cx, cy, max_error_px, 0.999, seed)
    if alt is not None and (
        alt.inliers.sum() > pose.inliers.sum()
        or (alt.inliers.sum() == pose.inliers.sum() and alt.rmse_px < pose.rmse_px)
    ):
        return DltPose(alt.R, alt.t, alt.focal_px, alt.inliers, pose.iterations, alt.rmse_px, True)
    return pose


def ransac_dlt_pose(
    x: np.ndarray,
    X: np.ndarray,
    cx: float,
    cy: float,
    f_init: float | None = None,
    *,
    max_error_px: float,
    confidence: float,
    max_iterations: int,
    refine_focal: bool = True,
    seed: int,
    batch: int = 64,
) -> DltPose | None:
    """RANSAC over DLT camera matrices, RQ decomposition, refinement of f, R, T.

    Args:
        x: (n, 2) undistorted pixels of the matched query features.
        X: (n, 3) matched 3D points (m).
        cx, cy: principal point (pixels), fixed (the paper uses w/2, h/2).
        f_init: focal length (pixels) to use if the DLT's is implausible, and the fixed
            focal length when ``refine_focal`` is False; None: trust the DLT.
        max_error_px: inlier threshold on the reprojection error.
        confidence: stop when the chance of having missed an all-inlier sample is below
            ``1 - confidence``.
        max_iterations: hypotheses at most.
        refine_focal: refine f with R and T (the paper) or keep ``f_init``.
        seed: random seed.
        batch: hypotheses estimated together (vectorised).

    Returns:
        The pose, or None with fewer than 6 matches or no hypothesis with 6 inliers.
    """
    x = np.asarray(x, float)
    X = np.asarray(X, float)
    if len(x) < MIN_SAMPLE:
        return None
    rng = np.random.default_rng(seed)
    thr2 = max_error_px**2
    best_count, best_mask, best_P, done = _ransac_camera(
        x, X, cx, cy, f_init, thr2, confidence, max_iterations, rng, batch
    )
    if best_mask is None or best_count < MIN_SAMPLE:
        if f_init is None:
            return None
        return planar_pose(x, X, f_init, cx, cy, max_error_px, confidence, seed)
    pose = _refine_on_inliers(
        x, X, best_mask, best_P, cx, cy, f_init, refine_focal, thr2, iterations=done
    )
    if pose is None or f_init is None:
        return pose
    return _better_of_planar(pose, x, X, cx, cy, f_init, refine_focal, max_error_px, seed)


def _dominant_plane(
    X: np.ndarray, rng: np.random.Generator, iterations: int = 200
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The plane through the most 3D points (RANSAC on 3-point samples).

    Returns:
        origin (3,), E (3, 3) columns: two in-plane axes and the normal, inlier mask (n,).
    """
    n = len(X)
    centred = X - X.mean(axis=0)
    tol = 0.01 * float(np.median(np.linalg.norm(centred, axis=1))) + 1e-9
    idx = np.argpartition(rng.random((iterations, n)), 2, axis=1)[:, :3]
    a, b, c = X[idx[:, 0]], X[idx[:, 1]], X[idx[:, 2]]
    normal = np.cross(b - a, c - a)
    norm = np.linalg.norm(normal, axis=1)
    good = norm > 1e-12
    normal = normal[good] / norm[good, None]
    dist = np.abs((X[None] - a[good, None]) @ normal[..., None])[..., 0]
    counts = (dist < tol).sum(axis=1)
    j = int(np.argmax(counts))
    mask = dist[j] < tol
    o = X[mask].mean(axis=0)
    _, _, vt = np.linalg.svd(X[mask] - o, full_matrices=False)  # refit: least squares
    E = np.stack([vt[0], vt[1], np.cross(vt[0], vt[1])], axis=1)
    return o, E, mask


def planar_pose(
    x: np.ndarray,
    X: np.ndarray,
    f: float,
    cx: float,
    cy: float,
    max_error_px: float,
    confidence: float,
    seed: int,
) -> DltPose | None:
    """Pose from matches on one plane with a known focal length (see the module docstring).

    Args:
        x: (n, 2) undistorted pixels.
        X: (n, 3) 3D points (m).
        f: focal length (pixels), kept fixed.
        cx, cy: principal point (pixels).
        max_error_px: inlier threshold.
        confidence: RANSAC confidence of the homography.
        seed: random seed.

    Returns:
        The pose (``planar=True``), or None if fewer than 6 matches fit one plane.
    """
    rng = np.random.default_rng(seed)
    if len(x) < MIN_SAMPLE:
        return None
    o, E, on_plane = _dominant_plane(X, rng)
    if on_plane.sum() < MIN_SAMPLE:
        return None
    u = ((X[on_plane] - o) @ E)[:, :2]
    cv2.setRNGSeed(seed)
    H, hmask = cv2.findHomography(
        u.astype(np.float64),
        x[on_plane].astype(np.float64),
        cv2.RANSAC,
        max_error_px,
        maxIters=2000,
        confidence=confidence,
    )
    if H is None or hmask is None or int(hmask.sum()) < MIN_SAMPLE:
        return None
    K = np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])
    B = np.linalg.solve(K, H)  # ~ lambda [r1 r2 t]
    lam = 2.0 / (np.linalg.norm(B[:, 0]) + np.linalg.norm(B[:, 1]))
    B = B * lam
    if B[2, 2] < 0:  # the plane's origin must be in front of the camera
        B = -B
    r1, r2 = B[:, 0], B[:, 1]
    U, _, Vt = np.linalg.svd(np.stack([r1, r2, np.cross(r1, r2)], axis=1))
    Rp = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    R = Rp @ E.T  # world -> plane frame -> camera
    t = B[:, 2] - R @ o
    thr2 = max_error_px**2
    mask = on_plane.copy()
    mask[on_plane] = hmask.ravel().astype(bool)
    for _ in range(2):
        _, R, t = refine_f_r_t(x[mask], X[mask], f, R, t, cx, cy, refine_focal=False)
        uv, z = project(_camera_matrix(f, cx, cy, R, t), X)
        err2 = ((uv - x) ** 2).sum(axis=1)
        new_mask = (z > 0) & (err2 < thr2)
        if new_mask.sum() < MIN_SAMPLE:
            return None
        if np.array_equal(new_mask, mask):
            break
        mask = new_mask
    rmse = float(np.sqrt(err2[mask].mean()))
    return DltPose(R, t, f, mask, 0, rmse, planar=True)
