"""Constant-velocity Kalman filter and Rauch–Tung–Striebel smoother, vectorised over
channels.

Model (per channel, state ``[position, velocity]``; Bar-Shalom, Li & Kirubarajan,
*Estimation with Applications to Tracking and Navigation*, 2001, §6.2.2 "continuous
white-noise acceleration model")::

    x_{t+1} = F x_t + w_t,   F = [[1, dt], [0, 1]],
    Q = q [[dt³/3, dt²/2], [dt²/2, dt]]          (q: acceleration spectral density)
    y_t = x_t[0] + v_t,      v_t ~ N(0, r)

Missing samples (NaN) skip the measurement update, so the smoother also bridges gaps with
the constant-velocity prediction, blended from both sides by the RTS pass (Rauch, Tung &
Striebel 1965). The 2×2 algebra is written out component-wise on (C,) arrays: one Python
loop over frames for the forward pass and one for the backward pass, no loop over channels.
"""
from __future__ import annotations

import numpy as np


def cv_rts_smoother(y: np.ndarray, dt: float, q: float, r: float, p0_pos: float,
                    p0_vel: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smooth every column of ``y`` (T, C) with a constant-velocity Kalman filter + RTS.

    Parameters
    ----------
    y : (T, C) measurements, NaN = missing.
    dt : sample interval (s).
    q : acceleration spectral density (unit² / s³).
    r : measurement noise variance (unit²).
    p0_pos, p0_vel : prior variances of position (unit²) and velocity (unit²/s²); the prior
        mean is the first observed sample of each column with zero velocity, so large values
        give a diffuse start.

    Returns
    -------
    position : (T, C) smoothed positions (defined also in gaps and before/after the first/
        last observation, where it is a prediction — callers decide what to keep).
    velocity : (T, C) smoothed velocities (unit/s).
    variance : (T, C) smoothed position variances (unit²).
    """
    y = np.asarray(y, dtype=np.float64)
    T, C = y.shape
    obs = ~np.isnan(y)
    first = np.argmax(obs, axis=0)
    m0 = np.where(obs.any(axis=0), y[first, np.arange(C)], 0.0)
    q00, q01, q11 = q * dt ** 3 / 3.0, q * dt ** 2 / 2.0, q * dt

    # filtered (f) and predicted (p) means and covariances, component-wise
    fx = np.empty((T, C)); fv = np.empty((T, C))
    fa = np.empty((T, C)); fb = np.empty((T, C)); fc = np.empty((T, C))
    px = np.empty((T, C)); pv = np.empty((T, C))
    pa = np.empty((T, C)); pb = np.empty((T, C)); pc = np.empty((T, C))

    x, v = m0, np.zeros(C)
    a, b, c = np.full(C, float(p0_pos)), np.zeros(C), np.full(C, float(p0_vel))
    for t in range(T):
        if t > 0:
            x, v = x + dt * v, v
            a, b, c = a + 2.0 * dt * b + dt * dt * c + q00, b + dt * c + q01, c + q11
        px[t], pv[t], pa[t], pb[t], pc[t] = x, v, a, b, c
        o = obs[t]
        if o.any():
            s = a + r
            k0 = np.where(o, a / s, 0.0)
            k1 = np.where(o, b / s, 0.0)
            innov = np.where(o, y[t], x) - x
            x, v = x + k0 * innov, v + k1 * innov
            a, b, c = (1.0 - k0) * a, (1.0 - k0) * b, c - k1 * b
        fx[t], fv[t], fa[t], fb[t], fc[t] = x, v, a, b, c

    sx, sv, sa = fx.copy(), fv.copy(), fa.copy()
    xs, vs = fx[-1].copy(), fv[-1].copy()
    As, Bs, Cs = fa[-1].copy(), fb[-1].copy(), fc[-1].copy()
    for t in range(T - 2, -1, -1):
        # G = P_f Fᵀ P_p(t+1)⁻¹
        a, b, c = fa[t], fb[t], fc[t]
        ppa, ppb, ppc = pa[t + 1], pb[t + 1], pc[t + 1]
        det = ppa * ppc - ppb * ppb
        m00, m01, m10, m11 = a + dt * b, b, b + dt * c, c          # P_f Fᵀ
        g00 = (m00 * ppc - m01 * ppb) / det
        g01 = (m01 * ppa - m00 * ppb) / det
        g10 = (m10 * ppc - m11 * ppb) / det
        g11 = (m11 * ppa - m10 * ppb) / det
        dx, dv = xs - px[t + 1], vs - pv[t + 1]
        xs, vs = fx[t] + g00 * dx + g01 * dv, fv[t] + g10 * dx + g11 * dv
        da, db, dc = As - ppa, Bs - ppb, Cs - ppc
        # P_s = P_f + G dP Gᵀ
        h00, h01 = g00 * da + g01 * db, g00 * db + g01 * dc
        h10, h11 = g10 * da + g11 * db, g10 * db + g11 * dc
        As = a + h00 * g00 + h01 * g01
        Bs = b + h00 * g10 + h01 * g11
        Cs = c + h10 * g10 + h11 * g11
        sx[t], sv[t], sa[t] = xs, vs, As
    return sx, sv, sa
