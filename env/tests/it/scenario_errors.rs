//! Scenario loading: every kind of bad input gives an error naming file, field and value.

use dh_env::geom::Vec2;
use dh_env::scenario::{validate, Scenario};
use std::path::PathBuf;

fn fixture_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/world_fixtures")
}

/// The fixture scenario text with its map given by an absolute path computed at run time.
fn fixture_text() -> String {
    let base = std::fs::read_to_string(fixture_dir().join("cross.toml")).unwrap();
    let map = fixture_dir().join("cross.net.xml");
    base.replace("map = \"cross.net.xml\"", &format!("map = {:?}", map.display().to_string()))
}

/// The fixture scenario with `edit` applied, written to a temporary file.
fn write_variant(tag: &str, edit: impl Fn(String) -> String) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("dh_scenario_errors_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(format!("{tag}.toml"));
    std::fs::write(&p, edit(fixture_text())).unwrap();
    p
}

fn err_of(tag: &str, edit: impl Fn(String) -> String) -> String {
    let p = write_variant(tag, edit);
    let e = Scenario::load(&p).expect_err("must fail").to_string();
    assert!(e.contains(&p.display().to_string()), "error names the file: {e}");
    e
}

/// The `line:column` that follows the file name in the error of a broken variant, and the error.
fn located(tag: &str, edit: impl Fn(String) -> String) -> ((usize, usize), String) {
    let p = write_variant(tag, edit);
    let e = Scenario::load(&p).expect_err("must fail").to_string();
    let rest = e.strip_prefix(&format!("{}:", p.display())).unwrap_or_else(|| panic!("no file: prefix: {e}"));
    let mut it = rest.splitn(3, ':').map(|n| n.parse::<usize>());
    match (it.next(), it.next()) {
        (Some(Ok(l)), Some(Ok(c))) => ((l, c), e),
        _ => panic!("no file:line:column: prefix: {e}"),
    }
}

/// Resolution errors (which need the map) carry the line and column of their field, like
/// syntax and type errors do. Line numbers refer to `world_fixtures/cross.toml`.
#[test]
fn resolution_errors_have_line_and_column() {
    let cases = [
        // The value itself: the unknown lane in a lane list.
        (
            "lanes = [\"W_in_0\", \"C_E_0\"]",
            "lanes = [\"W_in_0\", \"C_E_9\"]",
            "actors[2].route.lanes[1]",
            (32, 30),
            "unknown lane",
        ),
        // s beyond the lane's end.
        ("s = 80.0 }", "s = 800.0 }", "ego.destination.s", (11, 37), "beyond the end"),
        // Destination behind the start: the destination's inline table.
        (
            "destination = { lane = \"C_E_0\", s = 80.0 }",
            "destination = { lane = \"W_in_0\", s = 5.0 }",
            "ego.destination",
            (11, 15),
            "behind",
        ),
        // A bad trigger reference.
        ("of = \"actor_self\"", "of = \"the_ego\"", "actors[0].start.of", (19, 37), "actor_self"),
        // Both braking conditions: the brake table.
        (
            "brake = { at_s = 60.0,",
            "brake = { at_s = 60.0, after_s = 1.0,",
            "actors[2].brake",
            (34, 9),
            "exactly one",
        ),
        // An edge not reachable from the previous one.
        (
            "edges = [\"N_in\", \"C_S\"]",
            "edges = [\"N_in\", \"C_N\"]",
            "actors[1].route.edges[1]",
            (24, 28),
            "not reachable",
        ),
        // A key left out: the header of its table.
        (
            "route = { edges = [\"N_in\", \"C_S\"] }\n",
            "",
            "actors[1].waypoints",
            (22, 1),
            "needs `waypoints` or `route`",
        ),
        // Unknown keys are serde's errors, located as before.
        ("color = [10, 200, 10]", "colour = [10, 200, 10]", "actors[2].colour", (35, 1), "unknown field"),
    ];
    for (i, (from, to, field, at, msg)) in cases.into_iter().enumerate() {
        let (got, e) = located(&format!("loc{i}"), |t| {
            assert!(t.contains(from), "{from}");
            t.replace(from, to)
        });
        assert_eq!(got, at, "{e}");
        assert!(e.contains(&format!(": field `{field}` = ")) && e.contains(msg), "{e}");
    }
    // Fields of `[traffic]` too.
    let (at, e) = located("traffic", |t| {
        format!("{t}\n[traffic]\nmode = \"idm\"\n\n[[traffic.flows]]\nfrom = \"W_in\"\nto = \"C_E\"\nvehs_per_hour = -5.0\n")
    });
    assert_eq!(at, (52, 17), "{e}");
    assert!(e.contains("traffic.flows[0].vehs_per_hour"), "{e}");
}

