//! SUMO road networks: reading `.net.xml` / `.net.xml.gz`, the lane graph, routing, route
//! polylines through junctions and the drivable-area index.
//!
//! API contract used by world/, scenario/, drive/, render/ (keep these signatures stable):
//! - [`Network::from_file`] reads a net (plain or gzip) into the model of [`model`].
//! - [`Network::edge_route`] fastest path over normal edges (Dijkstra on travel time at the
//!   speed limit), honouring the vehicle class; [`Network::route_lanes`] /
//!   [`Network::route_polyline`] the lanes and centreline of a route of edges through
//!   junctions (internal `via` lanes included).
//! - [`DrivableIndex`] answers which drivable lanes contain a point (microseconds per query).

mod drivable;
pub mod model;
mod network;
mod parse;
mod route;
mod signals;

pub use drivable::DrivableIndex;
pub use model::*;
pub use network::Network;
pub use signals::{signal_heads, SignalHead};
