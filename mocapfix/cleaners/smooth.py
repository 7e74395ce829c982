"""Classic smoothers per channel: Gaussian, zero-phase Butterworth,
wavelet shrinkage and a constant-velocity Kalman/RTS smoother.

All are NaN-safe: missing samples stay missing (except ``kalman`` with ``fill: true``),
no NaN spreads into observed samples, and nothing is extrapolated past the ends of the
capture. The kernels live in :mod:`mocapfix.solvers.segments` and
:mod:`mocapfix.solvers.kalman`.
"""
from __future__ import annotations

import numpy as np

from mocapfix.cleaners import register
from mocapfix.cleaners.base import Cleaner, Param
from mocapfix.core.gaps import gap_report
from mocapfix.core.errors import ConfigError
from mocapfix.core.motion import Motion
from mocapfix.solvers import segments
from mocapfix.solvers.kalman import cv_rts_smoother


def _channels(motion: Motion) -> np.ndarray:
    T, J, _ = motion.positions.shape
    return motion.positions.reshape(T, 3 * J)


def _with_channels(motion: Motion, x: np.ndarray) -> Motion:
    out = x.reshape(motion.positions.shape)
    out[np.isnan(motion.positions)] = np.nan
    return motion.replace(positions=out)


_GAPS = Param("gaps", "choice", "segments",
              "how gaps are handled: 'bridge' (interpolate across, filter, restore the gap) or "
              "'segments' (filter each observed segment alone)", choices=segments.GAP_MODES)


@register
class Gaussian(Cleaner):
    """Gaussian low-pass per channel. The zero-phase response is
    ``H(f) = exp(−2 π² σ² f²)`` (σ in seconds): half amplitude at ``f = 0.1874 / σ``
    (18.7 Hz for the default 0.01 s, which gave the lowest error on CMU 85_02 and HDM05
    with 2 mm jitter among 5–20 ms).

    NaN-safe by normalised convolution on each observed segment, extended by point
    reflection at its ends (:func:`mocapfix.solvers.segments.gaussian`), so no value is
    pulled across a gap and straight-line motion is not biased at the segment ends.
    """

    name = "gaussian"
    summary = "Gaussian low-pass per channel (NaN-safe normalised convolution)"
    params = (
        Param("sigma", "time", "0.01 s", "standard deviation of the Gaussian kernel",
              unit="s", low=0.0),
        _GAPS,
    )

    def _apply(self, motion: Motion):
        sigma = self.frames("sigma", motion)
        if motion.positions.size == 0:
            return motion.copy(), {}
        out = segments.gaussian(_channels(motion), sigma, gaps=self["gaps"])
        return _with_channels(motion, out), {"sigma_frames": round(float(sigma), 4)}


@register
class Butterworth(Cleaner):
    """Zero-phase Butterworth low-pass (``scipy.signal.butter`` + ``sosfiltfilt``).

    ``order`` is the order of the designed filter; running it forwards and backwards
    doubles it, so the default ``order: 2`` is the biomechanics convention of a
    4th-order zero-phase filter (Winter, *Biomechanics and Motor Control of Human
    Movement*, 4th ed., §3.4). The zero-phase response is ``|H(f)|²``: the amplitude at
    ``cutoff`` is 1/2 (−6 dB); no cutoff correction for the double pass is applied.

    Gaps: by default each observed segment is filtered on its own after an odd (point-
    reflection) extension of ``max(scipy default, fps / cutoff)`` samples (``gaps:
    segments``): no ringing at gap edges and nothing pulled across a gap. The straight line
    through a segment's end samples is taken out before and added back after
    (:func:`mocapfix.solvers.segments.end_line`): a segment shorter than the filter's
    transient keeps a straight movement (a 2-sample piece came out 40 mm off). ``gaps: bridge``
    bridges gaps with PCHIP first; measured worse next to long gaps (see
    :mod:`mocapfix.solvers.segments`).
    """

    name = "butterworth"
    summary = "zero-phase Butterworth low-pass per channel"
    params = (
        Param("cutoff", "frequency", "6 Hz", "cut-off frequency of the designed filter",
              unit="Hz", low=0.0, low_open=True),
        Param("order", "int", 2, "order of the designed filter (doubled by the forward-"
              "backward pass)", low=1, high=10),
        _GAPS,
    )

    def _apply(self, motion: Motion):
        cutoff = self.hertz("cutoff")
        if not cutoff < motion.fps / 2.0:
            raise ConfigError(
                f"{self.step}: cutoff {cutoff:g} Hz must be below the Nyquist frequency "
                f"{motion.fps / 2.0:g} Hz of this motion ({motion.fps:g} fps)")
        if motion.positions.size == 0:
            return motion.copy(), {}
        from scipy import signal      # imported here: loading it costs ~0.5 s

        sos = signal.butter(self["order"], cutoff, btype="low", fs=motion.fps, output="sos")
        pad = max(segments.default_padlen(sos), int(np.ceil(motion.fps / cutoff)))
        out = segments.filtfilt(_channels(motion), sos, gaps=self["gaps"], padlen=pad)
        return _with_channels(motion, out), {}


