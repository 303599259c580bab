"""The random task of a procedural world: one :class:`TaskSpec` per generator seed.

A task has 2–3 control variables, each a point (1-D or 2-D) with 3–5 MPs; every MP is a
first-order attractor to its own *nominal goal* (jittered per context by the world). Each
variable runs a *chain* of MPs; the generator adds at random

* a **branch** decided by the ``context`` feature (strategies ``a``/``b``): one variable starts
  with one of two MPs, or ends with one of two MPs;
* a **loop** ``try -> (undo -> try)* -> next`` on one variable: a failing try jams short of its
  goal and a ``force`` feature rises, so the count of failures (0–2, hidden per context) is
  decided during execution;
* a **hold** through the loop: another variable's ``hold`` MP leaves only once the loop's try
  succeeded, and the loop's first try waits until that variable is at its hold goal;
* a **wait**: one variable's last MP starts only once another variable is at its final goal;
* 1–3 **distractor** features that vary between episodes and decide nothing.

Decidable by construction: every switch is a :class:`Guard` on the switching variable's own
MP and the current features only (own point within ``TOLERANCE`` of the source MP's nominal
goal, a force level, the context's side, another variable's point within ``TOLERANCE`` of one
of its nominal goals), so two demonstrated states with different decisions differ in the
features. Goals are placed so that the guards mean what they say: the goals of a variable are
at least ``SEPARATION`` apart, a jammed try stops ``JAM_DISTANCE`` short of its goal (outside the
tolerance), and no path of a variable passes within ``CLEARANCE`` of a goal another variable
waits on (so a point in transit never looks like a point that arrived).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cpmp.errors import ConfigError, UnknownMPError

STRATEGIES: tuple[str, str] = ("a", "b")
"""The two strategies every task's context feature decides."""
TOLERANCE = 0.07
"""A point is *at* a goal within this distance of the goal's nominal position [feature units]."""
MAX_GOAL_JITTER = 0.035
"""The largest per-axis goal jitter that keeps every jittered goal inside the tolerance."""
MAX_START_JITTER = 0.05
"""The largest per-axis start jitter the clearance allows for."""
SEPARATION = 0.38
"""Least distance between two nominal goals of one variable, and a start and its first goal."""
CLEARANCE = 3.0 * TOLERANCE
"""Least distance between a waited-on goal and any path of its variable not ending there."""
JAM_DISTANCE = 0.17
"""A failing try is blocked this far from its (jittered) goal."""
FORCE_MAX = 1.6
"""The force a jammed try settles to."""
FORCE_RATE = 15.0
"""Rate [1/s] at which the force follows its target (``FORCE_MAX`` jammed, else 0)."""
FAIL_LEVEL = 1.0
"""A try fails (``try -> undo``) once the force exceeds this level."""
CLEAR_LEVEL = 0.3
"""An undo is over (``undo -> try``) at its goal once the force is below this level."""
CONTEXT_SPLIT = 1.0
"""The context feature is below this for strategy ``a`` and at or above it for ``b``."""
LOW, HIGH = 0.1, 1.9
"""The range of nominal goals and starts per axis."""
GAIN_RANGE = (3.0, 6.0)
"""Attractor gains K [1/s] are drawn uniformly from this range."""
_SALT = 0x9E0C
"""Mixed into the generator seed (task seeds and context seeds draw different streams)."""
_DRAWS = 2000
"""Task draws tried per seed before giving up (none needed more than a few dozen)."""
_PLACEMENTS = 300
"""Goal placements tried per variable before the task draw is rejected."""


@dataclass(frozen=True)
class MPSpec:
    """One movement primitive: a first-order attractor to ``goal``.

    Attributes:
        name: unique over the task (prefixed by its variable).
        goal: nominal goal ``(dim,)`` in feature units (jittered per context).
        role: ``move``, ``try``, ``undo`` or ``hold``.
    """

    name: str
    goal: tuple[float, ...]
    role: str = "move"


