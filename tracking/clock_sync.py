"""Each camera's clock offset and drift from the markers' motion, for recordings without usable
time stamps (``rehab track --sync auto``; docs/TRACKING.md, "Cameras on their own clocks").

A camera that images ``tau`` seconds after the frame set's instant sees a marker where it is
then: ``x_obs = x(p + v tau)``, so its view's reprojection residual against the tracked position
``p`` (velocity ``v``) is ``g tau`` with ``g`` the image velocity of the marker. Over many views
of moving markers, ``tau`` of each camera is a least-squares ratio; it is taken per block of about
a second, relative to the first camera (whose clock the frame sets follow), unwrapped modulo the
frame period (a drifting camera's phase wraps when a recorder pairs nearest frames), and fitted
by a line: ``tau_c(t) = offset_c + rate_c t``. Pure numpy on the tracker's output.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from calibration.camera import Camera, CameraStack


@dataclass(frozen=True, slots=True)
class ClockEstimate:
    """Cameras' image instants relative to the first camera's.

    Attributes:
        offset_s: (C,) each camera's offset at time 0, seconds (0 for the first camera).
        rate: (C,) each camera's drift, seconds per second.
        sigma_s: (C,) the offsets' standard error from the blocks' scatter (inf: not estimated; NaN:
            too few blocks to tell; negative: above ``max_sigma_s`` of :func:`fit_clocks`, not used).
        period_s: the frame period (the skews wrap into +-half of it).
    """

    offset_s: np.ndarray
    rate: np.ndarray
    sigma_s: np.ndarray
    period_s: float

    def skews(self, times_s: np.ndarray) -> np.ndarray:
        """(T,) frame-set instants -> (T, C) each camera's image instant minus the set's."""
        raw = self.offset_s[None, :] + self.rate[None, :] * np.asarray(times_s, dtype=np.float64)[:, None]
        half = self.period_s / 2.0
        return (raw + half) % self.period_s - half

    def line(self, names: Sequence[str]) -> str:
        parts = []
        for name, o, r, s in zip(names[1:], self.offset_s[1:], self.rate[1:], self.sigma_s[1:]):
            if np.isinf(s):
                parts.append(f"{name} not estimated (too little motion)")
            elif s < 0:
                parts.append(f"{name} uncertain (+-{-1000 * s:.1f} ms: too little motion), not used")
            else:
                spread = f"+-{1000 * s:.2f}" if np.isfinite(s) else "few seconds of motion: no spread"
                parts.append(f"{name} {1000 * o:+.1f} ms ({spread}), drift {100 * r:+.3f} %")
        return f"clock offsets from the markers' motion against {names[0]}: " + "; ".join(parts)


def block_offsets(cameras: Sequence[Camera], times_s: np.ndarray, positions_m: np.ndarray, uv_px: np.ndarray,
                  block_s: float = 1.0, min_info_px: float = 2.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per block of ``block_s`` seconds, each camera's image instant minus the first camera's.

    Each marker's views in a frame set are explained by one point (a small shift ``dp`` of the
    tracked position, unknown) and the cameras' skews: ``r_c = g_c tau_c - J_c dp`` (``J_c`` the
    projection's derivative, ``g_c = J_c v`` the image velocity). ``dp`` is eliminated per point
    (its least-squares part is projected out of the views' residuals), the skews are solved over
    all of a block's points, the first camera's fixed at 0 (a common skew is a shift of ``dp``).

    Args:
        cameras: the C cameras (their ``rolling_shutter_s`` rows are taken into account).
        times_s: (T,) frame-set instants; positions_m: (T, M, 3) tracked positions (NaN where not
            measured); uv_px: (T, M, C, 2) the centroids they were triangulated from, as seen
            (NaN unused).
        min_info_px: a camera's skew is taken when its views' image motion left after the
            elimination, in pixels per frame period summed in quadrature, reaches this.
    Returns:
        centres (B,) block mid-times, tau (B, C) seconds (first column 0; NaN where the block
        tells too little), info (B, C) the image motion behind each (px per frame period, in
        quadrature: the skew's standard error is the centroids' noise over it).
    """
    stack = CameraStack(tuple(cameras))
    t = np.asarray(times_s, dtype=np.float64)
    p = np.asarray(positions_m, dtype=np.float64)
    n_t, n_m = p.shape[:2]
    n_c = len(cameras)
    v = np.full_like(p, np.nan)  # central differences where three frame sets in a row are measured
    if n_t > 2:
        v[1:-1] = (p[2:] - p[:-2]) / (t[2:] - t[:-2])[:, None, None]
    period = float(np.median(np.diff(t))) if n_t > 1 else 1.0
    row_s = np.array([c.rolling_shutter_s / c.size_px[1] for c in cameras])
    f = stack.focal_px
    cam = stack.world_to_cameras(p.reshape(-1, 3)).reshape(n_t, n_m, n_c, 3)
    vel = stack.rotate_to_cameras(v.reshape(-1, 3)).reshape(n_t, n_m, n_c, 3)
    rot = stack.rotation  # (C, 3, 3)
    with np.errstate(invalid="ignore", divide="ignore"):
        z = cam[..., 2:]
        x = cam[..., :2] / z
        g = (vel[..., :2] - x * vel[..., 2:]) / z * f[:, None]  # image velocity, px per second
        # d x / d p (2x3 per view, px per metre): (R[:2] - x R[2]) / z
        jac = (rot[None, None, :, :2, :] - x[..., :, None] * rot[None, None, :, 2:3, :]) / z[..., None]
        jac *= f[None, None, :, None, None]
        xn = stack.undistort_points(uv_px.reshape(-1, n_c, 2)).reshape(n_t, n_m, n_c, 2)
        r = (xn - x) * f[:, None] - g * (row_s[None, None, :] * uv_px[..., 1])[..., None]  # px, rows' delay out
    ok = np.isfinite(g).all(-1) & np.isfinite(r).all(-1) & np.isfinite(jac).all((-1, -2))
    centres, taus, infos = [], [], []
    for lo in np.arange(t[0], t[-1] + block_s, block_s):
        frames = np.flatnonzero((t >= lo) & (t < lo + block_s))
        if frames.size < 3:
            continue
        a = np.zeros((n_c, n_c))
        b = np.zeros(n_c)
        for k in frames.tolist():
            for m in np.flatnonzero(ok[k].sum(axis=1) >= 2).tolist():
                views = np.flatnonzero(ok[k, m])
                J = jac[k, m, views].reshape(-1, 3)  # (2V, 3)
                G = np.zeros((2 * views.size, n_c))
                G[np.arange(2 * views.size), np.repeat(views, 2)] = g[k, m, views].reshape(-1)
                rr = r[k, m, views].reshape(-1)
                # project out what a shift of the point explains
                q, _ = np.linalg.qr(J)
                Gp = G - q @ (q.T @ G)
                rp = rr - q @ (q.T @ rr)
                a += Gp.T @ Gp
                b += Gp.T @ rp
        tau = np.full(n_c, np.nan)
        tau[0] = 0.0
        info = np.sqrt(np.diag(a) * period**2)
        info[0] = 0.0
        use = np.flatnonzero(info >= min_info_px)
        if use.size:
            tau[use] = np.linalg.lstsq(a[np.ix_(use, use)], b[use], rcond=None)[0]
        centres.append(lo + block_s / 2)
        taus.append(tau)
        infos.append(info)
    if not centres:
        return np.zeros(0), np.zeros((0, n_c)), np.zeros((0, n_c))
    return np.array(centres), np.array(taus), np.array(infos)


