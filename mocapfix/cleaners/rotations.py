"""Channel-space smoothing of the rotations a BVH or AMC file stores.

Position-space cleaners work on forward-kinematics joint positions and are written back
as rotations (:mod:`mocapfix.core.writeback`). This cleaner instead low-passes the channels
themselves, in a continuous representation (never raw, wrapped Euler angles): each joint with
three rotation DOFs is turned into unit quaternions (scipy ``Rotation``, intrinsic order
of the file), signs are made continuous (q and −q are the same rotation; a flip would be
a jump for the filter), the four components are filtered, renormalised and turned back
into the joint's Euler angles, each shifted by multiples of 360° to the branch nearest
the input — so no Euler wrap (±180°) and no quaternion sign flip is ever filtered across.
Joints with one or two DOFs are unwrapped and filtered as angles; translation channels
are filtered as they are. The filters are the shared NaN-safe kernels of
:mod:`mocapfix.solvers.segments`.

Marker data (no rotation channels) passes through unchanged. When an earlier step of the
pipeline changed the positions, they are first written back into the channels, so the
two kinds of cleaning compose.
"""
from __future__ import annotations

import numpy as np

from mocapfix.cleaners import register
from mocapfix.cleaners.base import REPLACED_FRAMES, Cleaner, Param
from mocapfix.core.errors import ConfigError
from mocapfix.core.kinematics import nearest_branch, nearest_euler
from mocapfix.core.motion import Motion
from mocapfix.solvers import glitches, rotation_glitches, rotchannels, segments, sure
from mocapfix.solvers.noise import white_noise
from mocapfix.solvers.rotchannels import continuous_quaternions
from mocapfix.solvers.segments import linear_bridge
from mocapfix.core.writeback import solve_channels


def _channels_from_positions(motion: Motion) -> np.ndarray:
    """The motion's channels; when an earlier step cleaned the positions, they are first
    written back into the channels, so position and channel cleaning compose."""
    ch = motion.channels.copy()
    if not np.allclose(motion.rig.positions(ch), motion.positions, rtol=0, atol=1e-9, equal_nan=False):
        ch = solve_channels(motion.rig, ch, motion.positions)
    return ch


def _rotation_columns(rig) -> list[int]:
    return [c for cols in rig.rot_columns for c in cols]


@register
class RotationSmooth(Cleaner):
    """Low-pass the rotation (and translation) channels of BVH/AMC motions."""

    name = "rotation_smooth"
    summary = "smooth BVH/AMC rotation channels as continuous quaternions"
    params = (
        Param("method", "choice", "butterworth", choices=("butterworth", "gaussian")),
        Param("cutoff", "frequency", "6 Hz", "Butterworth cut-off", unit="Hz", low=0.0, low_open=True),
        Param("order", "int", 2, "Butterworth order (doubled by the zero-phase pass)", low=1, high=10),
        Param("sigma", "time", "2 frames", "Gaussian sigma", unit="s", low=0.0),
        Param("translations", "bool", True, "also smooth translation channels"),
    )

    def _filter(self, x: np.ndarray, motion: Motion) -> np.ndarray:
        if self["method"] == "gaussian":
            return segments.gaussian(x, self.frames("sigma", motion))
        cutoff = self.hertz("cutoff")
        if not cutoff < motion.fps / 2.0:
            raise ConfigError(f"{self.step}: cutoff {cutoff:g} Hz must be below the Nyquist "
                              f"frequency {motion.fps / 2.0:g} Hz of this motion")
        from scipy import signal   # only this cleaner needs it: not loaded with the default config

        sos = signal.butter(self["order"], cutoff, fs=motion.fps, output="sos")
        pad = max(segments.default_padlen(sos), int(np.ceil(motion.fps / cutoff)))
        return segments.filtfilt(x, sos, padlen=pad)

    def _apply(self, motion: Motion):
        rig = motion.rig
        if rig is None or motion.channels is None or motion.n_frames < 3:
            return motion.copy(), {"skipped": "no rotation channels"}
        ch = _channels_from_positions(motion)
        full = [j for j in range(rig.n_joints) if len(rig.rot_axes[j]) == 3]
        partial = [c for j in range(rig.n_joints) if 0 < len(rig.rot_axes[j]) < 3
                   for c in rig.rot_columns[j]]
        unit = 360.0 if rig.degrees else 2 * np.pi
        if full:
            from scipy.spatial.transform import Rotation  # imported here: not loaded unless needed
            quats = []
            for j in full:
                rot = Rotation.from_euler(rig.rot_axes[j].upper(), ch[:, rig.rot_columns[j]],
                                          degrees=rig.degrees)
                quats.append(continuous_quaternions(rot.as_quat()))
            smooth = self._filter(np.concatenate(quats, axis=1), motion)
            for n, j in enumerate(full):
                q = smooth[:, 4 * n:4 * n + 4]
                q = q / np.linalg.norm(q, axis=1, keepdims=True)
                cols = rig.rot_columns[j]
                ang = Rotation.from_quat(q).as_euler(rig.rot_axes[j].upper(), degrees=rig.degrees)
                ch[:, cols] = nearest_euler(ang, ch[:, cols], rig.degrees)
        if partial:
            unwrapped = np.unwrap(ch[:, partial], period=unit, axis=0)
            smooth = self._filter(unwrapped, motion)
            ch[:, partial] = nearest_branch(smooth, ch[:, partial], rig.degrees)
        trans = rig.trans_columns[rig.trans_columns >= 0]
        if self["translations"] and trans.size:
            ch[:, trans] = self._filter(ch[:, trans], motion)
        positions = rig.positions(ch)
        return motion.replace(channels=ch, positions=positions), {
            "joints_as_quaternions": len(full), "angle_channels": len(partial),
            "translation_channels": int(trans.size) if self["translations"] else 0}


