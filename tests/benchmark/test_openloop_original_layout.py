"""`openloop score` on the original release's result folders (`<Task>_pred.jsonl`), checked
against an independent Python port of the original formulas (docs/protocol.md#answer-parsing,
#record-scores) on the
released sample records; inputs with nothing to score fail loudly; our runner's lines carry
the original's fields."""

from __future__ import annotations

import hashlib
import json
import math
import re
import shutil
from pathlib import Path
from typing import Any

import pytest

from drivehierarchy import ConfigError, _core
from drivehierarchy.benchmark.openloop.scoring import PredictionFileWarning, score_run
from drivehierarchy.cli import main

TASKS = {t["id"]: t for t in _core.openloop_tasks()}

# --- an independent port of the original scorer's formulas (docs/protocol.md#record-scores) -------

_NUM = re.compile(r"[-+]?(?:\d+\.\d+|\d+|\.\d+)(?:[eE][-+]?\d+)?")
_LEAD = re.compile(r"^\s*[\"'\(\[\{]*\s*([A-Z])(?:\s*[\)\]\}\"'\.,:;-]|$)")
_HINT = re.compile(r"\b(?:OPTION|ANSWER|CHOICE)\s*[:\-]?\s*([A-Z])\b")


def _norm(v: Any) -> str:
    t = re.sub(r"\s+", " ", str(v).strip().lower())
    return re.sub(r"[^a-z0-9 ]+", "", t).strip()


def _yes_no(v: Any) -> str | None:
    t = _norm(v)
    if t in ("yes", "y", "true") or t.startswith("yes"):
        return "yes"
    if t in ("no", "n", "false") or t.startswith("no"):
        return "no"
    return None


def _letter(v: Any) -> str | None:
    if v is None:
        return None
    t = str(v).strip().upper()
    if len(t) == 1 and t.isalpha():
        return t
    for rx in (_LEAD, _HINT):
        m = rx.search(t)
        if m:
            return m.group(1)
    return None


def _strip_prefix(v: Any) -> str:
    t = re.sub(r"^\s*[A-Za-z]\s*[\.\):\-]\s*", "", str(v).strip())
    t = re.sub(r"^\s*(?:option|answer|choice)\s*[:\-]?\s*[A-Za-z]\s*", "", t, flags=re.IGNORECASE)
    return t.strip()


def _number(v: Any) -> float | None:
    if isinstance(v, bool) or v is None:
        return None
    if isinstance(v, int | float):
        return float(v)
    if isinstance(v, str):
        m = _NUM.search(v.replace(",", " "))
        return float(m.group(0)) if m else None
    return None


def _box(v: Any) -> list[float] | None:
    if isinstance(v, dict):
        return _box(v["bbox"]) if "bbox" in v else None
    if isinstance(v, list):
        nums = [_number(x) for x in v[:4]]
        if len(v) >= 4 and all(n is not None for n in nums):
            x1, y1, x2, y2 = nums  # type: ignore[misc]
            return [min(x1, x2), min(y1, y2), max(x1, x2), max(y1, y2)]
        return _box(v[0]) if v and isinstance(v[0], list) else None
    if isinstance(v, str) and v.strip():
        try:
            b = _box(json.loads(v.strip()))
            if b is not None:
                return b
        except json.JSONDecodeError:
            pass
        nums = [float(x) for x in _NUM.findall(v.strip())]
        if len(nums) >= 4:
            return _box(nums[:4])
    return None


def _labels(v: Any) -> list[str]:
    if isinstance(v, list):
        items = list(v)
    elif isinstance(v, str):
        if not v.strip():
            return []
        try:
            parsed = json.loads(v.strip())
            items = parsed if isinstance(parsed, list) else [parsed]
        except json.JSONDecodeError:
            items = re.findall(r"\b([A-Z])\b", v.strip().upper())
    else:
        return []
    out: list[str] = []
    for it in items:
        lab = _letter(it)
        if lab is None and len(str(it).strip()) == 1 and str(it).strip().isalpha():
            lab = str(it).strip().upper()
        if lab and lab not in out:
            out.append(lab)
    return out


def _decay(e: float, tau: float, sigma: float) -> float:
    return 100.0 if e <= tau else max(0.0, min(100.0, 100.0 * math.exp(-(e - tau) / sigma)))