def fit_clocks(centres_s: np.ndarray, tau_s: np.ndarray, info: np.ndarray, period_s: float,
               min_span_s: float = 3.0, max_sigma_s: float = 0.001) -> ClockEstimate:
    """Blocks' skews (B,), (B, C) -> offsets and drifts relative to the first camera: each
    camera's block values taken against the first camera's, unwrapped modulo the period and fitted
    by a line weighted by each block's information squared (``info`` of :func:`block_offsets`; a
    constant when the blocks span less than ``min_span_s``: a drift from two close blocks
    extrapolated to the start was worse than none), robustly: blocks farther from a first fit
    than 3 median deviations and 1.5 ms are dropped (a block that holds a wrap mixes two phases)."""
    n_c = tau_s.shape[1]
    offset, rate, sigma = np.zeros(n_c), np.zeros(n_c), np.zeros(n_c)
    for c in range(1, n_c):
        rel = tau_s[:, c] - tau_s[:, 0]
        ok = np.isfinite(rel)
        if not ok.any():
            offset[c], rate[c], sigma[c] = 0.0, 0.0, np.inf
            continue
        tc, y, w = centres_s[ok], rel[ok], info[ok, c] ** 2
        # unwrap: each block against the previous one's value, modulo the period
        y = np.concatenate([[y[0]], y[0] + np.cumsum((np.diff(y) + period_s / 2) % period_s - period_s / 2)])
        keep = np.ones(len(y), bool)
        for _ in range(2 if len(y) >= 4 else 1):  # (a line through 2 or 3 blocks keeps them all)
            sw = np.sqrt(w[keep])
            if np.ptp(tc[keep]) >= min_span_s:
                a = np.vstack([np.ones(keep.sum()), tc[keep]]).T
                coef = np.linalg.lstsq(a * sw[:, None], y[keep] * sw, rcond=None)[0]
            else:
                coef = np.array([float(np.average(y[keep], weights=w[keep])), 0.0])
            resid = y - (coef[0] + coef[1] * tc)
            if len(y) >= 4:  # (a block that holds a wrap mixes two phases: an outlier)
                mad = float(np.median(np.abs(resid[keep] - np.median(resid[keep]))))
                keep = np.abs(resid) < max(0.0015, 3 * 1.4826 * mad)
        # the standard error from the blocks' scatter about the fit (NaN: too few blocks to tell)
        n, dof = int(keep.sum()), int(keep.sum()) - (2 if coef[1] != 0.0 else 1)
        scatter = float(np.sqrt((resid[keep] ** 2).sum() / dof)) if dof > 0 else np.nan
        offset[c], rate[c], sigma[c] = coef[0], coef[1], scatter / np.sqrt(n)
    half = period_s / 2.0
    offset = (offset + half) % period_s - half
    # an estimate whose blocks scatter by more than a millisecond (slow motions: the skews' image
    # displacement is below the centroids' noise; on the population's slow motion such estimates
    # were several milliseconds off) is not used: that camera keeps the first camera's instants
    unsure = np.isfinite(sigma) & (sigma > max_sigma_s)
    offset[unsure], rate[unsure] = 0.0, 0.0
    return ClockEstimate(offset, rate, np.where(unsure, -sigma, sigma), float(period_s))
