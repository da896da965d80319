"""Background-traffic modes: `sumo` (SUMO co-simulation over a transport chosen in
`envs/traffic/transport.py`), `idm` (the Rust IDM model, `dh_env::world::idm`) and `none`.

The names come from the Rust `TrafficMode` (`_core.constants()`); a deprecated name (`native`
for `idm`) is accepted for one release with a `DeprecationWarning`.
"""

from __future__ import annotations

import warnings

from drivehierarchy import _core
from drivehierarchy._core import ConfigError

_FACTS = _core.constants()
TRAFFIC_MODES: tuple[str, ...] = tuple(_FACTS["traffic_modes"])
DEPRECATED_TRAFFIC_MODES: dict[str, str] = dict(_FACTS["deprecated_traffic_modes"])


def canonical_traffic_mode(mode: str, where: str = "config `traffic`", stacklevel: int = 2) -> str:
    """`mode` under its current name (a `DeprecationWarning` for an old one); `ConfigError` for
    an unknown one. `where` names the setting in messages."""
    new = DEPRECATED_TRAFFIC_MODES.get(mode) if isinstance(mode, str) else None
    if new is not None:
        warnings.warn(
            f"{where} = {mode!r} is deprecated and will be removed in the next release: use {new!r}",
            DeprecationWarning,
            stacklevel=stacklevel + 1,
        )
        return new
    if mode not in TRAFFIC_MODES:
        raise ConfigError(f"{where} = {mode!r}: expected one of {', '.join(TRAFFIC_MODES)}")
    return mode


def resolve_traffic_mode(config_mode: str | None, scenario_mode: str) -> str:
    """The effective mode: the env config's `traffic=` if set, else the scenario's."""
    if config_mode is None:
        return canonical_traffic_mode(scenario_mode, "scenario `[traffic] mode`", stacklevel=3)
    return canonical_traffic_mode(config_mode, stacklevel=3)


def deprecated_scenario_mode(path: str, text: str | None = None) -> str | None:
    """The message for a scenario file whose `[traffic] mode` is an old name (the core reads it as
    the new one, so only the file says it), else None. Unreadable files are left to the core."""
    import tomllib

    try:
        if text is None:
            with open(path, "rb") as fh:
                doc = tomllib.load(fh)
        else:
            doc = tomllib.loads(text)
    except (OSError, tomllib.TOMLDecodeError):
        return None
    traffic = doc.get("traffic")
    mode = traffic.get("mode") if isinstance(traffic, dict) else None
    if not isinstance(mode, str) or mode not in DEPRECATED_TRAFFIC_MODES:
        return None
    return (
        f"{path}: field `traffic.mode` = {mode!r} is deprecated and will be removed in the next "
        f"release: use {DEPRECATED_TRAFFIC_MODES[mode]!r}"
    )


def warn_deprecated_scenario_mode(path: str, text: str | None = None) -> None:
    """A `DeprecationWarning` when the scenario file's `[traffic] mode` is an old name."""
    msg = deprecated_scenario_mode(path, text)
    if msg is not None:
        warnings.warn(msg, DeprecationWarning, stacklevel=3)


def traffic_mode_arg(value: str) -> str:
    """argparse `type` of a `--traffic` option: a current mode name, or an old one with the
    deprecation also printed on stderr (a CLI user does not see Python warnings)."""
    import argparse
    import sys

    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            mode = canonical_traffic_mode(value, "--traffic")
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    for w in caught:
        print(f"warning: {w.message}", file=sys.stderr)
        warnings.warn(str(w.message), w.category, stacklevel=2)
    return mode