@dataclass(frozen=True)
class Guard:
    """When a variable switches from ``source`` to ``target``: all conditions hold.

    Attributes:
        source: the MP switched from.
        target: the MP switched to.
        arrive: the variable's point is within ``TOLERANCE`` of ``source``'s nominal goal.
        force_above: the variable's force feature exceeds this level (``None``: no condition).
        force_below: the variable's force feature is below this level (``None``: none).
        strategy: the context feature's side (``a``/``b``; ``None``: either).
        wait_variable: another variable that must be at one of ``wait_mps``' nominal goals.
        wait_mps: MPs of ``wait_variable`` (any of them).
    """

    source: str
    target: str
    arrive: bool = True
    force_above: float | None = None
    force_below: float | None = None
    strategy: str | None = None
    wait_variable: str | None = None
    wait_mps: tuple[str, ...] = ()


@dataclass(frozen=True)
class VariableSpec:
    """One control variable.

    Attributes:
        name: ``v0``, ``v1``, ``v2``.
        dim: 1 or 2 (the point's axes).
        gain: attractor gain K [1/s].
        start: nominal start ``(dim,)``.
        mps: its MPs (3–5).
        chain: the MPs it runs in order for strategy ``a`` with no failure (a loop's ``try``
            once, no ``undo``).
        guards: its switches, in the order they are tested.
    """

    name: str
    dim: int
    gain: float
    start: tuple[float, ...]
    mps: tuple[MPSpec, ...]
    chain: tuple[str, ...]
    guards: tuple[Guard, ...]

    def mp(self, name: str) -> MPSpec:
        """The MP ``name``.

        Raises:
            UnknownMPError: not one of this variable's MPs.
        """
        for mp in self.mps:
            if mp.name == name:
                return mp
        raise UnknownMPError(
            f"{self.name}: unknown MP {name!r}; it knows {', '.join(m.name for m in self.mps)}"
        )

    @property
    def edges(self) -> set[tuple[str, str]]:
        """Every switch ``(source, target)`` its guards allow."""
        return {(g.source, g.target) for g in self.guards}


@dataclass(frozen=True)
class BranchSpec:
    """The strategy decision.

    Attributes:
        variable: the variable that branches.
        kind: ``start`` (two initial MPs) or ``end`` (two last MPs).
        mps: its MP for strategy ``a`` and for ``b``.
    """

    variable: str
    kind: str
    mps: tuple[str, str]


@dataclass(frozen=True)
class LoopSpec:
    """The ``try -> (undo -> try)* -> next`` loop.

    Attributes:
        variable: the looping variable.
        try_mp: the try (a failing one jams and the force rises).
        undo_mp: the undo (back to its own goal, then try again).
        hold_variable: the variable holding through the loop (``None``: none).
    """

    variable: str
    try_mp: str
    undo_mp: str
    hold_variable: str | None = None


@dataclass(frozen=True)
class WaitSpec:
    """A cross-variable wait: ``variable``'s ``mp`` starts only once ``other`` is at a goal.

    Attributes:
        variable: the waiting variable.
        mp: the MP(s) it starts after the wait (``|``-joined when two, by strategy).
        other: the variable waited on.
        other_mps: the MPs of ``other`` whose goals end the wait.
        kind: ``final`` (``other`` reached its last MP), ``loop`` (the loop's first try waits
            for the holder) or ``hold`` (the holder leaves when the loop ends).
    """

    variable: str
    mp: str
    other: str
    other_mps: tuple[str, ...]
    kind: str


