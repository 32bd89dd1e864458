"""Each camera's clock offset and drift from the markers' motion, for recordings without usable
time stamps (``rehab track --sync auto``; docs/TRACKING.md, "Cameras on their own clocks").

A camera that images ``tau`` seconds after the frame set's instant sees a marker where it is
then: ``x_obs = x(p + v tau)``, so its view's reprojection residual against the tracked position
``p`` (velocity ``v``) is ``g tau`` with ``g`` the image velocity of the marker. Each camera's
skew relative to the first camera's (whose clock the frame sets follow) is a line wrapped into
the frame period, ``tau_c(t) = wrap(offset_c + rate_c t)``, fitted to every moving marker's views
of the whole study at once (the views weigh by their image speed squared: the information about
a skew is proportional to the speed), with its standard error from the curvature of the cost.
Pure numpy on the tracker's output.
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
        sigma_s: (C,) the skews' standard error, RMS over the study's frame sets (inf: the camera's
            views never moved enough to tell; negative: above ``max_sigma_s`` of
            :func:`fit_clocks`, not used, the offset and drift set to 0).
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
                parts.append(f"{name} not estimated (its views of the markers hardly moved)")
            elif s < 0:
                parts.append(f"{name} uncertain (+-{-1000 * s:.1f} ms: too little motion), not used")
            else:
                parts.append(f"{name} {1000 * o:+.1f} ms (+-{1000 * s:.2f}), drift {100 * r:+.3f} %")
        return f"clock offsets from the markers' motion against {names[0]}: " + "; ".join(parts)


@dataclass(frozen=True, slots=True)
class SkewEvidence:
    """What the views of moving markers say about the cameras' skews, per marker and frame set:
    the cost of skews ``tau`` (C,) for point ``i`` is ``tau A_i tau - 2 b_i tau + rr_i`` (px^2, the
    views' residuals left after the best shift of the point), with ``dof_i`` equations left.

    Attributes:
        times_s: (N,) the frame set's instant of each point; a: (N, C, C); b: (N, C); rr: (N,);
            dof: (N,) the point's views times 2 minus 3.
    """

    times_s: np.ndarray
    a: np.ndarray
    b: np.ndarray
    rr: np.ndarray
    dof: np.ndarray


def skew_evidence(cameras: Sequence[Camera], times_s: np.ndarray, positions_m: np.ndarray,
                  uv_px: np.ndarray) -> SkewEvidence:
    """Each marker's views in a frame set explained by one point (a small shift ``dp`` of the
    tracked position, unknown) and the cameras' skews: ``r_c = g_c tau_c - J_c dp`` (``J_c`` the
    projection's derivative, ``g_c = J_c v`` the image velocity). ``dp`` is eliminated per point
    (its least-squares part is projected out of the views' residuals).

    Args:
        cameras: the C cameras (their ``rolling_shutter_s`` rows are taken into account).
        times_s: (T,) frame-set instants; positions_m: (T, M, 3) tracked positions (NaN where not
            measured); uv_px: (T, M, C, 2) the centroids they were triangulated from, as seen
            (NaN unused). Points seen by two cameras or more, measured in the frame sets before
            and after (their velocity), are taken.
    """
    stack = CameraStack(tuple(cameras))
    t = np.asarray(times_s, dtype=np.float64)
    p = np.asarray(positions_m, dtype=np.float64)
    n_t, n_m = p.shape[:2]
    n_c = len(cameras)
    v = np.full_like(p, np.nan)  # central differences where three frame sets in a row are measured
    if n_t > 2:
        v[1:-1] = (p[2:] - p[:-2]) / (t[2:] - t[:-2])[:, None, None]
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
    times, a_all, b_all, rr_all, dof_all = [], [], [], [], []
    for k, m in zip(*np.nonzero(ok.sum(axis=2) >= 2)):
        views = np.flatnonzero(ok[k, m])
        J = jac[k, m, views].reshape(-1, 3)  # (2V, 3)
        G = np.zeros((2 * views.size, n_c))
        G[np.arange(2 * views.size), np.repeat(views, 2)] = g[k, m, views].reshape(-1)
        rr = r[k, m, views].reshape(-1)
        q, _ = np.linalg.qr(J)  # project out what a shift of the point explains
        Gp = G - q @ (q.T @ G)
        rp = rr - q @ (q.T @ rr)
        times.append(t[k])
        a_all.append(Gp.T @ Gp)
        b_all.append(Gp.T @ rp)
        rr_all.append(rp @ rp)
        dof_all.append(2 * views.size - 3)
    if not times:
        return SkewEvidence(np.zeros(0), np.zeros((0, n_c, n_c)), np.zeros((0, n_c)), np.zeros(0), np.zeros(0))
    return SkewEvidence(np.array(times), np.array(a_all), np.array(b_all), np.array(rr_all),
                        np.array(dof_all, dtype=np.float64))


def _wrap(x: np.ndarray, period_s: float) -> np.ndarray:
    return (x + period_s / 2.0) % period_s - period_s / 2.0


def fit_clocks(ev: SkewEvidence, period_s: float, *, min_span_s: float = 3.0, max_rate: float = 0.003,
               min_info_px: float = 2.0, max_sigma_s: float = 0.0005, block_s: float = 1.0) -> ClockEstimate:
    """Offsets and drifts relative to the first camera that minimize the evidence's cost over the
    whole study. A start: per block of ``block_s`` seconds, the cameras' skews solved together
    (they are coupled: a skew common to all is a shift of the points), and per camera the line
    closest to them modulo the period (a grid over the offset and the drift, +-``max_rate``; no
    drift when the points span less than ``min_span_s``). Then every camera's line together by
    least squares on every frame set's evidence (Gauss-Newton with the lines' wrap patterns,
    kept while the cost falls). Points whose residual is beyond 3 standard deviations of the rest
    (a view of another ball, a centroid moved by an occlusion) are left out and the fit repeated.
    The skews' standard error comes from the cost's curvature (all cameras' offsets and drifts
    together) and the residuals' noise, times how much more the blocks scatter about the lines
    than that noise explains (:func:`_scatter_factor`); an estimate whose error exceeds ``max_sigma_s`` (RMS over
    the study's frame sets: 2 standard errors within a millisecond) is not used (that camera keeps the first camera's instants), nor one whose
    views' image motion, after the point's shift is taken out, sums to less than ``min_info_px``
    per frame period in quadrature."""
    n_c = ev.a.shape[1] if ev.a.ndim == 3 else 1
    offset, rate = np.zeros(n_c), np.zeros(n_c)
    sigma = np.full(n_c, np.inf)
    sigma[0] = 0.0
    t = ev.times_s
    if t.size == 0:
        return ClockEstimate(offset, rate, sigma, float(period_s))
    t0 = float(t.min())
    tc = t - t0
    span = float(np.ptp(t))
    with_rate = span >= min_span_s
    info = np.sqrt(np.einsum("ncc->c", ev.a)) * period_s
    est = np.flatnonzero(info >= min_info_px)
    est = est[est > 0]
    frames, at = np.unique(tc, return_inverse=True)  # (the points of a frame set share its skews)
    basis = np.stack([np.ones_like(frames), frames], axis=1) if with_rate else np.ones((frames.size, 1))
    nb = basis.shape[1]
    keep = np.ones(t.size, bool)
    noise2 = 0.0
    for _ in range(2):
        a = np.zeros((frames.size, n_c, n_c))
        b = np.zeros((frames.size, n_c))
        np.add.at(a, at[keep], ev.a[keep])
        np.add.at(b, at[keep], ev.b[keep])
        if est.size:
            line = _start_lines(frames, a, b, est, period_s, span if with_rate else 0.0, max_rate, block_s,
                                min_info_px)
            line = _refine_lines(frames, a, b, est, basis, line, period_s)
            offset[est], rate[est] = line[:, 0] - line[:, 1] * t0, line[:, 1]
        full = _wrap(offset[None, :] + rate[None, :] * t[:, None], period_s)
        full[:, 0] = 0.0
        cost = ev.rr - 2 * np.einsum("nc,nc->n", ev.b, full) + np.einsum("nc,ncd,nd->n", full, ev.a, full)
        noise2 = float(cost[keep].sum() / max(ev.dof[keep].sum(), 1.0))
        keep = cost <= 9.0 * noise2 * np.maximum(ev.dof, 1.0)
    if est.size:  # the curvature of the cost over every estimated camera's offset and drift
        a = np.zeros((frames.size, n_c, n_c))
        np.add.at(a, at[keep], ev.a[keep])
        b = np.zeros((frames.size, n_c))
        np.add.at(b, at[keep], ev.b[keep])
        cov = noise2 * np.linalg.pinv(_curvature(a[:, est][:, :, est], basis))
        line = np.stack([offset[est] + rate[est] * t0, rate[est]], axis=1)
        factor = _scatter_factor(frames, a, b, est, line, period_s, block_s, min_info_px, noise2, nb)
        for i, c in enumerate(est.tolist()):  # the skew's standard error, RMS over the frame sets
            block = cov[i * nb:(i + 1) * nb, i * nb:(i + 1) * nb]
            sigma[c] = factor[i] * float(np.sqrt(max(np.mean(np.einsum("ti,ij,tj->t", basis, block, basis)), 0.0)))
    offset = _wrap(offset, period_s)
    unsure = np.isfinite(sigma) & (sigma > max_sigma_s)
    offset[unsure], rate[unsure] = 0.0, 0.0
    offset[np.isinf(sigma)] = 0.0
    rate[np.isinf(sigma)] = 0.0
    return ClockEstimate(offset, rate, np.where(unsure, -sigma, sigma), float(period_s))


def _curvature(a: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """(T, E, E) frame sets' evidence, (T, B) line basis -> (E B, E B) the cost's curvature in the
    cameras' line coefficients."""
    e, nb = a.shape[1], basis.shape[1]
    return np.einsum("nij,nk,nl->ikjl", a, basis, basis).reshape(e * nb, e * nb)


