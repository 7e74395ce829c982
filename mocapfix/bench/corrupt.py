"""Seeded corruption of clean motions, for tests and ``mocapfix bench``.

The ``occlusion`` scenarios model an optical capture (docs/benchmarks.md,
"Benchmarks" section): occlusion gaps of 0.1–1.5 s on a quarter of the markers,
2 mm jitter with 2 % spikes of 20–100 mm, both together, and a marker swap. Physical
sizes are converted to the motion's units. Every function returns the corrupted motion
and a (T, J) mask of the samples it touched; the input is never modified.
"""
from __future__ import annotations

import numpy as np

from mocapfix.core.motion import Motion


def _mm(motion: Motion, value_mm: float) -> float:
    return value_mm * 1e-3 / motion.metres_per_unit


def occlusion_gaps(motion: Motion, rng: np.random.Generator, marker_fraction: float = 0.25,
                   min_s: float = 0.1, max_s: float = 1.5, gaps_per_marker: tuple[int, int] = (1, 3)):
    """Interior gaps of ``min_s``–``max_s`` seconds on ``marker_fraction`` of the markers."""
    pos = motion.positions.copy()
    T, J, _ = pos.shape
    mask = np.zeros((T, J), dtype=bool)
    observed_markers = np.flatnonzero(~np.isnan(pos).any(axis=2).all(axis=0))
    n_markers = max(1, int(round(marker_fraction * len(observed_markers))))
    chosen = rng.choice(observed_markers, size=min(n_markers, len(observed_markers)), replace=False)
    lo, hi = max(1, int(round(min_s * motion.fps))), max(1, int(round(max_s * motion.fps)))
    for j in chosen:
        for _ in range(rng.integers(gaps_per_marker[0], gaps_per_marker[1] + 1)):
            length = int(rng.integers(lo, hi + 1))
            if length >= T - 2:
                length = T // 3
            start = int(rng.integers(1, T - length - 1))
            mask[start:start + length, j] = True
    pos[mask] = np.nan
    return motion.replace(positions=pos), mask


