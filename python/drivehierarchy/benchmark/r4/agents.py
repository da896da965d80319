"""The agents `r4 evaluate --agent NAME` can drive: a registry of named factories (and
`prefix:ARG` factories such as `sb3:PATH`); the VLM agent is driven by the async harness.

The reference drivers of `scenario probe` and the editor are accepted by the same names
(`late_expert`, `follower@V`, `lights@V`, `constant@V`; `suite_probe.parse_cell`), so a probe
row or an editor run is reproduced with `r4 run --agent follower@8`."""

from __future__ import annotations

from collections.abc import Callable

from drivehierarchy._core import ConfigError
from drivehierarchy.agents.base import Agent, ConstantAgent
from drivehierarchy.agents.expert import ExpertAgent


class AgentRegistry:
    """Named agent factories; registering a name twice is an error."""

    def __init__(self) -> None:
        self._factories: dict[str, Callable[[], Agent]] = {}
        # "prefix:ARG" names (e.g. "sb3:runs/ppo/model.zip") → factory(ARG)
        self._prefixes: dict[str, Callable[[str], Agent]] = {}

    def register(self, name: str, factory: Callable[[], Agent]) -> None:
        if name in self._factories:
            raise ValueError(f"agent {name!r} is already registered")
        self._factories[name] = factory

    def register_prefix(self, prefix: str, factory: Callable[[str], Agent]) -> None:
        if prefix in self._prefixes:
            raise ValueError(f"agent prefix {prefix!r} is already registered")
        self._prefixes[prefix] = factory

    def create(self, name: str) -> Agent:
        prefix, sep, arg = name.partition(":")
        if sep and prefix in self._prefixes:
            return self._prefixes[prefix](arg)
        if name in self._factories:
            return self._factories[name]()
        family, at, _ = name.partition("@")
        if at and family in PROBE_FAMILIES:
            from drivehierarchy.suite_probe import _agent, parse_cell

            try:
                parse_cell(name)
            except ConfigError:
                raise ConfigError(
                    f"config `agent` = {name!r}: expected {family}@V with V a speed in m/s in (0, 30] "
                    f"(e.g. {family}@8)"
                ) from None
            # The probe's own factory: the same driver as its rows and the editor's runs.
            return _agent(name)
        from drivehierarchy._suggest import did_you_mean

        known = [*sorted(self._factories), VLM_AGENT]
        raise ConfigError(
            f"config `agent` = {name!r}: unknown agent{did_you_mean(name, known)} (known: "
            f"{', '.join([*known, *PROBE_CELL_FORMS, *(f'{p}:PATH' for p in sorted(self._prefixes))])})"
        )

    def names(self) -> list[str]:
        return sorted(self._factories) + list(PROBE_CELL_FORMS) + [f"{p}:..." for p in sorted(self._prefixes)]


# The probe's speed families (`follower@8`): V in m/s, (0, 30].
PROBE_FAMILIES = ("follower", "lights", "constant")
PROBE_CELL_FORMS = tuple(f"{f}@V" for f in PROBE_FAMILIES)


def _late_expert() -> Agent:
    from drivehierarchy.suite_probe import _agent

    return _agent("late_expert")


AGENTS = AgentRegistry()
AGENTS.register("expert", ExpertAgent)
AGENTS.register("late_expert", _late_expert)
AGENTS.register("zero", lambda: ConstantAgent([0.0, 0.0], name="zero"))
AGENTS.register("constant8", lambda: ConstantAgent([0.0, 8.0], name="constant8"))


def _sb3_agent(path: str) -> Agent:
    from drivehierarchy.agents.sb3 import Sb3Agent  # needs the `rl` extra; imported on use

    return Sb3Agent(path)


AGENTS.register_prefix("sb3", _sb3_agent)

# The VLM agent needs a server (`RunOptions.vlm`) and is driven by the async harness, not a factory.
VLM_AGENT = "vlm"

__all__ = ["AGENTS", "VLM_AGENT", "AgentRegistry", "ConstantAgent"]
