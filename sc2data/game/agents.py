"""BuildMarines agents as pysc2 ``BaseAgent``s, and a registry to make them by name.

Every agent reads only what pysc2 observes (screen layers, ``player``, ``single_select``,
``multi_select``, ``build_queue``, ``available_actions``) and answers with pysc2
``actions.FunctionCall``s, so the same agent plays the embedded simulator and the real game.

* ``random``: pysc2's own ``RandomAgent`` (uniform over available functions and arguments). Its
  policy code is pysc2's, unchanged; only its numpy RNG is private (see :class:`SeededRandomAgent`).
* ``reduced-random``: the paper's random agent over a reduced action set — each time its previous
  macro action ends it picks one uniformly (train SCV, build a depot, build a barracks, train a
  marine, send idle workers to mine, no-op) and plays it out as pysc2 selection and command calls.
* ``macro-rules``: the scripted agent's rules played with the reduced-random agent's six macros
  (random sites, no kills): what the macro space of ``sc2data.rl`` allows a policy.
* ``scripted``: a build order — SCVs, depots ahead of supply, several barracks, marines nonstop,
  idle SCVs back to mining, and, near the supply ceiling, its own marines killed with Attack_screen
  (as the published scripted agent does) to make room for more.

Agents of other rooms: a name ``kind:ARG`` (``policy:RUN``, a trained ``sc2data rl`` policy)
is resolved through :data:`AGENT_KINDS`, which the room that defines the kind fills when it is
imported (:func:`register_agent_kind`; ``sc2data.rl`` registers ``policy``). The game room plays
agents but must not import the rooms above it (``tests/test_layout.py``): a registry filled from
above keeps the import arrow pointing down, and the factory a kind returns is a picklable object
of its own room, so a spawned rollout worker that unpickles it imports (and registers) that room
itself.

Macros are generators of calls over successive agent steps; each call is checked against
``available_actions`` and, when unavailable, the macro is dropped and the agent plays ``no_op``.
Lack of minerals is not visible there (the game refuses such orders silently), so the scripted
agent checks ``player.minerals`` itself.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Generator, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sc2data._pysc2 import (  # first: it makes pysc2 importable on 3.11
    actions,
    features,
    units,
)

from pysc2.agents import base_agent, random_agent  # isort: skip
from sc2data.game.screen import ScreenView
from sc2data.ground.errors import Sc2DataError

_F = actions.FUNCTIONS
_P = features.Player
NO_OP = _F.no_op()

Macro = Iterator[actions.FunctionCall]
Selecting = Generator[actions.FunctionCall, None, bool]
"""A sub-macro that selects something; it returns whether the selection is as wanted."""


class _NumpyWithOwnRandom:
    """Stands in for the ``numpy`` module inside pysc2's ``random_agent``, with our RNG."""

    def __init__(self, rng: np.random.RandomState) -> None:
        self.random = rng

    def __getattr__(self, name: str) -> Any:
        return getattr(np, name)


class SeededRandomAgent(random_agent.RandomAgent):
    """pysc2's ``RandomAgent`` with a private, seeded numpy RNG.

    ``RandomAgent.step`` draws from ``numpy.random`` (the global legacy RNG). For the duration
    of each of our steps, the ``numpy`` name in pysc2's ``random_agent`` module is pointed at a
    stand-in whose ``random`` is our own ``RandomState(seed)``, so the agent plays exactly what
    ``numpy.random.seed(seed)`` followed by pysc2's agent would, yet neither disturbs nor is
    disturbed by anyone else's use of the global RNG. (Swapping the global state in and out
    instead costs ~10× the agent's own step.) The policy is pysc2's code, unchanged.
    """

    def __init__(self, seed: int) -> None:
        super().__init__()
        self._numpy = _NumpyWithOwnRandom(np.random.RandomState(seed))

    def step(self, obs: Any) -> actions.FunctionCall:
        module = random_agent.numpy
        random_agent.numpy = self._numpy
        try:
            return super().step(obs)
        finally:
            random_agent.numpy = module


