"""The rules that decide what a generated question may say, on hand-made inputs (issue 33):
R1_4's action from the frames shown (a sustained turn, not a weave), colour words from the
renderer's palette names, R2_3's reference heading, the per-class yes/no balance, the per-image
cap, the text-only prior check and the review sheet's verdict file."""

from __future__ import annotations

import json
import math
import random
import subprocess
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import pytest

from drivehierarchy import _core
from drivehierarchy.benchmark.openloop.generate import quality, r1
from drivehierarchy.benchmark.openloop.generate.rollout import (
    ActorState,
    EgoState,
    Frame,
    Moment,
    Rollout,
    RouteLight,
    Visible,
    colour_name,
    shown_colour,
)

REPO = Path(__file__).resolve().parents[3]


# -- R1_4: the ego's action over the frames shown ------------------------------------------------
def test_a_turn_needs_a_sustained_yaw_rate() -> None:
    steady_left = [math.radians(2.5 * k) for k in range(9)]  # 20° over 2 s, every step left
    assert r1.ego_turn(steady_left) == "left"
    assert r1.ego_turn([-y for y in steady_left]) == "right"
    assert r1.ego_turn([0.0] * 9) == "straight"
    weave = [math.radians(v) for v in (0, 4, 8, 4, 0, 4, 8, 12, 16)]  # back and forth, then left
    assert r1.ego_turn(weave) is None
    late_flick = [0.0] * 7 + [math.radians(10), math.radians(18)]  # one noisy step at the end
    assert r1.ego_turn(late_flick) is None
    slight_bend = [math.radians(1.0 * k) for k in range(9)]  # 8°: neither straight nor a turn
    assert r1.ego_turn(slight_bend) is None


def test_speed_action_uses_the_frames_shown_only() -> None:
    assert r1.ego_speed_action([8.0] * 9) == "steady"
    assert r1.ego_speed_action([8.0 - 0.5 * k for k in range(9)]) == "slowing"
    assert r1.ego_speed_action([2.0 + 0.5 * k for k in range(9)]) == "speeding"
    assert r1.ego_speed_action([0.0] * 9) == "stopped"
    # Slowed down, then speeding up again in the last second: neither class, no speed named.
    assert r1.ego_speed_action([8, 7, 6, 5, 4, 4.2, 4.4, 4.6, 4.8]) == "moving"
    # Creeping (below the driving speed) without standing: no clear class at all.
    assert r1.ego_speed_action([1.0, 1.2, 1.0, 1.1, 1.0, 1.2, 1.1, 1.0, 1.1]) is None


def test_speed_words_only_for_a_change_a_person_sees() -> None:
    # Audit: 5.4 → 6.4 m/s over the 2 s shown was called "speeding up"; nobody sees +1 m/s.
    assert r1.ego_speed_action([5.4 + 0.125 * k for k in range(9)]) == "moving"
    # +2.5 m/s from 9 m/s (28 % of the slower end): the ground visibly moves faster.
    assert r1.ego_speed_action([9.0 + 2.5 * k / 8 for k in range(9)]) == "speeding"
    # 2 m/s at 18–20 m/s is only 11 %: not named; 2.5 m/s at 10 m/s is.
    assert r1.ego_speed_action([20.0 - 0.25 * k for k in range(9)]) == "moving"
    assert r1.ego_speed_action([12.6 - 2.6 * k / 8 for k in range(9)]) == "slowing"
    # 1.5 m/s at 3–4.5 m/s is 50 % but below the 2 m/s floor.
    assert r1.ego_speed_action([3.0 + 1.5 * k / 8 for k in range(9)]) == "moving"


# -- colour words ---------------------------------------------------------------------------------
def test_colour_words_use_the_renderers_one_mapping() -> None:
    # Every palette entry is named by the renderer's mapping (render::palette::name_of).
    for entry in _core.colour_palette():
        assert colour_name(tuple(entry["rgb"])) == entry["name"]
    # Colours outside the palette get the name of the range they fall in.
    assert colour_name((230, 230, 230)) == "white"
    assert colour_name((150, 150, 150)) == "silver"


