"""R1 (perception) task builders: R1_1_A–C, R1_2_A–C, R1_3, R1_4.

Every answer comes from the world and the renderer at the moment: which actors the
CAM_FRONT image shows (the visibility rule of `rollout`), their class, status and centre
distance to the ego. Questions whose answer could depend on an object that is only partly
shown (in the image but below the visibility rule) are not asked.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from typing import Any

from . import quality
from .rollout import FRONT, IMAGE_SIZE, Frame, Moment, Needs, Visible, register

CATEGORIES = ("Vehicle", "Pedestrian", "Bicycle", "Traffic Cone")
PLURAL = {
    "Vehicle": "Vehicles",
    "Pedestrian": "Pedestrians",
    "Bicycle": "Bicycles",
    "Traffic Cone": "Traffic Cones",
}
STATUS_OPTIONS = {
    "Vehicle": ("moving", "parked", "stopped"),
    "Pedestrian": ("moving", "standing", "sitting_or_lying"),
}
BUCKETS = (("Near", "<20m", 0.0, 20.0), ("Mid", "20-50m", 20.0, 50.0), ("Far", ">50m", 50.0, math.inf))
# Distances this close to a bucket edge are not asked about (the edge must be clear-cut).
BUCKET_MARGIN_M = 1.5
# A nearest object must be this much nearer than the next one of its class.
NEAREST_MARGIN_M = 2.0
# Objects referred to by a point or a description: near enough to be seen clearly.
MAX_TARGET_M = 80.0
MIN_BOX_PX = 16
W, H = IMAGE_SIZE
RES = f"{W}x{H}"


def image_ref(frame: Frame) -> str:
    """The record's path of a frame's image, relative to the output folder."""
    return f"images/{frame.name}"


def _base(task_dash: str, m: Moment, frame: Frame) -> dict[str, Any]:
    return {
        "scene_token": m.scenario_id,
        "sample_token": f"{m.key}__{frame.camera}",
        "camera_channel": frame.camera,
    }


def _ego_xy(m: Moment, v: Visible) -> list[float]:
    """Object centre in the ego frame (x forward, y left), metres."""
    dx, dy = v.actor.x - m.ego.x, v.actor.y - m.ego.y
    c, s = math.cos(m.ego.yaw), math.sin(m.ego.yaw)
    return [round(dx * c + dy * s, 3), round(-dx * s + dy * c, 3)]


def _clear(frame: Frame, category: str) -> bool:
    """No actor of `category` is only partly shown (so counts and existence are clear-cut)."""
    return not any(p.actor.category == category for p in frame.partial)


def _front_frames(moments: Sequence[Moment]) -> list[tuple[Moment, Frame]]:
    out = []
    for m in moments:
        f = m.frame(FRONT)
        if f is not None and f.size == IMAGE_SIZE:
            out.append((m, f))
    return out


def _finish(recs: list[dict[str, Any]], prefix: str, frames: list[list[Frame]]) -> list[dict[str, Any]]:
    for i, (r, fr) in enumerate(zip(recs, frames, strict=True)):
        key = "task_id" if prefix == "R1_3" else "Question_id"
        r[key] = f"{prefix}_{i}"
        r["_frames"] = fr
    return recs


def _order(rec: dict[str, Any], id_key: str = "Question_id") -> dict[str, Any]:
    """Puts the id first (as in the original files)."""
    return {id_key: None, **rec}


# -- R1_1 ---------------------------------------------------------------------------------------
@register("R1_1_A", needs=Needs())
def r1_1_a(moments: Sequence[Moment], n: int, rng: random.Random) -> list[dict[str, Any]]:
    yes: list[tuple[dict[str, Any], list[Frame]]] = []
    no: list[tuple[dict[str, Any], list[Frame]]] = []
    for m, f in _front_frames(moments):
        for cat in CATEGORIES:
            if not _clear(f, cat):
                continue
            vis = f.visible_of(cat)
            rec = _order(
                {
                    **_base("L1-1", m, f),
                    "question_type": "L1-1_Existence",
                    "question": f"Is there any {cat} visible in CAM_FRONT?",
                    "answer": "Yes" if vis else "No",
                    "meta_data": {
                        "category": cat,
                        **_shown(vis),
                    },
                    "image_path": image_ref(f),
                    "original_Question_id": "",
                    "refined_subtask_id": "R1-1-A",
                    "original_subtask_id": "L1-1-A",
                }
            )
            (yes if vis else no).append((rec, [f]))
    chosen = quality.balance_binary(yes, no, n, rng)
    return _finish([c[0] for c in chosen], "R1_1_A", [c[1] for c in chosen])


@register("R1_1_B", needs=Needs())
def r1_1_b(moments: Sequence[Moment], n: int, rng: random.Random) -> list[dict[str, Any]]:
    by_count: dict[int, list[Any]] = {}
    for m, f in _front_frames(moments):
        for cat in CATEGORIES:
            if not _clear(f, cat):
                continue
            vis = f.visible_of(cat)
            rec = _order(
                {
                    **_base("L1-1", m, f),
                    "question_type": "L1-1_Counting",
                    "question": f"How many {PLURAL[cat]} are visible in CAM_FRONT?",
                    "answer": str(len(vis)),
                    "meta_data": {
                        "category": cat,
                        **_shown(vis),
                    },
                    "image_path": image_ref(f),
                    "original_Question_id": "",
                    "refined_subtask_id": "R1-1-B",
                    "original_subtask_id": "L1-1-B",
                }
            )
            by_count.setdefault(len(vis), []).append((rec, [f]))
    chosen = quality.balance_counts(by_count, n, rng)
    return _finish([c[0] for c in chosen], "R1_1_B", [c[1] for c in chosen])


def _shown(objs: list[Visible]) -> dict[str, Any]:
    """The meta_data of the objects a count or existence answer rests on (ids, distances,
    visible fractions) and the image size."""
    return {
        "object_ids": [str(v.actor.id) for v in objs],
        "distances_m": [v.distance_m for v in objs],
        "visible_fractions": [v.visible_fraction for v in objs],
        "image_size": [W, H],
    }


def _nearest(f: Frame, cat: str) -> Visible | None:
    """The nearest visible object of `cat` when it is clearly the nearest (no partly shown one
    and the runner-up `NEAREST_MARGIN_M` farther)."""
    vis = f.visible_of(cat)
    if not vis or not _clear(f, cat):
        return None
    if len(vis) > 1 and vis[1].distance_m - vis[0].distance_m < NEAREST_MARGIN_M:
        return None
    return vis[0]


@register("R1_1_C", needs=Needs())
def r1_1_c(moments: Sequence[Moment], n: int, rng: random.Random) -> list[dict[str, Any]]:
    by_status: dict[str, list[Any]] = {}
    for m, f in _front_frames(moments):
        for cat, vocab in STATUS_OPTIONS.items():
            v = _nearest(f, cat)
            if v is None or v.actor.status not in vocab:
                continue
            rec = _order(
                {
                    **_base("L1-1", m, f),
                    "question_type": "L1-1_State",
                    "question": f"What is the current status of the nearest {cat} in CAM_FRONT?",
                    "options": list(vocab),
                    "answer": v.actor.status,
                    "meta_data": {
                        "category": cat,
                        "target_object_id": str(v.actor.id),
                        "target_distance_m": v.distance_m,
                        "gt_status": v.actor.status,
                        "speed_mps": round(v.actor.speed_mps, 3),
                        "visible_fraction": v.visible_fraction,
                        "image_size": [W, H],
                    },
                    "image_path": image_ref(f),
                    "original_Question_id": "",
                    "refined_subtask_id": "R1-1-C",
                    "original_subtask_id": "L1-1-C",
                }
            )
            by_status.setdefault(f"{cat}:{v.actor.status}", []).append((rec, [f]))
    chosen = quality.balance_groups(by_status, n, rng)
    recs = [c[0] for c in chosen]
    quality.letter_options(recs, rng, answer_style="letter")
    return _finish(recs, "R1_1_C", [c[1] for c in chosen])


# -- R1_2 ---------------------------------------------------------------------------------------
def _distance_meta(m: Moment, v: Visible) -> dict[str, Any]:
    return {
        "target_instance_token": str(v.actor.id),
        "target_annotation_token": f"{m.key}__{v.actor.id}",
        "true_distance_m": v.distance_m,
        "ego_xy": _ego_xy(m, v),
        "global_center_xyz": [round(v.actor.x, 3), round(v.actor.y, 3), round(v.actor.height_m / 2, 3)],
        "visible_fraction": v.visible_fraction,
    }


def _metres(d: float) -> str:
    return f"{d:.2f} m"


@register("R1_2_A", needs=Needs())
def r1_2_a(moments: Sequence[Moment], n: int, rng: random.Random) -> list[dict[str, Any]]:
    groups: dict[str, list[Any]] = {}
    for m, f in _front_frames(moments):
        for cat in CATEGORIES:
            v = _nearest(f, cat)
            if v is None:
                continue
            rec = _order(
                {
                    **_base("L1-2", m, f),
                    "question_type": "L1_2_Distance_Global",
                    "question": (
                        f"What is the distance to the nearest {cat} in CAM_FRONT? "
                        f"(Image resolution: {RES}). Answer in meters."
                    ),
                    "answer": _metres(v.distance_m),
                    "meta_data": _distance_meta(m, v),
                    "image_path": image_ref(f),
                    "original_Question_id": "",
                    "refined_subtask_id": "R1-2-A",
                    "original_subtask_id": "L1-2-A",
                }
            )
            groups.setdefault(cat, []).append((rec, [f]))
    chosen = quality.balance_groups(groups, n, rng)
    return _finish([c[0] for c in chosen], "R1_2_A", [c[1] for c in chosen])


def _point_target(f: Frame, v: Visible) -> bool:
    """`v`'s box centre names it unambiguously: mostly unoccluded and inside no other box."""
    if v.visible_fraction < 0.8:
        return False
    u, w = v.center_px
    return not any(
        o.actor.id != v.actor.id and o.bbox[0] <= u <= o.bbox[2] and o.bbox[1] <= w <= o.bbox[3]
        for o in [*f.visible, *f.partial]
    )


