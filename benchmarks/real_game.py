"""The simulator held against real StarCraft II games: income, build and queue timings, supply.

Real side: LotV 1v1 replays read with sc2reader (no game binary). Their tracker events give,
every 160 game loops, each player's ``minerals_collection_rate`` — minerals gathered over the
last 240 loops, per real minute (1,344 loops) — and ``workers_active_count``; and every unit's
start (``UnitInitEvent``) and finish (``UnitDoneEvent`` / ``UnitBornEvent``). Their game events
give each ``TrainSCV`` / ``TrainMarine`` command's loop.

Sim side: the embedded BuildMarines simulator driven through pysc2 ``FunctionCall``s only, by
:class:`Opening` (a standard Terran opening: SCVs back to back, a depot at 14 supply, a barracks
when it is done, marines), and timed by ``env.events``.

Income is binned the same way on both sides: a sample is the collection rate at a loop where the
worker count has not changed for the 240 loops it covers; one base, before any gas, MULE or second
town hall. Real samples fall every 160 loops; the sim's after every agent step (8 loops), over
several seeds, since one opening gives few windows of 240 loops between SCVs 272 loops apart.
Like for like, income per SCV on the line also takes the SCVs constructing out of the worker
count (Terrans: a replay shows each structure's start and finish; scouts it does not show). And
mining itself, whoever the agent: every window binned by its mean SCVs on the line (workers
alive less builders, the count free to change within the window; Terrans and Protoss, whose
probes only warp a building in), which gives many more windows at 15-18 than a constant count.
``REAL_MEDIANS`` are the medians measured the same way on 32 LotV 1v1 replays (64 player-games,
releases 2.5.5 to 5.0): the figures the test holds the simulator to, within ±5 %.

    python benchmarks/real_game.py                       # the replays carried in the repository
    python benchmarks/real_game.py --seeds 16 path/to/*.SC2Replay
"""

from __future__ import annotations

import argparse
import collections
import statistics
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sc2data._pysc2 import actions, features, units  # first: it makes pysc2 importable

from pysc2.agents.base_agent import BaseAgent  # isort: skip
from sc2data.game.agents import Macro, MacroAgent, far_spot, make_agent, play
from sc2data.game.sim import BuildMarinesEnv
from sc2data.game.sim import mapdata as md

REPLAYS = Path(__file__).resolve().parent / "real-replays"
"""The real replays carried in the repository (with their licence and attribution)."""

WINDOW = 240
"""Loops the game's ``minerals_collection_rate`` covers."""
FIRST_WINDOW = 160
"""Windows begin no earlier: the first minerals come in ≈120 loops after the start, and a window
that reaches back before them measures the walk out, not the income."""
REAL_MINUTE = 1344
"""Game loops per real minute at "Faster" (22.4 loops a second)."""
WORKERS = range(12, 21)
NEVER = 1 << 30
"""A game loop no replay reaches (a structure that never died, a phase that never ended)."""
REAL_MEDIANS: dict[int, int] = {12: 713, 13: 727, 14: 728, 15: 756, 16: 811, 17: 840, 18: 882,
                                19: 896, 20: 937}
"""Median mineral income per real minute by worker count, one base, no gas, 32 LotV replays."""
INCOME_TOLERANCE = 0.05
REAL_TIMINGS: dict[str, int] = {
    "depot build": 480, "barracks build": 1040, "command center build": 1600,
    "SCV from idle": 272, "SCV back to back": 271, "marine from idle": 400,
    "marine back to back": 399,
}
"""Build and production times in game loops, every sample of the 32 replays."""

SIM_DRIVES = ("mining", "scripted", "opening")
"""How the simulator is played: the start's 12 workers left to mine (the only way 12 workers
hold for a window: every opening trains an SCV at once), the project's scripted agent, and
:class:`Opening`."""

_F = actions.FUNCTIONS
_P = features.Player
_WORKER_NAMES = {"SCV", "Drone", "Probe"}
_ONE_BASE_ENDS = ("Refinery", "Extractor", "Assimilator", "CommandCenter", "Hatchery", "Nexus")
_ADD_ONS = ("Reactor", "TechLab")
_BUILD_NAMES = {"SupplyDepot": "depot build", "Barracks": "barracks build",
                "CommandCenter": "command center build"}