@pytest.mark.parametrize(
    ("painted", "seen", "word"),
    [
        ("red", "red", "red"),
        ("white", "white", "white"),
        ("white", "silver", ""),  # shaded or near a boundary: either word fits
        ("gray", None, ""),  # no body paint visible
        ("brown", "red", ""),
    ],
)
def test_a_colour_word_is_the_name_the_renderer_drew(painted: str, seen: str | None, word: str) -> None:
    assert shown_colour(painted, seen) == word


# -- balancing ------------------------------------------------------------------------------------
def _rec(img: str, q: str, a: str) -> tuple[dict[str, Any], list[Any]]:
    return ({"image_path": img, "question": q, "answer": a}, [])


def test_yes_no_is_half_and_half_within_every_class() -> None:
    groups = {
        "Vehicle": (
            [_rec(f"v{i}", "car?", "Yes") for i in range(50)],
            [_rec(f"w{i}", "car?", "No") for i in range(5)],
        ),
        "Pedestrian": (
            [_rec(f"p{i}", "ped?", "Yes") for i in range(5)],
            [_rec(f"q{i}", "ped?", "No") for i in range(50)],
        ),
    }
    out = quality.balance_binary_by(groups, 40, random.Random(0))
    for q in ("car?", "ped?"):
        answers = [r[0]["answer"] for r in out if r[0]["question"] == q]
        assert answers.count("Yes") == answers.count("No") == 5


def test_an_image_serves_at_most_two_records() -> None:
    groups = {
        "a": [_rec("same.jpg", f"q{i}", "x") for i in range(10)],
        "b": [_rec(f"{i}.jpg", "q", "y") for i in range(10)],
    }
    out = quality.balance_groups(groups, 20, random.Random(0))
    assert sum(1 for r in out if r[0]["image_path"] == "same.jpg") == 2


def test_max_share_caps_one_answer() -> None:
    groups = {
        "straight": [_rec(f"s{i}", "q", "s") for i in range(100)],
        "turn": [_rec(f"t{i}", "q", "t") for i in range(10)],
        "stop": [_rec(f"x{i}", "q", "x") for i in range(10)],
    }
    out = quality.balance_groups(groups, 100, random.Random(0), max_share=0.4)
    n_straight = sum(1 for r in out if r[0]["answer"] == "s")
    assert n_straight <= 0.4 * len(out) + 1e-9 and len(out) == 33
    # Two answers: no share can be below a half.
    two = {k: groups[k] for k in ("straight", "turn")}
    out = quality.balance_groups(two, 100, random.Random(0), max_share=0.4)
    assert len(out) == 20


def test_an_answer_two_classes_share_stays_within_the_task_share() -> None:
    # R1_1_C: "moving" is an option for people and vehicles; standing still is rare.
    by_class = {
        "Pedestrian": {
            "moving": [_rec(f"pm{i}", "qp", "moving") for i in range(60)],
            "standing": [_rec(f"ps{i}", "qp", "standing") for i in range(40)],
        },
        "Vehicle": {
            "moving": [_rec(f"vm{i}", "qv", "moving") for i in range(200)],
            "parked": [_rec(f"vp{i}", "qv", "parked") for i in range(30)],
            "stopped": [_rec(f"vs{i}", "qv", "stopped") for i in range(35)],
        },
    }
    loose = quality.balance_within_classes(by_class, 200, random.Random(0), max_share=0.4)
    assert sum(r[0]["answer"] == "moving" for r in loose) > 0.4 * len(loose)
    out = quality.balance_within_classes(by_class, 200, random.Random(0), max_share=0.4, max_answer_share=0.4)
    answers = Counter(r[0]["answer"] for r in out)
    assert answers["moving"] <= 0.4 * len(out) and len(out) >= 150, answers
    for q, k in (("qp", 2), ("qv", 3)):
        mine = Counter(r[0]["answer"] for r in out if r[0]["question"] == q)
        assert max(mine.values()) <= max(0.4, 1 / k) * sum(mine.values()) + 1e-9, mine