@register("R1_2_B", needs=Needs())
def r1_2_b(moments: Sequence[Moment], n: int, rng: random.Random) -> list[dict[str, Any]]:
    groups: dict[str, list[Any]] = {}
    for m, f in _front_frames(moments):
        for v in f.visible:
            if v.actor.category not in CATEGORIES or v.distance_m > MAX_TARGET_M or not _point_target(f, v):
                continue
            u, w = v.center_px
            rec = _order(
                {
                    **_base("L1-2", m, f),
                    "question_type": "L1-2_Distance_Pixel",
                    "question": (
                        f"In CAM_FRONT, calculate the distance to the {v.actor.category} located at pixel "
                        f"coordinates [{u}, {w}] (Image resolution: {RES}). Answer in meters."
                    ),
                    "answer": _metres(v.distance_m),
                    "meta_data": {"pixel_coords": [u, w], **_distance_meta(m, v), "bbox": list(v.bbox)},
                    "image_path": image_ref(f),
                    "original_Question_id": "",
                    "refined_subtask_id": "R1-2-B",
                    "original_subtask_id": "L1-2-B",
                }
            )
            groups.setdefault(v.actor.category, []).append((rec, [f]))
    chosen = quality.balance_groups(groups, n, rng)
    return _finish([c[0] for c in chosen], "R1_2_B", [c[1] for c in chosen])


