"""Train the models shipped in ``mocapfix/data/models`` from the CMU corpus in
``../shared/training/cmu-asfamc`` (47 motions; CMU terms allow shipping models trained on
them). Anyone can re-run it::

    python scripts/train_models.py [--training DIR] [--out DIR]

- ``partlet-cmu.npz``: partlet dictionaries (Feng 2015) on the 31 CMU ASF joints, windows of
  16 frames at 120 Hz, and a coarse scale of 16 samples at 30 Hz for heavy noise; used by
  ``partlet_dictionary`` with no ``model`` on CMU ASF/AMC and CMU BVH skeletons.
- ``partlet-kinect.npz``: the same method on Kinect v2 joints made from the CMU joints
  (:data:`mocapfix.core.bodyparts.ASF_TO_KINECT_V2`), for Kinect v1/v2/Azure skeletons.
- ``mssa-cmu.npz``: M-SSA filter bases (Lou 2012) on the rotation channels of the CMU ASF
  skeleton at 120 Hz; used by ``mssa`` with no ``model`` on files with that channel layout.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from mocapfix.core import bodyparts, models
from mocapfix.core.motion import Motion
from mocapfix.train import METHODS, discover_training, read_all
from mocapfix.cleaners import build

REPO = Path(__file__).resolve().parents[1]


def as_kinect(motion: Motion) -> Motion:
    """CMU ASF joint positions → Kinect v2 joints (averages of bone ends)."""
    index = {n: i for i, n in enumerate(motion.names)}
    pos = np.stack([motion.positions[:, [index[b] for b in bones]].mean(axis=1)
                    for bones in bodyparts.ASF_TO_KINECT_V2.values()], axis=1)
    return Motion(pos, list(bodyparts.KINECT_V2_NAMES), motion.fps, units=motion.units,
                  metres_per_unit=motion.metres_per_unit, format="kinect", path=motion.path)


def fit_and_save(motions, paths, out: Path, method: str = "partlet", **params):
    started = time.perf_counter()
    cleaner = build(METHODS[method][0], **{**METHODS[method][1], **params})
    cleaner.fit(motions)
    header, arrays = cleaner.state()
    header.update(cleaner.model_header_fields())
    header["training"] = models.provenance(paths, [m.n_frames for m in motions],
                                           time.perf_counter() - started)
    models.save(out, header, arrays)
    unexplained = header["state"]["unexplained"]
    if not isinstance(unexplained, dict):
        unexplained = {"all": unexplained}
    print(f"{out}: {time.perf_counter() - started:.1f} s, unexplained "
          + ", ".join(f"{p} {100 * f:.3f} %" for p, f in unexplained.items()))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--training", default=str(REPO.parent / "shared" / "training" / "cmu-asfamc"))
    ap.add_argument("--out", default=str(REPO / "mocapfix" / "data" / "models"))
    args = ap.parse_args()
    paths = discover_training([args.training])
    motions = read_all(paths, jobs=2)
    out = Path(args.out)
    fit_and_save(motions, paths, out / "partlet-cmu.npz")
    # Kinect skeletons come at 30 Hz: windows of 8 samples at 30 Hz (0.27 s)
    fit_and_save([as_kinect(m) for m in motions], paths, out / "partlet-kinect.npz",
                 sample_rate="30 Hz", window=8)
    fit_and_save(motions, paths, out / "mssa-cmu.npz", method="mssa")


if __name__ == "__main__":
    main()