#[test]
fn fixture_validates_with_summary() {
    let s = validate(fixture_dir().join("cross.toml")).unwrap();
    assert_eq!(s.id, "test_cross");
    assert_eq!((s.actors, s.obstacles, s.signs, s.traffic_lights), (3, 1, 1, 8));
    assert_eq!(s.route_edges, vec!["W_in", "C_E"]);
    assert!(s.to_string().contains("route"));
    // Unchanged variant loads too (the map-path rewrite works).
    Scenario::load(write_variant("same", |t| t)).unwrap();
}

#[test]
fn malformed_toml_has_line_and_column() {
    let (at, e) = located("syntax", |t| t.replace("speed_mps = 0.0", "speed_mps = = 0.0"));
    assert_eq!(at.0, 12, "{e}");
}

#[test]
fn unknown_key_is_named_with_its_path() {
    let e = err_of("unknown_key", |t| t.replace("color = [10, 200, 10]", "colour = [10, 200, 10]"));
    assert!(e.contains("actors[2].colour"), "{e}");
}

#[test]
fn missing_map_file() {
    let e = err_of("missing_map", |t| {
        let i = t.find("map = ").unwrap();
        let j = t[i..].find('\n').unwrap() + i;
        format!("{}map = \"no/such.net.xml\"{}", &t[..i], &t[j..])
    });
    assert!(e.contains("`map`") && e.contains("no/such.net.xml") && e.contains("not found"), "{e}");
}

#[test]
fn unknown_lane_and_edge_ids() {
    let e = err_of("lane", |t| t.replace("lane = \"W_in_0\", s = 20.0", "lane = \"W_in_7\", s = 20.0"));
    assert!(e.contains("ego.start.lane") && e.contains("W_in_7"), "{e}");
    let e = err_of("edge", |t| t.replace("edges = [\"N_in\", \"C_S\"]", "edges = [\"N_in\", \"nowhere\"]"));
    assert!(e.contains("actors[1].route.edges[1]") && e.contains("nowhere"), "{e}");
}

#[test]
fn unconnected_routes() {
    // N_in → C_N is a U-turn, absent with --no-turnarounds.
    let e = err_of("uturn", |t| t.replace("edges = [\"N_in\", \"C_S\"]", "edges = [\"N_in\", \"C_N\"]"));
    assert!(e.contains("actors[1].route.edges[1]") && e.contains("not reachable"), "{e}");
    let e =
        err_of("lanes", |t| t.replace("lanes = [\"W_in_0\", \"C_E_0\"]", "lanes = [\"W_in_0\", \"C_W_0\"]"));
    assert!(e.contains("actors[2].route.lanes[1]") && e.contains("not connected"), "{e}");
    let e = err_of("ego_route", |t| {
        t.replace(
            "destination = { lane = \"C_E_0\", s = 80.0 }",
            "destination = { lane = \"C_E_0\", s = 80.0 }\nroute_edges = [\"W_in\", \"C_S\"]",
        )
    });
    assert!(e.contains("ego.destination") && e.contains("C_E"), "{e}");
}

#[test]
fn bad_numbers() {
    let e = err_of("nan", |t| t.replace("speed_mps = 8.0", "speed_mps = nan"));
    assert!(e.contains("actors[1].speed_mps") && e.contains("NaN"), "{e}");
    let e = err_of("neg", |t| t.replace("decel_mps2 = 6.0", "decel_mps2 = -6.0"));
    assert!(e.contains("actors[2].brake.decel_mps2") && e.contains("-6"), "{e}");
    let e = err_of("beyond", |t| t.replace("s = 80.0", "s = 500.0"));
    assert!(e.contains("ego.destination.s") && e.contains("500"), "{e}");
    let e = err_of("tref", |t| t.replace("reference_duration_s = 30.0", "reference_duration_s = -1.0"));
    assert!(e.contains("reference_duration_s"), "{e}");
}

