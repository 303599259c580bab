"""Labelled demonstrations: the record and its activations.

The record is :class:`Demonstration` (validated on construction), an MP's activation in it
:class:`Activation`.

A :class:`Demonstration` is one recorded execution of a task (paper Sec. III-A): a feature
trajectory ``X`` of shape ``(n, d)`` sampled at times ``t`` and, for every control variable, the
name of the movement primitive (MP) active at each time step. The HDF5 file format is
:mod:`cpmp.data.datafile` (``save_demonstrations``, ``load_demonstrations``, ``list_splits``); the
record needs no h5py.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from cpmp.errors import DataError, UnknownMPError
from cpmp.records import TransitionEvent

MetadataValue = str | int | float | bool | None


@dataclass(frozen=True)
class Activation:
    """One activation of an MP: samples ``start`` (inclusive) to ``stop`` (exclusive).

    Attributes:
        mp: MP name.
        start: first sample index (inclusive).
        stop: index after the last sample (exclusive).
        time: (n,) sample times [s] (a view into the demonstration's ``time``).
        features: (n, d) feature trajectory while the MP was active (a view).
        demo: index of the demonstration in the list a sequence graph was built from
            (:func:`cpmp.graph.build_graph`); ``None`` from :meth:`Demonstration.segments`.

    ``==`` compares ``mp``, ``start``, ``stop`` and ``demo``.
    """

    mp: str
    start: int
    stop: int
    time: np.ndarray = field(repr=False, compare=False)
    features: np.ndarray = field(repr=False, compare=False)
    demo: int | None = None

    @property
    def n_samples(self) -> int:
        """Number of samples ``n`` in the activation."""
        return self.stop - self.start


@dataclass(eq=False, repr=False)
class Demonstration:
    """One labelled demonstration, validated on construction.

    Args:
        time: (n,) sample times [s], finite and strictly increasing, ``n >= 2``.
        features: (n, d) feature state ``x`` at each sample (stored as float64), finite,
            ``d >= 1``.
        labels: variable name -> (n,) str array, the name of the MP active on that control
            variable at each sample.
        feature_names: d unique column names; defaults to ``f0 .. f{d-1}``.
        name: used in error messages and as the HDF5 group name (``demo_<something>``).
        metadata: free-form scalars (str/int/float/bool/None) such as box size or strategy.

    Raises:
        DataError: if any of the above does not hold; the message names the demonstration and
            the fix. Call :meth:`validate` again after editing the arrays in place.
    """

    time: np.ndarray
    features: np.ndarray
    labels: dict[str, np.ndarray]
    feature_names: list[str] | None = None
    name: str | None = None
    metadata: dict[str, MetadataValue] | None = None

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Convert the fields to their canonical types and check every invariant."""
        if self.name is not None and (not isinstance(self.name, str) or not self.name):
            raise DataError(f"demonstration name must be a non-empty string, got {self.name!r}")
        self.time = self._check_time(self.time)
        self.features = self._check_features(self.features, len(self.time))
        self.feature_names = self._check_feature_names(self.feature_names)
        self.labels = self._check_labels(self.labels)
        self.metadata = self._check_metadata(self.metadata)

    @property
    def n_samples(self) -> int:
        """Number of time steps ``n``."""
        return int(self.features.shape[0])

    @property
    def n_features(self) -> int:
        """Feature dimension ``d``."""
        return int(self.features.shape[1])

    @property
    def variables(self) -> list[str]:
        """Sorted control-variable names."""
        return sorted(self.labels)

    @property
    def duration(self) -> float:
        """``time[-1] - time[0]`` [s]."""
        return float(self.time[-1] - self.time[0])

    def segments(self, variable: str) -> list[Activation]:
        """Consecutive activations of ``variable``'s MPs, in time order.

        Their ``time`` and ``features`` are views into this demonstration's arrays.
        """
        labels = self._variable_labels(variable)
        bounds = [0, *self.switch_indices(variable).tolist(), len(labels)]
        return [
            Activation(str(labels[a]), a, b, self.time[a:b], self.features[a:b])
            for a, b in itertools.pairwise(bounds)
        ]

    def transitions(self, variable: str | None = None) -> list[TransitionEvent]:
        """The demonstrated switches of ``variable`` (of every variable if ``None``), in order.

        In time order, variables in :attr:`variables` order at equal times. Each is at the
        time of the first sample under the new MP, with that sample's features as ``state``
        (d,) and no ``probability`` (``nan``: a label is not a prediction).
        """
        variables = self.variables if variable is None else [variable]
        events = []
        for v in variables:
            labels = self._variable_labels(v)
            for i in self.switch_indices(v).tolist():
                source, target = str(labels[i - 1]), str(labels[i])
                events.append(
                    TransitionEvent(float(self.time[i]), v, source, target, state=self.features[i])
                )
        return sorted(events, key=lambda event: event.t)

    def switch_indices(self, variable: str) -> np.ndarray:
        """Indices ``i`` (int64, shape (k,)) where ``labels[variable][i] != ...[i - 1]``."""
        labels = self._variable_labels(variable)
        return (np.flatnonzero(labels[1:] != labels[:-1]) + 1).astype(np.int64)

    def __repr__(self) -> str:
        return (
            f"Demonstration(name={self.name!r}, n_samples={self.n_samples}, "
            f"n_features={self.n_features}, variables={self.variables})"
        )

    @property
    def _who(self) -> str:
        return self.name if self.name else "demonstration"

    def _variable_labels(self, variable: str) -> np.ndarray:
        if variable not in self.labels:
            raise UnknownMPError(
                f"{self._who}: unknown control variable {variable!r}; "
                f"known variables: {', '.join(self.variables)}"
            )
        return self.labels[variable]

    def _check_time(self, time: ArrayLike) -> np.ndarray:
        who = self._who
        if np.iscomplexobj(time):
            raise DataError(f"{who}: time must be real seconds, got complex values")
        try:
            t = np.array(time, dtype=np.float64)
        except (TypeError, ValueError) as err:
            raise DataError(f"{who}: time must be numeric seconds ({err})") from None
        if t.ndim != 1:
            raise DataError(f"{who}: time must be 1-D with shape (n,), got shape {t.shape}")
        if len(t) < 2:
            raise DataError(
                f"{who}: has {len(t)} sample(s) but at least 2 are needed; record a longer "
                "demonstration"
            )
        bad = np.flatnonzero(~np.isfinite(t))
        if bad.size:
            raise DataError(
                f"{who}: time is NaN/inf at sample {bad[0]}; remove or re-time non-finite samples"
            )
        step = np.flatnonzero(np.diff(t) <= 0)
        if step.size:
            i = int(step[0]) + 1
            raise DataError(
                f"{who}: time is not strictly increasing at sample {i} "
                f"(t={t[i]!r} after t={t[i - 1]!r}); sort samples by time and drop duplicates"
            )
        return t

    def _check_features(self, features: ArrayLike, n: int) -> np.ndarray:
        who = self._who
        if np.iscomplexobj(features):
            raise DataError(
                f"{who}: features must be real numbers, got complex values; pass the real and "
                "imaginary parts (or magnitude and phase) as separate features"
            )
        try:
            x = np.array(features, dtype=np.float64)
        except (TypeError, ValueError) as err:
            raise DataError(f"{who}: features must be numeric ({err})") from None
        if x.ndim != 2:
            raise DataError(
                f"{who}: features must be 2-D with shape (n, d), got shape {x.shape}; "
                "use features.reshape(-1, 1) for a single feature"
            )
        if x.shape[0] != n:
            raise DataError(
                f"{who}: features has {x.shape[0]} rows but time has {n} samples; "
                "give one feature row per time step"
            )
        if x.shape[1] == 0:
            raise DataError(f"{who}: features has 0 columns; give at least one feature")
        bad = np.argwhere(~np.isfinite(x))
        if bad.size:
            i, j = (int(v) for v in bad[0])
            raise DataError(
                f"{who}: features is NaN/inf at sample {i}, column {j} ({len(bad)} value(s) in "
                "all); remove, interpolate or fill non-finite values"
            )
        return x

    def _check_feature_names(self, names: Sequence[str] | None) -> list[str]:
        who, d = self._who, self.features.shape[1]
        if names is None:
            return [f"f{j}" for j in range(d)]
        if isinstance(names, str):
            raise DataError(f"{who}: feature_names must be a list of strings, not one string")
        names = list(names)
        if len(names) != d:
            raise DataError(
                f"{who}: feature_names has {len(names)} entries but features has {d} columns; "
                "give one name per column"
            )
        for j, name in enumerate(names):
            if not isinstance(name, str) or not name:
                raise DataError(
                    f"{who}: feature_names[{j}] is {name!r}; every feature needs a non-empty name"
                )
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise DataError(
                f"{who}: feature_names are not unique ({', '.join(dupes)} repeated); "
                "give every column a distinct name"
            )
        return names

    def _check_labels(self, labels: object) -> dict[str, np.ndarray]:
        who, n = self._who, len(self.time)
        if not isinstance(labels, Mapping) or not labels:
            raise DataError(
                f"{who}: labels must be a non-empty dict {{variable: MP names per step}}; "
                "label at least one control variable"
            )
        checked: dict[str, np.ndarray] = {}
        for variable in sorted(labels, key=str):
            if not isinstance(variable, str) or variable in ("", ".") or "/" in variable:
                raise DataError(
                    f"{who}: control variable name {variable!r} is invalid; use a non-empty "
                    "string without '/'"
                )
            checked[variable] = _check_label_array(who, variable, labels[variable], n)
        return checked

    def _check_metadata(self, metadata: Mapping[str, object] | None) -> dict[str, MetadataValue]:
        who = self._who
        if metadata is None:
            return {}
        if not isinstance(metadata, Mapping):
            raise DataError(f"{who}: metadata must be a dict, got {type(metadata).__name__}")
        checked: dict[str, MetadataValue] = {}
        for key, value in metadata.items():
            if not isinstance(key, str) or not key:
                raise DataError(f"{who}: metadata key {key!r} must be a non-empty string")
            if isinstance(value, np.generic):
                value = value.item()
            if value is not None and not isinstance(value, str | int | float | bool):
                raise DataError(
                    f"{who}: metadata[{key!r}] is a {type(value).__name__}; metadata holds only "
                    "str/int/float/bool/None (store arrays as features instead)"
                )
            if isinstance(value, float) and not math.isfinite(value):
                raise DataError(f"{who}: metadata[{key!r}] is {value}; use a finite number")
            checked[key] = value
        return checked


def _check_label_array(who: str, variable: str, values: ArrayLike, n: int) -> np.ndarray:
    """Return ``values`` as a unicode array of shape (n,), or raise :class:`DataError`."""
    raw = np.asarray(values)
    if raw.ndim != 1:
        raise DataError(
            f"{who}: labels[{variable!r}] must be 1-D with shape (n,), got shape {raw.shape}"
        )
    if len(raw) != n:
        raise DataError(
            f"{who}: labels[{variable!r}] has {len(raw)} entries but time has {n} samples; "
            "label every time step"
        )
    if raw.dtype.kind != "U":
        objects = np.asarray(values, dtype=object)
        for i, value in enumerate(objects):
            if not isinstance(value, str):
                raise DataError(
                    f"{who}: labels[{variable!r}][{i}] is {value!r}; labels must be MP names "
                    "(str) at every time step"
                )
        raw = objects.astype(str)
    empty = np.flatnonzero(np.char.str_len(np.char.strip(raw)) == 0)
    if empty.size:
        raise DataError(
            f"{who}: labels[{variable!r}] is empty at step {empty[0]} ({empty.size} step(s) in "
            "all); label every time step with the active MP's name"
        )
    return raw.copy()


def mp_catalogue(demos: Sequence[Demonstration]) -> dict[str, list[str]]:
    """Sorted MP names seen per control variable across ``demos``."""
    names: dict[str, set[str]] = {}
    for demo in demos:
        for variable, labels in demo.labels.items():
            names.setdefault(variable, set()).update(np.unique(labels).tolist())
    return {variable: sorted(names[variable]) for variable in sorted(names)}


def mp_sequences(demo: Demonstration) -> dict[str, list[str]]:
    """Variable -> the MPs ``demo`` runs, in order (one entry per activation)."""
    return {v: [a.mp for a in demo.segments(v)] for v in demo.variables}


class DemonstrationLog:
    """A demonstration being recorded by a scripted demonstrator, one sample per control tick.

    :meth:`to_demonstration` validates it into a :class:`Demonstration`.
    """

    def __init__(self, variables: Sequence[str]) -> None:
        self.variables = list(variables)
        self.time: list[float] = []
        self.features: list[np.ndarray] = []
        self.labels: dict[str, list[str]] = {v: [] for v in self.variables}

    def append(self, t: float, x: ArrayLike, active: Mapping[str, str]) -> None:
        """Record time ``t`` [s], features ``x`` (d,) and the active MP of every variable."""
        self.time.append(t)
        self.features.append(np.array(x, dtype=np.float64))
        for v in self.variables:
            self.labels[v].append(active[v])

    def to_demonstration(
        self,
        feature_names: Sequence[str] | None = None,
        name: str | None = None,
        metadata: Mapping[str, MetadataValue] | None = None,
    ) -> Demonstration:
        """The samples so far as a validated :class:`Demonstration`."""
        return Demonstration(
            time=np.array(self.time),
            features=np.array(self.features),
            labels={v: np.array(self.labels[v]) for v in self.variables},
            feature_names=None if feature_names is None else list(feature_names),
            name=name,
            metadata=None if metadata is None else dict(metadata),
        )


__all__ = [
    "Activation",
    "Demonstration",
    "DemonstrationLog",
    "mp_catalogue",
    "mp_sequences",
]