@register("R1_2_C", needs=Needs())
def r1_2_c(moments: Sequence[Moment], n: int, rng: random.Random) -> list[dict[str, Any]]:
    by_count: dict[int, list[Any]] = {}
    for m, f in _front_frames(moments):
        for cat in CATEGORIES:
            if not _clear(f, cat):
                continue
            vis = f.visible_of(cat)
            edges = [lo for _, _, lo, _ in BUCKETS[1:]]
            if any(abs(v.distance_m - e) < BUCKET_MARGIN_M for v in vis for e in edges):
                continue
            for name, label, lo, hi in BUCKETS:
                inside = [v for v in vis if lo <= v.distance_m < hi]
                rec = _order(
                    {
                        **_base("L1-2", m, f),
                        "question_type": "L1-1_DistanceBucket",
                        "question": (
                            f"How many {PLURAL[cat]} are within the {name} range ({label}) in CAM_FRONT?"
                        ),
                        "answer": str(len(inside)),
                        "meta_data": {
                            "category": cat,
                            "bucket": name,
                            "bucket_range": label,
                            **_shown(inside),
                        },
                        "image_path": image_ref(f),
                        "original_Question_id": "",
                        "refined_subtask_id": "R1-2-C",
                        "original_subtask_id": "L1-2-C",
                    }
                )
                by_count.setdefault(len(inside), []).append((rec, [f]))
    chosen = quality.balance_counts(by_count, n, rng)
    return _finish([c[0] for c in chosen], "R1_2_C", [c[1] for c in chosen])


