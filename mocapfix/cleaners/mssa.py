"""Example-based M-SSA filter bases (Lou 2012, PhD thesis ch. 2):
denoise, remove outliers and fill gaps with spatio-temporal filter bases learned from clean
motions, by the robust reconstruction of eq. 2.16 (:mod:`mocapfix.solvers.ssa`).

Two spaces (``space``):

- ``rotations`` (BVH, ASF/AMC): the rotation channels as continuous signals
  (:mod:`mocapfix.solvers.rotchannels`: sign-continuous quaternions for 3-DOF joints,
  unwrapped angles otherwise, in degrees; never raw wrapped Euler angles). The cleaned
  channels are written on the branch nearest the input; translation channels are left as
  they are.
- ``positions`` (markers, Kinect, or any motion without rotation channels): joint
  positions in metres relative to the frame's centroid of all joints (gaps bridged
  linearly for the centroid only).

Training (``fit``, ``mocapfix train-dictionary --method mssa``): the features are centred
with the training mean, the grand lag-covariance of every ``window``-frame window
(eq. 2.3; every ``step``-th window) is summed over the training files, and the leading
eigenvectors are kept — as many as hold ``energy`` of it (the thesis keeps 99 %), and at
least as many as bring the training residual per sample below ``max_residual``: on
acrobatics the root's heading holds most of the energy and 99 % kept two bases, which
explain nothing of the limbs. ``bases`` fixes K instead. The model stores the feature
layout (joint names and axes, or joint names), the window, the frame rate, the mean and
the bases.

Cleaning: a model is used when its layout and frame rate are the file's (a ``model``
named in the config — a file it does not fit is an error — else a shipped model made for
that layout). Otherwise the bases are learned from the file itself (always with ``model: self``;
:func:`mocapfix.solvers.ssa.robust_bases`: spikes flagged
by a running median are replaced by it before the covariance, and the worst-explained
windows are trimmed; K keeps the eigenvalues above ``noise_floor`` × the file's noise
variance), and the report says so (``bases: "self"``). The report also gives
``unexplained``: the fraction of the input's (centred, gaps filled with the result)
window energy the bases cannot explain, with a warning when it is above
``out_of_sample`` × the training figure — motion unlike the training set.
"""
from __future__ import annotations

import time

import numpy as np

from mocapfix.cleaners import register
from mocapfix.cleaners.base import FittedCleaner, Param
from mocapfix.core.errors import MocapfixError
from mocapfix.core.motion import Motion
from mocapfix.solvers import rotchannels, ssa
from mocapfix.solvers.nanstats import nanmedian_columns
from mocapfix.solvers.segments import linear_bridge

#: shipped model per rotation layout signature (first joints' names), used with no ``model``
AUTO_MODELS = ("mssa-cmu",)


def _space(motion: Motion, wanted: str) -> str:
    has_rot = motion.rig is not None and motion.channels is not None and any(motion.rig.rot_axes)
    if wanted == "auto":
        return "rotations" if has_rot else "positions"
    if wanted == "rotations" and not has_rot:
        raise MocapfixError(f"{motion.path or 'motion'}: space 'rotations' needs rotation channels "
                            f"(BVH or ASF/AMC)")
    return wanted


def _signature(motion: Motion, space: str) -> list:
    if space == "rotations":
        return [[e["joint"], e["axes"]] for e in rotchannels.layout(motion.rig)]
    return [[n, "xyz"] for n in motion.names]


def _features(motion: Motion, space: str):
    """(T, L) features and what is needed to undo them."""
    if space == "rotations":
        return rotchannels.to_features(motion.rig, motion.channels), None
    P = motion.positions * motion.metres_per_unit
    T, J, _ = P.shape
    flat = P.reshape(T, -1)
    anchor = linear_bridge(flat).reshape(T, J, 3).mean(axis=1)
    return (P - anchor[:, None]).reshape(T, -1), anchor


def _undo(motion: Motion, space: str, Z: np.ndarray, anchor) -> Motion:
    if space == "rotations":
        ch = rotchannels.from_features(motion.rig, Z, motion.channels)
        return motion.replace(channels=ch, positions=motion.rig.positions(ch))
    T, J = motion.n_frames, motion.n_joints
    P = (Z.reshape(T, J, 3) + anchor[:, None]) / motion.metres_per_unit
    return motion.replace(positions=P)