@dataclass
class Figures:
    """What one side measured: income samples by worker count, timings, start and supply."""

    income: dict[int, list[int]] = field(default_factory=lambda: collections.defaultdict(list))
    timings: dict[str, list[int]] = field(default_factory=lambda: collections.defaultdict(list))
    start: list[tuple[int, int, int, int]] = field(default_factory=list)
    """(minerals, workers, food_used, food_made) at the start of each game."""
    supply_checks: list[bool] = field(default_factory=list)
    """Per stats sample: food_made == 15 × town halls + 8 × finished depots (Terrans)."""
    line: dict[int, list[float]] = field(default_factory=lambda: collections.defaultdict(list))
    """Income per SCV on the mineral line, by worker count, for each income sample (Terrans):
    the rate over the workers less the SCVs constructing, averaged over the window."""
    on_line: dict[int, list[float]] = field(
        default_factory=lambda: collections.defaultdict(list))
    """Income per SCV on the line binned by the SCVs on the line themselves (the window's mean
    workers less its mean builders, rounded): every sample of one base before gas, the worker
    count free to change within the window, so far more samples than ``line`` (Terrans)."""

    def income_median(self, n: int) -> float | None:
        return statistics.median(self.income[n]) if self.income.get(n) else None

    def line_median(self, n: int) -> float | None:
        return statistics.median(self.line[n]) if self.line.get(n) else None

    def on_line_median(self, n: int) -> float | None:
        return statistics.median(self.on_line[n]) if self.on_line.get(n) else None

    def timing_median(self, key: str) -> float | None:
        return statistics.median(self.timings[key]) if self.timings.get(key) else None


# ------------------------------------------------------------------ the real side


def read_replays(paths: Iterable[Path]) -> Figures:
    """Income, timings, start and supply from real replays (sc2reader, a test extra)."""
    import sc2reader  # a test/benchmark dependency, not a runtime one

    out = Figures()
    for path in paths:
        replay = sc2reader.load_replay(str(path), load_level=4)
        if len(replay.players) == 2:
            _read_replay(replay, out)
    return out