def jitter_and_spikes(motion: Motion, rng: np.random.Generator, jitter_mm: float = 2.0,
                      spike_fraction: float = 0.02, spike_mm: tuple[float, float] = (20.0, 100.0)):
    """Gaussian jitter of ``jitter_mm`` (per coordinate) on every sample, plus spikes of
    random direction and uniform size in ``spike_mm`` on ``spike_fraction`` of the samples."""
    pos = motion.positions.copy()
    T, J, _ = pos.shape
    pos += rng.normal(0.0, _mm(motion, jitter_mm), size=pos.shape)
    n_spikes = int(round(spike_fraction * T * J))
    flat = rng.choice(T * J, size=n_spikes, replace=False)
    t, j = np.unravel_index(flat, (T, J))
    direction = rng.normal(size=(n_spikes, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    size = rng.uniform(*spike_mm, size=n_spikes)
    pos[t, j] += direction * _mm(motion, 1.0) * size[:, None]
    mask = np.zeros((T, J), dtype=bool)
    mask[t, j] = True
    return motion.replace(positions=pos), mask


def marker_swap(motion: Motion, rng: np.random.Generator, min_s: float = 0.3, max_s: float = 1.5):
    """Two neighbouring markers exchange trajectories for a stretch (a labelling error)."""
    pos = motion.positions.copy()
    T, J, _ = pos.shape
    mean = np.nanmean(pos, axis=0)
    a = int(rng.integers(J))
    dist = np.linalg.norm(mean - mean[a], axis=1)
    dist[a] = np.inf
    dist[np.isnan(dist)] = np.inf
    neighbours = np.argsort(dist)[:3]
    b = int(rng.choice(neighbours))
    length = int(rng.integers(max(1, round(min_s * motion.fps)), max(2, round(max_s * motion.fps)) + 1))
    length = min(length, T // 2)
    start = int(rng.integers(1, T - length))
    span = slice(start, start + length)
    pos[span, a], pos[span, b] = motion.positions[span, b], motion.positions[span, a]
    mask = np.zeros((T, J), dtype=bool)
    mask[span, [a, b]] = True
    return motion.replace(positions=pos), mask


OCCLUSION_SCENARIOS = ("gaps", "noise", "mixed", "swap")


def _occlusion_refusal(motion: Motion) -> str | None:
    if len(motion.positions) < 4:   # an interior gap or swap needs frames on both sides
        return f"{len(motion.positions)} frames; the occlusion protocol needs at least 4"
    return None


def occlusion(motion: Motion, scenario: str, seed: int = 0):
    """One scenario of the ``occlusion`` protocol; returns (corrupted motion, mask)."""
    why = _occlusion_refusal(motion)
    if why:
        raise ValueError(why)
    rng = np.random.default_rng(seed)
    if scenario == "gaps":
        return occlusion_gaps(motion, rng)
    if scenario == "noise":
        return jitter_and_spikes(motion, rng)
    if scenario == "mixed":
        noisy, m1 = jitter_and_spikes(motion, rng)
        gapped, m2 = occlusion_gaps(noisy, rng)
        return gapped, m1 | m2
    if scenario == "swap":
        return marker_swap(motion, rng)
    raise ValueError(f"unknown occlusion scenario {scenario!r} (known: {', '.join(OCCLUSION_SCENARIOS)})")


# ---------------------------------------------------------------------------------------
# The research papers' protocols (Feng 2014, Feng 2015, Yang 2019), used by
# ``mocapfix bench``. Every detail a paper leaves open is fixed here and named in the
# docstring that uses it; docs/benchmarks.md repeats the list.
#
# Common choices:
# * Corruption acts on *samples* (one joint or marker at one frame, all three coordinates),
#   never on a single coordinate: a missing sample is NaN in x, y and z (the way every
#   reader reports a missing marker), and a noisy sample gets independent noise on x, y, z.
# * Fractions are exact: ``round(fraction × n)`` samples are drawn without replacement from
#   the n samples present in the clean motion (samples already missing are never counted
#   or touched).
# * Sizes given by the papers in cm or in ASF length units are converted to the motion's
#   length unit with ``motion.metres_per_unit``.
# * The same ``seed`` gives the same corruption; every function takes a
#   ``numpy.random.Generator`` and returns (corrupted motion, touched (T, J) mask).

#: the CMU/Acclaim ASF length unit (``:units length 0.45``): 1/0.45 inch in metres.
ASF_UNIT_M = 0.0254 / 0.45


def _cm(motion: Motion, value_cm: float) -> float:
    return value_cm * 1e-2 / motion.metres_per_unit


def _pick_samples(rng: np.random.Generator, eligible: np.ndarray, fraction: float) -> np.ndarray:
    """A (T, J) mask of exactly ``round(fraction × eligible.sum())`` eligible samples."""
    if not 0.0 <= fraction <= 1.0:
        raise ValueError(f"fraction must be in [0, 1], got {fraction}")
    flat = np.flatnonzero(eligible.ravel())
    count = int(round(fraction * len(flat)))
    mask = np.zeros(eligible.size, dtype=bool)
    mask[rng.choice(flat, size=count, replace=False)] = True
    return mask.reshape(eligible.shape)


def signal_power(positions: np.ndarray) -> float:
    """Mean power of the centred signal: the mean over all present entries of
    (x − channel mean)², each channel (one coordinate of one joint) centred on its own
    temporal mean. This is the signal power behind :func:`gaussian_snr`; centring makes
    the SNR independent of where the capture volume's origin is."""
    centred = positions - np.nanmean(positions, axis=0, keepdims=True)
    return float(np.nanmean(centred ** 2))


def gaussian_snr(motion: Motion, rng: np.random.Generator, snr_db: float):
    """Feng et al. 2015 §V-A "Gaussian noise with SNR ∈ {30 … 5} dB".

    Unspecified in the paper, chosen here: one noise level for the whole motion,
    i.i.d. N(0, σ²) on every coordinate of every present sample, with
    σ² = P / 10^(SNR/10) and P = :func:`signal_power` (the centred signal; a raw,
    uncentred power would make the noise depend on the room's origin). The mask is every
    present sample."""
    pos = motion.positions.copy()
    present = ~np.isnan(pos).any(axis=2)
    sigma = np.sqrt(signal_power(pos) / 10.0 ** (snr_db / 10.0))
    pos += rng.normal(0.0, sigma, size=pos.shape)
    return motion.replace(positions=pos), present


#: the SNR definitions :func:`feng2015_gaussian` knows (benchmarks/feng2015_calibration.py
#: measures each against the paper's tuned baselines); the protocol uses
#: :data:`FENG2015_SNR_DEFINITION`.
FENG2015_SNR_DEFINITIONS = ("uncentred", "uncentred-per-channel", "centred",
                            "centred-per-channel", "root-relative")

#: the definition the ``feng2015`` protocol uses (evidence: benchmarks/RESULTS.md,
#: "Feng 2015: calibrating the SNR").
FENG2015_SNR_DEFINITION = "uncentred"

#: half-width (cm) of the feng2015 outliers, U(−h, h) per coordinate. The paper gives no
#: size. Chosen by calibration (benchmarks/feng2015_calibration.py, RESULTS.md "Feng 2015:
#: calibrating the SNR"): with the oracle-tuned Gaussian, wavelet and Kalman baselines on
#: CMU dance, ±50 cm puts the most cells of the paper's dance rows of Tables II and III
#: within ±25 %; Yang 2019's ±25 cm gives about half the paper's errors.
FENG2015_OUTLIER_CM = 50.0


def feng2015_noise_sigma(positions: np.ndarray, snr_db: float,
                         definition: str = FENG2015_SNR_DEFINITION) -> np.ndarray:
    """Noise standard deviation per channel, shape (1, J, 3), for ``snr_db`` under one SNR
    definition: σ_c² = P_c / 10^(SNR/10), P_c the signal power of channel c (one coordinate
    of one joint, over its present samples):

    ``uncentred``              P_c = mean of x² over every present entry of the whole motion
                               (one σ), positions in the file's own frame — what MATLAB's
                               ``awgn(X, snr, 'measured')`` does to a whole data matrix;
    ``uncentred-per-channel``  P_c = mean of x_c² of the channel alone (``awgn`` per column);
    ``centred``                P_c = :func:`signal_power` (each channel minus its temporal
                               mean, pooled: one σ; the definition of :func:`gaussian_snr`);
    ``centred-per-channel``    P_c = the temporal variance of channel c alone;
    ``root-relative``          P_c = pooled centred power of the positions relative to the
                               root (first joint) at each frame: the body's own movement,
                               without the travel through the room (one σ).

    The SNR is unit-free under every definition; the ``uncentred`` ones depend on where the
    file puts its origin (CMU ASF/AMC: floor y = 0, room centre x = z = 0)."""
    pos = np.asarray(positions, dtype=float)
    scale = 10.0 ** (snr_db / 10.0)
    if definition == "uncentred":
        power = np.full((1,) + pos.shape[1:], np.nanmean(pos ** 2))
    elif definition == "uncentred-per-channel":
        power = np.nanmean(pos ** 2, axis=0, keepdims=True)
    elif definition == "centred":
        power = np.full((1,) + pos.shape[1:], signal_power(pos))
    elif definition == "centred-per-channel":
        power = np.nanvar(pos, axis=0, keepdims=True)
    elif definition == "root-relative":
        power = np.full((1,) + pos.shape[1:], signal_power(pos - pos[:, :1]))
    else:
        raise ValueError(f"unknown SNR definition {definition!r} "
                         f"(known: {', '.join(FENG2015_SNR_DEFINITIONS)})")
    return np.sqrt(np.nan_to_num(power) / scale)


def feng2015_gaussian(motion: Motion, rng: np.random.Generator, snr_db: float,
                      definition: str = FENG2015_SNR_DEFINITION):
    """Feng et al. 2015 §V-A "Gaussian noise with SNR ∈ {30 … 5} dB": i.i.d. N(0, σ_c²) on
    every coordinate of every present sample, σ_c from :func:`feng2015_noise_sigma`.

    The paper does not define its SNR. Chosen (``uncentred``): one σ for the whole
    motion, σ² = mean(x²) / 10^(SNR/10) over the positions as the CMU ASF/AMC file puts
    them (MATLAB ``awgn(X, snr, 'measured')`` on the data matrix). Evidence
    (benchmarks/feng2015_calibration.py → benchmarks/results/feng2015_calibration.md): with the
    Gaussian, wavelet and Kalman smoothers oracle-tuned per run (the paper "tune[s] all
    model parameters … and report[s] their best results"), on four CMU dance trials, 4 of
    the 9 cells of the paper's dance rows at 30/20/10 dB are within ±25 % (10 dB: 1.28,
    1.07, 0.98 × the paper; 20 dB: 1.07, 0.80, 0.67), none for the centred definitions
    (the old :func:`gaussian_snr`: 0.5–0.65 × at 10 dB, less noise than the paper's) or
    the root-relative one. Not reproduced: 30 dB (0.60, 0.64, 0.27 ×: the paper's rows
    have a floor an oracle does not). The noise depends on where the trial sits in the
    room (10 dB: σ = 21–36 cm per coordinate over the 18 subject-05 dance trials). The
    mask is every present sample."""
    pos = motion.positions.copy()
    present = ~np.isnan(pos).any(axis=2)
    sigma = feng2015_noise_sigma(pos, snr_db, definition)
    pos += rng.normal(0.0, 1.0, size=pos.shape) * sigma
    return motion.replace(positions=pos), present


def uniform_outliers(motion: Motion, rng: np.random.Generator, fraction: float,
                     half_width_cm: float = 25.0):
    """Yang et al. 2019 §IV-A: "random noise is added to a fraction of entities …
    uniformly distributed in the range of [−25 25] cm in each spatial dimension".

    Chosen here: the fraction counts joint samples ("polluted joints"), each polluted
    sample gets independent U(−25, 25) cm on x, y and z. Also used for the outliers of
    Feng et al. 2015 with ``half_width_cm`` = :data:`FENG2015_OUTLIER_CM` (their outlier
    size is unspecified; see :data:`PROTOCOLS`)."""
    pos = motion.positions.copy()
    mask = _pick_samples(rng, ~np.isnan(pos).any(axis=2), fraction)
    h = _cm(motion, half_width_cm)
    pos[mask] += rng.uniform(-h, h, size=(int(mask.sum()), 3))
    return motion.replace(positions=pos), mask


def gaussian_on_fraction(motion: Motion, rng: np.random.Generator, fraction: float,
                         sigma_asf_units: float = 2.0, eligible: np.ndarray | None = None):
    """Feng et al. 2014 §4 "randomly added gaussian noise (σ = 2) on 30 % data", σ in
    ASF length units (they multiply by 5.6444 to get cm): N(0, σ²) on x, y, z of exactly
    ``round(fraction × n)`` present samples (or of the ``eligible`` ones)."""
    pos = motion.positions.copy()
    present = ~np.isnan(pos).any(axis=2)
    mask = _pick_samples(rng, present if eligible is None else (present & eligible), fraction)
    sigma = sigma_asf_units * ASF_UNIT_M / motion.metres_per_unit
    pos[mask] += rng.normal(0.0, sigma, size=(int(mask.sum()), 3))
    return motion.replace(positions=pos), mask


def random_missing(motion: Motion, rng: np.random.Generator, fraction: float):
    """Feng et al. 2014 "randomly removed 40 % data": exactly ``round(fraction × n)``
    present samples, drawn uniformly, become NaN (whole samples, see above)."""
    pos = motion.positions.copy()
    mask = _pick_samples(rng, ~np.isnan(pos).any(axis=2), fraction)
    pos[mask] = np.nan
    return motion.replace(positions=pos), mask


def regular_gaps(motion: Motion, rng: np.random.Generator, fraction: float = 0.30,
                 markers: int = 10, frames: int = 60):
    """Feng et al. 2014 "regularly removed about 30 % data wherein the number of selected
    missing markers is fixed to 10 for each incomplete frame and each selected marker
    misses 60 frames".

    Chosen here: the timeline is cut into consecutive windows of ``frames`` frames from
    frame 0 (the last one may be shorter); windows are taken in a random order until the
    missing count is closest to ``fraction × T × J``; in each chosen window ``markers``
    distinct markers, drawn at random among those not missing in the window just before,
    are missing for the whole window. So every incomplete frame misses exactly ``markers``
    markers, every gap is ``frames`` long (the last window may be shorter: the paper also
    tests gaps at the end of the capture) when J >= 2 × ``markers``, and the fraction is
    capped at ``markers / J`` (24 % on a 41-marker set). Samples already missing in the
    clean motion stay missing but are not counted as corrupted."""
    why = _regular_gaps_refusal(motion, markers)
    if why:
        raise ValueError(why)
    pos = motion.positions.copy()
    T, J, _ = pos.shape
    starts = np.arange(0, T, frames)
    lengths = np.minimum(starts + frames, T) - starts
    order = rng.permutation(len(starts))
    cum = np.cumsum(lengths[order]) * markers
    n_windows = int(np.argmin(np.abs(cum - fraction * T * J))) + 1
    mask = np.zeros((T, J), dtype=bool)
    previous, prev_w = np.zeros(J, dtype=bool), -2
    for w in np.sort(order[:n_windows]):
        # a marker missing in the window just before is not drawn again, so that every
        # gap is one window long (possible when J >= 2 × markers; else gaps may merge)
        pool = np.flatnonzero(~previous) if w == prev_w + 1 else np.arange(J)
        if len(pool) < markers:
            pool = np.arange(J)
        chosen = rng.choice(pool, size=markers, replace=False)
        mask[starts[w]:starts[w] + lengths[w], chosen] = True
        previous = np.zeros(J, dtype=bool)
        previous[chosen] = True
        prev_w = w
    mask &= ~np.isnan(pos).any(axis=2)
    pos[mask] = np.nan
    return motion.replace(positions=pos), mask


def _regular_gaps_refusal(motion: Motion, markers: int) -> str | None:
    if markers > motion.n_joints:
        return f"regular gaps need at least {markers} markers, the motion has {motion.n_joints}"
    return None


def _feng2015(motion, rng, snr_db=None, outliers=None):
    touched = np.zeros(motion.positions.shape[:2], dtype=bool)
    if snr_db is not None:
        motion, m = feng2015_gaussian(motion, rng, snr_db)
        touched |= m
    if outliers is not None:
        motion, m = uniform_outliers(motion, rng, outliers, FENG2015_OUTLIER_CM)
        touched |= m
    return motion, touched


#: Feng et al. 2014's regular gaps: the markers missing in each incomplete frame
FENG2014_GAP_MARKERS = 10


def _feng2014(motion, rng, kind):
    if kind == "random-missing":
        return random_missing(motion, rng, 0.40)
    if kind == "regular-gaps":
        return regular_gaps(motion, rng, 0.30, FENG2014_GAP_MARKERS, 60)
    if kind == "noise":
        return gaussian_on_fraction(motion, rng, 0.30, 2.0)
    if kind == "mixed":
        gapped, m1 = random_missing(motion, rng, 0.30)
        noisy, m2 = gaussian_on_fraction(gapped, rng, 0.30, 2.0)
        return noisy, m1 | m2
    raise ValueError(kind)


#: protocol → {setting name: keyword arguments of the protocol's corruption}.
PROTOCOLS: dict[str, dict[str, dict]] = {
    # Feng et al. 2015, §V-A and Tables I–III: SNR noise (:func:`feng2015_gaussian`),
    # outliers (size unspecified in the paper; chosen by calibration:
    # U(−FENG2015_OUTLIER_CM, +FENG2015_OUTLIER_CM) per coordinate), and mixed = SNR noise
    # on every sample, then outliers on top of it.
    "feng2015": {
        **{f"snr{s}": {"snr_db": s} for s in (30, 25, 20, 15, 10, 5)},
        **{f"out{p}": {"outliers": p / 100} for p in (5, 10, 15, 20, 25, 30)},
        **{f"snr{s}+out{p}": {"snr_db": s, "outliers": p / 100}
           for s, p in ((20, 10), (20, 20), (10, 10), (10, 20))},
    },
    # Yang et al. 2019, §IV-A and Table II: 5/10/15/20/80 % samples, U(−25, 25) cm.
    "yang2019": {f"{p}%": {"fraction": p / 100} for p in (5, 10, 15, 20, 80)},
    # Feng et al. 2014, §4 (results only as bar charts, Figs. 6–9).
    "feng2014": {k: {"kind": k} for k in ("random-missing", "regular-gaps", "noise", "mixed")},
    # Realistic optical occlusions (this module's ``occlusion``).
    "occlusion": {s: {"scenario": s} for s in OCCLUSION_SCENARIOS},
    # Rotation channels of BVH/AMC (mocapfix.bench.rotations).
    "rotations": {s: {"setting": s} for s in ("clean", "jitter", "spikes", "mixed")},
    # Nothing: the file as read (mocapfix.bench.harm scores what a method changes).
    "harm": {"as-read": {}},
}


def refusal(motion: Motion, protocol: str, setting: str) -> str | None:
    """Why one setting of one protocol cannot corrupt ``motion`` (what
    :func:`apply_protocol` would raise), or None: ``mocapfix bench`` asks it of every file
    before any work and leaves out a file it cannot use."""
    if protocol == "occlusion":
        return _occlusion_refusal(motion)
    if protocol == "feng2014" and PROTOCOLS[protocol][setting]["kind"] == "regular-gaps":
        return _regular_gaps_refusal(motion, FENG2014_GAP_MARKERS)
    if protocol == "rotations":
        from mocapfix.bench import rotations as bench_rotations

        return bench_rotations.refusal(motion)
    return None


def apply_protocol(motion: Motion, protocol: str, setting: str, seed: int = 0):
    """Corrupt ``motion`` with one setting of one protocol; returns (motion, mask).

    ``seed`` alone fixes the corruption (``numpy.random.default_rng(seed)``)."""
    if protocol not in PROTOCOLS:
        raise ValueError(f"unknown protocol {protocol!r} (known: {', '.join(PROTOCOLS)})")
    settings = PROTOCOLS[protocol]
    if setting not in settings:
        raise ValueError(f"unknown {protocol} setting {setting!r} (known: {', '.join(settings)})")
    kw = settings[setting]
    if protocol == "harm":
        return motion.copy(), np.zeros(motion.positions.shape[:2], bool)
    if protocol == "occlusion":
        return occlusion(motion, kw["scenario"], seed)
    if protocol == "rotations":
        from mocapfix.bench import rotations as bench_rotations

        return bench_rotations.corrupt(motion, kw["setting"], seed)
    rng = np.random.default_rng(seed)
    if protocol == "feng2015":
        return _feng2015(motion, rng, **kw)
    if protocol == "yang2019":
        return uniform_outliers(motion, rng, kw["fraction"], 25.0)
    return _feng2014(motion, rng, kw["kind"])
