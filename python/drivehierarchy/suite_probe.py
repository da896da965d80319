"""`drivehierarchy scenario probe`: how discriminating is a scenario suite?

Sweeps reference drivers over every scenario and several seeds, state-only (no images), and
tabulates their S_R4 per category. A probe *cell* is one driver at one setting:

* `expert`        — the privileged autopilot (solvability: it should score high everywhere);
* `late_expert`   — the expert with its speed decision applied two decisions (0.5 s) late:
  graded competence must still earn a graded score;
* `zero`          — target speed 0 (a suite must not reward standing still);
* `constant@V`    — steer 0 at V m/s (a suite must not reward driving blindly straight);
* `follower@V`    — the hazard-blind route follower (pure pursuit on the route points at V m/s,
  4 m/s in turns, ignoring every actor and light): what route-following alone earns;
* `lights@V`      — the follower that stops at red/yellow lights on its route, otherwise blind.

The full sweep (`SWEEP` × seeds 0–4) is thousands of episodes; its rows are committed
(`docs/suite_probe.csv`) and `docs/suite.md`'s table is generated from them. The suite test
re-runs a deterministic subset (`ci_subset`) and requires bit-identical scores, then checks the
must-holds (`must_holds`) on the committed rows. Episodes run in worker processes, one scenario
and cell per task (one env, reset per seed), so SUMO scenarios are fine.
"""

from __future__ import annotations

import csv
import hashlib
import io
import multiprocessing as mp
import statistics
import sys
import time
from collections import defaultdict
from collections.abc import Iterable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from drivehierarchy._core import ConfigError

if TYPE_CHECKING:
    from drivehierarchy.agents.base import Agent

FOLLOWER_SPEEDS = (4, 6, 8, 10, 12)
CONSTANT_SPEEDS = (2, 4, 6, 8, 10, 12)
LIGHTS_SPEEDS = FOLLOWER_SPEEDS
SEEDS = (0, 1, 2, 3, 4)
# Blind families: their worst (highest-scoring) setting is what the suite must keep low.
FAMILIES = {"follower": FOLLOWER_SPEEDS, "constant": CONSTANT_SPEEDS, "lights": LIGHTS_SPEEDS}
SWEEP: tuple[str, ...] = (
    "expert",
    "late_expert",
    "zero",
    *(f"follower@{v}" for v in FOLLOWER_SPEEDS),
    *(f"constant@{v}" for v in CONSTANT_SPEEDS),
    *(f"lights@{v}" for v in LIGHTS_SPEEDS),
)
# Categories whose only hazard is a traffic light (the light-obeying driver may score there).
LIGHT_ONLY_CATEGORIES: frozenset[str] = frozenset()
RESULT_FIELDS = (
    "category",
    "id",
    "cell",
    "seed",
    "score",
    "termination",
    "sim_s",
    "trajectory_hash",
    "scenario_sha256",
)


# Hex digits of the trajectory hash kept in the committed results (64 bits are plenty to detect a
# changed episode and keep the file at ~1 MB).
TRAJECTORY_HASH_HEX = 16


def parse_cell(cell: str) -> tuple[str, float | None]:
    """`"follower@6"` → ("follower", 6.0); `"expert"` → ("expert", None)."""
    name, _, speed = cell.partition("@")
    if name in ("expert", "late_expert", "zero") and not speed:
        return name, None
    if name in FAMILIES and speed:
        try:
            v = float(speed)
        except ValueError:
            v = -1.0
        if 0.0 < v <= 30.0:
            return name, v
    raise ConfigError(
        f"probe cell {cell!r}: expected expert, late_expert, zero or "
        "<follower|constant|lights>@<m/s in (0, 30]>"
    )


def expand_cells(spec: str) -> tuple[str, ...]:
    """A comma-separated list; a bare family name (`follower`) means all of its sweep speeds."""
    out: list[str] = []
    for item in (s.strip() for s in spec.split(",")):
        if not item:
            continue
        cells = [f"{item}@{v}" for v in FAMILIES[item]] if item in FAMILIES else [item]
        for c in cells:
            parse_cell(c)
            if c not in out:
                out.append(c)
    if not out:
        raise ConfigError(f"--policies {spec!r}: no probe cell named")
    return tuple(out)