@register
class EulerSmooth(Cleaner):
    """The curve editor's filters on the Euler angle curves themselves: each rotation
    channel is unwrapped (±180° jumps removed), optionally median-filtered, then
    Gaussian-smoothed, and put back on the file's branch. The animator's baselines of the
    ``rotations`` bench protocol (a Gaussian; a median then a Gaussian); unlike
    ``rotation_smooth`` they filter each Euler angle independently, so near gimbal lock
    they mix axes."""

    name = "euler_smooth"
    summary = "median and/or Gaussian filter on unwrapped Euler angle curves (animators' filters)"
    params = (
        Param("median", "int", 0, "median filter width in frames (0: none; odd)", low=0, high=1001),
        Param("sigma", "time", "2 frames", "Gaussian sigma (0: none)", unit="s", low=0.0),
        Param("translations", "bool", False, "also filter translation channels"),
    )

    def _validate(self):
        if self["median"] and self["median"] % 2 == 0:
            raise ConfigError(f"{self.step}: parameter 'median' must be odd (or 0), got {self['median']}")

    def _apply(self, motion: Motion):
        rig = motion.rig
        if rig is None or motion.channels is None or motion.n_frames < 3:
            return motion.copy(), {"skipped": "no rotation channels"}
        ch = _channels_from_positions(motion)
        cols = _rotation_columns(rig)
        if self["translations"]:
            cols += [int(c) for c in rig.trans_columns.ravel() if c >= 0]
        rot = set(_rotation_columns(rig))
        period = 360.0 if rig.degrees else 2 * np.pi
        x = ch[:, cols].copy()
        for n, c in enumerate(cols):
            ok = ~np.isnan(x[:, n])
            if c in rot and ok.any():
                x[ok, n] = np.unwrap(x[ok, n], period=period)
        if self["median"] > 1:
            from scipy import ndimage

            filled, _ = segments.interpolate_gaps(x, "linear")
            med = ndimage.median_filter(np.where(np.isnan(filled), 0.0, filled),
                                        size=(self["median"], 1), mode="nearest")
            x = np.where(np.isnan(x), np.nan, med)
        sigma = self.frames("sigma", motion)
        if sigma > 0:
            x = segments.gaussian(x, sigma)
        for n, c in enumerate(cols):
            ch[:, c] = nearest_branch(x[:, n], ch[:, c], rig.degrees) if c in rot else x[:, n]
        return motion.replace(channels=ch, positions=rig.positions(ch)), {
            "channels": len(cols), "median_frames": self["median"], "sigma_frames": round(sigma, 3)}


