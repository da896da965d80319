"""R3 task builders: outcome prediction and sequential planning (the original release's R3
files).

- R3_1: what an actor shown in CAM_FRONT does over the next seconds, in the original's option
  vocabulary, read from what the actor actually did next in the rollout (its future poses and
  speeds). Motions near a class boundary (a 20° heading change, a half-lane drift, a slowing
  that is neither steady nor a stop) are not asked about. Distractors are options that are
  false for that motion: a turning car is not offered "Decelerate gradually", which it may
  also have done.
- R3_2: the chronological order of 3–5 shuffled CAM_FRONT frames of the ego driving (at least
  2 m/s, as the original's `speed_thresh_mps`, and a few metres apart, so the order shows).
"""

from __future__ import annotations

import itertools
import math
import random
import string
from collections.abc import Sequence
from typing import Any

from .quality import dropped, passed
from .r1 import lamps_visible
from .r2 import _balance_by, _finish, image_path, point_is_unique, sample_token, scene_token
from .rollout import BLINKER_LEFT, BLINKER_RIGHT, DECISION_HZ, FRONT, WHOLE_FIGURE, Moment, Needs, register

HORIZON_S = 3.0
# Vehicles asked about show at least this share of themselves (image border and occluders
# count as hidden): a cut-off vehicle may hide its indicator or lamps (audit: a truck 31 % cut
# off at a roundabout entry).
TARGET_WHOLE = 0.9
# Scenario categories (by a word of their name) whose lanes curve: a heading swing there is
# no turn cue.
CURVED_CATEGORIES = ("roundabout",)
# Actors farther than this are a few pixels wide: not asked about.
OUTCOME_MAX_DISTANCE_M = 40.0
R3_1_QUESTION = "What is the future state of the {desc}. located at [{x0:.1f}, {y0:.1f}, {x1:.1f}, {y1:.1f}]?"
# The original's vocabulary (R3_1_Outcome_Prediction.jsonl), without the final period.
STRAIGHT = "Keep going straight"
TURN_LEFT, TURN_RIGHT = "Turn left", "Turn right"
LANE_LEFT, LANE_RIGHT = "Change to the left lane", "Change to the right lane"
ACCELERATE = "Accelerate and go ahead"
DECELERATE = "Decelerate gradually without braking"
BRAKE_STOP = "Brake gently to a stop"
STATIONARY = "Stationary"
BACK_UP = "Back up"
REVERSE_PARKING = "Reverse parking"
OFFSET_LEFT = "Slightly offset to the left while maneuvering"
OFFSET_RIGHT = "Slightly offset to the right while maneuvering"
VOCABULARY = (
    STRAIGHT, TURN_LEFT, TURN_RIGHT, LANE_LEFT, LANE_RIGHT, ACCELERATE, DECELERATE, BRAKE_STOP,
    STATIONARY, BACK_UP, REVERSE_PARKING, OFFSET_LEFT, OFFSET_RIGHT,
)  # fmt: skip
# Options that are false for an actor whose outcome is the key (and not vague about it): the
# path labels exclude speed labels the actor may also fit, and the other way round.
# (Not "Stationary": a car that starts after two seconds was stationary for most of them.)
_PATH_FALSE = (TURN_LEFT, TURN_RIGHT, LANE_LEFT, LANE_RIGHT, BACK_UP, REVERSE_PARKING)
DISTRACTORS: dict[str, tuple[str, ...]] = {
    TURN_LEFT: (STRAIGHT, TURN_RIGHT, LANE_RIGHT, BACK_UP, REVERSE_PARKING, STATIONARY),
    TURN_RIGHT: (STRAIGHT, TURN_LEFT, LANE_LEFT, BACK_UP, REVERSE_PARKING, STATIONARY),
    LANE_LEFT: (TURN_LEFT, TURN_RIGHT, LANE_RIGHT, BACK_UP, REVERSE_PARKING, STATIONARY),
    LANE_RIGHT: (TURN_LEFT, TURN_RIGHT, LANE_LEFT, BACK_UP, REVERSE_PARKING, STATIONARY),
    # (Not "Accelerate": a moving car with dark lamps may be speeding up. "Brake gently to a
    # stop" only where its dark brake lamps show: `speed_distractors`.)
    STRAIGHT: (TURN_LEFT, TURN_RIGHT, LANE_LEFT, LANE_RIGHT, BACK_UP, STATIONARY),
    # Asked only from a visible standstill (lamps lit, standing): it cannot be slowing down.
    # (Not "Brake gently to a stop": a standing car that stays put fits it as well.)
    ACCELERATE: (*_PATH_FALSE, DECELERATE),
    BRAKE_STOP: (TURN_LEFT, TURN_RIGHT, LANE_LEFT, LANE_RIGHT, BACK_UP, REVERSE_PARKING, ACCELERATE),
    # (Not "Accelerate": a car standing with its lamps lit may move off at any moment.)
    STATIONARY: (STRAIGHT, TURN_LEFT, TURN_RIGHT, LANE_LEFT, LANE_RIGHT, BACK_UP),
}
PEDESTRIAN_DISTRACTORS: dict[str, tuple[str, ...]] = {
    STRAIGHT: (TURN_LEFT, TURN_RIGHT, BACK_UP, STATIONARY),
    STATIONARY: (STRAIGHT, TURN_LEFT, TURN_RIGHT, BACK_UP),
}
NOUN = {"car": "car", "bus": "bus", "truck": "truck", "motorcycle": "motorcycle", "adult": "pedestrian"}