def _read_replay(replay: Any, out: Figures) -> None:
    from sc2reader.events.game import CommandEvent
    from sc2reader.events.tracker import (
        PlayerStatsEvent,
        UnitBornEvent,
        UnitDiedEvent,
        UnitDoneEvent,
        UnitInitEvent,
        UnitTypeChangeEvent,
    )

    one_base_until: dict[int, int] = {}
    worker_lives: dict[int, list[tuple[int, int]]] = collections.defaultdict(list)
    """Per player, (birth, death) of each worker, the start's included (born at loop 0)."""
    worker_born: dict[int, tuple[int, int]] = {}
    started: dict[int, tuple[int, int, str]] = {}
    depots: dict[int, set[int]] = collections.defaultdict(set)
    halls: dict[int, set[int]] = collections.defaultdict(set)
    died_at: dict[int, int] = {}
    births: dict[tuple[int, str], list[int]] = collections.defaultdict(list)
    barracks: dict[int, list[int]] = collections.defaultdict(list)
    changed: dict[int, int] = {}
    done_at: dict[int, int] = {}
    constructing: dict[int, list[tuple[int, int]]] = collections.defaultdict(list)
    """Per player, (start, end) of each structure an SCV built: from init to done or death."""

    def end_one_base(pid: int, loop: int) -> None:
        one_base_until[pid] = min(one_base_until.get(pid, NEVER), loop)

    for e in replay.tracker_events:
        if isinstance(e, UnitBornEvent):
            name = e.unit_type_name
            if name in _WORKER_NAMES:
                worker_born[e.unit_id] = (e.control_pid, e.frame)
            if name == "MULE":
                end_one_base(e.control_pid, e.frame)
            if name in ("SCV", "Marine") and e.frame > 0:
                births[(e.control_pid, name)].append(e.frame)
            if name == "CommandCenter":
                halls[e.control_pid].add(e.unit_id)
        elif isinstance(e, UnitInitEvent):
            started[e.unit_id] = (e.control_pid, e.frame, e.unit_type_name)
            if e.unit_type_name.startswith(("BarracksReactor", "BarracksTechLab")):
                barracks[e.control_pid].append(-e.frame)  # an add-on: production changes
        elif isinstance(e, UnitDoneEvent) and e.unit_id in started:
            pid, begun, name = started[e.unit_id]
            done_at[e.unit_id] = e.frame
            if name in _BUILD_NAMES:
                out.timings[_BUILD_NAMES[name]].append(e.frame - begun)
            if name.startswith(_ONE_BASE_ENDS):
                end_one_base(pid, e.frame)
            if name.startswith("SupplyDepot"):
                depots[pid].add(e.unit_id)
            if name == "CommandCenter":
                halls[pid].add(e.unit_id)
            if name == "Barracks":
                barracks[pid].append(e.frame)
        elif isinstance(e, UnitTypeChangeEvent) and e.unit_type_name == "OrbitalCommand":
            changed[e.unit_id] = e.frame
        elif isinstance(e, UnitDiedEvent):
            died_at[e.unit_id] = e.frame

    for uid, (pid, born) in worker_born.items():
        worker_lives[pid].append((born, died_at.get(uid, NEVER)))
    for uid, (pid, begun, name) in started.items():
        if not name.endswith(_ADD_ONS):  # add-ons are built by their building, not an SCV
            constructing[pid].append((begun, min(done_at.get(uid, NEVER), died_at.get(uid, NEVER))))

    commands: dict[tuple[int, str], list[int]] = collections.defaultdict(list)
    orbital: dict[int, int] = {}
    for e in replay.game_events:
        if isinstance(e, CommandEvent) and e.player is not None:
            pid = e.player.pid
            if e.ability_name == "TrainSCV":
                commands[(pid, "SCV")].append(e.frame)
            elif e.ability_name == "TrainMarine":
                commands[(pid, "Marine")].append(e.frame)
            elif e.ability_name == "UpgradeToOrbital":
                orbital.setdefault(pid, e.frame)

    races = {p.pid: p.play_race for p in replay.players}
    for pid, race in races.items():
        if race != "Terran":
            continue
        # SCVs from the first CC while it is the only producer; marines from the first barracks
        # while it is the only one and has no add-on (a reactor trains two at once).
        scv_until = min(orbital.get(pid, NEVER), one_base_until.get(pid, NEVER))
        _production(commands[(pid, "SCV")], births[(pid, "SCV")], scv_until, "SCV", out)
        rax = sorted(barracks[pid], key=abs)
        if rax and rax[0] > 0:
            until = abs(rax[1]) if len(rax) > 1 else NEVER
            _production([c for c in commands[(pid, "Marine")] if c >= rax[0]],
                        births[(pid, "Marine")], until, "marine", out)

    last_workers: dict[int, int] = {}
    for e in replay.tracker_events:
        if not isinstance(e, PlayerStatsEvent):
            continue
        pid, loop, n = e.pid, e.frame, e.workers_active_count
        if loop <= 1:
            out.start.append((e.minerals_current, n, int(e.food_used), int(e.food_made)))
        if races.get(pid) == "Terran" and 1 < loop <= one_base_until.get(pid, NEVER):
            # Stats come first in a loop; a structure counts from when it was done until it died
            # (a set emptied of the dead as the pass goes would miss them in earlier samples).
            cc = sum(1 for u in halls[pid] if done_at.get(u, 0) < loop <= died_at.get(u, NEVER))
            dep = sum(1 for u in depots[pid] if done_at[u] < loop <= died_at.get(u, NEVER))
            out.supply_checks.append(int(e.food_made) == min(200, 15 * cc + 8 * dep))
        previous = last_workers.get(pid)
        last_workers[pid] = n
        if (races.get(pid) in ("Terran", "Protoss") and FIRST_WINDOW + WINDOW <= loop
                <= one_base_until.get(pid, NEVER) and not e.vespene_collection_rate
                and not any(loop - WINDOW < d <= loop for _, d in worker_lives[pid])):
            points = range(loop - WINDOW, loop, 8)
            alive = sum(a <= t < b for t in points for a, b in worker_lives[pid]) / len(points)
            builders = constructing[pid] if races[pid] == "Terran" else []  # a probe walks on
            _on_line(e.minerals_collection_rate, alive, builders, loop, out)
        if (loop < FIRST_WINDOW + WINDOW or loop > one_base_until.get(pid, NEVER) or previous != n
                or e.vespene_collection_rate
                or any(loop - WINDOW < b <= loop for b, _ in worker_lives[pid])):
            continue
        out.income[n].append(e.minerals_collection_rate)
        if races.get(pid) == "Terran":
            out.line[n].append(_per_line(e.minerals_collection_rate, n, constructing[pid], loop))