def _features_of(motion: Motion):
    """(channels, features) of a BVH/AMC motion (positions cleaned by an earlier step are
    written back first)."""
    ch = _channels_from_positions(motion)
    return ch, rotchannels.to_features(motion.rig, ch)


@register
class RotationOutliers(Cleaner):
    """Remove glitches from the rotation channels of BVH/AMC without touching real motion.
    Works on the continuous features of :mod:`mocapfix.solvers.rotchannels` (quaternions
    of 3-DOF joints, unwrapped angles otherwise; degrees). A sample is a spike when it is
    farther from the running median of ``width`` frames than ``threshold`` × the robust
    spread (1.4826 · MAD) of its channel's median residuals, and at least ``min_angle``
    (Hampel identifier), and stands off the cubic through the frames around it
    (:func:`mocapfix.solvers.glitches.glitches`), unless the same deviation recurs at
    least twice more in its channel with the motion around it (a toe-off in every gait
    cycle is motion). A marked joint's channels are re-made by PCHIP interpolation of its
    features from the frames around — only when the world-space path of the joints its
    rotation moves contradicts the input there (re-made, that path keeps at most
    ``evidence`` of its summed squared acceleration:
    :func:`mocapfix.solvers.rotation_glitches.contradicted_by_limbs`). Every other
    channel value is kept bit for bit. Measurements: docs/methods/rotations.md.
    """

    name = "rotation_outliers"
    summary = "remove spikes from BVH/AMC rotation channels (Hampel on continuous rotations)"
    params = (
        Param("width", "int", 7, "running median width in frames (odd)", low=3, high=101),
        Param("threshold", "float", 6.0, "spike threshold in robust spreads of the channel", low=1.0,
              high=100.0),
        Param("min_angle", "float", 5.0, "smallest deviation (degrees) that can be a spike", low=0.0,
              high=180.0),
        Param("evidence", "float", glitches.EVIDENCE_RATIO, "a spike is re-made only when "
              "re-making it leaves the joints its rotation moves at most this share of their "
              "squared acceleration around it (the limb's path contradicts the channel)",
              low=0.0, high=1.0, low_open=True),
        Param("neutral", "length", "1 mm", "a spike whose re-making moves no joint by more "
              "than this has no lever to test it by, and is left as it is", unit="mm", low=0.0),
    )

    def _validate(self):
        if self["width"] % 2 == 0:
            raise ConfigError(f"{self.step}: parameter 'width' must be odd, got {self['width']}")

    def _apply(self, motion: Motion):
        rig = motion.rig
        if rig is None or motion.channels is None or motion.n_frames < self["width"]:
            return motion.copy(), {"skipped": "no rotation channels (or too few frames)"}
        ch, F = _features_of(motion)
        out, joint_bad, candidates = rotation_glitches.remake(
            rig, ch, F, width=self["width"], k=self["threshold"], floor=self["min_angle"],
            neutral=self.length("neutral", motion), ratio=self["evidence"])
        if not candidates:
            return motion.replace(channels=ch, positions=rig.positions(ch)), {"spike_frames": 0}
        layout = rotchannels.layout(rig)
        hit = np.flatnonzero(joint_bad.any(axis=0))
        return motion.replace(channels=out, positions=rig.positions(out)), {
            "spike_frames": int(joint_bad.any(axis=1).sum()), "joint_frames_replaced": int(joint_bad.sum()),
            "spikes_left_uncontradicted": candidates - int(joint_bad.sum()),
            "joints": {layout[n]["joint"]: int(joint_bad[:, n].sum()) for n in hit},
            REPLACED_FRAMES: {layout[n]["joint"]: np.flatnonzero(joint_bad[:, n]).tolist()
                              for n in hit}}


