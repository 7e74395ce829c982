"""Partlet dictionary denoising (Feng et al. 2015, IEEE T-Cybernetics 45(11)), with the
K-SVD poselet variant of Xiao et al. 2015 (Neurocomputing) as an option.

Pipeline (Feng 2015, Algorithm 1):

1. *Coordinate normalisation* (§III-B-1): every pose is moved into its torso frame
   (:func:`mocapfix.solvers.rigid.torso_frames`) and each joint centred on the file's
   own median position in that frame.
2. *Partlets* (§III-B-2): torso + head, two arms, two legs; the joints at the seams
   belong to several partlets and are averaged back.
3. *Grouping* (§III-B-3): lagged windows of ``m`` samples, taken every ``dilation``
   frames (the model's sample rate), one window starting every ``stride`` frames.
4. *Robust structured sparse coding* (§III-D, eq. 11): alternate the Ψ-step — FISTA on
   eq. 12 with the k-NN graph Laplacian of eq. 9 — and the E-step of the ℓ2,p noise term
   (eq. 16–18), one group per joint sample. Missing samples have zero weight in the data
   term, so the cleaner also fills gaps.
5. *Reconstruction* (§III-D-3): windows averaged where they overlap, partlets merged,
   normalisation undone.

Beyond the paper: λ1, λ3 scaled by the noise level measured on the file, λ2 off; the
windows coded are presmoothed (GCV, then a SURE choice per sample,
:mod:`mocapfix.solvers.local_sure`); the residual the dictionary leaves is added back
smoothed; a coarse scale under heavy noise; suspect samples
(:func:`mocapfix.solvers.partlet.suspect_samples`) kept out of the presmoothing and the
frame fit; bones projected to their median length where the input is rigid
(:func:`mocapfix.solvers.partlet.rigid_bones`). Each change, what was tried and not kept,
and the measurements against the paper: docs/methods/partlet.md.

Xiao 2015 (``coding: ksvd``): codes by OMP with ``sparsity`` atoms from a K-SVD model;
``loss: l2`` for Gaussian noise, ``loss: l1`` reweights samples against outliers.

The report's ``unexplained`` is, per partlet, the fraction of the energy of the coded
signal the dictionary cannot explain on observed samples; a limb above
``out_of_sample`` is reported as motion unlike the training set.
"""
from __future__ import annotations

import time
import warnings

import numpy as np

from mocapfix.core import bodyparts
from mocapfix.cleaners import register
from mocapfix.cleaners.base import FittedCleaner, Param
from mocapfix.core.errors import ConfigError, MocapfixError
from mocapfix.core.motion import Motion
from mocapfix.solvers import partlet as pk
from mocapfix.solvers.dct import gcv_smooth
from mocapfix.solvers.lowrank import blas_single_thread
from mocapfix.solvers.rigid import from_frame, kabsch, to_frame, torso_frames
from mocapfix.solvers.segments import linear_bridge

#: a model for a file when no ``model`` is given: shipped name by skeleton convention
AUTO_MODELS = (("lfemur", "partlet-cmu"), ("kneeleft", "partlet-kinect"))