def _lines_cost(t, a, b, est, line, period_s) -> float:
    tau = np.zeros(b.shape)
    tau[:, est] = _wrap(line[None, :, 0] + line[None, :, 1] * t[:, None], period_s)
    return float(np.einsum("nc,ncd,nd->", tau, a, tau) - 2 * np.einsum("nc,nc->", b, tau))


def _blocks(t, a, b, est, period_s, block_s, min_info_px) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per block of ``block_s`` seconds, the estimated cameras' skews solved together: (B,) the
    blocks' mean instants, (B, E) skews and (B, E) their weights (the inverse of their variance
    over the noise's; 0 where the block tells too little)."""
    seen, weight, centres = [], [], []
    for lo in np.arange(t[0], t[-1] + block_s, block_s):
        inside = (t >= lo) & (t < lo + block_s)
        if not inside.any():
            continue
        ab, bb = a[inside].sum(axis=0)[np.ix_(est, est)], b[inside].sum(axis=0)[est]
        tau, w = np.zeros(est.size), np.zeros(est.size)
        use = np.flatnonzero(np.sqrt(np.diag(ab)) * period_s >= min_info_px / 4)
        if use.size:
            inv = np.linalg.pinv(ab[np.ix_(use, use)])
            tau[use] = inv @ bb[use]
            w[use] = 1.0 / np.maximum(np.diag(inv), 1e-30)
        seen.append(tau)
        weight.append(w)
        centres.append(float(np.mean(t[inside])))
    return np.array(centres), np.array(seen).reshape(-1, est.size), np.array(weight).reshape(-1, est.size)