# -- R1_3 ---------------------------------------------------------------------------------------
def _region(f: Frame, v: Visible) -> str:
    u = v.center_px[0] / f.size[0]
    return "on the left side" if u < 0.38 else ("on the right side" if u > 0.62 else "in the middle")


def _motion_phrase(m: Moment, v: Visible) -> str:
    a = v.actor
    if a.category == "Pedestrian":
        return "walking" if a.moving else "standing still"
    if a.status == "parked":
        return "parked"
    if not a.moving:
        return "stopped"
    rel = (a.yaw - m.ego.yaw + math.pi) % (2 * math.pi) - math.pi
    if abs(rel) < math.pi / 4:
        return "driving in the same direction as the ego car"
    if abs(rel) > 3 * math.pi / 4:
        return "driving toward the ego car"
    return "crossing from left to right" if rel < 0 else "crossing from right to left"


def describe(m: Moment, f: Frame, v: Visible) -> str:
    noun = {"Pedestrian": "pedestrian", "Bicycle": "cyclist", "Traffic Cone": "traffic cone"}.get(
        v.actor.category, v.actor.subtype
    )
    colour = "" if v.actor.category == "Pedestrian" else f"{v.actor.colour} "
    where = f"{_region(f, v)} of the image, ahead of the ego car"
    return f"There is a {colour}{noun} {_motion_phrase(m, v)}, {where}."


@register("R1_3", needs=Needs())
def r1_3(moments: Sequence[Moment], n: int, rng: random.Random) -> list[dict[str, Any]]:
    groups: dict[str, list[Any]] = {}
    for m, f in _front_frames(moments):
        descs = {v.actor.id: describe(m, f, v) for v in f.visible}
        for v in f.visible:
            if v.actor.category not in ("Vehicle", "Pedestrian", "Bicycle", "Motorcycle"):
                continue
            d = descs[v.actor.id]
            # The description must single the object out among everything shown, and the box
            # (the whole silhouette) must be mostly unoccluded.
            bw, bh = v.bbox[2] - v.bbox[0], v.bbox[3] - v.bbox[1]
            if (
                v.visible_fraction < 0.8
                or min(bw, bh) < MIN_BOX_PX
                or v.distance_m > MAX_TARGET_M
                or list(descs.values()).count(d) != 1
                or f.partial
            ):
                continue
            rec = {
                "task_id": None,
                "image_path": image_ref(f),
                "question": (
                    f'Please locate the object described as: "{d}". Image resolution: {RES}. Find the '
                    "bounding box and output its diagonal points in the format [xmin, ymin, xmax, ymax]."
                ),
                "ground_truth": {"bbox": list(v.bbox), "format": "xyxy"},
                "meta_data": {
                    "risk": "Yes" if v.distance_m < 20.0 else "No",
                    "scene_classifier": m.category,
                    "agent_type": v.actor.category,
                    "image_resolution": [W, H],
                    "object_id": str(v.actor.id),
                    "visible_fraction": v.visible_fraction,
                    "distance_m": v.distance_m,
                    "scene_token": m.scenario_id,
                    "sample_token": f"{m.key}__{f.camera}",
                },
                "original_task_id": "",
                "refined_subtask_id": "R1-3",
                "original_subtask_id": "L1-3",
            }
            groups.setdefault(v.actor.category, []).append((rec, [f]))
    chosen = quality.balance_groups(groups, n, rng)
    return _finish([c[0] for c in chosen], "R1_3", [c[1] for c in chosen])