def _production(commands: Sequence[int], births: Sequence[int], until: int, unit: str,
                out: Figures) -> None:
    """Match train commands to births first in, first out, for one producer before ``until``.

    A unit commanded while its producer was idle times command → birth; one commanded while
    another was in production times the gap between the two births.
    """
    births = [b for b in births if b < until]
    commands = [c for c in commands if c < until][: len(births)]
    for i, (c, b) in enumerate(zip(commands, births)):
        if b <= c:
            return  # the matching broke (a cancel): trust nothing after it
        if i == 0 or c >= births[i - 1]:
            out.timings[f"{unit} from idle"].append(b - c)
        else:
            out.timings[f"{unit} back to back"].append(b - births[i - 1])


def _per_line(rate: int, workers: int, constructing: Sequence[tuple[int, int]],
              loop: int) -> float:
    """Income per SCV on the mineral line over the window ending at ``loop``: ``rate`` over the
    workers less the mean number of SCVs constructing (one a structure under construction,
    sampled every 8 loops of the window). Scouts and builders still walking are not seen."""
    points = range(loop - WINDOW, loop, 8)
    building = sum(a <= t < b for t in points for a, b in constructing) / len(points)
    return rate / (workers - building)


def _on_line(rate: int, workers: float, constructing: Sequence[tuple[int, int]], loop: int,
             out: Figures) -> None:
    """Bin one window ending at ``loop`` by its mean SCVs on the line (``workers``, the mean
    alive over the window, less the structures under construction, sampled every 8 loops) and
    record the rate per such SCV."""
    points = range(loop - WINDOW, loop, 8)
    building = sum(a <= t < b for t in points for a, b in constructing) / len(points)
    line = workers - building
    out.on_line[round(line)].append(rate / line)


# ------------------------------------------------------------------ the sim side


class Opening(MacroAgent):
    """A standard Terran opening played through pysc2 calls: SCVs back to back up to ``scvs``,
    a depot at 14 supply and another when supply runs short, a barracks once a depot is done,
    marines from it; idle SCVs back to the minerals."""

    def __init__(self, seed: int, scvs: int = 22) -> None:
        super().__init__(seed)
        self.scvs = scvs
        self._next_build = 0
        """Step before which no new building is ordered: the SCV is still on its way."""

    def next_macro(self) -> Macro:
        v = self._v()
        minerals = int(v.player[_P.minerals])
        used, cap = int(v.player[_P.food_used]), int(v.player[_P.food_cap])
        depots = len(v.blobs(v.own(units.Terran.SupplyDepot)))
        rax = v.blobs(v.own(units.Terran.Barracks))
        walking = self.steps < self._next_build
        need_depot = (not walking and depots <= (cap - 15) // 8 and cap < 200
                      and used >= (14 if cap <= 15 else cap - 4))
        if need_depot and minerals >= 100:
            self._next_build = self.steps + 30
            return self.build(_F.Build_SupplyDepot_screen, far_spot, 2)
        if v.player[_P.idle_worker_count] > 0:
            return self.gather()
        cc = v.centre_pixel(v.own(units.Terran.CommandCenter))
        if (v.player[_P.food_workers] < self.scvs and used < cap and not need_depot
                and minerals >= 50):
            return self._queue(units.Terran.CommandCenter, cc, _F.Train_SCV_quick)
        if not rax and not walking and cap > 15 and used >= 16 and minerals >= 150:
            self._next_build = self.steps + 30
            return self.build(_F.Build_Barracks_screen, far_spot, 3)
        if rax and used < cap and minerals >= 50:
            return self._queue(units.Terran.Barracks, v.centre_pixel(rax[0]),
                               _F.Train_Marine_quick)
        return self.no_op()

    def _queue(self, unit_type: int, xy: tuple[int, int] | None, train: Any) -> Macro:
        """Queue the next unit when the building is idle or its unit nearly done, as players
        do: back to back, without locking minerals in a long queue."""
        ok = yield from self.select_unit(unit_type, xy)
        q = self._v().build_queue
        if ok and (len(q) == 0 or (len(q) == 1 and q[0][-1] >= 80)):
            yield train("now")


