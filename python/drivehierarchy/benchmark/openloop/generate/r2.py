"""R2 task builders: multi-view and temporal memory, spatial relations (docs/protocol.md#open-loop-tasks, the
original release's R2 files).

- R2_1: unique vehicles across the six surround cameras, each vehicle counted once;
- R2_2_A: unique vehicles in CAM_FRONT over 10 frames at 2 Hz;
- R2_2_B: the state transition of an object given by pixel coordinates, over a clip;
- R2_3: where one object is relative to another, in the ego car's axes centred on the reference
  object (the original's "Using the car as a reference frame": `gt_relation` follows from the
  two objects' ego-frame positions).

Ground truth comes from the world (actor ids, classes, poses, speeds, motion kinds) and the
renderer (which actors each camera shows, `rollout.Visible`). A question is not asked when an
object the camera shows only in part could change its answer, when a pixel point could name two
objects, or when a relation or state lies near a class boundary.
"""

from __future__ import annotations

import itertools
import math
import random
from collections.abc import Iterable, Sequence
from typing import Any

from .quality import dropped, passed
from .rollout import FRONT, SURROUND, Frame, Moment, Needs, Visible, register

VEHICLE_CATEGORIES = ("Vehicle", "Motorcycle")

R2_1_QUESTION = (
    "Given the 6 surround-view images (Front, Front-Left, Front-Right, Back, Back-Left, Back-Right) "
    "at this timestamp, how many unique vehicles are visible in the surrounding environment?"
)
R2_2_A_FRAMES = 10
R2_2_A_STRIDE = 2  # decisions at 4 Hz: 2 Hz keyframes, as the original's nuScenes samples
R2_2_A_QUESTION = (
    "Observing the sequence starting from this frame for the next {window:.1f} seconds (including "
    "the current frame), how many unique vehicles appear in CAM_FRONT?"
)
R2_2_B_FRAMES = 9  # t = 0 … 4.0 s at 2 Hz
R2_2_B_MIN_FRAMES = 5  # … down to t = 2.0 s when the object leaves the view earlier
R2_2_B_QUESTION = (
    "Focus on the {category} at pixel coordinates [{u}, {v}] in the initial frame (Image resolution: "
    "{w}x{h}), located in the {region} region. Observing the clip from t=0s to t={dur:.1f}s, how does "
    "its state change?"
)
R2_3_QUESTION = (
    "In CAM_FRONT, what is the position of the {s_cat} located at pixel coordinates [{su}, {sv}] "
    "relative to the {r_cat} located at pixel coordinates [{ru}, {rv}] (Image resolution: {w}x{h}. "
    "Using the car as a reference frame)?"
)
# States whose speed is this close to the moving/stopped threshold are not asked about: in
# frames half a second apart a person cannot tell them.
CLEARLY_MOVING_MPS = 1.0
CLEARLY_STILL_MPS = 0.1
R2_2_B_MAX_SHARE = 0.3
STATES = {"Vehicle": ("moving", "stopped", "parked"), "Pedestrian": ("moving", "standing", "sitting/lying")}
ATTRIBUTE = {"sitting/lying": "sitting_lying_down"}
# Relations: sector centre (degrees, counter-clockwise from the ego's forward axis), name.
RELATIONS = (
    (0.0, "Front"),
    (45.0, "Front-Left"),
    (90.0, "Left"),
    (135.0, "Rear-Left"),
    (180.0, "Rear"),
    (-135.0, "Rear-Right"),
    (-90.0, "Right"),
    (-45.0, "Front-Right"),
)
# Only pairs within this many degrees of a sector's centre (sectors are 45° wide; the rest is a
# no-ask margin) and at least this far apart.
RELATION_MARGIN_DEG = 15.0
RELATION_MIN_GAP_M = 3.0
# ... and at least this share of the farther one's distance from the ego: a few metres of depth
# show at 10 m, not at 30 m.
RELATION_MIN_GAP_SHARE = 0.25
# Farther than this, depth is hard to judge in the image: neither object may be.
RELATION_MAX_DISTANCE_M = 40.0
RELATION_CATEGORIES = ("Vehicle", "Pedestrian", "Bicycle", "Motorcycle", "Traffic Cone")
# The reference object must have a front (not a cone) and face within this many degrees of the
# ego's heading: then its own axes agree with the ego's on the answer (sectors are 45° wide and
# asked only within RELATION_MARGIN_DEG of their centre).
REFERENCE_CATEGORIES = ("Vehicle", "Pedestrian", "Bicycle", "Motorcycle")
REFERENCE_HEADING_DEG = 45.0