def test_a_single_record_fits_any_share() -> None:
    # --per-task 1 (or 2) must still give records: one of each option is within any share.
    groups = {"moving": [_rec("m.jpg", "q", "m")], "stopped": [_rec("s.jpg", "q", "s")]}
    assert len(quality.balance_groups(groups, 1, random.Random(0), max_share=0.4)) == 1
    assert len(quality.balance_groups(groups, 2, random.Random(0), max_share=0.4)) == 2
    yes, no = [_rec("y.jpg", "q", "Yes")], [_rec("n.jpg", "q", "No")]
    assert len(quality.balance_binary(yes, no, 1, random.Random(0))) == 1


# -- short and empty tasks ------------------------------------------------------------------------
def test_a_short_task_is_a_problem_that_names_the_rules() -> None:
    recs = [_existence(i, "Vehicle", i % 2 == 0) for i in range(4)]
    with quality.tracking() as funnel:
        quality.dropped("an object of the class in the dead band", 7)
        quality.dropped("no clearly nearest object", 3)
        quality.passed(4)
    (row,) = quality.quality_rows({"R1_1_A": recs}, {}, asked=10, funnels={"R1_1_A": funnel})
    (problem,) = row["problems"]
    assert problem.startswith("4 of 10 records: 4 candidates passed the rules")
    assert "an object of the class in the dead band (7), no clearly nearest object (3)" in problem
    assert not quality.format_table([row]).splitlines()[1].endswith("ok")
    (full,) = quality.quality_rows({"R1_1_A": recs}, {}, asked=4, funnels={"R1_1_A": funnel})
    assert full["problems"] == []
    (empty,) = quality.quality_rows({"R1_1_A": []}, {}, asked=1, funnels={"R1_1_A": {"no cue": 5}})
    assert empty["problems"] == ["0 of 1 records: no candidate passed the rules; removed by: no cue (5)"]
    # Outside a builder run nothing is counted.
    quality.dropped("ignored")


# -- the text-only prior --------------------------------------------------------------------------
def _existence(i: int, cat: str, yes: bool) -> dict[str, Any]:
    return {
        "Question_id": f"R1_1_A_{i}",
        "scene_token": f"scene{i % 20}",
        "question": f"Is there any {cat} visible in CAM_FRONT?",
        "answer": "Yes" if yes else "No",
        "image_path": f"images/{i}.jpg",
    }


def test_the_prior_check_finds_a_class_shortcut() -> None:
    # "Yes for Vehicle, No for everything else": the 94 % shortcut.
    recs = [_existence(i, cat, cat == "Vehicle") for i in range(200) for cat in ("Vehicle", "Pedestrian")]
    p = quality.prior_check("R1_1_A", recs)
    assert p["prior"] == 100.0 and p["chance"] == 50.0
    rows = quality.quality_rows({"R1_1_A": recs}, {})
    assert any("text-only prior" in x for x in rows[0]["problems"])
    # Balanced within each class: the question says nothing.
    fair = [_existence(i, cat, i % 2 == 0) for i in range(200) for cat in ("Vehicle", "Pedestrian")]
    p = quality.prior_check("R1_1_A", fair)
    assert abs(p["prior"] - p["chance"]) <= 15.0


