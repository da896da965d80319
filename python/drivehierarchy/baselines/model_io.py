"""`model.zip` of every trained baseline: a plain Stable-Baselines3 archive plus one extra member,
`drivehierarchy.json`, holding the algorithm and the `WrapperConfig` the policy was trained with
(SB3's loader ignores members it does not know, so the file stays a normal SB3 model)."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any

from drivehierarchy._core import ConfigError
from drivehierarchy.baselines.wrappers import WrapperConfig

META_MEMBER = "drivehierarchy.json"
ALGOS = ("ppo", "sac")


def algo_class(name: str) -> Any:
    try:
        from stable_baselines3 import PPO, SAC
    except ImportError:
        raise ConfigError(
            f"config `algo` = {name!r}: Stable-Baselines3 is not installed (pip install 'drivehierarchy[rl]')"
        ) from None

    classes = {"ppo": PPO, "sac": SAC}
    try:
        return classes[name]
    except KeyError:
        raise ConfigError(f"config `algo` = {name!r}: expected one of {sorted(classes)}") from None


def save_model(model: Any, path: Path, algo: str, wrapper: WrapperConfig, **extra: Any) -> Path:
    """`model.save(path)` then adds the wrapper config inside the archive."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.stem + ".tmp.zip")
    model.save(tmp)
    meta = {"algo": algo, "wrapper": wrapper.to_dict(), **extra}
    with zipfile.ZipFile(tmp, "a") as zf:
        zf.writestr(META_MEMBER, json.dumps(meta, indent=2, sort_keys=True))
    tmp.replace(path)  # atomic: a kill never leaves a half-written model.zip
    return path


def read_meta(path: Path) -> dict[str, Any]:
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"config `model` = {str(path)!r}: file not found")
    try:
        with zipfile.ZipFile(path) as zf:
            if META_MEMBER not in zf.namelist():
                raise ConfigError(
                    f"{path}: field `{META_MEMBER}` missing: not a model saved by `drivehierarchy baselines "
                    "train` (the observation/action wrapping it needs is unknown)"
                )
            meta = json.loads(zf.read(META_MEMBER))
    except zipfile.BadZipFile:
        raise ConfigError(f"{path}: not a zip archive (expected an SB3 model.zip)") from None
    if meta.get("algo") not in ALGOS:
        raise ConfigError(f"{path}: field `algo` = {meta.get('algo')!r}: expected one of {list(ALGOS)}")
    return meta


def load_model(path: Path, env: Any = None, device: str = "cpu") -> tuple[Any, WrapperConfig, dict[str, Any]]:
    meta = read_meta(path)
    model = algo_class(meta["algo"]).load(str(path), env=env, device=device)
    return model, WrapperConfig.from_dict(meta["wrapper"]), meta