def simulate(seeds: Iterable[int], agent: str = "opening", loops: int = 8000) -> Figures:
    """The simulator's figures over ``seeds``, played by ``agent`` through pysc2 calls:
    ``opening`` (:class:`Opening`), a project agent by name (``scripted``), or ``mining``
    (no orders: the 12 workers of the start mine, and nothing else happens)."""
    out = Figures()
    for seed in seeds:
        env = BuildMarinesEnv(seed=seed, game_loops=loops)
        player = (Opening(seed) if agent == "opening" else BaseAgent() if agent == "mining"
                  else make_agent(agent, seed=seed))
        counts: collections.deque[tuple[int, int]] = collections.deque()
        queued: dict[int, list[int]] = collections.defaultdict(list)
        born: dict[int, list[int]] = collections.defaultdict(list)
        placed: dict[int, tuple[int, int]] = {}
        constructing: list[tuple[int, int]] = []
        for ts in play(env, player):
            obs = ts.observation
            loop, n = int(obs.game_loop[0]), int(obs.player.food_workers)
            if loop == 0:
                out.start.append((int(obs.player.minerals), n, int(obs.player.food_used),
                                  int(obs.player.food_cap)))
            for e in env.events:
                if e.kind == "queued":
                    queued[e.tag].append(e.loop)
                elif e.kind == "placed":
                    placed[e.tag] = (e.unit_type, e.loop)
                elif e.kind == "completed" and e.tag in placed:
                    utype, begun = placed.pop(e.tag)
                    constructing.append((begun, e.loop))
                    name = "depot build" if utype == md.DEPOT else "barracks build"
                    out.timings[name].append(e.loop - begun)
                elif e.kind == "completed" and e.unit_type in (md.SCV, md.MARINE):
                    born[e.unit_type].append(e.loop)
            g = env.game
            cc = g.completed.get(md.CC, 0)
            out.supply_checks.append(
                g.food_cap == min(200, 15 * cc + 8 * g.completed.get(md.DEPOT, 0)))
            counts.append((loop, n))
            while counts[0][0] < loop - WINDOW:
                counts.popleft()
            if loop < FIRST_WINDOW + WINDOW or counts[0][0] > loop - WINDOW:
                continue
            rate = int(obs.score_cumulative.collection_rate_minerals)
            now = constructing + [(begun, NEVER) for _, begun in placed.values()]
            before = [m for t, m in counts if t < loop]  # the window's points, 8 loops apart
            _on_line(rate, sum(before) / len(before), now, loop, out)
            if all(m == n for _, m in counts):
                out.income[n].append(rate)
                out.line[n].append(_per_line(rate, n, now, loop))
        rax = [t for t in queued if t != g.cc.tag]
        _production(queued.get(g.cc.tag, []), born[md.SCV], NEVER, "SCV", out)
        if len(rax) == 1:  # marines matched to their one barracks
            _production(queued[rax[0]], born[md.MARINE], NEVER, "marine", out)
    return out


# ------------------------------------------------------------------ the table