R3_2_SPEED_THRESH_MPS = 2.0
R3_2_MIN_GAP_M = 3.0
R3_2_CLIP = 10  # FRONT frames 2 decisions (0.5 s) apart: the pool the shuffled frames come from
R3_2_NOTE = "Images are shuffled for input; ground_truth_order lists labels in chronological order."


def _wrap_deg(a: float) -> float:
    return (math.degrees(a) + 180.0) % 360.0 - 180.0


def vehicle_outcome(v0: float, yaw0: float, x0: float, y0: float, future: Sequence[Any]) -> str | None:
    """What a vehicle did over `future` (its states, one per decision), or None when the
    motion is near a class boundary. Clear cases only: a person watching the next seconds would
    name the same option."""
    speeds = [s.speed_mps for s in future]
    end = future[-1]
    v_end, v_max, v_min = speeds[-1], max(speeds), min(speeds)
    dyaw = _wrap_deg(end.yaw - yaw0)
    dx, dy = end.x - x0, end.y - y0
    fwd = math.cos(yaw0) * dx + math.sin(yaw0) * dy
    lat = -math.sin(yaw0) * dx + math.cos(yaw0) * dy
    if max(v0, v_max) < 0.2:
        return STATIONARY
    if fwd < -0.5:
        return None  # reversing: not generated (no sim actor reverses on purpose)
    if abs(dyaw) >= 45.0:
        return TURN_LEFT if dyaw > 0 else TURN_RIGHT
    if abs(dyaw) > 10.0:
        return None
    if abs(lat) >= 2.5 and fwd > 5.0:
        return LANE_LEFT if lat > 0 else LANE_RIGHT
    if abs(lat) > 1.0:
        return None
    if v0 >= 2.0 and v_end < 0.2:
        return BRAKE_STOP
    if v_end - v0 >= 2.0 and v_end >= 1.3 * v0:
        return ACCELERATE
    if v0 - v_end >= 2.0 and v_end >= 1.0 and not any(s.braking for s in future):
        return DECELERATE
    if v0 >= 2.0 and abs(v_end - v0) <= 0.15 * v0 and v_min >= 0.8 * v0:
        return STRAIGHT
    return None


