"""``pma``: gap filling by model averaging with soft distance constraints, after Tits et
al. 2018 (PLoS ONE 13(7): e0199744); the kernels and the method are described in
:mod:`mocapfix.solvers.pma`. Written from the paper's description as a baseline for the
versus-peers benchmark (``benchmarks/versus_peers.py``) and usable as a cleaner.

The members are the four local/global fillers of :mod:`mocapfix.solvers.pma` and the
Gløersen weighted PCA (``fill_pca``, run once on the whole capture); ``members`` can add
``tsmc`` (the default C3D filler) or drop any of them. Observed samples are never changed.
A gap whose fill leaves the capture volume (the box of every observed sample grown by 10 %
of its size per side, as in ``fill_pca``) is left missing and counted in
``rejected_samples``.
Every filled sample gets a confidence in ``Motion.confidence`` (observed samples keep
theirs): ``exp(-spread / confidence_scale) · exp(-d / confidence_horizon) · m / M``, with
``spread`` the weighted RMS distance of the members from their average, ``d`` the time to
the nearest observed sample of the marker, and ``m`` of the ``M`` configured members able
to fill the gap (the local ones need the marker seen with its neighbours for a while).
A marker rebuilt across long stretches, or from few members, gets a low confidence.

Every fill also gets an estimated error and a calibrated 90 % bound
(:mod:`mocapfix.solvers.fill_error`): the combined fill — the same weighted average, soft
constraint and jump screen — is made on each of the gap's validation windows with the
members weighted on the gap's other windows, and its error there measured; the short
gaps' cubic Hermite curves are measured on windows of their own. A gap longer than any
window of its marker is measured on the longest and its error extrapolated
(:func:`mocapfix.solvers.fill_error.extrapolated_bounds`). Under the pipeline's
``max_fill_error`` (:class:`mocapfix.cleaners.base.FillGate`) a gap whose bound exceeds
it is left missing (``rejected_fills``, with its estimate and bound), a gap with no
window is not fitted at all, and neither is refilled nor lent to the refill rounds;
``pma`` (plausibility weights) validates its members only under the gate, to estimate.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from mocapfix.cleaners import build, register
from mocapfix.cleaners.base import FILL_ERRORS, REJECTED_FILLS, Cleaner, FillGate, Param
from mocapfix.core.errors import ConfigError
from mocapfix.core import forked
from mocapfix.core.motion import Motion, missing_samples
from mocapfix.solvers import fill_error, pma
from mocapfix.solvers.nanstats import mean_of
from mocapfix.solvers.pca_gapfill import fill_gaps_pca
from mocapfix.solvers.segments import largest_steps

_EXTERNAL = ("pca", "tsmc")
#: shortest gap (s) the refill rounds fill again: shorter ones changed by at most 0.04 mm
#: on the shared files (107 of ktk_racing_full's 228 gaps, for +1.3 s) and not at all on
#: benchmarks/versus_peers.py
REFILL_MIN_S = 0.2
#: validation copies of the refilled members (one: c3d.org s01 and the PhoeniX dance, six
#: seeds, gap RMSE within 1 % of two; with the later rounds' skipping of unchanged
#: markers and the first pass's reference shapes, numediart_03_rolling's fill 19.6 →
#: 16.3 s, against 7.4 s without the refill)
REFILL_COPIES = 1
#: frames × markers² from which the distance statistics are made in a child process beside
#: the short gaps' fills (:func:`mocapfix.core.forked.both`): ~7 ms of them, the fork ~3
DISTANCES_APART = 2_000_000


@register
class PMA(Cleaner):
    name = "pma"
    single_thread_blas = True
    gated = True
    summary = ("fill gaps by a plausibility-weighted average of five fillers with soft "
               "distance constraints (Tits et al. 2018 'PMA')")
    params = (
        Param("members", "list", ["interp", "poly", "grnn", "linear", "pca"],
              "fillers averaged: interp, poly, grnn, linear, pose, pca, tsmc"),
        Param("neighbours", "list", [3], "rigid neighbours of the local fillers: one or more "
              "counts (each count gives its own set of local members)"),
        Param("constraint_neighbours", "int", 3, "most rigid neighbours of the soft "
              "distance constraint (0: no constraint)", low=0, high=10),
        Param("width", "float", 2.0, "the constraint keeps each distance within mean ± "
              "width × standard deviation", low=0.0, low_open=True),
        Param("weight_scale", "length", "300 mm", "distance scale of the global regression's "
              "marker weights", unit="mm", low=0.0, low_open=True),
        Param("sd_floor", "length", "1 mm", "smallest distance deviation in the plausibility "
              "weights", unit="mm", low=0.0, low_open=True),
        Param("max_gap", "time", None, "longest gap filled (null: all)", unit="s", low=0.0,
              nullable=True),
        Param("fill_ends", "bool", True, "also fill leading/trailing gaps"),
        Param("short_gap", "time", None, "interior gaps up to this long are filled first by "
              "a cubic Hermite curve (spike holes, dropouts) and count as seen for the rest "
              "(null: every gap goes through the members)", unit="s", low=0.0, nullable=True),
        Param("weights", "choice", "plausibility", "how members are weighted per gap: "
              "'plausibility' (Tits 2018: how well the fill keeps its neighbour distances), "
              "'validation' (inverse squared error of each member on gaps of the same length "
              "cut where the marker was seen) or 'best' (the member with the lowest such error)",
              choices=("plausibility", "validation", "best")),
        Param("refill", "int", 0, "weights: validation/best — rounds that fill again, with "
              "the other markers' interior fills counted as seen, each interior gap of 0.2 s "
              "or more during which one of its marker's most rigid neighbours is missing "
              "too; those fills join the members (0: none)", low=0, high=5),
        Param("max_step", "float", 0.0, "a gap whose fill (joined to the data at its borders) "
              "moves further from one frame to the next than this many times the marker's "
              "largest observed step is averaged again without the members that do, if some "
              "do not (0: never)", low=0.0, high=1e6),
        Param("validation_copies", "int", 2, "weights: validation/best — synthetic gaps per "
              "real gap", low=1, high=20),
        Param("confidence_scale", "length", "10 mm", "member spread at which a filled "
              "sample's confidence falls by 1/e", unit="mm", low=0.0, low_open=True),
        Param("confidence_horizon", "time", "1 s", "time from the nearest observed sample "
              "at which a filled sample's confidence falls by 1/e", unit="s", low=0.0,
              low_open=True),
    )

    def _validate(self):
        ks = self["neighbours"]
        if not ks or not all(isinstance(k, int) and not isinstance(k, bool) and 1 <= k <= 20
                             for k in ks):
            raise ConfigError(f"{self.step}: parameter 'neighbours' must list counts from 1 to "
                              f"20, got {ks!r}")
        bad = [m for m in self["members"] if m not in pma.LOCAL_FILLERS + _EXTERNAL]
        if bad or not self["members"]:
            raise ConfigError(f"{self.step}: parameter 'members' must list some of "
                              f"{', '.join(pma.LOCAL_FILLERS + _EXTERNAL)}, got {self['members']!r}")

    def _external(self, motion: Motion) -> dict[str, np.ndarray]:
        out = {}
        if "pca" in self["members"]:
            out["pca"] = fill_gaps_pca(motion.positions, metres_per_unit=motion.metres_per_unit,
                                       fill_ends=True, min_observed=0.0)[0]
        if "tsmc" in self["members"]:
            out["tsmc"] = build("tsmc", observed="keep").apply(motion)[0].positions
        return out

    def _apply(self, motion: Motion, gate: FillGate | None = None):
        pos = motion.positions
        T, J, _ = pos.shape
        observed = ~motion.missing
        info = {"gaps": 0, "gaps_filled": 0, "filled": 0, "weights_mean": {}}
        if T < 3 or observed.all() or observed.sum(axis=0).max(initial=0) < 2:
            return motion.copy(), info
        local = tuple(m for m in self["members"] if m in pma.LOCAL_FILLERS)
        max_gap = None if self["max_gap"] is None else self.frames("max_gap", motion)
        out = pos.copy()
        conf = np.ones((T, J)) if motion.confidence is None else motion.confidence.copy()
        conf[~observed] = 0.0
        weight_sum: dict[str, float] = {}
        # a gap an earlier step left as too uncertain to fill stays missing (FillGate)
        gaps = [g for g in pma.gap_list(observed, max_gap, self["fill_ends"])
                if gate is None or not gate.left(*g)]
        info["gaps"] = len(gaps)
        horizon = self.frames("confidence_horizon", motion)
        trust = fill_error.FillTrust(motion, gate)
        if self["short_gap"] is not None and self.frames("short_gap", motion) >= 1:
            # the distance statistics (large array operations, ~27 ms on 4,500 × 41) in a
            # child beside the short gaps' fills and validation here (small operations
            # holding the GIL, ~75 ms): mocapfix.core.forked
            (mu, sd), gaps = forked.both(
                lambda: pma.distance_stats(pos, observed),
                lambda: self._fill_short(out, conf, gaps, self.frames("short_gap", motion),
                                         horizon, trust),
                fork=T * J * J >= DISTANCES_APART)
            info["gaps_filled"] = info["gaps"] - len(gaps)
            seen = ~missing_samples(out)
            info["filled"] = int((seen & ~observed).sum())
            # a short gap left as too uncertain is no gap for the members to fill
            gaps = [g for g in gaps if not trust.refused(g)]
            pos, observed = out.copy(), seen
        else:
            mu, sd = pma.distance_stats(pos, observed)
        work = motion if pos is motion.positions else motion.replace(positions=pos)
        external = self._external(work)
        seen_points = motion.positions[~motion.missing]
        lo, hi = seen_points.min(axis=0), seen_points.max(axis=0)
        box = (lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo))
        floor = self.length("sd_floor", motion)
        ctx = pma.Combination(mu, sd, floor, box, largest_steps(pos, observed),
                              self["weights"], self["constraint_neighbours"], self["width"],
                              self["max_step"])
        # windows are needed to weight the members (weights: validation/best) or, under the
        # gate, to estimate the fills' error (weights: plausibility weights them as before)
        validate = self["weights"] != "plausibility" or gate is not None
        windows: list = [[] for _ in gaps]
        if not validate:
            members = pma.member_fills(pos, observed, gaps, external, local=local,
                                       neighbours=self["neighbours"], mu=mu, sd=sd,
                                       weight_scale=self.length("weight_scale", motion))
            validated = [{}] * len(gaps)
        else:
            # the rigid frames' reference shapes, by marker and neighbours: the first pass
            # makes them, the refill rounds reuse them (a reference only fixes a frame's
            # orientation)
            references: dict = {}
            # each gap's combined fill and the combination's errors on its windows are
            # made where its members were fitted (a forked child's with its fits)
            members, validated, windows, plan, finished = self._validated_fills(
                work, observed, gaps, external, local, mu, sd, references=references,
                skip_unsupported=not external, skip_unvalidated=gate is not None,
                with_windows=True,
                finish=lambda which, rows, cut_of: self._finish(pos, gaps, which, rows,
                                                                cut_of, ctx))
        if self["weights"] == "plausibility":
            validated = [{}] * len(gaps)
        expected = len(pma.member_names(local, self["neighbours"])) + len(external)
        if validate:
            combined = [result for result, _, _ in finished]
            # (gaps, copies) errors of the combination on the windows; NaN where a copy has
            # no window for the gap or the window's fill left the capture volume
            cross = np.full((len(gaps), max(len(plan.windows), 1)), np.nan)
            fitted = cross.copy()
            for g, (_, on_windows, on_all) in enumerate(finished):
                for errors, into in ((on_windows, cross), (on_all, fitted)):
                    for c, e in errors.items():
                        into[g, c] = e
            trust.estimate(gaps, plan, cross, "the members", fitted=fitted)
        else:
            combined = [pma.combine(pos, gap, cand, fills, verr, ctx)
                        for gap, (cand, fills), verr in zip(gaps, members, validated)]
        if self["refill"] > 0 and self["weights"] != "plausibility":
            combined = self._refill(work, observed, gaps, local, ctx, members, validated,
                                    combined, info, references, trust)
        info["rejected_samples"] = 0
        info[REJECTED_FILLS] = trust.rejected
        for (j, s, e), result, (cand, _), tested in zip(gaps, combined, members, windows):
            n = e - s
            if result is None:
                # under the gate a gap with no window was not fitted (no members, no
                # candidates listed): it is left as too uncertain, unless no other marker
                # is seen through it either
                if gate is not None and not tested and (
                        len(cand) or len(pma.candidates(observed, sd, j, s, e))):
                    trust.refuse((j, s, e))
                elif not len(cand):
                    info[REJECTED_FILLS].setdefault(motion.names[j], []).append(
                        [int(s), int(n), "no other marker is seen through it"])
                continue
            avg, spread, names, w = result
            if avg is None:
                # outside the capture volume: the members do not know this marker; leave
                # the gap for the next step and the report (as fill_pca and tsmc do)
                info["rejected_samples"] += int(n)
                info[REJECTED_FILLS].setdefault(motion.names[j], []).append(
                    [int(s), int(n), "its fill left the capture volume"])
                continue
            if not trust.allows((j, s, e)):
                continue
            out[s:e, j] = avg
            # confidence: the members' agreement, the distance to the nearest observed
            # sample, and the share of the members that could fill this gap
            t = np.arange(s, e)
            dist = np.minimum(t - s + 1 if s > 0 else np.full(n, np.inf),
                              e - t if e < T else np.full(n, np.inf))
            conf[s:e, j] = (np.exp(-spread / self.length("confidence_scale", motion))
                            * np.exp(-dist / horizon) * min(1.0, len(names) / expected))
            info["gaps_filled"] += 1
            info["filled"] += int(n)
            for name, wk in zip(names, w):
                weight_sum[name] = weight_sum.get(name, 0.0) + float(wk)
        if info["gaps_filled"]:
            averaged = max(sum(weight_sum.values()), 1e-12)     # one unit per averaged gap
            info["weights_mean"] = {k: round(v / averaged, 3) for k, v in weight_sum.items()}
        info.update({FILL_ERRORS: trust.written, "fill_error_factors": trust.factors,
                     "fill_error_slopes": trust.slopes})
        if gate is not None:
            info["gaps_too_uncertain"] = trust.count
        return motion.replace(positions=out, confidence=conf), info

    def _finish(self, pos, gaps, which, rows, cut_of, ctx):
        """Per gap of ``which`` (its row of :func:`mocapfix.solvers.pma.validated_member_fills`):
        ``(result, cross, fitted)``, its combined fill (:func:`mocapfix.solvers.pma.combine`:
        the weighted average, the soft constraint, the jump screen) and two errors of the
        combination on each of its validation windows, copy → RMS error: ``cross``, its
        members weighted by their errors on the gap's *other* windows (cross-fitted: the
        weights are not chosen on the window they are judged on — a window's test error,
        as the real gap's fill is judged on a gap its weights were not chosen on; a gap
        with one window uses that window's), and ``fitted``, weighted by their errors on
        all its windows, as the real gap's fill is (the errors its estimate is made of).
        No entry where the window's fill leaves the capture volume. ``cut_of(copy)``: the
        positions of a validation copy (its windows missing). Every gap's are its own:
        they are made where its members were fitted; the members' fills of its windows
        are then dropped from its row (kept: where they were and their errors)."""
        plausibility = self["weights"] == "plausibility"

        def mean_errors(fills, chosen):
            return {} if plausibility else {
                k: mean_of([o[k] for o in chosen if k in o])
                for k in fills if any(k in o for o in chosen)}

        out = []
        for g, (cand, fills, verr, ws) in zip(which, rows):
            j = gaps[g][0]
            result = pma.combine(pos, gaps[g], cand, fills, {} if plausibility else verr, ctx)
            cross: dict = {}
            fitted: dict = {}
            for c, u, v, wcand, wfills, _ in ws:
                if not wfills:
                    continue
                others = [w[5] for w in ws if w[0] != c] or [w[5] for w in ws if w[0] == c]
                for errors, chosen in ((cross, others), (fitted, [w[5] for w in ws])):
                    window = pma.combine(cut_of(c), (j, u, v), wcand, wfills,
                                         mean_errors(wfills, chosen), ctx)
                    if window is not None and window[0] is not None:
                        errors[c] = fill_error.rms_error(window[0], pos[u:v, j])
            out.append((result, cross, fitted))
            # the windows' fills have served: not sent back from a child
            ws[:] = [(c, u, v, wcand, {}, werr) for c, u, v, wcand, _, werr in ws]
        return out

    def _refill(self, motion, observed, gaps, local, ctx, members, validated, combined, info,
                references, trust):
        """The refill rounds (``refill``): an interior gap of at least
        :data:`REFILL_MIN_S` during which one of its marker's most rigid neighbours (as
        many as the largest ``neighbours`` count) is missing too, and that neighbour's
        interior gap was filled, is filled again with the other markers' current interior
        fills (validation-weighted, before the soft constraint) counted as seen. The new
        fills join the gap's members (named ``<member>+``) with their validation errors of
        the first round. The marker's own gaps stay missing in its refills; edge gaps are
        neither refilled nor lent; a later round skips the markers none of whose refilled
        gaps lies by a gap refilled in the round before. ``refilled_gaps`` in the info
        counts the gaps chosen for the rounds. Returns the gaps' combined fills
        (:func:`mocapfix.solvers.pma.combine`); why each choice: docs/methods/pma.md."""
        mu, sd = ctx.mu, ctx.sd
        pos = motion.positions
        T = pos.shape[0]
        K = max(self["neighbours"])
        ranked = np.argsort(np.where(np.isfinite(sd), sd, np.inf), axis=1, kind="stable")
        members, validated = list(members), list(validated)

        def current_fills():
            """The capture with every interior gap the ensemble filled taken as seen."""
            filled = pos.copy()
            for (j, s, e), (_, fills), verr, done in zip(gaps, members, validated, combined):
                if (0 < s and e < T and done is not None and done[0] is not None
                        and trust.trusted((j, s, e))):
                    filled[s:e, j] = pma.average(pos, (j, s, e), fills, verr, ctx)
            return filled

        filled = current_fills()
        redo: dict[int, list[int]] = {}
        for g, (j, s, e) in enumerate(gaps):
            if s == 0 or e == T or e - s < REFILL_MIN_S * motion.fps or not trust.trusted(gaps[g]):
                continue
            best = np.array([k for k in ranked[j] if k != j and np.isfinite(sd[j, k])][:K],
                            dtype=np.intp)
            window = slice(s - 1, e + 1)
            lost = best[~observed[window][:, best].all(axis=0)]
            if len(lost) and (~np.isnan(filled[window][:, lost]).any(axis=(0, 2))).any():
                redo.setdefault(j, []).append(g)
        info["refilled_gaps"] = sum(map(len, redo.values()))

        def near(g, h):
            """Gap ``h`` overlaps gap ``g`` or its border frames."""
            return gaps[h][1] <= gaps[g][2] and gaps[h][2] >= gaps[g][1]

        changed = set(redo)
        for round_ in range(self["refill"] if redo else 0):
            if round_:
                filled = current_fills()
                # a marker none of whose refilled gaps lies by a gap refilled last round
                # would get nearly the same neighbours again: it keeps its fills
                todo = {j: group for j, group in redo.items()
                        if any(near(g, h) for k in changed - {j} for h in redo[k] for g in group)}
            else:
                todo = redo
            for j, group in todo.items():
                second = filled.copy()
                for jj, s, e in gaps:
                    if jj == j:
                        second[s:e, j] = np.nan
                seen = ~missing_samples(second)
                redone = [gaps[g] for g in group]
                if round_ == 0:
                    again, errors = self._validated_fills(motion.replace(positions=second), seen,
                                                          redone, {}, local, mu, sd,
                                                          copies=REFILL_COPIES,
                                                          references=references)
                else:
                    again = pma.member_fills(second, seen, redone, {}, local=local,
                                             neighbours=self["neighbours"], mu=mu, sd=sd,
                                             weight_scale=self.length("weight_scale", motion),
                                             references=references)
                    errors = [{k[:-1]: v for k, v in validated[g].items() if k.endswith("+")}
                              for g in group]
                for g, (_, fills2), err2 in zip(group, again, errors):
                    cand, fills = members[g]
                    members[g] = (cand, {**fills, **{k + "+": v for k, v in fills2.items()}})
                    validated[g] = {**validated[g], **{k + "+": v for k, v in err2.items()}}
            changed = set(todo)
        for g in (g for group in redo.values() for g in group):
            cand, fills = members[g]
            combined[g] = pma.combine(pos, gaps[g], cand, fills, validated[g], ctx)
        return combined

    def _fill_short(self, out, conf, gaps, short, horizon, trust):
        """Fill (in place) the interior gaps of at most ``short`` frames by cubic Hermite
        curves (:func:`mocapfix.solvers.pma.hermite_short_gaps`), each with its error on
        validation windows of its length and a bound calibrated on them (``trust``: under
        a gate, only those it trusts are filled); returns the gaps not filled."""
        T = out.shape[0]
        observed = ~missing_samples(out)
        small = [g for g in gaps if g[2] - g[1] <= short and 0 < g[1] and g[2] < T]

        def hermite(cut_positions, spans):
            pma.hermite_short_gaps(cut_positions, ~missing_samples(cut_positions), spans)
            return cut_positions

        plan = fill_error.window_plan(observed, small, self["validation_copies"])
        trust.estimate(small, plan, fill_error.window_fill_errors(out, small, plan.windows,
                                                                  hermite), "cubic Hermite")
        done = pma.hermite_short_gaps(out, observed, [g for g in small if trust.allows(g)])
        if done:
            g = np.array(done, dtype=np.intp)
            n = g[:, 2] - g[:, 1]
            gi = np.repeat(np.arange(len(g)), n)
            t = g[gi, 1] + np.arange(len(gi)) - np.repeat(np.cumsum(n) - n, n)
            conf[t, g[gi, 0]] = np.exp(-np.minimum(t - g[gi, 1] + 1, g[gi, 2] - t) / horizon)
        done = set(done)
        return [g for g in gaps if g not in done]

    def _validation_windows(self, observed, gaps, copies=None, probes=False):
        """The synthetic gaps that validate the members, ``copies`` (default
        ``validation_copies``) of them per gap, with ``probes`` for the extrapolated
        estimates (:func:`mocapfix.solvers.fill_error.window_plan`)."""
        return fill_error.window_plan(observed, gaps, copies or self["validation_copies"],
                                      probes=probes)

    def _validated_fills(self, motion, observed, gaps, external, local, mu, sd, copies=None,
                         references=None, skip_unsupported=False, skip_unvalidated=False,
                         with_windows=False, finish=None):
        """Every member's fill of every gap and, per gap, member name → mean squared error
        on the gap's validation windows (:meth:`_validation_windows`;
        :func:`mocapfix.solvers.pma.validated_member_fills`); the external members are
        rerun on each copy with its windows cut. ``skip_unsupported``: a gap through which
        no other marker is seen (no local member can fill it: a whole-body dropout, the
        empty frames at the end of an export) gets no members, and its validation windows
        are cut but not filled — the members fitted for them were thrown away
        (btk_mocap36_optitrack, whose 36 gaps are its last 229 frames with no marker at
        all: 4.9 → 0.05 s, measured on the whole file; the pipeline now runs steps on the
        take, so in a clean this is the case of a whole-body dropout inside it); the other
        gaps' windows and fills stay as they were. ``skip_unvalidated``: likewise a gap
        that gets no validation window (its marker is never seen as long as a sixth of
        the gap: :func:`mocapfix.solvers.fill_error.window_plan`): under a
        :class:`FillGate` its fill has no estimate and would not be written.
        ``with_windows``: also return, per gap, its windows with the members' fills there
        (:func:`mocapfix.solvers.pma.validated_member_fills`), and the windows' plan (with
        the probes of the extrapolated estimates). ``finish(indices, rows, cut_of)``: run
        on each group of gaps where it was fitted (its ``finish``), ``cut_of(copy)`` the
        positions of a validation copy; also returns its results, one per gap."""
        pos = motion.positions
        plan = self._validation_windows(observed, gaps, copies, probes=with_windows)
        windows = plan.windows
        keep = np.ones(len(gaps), bool)
        if skip_unsupported:
            keep = np.array([len(pma.candidates(observed, sd, *g)) > 0 for g in gaps], bool)
        if skip_unvalidated:
            tested = np.zeros(len(gaps), bool)
            for _, synth in windows:
                tested[[g for g, _, _ in synth]] = True
            keep &= tested
        if not keep.all():
            index = np.cumsum(keep) - 1             # a kept gap's place among the kept
            windows = [(cut, [(int(index[g]), u, v) for g, u, v in synth if keep[g]])
                       for cut, synth in windows]

        def copy_external(cut):
            return self._external(motion.replace(positions=np.where(cut[..., None], pos, np.nan),
                                                 confidence=None))

        kept = np.flatnonzero(keep)
        cuts: dict = {}             # per process: a child makes its own

        def cut_of(c):
            if c not in cuts:
                cuts[c] = cut = pos.copy()
                for g, u, v in windows[c][1]:
                    cut[u:v, gaps[kept[g]][0]] = np.nan
            return cuts[c]

        found = pma.validated_member_fills(
            pos, observed, [gaps[g] for g in kept], windows, external, local=local,
            neighbours=self["neighbours"], mu=mu, sd=sd,
            weight_scale=self.length("weight_scale", motion),
            copy_external=copy_external if external else None, references=references,
            finish=None if finish is None else
            (lambda which, rows: finish([int(kept[w]) for w in which], rows, cut_of)))
        found, finished = found if finish else (found, None)
        rows, done = [None] * len(gaps), [None] * len(gaps)
        for k, g in enumerate(kept):
            rows[g] = found[k]
            done[g] = finished[k] if finish else None
        for g in np.flatnonzero(~keep):
            rows[g] = (np.array([], dtype=np.intp), {}, {}, [])
            if finish:
                done[g] = finish([int(g)], [rows[g]], cut_of)[0]
        out = [(cand, fills) for cand, fills, _, _ in rows], [errs for _, _, errs, _ in rows]
        out = (*out, [w for *_, w in rows], plan) if with_windows else out
        return (*out, done) if finish else out


def _defaults(params, **new):
    return tuple(dataclasses.replace(p, default=new[p.name]) if p.name in new else p
                 for p in params)


@register
class FillEnsemble(PMA):
    """The PMA engine with what measurably beats the paper's choices: the three local
    fillers run with 3 and with 5 rigid neighbours, plus two ``pose`` members
    (:func:`mocapfix.solvers.pma.pose_fills`); each gap's members weighted by their
    inverse squared error on synthetic gaps of the same length cut where the marker was
    seen (``weights: validation``), not by plausibility; the soft constraint at ±3
    standard deviations, not ±2; gaps whose rigid neighbours were missing too filled
    again with those neighbours' fills (``refill: 2``, :meth:`PMA._refill`); a fill that
    jumps more than ``max_step`` × its marker's largest observed step averaged again
    without the members that jump (:func:`mocapfix.solvers.pma.without_jumps`).
    Each choice, with its measurements on benchmarks/versus_peers.py:
    docs/methods/pma.md."""
    name = "fill_ensemble"
    summary = ("fill gaps by averaging nine fillers weighted by their error on synthetic "
               "gaps, with soft distance constraints, refilling gaps whose neighbours were "
               "missing too (PMA-style ensemble)")
    params = _defaults(PMA.params, neighbours=[3, 5], weights="validation",
                       members=["interp", "poly", "grnn", "linear", "pose"], short_gap="0.05 s",
                       width=3.0, refill=2, max_step=3.0)