def parse_seeds(spec: str) -> tuple[int, ...]:
    """`"0-4"`, `"0,2,5"` or `"3"`."""
    seeds: list[int] = []
    try:
        for part in (p.strip() for p in spec.split(",")):
            lo, sep, hi = part.partition("-")
            rng = range(int(lo), int(hi) + 1) if sep else range(int(lo), int(lo) + 1)
            seeds.extend(s for s in rng if s not in seeds)
    except ValueError:
        raise ConfigError(f"--seeds {spec!r}: expected e.g. 0-4 or 0,2,5") from None
    if not seeds or min(seeds) < 0:
        raise ConfigError(f"--seeds {spec!r}: expected non-negative seeds")
    return tuple(seeds)


def _agent(cell: str) -> Agent:
    from drivehierarchy.agents.base import ConstantAgent
    from drivehierarchy.agents.expert import ExpertAgent
    from drivehierarchy.agents.follower import LateExpertAgent, LightObeyingFollowerAgent, RouteFollowerAgent

    name, v = parse_cell(cell)
    if name == "expert":
        return ExpertAgent()
    if name == "late_expert":
        return LateExpertAgent(delay=2)
    if name == "zero":
        return ConstantAgent([0.0, 0.0], name="zero")
    assert v is not None
    if name == "constant":
        return ConstantAgent([0.0, v], name=cell)
    if name == "follower":
        return RouteFollowerAgent(name=cell, cruise_mps=v, turn_mps=4.0)
    return LightObeyingFollowerAgent(name=cell, cruise_mps=v, turn_mps=4.0)


def run_cell(scenario: str, cell: str, seeds: Iterable[int], traffic: str | None) -> list[dict[str, Any]]:
    """Episodes of one scenario and cell, one per seed, on one env (runs in a worker process)."""
    from drivehierarchy.agents.base import run_episode
    from drivehierarchy.envs.r4 import DriveHierarchyR4Env

    overrides: dict[str, Any] = {"front": None, "bev": None, "prompt": False}
    if traffic is not None:
        overrides["traffic"] = traffic
    env = DriveHierarchyR4Env(scenario=scenario, **overrides)
    agent = _agent(cell)
    # Ties the committed results to the scenario file they were measured on (stale-row check).
    digest = scenario_digest(Path(scenario))
    rows = []
    try:
        for seed in seeds:
            t0 = time.perf_counter()
            rec = run_episode(env, agent, seed=seed).score
            rows.append(
                {
                    "scenario": scenario,
                    "category": env.sim.category,
                    "id": rec["scene_id"],
                    "cell": cell,
                    "seed": seed,
                    "traffic": env.traffic_mode,
                    # repr keeps every bit (the CI check compares scores exactly).
                    "score": float(rec["score_composed"]),
                    "termination": rec["termination_reason"],
                    "events": sorted({e["type"] for e in rec["events"]}),
                    "sim_s": float(rec["meta"]["duration_game"]),
                    "trajectory_hash": env.sim.trajectory_hash,
                    "scenario_sha256": digest,
                    "wall_s": round(time.perf_counter() - t0, 3),
                }
            )
    finally:
        env.close()
    return rows


def scenario_digest(path: Path) -> str:
    """The first 16 hex digits of the file's SHA-256."""
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


def run_one(scenario: str, cell: str, seed: int, traffic: str | None) -> dict[str, Any]:
    """One episode on a fresh env."""
    return run_cell(scenario, cell, [seed], traffic)[0]


def probe(
    scenarios: list[Path],
    cells: Iterable[str] = SWEEP,
    seeds: Iterable[int] = (0,),
    jobs: int = 2,
    traffic: str | None = None,
    progress: bool = True,
    tasks: list[tuple[str, str, tuple[int, ...]]] | None = None,
) -> list[dict[str, Any]]:
    """Runs every (scenario, cell, seed), or the given (scenario, cell, seeds) tasks."""
    if tasks is None:
        seeds = tuple(seeds)
        tasks = [(str(s), c, seeds) for s in scenarios for c in cells]
    rows: list[dict[str, Any]] = []
    ctx = mp.get_context("spawn")
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=max(1, jobs), mp_context=ctx) as pool:
        futs = {pool.submit(run_cell, s, c, sd, traffic): (s, c) for s, c, sd in tasks}
        for done, fut in enumerate(as_completed(futs), start=1):
            s, c = futs[fut]
            try:
                got = fut.result()
            except Exception as exc:
                raise RuntimeError(f"{s}: probe cell {c} failed: {exc}") from exc
            rows.extend(got)
            if progress:
                scores = " ".join(f"{r['score']:5.1f}" for r in got)
                print(
                    f"[{done}/{len(tasks)} {time.perf_counter() - t0:6.0f}s] "
                    f"{got[0]['id']:40} {c:13} {scores}",
                    file=sys.stderr,
                )
    rows.sort(key=_row_key)
    return rows


