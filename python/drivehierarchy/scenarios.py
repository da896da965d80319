"""Where scenarios live: built-in ones by id, or any scenario file by path."""

from __future__ import annotations

import functools
import os
from pathlib import Path

from drivehierarchy import _core
from drivehierarchy._core import ScenarioError

DEFAULT_SCENARIO = "03_turning/town01_03_right_turn_signalised"


def builtin_root() -> Path:
    """The shipped scenario data (`scenarios/` at the top of a checkout links here)."""
    return Path(__file__).resolve().parent / "_data" / "scenarios"


def builtin_scenarios() -> list[Path]:
    """Every built-in R4 scenario file, in suite order (category, then name)."""
    return sorted((builtin_root() / "r4").glob("*/*.toml"))


def scenario_id(path: Path) -> str:
    """`<category>/<name>` of a built-in scenario file."""
    return f"{path.parent.name}/{path.stem}"


def resolve_scenario(scenario: str | Path | None) -> str:
    """A scenario path from a path or a built-in id (`03_turning/town01_right_turn`)."""
    if scenario is None:
        scenario = DEFAULT_SCENARIO
    p = Path(scenario)
    if p.suffix == ".toml" or p.exists():
        if not p.is_file():
            raise ScenarioError(f"{p}: scenario file not found")
        return str(p)
    candidate = builtin_root() / "r4" / f"{scenario}.toml"
    if candidate.is_file():
        return str(candidate)
    from drivehierarchy._suggest import did_you_mean

    ids = [scenario_id(q) for q in builtin_scenarios()]
    raise ScenarioError(
        f"scenario `{scenario}`: not a file and not a built-in scenario id"
        f"{did_you_mean(str(scenario), ids)} (`drivehierarchy scenario list` shows all {len(ids)})"
    )


@functools.cache
def sumo_home() -> str | None:
    """SUMO_HOME for `sumo:` map paths and for starting SUMO, if any: the folder of the installed
    `eclipse-sumo` package, else `$SUMO_HOME` (`_core.sumo_home`, the one lookup of the workspace;
    docs/traffic.md, "Where SUMO is found"). Fixed for the process after the first call.
    """
    return _core.sumo_home()


def sumo_runtime_home() -> str:
    """`sumo_home()` for starting SUMO, with the environment `import sumo` would set up
    (`SUMO_HOME`, and `PROJ_LIB`/`PROJ_DATA` for its projection data) without paying for the
    import; `ImportError` when there is neither the eclipse-sumo package nor `$SUMO_HOME`."""
    home = sumo_home()
    if home is None:
        raise ImportError("no module named 'sumo' (the eclipse-sumo package) and no SUMO_HOME")
    os.environ.setdefault("SUMO_HOME", home)
    if not os.environ.get("PROJ_LIB") and not os.environ.get("PROJ_DATA"):
        os.environ["PROJ_LIB"] = os.environ["PROJ_DATA"] = os.path.join(home, "data", "proj")
    return home
