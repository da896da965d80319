#![no_main]
//! SUMO `.net.xml` reader: parse and build the network (lanes, junctions, connections, signal
//! programs, drivable-area index). Must never panic on any bytes.

use dh_env::map::Network;
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let Ok(net) = Network::from_xml_str(Path::new("fuzz.net.xml"), text) else { return };
    let b = net.bounds();
    let centre = dh_env::geom::Vec2::new((b.min.x + b.max.x) / 2.0, (b.min.y + b.max.y) / 2.0);
    let _ = net.drivable().is_drivable(centre);
    let _ = net.drivable().nearest_lane(centre, 50.0);
    for tl in net.tl_ids() {
        let _ = net.tl_links(tl);
        let _ = net.tl_logic(tl);
    }
    for lane in 0..net.lanes.len() {
        let _ = net.stop_line(lane);
        let _ = net.lane_position(lane, net.lanes[lane].length_m * 0.5);
    }
});