# -- shared helpers (also used by r3) ------------------------------------------------------------
def image_path(frame: Frame) -> str:
    return f"images/{frame.name}"


def scene_token(m: Moment) -> str:
    return f"{m.scenario_id}__{m.driver}__s{m.seed}"


def sample_token(m: Moment, step: int | None = None) -> str:
    return f"{scene_token(m)}__{m.step if step is None else step:04d}"


def region(u: int, v: int, size: tuple[int, int]) -> str:
    """The original's coarse location: top/middle/bottom × left/center/right thirds."""
    w, h = size
    row = ("top", "middle", "bottom")[min(2, 3 * v // h)]
    col = ("left", "center", "right")[min(2, 3 * u // w)]
    return f"{row}-{col}"


def point_is_unique(frame: Frame, target: Visible, point: tuple[int, int]) -> bool:
    """Whether `point` lies in no other shown actor's box (else it could name two objects)."""
    u, v = point
    for other in (*frame.visible, *frame.partial):
        if other.actor.id == target.actor.id:
            continue
        x0, y0, x1, y1 = other.bbox
        if x0 <= u <= x1 and y0 <= v <= y1:
            return False
    return True


# Where in its box an object is pointed at: the centre first, then inner points of the box (a
# box is mostly the object's silhouette there), so a partly overlapped object can still be named.
_POINT_FRACTIONS = ((0.5, 0.5), (0.3, 0.5), (0.7, 0.5), (0.5, 0.3), (0.5, 0.7), (0.3, 0.3), (0.7, 0.3),
                    (0.3, 0.7), (0.7, 0.7))  # fmt: skip


def unique_point(frame: Frame, target: Visible) -> tuple[int, int] | None:
    """A pixel of `target`'s box that lies in no other shown actor's box, or None."""
    x0, y0, x1, y1 = target.bbox
    for fx, fy in _POINT_FRACTIONS:
        point = (round(x0 + fx * (x1 - x0)), round(y0 + fy * (y1 - y0)))
        if point_is_unique(frame, target, point):
            return point
    return None


def _ambiguous_ids(frames: Iterable[Frame], categories: Sequence[str]) -> tuple[set[int], set[int]]:
    """(ids shown clearly in some frame, ids shown only in the dead band in every frame)."""
    clear: set[int] = set()
    unclear: set[int] = set()
    for f in frames:
        clear.update(v.actor.id for v in f.visible if v.actor.category in categories)
        unclear.update(v.actor.id for v in f.blocking(categories))
    return clear, unclear - clear


def sliver_only(frames: Sequence[Frame], ids: Iterable[int]) -> bool:
    """Whether a counted object (`ids`) never shows a recognisable part of its body in `frames`
    (`Visible.recognisable`): a roof sliver above a nearer car may or may not be counted."""
    return any(not any(v.recognisable for f in frames for v in f.visible if v.actor.id == i) for i in ids)


def identity_unclear(frames: Sequence[Frame], ids: Iterable[int]) -> bool:
    """Whether the clip cannot tell one counted vehicle (`ids`) from another: one leaves the view
    and comes back, or one leaves and a vehicle that looks alike (same kind, same or an unclear
    colour word) enters later. At 2 Hz a person cannot track identity across such a gap."""
    present: dict[int, list[int]] = {}
    looks: dict[int, tuple[str, set[str]]] = {}
    for k, f in enumerate(frames):
        for v in [*f.visible, *f.blocking(VEHICLE_CATEGORIES)]:
            if v.actor.category not in VEHICLE_CATEGORIES:
                continue
            if not present.get(v.actor.id) or present[v.actor.id][-1] != k:
                present.setdefault(v.actor.id, []).append(k)
            if v.colour:
                looks.setdefault(v.actor.id, (v.actor.subtype, set()))[1].add(v.colour)
            looks.setdefault(v.actor.id, (v.actor.subtype, set()))
    counted = set(ids)
    for i in counted:
        ks = present.get(i, [])
        if any(b - a > 1 for a, b in itertools.pairwise(ks)):
            return True
    for i in sorted(counted):
        for j in sorted(present):
            if j == i or i not in present:
                continue
            (si, ci), (sj, cj) = looks[i], looks[j]
            alike = si == sj and (not ci or not cj or bool(ci & cj))
            if alike and (present[i][-1] < present[j][0] or present[j][-1] < present[i][0]):
                return True
    return False


def cyclist_shown(frames: Iterable[Frame]) -> bool:
    """A bicycle shows (clearly or in the dead band) in one of `frames`: a person may count it
    among "vehicles" (nuScenes does) while the answer, like the original's, counts motor
    vehicles only, so no vehicle count is asked (as R1's `_clear`)."""
    return any(f.blocking("Bicycle") or any(v.actor.category == "Bicycle" for v in f.visible) for f in frames)


def _distribution(values: Iterable[str]) -> dict[str, int]:
    out: dict[str, int] = {}
    for v in values:
        out[v] = out.get(v, 0) + 1
    return dict(sorted(out.items(), key=lambda kv: (-kv[1], kv[0])))


def _balance_counts(
    cands: list[tuple[dict[str, Any], int]], n: int, rng: random.Random
) -> list[dict[str, Any]]:
    from .quality import balance_counts

    by: dict[int, list[Any]] = {}
    for rec, count in cands:
        by.setdefault(count, []).append((rec,))
    return [item[0] for item in balance_counts(by, n, rng)]


def _balance_by(cands: list[tuple[dict[str, Any], str]], n: int, rng: random.Random) -> list[dict[str, Any]]:
    """Balanced over the answers: no answer is that of more than MAX_OPTION_SHARE of the records."""
    from .quality import MAX_OPTION_SHARE, balance_groups

    by: dict[str, list[Any]] = {}
    for rec, key in cands:
        by.setdefault(key, []).append((rec,))
    return [item[0] for item in balance_groups(by, n, rng, max_share=MAX_OPTION_SHARE)]


def _sorted_by_key(recs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Final order: by moment (deterministic, independent of the balancing's draw order)."""
    return sorted(recs, key=lambda r: r["_key"])


def _finish(recs: list[dict[str, Any]], id_fmt: str, orig_fmt: str, **fixed: str) -> list[dict[str, Any]]:
    """Numbers the records in their final order and fixes the original's trailing fields."""
    out = []
    for i, rec in enumerate(_sorted_by_key(recs)):
        rec.pop("_key")
        frames = rec.pop("_frames")
        body = {k: v for k, v in rec.items()}
        first = {"Question_id": id_fmt.format(i)}
        tail = {"original_Question_id": orig_fmt.format(i), **fixed}
        out.append({**first, **body, **tail, "_frames": frames})
    return out


# -- R2_1 -----------------------------------------------------------------------------------------
# About half the surround moments have a vehicle in the gray zone somewhere (no question).
@register("R2_1", Needs(cameras=SURROUND, oversample=2.5))
def build_r2_1(moments: Sequence[Moment], n: int, rng: random.Random) -> list[dict[str, Any]]:
    cands = []
    for m in moments:
        frames = [m.frame(cam) for cam in SURROUND]
        if any(f is None for f in frames):
            dropped("moment without the six surround frames")
            continue
        clear, unclear = _ambiguous_ids(frames, VEHICLE_CATEGORIES)  # type: ignore[arg-type]
        if unclear:
            dropped("a vehicle shown only in the dead band")
            continue
        if cyclist_shown(frames):  # type: ignore[arg-type]
            dropped("a bicycle shown: is it a vehicle?")
            continue
        seen_in: dict[int, list[str]] = {}
        actor_of: dict[int, Visible] = {}
        fraction: dict[str, dict[str, float]] = {}
        for cam, f in zip(SURROUND, frames, strict=True):
            assert f is not None
            for v in f.visible:
                if v.actor.category in VEHICLE_CATEGORIES:
                    seen_in.setdefault(v.actor.id, []).append(cam)
                    actor_of.setdefault(v.actor.id, v)
                    fraction.setdefault(str(v.actor.id), {})[cam] = v.visible_fraction
        count = len(clear)
        rec = {
            "scene_token": scene_token(m),
            "sample_token": sample_token(m),
            "question_type": "L2_1_A_Multiview_memory(CrossView_Counting)",
            "question": R2_1_QUESTION,
            "answer": str(count),
            "meta_data": {
                "overlapping_instances": [str(i) for i in sorted(seen_in) if len(seen_in[i]) > 1],
                "total_unique_count": count,
                "camera_breakdown": {
                    cam: sum(1 for v in f.visible if v.actor.category in VEHICLE_CATEGORIES)  # type: ignore[union-attr, misc]
                    for cam, f in zip(SURROUND, frames, strict=True)
                },
                "subtype_distribution": _distribution(actor_of[i].actor.subtype for i in sorted(actor_of)),
                "camera_channels": list(SURROUND),
                # nuScenes' visibility token and box-corner rule do not apply: the sim's rule is
                # the renderer's unoccluded share and pixel count (rollout.Visible).
                "min_visibility_token": None,
                "min_inside_corners": None,
                "visible_fraction": dict(sorted(fraction.items(), key=lambda kv: int(kv[0]))),
            },
            "image_paths": [image_path(f) for f in frames],  # type: ignore[arg-type]
            "image_paths_map": {cam: image_path(f) for cam, f in zip(SURROUND, frames, strict=True)},  # type: ignore[arg-type]
            "_key": m.key,
            "_frames": frames,
        }
        cands.append((rec, count))
    passed(len(cands))
    picked = _balance_counts(cands, n, rng)
    return _finish(
        picked, "R2_1_A_{}", "L2_1_A_{}", refined_subtask_id="R2-1-A", original_subtask_id="L2-1-A"
    )


# -- R2_2_A ---------------------------------------------------------------------------------------
# Over 10 frames a vehicle in the gray zone is likelier than in one: more candidates needed.
@register("R2_2_A", Needs(clip=R2_2_A_FRAMES, clip_stride=R2_2_A_STRIDE, oversample=2.5))
def build_r2_2_a(moments: Sequence[Moment], n: int, rng: random.Random) -> list[dict[str, Any]]:
    cands = []
    for m in moments:
        clip = m.clip(R2_2_A_FRAMES, R2_2_A_STRIDE)
        if clip is None:
            dropped("moment without its 10-frame clip")
            continue
        clear, unclear = _ambiguous_ids(clip, VEHICLE_CATEGORIES)
        if unclear:
            dropped("a vehicle shown only in the dead band")
            continue
        if cyclist_shown(clip):
            dropped("a bicycle shown: is it a vehicle?")
            continue
        if sliver_only(clip, clear):
            dropped("a counted vehicle shows only a sliver (e.g. its roof) in every frame")
            continue
        if identity_unclear(clip, clear):
            dropped("a vehicle leaves the view and it or a look-alike enters later")
            continue
        actor_of = {v.actor.id: v for f in clip for v in f.visible if v.actor.id in clear}
        window = R2_2_A_FRAMES / 2.0
        rec = {
            "scene_token": scene_token(m),
            "sample_token_list": [sample_token(m, f.step) for f in clip],
            "camera_channel": FRONT,
            "question_type": "L2_1_B_Temporal_Sequence(Temporal_Counting)",
            "question": R2_2_A_QUESTION.format(window=window),
            "answer": str(len(clear)),
            "meta_data": {
                "time_window_sec": window,
                "keyframe_hz": 2.0,
                "frame_count": len(clip),
                "actual_span_sec": round(clip[-1].t_s - clip[0].t_s, 6),
                "unique_instance_tokens": [str(i) for i in sorted(clear)],
                "category_distribution": _distribution(actor_of[i].actor.subtype for i in sorted(actor_of)),
                "segmentation": "clipped_non_overlapping",
                "visible_fraction": {
                    str(i): max(v.visible_fraction for f in clip for v in f.visible if v.actor.id == i)
                    for i in sorted(clear)
                },
            },
            "image_paths": [image_path(f) for f in clip],
            "_key": m.key,
            "_frames": clip,
        }
        cands.append((rec, len(clear)))
    passed(len(cands))
    picked = _balance_counts(cands, n, rng)
    return _finish(
        picked, "R2_1_B_{}", "L2_1_B_{}", refined_subtask_id="R2-1-B", original_subtask_id="L2-1-B"
    )


# -- R2_2_B ---------------------------------------------------------------------------------------
def clear_state(category: str, status: str, speed: float) -> str | None:
    """The state a person can tell from frames half a second apart, or None near a threshold."""
    if category == "Vehicle" and status == "parked":
        return "parked"
    if speed >= CLEARLY_MOVING_MPS:
        return "moving"
    if speed <= CLEARLY_STILL_MPS:
        return "stopped" if category == "Vehicle" else "standing"
    return None


def transition_text(start: str, end: str) -> str:
    if start == end:
        return f"No Change (It remains {start})"
    return f"It transitions from {start} to {end}"


def _state_at(m: Moment, step: int, actor_id: int, category: str) -> str | None:
    actor = m.rollout.states[step][2].get(actor_id)
    if actor is None:
        return None
    return clear_state(category, actor.status, actor.speed_mps)


# Clips also at the extra anchors where a still object is in view: remaining and changing
# "parked", "stopped" and "standing" are rare at the regular ones.
@register("R2_2_B", Needs(clip=R2_2_B_FRAMES, clip_stride=R2_2_A_STRIDE, oversample=4.0, at_still=True))
def build_r2_2_b(moments: Sequence[Moment], n: int, rng: random.Random) -> list[dict[str, Any]]:
    cands: list[tuple[dict[str, Any], str]] = []
    for m in moments:
        full = m.clip(R2_2_B_FRAMES, R2_2_A_STRIDE)
        if full is None:
            dropped("moment without its 9-frame clip")
            continue
        first = full[0]
        for target in first.visible:
            cat = target.actor.category
            # A far speck's state change is not something a person can see (audit, issue 33).
            if cat not in STATES or target.distance_m > RELATION_MAX_DISTANCE_M:
                dropped("object not a vehicle or pedestrian within 40 m")
                continue
            point = unique_point(first, target)
            if point is None:
                dropped("no pixel of the object's box outside every other box")
                continue
            # The longest clip (4 s down to 2 s, as the original's varying durations) whose last
            # frame still shows the object, with the state holding over the first two and the
            # last two frames (seen, not guessed).
            found = None
            for k in range(R2_2_B_FRAMES, R2_2_B_MIN_FRAMES - 1, -1):
                clip = full[:k]
                if target.actor.id not in {v.actor.id for v in clip[-1].visible}:
                    continue
                start = {_state_at(m, f.step, target.actor.id, cat) for f in clip[:2]}
                end = {_state_at(m, f.step, target.actor.id, cat) for f in clip[-2:]}
                if len(start) == 1 and len(end) == 1 and None not in start and None not in end:
                    found = (clip, start.pop(), end.pop())
                    break
            if found is None:
                dropped("state unclear at either end of every clip that shows the object")
                continue
            clip, s, e = found
            last = clip[-1]
            assert s is not None and e is not None
            answer = transition_text(s, e)
            states = STATES[cat]
            # A parked and a stopped vehicle look alike in a clip: no distractor differs from
            # the key only by that swap.
            look = {"parked": "still", "stopped": "still"}
            seen = (look.get(s, s), look.get(e, e))
            pool = [
                transition_text(a, b)
                for a in states
                for b in states
                if (look.get(a, a), look.get(b, b)) != seen
            ]
            others = sorted(pool)
            rng.shuffle(others)
            u, v = point
            dur = last.t_s - first.t_s
            category = cat.lower()
            rec: dict[str, Any] = {
                "scene_token": scene_token(m),
                "sample_token_list": [sample_token(m, f.step) for f in clip],
                "target_instance_token": str(target.actor.id),
                "question_type": "L2-3_Event_State_Transition",
                "camera_channel": FRONT,
                "question": R2_2_B_QUESTION.format(
                    category=cat,
                    u=u,
                    v=v,
                    w=first.size[0],
                    h=first.size[1],
                    region=region(u, v, first.size),
                    dur=dur,
                ),
                "options": [answer, *others[:3]],
                "answer": answer,
                "meta_data": {
                    "start_attribute": f"{category}.{ATTRIBUTE.get(s, s)}",
                    "end_attribute": f"{category}.{ATTRIBUTE.get(e, e)}",
                    "duration_sec": round(dur, 3),
                    "is_state_change": s != e,
                    "u": u,
                    "v": v,
                    "mcq_key": f"{scene_token(m)}|{sample_token(m, first.step)}|{sample_token(m, last.step)}|"
                    f"{target.actor.id}|{FRONT}",
                    "mcq_global_seed": None,
                    "visible_fraction": target.visible_fraction,
                },
                "image_paths": [image_path(f) for f in clip],
                "_key": f"{m.key}|{target.actor.id:06d}",
                "_frames": clip,
            }
            cands.append((rec, answer))
    passed(len(cands))
    # Balanced within each question template (the asked class and region words, numbers blanked):
    # what a text-only rule learns its commonest answer for.
    from .quality import balance_within_classes, letter_options, template

    by: dict[str, dict[str, list[Any]]] = {}
    for rec, answer in cands:
        by.setdefault(template(rec["question"]), {}).setdefault(answer, []).append((rec,))
    # Tighter than the task-wide cap: a question's region words would otherwise let a text-only
    # rule pick the commonest state per region.
    picked = [c[0] for c in balance_within_classes(by, n, rng, max_share=R2_2_B_MAX_SHARE)]
    letter_options(picked, rng, answer_style="option")
    return _finish(
        picked, "R2_1_C_{}", "L2_1_C_{}", refined_subtask_id="R2-1-C", original_subtask_id="L2-1-C"
    )


# -- R2_3 -----------------------------------------------------------------------------------------
def ego_xy(m: Moment, x: float, y: float) -> tuple[float, float]:
    """World point → ego frame (forward, left), metres."""
    e = m.ego
    dx, dy = x - e.x, y - e.y
    c, s = math.cos(e.yaw), math.sin(e.yaw)
    return c * dx + s * dy, -s * dx + c * dy


def relation(subject: tuple[float, float], reference: tuple[float, float]) -> str | None:
    """Sector of `subject` seen from `reference`, in the ego's axes; None inside a margin."""
    fwd, left = subject[0] - reference[0], subject[1] - reference[1]
    far = max(math.hypot(*subject), math.hypot(*reference))
    if math.hypot(fwd, left) < max(RELATION_MIN_GAP_M, RELATION_MIN_GAP_SHARE * far):
        return None
    angle = math.degrees(math.atan2(left, fwd))
    for centre, name in RELATIONS:
        diff = (angle - centre + 180.0) % 360.0 - 180.0
        if abs(diff) <= RELATION_MARGIN_DEG:
            return name
    return None


def reference_agrees(m: Moment, v: Visible) -> bool:
    """Whether `v` can be the reference: it has a heading (not a cone) within
    REFERENCE_HEADING_DEG of the ego's, so its own axes and the ego's give the same sector."""
    if v.actor.category not in REFERENCE_CATEGORIES:
        return False
    diff = (math.degrees(v.actor.yaw - m.ego.yaw) + 180.0) % 360.0 - 180.0
    return abs(diff) <= REFERENCE_HEADING_DEG


def _sector_gap(a: str, b: str) -> float:
    centre = {name: c for c, name in RELATIONS}
    return abs((centre[a] - centre[b] + 180.0) % 360.0 - 180.0)


@register("R2_3", Needs())
def build_r2_3(moments: Sequence[Moment], n: int, rng: random.Random) -> list[dict[str, Any]]:
    cands = []
    names = [name for _, name in RELATIONS]
    for m in moments:
        f = m.frame(FRONT)
        if f is None:
            dropped("moment without a CAM_FRONT frame")
            continue
        objs = [
            (v, p)
            for v in f.visible
            if v.actor.category in RELATION_CATEGORIES and v.distance_m <= RELATION_MAX_DISTANCE_M
            for p in [unique_point(f, v)]
            if p is not None
        ]
        for i, (a_obj, a_px) in enumerate(objs):
            for b_obj, b_px in objs[i + 1 :]:
                # One record per unordered pair, with a reference whose own frame agrees with
                # the ego's (heading within REFERENCE_HEADING_DEG): both readings of "the car
                # as a reference frame" then give the same sector.
                refs = [o for o in (a_obj, b_obj) if reference_agrees(m, o)]
                if not refs:
                    dropped("neither object can be the reference (heading within 45° of the ego's)")
                    continue
                ref = refs[0] if len(refs) == 1 else refs[rng.randrange(2)]
                subj = b_obj if ref is a_obj else a_obj
                ref_px, subj_px = (a_px, b_px) if ref is a_obj else (b_px, a_px)
                sxy = ego_xy(m, subj.actor.x, subj.actor.y)
                rxy = ego_xy(m, ref.actor.x, ref.actor.y)
                rel = relation(sxy, rxy)
                if rel is None:
                    dropped("objects too close or the direction near a sector edge")
                    continue
                # No neighbouring sector among the distractors: "Rear" and "Rear-Right" can
                # both describe a car 15 m behind and one lane over.
                others = [x for x in names if _sector_gap(x, rel) >= 90.0]
                rng.shuffle(others)
                (su, sv), (ru, rv) = subj_px, ref_px
                rec = {
                    "scene_token": scene_token(m),
                    "sample_token": sample_token(m),
                    "camera_channel": FRONT,
                    "question_type": "L1-3_Spatial_Rel",
                    "question": R2_3_QUESTION.format(
                        s_cat=subj.actor.category,
                        su=su,
                        sv=sv,
                        r_cat=ref.actor.category,
                        ru=ru,
                        rv=rv,
                        w=f.size[0],
                        h=f.size[1],
                    ),
                    "options": [rel, *others[:3]],
                    "answer": rel,
                    "meta_data": {
                        "subject_instance_token": str(subj.actor.id),
                        "subject_annotation_token": f"{sample_token(m)}__{subj.actor.id}",
                        "reference_instance_token": str(ref.actor.id),
                        "reference_annotation_token": f"{sample_token(m)}__{ref.actor.id}",
                        "subject_pixel": [su, sv],
                        "reference_pixel": [ru, rv],
                        "subject_ego_xy": [round(sxy[0], 4), round(sxy[1], 4)],
                        "reference_ego_xy": [round(rxy[0], 4), round(rxy[1], 4)],
                        "gt_relation": rel,
                        "visible_fraction": {
                            "subject": subj.visible_fraction,
                            "reference": ref.visible_fraction,
                        },
                    },
                    "image_path": image_path(f),
                    "_key": f"{m.key}|{subj.actor.id:06d}|{ref.actor.id:06d}",
                    "_frames": [f],
                }
                cands.append((rec, rel))
    passed(len(cands))
    picked = _balance_by(cands, n, rng)
    from .quality import letter_options

    letter_options(picked, rng, answer_style="letter")
    return _finish(picked, "R2_3_{}", "L2_3_{}", refined_subtask_id="R2-3", original_subtask_id="L2-3")
