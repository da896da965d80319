//! Re-scoring a recorded run reproduces the live score bit for bit, through the JSONL log.

use dh_env::geom::{Polyline, Vec2};
use dh_env::score::*;
use dh_env::view::ContactClass;

fn route() -> Polyline {
    // A bent route with irrational vertices, so float round-trips matter.
    Polyline::new(vec![
        Vec2::new(0.1, -0.3),
        Vec2::new(40.0 / 3.0, 0.7),
        Vec2::new(60.0, 2.0_f64.sqrt() * 10.0),
        Vec2::new(61.0, 90.0 / 7.0 + 50.0),
    ])
}

/// Drives a wobbly trajectory along the route and logs it, as a runner would.
fn live_run(contact_at: Option<u64>, stop_after: Option<u64>) -> (SceneScore, String) {
    let route = route();
    let start = Vec2::new(0.1, -0.3);
    let dest = *route.points().last().unwrap();
    let params = ScoreParams::default();
    let header = RunHeader::new("SC-test", &route, start, dest, Some(11.3), params.clone());
    let mut tracker = ScoreTracker::new(route.clone(), start, dest, Some(11.3), params).unwrap();
    let mut lines = vec![LogLine::Header(Box::new(header)).to_json()];
    let mut s = 0.0;
    let mut k = 0u64;
    loop {
        k += 1;
        let speed = 6.0 + 3.0 * (k as f64 * 0.07).sin();
        s += speed * 0.05;
        let p = route.point_at(s) + Vec2::new((k as f64 * 0.3).cos() * 1.7, (k as f64 * 0.11).sin() * 2.9);
        let on_road = (k / 13) % 5 != 4;
        let contacts = if Some(k) == contact_at {
            vec![
                Contact { actor_id: 7, class: ContactClass::Vehicle },
                Contact { actor_id: 2, class: ContactClass::Static },
            ]
        } else {
            vec![]
        };
        let sample = TrajectorySample {
            tick: k,
            time_s: k as f64 * 0.05,
            x: p.x,
            y: p.y,
            yaw: (k as f64).sqrt(),
            speed_mps: speed,
            on_road,
            contacts,
            red_light: k == 17,
            stop_sign: k == 23,
            stop: None,
        };
        let end = tracker.update(&sample.tick_input());
        lines.push(LogLine::Tick(sample).to_json());
        if end.is_some() || Some(k) == stop_after {
            break;
        }
    }
    let mut footer =
        RunFooter { wall_duration_s: 3.0_f64.ln(), decisions: k / 5, parse_failures: 1, stop: None };
    if stop_after.is_some() && tracker.termination().is_none() {
        tracker.stop(ExternalStop::ManualInterrupt);
        footer.stop = Some(ExternalStop::ManualInterrupt);
    }
    lines.push(LogLine::End(footer.clone()).to_json());
    let info = RunInfo {
        scene_id: "SC-test".into(),
        wall_duration_s: footer.wall_duration_s,
        decisions: footer.decisions,
        parse_failures: footer.parse_failures,
    };
    (tracker.finish(&info), lines.join("\n") + "\n")
}

#[test]
fn rescore_equals_live_score() {
    for (contact_at, stop_after) in [(None, None), (Some(150), None), (None, Some(60))] {
        let (live, jsonl) = live_run(contact_at, stop_after);
        let log = RunLog::from_jsonl(&jsonl, "run.jsonl").unwrap();
        let again = log.rescore().unwrap();
        assert_eq!(again, live);
        assert_eq!(serde_json::to_string(&again).unwrap(), serde_json::to_string(&live).unwrap());
        // The log writer round-trips too.
        assert_eq!(log.to_jsonl(), jsonl);
        // Through the record file as well.
        let text = serde_json::to_string_pretty(&live).unwrap();
        assert_eq!(serde_json::from_str::<SceneScore>(&text).unwrap(), live);
    }
    let (live, _) = live_run(None, None);
    assert!(live.ticks > 100, "the wobbly run should last a while: {}", live.ticks);
    assert!(live.meta.offroad_time_s > 0.0);
    let (live, _) = live_run(Some(150), None);
    assert_eq!(live.termination_reason, TerminationReason::CollisionVehicle);
    let (live, _) = live_run(None, Some(60));
    assert_eq!(live.termination_reason, TerminationReason::ManualInterrupt);
}

#[test]
fn damaged_logs_are_named_errors() {
    let (_, jsonl) = live_run(Some(150), None);
    let lines: Vec<&str> = jsonl.lines().collect();
    let join = |v: Vec<&str>| v.join("\n");

    // A garbage line names the file and line.
    let mut v = lines.clone();
    v[3] = "{not json";
    let e = RunLog::from_jsonl(&join(v), "run.jsonl").unwrap_err().to_string();
    assert!(e.contains("run.jsonl") && e.contains("line 4"), "{e}");

    // Missing end line.
    let e = RunLog::from_jsonl(&join(lines[..lines.len() - 1].to_vec()), "r").unwrap_err().to_string();
    assert!(e.contains("end"), "{e}");

    // Missing header.
    let e = RunLog::from_jsonl(&join(lines[1..].to_vec()), "r").unwrap_err().to_string();
    assert!(e.contains("header"), "{e}");

    // A skipped tick.
    let mut v = lines.clone();
    v.remove(5);
    let e = RunLog::from_jsonl(&join(v), "r").unwrap().rescore().unwrap_err().to_string();
    assert!(e.contains("samples[4].tick"), "{e}");

    // Ticks after the terminating one.
    let mut log = RunLog::from_jsonl(&jsonl, "r").unwrap();
    let mut extra = log.samples.last().unwrap().clone();
    extra.tick += 1;
    extra.contacts.clear();
    log.samples.push(extra);
    let e = log.rescore().unwrap_err().to_string();
    assert!(e.contains("terminated at tick 150"), "{e}");

    // Unknown fields are rejected, not ignored.
    let mut v = lines.clone();
    let bad = v[2].replacen("{", r#"{"bogus":1,"#, 1);
    v[2] = &bad;
    assert!(RunLog::from_jsonl(&join(v), "r").is_err());

    // NaN positions are written as null and refused on reading.
    let mut log = RunLog::from_jsonl(&jsonl, "r").unwrap();
    log.samples[0].x = f64::NAN;
    assert!(RunLog::from_jsonl(&log.to_jsonl(), "r").is_err());
}

#[test]
fn read_from_disk() {
    let (live, jsonl) = live_run(None, Some(40));
    let dir = std::env::temp_dir().join(format!("dh-score-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("run.jsonl");
    std::fs::write(&path, jsonl).unwrap();
    assert_eq!(RunLog::read_jsonl(&path).unwrap().rescore().unwrap(), live);
    let e = RunLog::read_jsonl(dir.join("missing.jsonl")).unwrap_err().to_string();
    assert!(e.contains("missing.jsonl"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}