class MacroAgent(base_agent.BaseAgent):
    """Plays macro actions — generators of pysc2 calls over successive steps — one at a time."""

    def __init__(self, seed: int) -> None:
        super().__init__()
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.view: ScreenView | None = None
        self._macro: Macro | None = None

    def reset(self) -> None:
        super().reset()
        self._macro = None

    def step(self, obs: Any) -> actions.FunctionCall:
        super().step(obs)
        self.view = ScreenView(obs)
        for _ in range(2):  # finish the running macro, then maybe start the next in this step
            if self._macro is None:
                self._macro = self.next_macro()
            try:
                call = next(self._macro)
            except StopIteration:
                self._macro = None
                continue
            if not self.view.can(call):
                self._macro = None
                return NO_OP
            return call
        return NO_OP

    def next_macro(self) -> Macro:
        """The macro to play now that none is running."""
        raise NotImplementedError

    # --- building blocks: generators that yield calls and return whether they succeeded ---

    def _v(self) -> ScreenView:
        assert self.view is not None
        return self.view

    def select_unit(self, unit_type: int, xy: tuple[int, int] | None) -> Selecting:
        """Select the unit under pixel ``xy`` alone (skipped if it is selected already)."""
        if xy is None:
            return False
        v = self._v()
        if v.selected_type() == unit_type and v.selected[xy[1], xy[0]]:
            return True
        yield _F.select_point("select", xy)
        return self._v().selected_type() == unit_type

    def select_scv(self) -> Selecting:
        """Select one SCV off the mineral line, clicked at random (any SCV if none mines).

        Builders come from the mineral line, as players take them; idle SCVs are left to the
        gather macro. Always a fresh selection: the SCV still selected may be building what we
        ordered last.
        """
        v = self._v()
        scvs = v.own(units.Terran.SCV)
        miners = scvs & v.near(v.minerals(), 3)
        xy = v.random_pixel(miners if miners.any() else scvs, self.rng)
        if xy is None:
            return False
        yield _F.select_point("select", xy)
        return self._v().selected_type() == units.Terran.SCV

    def train_scv(self) -> Macro:
        v = self._v()
        ok = yield from self.select_unit(units.Terran.CommandCenter,
                                         v.centre_pixel(v.own(units.Terran.CommandCenter)))
        if ok:
            yield _F.Train_SCV_quick("now")

    def build(self, function: Any, spot: Callable[[ScreenView, int], tuple[int, int] | None],
              size: int) -> Macro:
        ok = yield from self.select_scv()
        if not ok:
            return
        xy = spot(self._v(), size)
        if xy is not None:
            yield function("now", xy)

    def train_marine(self, xy: tuple[int, int] | None) -> Macro:
        ok = yield from self.select_unit(units.Terran.Barracks, xy)
        if ok:
            yield _F.Train_Marine_quick("now")

    def gather(self) -> Macro:
        """Send every idle SCV to the mineral field nearest the Command Center."""
        if self._v().player[_P.idle_worker_count] == 0:
            return
        yield _F.select_idle_worker("select_all")
        v = self._v()
        xy = v.nearest_pixel(v.minerals(), v.centre_pixel(v.own(units.Terran.CommandCenter)))
        if xy is not None:
            yield _F.Harvest_Gather_screen("now", xy)

    def kill_marine(self) -> Macro:
        """Select the army and have it attack one of its own marines."""
        yield _F.select_army("select")
        v = self._v()
        xy = v.random_pixel(v.own(units.Terran.Marine), self.rng)
        if xy is not None:
            yield _F.Attack_screen("now", xy)

    def no_op(self) -> Macro:
        yield NO_OP

    def save_up(self, minerals: int, then: Macro, patience: int) -> Macro:
        """Wait (no_op) until ``minerals`` are banked, then play ``then``; give up after
        ``patience`` steps. The game takes the cost only when an order is carried out."""
        for _ in range(patience):
            if self._v().player[_P.minerals] >= minerals:
                yield from then
                return
            yield NO_OP


def _random_spot(rng: np.random.Generator) -> Callable[[ScreenView, int], tuple[int, int] | None]:
    return lambda v, size: v.random_pixel(v.placements(size), rng)