def _row_key(r: dict[str, Any]) -> tuple[Any, ...]:
    return (r["category"], r["id"], _cell_order(r["cell"]), int(r["seed"]))


def _cell_order(cell: str) -> tuple[int, str]:
    return (SWEEP.index(cell), "") if cell in SWEEP else (len(SWEEP), cell)


# -- committed results ------------------------------------------------------------------------
def write_results(path: Path, rows: list[dict[str, Any]]) -> None:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=RESULT_FIELDS, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in sorted(rows, key=_row_key):
        row = {**r, "score": repr(float(r["score"])), "sim_s": repr(float(r["sim_s"]))}
        row["trajectory_hash"] = str(r["trajectory_hash"])[:TRAJECTORY_HASH_HEX]
        w.writerow(row)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(buf.getvalue(), encoding="utf-8")


def read_results(path: Path) -> list[dict[str, Any]]:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read probe results: {exc}") from exc
    rows = []
    for i, r in enumerate(csv.DictReader(io.StringIO(text)), start=2):
        try:
            rows.append({**r, "seed": int(r["seed"]), "score": float(r["score"]), "sim_s": float(r["sim_s"])})
        except (KeyError, TypeError, ValueError) as exc:
            raise ConfigError(f"{path}:{i}: bad probe result row: {exc}") from exc
    return rows


def merge(
    old: list[dict[str, Any]], new: list[dict[str, Any]], keep_ids: set[str] | None = None
) -> list[dict[str, Any]]:
    """`old` with every (id, cell, seed) measured in `new` replaced; with `keep_ids`, rows of
    scenarios no longer in the suite are dropped."""
    key = lambda r: (r["id"], r["cell"], int(r["seed"]))  # noqa: E731
    out = {key(r): r for r in old if keep_ids is None or r["id"] in keep_ids}
    out.update({key(r): r for r in new})
    return sorted(out.values(), key=_row_key)


def ci_subset(
    ids: Iterable[str], cells: Iterable[str] = SWEEP, seeds: Iterable[int] = SEEDS, per_scenario: int = 2
) -> dict[str, list[tuple[str, int]]]:
    """For each scenario, `per_scenario` (cell, seed) pairs of the sweep chosen by a hash of the
    scenario id: a deterministic, stratified sample (every scenario, all cells over the suite)."""
    pairs = [(c, s) for c in cells for s in seeds]
    out: dict[str, list[tuple[str, int]]] = {}
    for sid in sorted(ids):
        ranked = sorted(pairs, key=lambda p: hashlib.sha256(f"{sid}|{p[0]}|{p[1]}".encode()).digest())
        out[sid] = ranked[:per_scenario]
    return out


# -- summary ----------------------------------------------------------------------------------
@dataclass
class Summary:
    categories: list[str]
    cells: list[str]
    counts: dict[str, int]  # scenarios per category
    seeds: list[int]
    table: dict[str, dict[str, float]]  # cell -> category -> mean over scenarios × seeds
    overall: dict[str, float]  # cell -> mean of categories
    completed: dict[str, float]  # cell -> destinations reached per seed (worst seed)
    per_scenario: dict[str, dict[str, float]]  # id -> cell -> mean over seeds
    scenario_category: dict[str, str]

    def worst(self, family: str) -> tuple[dict[str, tuple[float, str]], tuple[float, str]]:
        """Per category the highest score over the family's cells (and which cell), and the
        highest mean of categories."""
        cells = [c for c in self.cells if c.partition("@")[0] == family]
        per = {
            cat: max(((self.table[c][cat], c) for c in cells), key=lambda t: (t[0], -_cell_order(t[1])[0]))
            for cat in self.categories
        }
        overall = max(((self.overall[c], c) for c in cells), key=lambda t: (t[0], -_cell_order(t[1])[0]))
        return per, overall

    def families(self) -> list[str]:
        return [f for f in FAMILIES if any(c.partition("@")[0] == f for c in self.cells)]