def _start_lines(t, a, b, est, period_s, span_s, max_rate, block_s, min_info_px) -> np.ndarray:
    """(E, 2) a first line (offset at t = 0, drift) per estimated camera: each block's skews solved
    together (:func:`_blocks`), then each camera's line closest to them modulo the period
    (:func:`_fit_one`)."""
    centres, seen, weight = _blocks(t, a, b, est, period_s, block_s, min_info_px)
    line = np.zeros((est.size, 2))
    for i in range(est.size):
        line[i] = _fit_one(centres, weight[:, i], weight[:, i] * seen[:, i], period_s, span_s, max_rate)
    return line


def _scatter_factor(t, a, b, est, line, period_s, block_s, min_info_px, noise2, n_coef) -> np.ndarray:
    """(E,) how much more the blocks' skews scatter about the lines than the views' noise explains
    (the square root of their median chi-square over its expected value, at least 1): errors that persist
    over many frame sets (a partly hidden ball for a second) are not the independent noise the
    curvature assumes."""
    centres, seen, weight = _blocks(t, a, b, est, period_s, block_s, min_info_px)
    d = _wrap(seen - (line[None, :, 0] + line[None, :, 1] * centres[:, None]), period_s)
    out = np.ones(est.size)
    for i in range(est.size):
        used = weight[:, i] > 0
        if used.sum() > n_coef:
            # the median of chi-square with one degree of freedom is 0.455 (a median: a block that
            # holds a wrap mixes two phases and must not count)
            chi2 = weight[used, i] * d[used, i] ** 2 / max(noise2, 1e-30)
            out[i] = max(float(np.sqrt(np.median(chi2) / 0.455)), 1.0)
    return out