def far_spot(v: ScreenView, size: int) -> tuple[int, int] | None:
    """The free spot farthest from the minerals, so buildings never block mining (and pack
    against the screen's far edge, leaving room for more)."""
    ok = v.placements(size)
    if not ok.any():
        return None
    ys, xs = np.nonzero(ok)
    my, mx = np.nonzero(v.minerals())
    if len(my):
        d = (ys - my.mean()) ** 2 + (xs - mx.mean()) ** 2
    else:
        d = xs.astype(float)
    i = int(np.argmax(d))
    return int(xs[i]), int(ys[i])


SITES: tuple[str, ...] = ("random", "far")
"""Where the macros build: a free site drawn at random (the paper's random agent), or the free
site farthest from the minerals (:func:`far_spot`, the scripted agent's choice)."""


class ReducedRandomAgent(MacroAgent):
    """The paper's random agent over a reduced set of macro actions, picked uniformly.

    A macro that costs minerals first waits for them (up to ``PATIENCE`` steps), as a player
    choosing "build a barracks" would: spending whenever possible would leave a uniform random
    agent too poor to ever afford a barracks.
    """

    MACROS: tuple[str, ...] = ("train_scv", "build_supply_depot", "build_barracks",
                               "train_marine", "gather", "no_op")
    COST: dict[str, int] = {"train_scv": 50, "build_supply_depot": 100, "build_barracks": 150,
                            "train_marine": 50}
    PATIENCE = 60

    def __init__(self, seed: int, *, sites: str = "random") -> None:
        super().__init__(seed)
        if sites not in SITES:
            raise Sc2DataError(f"unknown sites {sites!r}; choose one of: {', '.join(SITES)}")
        self.sites = sites
        """Where its buildings go (:data:`SITES`)."""

    def next_macro(self) -> Macro:
        name = self.MACROS[int(self.rng.integers(len(self.MACROS)))]
        macro = self.macro(name)
        cost = self.COST.get(name, 0)
        return self.save_up(cost, macro, self.PATIENCE) if cost else macro

    def macro(self, name: str) -> Macro:
        """Macro ``name`` (one of :attr:`MACROS`) played out from the current view, at once.

        Random choices (which SCV builds, where — on random sites —, which barracks trains) come
        from ``self.rng``.
        ``self.view`` must be set to the observation before each call is drawn, as :meth:`step`
        does; the gymnasium environments of ``sc2data.rl`` drive macros this way.
        """
        if name not in self.MACROS:
            raise Sc2DataError(f"unknown macro {name!r}; choose one of: {', '.join(self.MACROS)}")
        v = self._v()
        site = far_spot if self.sites == "far" else _random_spot(self.rng)
        if name == "build_supply_depot":
            macro = self.build(_F.Build_SupplyDepot_screen, site, 2)
        elif name == "build_barracks":
            macro = self.build(_F.Build_Barracks_screen, site, 3)
        elif name == "train_marine":
            macro = self.train_marine(v.random_pixel(v.own(units.Terran.Barracks), self.rng))
        else:
            macro = getattr(self, name)()
        return macro


def macro_feasible(v: ScreenView) -> np.ndarray:
    """``(6,)`` bool, in :attr:`ReducedRandomAgent.MACROS` order: which macros the observation
    says can start now (the macro space's action mask, :mod:`sc2data.rl.envs`)."""
    free = int(v.player[_P.food_cap]) - int(v.player[_P.food_used])
    cc = v.own(units.Terran.CommandCenter)
    has_scv = bool(v.own(units.Terran.SCV).any())
    n_cc = max(1, len(v.blobs(cc)))
    depot_done = int(v.player[_P.food_cap]) > 15 * n_cc  # a finished depot raises the cap
    ok = {
        "train_scv": bool(cc.any()) and free >= 1,
        "build_supply_depot": has_scv and bool(v.placements(2).any()),
        "build_barracks": has_scv and depot_done and bool(v.placements(3).any()),
        "train_marine": bool(v.own(units.Terran.Barracks).any()) and free >= 1,
        "gather": int(v.player[_P.idle_worker_count]) > 0,
        "no_op": True,
    }
    return np.array([ok[name] for name in ReducedRandomAgent.MACROS], dtype=bool)