# -- the review sheet's verdicts ------------------------------------------------------------------
def test_review_verdicts_are_recorded_beside_the_sheet(tmp_path: Path) -> None:
    out = tmp_path / "review"
    out.mkdir()
    (out / "verdicts.json").write_text(
        json.dumps(
            {
                "data_dir": "x",
                "seed": 3,
                "n": 2,
                "records": [
                    {"id": "R1_1_A_0", "task": "R1_1_A", "verdict": None, "reason": ""},
                    {"id": "R2_3_1", "task": "R2_3", "verdict": None, "reason": ""},
                ],
            }
        ),
        encoding="utf-8",
    )
    script = REPO / "scripts" / "review_generated.py"

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, str(script), "x", "--out", str(out), *args], capture_output=True, text=True
        )

    assert run("--verdict", "R1_1_A_0", "correct").returncode == 0
    assert run("--verdict", "R2_3_1", "wrong").returncode != 0  # a reason is required
    assert run("--verdict", "R2_3_1", "wrong", "subject is Front-Left").returncode == 0
    bad = run("--verdict", "R2_3_1", "maybe", "x")
    assert bad.returncode != 0 and "expected one of" in bad.stderr
    data = json.loads((out / "verdicts.json").read_text(encoding="utf-8"))
    assert [r["verdict"] for r in data["records"]] == ["correct", "wrong"]
    table = run("--table").stdout
    assert "| R2_3 | 0 | 1 | 0 | 0 | 0 |" in table and "review seed 3" in table


def test_bucket_edge_dead_band() -> None:
    # ±10 % around 20 m and 50 m: no bucket with that edge is asked about.
    assert r1.in_edge_band(18.5, 0.0, 20.0) and r1.in_edge_band(21.9, 20.0, 50.0)
    assert r1.in_edge_band(46.0, 20.0, 50.0) and r1.in_edge_band(54.0, 50.0, math.inf)
    assert not r1.in_edge_band(17.0, 0.0, 20.0) and not r1.in_edge_band(35.0, 20.0, 50.0)
    assert not r1.in_edge_band(46.0, 0.0, 20.0)  # another bucket's edge: Near is still clear
    assert not r1.in_edge_band(56.0, 50.0, math.inf)


# -- R1_4: one situation, several wordings that say the same ---------------------------------------
def _situation_moment(speeds: list[float], lead: ActorState | None = None) -> tuple[Moment, list[Frame]]:
    ro = Rollout("s.toml", "s", "06_traffic_flow", "expert", 0, "eval")
    x = 0.0
    for k, v in enumerate(speeds):
        actors = {} if lead is None else {lead.id: lead}
        ro.states.append((0.25 * k, EgoState(x, 0.0, 0.0, v), actors))
        ro.lights.append(RouteLight(100.0, "none"))
        x += 0.25 * v
    box = (700, 400, 900, 560)
    shown = [] if lead is None else [Visible(lead, box, (800, 480), 15.0, 1.0, 9000, 9000, "red")]
    frames = [Frame("CAM_FRONT", s, 0.25 * s, (1600, 900), b"", list(shown)) for s in range(0, 9, 2)]
    return Moment(ro, 8), frames


def test_situation_wordings_say_the_same() -> None:
    m, frames = _situation_moment([5.4 + 0.125 * k for k in range(9)])
    sit = r1.situation(m, frames)
    assert sit is not None and sit.speed == "moving" and sit.cause == "clear"
    # A change too small to see names no speed, in any wording.
    assert len(set(sit.wordings)) == 3
    for w in sit.wordings:
        assert "I am going straight" in w and "road ahead is clear" in w
        assert not any(word in w for word in ("speeding", "slowing", "steady", "km/h", "m/s"))
    assert r1.situation_answer(m, frames) == "I am going straight because the road ahead is clear."
    # A lead car of the ego's lane braking while the ego slows down clearly: every wording names
    # the car, its colour and its braking, in the first person.
    lead = ActorState(
        id=7, kind="car", category="Vehicle", subtype="car", colour="red", rgb=(200, 30, 30),
        x=30.0, y=0.0, yaw=0.0, speed_mps=5.0, length_m=4.5, width_m=1.8, height_m=1.5,
        motion="traffic", braking=True, blinkers=0, status="moving",
    )  # fmt: skip
    m, frames = _situation_moment([12.0 - 0.5 * k for k in range(9)], lead)
    sit = r1.situation(m, frames)
    assert sit is not None and (sit.speed, sit.cause) == ("slowing", "lead")
    for w in sit.wordings:
        assert "slowing down" in w and "red car ahead of me" in w and "braking" in w and "ego" not in w