def table(real: Figures, sims: dict[str, Figures]) -> str:
    """Markdown: income by worker count, then timings, then start and supply; one column for
    the replays read and one per simulator drive in ``sims``."""
    names = list(sims)
    head = "| workers | real median (32 replays) | these replays | " + " | ".join(
        f"sim, {k}" for k in names) + " |"
    lines = [head, "|" + " --- |" * (3 + len(names))]
    for n in WORKERS:
        cells = [f"{_fmt(f.income_median(n), len(f.income.get(n, [])))} "
                 f"{_pct(f.income_median(n), REAL_MEDIANS[n])}" for f in sims.values()]
        lines.append(f"| {n} | {REAL_MEDIANS[n]} | "
                     f"{_fmt(real.income_median(n), len(real.income.get(n, [])))} | "
                     + " | ".join(cells) + " |")
    lines += _per_scv(("workers", "per SCV on the line"), "line", real, sims)
    lines += _per_scv(("SCVs on the line (window mean)", "per SCV"), "on_line", real, sims)
    lines += ["", "| loops | real (32 replays) | these replays | " + " | ".join(
        f"sim, {k}" for k in names) + " |", "|" + " --- |" * (3 + len(names))]
    for key, want in REAL_TIMINGS.items():
        cells = [_fmt(f.timing_median(key), len(f.timings.get(key, []))) for f in sims.values()]
        lines.append(f"| {key} | {want} | "
                     f"{_fmt(real.timing_median(key), len(real.timings.get(key, [])))} | "
                     + " | ".join(cells) + " |")
    lines += ["", "| start and supply | these replays | " + " | ".join(
        f"sim, {k}" for k in names) + " |", "|" + " --- |" * (2 + len(names)),
        "| minerals, workers, food used / made at loop 0 | " + " | ".join(
            _start(f) for f in [real, *sims.values()]) + " |",
        "| food_made = 15 × CC + 8 × finished depots | " + " | ".join(
            _share(f) for f in [real, *sims.values()]) + " |"]
    return "\n".join(lines)


def _per_scv(head: tuple[str, str], attr: str, real: Figures,
             sims: dict[str, Figures]) -> list[str]:
    """Rows of median income per SCV by count (``Figures.line`` or ``Figures.on_line``): the
    replays, then each drive with its difference from them."""
    def cell(f: Figures, n: int) -> tuple[float | None, int]:
        return getattr(f, f"{attr}_median")(n), len(getattr(f, attr).get(n, []))

    lines = ["", f"| {head[0]} | {head[1]}, these replays | " + " | ".join(
        f"sim, {k}" for k in sims) + " |", "|" + " --- |" * (2 + len(sims))]
    for n in WORKERS:
        ref, count = cell(real, n)
        cells = [f"{_fmt(x, m, 1)} {_pct(x, ref) if ref else ''}"
                 for x, m in (cell(f, n) for f in sims.values())]
        lines.append(f"| {n} | {_fmt(ref, count, 1)} | " + " | ".join(cells) + " |")
    return lines


def _fmt(x: float | None, n: int, digits: int = 0) -> str:
    return "–" if x is None else f"{x:.{digits}f} (n={n})"


def _pct(x: float | None, ref: float) -> str:
    return "" if x is None else f"({(x / ref - 1) * 100:+.1f} %)"


def _start(f: Figures) -> str:
    c = collections.Counter(f.start).most_common(1)
    return "–" if not c else "{}, {}, {}/{}".format(*c[0][0])


def _share(f: Figures) -> str:
    return f"{sum(f.supply_checks)} of {len(f.supply_checks)}"


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("replays", nargs="*", type=Path,
                    help=f"replay files (default: those in {REPLAYS.name}/)")
    ap.add_argument("--seeds", type=int, default=8, help="simulator episodes (seeds 0..N-1)")
    args = ap.parse_args(argv)
    paths = args.replays or sorted(REPLAYS.glob("*.SC2Replay"))
    real = read_replays(paths)
    sims = {agent: simulate(range(args.seeds), agent) for agent in SIM_DRIVES}
    print(f"{len(paths)} replays; the simulator over seeds 0..{args.seeds - 1}\n")
    print(table(real, sims))
    return 0


if __name__ == "__main__":
    sys.exit(main())