class MacroRulesAgent(ReducedRandomAgent):
    """The scripted agent's rules played in the macro space: what its six macros allow.

    Each time its previous macro ends it picks one of :attr:`ReducedRandomAgent.MACROS` that
    :func:`macro_feasible` allows — idle SCVs back to mining, a depot when free supply runs low
    and none is being built, SCVs up to ``scvs``, barracks up to ``barracks``, marines, else
    no-op — and plays it out as the macro space does (:meth:`ReducedRandomAgent.macro`: which
    SCV, which barracks drawn at random, and the site as ``sites`` says; minerals waited for).
    Unlike ``scripted`` it cannot kill its own marines, so the buildings that fit on the screen
    cap its supply: on random sites about 109, on far sites 144 as the scripted agent's
    (BENCHMARKS.md, "The macro space's ceiling").
    """

    def __init__(self, seed: int, *, scvs: int = 20, barracks: int = 5,
                 sites: str = "random") -> None:
        super().__init__(seed, sites=sites)
        self.scvs = scvs
        self.barracks = barracks
        self._last: dict[str, int] = {}

    def reset(self) -> None:
        super().reset()
        self._last = {}

    GAPS: dict[str, int] = {"build_supply_depot": 25, "train_scv": 34, "build_barracks": 25}
    """pysc2 steps before a macro is chosen again: a depot or barracks shows only once its SCV
    has walked to the site; an SCV takes 272 game loops (34 steps), one queued at a time; a
    marine (400 loops, 50 steps) is ordered every ``50 // barracks`` steps."""

    def next_macro(self) -> Macro:
        name = self.choose()
        macro = self.macro(name)
        cost = self.COST.get(name, 0)
        return self.save_up(cost, macro, self.PATIENCE) if cost else macro

    def choose(self) -> str:
        """The macro its rules pick from ``self.view`` now (recorded as chosen at
        ``self.steps``): the first of its wants that is feasible and not chosen too recently,
        else ``no_op``. ``benchmarks/ppo_gradients.py`` asks it this at each decision of the
        macro space's env."""
        v = self._v()
        ok = dict(zip(self.MACROS, macro_feasible(v), strict=True))
        used, cap = int(v.player[_P.food_used]), int(v.player[_P.food_cap])
        rax = len(v.blobs(v.own(units.Terran.Barracks)))
        depots = len(v.blobs(v.own(units.Terran.SupplyDepot, units.Terran.SupplyDepotLowered)))
        depots_building = depots - max(0, cap - 15) // 8
        wants = (
            ("gather", True),
            ("build_supply_depot", cap < 200 and cap - used <= 4 + 2 * rax
             and depots_building <= 0),
            ("train_scv", int(v.player[_P.food_workers]) < self.scvs),
            ("build_barracks", rax < self.barracks),
            ("train_marine", True),
        )
        gaps = {**self.GAPS, "train_marine": 50 // max(1, rax)}
        for name, want in wants:
            if want and ok[name] and self._ready(name, gaps.get(name, 0)):
                self._last[name] = self.steps
                return name
        return "no_op"

    def _ready(self, name: str, gap: int) -> bool:
        return self.steps - self._last.get(name, -gap) >= gap


class ScriptedAgent(MacroAgent):
    """A build order: SCVs, depots ahead of supply, several barracks, marines nonstop."""

    def __init__(self, seed: int, *, scvs: int = 22, barracks: int = 5, max_supply: int = 200,
                 queue: int = 2) -> None:
        super().__init__(seed)
        self.scvs = scvs
        """Workers to train up to (16 mine 8 fields two to a patch; a few more still pay)."""
        self.barracks = barracks
        self.max_supply = max_supply
        """Supply ceiling: depots stop here, and marines are killed to stay under it."""
        self.queue = queue
        """Units kept queued per production building (minerals are spent when queued)."""
        self._wait: dict[str, int] = {}
        self._rax_turn = 0

    def reset(self) -> None:
        super().reset()
        self._wait = {}
        self._rax_turn = 0

    def _ready(self, key: str) -> bool:
        return self.steps >= self._wait.get(key, 0)

    def _hold(self, key: str, steps: int) -> None:
        self._wait[key] = self.steps + steps

    def next_macro(self) -> Macro:
        v = self._v()
        minerals = int(v.player[_P.minerals])
        used, cap = int(v.player[_P.food_used]), int(v.player[_P.food_cap])
        free = cap - used
        n_cc = len(v.blobs(v.own(units.Terran.CommandCenter)))
        depots = len(v.blobs(v.own(units.Terran.SupplyDepot, units.Terran.SupplyDepotLowered)))
        depots_building = depots - max(0, cap - 15 * n_cc) // 8
        rax = v.blobs(v.own(units.Terran.Barracks))
        margin = 4 + 2 * len(rax)

        need_depot = (cap < min(self.max_supply, 200) and free <= margin
                      and depots_building <= 0 and self._ready("depot"))
        # Minerals are spent when the SCV places the building: keep them until it has.
        reserve = 100 if need_depot or not self._ready("depot") else 0
        reserve += 0 if self._ready("barracks") else 150
        if need_depot and minerals >= 100 and v.placements(2).any():
            self._hold("depot", 25)  # the SCV walks to the site before the depot shows
            return self.build(_F.Build_SupplyDepot_screen, far_spot, 2)
        if v.player[_P.idle_worker_count] > 0 and self._ready("gather"):
            self._hold("gather", 4)
            return self.gather()
        if (v.player[_P.food_workers] < self.scvs and free >= 1 and minerals >= 50 + reserve
                and self._ready("scv")):
            self._hold("scv", 8)
            return self._queue(units.Terran.CommandCenter,
                               v.centre_pixel(v.own(units.Terran.CommandCenter)),
                               _F.Train_SCV_quick, upto=self.scvs)
        if (len(rax) < self.barracks and cap > 15 * n_cc and minerals >= 150 + reserve
                and self._ready("barracks") and v.placements(3).any()):
            self._hold("barracks", 25)
            return self.build(_F.Build_Barracks_screen, far_spot, 3)
        if rax and free >= 1 and minerals >= 50 + reserve and self._ready("marine"):
            self._rax_turn = (self._rax_turn + 1) % len(rax)
            if self._rax_turn == 0:
                self._hold("marine", 2)
            return self._queue(units.Terran.Barracks, v.centre_pixel(rax[self._rax_turn]),
                               _F.Train_Marine_quick)
        if (free <= 2 and v.player[_P.army_count] > 1 and self._ready("kill")
                and (cap >= min(self.max_supply, 200) or not v.placements(2).any())):
            self._hold("kill", 3)
            return self.kill_marine()
        return self.no_op()

    def _queue(self, unit_type: int, xy: tuple[int, int] | None, train: Any,
               upto: int | None = None) -> Macro:
        """Select a production building and top its queue up to ``self.queue``; with ``upto``,
        never past ``upto`` workers counting those in its queue (the game's ``food_workers``
        counts only workers that exist, as python-sc2 bots add their pending ones to it)."""
        ok = yield from self.select_unit(unit_type, xy)
        while ok:
            v = self._v()
            if (len(v.build_queue) >= self.queue or v.player[_P.minerals] < 50
                    or v.player[_P.food_used] >= v.player[_P.food_cap]
                    or (upto is not None
                        and v.player[_P.food_workers] + len(v.build_queue) >= upto)):
                return
            yield train("now")
            ok = self._v().selected_type() == unit_type


AGENTS: dict[str, Callable[[int], base_agent.BaseAgent]] = {
    "random": SeededRandomAgent,
    "reduced-random": ReducedRandomAgent,
    "scripted": ScriptedAgent,
    "macro-rules": MacroRulesAgent,
}
"""Agent factories by name; each takes the seed."""


@dataclass(frozen=True)
class AgentSpec:
    """An agent name resolved: how to make one per episode, and what a dataset records of it."""

    factory: Callable[[int], base_agent.BaseAgent]
    """``seed -> agent``; picklable (rollout workers are spawned processes)."""
    sha256: str | None = None
    """The sha256 of what the agent loads (a policy's checkpoint), recorded with the data so that
    a dataset says exactly which agent made it; None for agents that load nothing."""
    about: dict[str, Any] = field(default_factory=dict)
    """More about it, for people (a policy's action space, reward, trained steps)."""


AgentKind = Callable[[str], AgentSpec]
"""Resolves the ``ARG`` of an agent name ``kind:ARG``; a one-line error on a bad one."""

AGENT_KINDS: dict[str, AgentKind] = {}
"""Agent kinds by prefix, registered by the rooms that define them (see the module docstring)."""

KIND_HOMES: dict[str, str] = {"policy": "sc2data.rl"}
"""Where each kind sc2data defines comes from, for the error when it is not registered yet."""
_KIND_ARGS: dict[str, str] = {}


def register_agent_kind(kind: str, resolve: AgentKind, arg: str = "ARG") -> None:
    """Make agent names ``kind:ARG`` resolve through ``resolve`` (idempotent for one kind);
    ``arg`` names the argument in messages (``policy:RUN``)."""
    if not kind.isidentifier() or kind in AGENTS:
        raise ValueError(f"agent kind {kind!r} must be an identifier and no agent's name")
    AGENT_KINDS[kind] = resolve
    _KIND_ARGS[kind] = arg


def _named(name: str, seed: int) -> base_agent.BaseAgent:
    return AGENTS[name](seed)


def resolve_agent(name: str) -> AgentSpec:
    """The :class:`AgentSpec` of a registry name or a ``kind:ARG`` name; one line if unknown."""
    if name in AGENTS:
        return AgentSpec(functools.partial(_named, name))
    kind, sep, arg = name.partition(":")
    if sep and kind in AGENT_KINDS:
        if not arg:
            raise Sc2DataError(f"agent {name!r} names no {kind}: write "
                               f"{kind}:{_KIND_ARGS.get(kind, 'ARG')}")
        return AGENT_KINDS[kind](arg)
    choices = [*AGENTS, *(f"{k}:{_KIND_ARGS.get(k, 'ARG')}" for k in AGENT_KINDS)]
    hint = ""
    if sep and kind in KIND_HOMES:
        hint = f" ({kind}:… agents come with {KIND_HOMES[kind]}: import it first)"
    raise Sc2DataError(f"unknown agent {name!r}; choose one of: {', '.join(choices)}{hint}")


def make_agent(name: str, *, seed: int, sites: str = "random") -> base_agent.BaseAgent:
    """A new agent by registry name (or ``kind:ARG``, e.g. ``policy:RUN``); call
    ``setup(obs_spec, action_spec)`` before use. ``sites`` (:data:`SITES`) is where the agents
    that play the six macros (``reduced-random``, ``macro-rules``) build; the others ignore it.

    Seeding: ``random`` draws from its own ``numpy.random.RandomState(seed)`` (the same calls
    pysc2's agent makes after ``numpy.random.seed(seed)``); ``reduced-random`` and ``scripted``
    draw from ``numpy.random.default_rng(seed)`` (the scripted agent only to pick which SCV to
    click); a ``policy`` samples from its own torch generator seeded with ``seed``. None touches
    a global RNG, so one seed and one environment seed give one episode.
    """
    macro_agents = {"reduced-random": ReducedRandomAgent, "macro-rules": MacroRulesAgent}
    if sites != "random" and name in macro_agents:
        return macro_agents[name](seed, sites=sites)
    return resolve_agent(name).factory(seed)


def play(env: Any, agent: base_agent.BaseAgent, steps: int | None = None) -> Iterator[Any]:
    """Run one episode (or ``steps`` agent steps), yielding each TimeStep the agent sees.

    Like pysc2's ``run_loop`` for one agent: ``setup`` from the env's specs, ``reset``, then step
    until the episode's last TimeStep.
    """
    agent.setup(env.observation_spec()[0], env.action_spec()[0])
    agent.reset()
    timestep = env.reset()[0]
    n = 0
    while True:
        yield timestep
        n += 1
        if timestep.last() or (steps is not None and n >= steps):
            return
        timestep = env.step([agent.step(timestep)])[0]