#[test]
fn empty_waypoints_and_bad_triggers() {
    let e = err_of("empty", |t| {
        t.replace(
            "waypoints = [{ x = 180.0, y = 108.0 }, { x = 180.0, y = 125.0, speed_mps = 1.5 }]",
            "waypoints = []",
        )
    });
    assert!(e.contains("actors[0].waypoints") && e.contains("empty"), "{e}");
    let e = err_of("trigger", |t| t.replace("of = \"actor_self\"", "of = \"the_ego\""));
    assert!(e.contains("actors[0].start.of") && e.contains("the_ego"), "{e}");
    let e = err_of("trigger2", |t| {
        t.replace("start = { ego_within_m = 40.0,", "start = { time_s = 1.0, ego_within_m = 40.0,")
    });
    assert!(e.contains("actors[0].start"), "{e}");
}

#[test]
fn bad_category_version_and_destination_behind() {
    let e = err_of("cat", |t| t.replace("04_intersection", "04_crossing"));
    assert!(e.contains("category") && e.contains("04_crossing"), "{e}");
    let e = err_of("ver", |t| t.replace("version = 1", "version = 2"));
    assert!(e.contains("version"), "{e}");
    let e = err_of("behind", |t| {
        t.replace(
            "destination = { lane = \"C_E_0\", s = 80.0 }",
            "destination = { lane = \"W_in_0\", s = 5.0 }",
        )
    });
    assert!(e.contains("ego.destination") && e.contains("behind"), "{e}");
}

#[test]
fn sumo_map_needs_sumo_home() {
    use dh_env::scenario::{resolve_map_path, LoadOptions};
    let f = fixture_dir().join("x.toml");
    let e = resolve_map_path(&f, "sumo:nope/none.net.xml", Some(&fixture_dir())).unwrap_err().to_string();
    assert!(e.contains("not found under SUMO_HOME"), "{e}");
    let p = resolve_map_path(&f, "sumo:cross.net.xml", Some(&fixture_dir())).unwrap();
    assert!(p.ends_with("cross.net.xml"));
    let _ = LoadOptions::default();
}

#[test]
fn ego_start_and_destination_alternatives() {
    let e = err_of("nostart", |t| t.replace("start = { lane = \"W_in_0\", s = 20.0 }\n", ""));
    assert!(e.contains("ego.start") && e.contains("<missing>"), "{e}");
    let e = err_of("nodest", |t| t.replace("destination = { lane = \"C_E_0\", s = 80.0 }\n", ""));
    assert!(e.contains("ego.destination"), "{e}");
    // route_edges alone: start near the beginning of the first edge, destination near the end of the last.
    let p = write_variant("edges_only", |t| {
        t.replace("start = { lane = \"W_in_0\", s = 20.0 }\n", "")
            .replace("destination = { lane = \"C_E_0\", s = 80.0 }\n", "route_edges = [\"W_in\", \"C_N\"]\n")
    });
    let s = Scenario::load(&p).unwrap();
    assert_eq!(s.ego.route_edges.len(), 2);
    assert!((s.ego.start.pos.x - 5.0).abs() < 1e-9, "{:?}", s.ego.start);
    assert!(s.route_length_m() > 200.0);
    // Start by coordinates snaps to the lane heading.
    let p = write_variant("xy_start", |t| {
        t.replace("start = { lane = \"W_in_0\", s = 20.0 }", "start = { x = 30.0, y = 115.5 }")
    });
    let s = Scenario::load(&p).unwrap();
    assert!(s.ego.start.yaw.abs() < 1e-9 && s.ego.start.pos == Vec2::new(30.0, 115.5));
    let e = err_of("xy_far", |t| {
        t.replace("start = { lane = \"W_in_0\", s = 20.0 }", "start = { x = 30.0, y = 60.0 }")
    });
    assert!(e.contains("ego.start") && e.contains("no drivable lane"), "{e}");
}