# A turn or lane change is asked only when the frame shows it coming: the vehicle's indicator on
# that side is lit, or (turns) its heading has already swung by CUE_YAW_DEG over the last
# CUE_PAST_S toward that side after STRAIGHT_BEFORE_S of driving straight (within STRAIGHT_BEFORE_DEG),
# so it stands visibly askew to the lane it came along. On a curve or in a roundabout a vehicle
# following its lane swings as much without standing askew to anything: there (and whenever the
# heading before is unknown) only the indicator counts. Without a cue, "keep going straight" fits
# the frame as well. An oncoming vehicle (heading more than 90° from the ego's) is never asked
# about a lane change: its left and right are the viewer's right and left.
# Speed changes need their cue too: "Accelerate and go ahead" only from a visible standstill
# (standing with its brake lamps lit, seen from behind), "Brake gently to a stop" only with its
# brake lamps lit and seen; "Decelerate gradually without braking" has no cue in a still frame
# (dark lamps look the same at a steady speed) and is not asked.
CUE_YAW_DEG = 15.0
CUE_PAST_S = 2.0
STRAIGHT_BEFORE_S = 1.0
STRAIGHT_BEFORE_DEG = 3.0
STANDING_MPS = 0.05
_LEFT_SIDE = {TURN_LEFT: True, LANE_LEFT: True, TURN_RIGHT: False, LANE_RIGHT: False}


def frame_cue(
    outcome: str,
    a: Any,
    past_yaw: float | None,
    ego_yaw: float,
    *,
    before_yaw: float | None = None,
    curved: bool = False,
    lamps_seen: bool = False,
) -> bool:
    """Whether the frame that shows vehicle `a` (an `ActorState`) gives a cue for `outcome`.
    `past_yaw` is its heading CUE_PAST_S before the frame and `before_yaw` STRAIGHT_BEFORE_S
    earlier (None when unknown); `curved`: it drives on a curve or in a roundabout;
    `lamps_seen`: its rear (brake lamps) shows clearly in the frame."""
    lit_left, lit_right = bool(a.blinkers & BLINKER_LEFT), bool(a.blinkers & BLINKER_RIGHT)
    if outcome in _LEFT_SIDE:
        left = _LEFT_SIDE[outcome]
        if outcome in (LANE_LEFT, LANE_RIGHT) and abs(_wrap_deg(a.yaw - ego_yaw)) > 90.0:
            return False
        if lit_left != lit_right and lit_left == left:
            return True
        if outcome not in (TURN_LEFT, TURN_RIGHT) or curved or past_yaw is None or before_yaw is None:
            return False
        if abs(_wrap_deg(past_yaw - before_yaw)) > STRAIGHT_BEFORE_DEG:
            return False  # already swinging before: a curve, not a turn off the lane
        swung = _wrap_deg(a.yaw - past_yaw)
        return abs(swung) >= CUE_YAW_DEG and (swung > 0) == left
    if lit_left or lit_right:
        return False  # an indicator lit: a turn or lane change fits the frame too
    if outcome == STATIONARY:
        return bool(a.braking or a.motion == "static")
    if outcome == ACCELERATE:
        return lamps_seen and a.braking and a.speed_mps <= STANDING_MPS
    if outcome == BRAKE_STOP:
        return lamps_seen and a.braking
    return outcome != DECELERATE


def speed_distractors(outcome: str, pool: Sequence[str], a: Any, lamps_seen: bool) -> list[str]:
    """`pool` with "Brake gently to a stop" offered against "Keep going straight" only where the
    frame rules it out (the brake lamps show, dark)."""
    if outcome == STRAIGHT and lamps_seen and not a.braking:
        return [*pool, BRAKE_STOP]
    return list(pool)


def pedestrian_outcome(v0: float, yaw0: float, future: Sequence[Any]) -> str | None:
    speeds = [s.speed_mps for s in future]
    if max(v0, *speeds) < 0.2:
        return STATIONARY
    dyaw = _wrap_deg(future[-1].yaw - yaw0)
    if min(v0, *speeds) >= 0.8 and abs(dyaw) < 15.0:
        return STRAIGHT
    return None