@register
class MSSA(FittedCleaner):
    name = "mssa"
    summary = ("denoise, remove outliers and fill gaps with learned M-SSA filter bases "
               "(Lou 2012, example-based denoising)")
    single_thread_blas = True
    params = (
        Param("model", "model", None, "model file or shipped name, or 'self' (default: a shipped model "
              "for the file's channel layout, else bases learned from the file)", nullable=True),
        Param("space", "choice", "auto", "rotation channels (BVH/AMC) or joint positions; auto = "
              "rotations when the file has them", choices=("auto", "rotations", "positions")),
        Param("lam", "float", 1.0, "λ of eq. 2.16: weight of the filter term", low=0.0, low_open=True,
              high=1e6),
        Param("p", "float", 3.0, "Welsch scale p (eq. 2.9) on rotation features, degrees",
              low=1e-3, high=1e4),
        Param("p_length", "length", "30 mm", "Welsch scale p on position features", unit="mm",
              low=1e-6, high=10.0),
        Param("iterations", "int", 10, "alternations of the robust reconstruction", low=1, high=500),
        Param("out_of_sample", "float", 3.0, "warn when unexplained energy exceeds this × training",
              low=1.0, high=1e6),
        # training (fit, and bases learned from the file itself)
        Param("window", "int", 12, "training: window length M in frames", low=2, high=200),
        Param("energy", "float", 0.99, "training: energy the bases keep", low=0.0, low_open=True,
              high=1.0),
        Param("max_residual", "float", 0.25, "training: keep bases until the training residual per "
              "sample (RMS, degrees; positions: cm) is at most this", low=0.0, high=1e3),
        Param("bases", "int", None, "training: number of bases K (overrides energy/max_residual)",
              low=1, high=100000, nullable=True),
        Param("noise_floor", "float", 8.0, "bases learned from the file itself: keep the eigenvalues "
              "above this × the file's noise variance", low=0.0, high=1e6),
        Param("window_step", "int", 4, "training: take every window_step-th window", low=1, high=1000),
    )
    fitted_attributes = ("bases_", "mean_", "layout_", "window_", "fps_", "space_")
    auto_models = AUTO_MODELS

    def __init__(self, step=None, **values):
        super().__init__(step, **values)
        for a in self.fitted_attributes + ("unexplained_", "eigenvalues_"):
            setattr(self, a, None)
        self.training_ = None

    # -- helpers ------------------------------------------------------------------------
    def _scale(self, space: str) -> float:
        """Feature units per Welsch/residual unit: degrees as they are; positions (m) → cm."""
        return 1.0 if space == "rotations" else 0.01

    def _choose_k(self, vals: np.ndarray, d: int, space: str) -> int:
        if self.values["bases"] is not None:
            return int(min(self.values["bases"], d))
        total = float(vals.sum())
        if total <= 0:
            return 1
        k_energy = int(np.searchsorted(np.cumsum(vals) / total, self.values["energy"]) + 1)
        # per-sample RMS residual of a window: sqrt(energy left out / d)
        per_sample = np.sqrt(np.clip(total - np.cumsum(vals), 0, None) / d)
        limit = self.values["max_residual"] * self._scale(space)
        k_res = int(np.argmax(per_sample <= limit) + 1) if (per_sample <= limit).any() else len(vals)
        return int(min(max(k_energy, k_res, 1), d))

    # -- fit ----------------------------------------------------------------------------
    def fit(self, motions, progress=None) -> "MSSA":
        started = time.perf_counter()
        motions = list(motions)
        if not motions:
            raise MocapfixError("no training motions")
        first = motions[0]
        space = _space(first, self.values["space"])
        layout = _signature(first, space)
        m = self.values["window"]
        feats = []
        for mo in motions:
            if space == "rotations" and _space(mo, "auto") != "rotations":
                raise MocapfixError(f"{mo.path or 'training motion'}: has no rotation channels, but "
                                    f"the model learns the rotations of {first.path or 'the first'} "
                                    "(BVH/AMC); train one model per skeleton")
            if _signature(mo, space) != layout:
                raise MocapfixError(f"{mo.path or 'training motion'}: its channel layout differs from "
                                    f"{first.path or 'the first training motion'}'s; train one model per "
                                    f"skeleton")
            if abs(mo.fps - first.fps) > 0.01 * first.fps:
                raise MocapfixError(f"{mo.path or 'training motion'}: {mo.fps:g} Hz, the first training "
                                    f"motion has {first.fps:g} Hz; train one model per frame rate")
            feats.append(_features(mo, space)[0])
        allf = np.concatenate(feats)
        seen = (~np.isnan(allf)).sum(axis=0)      # a channel never seen: mean 0, no warning
        mean = np.nansum(allf, axis=0) / np.maximum(seen, 1)
        acc = ssa.LagCovariance(m, allf.shape[1])
        for n, F in enumerate(feats):
            acc.add(F - mean, step=self.values["window_step"])
            if progress:
                progress(n + 1, len(feats))
        if acc.count == 0:
            raise MocapfixError(f"no training motion has a complete window of {m} frames")
        _, vals = acc.bases(k=1)
        k = self._choose_k(vals, m * allf.shape[1], space)
        E, vals = acc.bases(k=k)
        self._set(E, vals, mean, layout, m, first.fps, space)
        self.training_ = {"frames": int(sum(len(F) for F in feats)), "windows": acc.count,
                          "seconds": round(time.perf_counter() - started, 3)}
        return self

    def _set(self, E, vals, mean, layout, m, fps, space):
        # stored as float32 in model files: hold the same values in memory, so a fitted
        # cleaner and its saved-and-loaded copy give identical results
        self.bases_ = np.asarray(E, dtype=np.float32).astype(np.float64)
        self.eigenvalues_ = np.asarray(vals, dtype=np.float64)
        self.mean_ = np.asarray(mean, dtype=np.float64)
        self.layout_ = [list(x) for x in layout]
        self.window_ = int(m)
        self.fps_ = float(fps)
        self.space_ = space
        self.unexplained_ = ssa.unexplained_fraction(vals, E.shape[1])

    # -- model files ----------------------------------------------------------------------
    def state(self) -> tuple[dict, dict]:
        if not self.is_fitted:
            raise MocapfixError(f"{self.step}: not fitted")
        header = {"state": {"space": self.space_, "layout": self.layout_, "window": self.window_,
                            "fps": self.fps_, "bases": int(self.bases_.shape[1]),
                            "unexplained": self.unexplained_,
                            "features": ("quaternions (sign-continuous, ×360/π) for 3-DOF joints, "
                                         "unwrapped degrees otherwise" if self.space_ == "rotations"
                                         else "joint positions in metres minus the frame centroid"),
                            "window_layout": "frame-major: window vector = X[s:s+M].ravel()"}}
        arrays = {"bases": self.bases_.astype(np.float32), "mean": self.mean_,
                  "eigenvalues": self.eigenvalues_}
        return header, arrays

    @staticmethod
    def check_state(st, arrays: dict) -> None:
        """A model's state must hold a positive frame rate, a window of at least one frame,
        a layout, a matrix of bases and vectors of means and eigenvalues
        (``FittedCleaner.check_state``)."""
        from mocapfix.core.models import matrix, positive, window

        if not isinstance(st, dict):
            raise ValueError("no state")
        positive(st, "fps")
        window(st)
        if not isinstance(st.get("layout"), list):
            raise ValueError("state 'layout' is not a list")
        matrix(arrays, "bases")
        for name in ("mean", "eigenvalues"):
            if name not in arrays or arrays[name].ndim != 1:
                raise ValueError(f"array {name!r} is missing or not a vector")

    def load_state(self, header: dict, arrays: dict) -> "MSSA":
        st = header["state"]
        E = np.asarray(arrays["bases"], dtype=np.float64)
        mean = np.asarray(arrays["mean"], dtype=np.float64)
        m = int(st["window"])
        if E.shape[0] != m * mean.shape[0]:
            raise ValueError(f"bases have {E.shape[0]} rows for window {m} × {mean.shape[0]} features")
        if st["space"] not in ("rotations", "positions"):
            raise ValueError(f"unknown space {st['space']!r}")
        self._set(E, np.asarray(arrays["eigenvalues"], dtype=np.float64), mean, st["layout"], m,
                  float(st["fps"]), st["space"])
        self.training_ = header.get("training")
        return self

    def resolve_models(self, base_dir=None) -> None:
        """``model: self`` forces bases learned from each file; anything else is resolved
        as for every fitted cleaner."""
        if self.values.get("model") == "self":
            return
        super().resolve_models(base_dir)

    # -- apply ------------------------------------------------------------------------------
    def _matching_model(self, motion: Motion, space: str, layout: list):
        """(E, mean, unexplained, source, window) of a model made for this layout and rate,
        or None."""
        def fits(lay, fps, sp):
            return sp == space and lay == layout and abs(fps - motion.fps) <= 0.01 * motion.fps

        if self.is_fitted:
            if fits(self.layout_, self.fps_, self.space_):
                return (self.bases_, self.mean_, self.unexplained_, self.values["model"] or "fitted",
                        self.window_)
            if self.values["model"] is not None:
                # the user named this model: bases learned from the file instead would not
                # be what was asked for (and the line would still say OK)
                what = {"positions": "joint positions", "rotations": "rotating joints"}
                raise MocapfixError(
                    f"{self.step}: the model {self.values['model']} was made for "
                    f"{len(self.layout_)} {what[self.space_]} at {self.fps_:g} Hz; "
                    f"{motion.path or 'this motion'} has {len(layout)} {what[space]} at "
                    f"{motion.fps:g} Hz{' in another layout' if len(layout) == len(self.layout_) else ''}"
                    "; train a model for it (mocapfix train-dictionary --method mssa) or use "
                    "model: self")
            return None
        if self.values["model"] is None:   # "self": no model
            from mocapfix.core import models

            ships = models.shipped()
            for name in AUTO_MODELS:
                if name in ships:
                    header, arrays = models.load(ships[name], cleaner=self.name,
                                                 check=self.check_state)
                    st = header["state"]
                    if fits([list(x) for x in st["layout"]], float(st["fps"]), st["space"]):
                        other = self.with_state(header, arrays)
                        return other.bases_, other.mean_, other.unexplained_, name, other.window_
        return None

    def _apply(self, motion: Motion):
        space = _space(motion, self.values["space"])
        layout = _signature(motion, space)
        T = motion.n_frames
        F, anchor = _features(motion, space)
        info: dict = {"space": space}
        found = self._matching_model(motion, space, layout)
        m = found[4] if found is not None else self.values["window"]
        if T < max(2 * m, 4) or F.shape[1] == 0:
            info["skipped"] = f"{T} frames are too few for windows of {m}"
            return motion.copy(), info
        if found is not None:
            E, mean, trained, source, _ = found
            info["bases"] = source
        else:
            mean = nanmedian_columns(F)           # no warning for a joint never seen
            mean = np.where(np.isnan(mean), 0.0, mean)
            scale = self._scale(space)
            E, vals, used = ssa.robust_bases(F - mean, m, energy=1.0, k=None, step=max(1, T // 1500),
                                             spike_floor=2.0 * scale)
            # the file's own noise spreads evenly over the eigenvalues (σ² each): keep the
            # bases standing above that floor (or K given)
            sigma = ssa.noise_level(F)
            info["noise"] = round(sigma / scale, 4)
            if self.values["bases"] is not None:
                k = min(self.values["bases"], E.shape[1])
            else:
                k = max(1, int((vals[:E.shape[1]] > self.values["noise_floor"] * sigma ** 2).sum()))
            E = E[:, :k]
            trained = ssa.unexplained_fraction(vals, k)
            info["bases"] = "self"
            info["note"] = ("no model for this channel layout and frame rate: filter bases learned "
                            "from the file itself (robustly)" if self.values["model"] in (None, "self")
                            and not self.is_fitted else "the model does not match this file's channel layout "
                            "or frame rate: filter bases learned from the file itself (robustly)")
            info["windows_used"] = used
        scale = self._scale(space)
        p = self.values["p"] if space == "rotations" else self.values["p_length"].si
        Y = F - mean
        Z, w, it = ssa.robust_reconstruct(Y, E, m, lam=self.values["lam"], p=p,
                                          iterations=self.values["iterations"])
        # unexplained energy of the input (gaps filled with the result)
        Yc = np.where(np.isnan(Y), Z, Y)
        Wm = ssa.windows(Yc, m, step=max(1, m // 2))
        R = Wm - (Wm @ E) @ E.T
        frac = float(np.vdot(R, R) / max(np.vdot(Wm, Wm), 1e-300))
        observed = ~np.isnan(Y)
        info.update({"window": int(m), "n_bases": int(E.shape[1]), "iterations": it,
                     "unexplained": round(frac, 5), "unexplained_training": round(float(trained), 5),
                     "outlier_samples": int((observed & (w < 0.5)).sum()),
                     "welsch_p": p / scale if space == "positions" else p})
        outliers = float((observed & (w < 0.5)).sum() / max(observed.sum(), 1))
        if (frac > self.values["out_of_sample"] * max(trained, 1e-4) and frac > 0.01) or outliers > 0.1:
            info["warning"] = (f"motion unlike the training set: the bases leave {100 * frac:.1f} % of "
                               f"its energy unexplained (training {100 * trained:.2f} %) and treat "
                               f"{100 * outliers:.1f} % of the samples as outliers")
        return _undo(motion, space, Z + mean, anchor), info