/// Every number of the fixture replaced by awkward values: loading either fails cleanly or
/// gives a world that ticks without panicking or producing non-finite poses.
#[test]
fn awkward_numbers_never_panic() {
    use dh_env::drive::Control;
    use dh_env::world::World;
    let base = fixture_text();
    // Byte ranges of numeric literals outside comments.
    let mut spans = Vec::new();
    let mut offset = 0;
    for line in base.split_inclusive('\n') {
        let code = line.split('#').next().unwrap_or("");
        let b = code.as_bytes();
        let mut i = 0;
        while i < b.len() {
            let starts = (b[i].is_ascii_digit() || b[i] == b'-')
                && (i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_'));
            if starts && !code[..i].ends_with('"') && code[..i].matches('"').count() % 2 == 0 {
                let j = i + code[i..]
                    .find(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-'))
                    .unwrap_or(code.len() - i);
                if code[i..j].chars().any(|c| c.is_ascii_digit()) {
                    spans.push((offset + i, offset + j));
                }
                i = j;
            } else {
                i += 1;
            }
        }
        offset += line.len();
    }
    assert!(spans.len() > 20, "{}", spans.len());
    let mut loaded = 0;
    for (k, &(a, b)) in spans.iter().enumerate() {
        for (m, v) in ["nan", "inf", "-1.0", "0", "1e300", "-0.0"].iter().enumerate() {
            let text = format!("{}{}{}", &base[..a], v, &base[b..]);
            let p = write_variant(&format!("awk_{k}_{m}"), |_| text.clone());
            let Ok(s) = Scenario::load(&p) else { continue };
            loaded += 1;
            let mut w = World::new(&s, 0).unwrap();
            for _ in 0..40 {
                let r = w.tick(&Control { throttle: 1.0, brake: 0.0, steer: 0.2 }).unwrap();
                assert!(r.ego.pose.pos.is_finite());
                for a in w.actors() {
                    assert!(
                        a.pose.pos.is_finite() && a.pose.yaw.is_finite() && a.speed_mps.is_finite(),
                        "{k} {v}: {a:?}"
                    );
                }
            }
        }
    }
    assert!(loaded > 0);
}

/// A town01 scenario (the shipped network, with its sidewalk lanes) with `traffic` appended,
/// written to a temporary file; returns the path and the text.
fn town01_variant(tag: &str, traffic: &str) -> (PathBuf, String) {
    let map = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios/maps/town01/town01.net.xml");
    let text = format!(
        "version = 1\nid = \"{tag}\"\nname = \"t\"\ncategory = \"06_traffic_flow\"\ndescription = \"d\"\n\
         map = {:?}\nreference_duration_s = 50.0\n\n[ego]\nstart = {{ lane = \"C2T_1\", s = 30.0 }}\n\
         destination = {{ lane = \"T2E_0\", s = 30.0 }}\nspeed_mps = 8.0\n\n{traffic}",
        map.display().to_string()
    );
    let dir = std::env::temp_dir().join(format!("dh_scenario_errors_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(format!("{tag}.toml"));
    std::fs::write(&p, &text).unwrap();
    (p, text)
}

/// The 1-based line and column of the first occurrence of `needle` in `text`.
fn where_is(text: &str, needle: &str) -> (usize, usize) {
    let off = text.find(needle).unwrap_or_else(|| panic!("{needle} not in the text"));
    let line = text[..off].matches('\n').count() + 1;
    let col = off - text[..off].rfind('\n').map_or(0, |i| i + 1) + 1;
    (line, col)
}

/// The error of `validate` (what `drivehierarchy scenario validate` runs) must start with
/// `file:line:column: field `field` = value:`, at the value of that key.
fn assert_located(p: &std::path::Path, text: &str, value_at: &str, field: &str, value: &str, msg: &str) {
    let e = validate(p).expect_err("must fail").to_string();
    let (l, c) = where_is(text, value_at);
    let c = c + value_at.find(value).unwrap_or(0);
    let want = format!("{}:{l}:{c}: field `{field}` = {value}: ", p.display());
    assert!(e.starts_with(&want), "want prefix {want:?}, got {e}");
    assert!(e.contains(msg), "{e}");
}

const LEFT_LANE_FLOW: &str =
    "[traffic]\nmode = \"sumo\"\nwarmup_s = 3.0\n\n[[traffic.flows]]\nid = \"left_lane\"\n\
     from = \"W2C\"\nto = \"T2E\"\ndepart_lane = 2\nvehs_per_hour = 720\nbegin_s = -3.0\n";

/// SUMO refuses a route file whose vehicle departs on a lane that does not exist or is closed
/// to its class ("Invalid departLane definition", naming no file): validation catches both, at
/// the `depart_lane` key, for flows and single vehicles.
#[test]
fn depart_lane_must_exist_and_be_open_to_the_class() {
    let (p, t) = town01_variant("dl_ok", LEFT_LANE_FLOW);
    validate(&p).unwrap_or_else(|e| panic!("{e}"));
    // Lane 0 of W2C is town01's sidewalk (pedestrians only).
    let (p, t0) =
        town01_variant("dl_sidewalk", &LEFT_LANE_FLOW.replace("depart_lane = 2", "depart_lane = 0"));
    assert_located(
        &p,
        &t0,
        "depart_lane = 0",
        "traffic.flows[0].depart_lane",
        "0",
        "lane \"W2C_0\" is closed to vehicle class passenger (lanes of \"W2C\" open to it: 1, 2)",
    );
    let (p, t5) = town01_variant("dl_missing", &LEFT_LANE_FLOW.replace("depart_lane = 2", "depart_lane = 5"));
    assert_located(
        &p,
        &t5,
        "depart_lane = 5",
        "traffic.flows[0].depart_lane",
        "5",
        "edge \"W2C\" has no lane 5",
    );
    assert_ne!(t, t0);
    // The same for `[[traffic.vehicles]]`.
    let veh = "[traffic]\nmode = \"idm\"\n\n[[traffic.vehicles]]\nid = \"v\"\nroute = [\"C2T\", \"T2E\"]\n\
               depart_lane = 0\ndepart_pos_m = 100.0\n";
    let (p, tv) = town01_variant("dl_vehicle", veh);
    assert_located(
        &p,
        &tv,
        "depart_lane = 0",
        "traffic.vehicles[0].depart_lane",
        "0",
        "closed to vehicle class",
    );
    let (p, tv) = town01_variant("dl_vehicle9", &veh.replace("depart_lane = 0", "depart_lane = 9"));
    assert_located(&p, &tv, "depart_lane = 9", "traffic.vehicles[0].depart_lane", "9", "has no lane 9");
    // A class the lane admits is fine: pedestrians are not vehicles, but a bicycle type on a
    // car lane is (town01's road lanes only exclude pedestrians).
    let (p, _) = town01_variant(
        "dl_bike",
        &veh.replace("depart_lane = 0", "depart_lane = 1")
            .replace("id = \"v\"", "id = \"v\"\nvtype = \"bicycle\""),
    );
    validate(&p).unwrap_or_else(|e| panic!("{e}"));
}

/// An unreachable `to` (or `via`) of a flow is reported at that key, not the table header.
#[test]
fn unreachable_flow_is_located_at_its_key() {
    let flow = |from: &str, via: &str, to: &str| {
        format!("{}\n[traffic]\nmode = \"idm\"\n\n[[traffic.flows]]\nfrom = \"{from}\"\n{via}to = \"{to}\"\nvehs_per_hour = 100.0\n", fixture_text())
    };
    for (tag, text, at, field, value) in [
        ("to", flow("N_in", "", "C_N"), "to = \"C_N\"", "traffic.flows[0].to", "\"C_N\""),
        (
            "via",
            flow("N_in", "via = [\"C_S\", \"C_N\"]\n", "C_N"),
            "\"C_N\"]",
            "traffic.flows[0].via[1]",
            "\"C_N\"",
        ),
        ("from", flow("X_in", "", "C_N"), "from = \"X_in\"", "traffic.flows[0].from", "\"X_in\""),
    ] {
        let dir = std::env::temp_dir().join(format!("dh_scenario_errors_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(format!("flow_{tag}.toml"));
        std::fs::write(&p, &text).unwrap();
        let msg = if tag == "from" { "no such edge" } else { "not reachable" };
        assert_located(&p, &text, at, field, value, msg);
    }
}