def _past_yaw(m: Moment, actor_id: int, back_s: float = CUE_PAST_S) -> float | None:
    k = m.step - round(back_s * DECISION_HZ)
    if k < 0:
        return None
    past = m.rollout.states[k][2].get(actor_id)
    return None if past is None else past.yaw


@register("R3_1", Needs())
def build_r3_1(moments: Sequence[Moment], n: int, rng: random.Random) -> list[dict[str, Any]]:
    cands = []
    steps = round(HORIZON_S * 4)
    for m in moments:
        f = m.frame(FRONT)
        if f is None:
            dropped("moment without a CAM_FRONT frame")
            continue
        for target in f.visible:
            a = target.actor
            if target.distance_m > OUTCOME_MAX_DISTANCE_M or a.subtype not in NOUN:
                dropped("object over 40 m away or of no asked kind")
                continue
            if not point_is_unique(f, target, target.center_px):
                dropped("the object's box centre lies in another box")
                continue
            future = m.future(a.id, HORIZON_S)
            if len(future) < steps:
                dropped("the object leaves the world within 3 s")
                continue  # left the world before the horizon: its outcome is not known
            if a.category == "Pedestrian":
                if target.visible_fraction < WHOLE_FIGURE:
                    dropped("a pedestrian cut off or half hidden")
                    continue  # walking or standing cannot be told from a cut-off figure
                outcome = pedestrian_outcome(a.speed_mps, a.yaw, future)
                pool = list(PEDESTRIAN_DISTRACTORS.get(outcome or "", ()))
            else:
                if target.visible_fraction < TARGET_WHOLE:
                    dropped("a vehicle cut off or partly hidden")
                    continue  # its indicators, lamps or heading may be out of sight
                outcome = vehicle_outcome(a.speed_mps, a.yaw, a.x, a.y, future)
                seen = lamps_visible(m, target)
                pool = speed_distractors(outcome or "", DISTRACTORS.get(outcome or "", ()), a, seen)
                cue = outcome is not None and frame_cue(
                    outcome,
                    a,
                    _past_yaw(m, a.id),
                    m.ego.yaw,
                    before_yaw=_past_yaw(m, a.id, CUE_PAST_S + STRAIGHT_BEFORE_S),
                    curved=any(c in m.category for c in CURVED_CATEGORIES),
                    lamps_seen=seen,
                )
                if outcome is not None and not cue:
                    dropped("no cue in the frame for the vehicle's next move")
                    continue
            if outcome is None:
                dropped("motion near a class boundary")
                continue
            others = sorted(pool)
            rng.shuffle(others)
            x0, y0, x1, y1 = target.bbox
            u, v = target.center_px
            tag = f"<c1,{FRONT},{u:.1f},{v:.1f}>"
            noun = NOUN[a.subtype]
            colour = target.colour  # as the image shows it
            if noun == "pedestrian":
                desc = f"{noun} wearing {colour}" if colour else noun
            else:
                desc = f"{colour.capitalize()} {noun}" if colour else noun.capitalize()
            rec = {
                "scene_token": scene_token(m),
                "frame_token": sample_token(m),
                "task_type": "L3-1_Outcome_Prediction",
                "question": R3_1_QUESTION.format(desc=desc, x0=x0, y0=y0, x1=x1, y1=y1),
                "options": [outcome, *others[:3]],
                "answer": outcome,
                "meta_data": {
                    "raw_question": f"What is the future state of {tag}?",
                    "raw_answer": f"{outcome}.",
                    "standardized_answer": f"{outcome}.",
                    "target_object_id": tag,
                    "all_object_tags_in_question": [tag],
                    "all_object_tags_in_answer": [],
                    "target_instance_token": str(a.id),
                    "horizon_sec": HORIZON_S,
                    "speeds_mps": [round(a.speed_mps, 3), *(round(s.speed_mps, 3) for s in future)],
                    "visible_fraction": target.visible_fraction,
                },
                "camera_channel": FRONT,
                "image_path": image_path(f),
                "_key": f"{m.key}|{a.id:06d}",
                "_frames": [f],
            }
            cands.append((rec, outcome))
    passed(len(cands))
    picked = _balance_by(cands, n, rng)
    from .quality import letter_options

    letter_options(picked, rng, answer_style="option")
    return _finish(picked, "R3_1_{}", "L3_1_{}", refined_subtask_id="R3-1", original_subtask_id="L3-1")