@dataclass(frozen=True)
class TaskSpec:
    """One member of the procedural family (:func:`generate`).

    Attributes:
        seed: the generator seed (the member's index).
        variables: the control variables, in the labels' order.
        branch: the strategy decision.
        loop: the retry loop (``None``: none).
        waits: the cross-variable waits.
        n_distractors: the distractor features (1–3).
        feature_names: positions (``<v>_x``, ``<v>_y``), the loop's ``<v>_force``, ``context``,
            ``distractor_<j>``, in this order; all in about [0, 2].
    """

    seed: int
    variables: tuple[VariableSpec, ...]
    branch: BranchSpec
    loop: LoopSpec | None
    waits: tuple[WaitSpec, ...]
    n_distractors: int
    feature_names: tuple[str, ...]

    @property
    def variable_names(self) -> tuple[str, ...]:
        """The variables' names."""
        return tuple(v.name for v in self.variables)

    def variable(self, name: str) -> VariableSpec:
        """The variable ``name``.

        Raises:
            UnknownMPError: not one of the task's variables.
        """
        for v in self.variables:
            if v.name == name:
                return v
        raise UnknownMPError(
            f"unknown control variable {name!r}; the task has {self.variable_names}"
        )

    def initial_mps(self, strategy: str) -> dict[str, str]:
        """Variable -> its first MP under ``strategy``."""
        return {v: seq[0] for v, seq in self.sequences(strategy, 0).items()}

    def final_mps(self, strategy: str) -> dict[str, str]:
        """Variable -> its last MP under ``strategy``."""
        return {v: seq[-1] for v, seq in self.sequences(strategy, 0).items()}

    def sequences(self, strategy: str, failures: int) -> dict[str, list[str]]:
        """Variable -> the MPs the demonstrator runs, in order, under ``strategy``.

        Args:
            strategy: ``a`` or ``b``.
            failures: failed tries of the loop before the one that succeeds (ignored without).

        Raises:
            ConfigError: an unknown strategy.
        """
        check_strategy(strategy)
        out: dict[str, list[str]] = {}
        for v in self.variables:
            seq = list(v.chain)
            b = self.branch
            if b.variable == v.name and strategy == "b":
                seq[0 if b.kind == "start" else -1] = b.mps[1]
            if self.loop is not None and self.loop.variable == v.name:
                i = seq.index(self.loop.try_mp)
                seq[i + 1 : i + 1] = [self.loop.undo_mp, self.loop.try_mp] * failures
            out[v.name] = seq
        return out

    def describe(self) -> list[str]:
        """A few readable lines: variables, MPs, branch, loop, waits, distractors."""
        lines = [
            f"procedural task {self.seed}: {len(self.variables)} variables, "
            f"{len(self.feature_names)} features ({self.n_distractors} distractors)"
        ]
        for v in self.variables:
            chain = " -> ".join(v.chain)
            lines.append(f"  {v.name} ({v.dim}-D, K={v.gain:.2f}/s, {len(v.mps)} MPs): {chain}")
        b = self.branch
        lines.append(
            f"  strategy a/b (context < / >= {CONTEXT_SPLIT:g}): {b.variable} {b.kind}s with "
            f"{b.mps[0]} / {b.mps[1]}"
        )
        if self.loop is not None:
            lp = self.loop
            lines.append(
                f"  loop: {lp.variable} {lp.try_mp} -> ({lp.undo_mp} -> {lp.try_mp})* -> next, "
                f"0-2 failures seen in {lp.variable}_force"
            )
        for w in self.waits:
            lines.append(
                f"  wait ({w.kind}): {w.variable} starts {w.mp} once {w.other} is at "
                f"{'/'.join(w.other_mps)}"
            )
        return lines


def check_strategy(strategy: object) -> str:
    """``strategy`` if it is ``a`` or ``b``.

    Raises:
        ConfigError: any other value.
    """
    if strategy not in STRATEGIES:
        raise ConfigError(f"a procedural task's strategy is one of {STRATEGIES}, got {strategy!r}")
    return str(strategy)


def check_seed(seed: object, what: str) -> int:
    """``seed`` if it is a non-negative integer (``bool`` is not one).

    Raises:
        ConfigError: any other value.
    """
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ConfigError(f"{what} must be a non-negative integer, got {seed!r}")
    return int(seed)


def generate(task: int) -> TaskSpec:
    """The procedural task of generator seed ``task`` (deterministic per seed).

    Args:
        task: the member's index, a non-negative integer.

    Returns:
        The task.

    Raises:
        ConfigError: ``task`` is not a non-negative integer.
    """
    seed = check_seed(task, "ProceduralWorld.task")
    rng = np.random.default_rng(np.random.SeedSequence([seed, _SALT]))
    for _ in range(_DRAWS):
        spec = _draw(rng, seed)
        if spec is not None:
            return spec
    raise RuntimeError(f"no procedural task for seed {seed} in {_DRAWS} draws")  # pragma: no cover


# ------------------------------------------------------------------------------- the draw
@dataclass(frozen=True)
class _Layout:
    """One variable's roles before its goals are placed.

    Attributes:
        chain: main chain MP names (branch slot holding the ``a`` MP).
        extra: further MPs ``(name, role)`` (branch alternative, undo).
        roles: chain MP name -> role.
    """

    chain: tuple[str, ...]
    extra: tuple[tuple[str, str], ...]
    roles: dict[str, str]


