//! SUMO road networks: reading `.net.xml` / `.net.xml.gz`, the lane graph, routing, route
//! polylines through junctions and the drivable-area index.
//!
//! API contract used by world/, scenario/, drive/, render/ (keep these signatures stable):
//! - [`Network::from_file`] reads a net (plain or gzip) into the model of [`model`].
//! - [`Network::edge_route`] shortest path over normal edges (Dijkstra on lane length),
//!   honouring the vehicle class; [`Network::route_polyline`] the centreline of a route of
//!   edges through junctions (internal `via` lanes included).
//! - [`DrivableIndex`] answers which drivable lanes contain a point (microseconds per query).

pub mod model;

pub use model::*;