@register
class PartletDictionary(FittedCleaner):
    name = "partlet_dictionary"
    summary = ("denoise and fill joints with learned partlet dictionaries (Feng et al. 2015; "
               "K-SVD variant of Xiao et al. 2015)")
    single_thread_blas = True
    params = (
        Param("model", "model", None, "model file or shipped name (default: by skeleton)", nullable=True),
        Param("coding", "choice", "auto", "robust structured sparse coding (Feng) or ksvd/OMP (Xiao); "
              "auto = as the model was trained", choices=("auto", "robust", "ksvd")),
        Param("loss", "choice", "l2", "ksvd coding: l2 (Gaussian noise) or l1 (outliers)", choices=("l2", "l1")),
        Param("lambda1", "float", 4.0, "ℓ2,p noise weight as a multiple of the noise level", low=0.0, high=1e3),
        Param("lambda2", "float", 0.0, "graph smoothness weight, relative to ||DᵀD||", low=0.0, high=1e3),
        Param("lambda3", "float", 1.0, "sparsity weight as a multiple of the noise level", low=0.0, high=1e3),
        Param("p", "float", 1.0, "p of the ℓ2,p noise norm", low=0.0, low_open=True, high=2.0),
        Param("min_outlier", "length", "40 mm", "smallest residual the noise term may absorb", unit="mm",
              low=0.0, high=10.0),
        Param("ridge", "float", 1e-2, "ridge (relative to ||DᵀD||) of the codes' starting point",
              low=1e-9, high=1e3),
        Param("iterations", "int", 3, "E/Ψ alternations", low=1, high=200),
        Param("fill_iterations", "int", 10, "E/Ψ alternations when samples are missing", low=1, high=500),
        Param("fista_iterations", "int", 20, "FISTA iterations per Ψ-step", low=1, high=2000),
        Param("neighbours", "int", 5, "k of the k-NN graph", low=0, high=50),
        Param("stride", "int", 4, "window samples between windows of one phase", low=1, high=64),
        Param("despike", "float", 5.0, "samples farther than this many noise σ from a running median are "
              "kept from the presmoothing and the frame fit (0: off)", low=0.0, high=100.0),
        Param("presmooth", "bool", True, "code windows of the input smoothed as GCV finds noise in it"),
        Param("local_smoothing", "time", "0.5 s", "window over which the presmoothing's strength is chosen "
              "per sample by SURE (0: one GCV strength per channel)", unit="s", low=0.0, high=60.0),
        Param("frame_gcv", "bool", True, "fit the torso frame to GCV-smoothed torso joints"),
        Param("frame_smoothing", "time", "0.05 s", "Gaussian smoothing of the torso frame", unit="s",
              low=0.0, high=2.0),
        Param("frame_noise", "length", "20 mm", "noise level above which the frame smoothing grows in "
              "proportion (up to 6×; 0: fixed)", unit="mm", low=0.0, high=10.0),
        Param("bones", "bool", True, "project the cleaned bones to their median lengths (files with a skeleton)"),
        Param("coarse_noise", "length", "180 mm", "noise level above which the model's coarse scale (longer "
              "windows) codes the file (robust coding), if it has one (0: never)", unit="mm", low=0.0, high=10.0),
        Param("detail", "bool", True, "add back the residual detail the dictionary misses, "
              "Wiener-weighted against the noise level", ),
        Param("out_of_sample", "float", 0.005, "warn when a partlet's dictionary leaves more than this "
              "fraction of its energy unexplained", low=0.0, high=1.0),
        # training (fit) parameters
        Param("method", "choice", "partlet", "training: robust dictionary (partlet) or K-SVD",
              choices=("partlet", "ksvd")),
        Param("atoms", "int", 128, "training: atoms per partlet dictionary", low=2, high=4096),
        Param("window", "int", 16, "training: window length m in samples", low=1, high=200),
        Param("sample_rate", "frequency", "120 Hz", "training: rate of the window samples", unit="Hz",
              low=1.0, high=10000.0),
        Param("coarse_rate", "frequency", "30 Hz", "training: rate of the window samples of a second, coarse "
              "scale (windows as long in samples; none unless below half the sample rate)", unit="Hz",
              low=0.0, high=10000.0),
        Param("train_lambda", "length", "50 mm", "training: outlier weight λ of eq. 5 (as a length)",
              unit="mm", low=0.0, high=10.0),
        Param("beta", "float", 0.05, "training: sparsity β of eq. 5, relative to the median window norm",
              low=0.0, high=10.0),
        Param("sparsity", "int", 6, "ksvd: atoms per window (OMP)", low=1, high=256),
        Param("train_iterations", "int", 15, "training: outer iterations", low=1, high=1000),
        Param("max_windows", "int", 8000, "training: windows per partlet (random subset)", low=10,
              high=10_000_000),
        Param("seed", "int", 0, "training: random seed", low=0, high=2**31),
    )
    fitted_attributes = ("dictionary_", "template_", "joints_", "partlets_")
    auto_models = tuple(name for _, name in AUTO_MODELS)

    def __init__(self, step=None, **values):
        super().__init__(step, **values)
        self.dictionary_ = None
        self.template_ = None
        self.joints_ = None
        self.partlets_ = None
        self.frame_ = None
        self.unexplained_ = None
        self.method_ = None
        self.sample_rate_ = None
        self.window_ = None
        self.coarse_ = None
        self.n_iter_ = None
        self.training_ = None

    # -- shared normalisation ------------------------------------------------------------
    def _map_joints(self, names: list[str]) -> np.ndarray:
        """For every model joint, the index of the file's joint (−1 if the file has none)."""
        where: dict[str, int] = {}
        for i, c in enumerate(bodyparts.canonical_names(names)):
            where.setdefault(c, i)
        return np.array([where.get(j, -1) for j in self.joints_], dtype=np.intp)

    def _written_joints(self, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """(file joints, model joints) to write: every file joint whose name maps to a model
        joint (joints a conversion placed at a zero offset share one model joint)."""
        model = {j: k for k, j in enumerate(self.joints_)}
        pairs = [(f, model[c]) for f, c in enumerate(bodyparts.canonical_names(names)) if c in model]
        f, k = zip(*pairs) if pairs else ((), ())
        return np.array(f, dtype=np.intp), np.array(k, dtype=np.intp)

    def _normalise(self, P: np.ndarray, fps: float):
        """Model-joint positions P (T, Jm, 3) in metres → (local, R, c, centre)."""
        frame_pts = P[:, self.frame_]
        if self.values["frame_gcv"] and len(P) > 8:
            # the frame comes from the torso joints smoothed as much as GCV finds noise in
            # them: under heavy noise a per-frame fit would turn noise into body rotation
            T = len(P)
            flat = frame_pts.reshape(T, -1)
            miss = np.isnan(flat)
            filled = linear_bridge(flat)
            ok = ~np.isnan(filled).any(axis=0)
            if ok.any():
                sm, _ = gcv_smooth(filled[:, ok], n_pad=min(T // 2, int(round(0.1 * fps))))
                filled[:, ok] = sm
            filled[miss] = np.nan
            frame_pts = filled.reshape(frame_pts.shape)
        # heavier noise, smoother frame: the smoothing grows with the torso joints' noise
        # level above ``frame_noise`` (up to 6×); clean input keeps its quick turns
        ref = self.values["frame_noise"].si
        fac = 1.0
        if ref > 0:
            fac = float(np.clip(pk.noise_level(P[:, self.frame_].reshape(len(P), -1)) / ref, 1.0, 6.0))
        R, c, valid = torso_frames(frame_pts, self.template_,
                                   smoothing=self.values["frame_smoothing"].si * fps * fac)
        local = to_frame(P, R, c)
        with warnings.catch_warnings():   # model joints the file lacks are all NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            centre = np.nanmedian(local, axis=0)
        return local, R, c, centre, valid

    @staticmethod
    def _dilation(fps: float, rate: float) -> int:
        """Frames between a window's samples for windows sampled at ``rate``."""
        return max(1, int(round(fps / rate)))

    # -- fit -----------------------------------------------------------------------------
    def fit(self, motions, progress=None) -> "PartletDictionary":
        started = time.perf_counter()
        motions = list(motions)
        if not motions:
            raise MocapfixError("no training motions")
        first = motions[0]
        canon = bodyparts.canonical_names(first.names)
        parents = first.skeleton.parents if first.skeleton is not None else None
        try:
            groups = bodyparts.partlets(canon, parents)
        except ValueError as exc:
            raise MocapfixError(f"{first.path or 'training motion'}: cannot find the five partlets "
                                f"from the joint names ({exc})") from None
        joints = list(canon)
        frame = bodyparts.frame_joints(canon, groups)
        m = self.values["window"]
        rate = self.values["sample_rate"].si
        # template: generalised Procrustes of the frame joints over (a subset of) all frames
        pts = []
        for mo in motions:
            P = self._model_positions(mo, joints)
            if (~np.isnan(P[:, frame]).any(axis=2)).sum(axis=1).max(initial=0) < 3:
                # a motion of another skeleton (the names do not map) cannot fix the body
                # frame (3 of its joints in a frame): it failed deep inside with "internal
                # error ValueError: no frame has enough torso points"
                raise MocapfixError(
                    f"{mo.path or 'training motion'}: lacks body-frame joints of "
                    f"{first.path or 'the first training motion'} "
                    f"({', '.join(joints[j] for j in frame if np.isnan(P[:, j]).all())}); "
                    "train one model per skeleton")
            pts.append(P[:: max(1, len(P) // 400), frame])
        pool = np.concatenate(pts)
        pool = pool[~np.isnan(pool).any(axis=(1, 2))]
        if not len(pool):
            raise MocapfixError("no training frame holds every body-frame joint "
                                f"({', '.join(joints[j] for j in frame)})")
        ref = pool[0] - pool[0].mean(axis=0)
        for _ in range(5):
            Rr, cs, ct = kabsch(pool, np.broadcast_to(ref, pool.shape), np.ones(pool.shape[:2]))
            aligned = (pool - cs[:, None]) @ np.swapaxes(Rr, 1, 2) + ct[:, None]
            ref = aligned.mean(axis=0)
            ref -= ref.mean(axis=0)
        self.joints_, self.frame_, self.template_ = joints, np.array(frame), ref
        self.partlets_ = {k: list(v) for k, v in groups.items()}
        self.sample_rate_, self.window_ = rate, m
        rng = np.random.default_rng(self.values["seed"])
        coarse = self.values["coarse_rate"].si
        scales = [rate] + ([coarse] if 0 < coarse <= rate / 2 else [])
        data = [{p: [] for p in bodyparts.PARTLETS} for _ in scales]
        frames = []
        for mo in motions:
            P = self._model_positions(mo, joints)
            local, *_rest, centre, _ = self._normalise(P, mo.fps)
            X = local - centre
            frames.append(len(P))
            for k, r in enumerate(scales):
                dil = self._dilation(mo.fps, r)
                # fine scale: a window every half window sample; coarse: every ``dil`` samples
                # (a quarter as many windows as the fine scale at 30 of 120 Hz)
                starts = pk.starts(len(P), m, dil, max(1, dil // 2) if k == 0 else dil)
                if not len(starts):
                    continue
                for p in bodyparts.PARTLETS:
                    Xp = X[:, self.partlets_[p]].reshape(len(P), -1)
                    W = pk.windows(Xp, m, dil, starts)
                    W = W[:, ~np.isnan(W).any(axis=0)]
                    data[k][p].append(W)
        if not all(data[0].values()):
            raise MocapfixError(f"no training motion has a complete window of {m} samples at "
                                f"{rate:g} Hz ({m / rate:.2f} s); give longer takes or a shorter --window")
        K = self.values["atoms"]
        total = len(bodyparts.PARTLETS) * len(scales)
        with blas_single_thread():
            self.dictionary_, self.unexplained_, iters = self._fit_partlets(data[0], K, rng, progress, total)
            self.coarse_ = None
            if len(scales) > 1 and all(data[1].values()):
                # its own random stream: the fine scale's dictionaries do not depend on it
                crng = np.random.default_rng(self.values["seed"] + 1)
                done = len(bodyparts.PARTLETS)
                step = (lambda n, t: progress(done + n, total)) if progress else None
                D, unexplained, _ = self._fit_partlets(data[1], K, crng, step, total)
                self.coarse_ = {"dictionary": D, "unexplained": unexplained, "window": m,
                                "sample_rate": scales[1]}
        self.method_ = self.values["method"]
        self.n_iter_ = iters
        self.training_ = {"frames": int(sum(frames)), "seconds": round(time.perf_counter() - started, 3)}
        return self

    def _fit_partlets(self, data, K, rng, progress, total):
        """Dictionaries of every partlet from its windows → (dictionaries, unexplained
        energy fractions, iterations)."""
        iters = 0
        dictionary, unexplained = {}, {}
        for n, p in enumerate(bodyparts.PARTLETS):
            B = np.concatenate(data[p], axis=1)
            if B.shape[1] > self.values["max_windows"]:
                B = B[:, rng.choice(B.shape[1], self.values["max_windows"], replace=False)]
            B = B.astype(np.float32)   # training in single precision: half the time, same atoms
            if self.values["method"] == "ksvd":
                D, W, iters = pk.train_ksvd(B, K, rng, sparsity=self.values["sparsity"],
                                            iterations=self.values["train_iterations"])
                E = 0.0
            else:
                D, W, E, iters = pk.train_robust(B, K, rng, beta=self.values["beta"],
                                                 lam=self.values["train_lambda"].si,
                                                 iterations=self.values["train_iterations"])
            D = D.astype(np.float64)
            R = B - D @ W - E
            unexplained[p] = float(np.vdot(R, R) / max(np.vdot(B, B), 1e-300))
            dictionary[p] = D
            if progress:
                progress(n + 1, total)
        return dictionary, unexplained, iters

    @staticmethod
    def _model_positions(motion: Motion, joints: list[str]) -> np.ndarray:
        canon = bodyparts.canonical_names(motion.names)
        where = {c: i for i, c in enumerate(canon)}
        idx = np.array([where.get(j, -1) for j in joints])
        P = np.full((motion.n_frames, len(joints), 3), np.nan)
        ok = idx >= 0
        P[:, ok] = motion.positions[:, idx[ok]] * motion.metres_per_unit
        return P

    # -- model files -----------------------------------------------------------------------
    def state(self) -> tuple[dict, dict]:
        if not self.is_fitted:
            raise MocapfixError(f"{self.step}: not fitted")
        header = {
            "state": {"joints": list(self.joints_), "partlets": self.partlets_,
                      "frame_joints": [int(j) for j in self.frame_], "method": self.method_,
                      "sample_rate": self.sample_rate_, "window": self.window_,
                      "unexplained": self.unexplained_, "n_iter": self.n_iter_,
                      "coarse": None if self.coarse_ is None else {
                          k: self.coarse_[k] for k in ("window", "sample_rate", "unexplained")},
                      "normalisation": "torso frame (robust Kabsch to template, smoothed), "
                                       "each joint centred on the file's median"},
        }
        arrays = {f"dictionary_{p}": D for p, D in self.dictionary_.items()}
        if self.coarse_ is not None:
            arrays.update({f"coarse_{p}": D for p, D in self.coarse_["dictionary"].items()})
        arrays["template"] = self.template_
        return header, arrays

    @staticmethod
    def check_state(st, arrays: dict) -> None:
        """A model's state must index its own joints (partlets, frame joints), with a
        positive sample rate, a window of at least one frame, dictionaries that are
        matrices and a template of the frame joints (``FittedCleaner.check_state``)."""
        from mocapfix.core.models import is_int, matrix, positive, window

        if not isinstance(st, dict):
            raise ValueError("no state")
        joints = st.get("joints")
        if not isinstance(joints, list) or not joints or not all(isinstance(j, str) for j in joints):
            raise ValueError("state 'joints' is not a list of joint names")

        def indices(value, what):
            if not isinstance(value, list) or not value or not all(
                    is_int(i) and 0 <= i < len(joints) for i in value):
                raise ValueError(f"{what} is {value!r}, not indices into the {len(joints)} joints")

        partlets = st.get("partlets")
        if not isinstance(partlets, dict) or not partlets:
            raise ValueError("state 'partlets' is not a table of partlets")
        for name, members in partlets.items():
            indices(members, f"partlet {name!r}")
        indices(st.get("frame_joints"), "state 'frame_joints'")
        positive(st, "sample_rate")
        window(st)
        for name in arrays:
            if name.startswith(("dictionary_", "coarse_")):
                matrix(arrays, name)
        template = arrays.get("template")
        if template is None or template.shape != (len(st["frame_joints"]), 3):
            raise ValueError("array 'template' does not match the frame joints")
        coarse = st.get("coarse")
        if coarse:
            if not isinstance(coarse, dict):
                raise ValueError("state 'coarse' is not a table")
            positive(coarse, "sample_rate", "coarse")
            window(coarse, "coarse")

    def load_state(self, header: dict, arrays: dict) -> "PartletDictionary":
        st = header["state"]
        self.joints_ = list(st["joints"])
        self.partlets_ = {p: [int(j) for j in st["partlets"][p]] for p in bodyparts.PARTLETS}
        self.frame_ = np.array(st["frame_joints"], dtype=np.intp)
        self.method_ = st["method"]
        self.sample_rate_ = float(st["sample_rate"])
        self.window_ = int(st["window"])
        self.unexplained_ = dict(st["unexplained"])
        self.n_iter_ = st.get("n_iter")
        self.training_ = header.get("training")
        self.template_ = np.asarray(arrays["template"], dtype=float)
        self.dictionary_ = {}
        for p in bodyparts.PARTLETS:
            D = np.asarray(arrays[f"dictionary_{p}"], dtype=float)
            if D.shape[0] != 3 * len(self.partlets_[p]) * self.window_:
                raise ValueError(f"dictionary {p} has {D.shape[0]} rows for "
                                 f"{len(self.partlets_[p])} joints × window {self.window_}")
            self.dictionary_[p] = D
        self.coarse_ = None
        if st.get("coarse"):   # models before the coarse scale have none
            c = st["coarse"]
            D = {p: np.asarray(arrays[f"coarse_{p}"], dtype=float) for p in bodyparts.PARTLETS}
            for p, Dp in D.items():
                if Dp.shape[0] != 3 * len(self.partlets_[p]) * int(c["window"]):
                    raise ValueError(f"coarse dictionary {p} has {Dp.shape[0]} rows for "
                                     f"{len(self.partlets_[p])} joints × window {c['window']}")
            self.coarse_ = {"dictionary": D, "unexplained": dict(c["unexplained"]),
                            "window": int(c["window"]), "sample_rate": float(c["sample_rate"])}
        if self.template_.shape != (len(self.frame_), 3):
            raise ValueError("template does not match the frame joints")
        return self

    def _shipped_for(self, motion: Motion) -> "PartletDictionary":
        """A cleaner with this one's parameters and the shipped model for ``motion``'s
        skeleton (by its joint names, :data:`AUTO_MODELS`), chosen per file: a batch may
        mix CMU and Kinect skeletons, and ``apply`` never changes the configured cleaner
        (it used to keep the first file's model for the whole run). Model files are read
        once per process (:func:`mocapfix.core.models.load`)."""
        from mocapfix.core import models

        canon = set(bodyparts.canonical_names(motion.names))
        for key, name in AUTO_MODELS:
            if key in canon:
                if name not in models.shipped():
                    break
                header, arrays = models.load(models.shipped()[name], cleaner=self.name,
                                             check=self.check_state)
                return self.with_state(header, arrays)
        raise ConfigError(
            f"{motion.path or 'motion'}: {self.step}: no partlet model for this skeleton (joints "
            f"{', '.join(motion.names[:6])}…); train one with `mocapfix train-dictionary` and name it "
            f"with `model:` in the config")

    # -- apply -------------------------------------------------------------------------------
    def _apply(self, motion: Motion):
        if not self.is_fitted:
            return self._shipped_for(motion)._apply(motion)
        idx = self._map_joints(motion.names)
        if (idx[self.frame_] < 0).sum() > len(self.frame_) - 3:
            raise ConfigError(f"{motion.path or 'motion'}: {self.step}: the model's torso joints are "
                              "not in this file; train a model for this skeleton")
        T = motion.n_frames
        coding = self.values["coding"] if self.values["coding"] != "auto" else (
            "ksvd" if self.method_ == "ksvd" else "robust")
        dil = self._dilation(motion.fps, self.sample_rate_)
        m = self.window_
        starts = pk.starts(T, m, dil, self.values["stride"])
        info = {"model_joints": int((idx >= 0).sum()), "coding": coding, "dilation": dil}
        rate = motion.fps / dil
        if not 0.75 <= rate / self.sample_rate_ <= 1.34:
            info["warning"] = (f"the model's windows are sampled at {self.sample_rate_:g} Hz, this file's "
                               f"at {rate:g} Hz: its windows span another time; train a model at this rate")
        if not len(starts):
            info["skipped"] = f"{T} frames are fewer than one window ({dil * (m - 1) + 1})"
            return motion.copy(), info
        P = np.full((T, len(self.joints_), 3), np.nan)
        ok = idx >= 0
        P[:, ok] = motion.positions[:, idx[ok]] * motion.metres_per_unit
        suspect = np.zeros(P.shape[:2], dtype=bool)
        if self.values["despike"] > 0:
            suspect = pk.suspect_samples(P, self.values["despike"], self.values["min_outlier"].si)
        try:
            local, R, c, centre, valid = self._normalise(np.where(suspect[..., None], np.nan, P), motion.fps)
        except ValueError as exc:
            info["skipped"] = str(exc)
            return motion.copy(), info
        centre = np.where(np.isnan(centre), 0.0, centre)
        if suspect.any():
            local = to_frame(P, R, c)
        X = local - centre
        info["suspect"] = int(suspect.sum())
        raw_sigma = pk.noise_level(np.where(suspect[..., None], np.nan, P).reshape(T, -1))
        sigma = pk.noise_level(X[:, self.frame_].reshape(T, -1))
        dictionary = self.dictionary_
        limit = self.values["coarse_noise"].si
        if self.coarse_ is not None and limit > 0 and sigma > limit and coding == "robust":
            # heavy noise: windows as long in samples at the coarse rate (16 at 30 Hz: 0.5 s
            # instead of 0.13 s) constrain the low frequencies the short windows let through.
            # Not for OMP codes: 6 atoms per 0.5 s window are too few (K-SVD model, 10 dB,
            # 2 seeds: ℓ2 6.23 → 6.49, ℓ1 5.18 → 6.04 cm)
            cdil = self._dilation(motion.fps, self.coarse_["sample_rate"])
            cstarts = pk.starts(T, self.coarse_["window"], cdil, self.values["stride"])
            if len(cstarts):
                dictionary, m, dil, starts = self.coarse_["dictionary"], self.coarse_["window"], cdil, cstarts
                info.update({"scale": "coarse", "dilation": dil})
        total = np.zeros_like(X)
        count = np.zeros(X.shape[:2])
        unexplained, iters = {}, 0
        v = self.values
        coding_settings = pk.Coding(
            presmooth=v["presmooth"], local_smoothing=v["local_smoothing"].si, lambda1=v["lambda1"],
            lambda2=v["lambda2"], lambda3=v["lambda3"], p=v["p"], min_outlier=v["min_outlier"].si,
            ridge=v["ridge"], iterations=v["iterations"], fill_iterations=v["fill_iterations"],
            fista_iterations=v["fista_iterations"], neighbours=v["neighbours"], loss=v["loss"],
            sparsity=v["sparsity"], detail=v["detail"])
        for p in bodyparts.PARTLETS:
            joints = self.partlets_[p]
            Xp = X[:, joints]
            if np.isnan(Xp).all():
                continue
            rec, frac, it = pk.code_partlet(Xp, dictionary[p], starts, m, dil, sigma, coding, motion.fps,
                                               suspect[:, joints], coding_settings)
            total[:, joints] += rec
            count[:, joints] += 1
            unexplained[p] = round(frac, 5)
            iters = max(iters, it)
        cleaned_local = total / np.maximum(count, 1)[..., None] + centre
        out = from_frame(cleaned_local, R, c) / motion.metres_per_unit
        pos = motion.positions.copy()
        file_j, model_j = self._written_joints(motion.names)
        pos[:, file_j] = out[:, model_j]
        if self.values["bones"] and motion.skeleton is not None:
            seen = np.where(suspect[..., None], np.nan, P)
            to_model = dict(zip(file_j.tolist(), model_j.tolist()))
            bones = np.array([(a, b) for a, b in motion.skeleton.bone_array.tolist()
                              if a in to_model and b in to_model], dtype=np.intp).reshape(-1, 2)
            ends = np.vectorize(to_model.get, otypes=[np.intp])(bones) if len(bones) else bones
            rigid = pk.rigid_bones(seen[:, ends[:, 0]], seen[:, ends[:, 1]], raw_sigma)
            pos, info["bones"] = pk.project_bones(pos, bones[rigid])
        info["unmodelled_joints"] = [n for i, n in enumerate(motion.names) if i not in set(file_j)]
        info.update({"noise_mm": round(sigma * 1e3, 3), "iterations": iters,
                     "unexplained": unexplained,
                     "frames_without_torso": int((~valid).sum())})
        # limbs only: in the torso frame the torso itself barely moves, so what its dictionary
        # leaves is mostly the noise left after smoothing, not novelty
        high = [p for p, f in unexplained.items() if p != "torso" and f > self.values["out_of_sample"]]
        if high:
            info["warning"] = (info.get("warning", "") + "; " if "warning" in info else "") + ("motion unlike the training set (out of sample) for "
                               + ", ".join(high) + ": the dictionary explains little of it")
        return motion.replace(positions=pos), info