def _draw(rng: np.random.Generator, seed: int) -> TaskSpec | None:
    """One random draw of a task, or ``None`` when its roles or goals do not fit."""
    n_vars = int(rng.integers(2, 4))
    names = [f"v{i}" for i in range(n_vars)]
    dims = [int(d) for d in rng.integers(1, 3, n_vars)]
    gains = [float(k) for k in rng.uniform(*GAIN_RANGE, n_vars)]
    n_mps = [int(n) for n in rng.integers(3, 6, n_vars)]
    n_distractors = int(rng.integers(1, 4))
    branch_var = int(rng.integers(n_vars))
    branch_kind = "start" if rng.random() < 0.5 else "end"
    loop_var = int(rng.integers(n_vars)) if rng.random() < 0.75 else None
    hold_var = None
    if loop_var is not None and rng.random() < 0.6:
        others = [i for i in range(n_vars) if i != loop_var]
        hold_var = others[int(rng.integers(len(others)))]
    wait_pair = None
    if rng.random() < 0.6:
        w, d = (int(i) for i in rng.permutation(n_vars)[:2])
        wait_pair = (w, d)

    layouts: list[_Layout] = []
    for i, v in enumerate(names):
        layout = _layout(
            rng,
            v,
            n_mps[i],
            branch=branch_kind if i == branch_var else None,
            loop=i == loop_var,
            handshake=i == loop_var and hold_var is not None,
            hold=i == hold_var,
            waits=wait_pair is not None and i == wait_pair[0],
        )
        if layout is None:
            return None
        layouts.append(layout)

    def last_mps(i: int) -> tuple[str, ...]:
        tail = (layouts[i].chain[-1],)
        if i == branch_var and branch_kind == "end":
            tail += (f"{names[i]}_end_b",)
        return tail

    loop = None
    waits: list[WaitSpec] = []
    guards: list[list[Guard]] = []
    for i, v in enumerate(names):
        lay = layouts[i]
        try_mp = next((m for m, r in lay.roles.items() if r == "try"), None)
        hold_mp = next((m for m, r in lay.roles.items() if r == "hold"), None)
        wait_on: dict[str, tuple[str, tuple[str, ...]]] = {}  # target MP -> (other, its MPs)
        loop_wait: tuple[str, tuple[str, ...]] | None = None
        hold_wait: tuple[str, tuple[str, ...]] | None = None
        if try_mp is not None:
            loop = LoopSpec(v, try_mp, f"{v}_undo", None if hold_var is None else names[hold_var])
            if hold_var is not None:
                other = layouts[hold_var]
                h = next(m for m, r in other.roles.items() if r == "hold")
                loop_wait = (names[hold_var], (h,))
                wait_on[try_mp] = loop_wait
                waits.append(WaitSpec(v, try_mp, names[hold_var], (h,), "loop"))
        if hold_mp is not None and loop_var is not None:  # a holder only comes with a loop
            hold_wait = (names[loop_var], (f"{names[loop_var]}_try",))
            nxt = lay.chain[lay.chain.index(hold_mp) + 1]
            waits.append(
                WaitSpec(v, _joined(nxt, v, i == branch_var, branch_kind, lay), *hold_wait, "hold")
            )
        if wait_pair is not None and i == wait_pair[0]:
            d = wait_pair[1]
            target = lay.chain[-1]
            final_wait = (names[d], last_mps(d))
            wait_on[target] = final_wait
            waits.append(
                WaitSpec(
                    v, _joined(target, v, i == branch_var, branch_kind, lay), *final_wait, "final"
                )
            )
        guards.append(_guards(v, lay, i == branch_var, branch_kind, wait_on, hold_wait))

    goals: list[dict[str, tuple[float, ...]]] = []
    starts: list[tuple[float, ...]] = []
    waited = _waited(names, guards)
    for i, v in enumerate(names):
        placed = _place(rng, dims[i], layouts[i], guards[i], waited[v])
        if placed is None:
            return None
        goals.append(placed[0])
        starts.append(placed[1])

    variables = []
    features: list[str] = []
    for i, v in enumerate(names):
        lay = layouts[i]
        order = list(lay.chain) + [m for m, _ in lay.extra]
        roles = {**lay.roles, **dict(lay.extra)}
        mps = tuple(MPSpec(m, goals[i][m], roles.get(m, "move")) for m in order)
        variables.append(
            VariableSpec(v, dims[i], gains[i], starts[i], mps, lay.chain, tuple(guards[i]))
        )
        features += [f"{v}_x", f"{v}_y"][: dims[i]]
    if loop is not None:
        features.append(f"{loop.variable}_force")
    features.append("context")
    features += [f"distractor_{j}" for j in range(n_distractors)]
    bv = layouts[branch_var]
    a_mp = bv.chain[0] if branch_kind == "start" else bv.chain[-1]
    branch = BranchSpec(
        names[branch_var], branch_kind, (a_mp, f"{names[branch_var]}_{branch_kind}_b")
    )
    return TaskSpec(
        seed=seed,
        variables=tuple(variables),
        branch=branch,
        loop=loop,
        waits=tuple(waits),
        n_distractors=n_distractors,
        feature_names=tuple(features),
    )


