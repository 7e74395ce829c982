"""``fill_pca``: inter-marker gap filling by iterative PCA in a body frame (Gloersen &
Federolf 2016, PLoS ONE 11(3): e0152616); the method and what we changed are described
in :mod:`mocapfix.solvers.pca_gapfill`."""
from __future__ import annotations

from mocapfix.cleaners import register
from mocapfix.cleaners.base import NOT_ESTIMATED, Cleaner, FillGate, Param
from mocapfix.solvers.pca_gapfill import ALIGNS, fill_gaps_pca


@register
class PCAFill(Cleaner):
    name = "fill_pca"
    single_thread_blas = True
    #: under the pipeline's ``max_fill_error`` it fills nothing: it gives no estimate of
    #: its fills' error, so none could be written (and it would cost its fits for nothing)
    gated = True
    summary = ("fill gaps from the other markers by iterative PCA in a body frame "
               "(Gloersen & Federolf 2016)")
    params = (
        Param("variance", "float", 0.99, "fraction of the pose variance the components keep",
              low=0.5, high=1.0),
        Param("rank", "int", None, "fixed number of components (overrides variance)",
              low=1, nullable=True),
        Param("weight_scale", "length", "300 mm",
              "distance scale of the per-marker refinement weights (null: global PCA only)",
              unit="mm", low=0.0, low_open=True, nullable=True),
        Param("max_iter", "int", 300, "cap on the model fits of the imputation loop (SQUAREM-accelerated)", low=1, high=10000),
        Param("tol", "length", "0.05 mm", "stop when no filled sample moves more than this",
              unit="mm", low=0.0),
        Param("max_gap", "time", None, "longest gap filled (null: all)", unit="s",
              low=0.0, nullable=True),
        Param("fill_ends", "bool", False, "also fill leading/trailing gaps of a marker"),
        Param("min_observed", "float", 0.5,
              "frames with fewer than this fraction of the markers are left alone",
              low=0.0, high=1.0),
        Param("align", "choice", "rigid", "moving reference removed before PCA",
              choices=ALIGNS),
    )

    def _apply(self, motion, gate: FillGate | None = None):
        if gate is not None:
            return motion.copy(), {"skipped_fills": NOT_ESTIMATED}
        max_gap = None if self["max_gap"] is None else self.frames("max_gap", motion)
        scale = self.values["weight_scale"]
        out, info = fill_gaps_pca(
            motion.positions, metres_per_unit=motion.metres_per_unit,
            variance=self["variance"], rank=self["rank"],
            weight_scale=None if scale is None else scale.si, max_iter=self["max_iter"],
            tol=self.values["tol"].si, max_gap=max_gap, fill_ends=self["fill_ends"],
            min_observed=self["min_observed"], align=self["align"])
        return motion.replace(positions=out), info
