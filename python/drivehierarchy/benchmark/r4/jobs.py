"""What an R4 run does: its options, its jobs (scenario × seed, keyed), and the suite's scenarios."""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drivehierarchy import _core
from drivehierarchy._core import ConfigError
from drivehierarchy.envs.config import R4Config
from drivehierarchy.scenarios import builtin_scenarios, sumo_home

# The paper's inputs: the current frames and the decision text, no history, no controls.
NO_INPUTS: dict[str, Any] = {
    "history": 0,
    "stride": 1,
    "history_bev": False,
    "ego_history": 0,
    "memory": 0,
    "controls": [],
}


@dataclass(frozen=True)
class Job:
    scenario: Path
    key: str  # "<category>__<name>[__s<seed>]", unique in a run
    seed: int = 0

    @property
    def category(self) -> str:
        return self.scenario.parent.name


@dataclass
class RunOptions:
    agent: str = "expert"
    seed: int = 0  # the first seed; `seeds` runs seed, seed + 1, ...
    frames: bool = False
    video: bool = False
    config: R4Config = field(default_factory=R4Config)
    seeds: int = 1
    jobs: int = 1
    vlm: Any = None  # VLMOptions when agent == "vlm"
    ray_address: str | None = None
    progress: bool = False
    # The longest one call to a SUMO worker process may take before the worker counts as hung and
    # is killed (its scenario fails, the others go on); None: no limit. For a registry agent one
    # call drives the whole scenario; for the VLM agent, one env step or message.
    worker_timeout_s: float | None = 600.0
    # Redo every requested scenario even if `results.jsonl` has it (a changed scenario file is
    # refused without it).
    force: bool = False
    # The level the agent decides at (`--action-level`): "control" (the paper's protocol), or this
    # project's extensions "waypoints" and "meta" (docs/r4.md#action-levels). Sets the env's
    # `action_mode`; recorded in the manifest and part of a run's identity.
    action_level: str = "control"

    def __post_init__(self) -> None:
        from drivehierarchy.envs.config import ACTION_LEVELS

        if self.action_level not in ACTION_LEVELS:
            raise ConfigError(
                f"config `action_level` = {self.action_level!r}: expected one of {', '.join(ACTION_LEVELS)}"
            )
        mode = ACTION_LEVELS[self.action_level]
        # The control level is the paper's decision, or the raw control of an RL policy.
        control = self.action_level == "control" and self.config.action_mode in ("decision", "raw")
        if self.config.action_mode != mode and not control:
            self.config = self.config.replace(action_mode=mode)

    def seed_list(self) -> list[int]:
        if self.seeds < 1:
            raise ConfigError(f"config `seeds` = {self.seeds!r}: expected ≥ 1")
        return [self.seed + i for i in range(self.seeds)]

    def identity(self) -> dict[str, Any]:
        """What must match for a run directory to be resumed."""
        ident: dict[str, Any] = {"agent": self.agent, "seeds": self.seed_list()}
        # Set controls only, so that directories of runs without them still resume.
        ident.update({k: v for k, v in self.controls().items() if k in ("conditions", "camera_fault")})
        if self.action_level != "control":  # control-level manifests predate the key
            ident["action_level"] = self.action_level
        if self.vlm is not None:
            m = self.vlm.manifest()
            ident["vlm"] = {k: m[k] for k in ("model", "decoding", "payload", "latency_aware")}
            if self.vlm.history.enabled:
                # Only when used, so directories of runs from before history existed still resume.
                ident["vlm"]["history"] = m["history"]
        return ident

    def inputs(self) -> dict[str, Any]:
        """What the agent is given beyond the paper's one turn (`r4 report`'s input columns)."""
        if self.vlm is not None:
            inputs: dict[str, Any] = self.vlm.inputs()
            return inputs
        return dict(NO_INPUTS)

    def run_facts(self) -> dict[str, Any]:
        """Recorded in the manifest, every results line and the summary."""
        return {"action_level": self.action_level, "inputs": self.inputs()}

    def model_name(self) -> str:
        return str(self.vlm.served_model) if self.vlm is not None else self.agent

    def controls(self) -> dict[str, Any]:
        """The robustness controls this run sets (none: `{}`): `conditions`, `camera_fault`, and
        the VLM payload's `blind`, `no_bev`, `corrupt` and `latency_aware`."""
        out: dict[str, Any] = {}
        if self.vlm is not None:
            p = self.vlm.payload
            out.update({k: True for k in ("blind", "no_bev") if getattr(p, k)})
            if p.corrupt is not None:
                out["corrupt"] = p.corrupt
            if self.vlm.latency_aware:
                out["latency_aware"] = True
        if self.config.conditions is not None:
            out["conditions"] = self.config.conditions
        if self.config.camera_fault is not None:
            out["camera_fault"] = self.config.camera_fault
        return out