@register
class RotationDenoise(Cleaner):
    """Denoise the rotation channels of BVH/AMC, each at the smoothing its motion allows.
    On the continuous features of :mod:`mocapfix.solvers.rotchannels`, every feature is
    smoothed by the member of least Stein's unbiased risk (:mod:`mocapfix.solvers.sure`)
    of a family of Gaussian kernels (0.7–48 frames, capped by ``max_sigma``) and, with
    ``quadratic``, Gaussian-weighted local quadratic fits (1–24 frames), one choice per
    joint (``per_joint``) at every frame (``local``) or for the whole take. The noise is
    isotropic rotation noise of one level for the file
    (:func:`mocapfix.solvers.rotchannels.noise_shape`), measured on the file or given as
    ``noise`` in degrees. A joint's own discontinuities
    (:func:`mocapfix.solvers.glitches.steps`, at least ``step_floor`` degrees of noise
    assumed) are not smoothed across (:func:`mocapfix.solvers.sure.sure_piecewise`). A
    take is smoothed only when its noise is measurable
    (:func:`mocapfix.solvers.noise.white_noise`: flat across difference orders) and at
    least ``min_noise``; otherwise it is returned unchanged. Why, and the measurements:
    docs/methods/rotations.md."""

    name = "rotation_denoise"
    summary = "SURE-tuned smoothing (Gaussian or local quadratic, per joint) of continuous BVH/AMC rotations"
    params = (
        Param("noise", "float", None, "noise level in degrees (default: estimated from the file)",
              low=0.0, high=90.0, nullable=True),
        Param("max_sigma", "time", None, "largest Gaussian sigma", unit="s", low=0.0, nullable=True),
        Param("local", "time", None, "choose the width per frame from the risk over this span "
              "(default: one width per channel)", unit="s", low=0.0, low_open=True, nullable=True),
        Param("quadratic", "bool", True, "also try Gaussian-weighted local quadratic fits"),
        Param("per_joint", "bool", True, "one smoother for all the features of a joint (chosen by "
              "their summed risk) rather than one per feature"),
        Param("steps", "float", 6.0, "a joint's frame-to-frame change standing off its neighbouring "
              "changes by more than this many noise deviations is a discontinuity, not smoothed "
              "across (null: smooth across everything)", low=0.0, low_open=True, nullable=True),
        Param("step_floor", "float", 0.5, "smallest noise level (degrees) the step test assumes: on "
              "nearly clean takes every turn of real motion would otherwise be a step", low=0.0, high=90.0),
        Param("min_noise", "float", 0.05, "a measured noise level (degrees) below this is left: "
              "it moves no joint by a millimetre, and smoothing each joint alone only disturbs "
              "how their rotations compensate each other", low=0.0, high=90.0),
    )

    def _apply(self, motion: Motion):
        rig = motion.rig
        if rig is None or motion.channels is None or motion.n_frames < 8:
            return motion.copy(), {"skipped": "no rotation channels (or too few frames)"}
        ch, F = _features_of(motion)
        missing = np.isnan(F)
        X = linear_bridge(F)
        shape = rotchannels.noise_shape(rig, X)
        if self["noise"] is not None:
            noise = self["noise"]
        else:
            noise, measurable = white_noise(X, shape=shape)
            why = ("no measurable noise (the noise estimate falls with the order of the "
                   "differences: what they see is motion)" if not measurable else
                   f"noise below {self['min_noise']:g}° (nothing worth a change)"
                   if noise < self["min_noise"] else None)
            if why:
                return motion.replace(channels=ch, positions=rig.positions(ch)), {
                    "noise_deg": round(float(noise), 4), "unchanged": why}
        cap = None if self["max_sigma"] is None else self.frames("max_sigma", motion)
        span = None if self["local"] is None else self.frames("local", motion)
        joint_of = np.concatenate([np.full(e["size"], n) for n, e in enumerate(rotchannels.layout(rig))])
        groups = joint_of if self["per_joint"] else np.arange(X.shape[1])
        breaks = (glitches.steps(X, max(noise, self["step_floor"]) * shape, groups=groups, threshold=self["steps"])
                  if self["steps"] is not None else None)
        Z, widths = sure.sure_piecewise(X, noise * shape, breaks=breaks, groups=groups, max_width=cap,
                                        span=span, quadratic_widths=sure.QUADRATIC_WIDTHS if self["quadratic"] else ())
        Z[missing] = np.nan
        out = rotchannels.from_features(rig, Z, ch)
        return motion.replace(channels=out, positions=rig.positions(out)), {
            "noise_deg": round(float(noise), 4),
            "median_sigma_frames": float(np.median(widths)) if widths.size else 0.0,
            "unsmoothed_features": int((widths == 0).sum()),
            "steps_not_smoothed_across": 0 if breaks is None else int(breaks.sum())}