def _joined(target: str, v: str, branches: bool, kind: str, lay: _Layout) -> str:
    """``target``, or ``target|<alternative>`` when it is the end branch's slot of ``v``."""
    if branches and kind == "end" and target == lay.chain[-1]:
        return f"{target}|{v}_end_b"
    return target


def _layout(
    rng: np.random.Generator,
    v: str,
    n_mps: int,
    *,
    branch: str | None,
    loop: bool,
    handshake: bool,
    hold: bool,
    waits: bool,
) -> _Layout | None:
    """The chain of variable ``v`` with its roles, or ``None`` when they do not fit ``n_mps``.

    The chain has ``k = n_mps - (branch alternative) - (undo)`` MPs (at least 2); a loop's try
    is not the branch's start slot and not the last MP (a handshake's try has an MP before it);
    a hold is not the start slot nor last; the source of a final wait's edge (index ``k-2``) is
    neither try nor hold.
    """
    k = n_mps - (branch is not None) - loop
    if k < 2:
        return None
    lo = 1 if branch == "start" else 0
    hi = k - 3 if waits else k - 2  # try/hold index bound: after it an MP, then maybe the wait
    roles: dict[str, str] = {}
    chain = [f"{v}_m{j}" for j in range(k)]
    if loop:
        first = max(lo, 1 if handshake else 0)
        if first > hi:
            return None
        j = int(rng.integers(first, hi + 1))
        chain[j] = f"{v}_try"
        roles[chain[j]] = "try"
    if hold:
        if lo > hi:
            return None
        j = int(rng.integers(lo, hi + 1))
        chain[j] = f"{v}_hold"
        roles[chain[j]] = "hold"
    extra: list[tuple[str, str]] = []
    if branch == "start":
        chain[0] = f"{v}_start_a"
        extra.append((f"{v}_start_b", "move"))
    elif branch == "end":
        chain[-1] = f"{v}_end_a"
        extra.append((f"{v}_end_b", "move"))
    if loop:
        extra.append((f"{v}_undo", "undo"))
    return _Layout(tuple(chain), tuple(extra), roles)


def _guards(
    v: str,
    lay: _Layout,
    branches: bool,
    kind: str,
    wait_on: dict[str, tuple[str, tuple[str, ...]]],
    hold_wait: tuple[str, tuple[str, ...]] | None,
) -> list[Guard]:
    """The guards of variable ``v`` (see :class:`Guard`), failure guards first."""
    out: list[Guard] = []
    chain = lay.chain
    k = len(chain)
    for j in range(k - 1):
        sources = [chain[j]]
        if branches and kind == "start" and j == 0:
            sources.append(f"{v}_start_b")
        targets: list[tuple[str, str | None]] = [(chain[j + 1], None)]
        if branches and kind == "end" and j + 1 == k - 1:
            targets = [(chain[j + 1], "a"), (f"{v}_end_b", "b")]
        for s in sources:
            role = lay.roles.get(s, "move")
            if role == "try":
                out.append(Guard(s, f"{v}_undo", arrive=False, force_above=FAIL_LEVEL))
                out.append(Guard(f"{v}_undo", s, force_below=CLEAR_LEVEL))
            for t, strategy in targets:
                wait = wait_on.get(chain[j + 1]) or (hold_wait if role == "hold" else None)
                out.append(
                    Guard(
                        s,
                        t,
                        strategy=strategy,
                        wait_variable=None if wait is None else wait[0],
                        wait_mps=() if wait is None else wait[1],
                    )
                )
    return out


def _waited(names: Sequence[str], guards: Sequence[Sequence[Guard]]) -> dict[str, set[str]]:
    """Variable -> its MPs whose goals another variable's guard waits on."""
    out: dict[str, set[str]] = {v: set() for v in names}
    for gs in guards:
        for g in gs:
            if g.wait_variable is not None:
                out[g.wait_variable].update(g.wait_mps)
    return out