def _refine_lines(t, a, b, est, basis, line, period_s, steps: int = 10, margin_s: float = 0.003) -> np.ndarray:
    """Every camera's line together: the exact least squares on the frame sets' evidence for the
    lines' current wrap patterns, again with the new lines' patterns, a few times; the lowest cost
    is kept. A camera's frame sets within ``margin_s`` of half a period are left out of the solve
    when its line wraps in the study (a wrap placed a frame set early or late would pull the line
    by a whole period there)."""
    nb = basis.shape[1]
    best, best_cost = line, _lines_cost(t, a, b, est, line, period_s)
    for _ in range(steps):
        raw = line[None, :, 0] + line[None, :, 1] * t[:, None]
        wrapped = _wrap(raw, period_s)
        shift = raw - wrapped  # (T, E) whole periods taken off each camera's line
        # (a line that stays within one period over the study has no wrap to misplace)
        clear = (np.abs(wrapped) < period_s / 2 - margin_s) | (np.ptp(shift, axis=0) == 0)[None, :]
        ae = a[:, est][:, :, est] * clear[:, :, None] * clear[:, None, :]
        # minimize sum (c_e . basis - shift)^T A (...) - 2 b^T (...) over the lines' coefficients c
        rhs = b[:, est] * clear + np.einsum("nij,nj->ni", ae, shift)
        coef = (np.linalg.pinv(_curvature(ae, basis)) @ np.einsum("ni,nk->ik", rhs, basis).reshape(-1))
        new = line.copy()
        new[:, :nb] = coef.reshape(est.size, nb)
        cost = _lines_cost(t, a, b, est, new, period_s)
        if cost < best_cost:
            best, best_cost = new, cost
        if np.allclose(new, line, rtol=0.0, atol=1e-9):
            break
        line = new
    return best


def _fit_one(t: np.ndarray, alpha: np.ndarray, beta: np.ndarray, period_s: float, span_s: float,
             max_rate: float, start: tuple[float, float] | None = None) -> tuple[float, float]:
    """The line ``o + r t`` closest to the frame sets' skews ``beta / alpha`` (weights ``alpha``)
    modulo the period: a grid (0.5 ms, a drift step moving the last frame set by 1 ms), then
    least squares on the differences wrapped about the line, a few times. Modulo the period, as
    the clock is: near a wrap, a line a frame set early or late is as good as the camera's.
    ``start``: refine this line instead of searching the grid. Returns (o, r) at t = 0."""
    use = alpha > 0
    t, alpha = t[use], alpha[use]
    if t.size == 0:
        return 0.0, 0.0
    seen = beta[use] / alpha

    offsets = np.arange(-period_s / 2, period_s / 2, 0.0005)
    if span_s > 0:
        step = 0.001 / span_s
        rates = np.arange(-max_rate, max_rate + step / 2, step)
    else:
        rates = np.zeros(1)
    best = (np.inf, 0.0, 0.0) if start is None else (0.0, *start)
    for r in rates if start is None else ():  # (one row of the grid at a time: O x T)
        d = _wrap(offsets[:, None] + r * t[None, :] - seen[None, :], period_s)
        c = (alpha * d * d).sum(axis=1)
        i = int(np.argmin(c))
        if c[i] < best[0]:
            best = (float(c[i]), float(offsets[i]), float(r))
    _, o, r = best
    basis = np.stack([np.ones_like(t), t], axis=1) if span_s > 0 else np.ones((t.size, 1))
    h = basis.T @ (alpha[:, None] * basis)
    keep = np.ones(t.size, bool)
    for _ in range(2):  # then once more without the points far from the line (a block holding a wrap)
        w = alpha * keep
        h = basis.T @ (w[:, None] * basis)
        for _ in range(4):
            d = _wrap(seen - (o + r * t), period_s)
            step = np.linalg.lstsq(h, basis.T @ (w * d), rcond=None)[0]
            o, r = o + float(step[0]), (r + float(step[1]) if span_s > 0 else 0.0)
        d = np.abs(_wrap(seen - (o + r * t), period_s))
        keep = d < max(0.0015, 3 * 1.4826 * float(np.median(d)))
    return o, float(np.clip(r, -max_rate, max_rate))


