"""Every synthetic world by name: the one table the benchmarks, the comparison and the tests read.

Adding a world is one module implementing :class:`~cpmp.worlds.protocol.World` plus one line in
:data:`WORLDS`; every benchmark then runs it. A *family* (the procedural world) is a generator
of tasks: ``make(task=i)`` is its ``i``-th member, and its results are summarised over members.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TypeAlias

from cpmp.config.validation import OptionValue
from cpmp.errors import ConfigError
from cpmp.worlds.protocol import World

WorldOption: TypeAlias = "OptionValue | Mapping[str, OptionValue]"
"""A world's option: a field of its task (a number, a range, ...), or a mapping of such fields
(the paced relay's ``demo``, ``robot`` and ``relay``)."""


@dataclass(frozen=True)
class WorldEntry:
    """One registered world.

    Attributes:
        make: ``make(**options) -> World``: the world with its task options (a bad option
            raises :class:`~cpmp.errors.ConfigError`).
        summary: one line on what the world measures.
        family: a generator of tasks (``make(task=i)`` is member ``i``); its results are
            summarised over members.
        reactive: its switches are decided by events during execution (retry loops).
    """

    make: Callable[..., World]
    summary: str
    family: bool = False
    reactive: bool = False


def _lazy(module: str, name: str) -> Callable[..., World]:
    """``module.name(**options)``, imported when first called (keeps this table cheap)."""

    def make(**options: WorldOption) -> World:
        import importlib

        return getattr(importlib.import_module(module), name)(**options)

    make.__qualname__ = f"{module}.{name}"
    return make


WORLDS: dict[str, WorldEntry] = {
    "two_point": WorldEntry(
        _lazy("cpmp.worlds.two_point.registered", "TwoPointWorld"),
        "two points on a line; a context feature picks sequential or parallel",
    ),
    "relay": WorldEntry(
        _lazy("cpmp.worlds.relay.registered", "RelayWorld"),
        "a hand-over in the plane: a cross-variable wait on a grip force",
    ),
    "paced_relay": WorldEntry(
        _lazy("cpmp.worlds.relay.registered", "PacedRelayWorld"),
        "the relay with MPs at varied speeds and holds mid-MP",
    ),
    "repetition": WorldEntry(
        _lazy("cpmp.worlds.repetition.registered", "RepetitionWorld"),
        "a scoop-pour cycle repeated as the soup left says; a helper holds across it",
    ),
    "peg": WorldEntry(
        _lazy("cpmp.worlds.peg.registered", "PegWorld"),
        "peg-in-hole retried after jams read from a force; a holder holds across the retries",
        reactive=True,
    ),
    "slip": WorldEntry(
        _lazy("cpmp.worlds.slip.registered", "SlipWorld"),
        "a pick that may slip mid-lift and is retried; the other hand holds a drawer open",
        reactive=True,
    ),
    "procedural": WorldEntry(
        _lazy("cpmp.worlds.procedural.registered", "ProceduralWorld"),
        "random concurrent tasks from a seed: loops, waits, branches, distractors",
        family=True,
        reactive=True,
    ),
}
"""The registered worlds, by name."""


def world_names(*, family: bool | None = None) -> tuple[str, ...]:
    """The registered names (``family``: only families, or only single worlds)."""
    return tuple(n for n, e in WORLDS.items() if family is None or e.family == family)


def entry(name: str) -> WorldEntry:
    """The entry of ``name``.

    Raises:
        ConfigError: an unknown world (the message lists the known ones).
    """
    found = WORLDS.get(name)
    if found is None:
        raise ConfigError(f"unknown world {name!r}; registered: {', '.join(WORLDS)}")
    return found


def make_world(name: str, options: Mapping[str, WorldOption] | None = None) -> World:
    """The world ``name`` built with ``options`` (its task's fields).

    Raises:
        ConfigError: an unknown world or a bad option.
    """
    return _make(name, entry(name), dict(options or {}))


def _make(name: str, found: WorldEntry, options: dict[str, WorldOption]) -> World:
    """``found.make(**options)``, an unknown option a :class:`ConfigError` naming the world."""
    try:
        return found.make(**options)
    except TypeError as err:
        raise ConfigError(
            f"bad task option for the {name} world ({err}); its options are the parameters of "
            f"{found.make.__qualname__}"
        ) from err


def members(
    name: str, n_tasks: int, options: Mapping[str, WorldOption] | None = None
) -> list[World]:
    """The worlds a benchmark runs for ``name``: itself, or a family's first ``n_tasks`` members.

    Raises:
        ConfigError: an unknown world or a bad option.
    """
    found = entry(name)
    if not found.family:
        return [_make(name, found, dict(options or {}))]
    return [_make(name, found, {**dict(options or {}), "task": i}) for i in range(n_tasks)]