@register("R3_2", Needs(clip=R3_2_CLIP, clip_stride=2))
def build_r3_2(moments: Sequence[Moment], n: int, rng: random.Random) -> list[dict[str, Any]]:
    cands = []
    for m in moments:
        clip = m.clip(R3_2_CLIP, 2)
        if clip is None:
            dropped("moment without its clip")
            continue
        n_images = 3 + rng.randrange(3)
        # The smallest stride (in clip frames) at which consecutive frames are far enough apart.
        chosen = None
        for stride in (1, 2, 3):
            if (n_images - 1) * stride >= len(clip):
                break
            frames = [clip[k * stride] for k in range(n_images)]
            egos = [m.rollout.states[fr.step][1] for fr in frames]
            if min(e.speed_mps for e in egos) < R3_2_SPEED_THRESH_MPS:
                break
            gaps = [math.hypot(b.x - a.x, b.y - a.y) for a, b in itertools.pairwise(egos)]
            if min(gaps) >= R3_2_MIN_GAP_M:
                chosen = (stride, frames, egos)
                break
        if chosen is None:
            dropped("the ego too slow or the frames under 3 m apart")
            continue
        stride, frames, egos = chosen
        if len({fr.name for fr in frames}) != len(frames):
            dropped("two identical images")
            continue  # two identical images: no order to see
        labels = list(string.ascii_uppercase[:n_images])
        perm = list(range(n_images))
        while perm == sorted(perm):
            rng.shuffle(perm)  # label k shows chronological frame perm[k]; never in order
        images = [
            {"label": labels[k], "path": image_path(frames[perm[k]]), "frame_idx": frames[perm[k]].step}
            for k in range(n_images)
        ]
        order = [labels[perm.index(c)] for c in range(n_images)]
        rec = {
            "scene_token": scene_token(m),
            "images": images,
            "ground_truth_order": order,
            "meta_data": {
                "split": m.rollout.split,
                "log_name": scene_token(m),
                "log_token": scene_token(m),
                "scene_name": m.scenario_id,
                "map_location": m.category,
                "n_images": n_images,
                "stride": stride * 2,
                "speed_thresh_mps": R3_2_SPEED_THRESH_MPS,
                "frame_idxs_chronological": [fr.step for fr in frames],
                "sample_tokens_chronological": [sample_token(m, fr.step) for fr in frames],
                "speeds_mps": [e.speed_mps for e in egos],
                "cam_channel": FRONT,
                "source_log_pkl": None,
                "note": R3_2_NOTE,
            },
            "_key": m.key,
            "_frames": frames,
        }
        cands.append((rec, str(n_images)))
    passed(len(cands))
    picked = _balance_by(cands, n, rng)
    out = _finish(picked, "R3_2_{}", "L3_2_{}", refined_subtask_id="R3-2", original_subtask_id="L3-2")
    for i, rec in enumerate(out):
        # The original has both ids, task_id right after Question_id, and its own task id.
        body = {k: v for k, v in rec.items() if k != "Question_id"}
        rec.clear()
        rec.update({"Question_id": f"R3_2_{i}", "task_id": f"R3_2_{i}", **body})
        frames_ = rec.pop("_frames")
        sub = {k: rec.pop(k) for k in ("refined_subtask_id", "original_subtask_id")}
        rec["original_task_id"] = f"L3-2_Seq_{i:06d}"
        rec.update(sub)
        rec["_frames"] = frames_
    return out