@register
class Wavelet(Cleaner):
    """Wavelet shrinkage per channel (``pywt.wavedec``/``waverec``): noise std from the
    median absolute finest-detail coefficient / 0.6745 (Donoho & Johnstone 1994),
    BayesShrink soft thresholds per band (Chang, Yu & Vetterli 2000; the formula of
    ``skimage.restoration.denoise_wavelet``). Level None: ``dwt_max_level − 1`` (see
    :func:`mocapfix.solvers.segments.wavelet_denoise`)."""

    name = "wavelet"
    summary = "wavelet denoising per channel (BayesShrink, soft thresholds)"
    params = (
        Param("wavelet", "str", "sym8", "a discrete wavelet known to PyWavelets"),
        Param("level", "int", None, "decomposition levels (default: automatic)", low=1,
              high=20, nullable=True),
        Param("threshold", "choice", "bayes", "'bayes' (BayesShrink soft thresholds) or "
              "'linear' (drop every detail band: a wavelet low-pass)",
              choices=segments.WAVELET_THRESHOLDS),
        _GAPS,
    )

    def _validate(self):
        if self["wavelet"] == "sym8":     # the default: no need to load pywt to check it
            return
        import pywt

        if self["wavelet"] not in pywt.wavelist(kind="discrete"):
            raise ConfigError(f"{self.step}: parameter 'wavelet' = {self['wavelet']!r} is not a "
                              f"discrete wavelet (e.g. sym8, db4, coif3)")

    def _apply(self, motion: Motion):
        if motion.positions.size == 0:
            return motion.copy(), {}
        out = segments.wavelet_denoise(_channels(motion), self["wavelet"], self["level"],
                                       gaps=self["gaps"], threshold=self["threshold"])
        return _with_channels(motion, out), {}


@register
class Kalman(Cleaner):
    """Constant-velocity Kalman filter + RTS smoother per coordinate
    (:func:`mocapfix.solvers.kalman.cv_rts_smoother`).

    ``accel_noise`` is the square root of the white-noise acceleration spectral density,
    in m/s²/√Hz (q = accel_noise²); with ``measurement_noise`` σ it sets the bandwidth: the
    steady-state smoother is a 4th-order low-pass with half-power frequency
    ``≈ (q / (σ² dt))^{1/4} / 2π`` (the cubic smoothing-spline equivalence), about 12 Hz
    for the defaults at 120 fps. The defaults (0.5 m/s²/√Hz, 1 mm) gave the lowest error
    on CMU 85_02 and HDM05 with 2 mm jitter (after ``spikes`` + ``fill``): 1.7 and 1.5 mm
    RMSE, against 4.9 / 2.3 mm for 0.15 and 1.9 / 1.9 mm for 1.5.

    Missing samples skip the update; with ``fill: true`` the smoothed trajectory is kept in
    interior gaps of at most ``max_gap`` (never before the first or after the last
    observation). The initial state is diffuse (1 m, 10 m/s standard deviations).
    """

    name = "kalman"
    summary = "constant-velocity Kalman filter + RTS smoother per coordinate"
    params = (
        Param("accel_noise", "float", 0.5, "sqrt of the acceleration spectral density, "
              "m/s^2/sqrt(Hz)", low=0.0, low_open=True, high=1e4),
        Param("measurement_noise", "length", "1 mm", "std of the measurement noise",
              unit="mm", low=0.0, low_open=True),
        Param("fill", "bool", False, "keep the smoothed trajectory in interior gaps"),
        Param("max_gap", "time", "0.5 s", "longest gap to fill when fill is true", unit="s",
              low=0.0, nullable=True),
    )

    def _apply(self, motion: Motion):
        if motion.positions.size == 0:
            return motion.copy(), {}
        x = _channels(motion)
        mpu = motion.metres_per_unit
        q = (self["accel_noise"] / mpu) ** 2
        r = self.length("measurement_noise", motion) ** 2
        p0_pos, p0_vel = (1.0 / mpu) ** 2, (10.0 / mpu) ** 2       # 1 m, 10 m/s: diffuse
        pos, _, _ = cv_rts_smoother(x, 1.0 / motion.fps, q, r, p0_pos, p0_vel)
        missing = np.isnan(x)
        keep = np.zeros_like(missing)
        if self["fill"]:
            max_gap = None if self["max_gap"] is None else self.frames("max_gap", motion)
            keep = segments.fillable(missing, max_gap)
        pos[missing & ~keep] = np.nan
        out = pos.reshape(motion.positions.shape)
        # a marker is filled only where all of its coordinates are
        partial = np.isnan(out).any(axis=2)
        out[partial] = np.where(np.isnan(motion.positions[partial]), np.nan, out[partial])
        result = motion.replace(positions=out)
        info = gap_report(motion.missing, result.missing, motion.fps) if self["fill"] else {}
        return result, info
