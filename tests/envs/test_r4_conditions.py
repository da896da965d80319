"""Light, weather and camera faults as robustness controls: `r4 run/evaluate --conditions NAME
--camera-fault KIND` reach the env, are recorded in the manifest and the summary, keep a run's
identity, and `r4 report` shows a control run as its own row."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from drivehierarchy import ConfigError
from drivehierarchy.benchmark.r4 import report
from drivehierarchy.cli import main
from drivehierarchy.envs.config import R4Config, canonical_conditions
from drivehierarchy.envs.r4 import DriveHierarchyR4Env
from drivehierarchy.scenarios import builtin_root

SCENARIO = builtin_root() / "r4" / "07_sudden_brake"


def one_scenario_suite(tmp_path: Path) -> Path:
    src = sorted(SCENARIO.glob("*.toml"))[0]
    suite = tmp_path / "suite" / "07_sudden_brake"
    suite.mkdir(parents=True)
    (suite / src.name).write_text(src.read_text(encoding="utf-8"), encoding="utf-8")
    return suite.parent


@pytest.mark.parametrize(
    ("name", "canonical"),
    [
        ("night", "night"),
        ("rain+dusk", "dusk+rain"),
        ("noon+clear", "noon"),
        ("clear", "noon"),
        ("fog", "fog"),
    ],
)
def test_condition_names_are_canonical(name: str, canonical: str) -> None:
    assert canonical_conditions(name) == canonical
    assert R4Config(conditions=name).conditions == canonical


@pytest.mark.parametrize("bad", ["snow", "night+dusk", "rain+fog", "", "Night"])
def test_bad_conditions_and_faults_are_config_errors(bad: str) -> None:
    with pytest.raises(ConfigError, match="`conditions`"):
        R4Config(conditions=bad)
    with pytest.raises(ConfigError, match="`camera_fault` = 'cracked'"):
        R4Config(camera_fault="cracked")


def test_the_override_changes_the_images_not_the_world() -> None:
    scenario = str(sorted(SCENARIO.glob("*.toml"))[0])

    def episode(**cfg: str) -> tuple[list[bytes], list[float]]:
        env = DriveHierarchyR4Env(scenario=scenario, config=R4Config(**cfg))  # type: ignore[arg-type]
        try:
            obs, _ = env.reset(seed=2)
            frames, speeds = [obs["front"].tobytes()], []
            for _ in range(6):
                obs, _, term, trunc, _ = env.step(np.array([0.0, 6.0], dtype=np.float32))
                frames.append(obs["front"].tobytes())
                speeds.append(float(obs["state"][0]))
                if term or trunc:
                    break
            return frames, speeds
        finally:
            env.close()

    plain, night, night2 = episode(), episode(conditions="night+rain"), episode(conditions="night+rain")
    assert night == night2  # same seed and actions: the same bytes
    assert night[1] == plain[1]  # the world runs the same
    assert all(a != b for a, b in zip(night[0], plain[0], strict=True))
    frozen = episode(camera_fault="frozen")
    assert frozen[0][0] == plain[0][0] and frozen[1] == plain[1]


def test_cli_records_controls_and_report_shows_their_own_row(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    suite = one_scenario_suite(tmp_path)
    plain, night = tmp_path / "plain", tmp_path / "night"
    assert main(["r4", "evaluate", "--suite", str(suite), "--out", str(plain)]) == 0
    argv = ["r4", "evaluate", "--suite", str(suite), "--out", str(night), "--conditions", "rain+night",
            "--camera-fault", "dirty"]  # fmt: skip
    assert main(argv) == 0
    manifest = json.loads((night / "manifest.json").read_text())
    assert manifest["controls"] == {"conditions": "night+rain", "camera_fault": "dirty"}
    assert manifest["identity"]["conditions"] == "night+rain"
    assert manifest["config"]["conditions"] == "night+rain" and manifest["config"]["camera_fault"] == "dirty"
    assert json.loads((plain / "manifest.json").read_text())["controls"] == {}
    summary = json.loads((night / "summary.json").read_text())
    assert summary["controls"] == manifest["controls"]
    # A plain run is not resumed into the control run's directory.
    capsys.readouterr()
    assert main(["r4", "evaluate", "--suite", str(suite), "--out", str(night)]) == 2
    assert "belongs to another run" in capsys.readouterr().err
    rep = tmp_path / "report"
    assert main(["r4", "report", str(plain), str(night), "--out", str(rep), "--no-plot"]) == 0
    table = (rep / "table2.md").read_text()
    assert "| expert |" in table
    assert "| expert (--conditions night+rain, --camera-fault dirty) |" in table
    assert "expert (--conditions night+rain, --camera-fault dirty)" in (night / "table2.md").read_text()


def test_cli_rejects_a_bad_conditions_name(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    argv = ["r4", "run", "--scenario", "07_sudden_brake/" + sorted(SCENARIO.glob("*.toml"))[0].stem,
            "--out", str(tmp_path / "x"), "--conditions", "snow"]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "`conditions` = 'snow'" in err and "night+rain" in err
    assert not (tmp_path / "x" / "manifest.json").exists()


def test_row_labels_name_every_control() -> None:
    assert report.row_label("m", None) == "m"
    assert report.row_label("m", {}) == "m"
    controls = {"blind": True, "corrupt": "dark", "conditions": "fog", "camera_fault": "frozen"}
    label = "m (--blind, --corrupt dark, --conditions fog, --camera-fault frozen)"
    assert report.row_label("m", {"controls": controls}) == label
    # With an action level and inputs: both kinds of difference name the row.
    summary = {"controls": {"conditions": "night"}, "action_level": "waypoints", "inputs": {"memory": 2}}
    assert report.row_label("m", summary) == "m [waypoints; memory 2] (--conditions night)"
