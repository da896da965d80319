//! Load and query timings of the map module on real networks. Ignored by default (timings
//! are not assertions); run with
//! `cargo test -p dh-env --release --test it map_perf -- --ignored --nocapture`.

use dh_env::geom::Vec2;
use dh_env::map::Network;
use smallvec::SmallVec;
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Instant;

fn nets() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf();
    let mut v = vec![
        root.join("../shared/official/Close_Loop_Evaluation/Carla_Simulation/Co-Simulation/Sumo/tongji/tongji.net.xml"),
        root.join("scenarios/maps/town01/town01.net.xml"),
    ];
    if let Some(dh_env::sumo_home::SumoHome(h)) = dh_env::sumo_home::SumoHome::locate() {
        for rel in [
            "tools/game/fkk_in/ingolstadt.net.xml.gz",
            "tools/game/bs3d/bs.net.xml",
            "tools/game/A10KW/osm.net.xml",
        ] {
            v.push(h.join(rel));
        }
    }
    v.into_iter().filter(|p| p.exists()).collect()
}

/// Deterministic pseudo-random points over the network bounds.
fn points(net: &Network, n: usize) -> Vec<Vec2> {
    let b = net.bounds();
    let mut s = 0x9E37_79B9_7F4A_7C15u64;
    let mut r = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..n)
        .map(|_| Vec2::new(b.min.x + r() * (b.max.x - b.min.x), b.min.y + r() * (b.max.y - b.min.y)))
        .collect()
}

#[test]
#[ignore = "timing report, run explicitly in release"]
fn map_timings() {
    for path in nets() {
        let reps = 10;
        let mut net = None;
        let mut load_ms = f64::INFINITY;
        for _ in 0..reps {
            // Best of N wall-clock: the least disturbed run on a shared machine.
            let t0 = Instant::now();
            net = Some(Network::from_file(&path).unwrap());
            load_ms = load_ms.min(t0.elapsed().as_secs_f64() * 1e3);
        }
        let net = net.unwrap();
        let d = net.drivable();
        let pts = points(&net, 200_000);
        let mut out = SmallVec::new();
        let t = Instant::now();
        let mut hits = 0usize;
        for &p in &pts {
            d.lanes_at(p, &mut out);
            hits += out.len();
        }
        let lanes_at_ns = t.elapsed().as_nanos() as f64 / pts.len() as f64;
        let t = Instant::now();
        let on = pts.iter().filter(|&&p| d.is_drivable(p)).count();
        let drivable_ns = t.elapsed().as_nanos() as f64 / pts.len() as f64;
        let t = Instant::now();
        let mut found = 0usize;
        for &p in &pts[..50_000] {
            found += black_box(d.nearest_lane(p, 20.0)).is_some() as usize;
        }
        let nearest_ns = t.elapsed().as_nanos() as f64 / 50_000.0;
        let (segs, polys, cells, cell) = d.stats();
        println!(
            "{}: load {load_ms:.1} ms (best of {reps}) ({} edges, {} lanes, {} conns); index {segs} segs {polys} polys {cells} cells of {cell:.1} m; \
             lanes_at {lanes_at_ns:.0} ns, is_drivable {drivable_ns:.0} ns ({:.1}% on road), nearest_lane(20 m) {nearest_ns:.0} ns ({found} found); hits {hits}",
            path.file_name().unwrap().to_string_lossy(),
            net.edges.len(),
            net.lanes.len(),
            net.connections.len(),
            100.0 * on as f64 / pts.len() as f64,
        );
    }
}
