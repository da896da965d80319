//! Signal heads of a network (one per traffic light and drivable incoming lane): a property of
//! the map alone, so the scenario summary and the world's light state both read it from here.

use super::model::LaneIdx;
use super::network::Network;
use smallvec::SmallVec;

/// A signal head before it has a colour: light id, incoming lane and link indices.
#[derive(Debug, Clone, PartialEq)]
pub struct SignalHead {
    pub tl_id: String,
    pub lane: LaneIdx,
    pub link_indices: SmallVec<[usize; 4]>,
}

/// Signal heads of a network for drivable (passenger) incoming lanes — pedestrian crossings
/// and bicycle-only lanes get none — sorted by light id then lane index (deterministic order).
pub fn signal_heads(map: &Network) -> Vec<SignalHead> {
    let mut heads: Vec<SignalHead> = Vec::new();
    for tl in map.tl_ids() {
        let start = heads.len();
        for link in map.tl_links(tl) {
            if !map.lanes.get(link.from_lane).is_some_and(|l| l.is_drivable()) {
                continue;
            }
            match heads[start..].iter_mut().find(|h| h.lane == link.from_lane) {
                Some(h) => {
                    if !h.link_indices.contains(&link.link_index) {
                        h.link_indices.push(link.link_index);
                    }
                }
                None => heads.push(SignalHead {
                    tl_id: tl.to_string(),
                    lane: link.from_lane,
                    link_indices: SmallVec::from_slice(&[link.link_index]),
                }),
            }
        }
        heads[start..].sort_by_key(|h| h.lane);
    }
    heads
}