def _round_half_away(x: float) -> int:
    return math.floor(x + 0.5) if x >= 0 else math.ceil(x - 0.5)


def port_score(scorer: str, gt: Any, pred: Any) -> tuple[float, bool]:
    """(score, parsed) of one record, written from docs/protocol.md#answer-parsing, #record-scores."""
    if scorer == "yes_no":
        g, p = _yes_no(gt), _yes_no(pred)
        return (0.0, False) if g is None or p is None else (100.0 * (g == p), True)
    if scorer == "multi_choice":
        g, p = _letter(gt), _letter(pred)
        if g is not None and p is not None:
            return 100.0 * (g == p), True
        gt_t, p_t = _norm(_strip_prefix(gt)), _norm(_strip_prefix(pred))
        return (0.0, False) if not gt_t or not p_t else (100.0 * (gt_t == p_t), True)
    if scorer in ("numeric_count", "numeric_distance"):
        g, p = _number(gt), _number(pred)
        if g is None or p is None:
            return 0.0, False
        if scorer == "numeric_count":
            gc, pc = max(0, _round_half_away(g)), max(0, _round_half_away(p))
            return _decay(abs(pc - gc) / max(float(gc), 1.0), 0.05, (0.20 - 0.05) / math.log(2.0)), True
        e = abs(math.log((max(0.0, p) + 0.1) / (max(0.0, g) + 0.1)))
        return _decay(e, 0.0, 1.0), True
    if scorer == "bbox":
        gb, pb = _box(gt), _box(pred)
        if gb is None or pb is None:
            return 0.0, False
        iw = max(0.0, min(gb[2], pb[2]) - max(gb[0], pb[0]))
        ih = max(0.0, min(gb[3], pb[3]) - max(gb[1], pb[1]))
        union = (gb[2] - gb[0]) * (gb[3] - gb[1]) + (pb[2] - pb[0]) * (pb[3] - pb[1]) - iw * ih
        return (0.0 if union <= 0 else max(0.0, min(100.0, 100.0 * iw * ih / union))), True
    if scorer == "sequence_order":
        gs, ps = _labels(gt), _labels(pred)
        if not gs or not ps:
            return 0.0, False
        order = [x for x in ps if x in gs]
        order += [x for x in gs if x not in order]
        n = len(gs)
        if n == 1:
            return 100.0 * (order[0] == gs[0]), True
        pos = {x: i for i, x in enumerate(order)}
        inv = sum(pos[gs[i]] > pos[gs[j]] for i in range(n) for j in range(i + 1, n))
        return max(0.0, min(100.0, 100.0 * (1.0 - inv / (n * (n - 1) // 2)))), True
    raise AssertionError(scorer)


def _pct(v: list[float], p: float) -> float:
    s = sorted(v)
    r = (len(s) - 1) * p / 100.0
    lo, hi = math.floor(r), math.ceil(r)
    return s[lo] if lo == hi else s[lo] * (1 - (r - lo)) + s[hi] * (r - lo)


def port_folder(folder: Path) -> dict[str, dict[str, Any]]:
    """Per-file n, parse_fail, mean, p50, p90 of every non-judge `*_pred.jsonl` in `folder`."""
    by_file = {f"{t['stem']}_pred.jsonl": t["scorer"] for t in TASKS.values()}
    out = {}
    for path in sorted(folder.glob("*_pred.jsonl")):
        scorer = by_file[path.name]
        if scorer == "text_lingo_judge":
            continue
        scores, fails = [], 0
        for line in path.read_text(encoding="utf-8").splitlines():
            try:
                obj = json.loads(line)
            except json.JSONDecodeError:
                continue
            s, ok = port_score(scorer, obj.get("ground_truth"), obj.get("model_prediction"))
            scores.append(s)
            fails += not ok
        out[path.name] = {
            "n": len(scores),
            "parse_fail": fails,
            "mean": sum(scores) / len(scores),
            "p50": _pct(scores, 50),
            "p90": _pct(scores, 90),
        }
    return out


# --- original-layout folders from the released sample records -----------------------------------


def _target(tid: str, raw: dict[str, Any]) -> Any:
    scorer = TASKS[tid]["scorer"]
    if scorer == "sequence_order":
        return raw.get("ground_truth_order")
    if scorer == "bbox":
        return raw.get("ground_truth")
    return raw.get("answer")


def mixed_prediction(tid: str, raw: dict[str, Any]) -> str:
    """A deterministic mix (by id hash) of correct, wrong, near and unparseable replies."""
    rid = str(raw.get("Question_id", raw.get("task_id")))
    suffix = rid.rsplit("_", 1)[-1]
    pick = int(suffix) % 4 if suffix.isdigit() else int(hashlib.sha256(rid.encode()).hexdigest(), 16) % 4
    scorer, gt = TASKS[tid]["scorer"], _target(tid, raw)
    if scorer == "yes_no":
        yes = str(gt).lower().startswith("y")
        return ["yes" if yes else "no", "no" if yes else "yes", "maybe", "Yes, there is." if yes else "No."][
            pick
        ]
    if scorer in ("numeric_count", "numeric_distance"):
        g = float(str(gt).split()[0])
        return [str(gt), f"{g * 3 + 2:.1f}", "several", f"about {g * 1.3 + 1:.2f} m"][pick]
    if scorer == "multi_choice":
        letter = str(gt).strip()[0]
        other = next(o.strip()[0] for o in raw["options"] if o.strip()[0] != letter)
        full = next(o for o in raw["options"] if o.strip().startswith(letter))
        return [letter, f"Answer: {other}", "???", full][pick]
    if scorer == "bbox":
        x1, y1, x2, y2 = gt["bbox"]
        return [
            json.dumps(gt["bbox"]),
            "[0, 0, 5, 5]",
            "no box",
            f"({x1 + 20}, {y1 - 10}) to ({x2 + 20}, {y2})",
        ][pick]
    if scorer == "sequence_order":
        return [json.dumps(gt), json.dumps(gt[::-1]), "123", ", ".join([gt[1], gt[0], *gt[2:]])][pick]
    return ["The car is turning left.", "I am stopping.", "Unsure.", "Going straight."][pick]


def original_line(tid: str, raw: dict[str, Any], prediction: str) -> dict[str, Any]:
    """A line as the original runner writes it (docs/protocol.md#open-loop-tasks, its output record)."""
    id_key = next((k for k in ("Question_id", "task_id", "id") if k in raw), "id")
    rid = raw.get(id_key)
    line: dict[str, Any] = {"Question_id": None if rid is None else str(rid)}
    if id_key != "Question_id":
        line[id_key] = line["Question_id"]
    question = raw.get("question") or raw.get("prompt")
    if not question and TASKS[tid]["scorer"] == "sequence_order":
        labels = ", ".join(str(i["label"]) for i in raw["images"])
        question = (
            "Please determine the correct order of the images.\n"
            f'Option labels: {labels}.\nOutput format: ["A", "B", ...].'
        )
    line["question"] = question if isinstance(question, str) else json.dumps(question, ensure_ascii=False)
    line["ground_truth"] = _target(tid, raw)
    line["model_prediction"] = prediction
    if TASKS[tid]["scorer"] == "sequence_order":
        line["ground_truth_order"] = raw["ground_truth_order"]
    return line


def _released(official: Path) -> dict[str, list[dict[str, Any]]]:
    out = {}
    for tid, t in TASKS.items():
        text = (official / f"{t['stem']}.jsonl").read_text(encoding="utf-8")
        out[tid] = [json.loads(x) for x in text.splitlines() if x.strip()]
    return out


def _original_folder(dest: Path, released: dict[str, list[dict[str, Any]]]) -> Path:
    dest.mkdir(parents=True)
    for tid, recs in released.items():
        lines = [original_line(tid, r, mixed_prediction(tid, r)) for r in recs]
        text = "".join(json.dumps(x, ensure_ascii=False) + "\n" for x in lines)
        (dest / f"{TASKS[tid]['stem']}_pred.jsonl").write_text(text, encoding="utf-8")
    return dest


def _same(got: dict[str, Any], want: dict[str, Any]) -> None:
    # The same numbers, bit for bit (σ = (0.20 − 0.05)/ln 2 as computed, not 0.15/ln 2).
    assert {k: got[k] for k in want} == want


@pytest.fixture()
def released(openloop_data_dir: Path) -> dict[str, list[dict[str, Any]]]:
    return _released(openloop_data_dir)


def test_original_layout_scores_like_the_port(released, tmp_path: Path, capsys) -> None:
    folder = _original_folder(tmp_path / "Qwen2.5-VL-7B", released)
    want = port_folder(folder)
    # The mix really mixes: every file has perfect, wrong/partial and unparseable replies.
    assert all(0 < w["parse_fail"] < w["n"] and 0 < w["mean"] < 100 for w in want.values()), want
    assert main(["openloop", "score", str(folder), "--skip-l1-4"]) == 0
    saved = json.loads((folder / "evaluation" / "final_score.json").read_text(encoding="utf-8"))
    assert saved["layout"] == "original"
    assert [f["source_file"] for f in saved["per_file"]] == list(want)  # sorted, R1_4 skipped
    for f in saved["per_file"]:
        _same(f, want[f["source_file"]])
        assert f["skipped_lines"] == 0 and f["first_skip"] is None
    # The original's micro means per scorer type and overall.
    pooled: dict[str, list[float]] = {}
    for path in sorted(folder.glob("*_pred.jsonl")):
        scorer = TASKS[_core.openloop_task_from_original_file(path.name)]["scorer"]
        if scorer != "text_lingo_judge":
            for line in path.read_text(encoding="utf-8").splitlines():
                obj = json.loads(line)
                pooled.setdefault(scorer, []).append(
                    port_score(scorer, obj["ground_truth"], obj["model_prediction"])[0]
                )
    for t in saved["per_task"]:
        assert t["mean"] == sum(pooled[t["task_type"]]) / len(pooled[t["task_type"]])
    assert saved["overall"]["n"] == sum(len(v) for v in pooled.values())
    assert saved["skipped_files"] == [
        {"source_file": "R1_4_Situation_Description_pred.jsonl", "reason": "skip_l1_4_flag"}
    ]
    assert saved["config"]["l1_4"] == {
        **saved["config"]["l1_4"],
        "enabled": False,
        "skip_reason": "skip_l1_4_flag",
    }
    # Task ids come from the original names; S_t equals the file mean here.
    assert saved["tasks"]["R2_2_A"]["mean"] == want["R2_2_A_Temporal_Counting_pred.jsonl"]["mean"]
    printed = json.loads(capsys.readouterr().out)
    assert printed["tasks"]["R3_2"] == pytest.approx(want["R3_2_Sequential_Planning_pred.jsonl"]["mean"])


def test_legacy_names_and_our_fields_moved_under_predictions(released, tmp_path: Path) -> None:
    # The original scorer also knows the pre-release stems; ours reads them the same way.
    legacy = tmp_path / "legacy"
    legacy.mkdir()
    for tid in ("R1_1_A", "R1_3", "R3_2"):
        lines = [original_line(tid, r, mixed_prediction(tid, r)) for r in released[tid]]
        name = f"{TASKS[tid]['legacy_stem']}_pred.jsonl"
        (legacy / name).write_text("".join(json.dumps(x) + "\n" for x in lines), encoding="utf-8")
    want = port_folder_named(legacy)
    res = score_run(legacy)
    for f in res["per_file"]:
        _same(f, want[f["source_file"]])
    # Original lines under our predictions/ folder are read by their own fields (no "missing id").
    ours = tmp_path / "ours" / "predictions"
    ours.mkdir(parents=True)
    for path in legacy.glob("*_pred.jsonl"):
        tid = _core.openloop_task_from_original_file(path.name)
        shutil.copy(path, ours / f"{TASKS[tid]['stem']}.jsonl")
    res2 = score_run(tmp_path / "ours")
    assert res2["layout"] == "drivehierarchy"
    assert {t: v["mean"] for t, v in res2["tasks"].items()} == {t: v["mean"] for t, v in res["tasks"].items()}


def port_folder_named(folder: Path) -> dict[str, dict[str, Any]]:
    """`port_folder` for files under any original name (legacy stems included)."""
    tmp = folder.parent / (folder.name + "_released_names")
    tmp.mkdir()
    names = {}
    for path in folder.glob("*_pred.jsonl"):
        tid = _core.openloop_task_from_original_file(path.name)
        released_name = f"{TASKS[tid]['stem']}_pred.jsonl"
        shutil.copy(path, tmp / released_name)
        names[released_name] = path.name
    return {names[k]: v for k, v in port_folder(tmp).items()}


def _err(argv: list[str], capsys) -> str:
    assert main(argv) != 0
    return capsys.readouterr().err


def test_nothing_to_score_is_an_error_naming_the_file(released, tmp_path: Path, capsys) -> None:
    # An empty folder, and a folder with files that are not predictions.
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "run_config.json").write_text("{}")
    assert "no prediction files" in _err(["openloop", "score", str(empty)], capsys)
    # An unknown *_pred.jsonl name (the original only guessed a scorer type for these).
    unknown = _original_folder(tmp_path / "unknown", {"R1_1_A": released["R1_1_A"]})
    (unknown / "R3_3_MultiAgent_Intent_pred.jsonl").write_text(
        '{"ground_truth": "A", "model_prediction": "A"}\n'
    )
    err = _err(["openloop", "score", str(unknown)], capsys)
    assert "R3_3_MultiAgent_Intent_pred.jsonl" in err and "unknown task file" in err
    assert not (unknown / "evaluation" / "final_score.json").exists()
    # A file whose every line is skipped: our runner's lines stripped of the fields scored.
    skipped = _original_folder(tmp_path / "skipped", {"R1_1_B": released["R1_1_B"]})
    bad = skipped / "R2_3_Spatial_Relations_pred.jsonl"
    bad.write_text(
        "".join(json.dumps({"id": r["Question_id"], "answer": r["answer"]}) + "\n" for r in released["R2_3"])
    )
    err = _err(["openloop", "score", str(skipped)], capsys)
    assert "R2_3_Spatial_Relations_pred.jsonl" in err and "nothing to score" in err
    assert "line 1:" in err and "model_prediction" in err, err
    # An empty prediction file leaves its task unscored and listed, never a 0.
    bad.write_text("")
    with pytest.warns(PredictionFileWarning, match="empty"):
        res = score_run(skipped)
    assert res["skipped_files"] == [{"source_file": bad.name, "reason": "empty_file"}]
    assert set(res["tasks"]) == {"R1_1_B"} and res["S_open"] is None
    (skipped / "R1_1_B_Counting_pred.jsonl").write_text("\n")
    err = _err(["openloop", "score", str(skipped)], capsys)
    assert "nothing to score" in err and "R1_1_B_Counting_pred.jsonl: empty_file" in err
    # Only R1_4, skipped: no scorable record at all.
    judge_only = _original_folder(tmp_path / "judge_only", {"R1_4": released["R1_4"]})
    err = _err(["openloop", "score", str(judge_only), "--skip-l1-4"], capsys)
    assert "nothing to score" in err and "R1_4_Situation_Description_pred.jsonl: skip_l1_4_flag" in err
    # Without a judge model R1_4 is reported as skipped, not scored as 0.
    err = _err(["openloop", "score", str(judge_only)], capsys)
    assert "no_judge_model" in err


def test_partially_skipped_files_are_reported(released, tmp_path: Path, capsys) -> None:
    folder = _original_folder(tmp_path / "partial", {"R1_2_A": released["R1_2_A"], "R3_1": released["R3_1"]})
    path = folder / "R1_2_A_Nearest_Object_pred.jsonl"
    lines = path.read_text(encoding="utf-8").splitlines()
    broken = json.loads(lines[2])
    del broken["model_prediction"]
    lines[2] = json.dumps(broken)
    lines.insert(5, "not json")
    path.write_text("\n".join(lines) + "\n" + lines[0][:30], encoding="utf-8")  # + a cut last line
    want = port_folder(folder)["R1_2_A_Nearest_Object_pred.jsonl"]
    assert main(["openloop", "score", str(folder)]) == 0
    cap = capsys.readouterr()
    printed = json.loads(cap.out)
    assert printed["skipped_lines"] == {
        path.name: {
            "skipped_lines": 3,
            "first_skip": "line 3: missing field `model_prediction`",
            "scored": 17,
        }
    }
    assert f"{path.name}: skipped 3 lines" in cap.err
    saved = json.loads((folder / "evaluation" / "final_score.json").read_text(encoding="utf-8"))
    f = next(f for f in saved["per_file"] if f["source_file"] == path.name)
    assert f["skipped_lines"] == 3 and f["first_skip"].startswith("line 3: missing field")
    assert saved["read"][path.name]["truncated_tail"] is True
    # The original scorer would count the line without a reply as a 0; we skip and report it.
    assert want["n"] == 18 and f["n"] == 17
    with pytest.warns(PredictionFileWarning, match="skipped 3 of 20 lines"):
        score_run(folder)


def test_both_layouts_in_one_folder_need_a_choice(released, tmp_path: Path) -> None:
    folder = _original_folder(tmp_path / "both", {"R1_1_A": released["R1_1_A"]})
    pred = folder / "predictions"
    pred.mkdir()
    shutil.copy(folder / "R1_1_A_Existence_pred.jsonl", pred / "R1_1_A_Existence.jsonl")
    with pytest.raises(ConfigError, match="both"):
        score_run(folder)
    assert score_run(folder, layout="original")["per_file"][0]["source_file"] == "R1_1_A_Existence_pred.jsonl"
    assert (
        score_run(folder, layout="drivehierarchy")["per_file"][0]["source_file"] == "R1_1_A_Existence.jsonl"
    )


def test_our_runner_output_reads_as_the_original_layout(openloop_data_dir: Path, tmp_path: Path) -> None:
    from drivehierarchy.benchmark.openloop.catalog import ImageRootMap, default_catalog, load_dataset
    from drivehierarchy.benchmark.openloop.runner import RunConfig, predict
    from drivehierarchy.benchmark.openloop.synthetic import OraclePolicy, write_images
    from drivehierarchy.testing.openai_server import ScriptedOpenAIServer

    root_arg = f"/data/sets={tmp_path}/sets"
    cat = default_catalog(openloop_data_dir)
    records = [
        r for spec in cat.datasets for r in load_dataset(cat, spec, ImageRootMap.parse([root_arg])).records
    ]
    write_images(records)
    policy = OraclePolicy(records, answer=lambda rec: mixed_prediction(rec.task, rec.raw).strip())
    run = tmp_path / "run"
    with ScriptedOpenAIServer(policy) as url:
        config = RunConfig(
            base_url=url,
            model="mix",
            out=run,
            data_dir=openloop_data_dir,
            image_roots=(root_arg,),
            progress=False,
        )
        assert predict(config).complete
    # Every line carries the original runner's fields, exactly as it would have written them.
    flat = tmp_path / "as_original"
    flat.mkdir()
    for path in sorted((run / "predictions").glob("*.jsonl")):
        tid = _core.openloop_task_from_stem(path.stem)
        for text in path.read_text(encoding="utf-8").splitlines():
            line = json.loads(text)
            want = original_line(tid, line["record"], line["prediction"])
            assert {k: line[k] for k in want} == want, line["id"]
        shutil.copy(path, flat / f"{path.stem}_pred.jsonl")
    # The original's reading of those files (the port) = our scorer on the run = on the flat copy.
    want = port_folder(flat)
    ours = score_run(run, skip_l1_4=True)
    as_original = score_run(flat, skip_l1_4=True)
    assert as_original["layout"] == "original"
    for a, b in zip(ours["per_file"], as_original["per_file"], strict=True):
        _same(a, want[b["source_file"]])
        _same(b, want[b["source_file"]])


def test_repeated_ids_count_in_the_original_layout_only(released, tmp_path: Path, capsys) -> None:
    folder = _original_folder(tmp_path / "dup", {"R1_1_C": released["R1_1_C"]})
    path = folder / "R1_1_C_State_Attribute_pred.jsonl"
    lines = path.read_text(encoding="utf-8").splitlines()
    path.write_text("\n".join([*lines, lines[1], lines[2]]) + "\n", encoding="utf-8")
    assert main(["openloop", "score", str(folder)]) == 0
    assert "2 repeated ids, each line counted" in capsys.readouterr().err
    saved = json.loads((folder / "evaluation" / "final_score.json").read_text(encoding="utf-8"))
    _same(saved["per_file"][0], port_folder(folder)[path.name])
    assert saved["per_file"][0]["n"] == len(lines) + 2
    # Under our layout a repeated id is a resume artefact: the first line wins.
    ours = tmp_path / "ours" / "predictions"
    ours.mkdir(parents=True)
    shutil.copy(path, ours / "R1_1_C_State_Attribute.jsonl")
    res = score_run(tmp_path / "ours")
    assert res["per_file"][0]["n"] == len(lines)
    assert res["read"]["R1_1_C_State_Attribute.jsonl"]["duplicates_skipped"] == 2