def summarize(rows: list[dict[str, Any]]) -> Summary:
    by: dict[tuple[str, str], list[float]] = defaultdict(list)
    scen: dict[tuple[str, str], list[float]] = defaultdict(list)
    done: dict[tuple[str, int], int] = defaultdict(int)
    cat_of: dict[str, str] = {}
    for r in rows:
        by[(r["cell"], r["category"])].append(float(r["score"]))
        scen[(r["id"], r["cell"])].append(float(r["score"]))
        cat_of[r["id"]] = r["category"]
        done[(r["cell"], int(r["seed"]))] += r["termination"] == "destination_reached"
    cats = sorted(set(cat_of.values()))
    cells = sorted({c for c, _ in by}, key=_cell_order)
    seeds = sorted({int(r["seed"]) for r in rows})
    table = {c: {cat: statistics.fmean(by[(c, cat)]) for cat in cats if (c, cat) in by} for c in cells}
    overall = {c: statistics.fmean(table[c].values()) for c in cells}
    completed = {c: float(min(done[(c, s)] for s in seeds)) for c in cells}
    per_scenario: dict[str, dict[str, float]] = defaultdict(dict)
    for (sid, c), v in scen.items():
        per_scenario[sid][c] = statistics.fmean(v)
    counts = {cat: sum(1 for s in cat_of.values() if s == cat) for cat in cats}
    return Summary(cats, cells, counts, seeds, table, overall, completed, dict(per_scenario), cat_of)


def must_holds(s: Summary) -> list[tuple[str, bool, str]]:
    """The suite's discrimination requirements (docs/suite.md), each with what was measured."""
    out: list[tuple[str, bool, str]] = []
    cats_checked = s.categories

    def high(cells: list[str], limit: float, cats: Iterable[str]) -> dict[str, str]:
        return {
            f"{c} {cat}": f"{s.table[c][cat]:.1f}"
            for c in cells
            for cat in cats
            if s.table[c].get(cat, 0.0) > limit
        }

    def fam(name: str, speeds: Iterable[float]) -> list[str]:
        want = {float(v) for v in speeds}
        return [c for c in s.cells if parse_cell(c)[0] == name and parse_cell(c)[1] in want]

    fol = fam("follower", range(4, 13))
    con = fam("constant", range(2, 13))
    lig = fam("lights", range(4, 13))
    bad = high(fol, 50.0, cats_checked)
    out.append(("follower 4–12 m/s: ≤ 50 in every category", bool(fol) and not bad, str(bad)))
    bad = {c: f"{s.overall[c]:.1f}" for c in fol if s.overall[c] > 30.0}
    out.append(("follower 4–12 m/s: ≤ 30 mean of categories", bool(fol) and not bad, str(bad)))
    bad = {c: f"{s.overall[c]:.1f}" for c in con if s.overall[c] > 20.0}
    out.append(("constant 2–12 m/s: ≤ 20 mean of categories", bool(con) and not bad, str(bad)))
    bad = high(con, 40.0, cats_checked)
    out.append(("constant 2–12 m/s: ≤ 40 in every category", bool(con) and not bad, str(bad)))
    bad = high(lig, 50.0, [c for c in cats_checked if c not in LIGHT_ONLY_CATEGORIES])
    out.append(
        (
            "lights 4–12 m/s: ≤ 50 in every category with a hazard other than a light",
            bool(lig) and not bad,
            str(bad),
        )
    )
    if "expert" in s.table:
        bad = {cat: f"{v:.1f}" for cat, v in s.table["expert"].items() if v < 95.0}
        out.append(("expert: ≥ 95 in every category", not bad, str(bad)))
        n = s.completed["expert"]
        need = 0.97 * sum(s.counts.values())
        out.append((f"expert: ≥ {need:g} destinations reached (worst seed)", n >= need, f"{n:g}"))
    else:
        out.append(("expert measured", False, "no expert rows"))
    if "late_expert" in s.overall:
        v = s.overall["late_expert"]
        out.append(("late expert (0.5 s): ≥ 70 mean of categories", v >= 70.0, f"{v:.1f}"))
    else:
        out.append(("late expert measured", False, "no late_expert rows"))
    if "zero" in s.overall:
        v = s.overall["zero"]
        out.append(("zero: ≤ 20 mean of categories", v <= 20.0, f"{v:.1f}"))
    return out


# -- the published table ----------------------------------------------------------------------
def _f(v: float) -> str:
    return f"{v:.1f}"


def _speed(cell: str) -> str:
    v = parse_cell(cell)[1]
    return "" if v is None else f"{v:g}"


