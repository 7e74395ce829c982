"""The cleaner protocol: a name, parameters validated when the cleaner is built, and
``apply(motion) -> (motion, info)`` that never mutates its input.

Parameters are declared with :class:`Param`. Physical ones (``length``, ``time``,
``frequency``) accept ``"20 mm"``, ``"0.5 s"``, ``"12 frames"``, ``"6 Hz"`` or a bare number in
the declared default unit, and are converted to the motion's units and frame rate inside
``apply`` via :meth:`Cleaner.frames` and :meth:`Cleaner.length`. A bad value raises
:class:`~mocapfix.core.errors.ConfigError` naming the step, the parameter and the allowed range.

``info`` is a JSON-serialisable dict of what the cleaner wants in the report (iterations,
swaps found, ...). What was filled, flagged or moved is derived by the pipeline from the
motion before and after, so cleaners need not report it. A cleaner that judges samples
wrong and rebuilds them in place (a rotation spike re-made, a Kinect outlier replaced)
rather than making them missing lists them under :data:`REPLACED_FRAMES`, so the report
counts them as outliers and can say why a joint moved.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from mocapfix.core.errors import ConfigError
from mocapfix.core.motion import Motion
from mocapfix.core.quantity import Quantity, parse_quantity

_PHYSICAL = {"length", "time", "frequency"}

#: the info key of the samples a step judged wrong and rebuilt in place:
#: ``{name: [frame, ...]}`` (JSON-able, so the report keeps it)
REPLACED_FRAMES = "replaced_frames"
#: the info key of the fills a step made and did not write, with why:
#: ``{name: [[start, length, why], ...]}`` (the report says why such a gap is left); a
#: gap left because its fill could not be trusted (:class:`FillGate`) has five or six
#: entries, ``[start, length, why, error_mm, bound_mm, extrapolated]`` (None when there is
#: no estimate; ``extrapolated``: see :data:`FILL_ERRORS`), and no later step fills it
REJECTED_FILLS = "rejected_fills"
#: the info key of the error estimates of a step's fills (:mod:`mocapfix.solvers.fill_error`):
#: ``{name: [[start, length, error_mm, bound_mm, extrapolated], ...]}``, one entry per
#: filled run (``extrapolated``, optional: the estimate came from windows shorter than the
#: gap, :func:`mocapfix.solvers.fill_error.extrapolated_bounds`)
FILL_ERRORS = "fill_errors"

def shift_frames(info: dict, offset: int) -> dict:
    """A step's ``info`` run on frames ``offset:`` with its frame numbers
    (:data:`REPLACED_FRAMES`, :data:`REJECTED_FILLS`, :data:`FILL_ERRORS`, the ``start``
    and ``end`` of the ``swaps`` step's swaps) made whole-file frame numbers."""
    return _renumber(info, lambda f: (f + offset,), lambda s, n: (s + offset, n))


def map_frames(info: dict, first, stop) -> dict:
    """A step's ``info`` run on frames picked from a take, frame ``k`` of the run standing
    for the take's frames ``first[k]:stop[k]``, with its frame numbers (as
    :func:`shift_frames`) made the take's: a listed frame becomes every frame it stands
    for, a run ``[start, length]`` the frames ``first[start]:stop[start + length − 1]``."""
    def run(s, n):
        return (int(first[s]), int(stop[s + n - 1]) - int(first[s])) if n > 0 else (int(first[s]), 0)
    return _renumber(info, lambda f: range(int(first[f]), int(stop[f])), run)


def _renumber(info: dict, frames_of, run_of) -> dict:
    """``info`` with each listed frame ``f`` made the frames ``frames_of(f)`` and each run
    ``(start, length)`` made ``run_of(start, length)``."""
    info = dict(info or {})
    if info.get(REPLACED_FRAMES):
        info[REPLACED_FRAMES] = {name: [g for f in frames for g in frames_of(int(f))]
                                 for name, frames in info[REPLACED_FRAMES].items()}
    for key in (REJECTED_FILLS, FILL_ERRORS):
        if info.get(key):
            info[key] = {name: [[*run_of(int(entry[0]), int(entry[1])), *entry[2:]]
                                for entry in fills]
                         for name, fills in info[key].items()}
    if isinstance(info.get("swaps"), list):
        info["swaps"] = [_swap_run(s, run_of) if isinstance(s, dict) and "start" in s
                         and "end" in s else s for s in info["swaps"]]
    return info


def _swap_run(swap: dict, run_of) -> dict:
    start, n = run_of(int(swap["start"]), int(swap["end"]) - int(swap["start"]))
    return {**swap, "start": start, "end": start + n,
            **({"frames": n} if "frames" in swap else {})}


#: what a step that cannot estimate its fills' error says when it fills nothing under the
#: gate (``info["skipped_fills"]``)
NOT_ESTIMATED = ("no fills: it gives no error estimate, so under max_fill_error none "
                 "would be written")


@dataclass(frozen=True)
class FillGate:
    """What the pipeline tells a step about fills (top-level ``max_fill_error``): a fill
    is written only when its calibrated 90 % error bound is at most ``max_error_m``
    (metres); ``leave`` (T, J) marks the samples an earlier step left as too uncertain to
    fill, which this step leaves missing too (None: none). Steps that fill and can
    estimate their error (``fill_ensemble``, ``pma``, ``fill``) honour it themselves;
    steps that cannot (``tsmc``, ``fill_pca``) do not fill under it, and the pipeline
    drops any other step's fill that carries no estimate below the bound."""

    max_error_m: float
    leave: Any = None

    def max_error(self, motion: Motion) -> float:
        """The threshold in the length unit of ``motion``."""
        return self.max_error_m / motion.metres_per_unit

    def left(self, j: int, s: int, e: int) -> bool:
        """The gap ``(j, s, e)`` holds samples an earlier step left as too uncertain."""
        return self.leave is not None and bool(self.leave[s:e, j].any())


@dataclass(frozen=True)
class Param:
    """Declaration of one cleaner parameter.

    ``kind``: "length" | "time" | "frequency" | "float" | "int" | "bool" | "choice" | "str"
    | "list" | "model". ``unit`` is the default unit of a bare number for physical kinds.
    A "model" value is a model file path (relative to the config file) or the name of a
    model shipped with mocapfix; it is resolved and its header checked when the config is
    loaded (:meth:`FittedCleaner.resolve_models`).
    ``low``/``high`` bound the value (in SI for physical kinds, frames excepted);
    ``low_open`` makes the lower bound exclusive.

    Physical parameters always have an upper bound: ``high`` or, when it is None, the
    kind's ceiling in :data:`CEILINGS` (a time longer than an hour, a length over 100 m, a
    frequency over 100 kHz is a typo, and kernels sized from them would not fit in memory).
    A time given in frames is bounded by ``high`` seconds at :data:`MAX_RATE_HZ` (the frame
    rate is not known when the config is read), and never more than :data:`MAX_FRAMES`.
    """

    def bare_number_note(self, value) -> str | None:
        """The note for ``value`` when it is a bare number given to a physical parameter
        (read in :attr:`unit`), None otherwise: YAML configs and Python say the same."""
        if (self.kind in ("length", "time", "frequency") and isinstance(value, (int, float))
                and not isinstance(value, bool)):
            return f"{self.name}: {value} has no unit; read as '{value} {self.unit}' — write the unit to say so"
        return None

    #: upper bound (SI) of each physical kind when a parameter declares none
    CEILINGS: ClassVar[dict] = {"length": 100.0, "time": 3600.0, "frequency": 1e5}
    MAX_RATE_HZ: ClassVar[float] = 10_000.0
    MAX_FRAMES: ClassVar[float] = 1e6

    name: str
    kind: str
    default: Any
    help: str = ""
    unit: str = ""
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    choices: tuple = ()
    nullable: bool = False

    def upper(self) -> float | None:
        """The upper bound: ``high``, or the kind's ceiling for physical kinds."""
        return self.CEILINGS.get(self.kind) if self.high is None else self.high

    def max_frames(self) -> float:
        """Upper bound of a time given in frames."""
        return min(self.upper() * self.MAX_RATE_HZ, self.MAX_FRAMES)

    def describe_range(self) -> str:
        if self.kind == "choice":
            return "one of " + ", ".join(map(str, self.choices))
        lo = "" if self.low is None else (f"> {self.low:g}" if self.low_open else f">= {self.low:g}")
        hi = "" if self.upper() is None else f"<= {self.upper():g}"
        rng = " and ".join(x for x in (lo, hi) if x)
        unit = f" {self.si_unit()}" if self.kind in _PHYSICAL else ""
        return f"{self.kind} {rng}{unit}".strip()

    def si_unit(self) -> str:
        return {"length": "m", "time": "s", "frequency": "Hz"}.get(self.kind, "")

    def parse(self, value, where: str):
        where = f"{where}: parameter '{self.name}'"
        if value is None:
            if self.nullable:
                return None
            raise ConfigError(f"{where} needs a value ({self.describe_range()})")
        if self.kind in _PHYSICAL:
            q = parse_quantity(value, self.kind, self.unit, where)
            if q.frames is not None and q.frames > self.max_frames():
                raise ConfigError(f"{where} = {value!r} is out of range (allowed: at most "
                                  f"{self.max_frames():g} frames, {self.describe_range()})")
            self._check_range(q.si if q.si is not None else q.frames, where, value,
                              upper=q.si is not None)
            return q
        if self.kind == "bool":
            if not isinstance(value, bool):
                raise ConfigError(f"{where} must be true or false, got {value!r}")
            return value
        if self.kind == "int":
            if isinstance(value, bool) or not isinstance(value, int):
                raise ConfigError(f"{where} must be an integer ({self.describe_range()}), got {value!r}")
            self._check_range(value, where, value)
            return value
        if self.kind == "float":
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ConfigError(f"{where} must be a number ({self.describe_range()}), got {value!r}")
            self._check_range(float(value), where, value)
            return float(value)
        if self.kind == "choice":
            if value not in self.choices:
                raise ConfigError(f"{where} must be {self.describe_range()}, got {value!r}")
            return value
        if self.kind in ("str", "model"):
            if not isinstance(value, str):
                raise ConfigError(f"{where} must be a string, got {value!r}")
            return value
        if self.kind == "list":
            if not isinstance(value, (list, tuple)):
                raise ConfigError(f"{where} must be a list, got {value!r}")
            return list(value)
        raise AssertionError(self.kind)

    def _check_range(self, number: float, where: str, shown, upper: bool = True):
        low_bad = self.low is not None and (number <= self.low if self.low_open else number < self.low)
        high = self.upper() if upper else None
        high_bad = high is not None and number > high
        if low_bad or high_bad:
            raise ConfigError(f"{where} = {shown!r} is out of range (allowed: {self.describe_range()})")


class Cleaner:
    """Base class. Subclasses set ``name``, ``params``, ``summary`` and implement ``_apply``."""

    name: ClassVar[str] = ""
    summary: ClassVar[str] = ""
    params: ClassVar[tuple[Param, ...]] = ()
    #: run ``_apply`` with BLAS/LAPACK held to one thread
    #: (:func:`mocapfix.solvers.lowrank.blas_single_thread`): for cleaners whose kernels
    #: are many small matrix products, where threads only add overhead
    single_thread_blas: ClassVar[bool] = False
    #: ``_apply`` takes the pipeline's :class:`FillGate` as ``gate=`` (its fills carry
    #: :data:`FILL_ERRORS`, or it makes none under the gate)
    gated: ClassVar[bool] = False

    def __init__(self, step: str | None = None, **values):
        self.step = step or self.name
        known = {p.name: p for p in self.params}
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise ConfigError(
                f"{self.step}: unknown parameter(s) {', '.join(map(repr, unknown))} for cleaner "
                f"'{self.name}' (known: {', '.join(known) or 'none'})")
        self.values: dict[str, Any] = {}
        for p in self.params:
            raw = values.get(p.name, p.default)
            self.values[p.name] = p.parse(raw, self.step)
        self._validate()

    def _validate(self) -> None:
        """Cross-parameter checks; raise ConfigError."""

    # -- parameter access ---------------------------------------------------
    def __getitem__(self, name: str):
        return self.values[name]

    def frames(self, name: str, motion: Motion) -> float:
        """A time parameter in frames of ``motion``."""
        q: Quantity = self.values[name]
        return q.in_frames(motion.fps)

    def length(self, name: str, motion: Motion) -> float:
        """A length parameter in the length unit of ``motion``."""
        return self.values[name].in_units(motion.metres_per_unit)

    def hertz(self, name: str) -> float:
        return self.values[name].si

    def config(self) -> dict:
        """The effective parameters, as they would be written in a config."""
        out = {}
        for p in self.params:
            v = self.values[p.name]
            out[p.name] = str(v) if isinstance(v, Quantity) else v
        return out

    # -- the contract ---------------------------------------------------------
    def apply(self, motion: Motion, gate: FillGate | None = None) -> tuple[Motion, dict]:
        """Clean ``motion``; returns a new Motion and a JSON-able info dict. ``gate``: the
        pipeline's trust rule for fills, passed on to a :attr:`gated` cleaner."""
        kwargs = {"gate": gate} if self.gated else {}
        if self.single_thread_blas:
            from mocapfix.solvers.lowrank import blas_single_thread

            with blas_single_thread():
                result = self._apply(motion, **kwargs)
        else:
            result = self._apply(motion, **kwargs)
        if isinstance(result, Motion):
            return result, {}
        return result

    def _apply(self, motion: Motion):
        raise NotImplementedError

    def __repr__(self):
        args = ", ".join(f"{k}={v}" for k, v in self.config().items())
        return f"{type(self).__name__}({args})"


class FittedCleaner(Cleaner):
    """A cleaner with learned state, in the manner of scikit-learn estimators.

    Parameters stay exactly as given. ``fit(motions)`` sets the learned state in
    trailing-underscore attributes (listed in ``fitted_attributes``; lengths in metres)
    and never changes a parameter; ``apply`` never changes the cleaner. The state goes to
    and comes from model files (:mod:`mocapfix.core.models`) through :meth:`state` and
    :meth:`load_state`. A cleaner with a ``model`` parameter loads its state from that
    model when the config is loaded.
    """

    #: names of the learned arrays (trailing underscore) saved in a model file
    fitted_attributes: ClassVar[tuple[str, ...]] = ()
    #: the parameter naming the model file, if the cleaner takes one
    model_param: ClassVar[str | None] = "model"
    #: the shipped models the cleaner chooses from per file when no model is named
    auto_models: ClassVar[tuple[str, ...]] = ()
    #: the model file :meth:`resolve_models` loaded
    _model_file: Path | None = None

    def fit(self, motions, progress=None) -> "FittedCleaner":
        """Learn the state from ``motions`` (a list of :class:`Motion`); returns self."""
        raise NotImplementedError

    @property
    def is_fitted(self) -> bool:
        return all(getattr(self, a, None) is not None for a in self.fitted_attributes)

    def state(self) -> tuple[dict, dict]:
        """(JSON-able header fields, {name: array}) of the learned state."""
        raise NotImplementedError

    def load_state(self, header: dict, arrays: dict) -> "FittedCleaner":
        """Set the learned state from a model file's header and arrays; returns self."""
        raise NotImplementedError

    @staticmethod
    def check_state(state, arrays: dict) -> None:
        """A ValueError or TypeError when a model file's ``state`` and ``arrays`` cannot be
        this cleaner's (indices past its joints, a rate of 0, an array of another rank):
        :func:`mocapfix.core.models.load` makes it a corrupt model, when the config loads,
        instead of an internal error on every file. Nothing to check by default."""

    def with_state(self, header: dict, arrays: dict) -> "FittedCleaner":
        """A new cleaner with this one's parameters and the given learned state (a model
        chosen per file; ``apply`` never changes the configured cleaner)."""
        return type(self)(step=self.step, **self.config()).load_state(header, arrays)

    def model_header_fields(self) -> dict:
        """What a model file records besides the state: the cleaner and its parameters."""
        return {"cleaner": self.name, "parameters": self.config()}

    def model_files(self) -> list[Path]:
        """The model files this step may read: the one its ``model`` parameter named, or
        when none is named the shipped models it chooses from per file (:attr:`auto_models`).
        Their content decides the outputs as much as the config does: a resumed batch
        hashes them (:func:`mocapfix.batch.manifest.run_key`)."""
        from mocapfix.core import models

        if self._model_file is not None:
            return [self._model_file]
        if self.is_fitted or self.values.get(self.model_param) is not None:
            return []                   # state learned in memory, or mssa's ``model: self``
        ships = models.shipped()
        return [ships[name] for name in self.auto_models if name in ships]

    def resolve_models(self, base_dir=None) -> None:
        """Resolve the ``model`` parameter against ``base_dir`` (the config's folder) or the
        shipped models, read and check its header (a ConfigError naming the step if it is
        missing, corrupt or made for another cleaner) and load the state (cached per
        process, so a worker reads each model once)."""
        from mocapfix.core import models

        if self.model_param is None:
            return
        ref = self.values.get(self.model_param)
        if ref is None:
            return
        path = models.resolve(ref, base_dir, where=f"{self.step}: parameter '{self.model_param}'")
        header, arrays = models.load(path, cleaner=self.name,
                                     where=f"{self.step}: parameter '{self.model_param}'",
                                     check=self.check_state)
        if path.parent != models.SHIPPED_DIR:
            self.values[self.model_param] = str(path)   # absolute: workers need no config folder
        self._model_file = path
        try:
            self.load_state(header, arrays)
        except (KeyError, ValueError, TypeError) as exc:
            from mocapfix.core.errors import ConfigError
            raise ConfigError(f"{self.step}: model {path} is incompatible with {self.name!r}: "
                              f"{type(exc).__name__}: {exc}") from None