#: A camera whose image stamps scatter by more than this about its own steady clock is too
#: irregular for the stamps to correct its views: at 1 m/s a view is then placed 2 mm or more
#: off, twice the synchronized cameras' error (docs/TRACKING.md, "Cameras on their own clocks").
MAX_JITTER_S = 0.002
#: What helps a camera whose timing is too irregular (said under its line).
IRREGULAR_ADVICE = "give it a USB port of its own, or a lower resolution or frame rate"


@dataclass(frozen=True, slots=True)
class StampTiming:
    """Each camera's clock as its image stamps show it (the live camera check).

    Attributes:
        offset_s: (C,) each camera's image instant minus the first camera's at the last frame set,
            wrapped into +-half a period (NaN: too few stamps).
        drift: (C,) each camera's frame rate against the first camera's, relative (0.001: 0.1 %
            fast); NaN: too few stamps.
        jitter_s: (C,) scatter of each camera's stamps about its own steady clock (1.4826 median
            absolute deviation); NaN: too few stamps.
        period_s: the frame period the stamps were counted in.
    """

    offset_s: np.ndarray
    drift: np.ndarray
    jitter_s: np.ndarray
    period_s: float

    @property
    def irregular(self) -> np.ndarray:
        """(C,) cameras whose stamps are too irregular to correct (jitter above MAX_JITTER_S)."""
        return np.nan_to_num(self.jitter_s, nan=0.0) > MAX_JITTER_S

    def lines(self, names: Sequence[str]) -> list[str]:
        """One line per camera, in words."""
        out = []
        for c, name in enumerate(names):
            if not np.isfinite(self.jitter_s[c]):
                out.append(f"{name}: timing being measured")
                continue
            jitter = f"jitter {1000 * self.jitter_s[c]:.1f} ms"
            if self.irregular[c]:
                out.append(f"{name}: timing too irregular to correct ({jitter})")
            elif c == 0:
                out.append(f"{name}: the reference clock, {jitter}")
            elif not np.isfinite(self.offset_s[c]):
                out.append(f"{name}: {jitter}")
            else:
                out.append(f"{name}: {1000 * self.offset_s[c]:+.1f} ms from {names[0]}, drift "
                           f"{100 * self.drift[c]:+.3f} %, {jitter}")
        return out


def stamp_timing(stamps_s: np.ndarray, period_s: float | None = None, min_images: int = 30) -> StampTiming:
    """(T, C) image stamps of the recent frame sets (NaN: missing) -> each camera's offset, drift
    and jitter (``period_s`` None: the median gap between a camera's images). A camera's own
    images (its distinct stamps) are counted in frame periods against its line (a camera that
    skips an image or gives one twice stays counted right) and fitted by the line, robustly
    (stamps farther than 5 deviations, a stall, left out); its residuals are the jitter. Pure numpy."""
    st = np.asarray(stamps_s, dtype=np.float64)
    n_c = st.shape[1] if st.ndim == 2 else 0
    nan = np.full(n_c, np.nan)
    phase, rate, jitter = nan.copy(), nan.copy(), nan.copy()
    last = float(np.nanmax(st)) if np.isfinite(st).any() else np.nan
    if period_s is None:
        gaps = [np.diff(np.unique(st[np.isfinite(st[:, c]), c])) for c in range(n_c)]
        gaps = np.concatenate(gaps) if gaps else np.zeros(0)
        period_s = float(np.median(gaps)) if gaps.size else np.nan
    if not (np.isfinite(period_s) and period_s > 0):
        return StampTiming(nan, nan.copy(), nan.copy(), float("nan"))
    for c in range(n_c):
        s = np.unique(st[np.isfinite(st[:, c]), c])
        if s.size < min_images:
            continue
        coef = np.array([period_s, s[0]])
        keep = np.ones(s.size, bool)
        for _ in range(3):  # each image's count of periods against the line, then the line again
            k = np.round((s - coef[1]) / coef[0])
            coef = np.polyfit(k[keep], s[keep], 1)
            resid = s - np.polyval(coef, k)
            mad = 1.4826 * float(np.median(np.abs(resid[keep] - np.median(resid[keep]))))
            keep = np.abs(resid) <= max(5 * mad, 1e-6)
        jitter[c] = mad
        rate[c] = float(coef[0])
        # the camera's image instant nearest the last frame set's (its steady clock's)
        frames = np.round((last - coef[1]) / coef[0])
        phase[c] = float(coef[1] + coef[0] * frames)
    offset = _wrap(phase - phase[0], period_s) if n_c else nan
    drift = rate[0] / rate - 1.0 if n_c else nan
    return StampTiming(offset, drift, jitter, float(period_s))