def markdown(s: Summary) -> str:
    fams = s.families()
    worst = {f: s.worst(f) for f in fams}
    singles = [c for c in ("expert", "late_expert", "zero") if c in s.cells]
    label = {
        "follower": "blind follower, worst (m/s)",
        "constant": "constant straight, worst (m/s)",
        "lights": "light-obeying, worst (m/s)",
        "expert": "expert",
        "late_expert": "late expert (0.5 s)",
        "zero": "zero",
    }
    cols = [*fams, *singles]
    out = [
        f"Seeds {', '.join(map(str, s.seeds))}; every cell is the mean over scenarios × seeds; "
        "a blind family's entry is its highest score over its speeds (the speed in brackets).",
        "",
        "| category | n | " + " | ".join(label[c] for c in cols) + " |",
        "|---|---:|" + "---:|" * len(cols),
    ]
    for cat in s.categories:
        cells = [f"{_f(worst[f][0][cat][0])} ({_speed(worst[f][0][cat][1])})" for f in fams]
        cells += [_f(s.table[c][cat]) for c in singles]
        out.append(f"| {cat} | {s.counts[cat]} | " + " | ".join(cells) + " |")
    cells = [f"**{_f(worst[f][1][0])}** ({_speed(worst[f][1][1])})" for f in fams]
    cells += [f"**{_f(s.overall[c])}**" for c in singles]
    out.append(f"| **mean of categories** | {sum(s.counts.values())} | " + " | ".join(cells) + " |")
    cells = ["" for _ in fams] + [f"{s.completed[c]:g}" for c in singles]
    out.append("| destination reached (worst seed) | | " + " | ".join(cells) + " |")
    out.append("")
    out.append("Every cell of the sweep (mean of categories; the highest category in brackets):")
    out.append("")
    out.append(
        "| driver | "
        + " | ".join(f"{v:g} m/s" for v in sorted({float(_speed(c)) for c in s.cells if "@" in c}))
        + " |"
    )
    speeds = sorted({float(_speed(c)) for c in s.cells if "@" in c})
    out.append("|---|" + "---:|" * len(speeds))
    for f in fams:
        row = []
        for v in speeds:
            c = next((c for c in s.cells if parse_cell(c) == (f, v)), None)
            if c is None:
                row.append("–")
            else:
                top = max(s.categories, key=lambda cat: s.table[c][cat])  # type: ignore[index]
                row.append(f"{_f(s.overall[c])} ({_f(s.table[c][top])} {top[:2]})")
        out.append(f"| {f} | " + " | ".join(row) + " |")
    out.append("")
    out.append("Must hold (checked by `tests/scenarios/test_suite.py` on the committed results):")
    out.append("")
    for name, ok, detail in must_holds(s):
        out.append(f"- {'✅' if ok else '❌'} {name}" + ("" if ok else f" — measured {detail}"))
    out.append("")
    # Per scenario, for the authors.
    out.append("| scenario | " + " | ".join(label[c] for c in cols) + " |")
    out.append("|---|" + "---:|" * len(cols))
    for sid in sorted(s.per_scenario, key=lambda k: (s.scenario_category[k], k)):
        ps = s.per_scenario[sid]
        cells = []
        for f in fams:
            fc = [c for c in ps if c.partition("@")[0] == f]
            if fc:
                c = max(fc, key=lambda c: (ps[c], -_cell_order(c)[0]))
                cells.append(f"{_f(ps[c])} ({_speed(c)})")
            else:
                cells.append("–")
        cells += [_f(ps[c]) if c in ps else "–" for c in singles]
        out.append(f"| {s.scenario_category[sid]}/{sid} | " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


BEGIN, END = "<!-- probe:begin -->", "<!-- probe:end -->"


def doc_block(path: Path) -> str:
    text = path.read_text(encoding="utf-8")
    if text.count(BEGIN) != 1 or text.count(END) != 1 or text.index(BEGIN) > text.index(END):
        raise ConfigError(f"{path}: needs exactly one {BEGIN} … {END} block")
    return text.split(BEGIN)[1].split(END)[0].removeprefix("\n")


def update_doc(path: Path, table: str) -> None:
    """Replaces the generated part of a Markdown page (between the probe markers)."""
    doc_block(path)
    text = path.read_text(encoding="utf-8")
    head, rest = text.split(BEGIN)
    _, tail = rest.split(END)
    path.write_text(f"{head}{BEGIN}\n{table}{END}{tail}", encoding="utf-8")