# -- R1_4 ---------------------------------------------------------------------------------------
R1_4_FRAMES = 5
R1_4_STRIDE = 2  # 2 Hz: the five frames span the 2 s up to the moment
R1_4_QUESTIONS = (
    "What action are you currently taking as the driver?",
    "What are you doing right now and why?",
    "Describe the current driving situation and your action.",
)
SCENE_PHRASES = {
    "01_pedestrian": "pedestrians may cross the road",
    "02_obstacles": "there are obstacles on the road",
    "03_turning": "the route turns at the junction",
    "04_intersection": "the ego car is crossing an intersection",
    "05_t_intersection": "the ego car is at a T-intersection",
    "06_traffic_flow": "the ego car is driving in traffic",
    "07_sudden_brake": "the vehicle ahead may brake suddenly",
    "08_merging": "traffic is merging",
    "09_yielding": "the ego car has to yield to other road users",
    "10_roundabout": "the ego car is in a roundabout",
}


def situation_answer(m: Moment, frames: list[Frame]) -> str:
    """Templated reference: the ego's action (from its speed change and heading change over
    the next second), the closest road user ahead and the scenario's semantics."""
    fut = m.ego_future(1.0)
    v0 = m.ego.speed_mps
    v1 = fut[-1].speed_mps if fut else v0
    dyaw = ((fut[-1].yaw if fut else m.ego.yaw) - m.ego.yaw + math.pi) % (2 * math.pi) - math.pi
    if v0 < 0.3 and v1 < 0.3:
        action = "I am stopped"
    elif v1 < v0 - 0.5:
        action = "I am slowing down"
    elif v1 > v0 + 0.5:
        action = "I am accelerating"
    else:
        action = f"I am keeping a steady speed of about {round(v0 * 3.6):d} km/h"
    if v0 >= 0.3 or v1 >= 0.3:
        action += (
            " and turning left"
            if dyaw > 0.12
            else (" and turning right" if dyaw < -0.12 else " and going straight")
        )
    near = [
        v
        for v in frames[-1].visible
        if v.actor.category in ("Vehicle", "Pedestrian", "Bicycle", "Motorcycle")
    ]
    why = SCENE_PHRASES.get(m.category, "of the road layout ahead")
    if near:
        v = near[0]
        what = "pedestrian" if v.actor.category == "Pedestrian" else f"{v.actor.colour} {v.actor.subtype}"
        near_text = f"the closest road user ahead is a {what} about {round(v.distance_m)} m away"
        return f"{action} because {why}; {near_text}."
    return f"{action} because {why}; no other road user is visible ahead."


@register("R1_4", needs=Needs(history=R1_4_FRAMES, history_stride=R1_4_STRIDE))
def r1_4(moments: Sequence[Moment], n: int, rng: random.Random) -> list[dict[str, Any]]:
    cands: list[tuple[dict[str, Any], list[Frame]]] = []
    for m in moments:
        frames = m.history(R1_4_FRAMES, R1_4_STRIDE)
        if frames is None:
            continue
        q = R1_4_QUESTIONS[len(cands) % len(R1_4_QUESTIONS)]
        rec = {
            "Question_id": None,
            "task_id": f"R1-4_DriveHierarchy_{m.key}",
            "segment_id": m.key,
            "image_paths": [image_ref(f) for f in frames],
            "question": q,
            "answer": situation_answer(m, frames),
            "original_Question_id": "",
            "original_task_id": "",
            "refined_subtask_id": "R1-4",
            "original_subtask_id": "L1-4",
        }
        cands.append((rec, frames))
    chosen = quality.balance_groups({"all": cands}, n, rng)
    return _finish([c[0] for c in chosen], "R1_4", [c[1] for c in chosen])