def scenario_key(path: Path) -> str:
    return f"{path.parent.name}__{path.stem}"


def jobs_for(scenarios: Iterable[Path], seeds: list[int] | None = None) -> list[Job]:
    """One job per scenario and seed; with several seeds the key carries `__s<seed>`."""
    seeds = seeds if seeds is not None else [0]
    jobs, seen = [], set()
    for p in scenarios:
        base = scenario_key(p)
        if base in seen:
            raise ConfigError(f"config `scenarios` = {p}: two scenarios share the key {base!r}")
        seen.add(base)
        for sd in seeds:
            jobs.append(Job(scenario=p, key=base if len(seeds) == 1 else f"{base}__s{sd}", seed=sd))
    return jobs


def suite_scenarios(suite: str) -> list[Path]:
    """`builtin` (the shipped suite), a folder of `*/*.toml`, or a single file."""
    if suite == "builtin":
        return builtin_scenarios()
    root = Path(suite)
    if root.is_file():
        return [root]
    if not root.exists():
        from drivehierarchy._suggest import did_you_mean

        hint = did_you_mean(suite, ["builtin"]) if "/" not in suite else ""
        raise ConfigError(f"config `suite` = {suite!r}: {root} does not exist{hint}")
    if not root.is_dir():
        raise ConfigError(f"config `suite` = {suite!r}: {root} is neither a folder nor a scenario file")
    found = sorted(root.glob("*/*.toml")) + sorted(root.glob("*.toml"))
    if not found:
        raise ConfigError(f"config `suite` = {suite!r}: no scenario files (*.toml) found under {root}")
    return found


def traffic_mode(scenario: Path, config: R4Config) -> str:
    """The background traffic ("sumo", "idm", "none") the env runs the scenario with: the
    config's `traffic` override, else the scenario's `[traffic]` as the Rust loader resolves it
    (a table without `mode` is SUMO). Loads the scenario, so a bad file is a `ScenarioError` here."""
    from drivehierarchy.envs.traffic import resolve_traffic_mode  # imports libsumo on use

    sim = _core.Sim(str(scenario), config.replace(front=None, bev=None).to_core(), sumo_home())
    return resolve_traffic_mode(config.traffic, sim.scenario_traffic_mode)


def uses_sumo(scenario: Path, config: R4Config) -> bool:
    """Whether the scenario runs SUMO background traffic (then, with several jobs, it runs in a
    worker process of its own: libsumo runs one simulation per process)."""
    return traffic_mode(scenario, config) == "sumo"


_REFERENCE_DURATION = re.compile(r"^\s*reference_duration_s\s*=\s*([0-9.eE+-]+)", re.MULTILINE)


def expected_duration_s(scenario: Path) -> float:
    """The scenario's `reference_duration_s` (0 when it has none): a proxy for its length."""
    m = _REFERENCE_DURATION.search(scenario.read_text(encoding="utf-8"))
    try:
        return float(m.group(1)) if m else 0.0
    except ValueError:
        return 0.0