def _place(
    rng: np.random.Generator,
    dim: int,
    lay: _Layout,
    guards: Sequence[Guard],
    waited: set[str],
) -> tuple[dict[str, tuple[float, ...]], tuple[float, ...]] | None:
    """Nominal goals and start of one variable, or ``None`` when no placement was found.

    Goals are ``SEPARATION`` apart (1-D: sorted gaps of at least ``SEPARATION``, shuffled over
    the MPs); the start is ``SEPARATION`` from every initial MP's goal; every path segment
    (start -> initial goal, source goal -> target goal, a jammed try -> undo) keeps
    ``CLEARANCE`` from every waited-on goal it neither starts nor ends at.
    """
    mps = list(lay.chain) + [m for m, _ in lay.extra]
    n = len(mps)
    initial = [lay.chain[0]] + [m for m, _ in lay.extra if m.endswith("_start_b")]
    try_mp = next((m for m, r in lay.roles.items() if r == "try"), None)
    for _ in range(_PLACEMENTS):
        if dim == 1:
            slack = (HIGH - LOW) - (n - 1) * SEPARATION
            base = np.sort(rng.uniform(0.0, slack, n)) + LOW + SEPARATION * np.arange(n)
            pts = rng.permutation(base)[:, None]
        else:
            pts = rng.uniform(LOW, HIGH, (n, 2))
            d = np.linalg.norm(pts[:, None] - pts[None], axis=-1) + np.eye(n) * 9
            if d.min() < SEPARATION:
                continue
        goal = {m: pts[j] for j, m in enumerate(mps)}
        start = rng.uniform(LOW, HIGH, dim)
        if min(np.linalg.norm(start - goal[m]) for m in initial) < SEPARATION:
            continue
        if _clear(start, goal, initial, guards, waited, try_mp):
            return {m: tuple(float(c) for c in g) for m, g in goal.items()}, tuple(
                float(c) for c in start
            )
    return None


def _clear(
    start: np.ndarray,
    goal: dict[str, np.ndarray],
    initial: Sequence[str],
    guards: Sequence[Guard],
    waited: set[str],
    try_mp: str | None,
) -> bool:
    """Whether every path segment keeps ``CLEARANCE`` from the waited-on goals (see _place)."""
    if not waited:
        return True
    segments: list[tuple[np.ndarray, np.ndarray, str | None, str]] = [
        (start, goal[m], None, m) for m in initial
    ]
    approach: dict[str, np.ndarray] = {"start": start} if try_mp in initial else {}
    for g in guards:
        if g.target == try_mp:
            approach.setdefault(g.source, goal[g.source])
    for g in guards:
        if g.force_above is not None and try_mp is not None:  # jammed try -> undo
            for p in approach.values():
                jam = goal[try_mp] + JAM_DISTANCE * _unit(p - goal[try_mp])
                # the undo leaves the jam point away from the try's goal, never past it
                if try_mp in waited and _segment_distance(goal[try_mp], jam, goal[g.target]) < (
                    JAM_DISTANCE - 1e-9
                ):
                    return False
                segments.append((jam, goal[g.target], try_mp, g.target))
        else:
            segments.append((goal[g.source], goal[g.target], g.source, g.target))
    for w in waited:
        for a, b, src, dst in segments:
            if w in (src, dst):
                continue
            if _segment_distance(goal[w], a, b) < CLEARANCE:
                return False
    return True


def _unit(v: np.ndarray) -> np.ndarray:
    """``v`` scaled to length 1 (``v`` is never zero: goals are apart)."""
    return v / float(np.linalg.norm(v))


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Distance from point ``p`` to the segment ``a``–``b`` (all ``(dim,)``)."""
    ab = b - a
    u = float(np.clip(np.dot(p - a, ab) / max(float(np.dot(ab, ab)), 1e-12), 0.0, 1.0))
    return float(np.linalg.norm(p - (a + u * ab)))


def distance(p: Sequence[float], q: Sequence[float]) -> float:
    """Euclidean distance of two points of 1 or 2 axes (plain floats: fast on ticks)."""
    if len(p) == 1:
        return abs(p[0] - q[0])
    return math.hypot(p[0] - q[0], p[1] - q[1])
