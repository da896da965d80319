//! A SUMO road network as the world reads it (`dh_env::map::Network`), for Python tools that
//! place things on lanes (the official-scene importer): lanes and their shapes, snapping,
//! projection, poses along a lane and footprint overlap. All geometry is the world's own.

use crate::errors::to_pyerr;
use dh_env::geom::{Obb, Pose, Vec2};
use dh_env::map::{EdgeFunction, Lane, LaneIdx, VClass};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use std::sync::Arc;

fn function_name(f: EdgeFunction) -> &'static str {
    match f {
        EdgeFunction::Normal => "normal",
        EdgeFunction::Internal => "internal",
        EdgeFunction::Crossing => "crossing",
        EdgeFunction::WalkingArea => "walkingarea",
        EdgeFunction::Connector => "connector",
    }
}

fn vclass(py: Python<'_>, name: &str) -> PyResult<VClass> {
    VClass::from_sumo(name).ok_or_else(|| {
        to_pyerr(
            py,
            dh_env::Error::config("vclass", name, "not a SUMO vehicle class (e.g. passenger, pedestrian)"),
        )
    })
}

fn finite(py: Python<'_>, field: &str, values: &[f64]) -> PyResult<()> {
    if values.iter().all(|v| v.is_finite()) {
        return Ok(());
    }
    let shown = values.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(", ");
    Err(to_pyerr(py, dh_env::Error::config(field, format!("({shown})"), "must be finite")))
}

/// A road network read from a SUMO `.net.xml` (or `.net.xml.gz`) file.
#[pyclass(name = "Network", module = "drivehierarchy._core", frozen)]
pub struct PyNetwork {
    net: Arc<dh_env::map::Network>,
}

impl PyNetwork {
    fn lane_idx(&self, py: Python<'_>, id: &str) -> PyResult<LaneIdx> {
        self.net
            .lane_by_id(id)
            .ok_or_else(|| to_pyerr(py, dh_env::Error::map(&self.net.file, format!("no lane \"{id}\""))))
    }

    /// The lane `id` if its shape has a direction (SUMO keeps lanes whose shape points all
    /// coincide, e.g. 0.1 m stubs: nothing can be projected onto or placed along those).
    fn shaped_lane(&self, py: Python<'_>, id: &str) -> PyResult<&Lane> {
        let lane = &self.net.lanes[self.lane_idx(py, id)?];
        if lane.shape.len() < 2 {
            let msg =
                format!("lane \"{id}\": every point of its shape coincides (no direction to place along)");
            return Err(to_pyerr(py, dh_env::Error::map(&self.net.file, msg)));
        }
        Ok(lane)
    }

    fn lane_dict<'py>(&self, py: Python<'py>, l: &Lane) -> PyResult<Bound<'py, PyDict>> {
        let edge = &self.net.edges[l.edge];
        let d = PyDict::new(py);
        d.set_item("id", &l.id)?;
        d.set_item("edge", &edge.id)?;
        d.set_item("function", function_name(edge.function))?;
        d.set_item("index", l.index)?;
        d.set_item("width_m", l.width_m)?;
        d.set_item("length_m", l.length_m)?;
        d.set_item("shape_length_m", l.shape.length())?;
        d.set_item("speed_mps", l.speed_mps)?;
        d.set_item("allow", l.allow.sumo_names())?;
        d.set_item("shape", l.shape.points().iter().map(|p| (p.x, p.y)).collect::<Vec<_>>())?;
        Ok(d)
    }
}

#[pymethods]
impl PyNetwork {
    /// Reads a network file; a file that cannot be read or parsed raises `ScenarioError`
    /// naming it.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<PyNetwork> {
        let net = py.detach(|| dh_env::map::Network::from_file(&path)).map_err(|e| to_pyerr(py, e))?;
        Ok(PyNetwork { net: Arc::new(net) })
    }

    /// The file it was read from, as given.
    #[getter]
    fn path(&self) -> &str {
        &self.net.file
    }

    /// `<location netOffset>`: network coordinates = projected coordinates + offset.
    #[getter]
    fn offset(&self) -> (f64, f64) {
        let o = self.net.location.net_offset;
        (o.x, o.y)
    }

    /// `<location projParameter>` (a PROJ string; "!" when the network has no projection).
    #[getter]
    fn proj_parameter(&self) -> &str {
        &self.net.location.proj_parameter
    }

    /// The edge `id` as a dict (id, function, lanes: lane ids by index, successors: normal
    /// edges reached by a connection), or `None` if the network has no such edge.
    fn edge<'py>(&self, py: Python<'py>, id: &str) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(e) = self.net.edge_by_id(id) else { return Ok(None) };
        let edge = &self.net.edges[e];
        let d = PyDict::new(py);
        d.set_item("id", &edge.id)?;
        d.set_item("function", function_name(edge.function))?;
        d.set_item("lanes", edge.lanes.iter().map(|&l| self.net.lanes[l].id.as_str()).collect::<Vec<_>>())?;
        d.set_item(
            "successors",
            self.net.successors(e).map(|s| self.net.edges[s].id.as_str()).collect::<Vec<_>>(),
        )?;
        Ok(Some(d))
    }

    /// The lane `id` as a dict (id, edge, function, index, width_m, length_m, shape_length_m,
    /// speed_mps, allow: SUMO class names, shape: [(x, y), ...]), or `None`.
    fn lane<'py>(&self, py: Python<'py>, id: &str) -> PyResult<Option<Bound<'py, PyDict>>> {
        match self.net.lane_by_id(id) {
            Some(l) => self.lane_dict(py, &self.net.lanes[l]).map(Some),
            None => Ok(None),
        }
    }

    /// Lanes as dicts (see `lane`): every lane in file order (junction-internal ones only when
    /// `internal`), or the lanes of one `edge` by index; only those allowing `vclass` when given.
    /// An unknown edge raises `ScenarioError`, an unknown class `ConfigError`.
    #[pyo3(signature = (edge=None, vclass=None, internal=false))]
    fn lanes<'py>(
        &self,
        py: Python<'py>,
        edge: Option<&str>,
        vclass: Option<&str>,
        internal: bool,
    ) -> PyResult<Vec<Bound<'py, PyDict>>> {
        let class = vclass.map(|v| self::vclass(py, v)).transpose()?;
        let idx: Vec<LaneIdx> = match edge {
            Some(id) => match self.net.edge_by_id(id) {
                Some(e) => self.net.edges[e].lanes.clone(),
                None => {
                    return Err(to_pyerr(py, dh_env::Error::map(&self.net.file, format!("no edge \"{id}\""))))
                }
            },
            None => (0..self.net.lanes.len()).collect(),
        };
        idx.into_iter()
            .map(|l| &self.net.lanes[l])
            .filter(|l| class.is_none_or(|c| l.allow.contains(c)))
            .filter(|l| {
                internal || edge.is_some() || self.net.edges[l.edge].function != EdgeFunction::Internal
            })
            .map(|l| self.lane_dict(py, l))
            .collect()
    }

    /// `(s, offset)` of a point on lane `lane`: arc length along its shape and signed lateral
    /// offset (> 0 left of the direction of travel). Past the shape's ends `s` continues along
    /// the end segment (< 0 or > length) and the offset is taken square to it. An unknown lane,
    /// or one whose shape points all coincide, raises `ScenarioError` naming the network file.
    fn project(&self, py: Python<'_>, lane: &str, x: f64, y: f64) -> PyResult<(f64, f64)> {
        finite(py, "point", &[x, y])?;
        let pr = self
            .shaped_lane(py, lane)?
            .shape
            .project_extended(Vec2::new(x, y))
            .expect("a shaped lane has a segment");
        Ok((pr.s, pr.lateral))
    }

    /// `(x, y, heading)` at arc length `s` and lateral `offset` (> 0 left) of lane `lane`;
    /// heading in radians counter-clockwise from east. Past the shape's ends the position
    /// continues along the end segment.
    #[pyo3(signature = (lane, s, offset=0.0))]
    fn position(&self, py: Python<'_>, lane: &str, s: f64, offset: f64) -> PyResult<(f64, f64, f64)> {
        finite(py, "position", &[s, offset])?;
        let pose = self.shaped_lane(py, lane)?.shape.pose_extended(s);
        let p = pose.local_to_world(0.0, offset);
        Ok((p.x, p.y, pose.yaw))
    }

    /// The `length` × `width` footprint centred at arc length `s` and lateral `offset` of lane
    /// `lane`, aligned with the lane there (see `position`).
    fn lane_box(
        &self,
        py: Python<'_>,
        lane: &str,
        s: f64,
        offset: f64,
        length: f64,
        width: f64,
    ) -> PyResult<PyOrientedBox> {
        let (x, y, heading) = self.position(py, lane, s, offset)?;
        PyOrientedBox::new(py, x, y, heading, length, width)
    }

    /// `(lane id, s, distance)` of the lane nearest to a point within `max_dist_m`, or `None`:
    /// only lanes allowing `vclass` when given; junction-internal lanes only when `internal`.
    #[pyo3(signature = (x, y, max_dist_m=10.0, vclass=None, internal=false))]
    fn snap(
        &self,
        py: Python<'_>,
        x: f64,
        y: f64,
        max_dist_m: f64,
        vclass: Option<&str>,
        internal: bool,
    ) -> PyResult<Option<(String, f64, f64)>> {
        finite(py, "point", &[x, y])?;
        let class = vclass.map(|v| self::vclass(py, v)).transpose()?;
        let hit = self.net.nearest_lane(Vec2::new(x, y), max_dist_m, class, internal);
        Ok(hit.map(|(l, pr)| (self.net.lanes[l].id.clone(), pr.s, pr.distance)))
    }

    fn __repr__(&self) -> String {
        format!(
            "Network({:?}: {} edges, {} lanes)",
            self.net.file,
            self.net.edges.len(),
            self.net.lanes.len()
        )
    }
}

/// A rectangle on the ground (a vehicle's footprint): centre, heading (radians), length, width.
#[pyclass(name = "OrientedBox", module = "drivehierarchy._core", frozen)]
pub struct PyOrientedBox {
    obb: Obb,
}

#[pymethods]
impl PyOrientedBox {
    #[new]
    fn new(py: Python<'_>, x: f64, y: f64, heading: f64, length: f64, width: f64) -> PyResult<Self> {
        finite(py, "box", &[x, y, heading, length, width])?;
        if length < 0.0 || width < 0.0 {
            return Err(to_pyerr(
                py,
                dh_env::Error::config(
                    "box",
                    format!("length {length}, width {width}"),
                    "must not be negative",
                ),
            ));
        }
        Ok(PyOrientedBox {
            obb: Obb {
                pose: Pose::new(Vec2::new(x, y), heading),
                half_length: 0.5 * length,
                half_width: 0.5 * width,
            },
        })
    }
    #[getter]
    fn x(&self) -> f64 {
        self.obb.pose.pos.x
    }
    #[getter]
    fn y(&self) -> f64 {
        self.obb.pose.pos.y
    }
    #[getter]
    fn heading(&self) -> f64 {
        self.obb.pose.yaw
    }
    #[getter]
    fn length(&self) -> f64 {
        2.0 * self.obb.half_length
    }
    #[getter]
    fn width(&self) -> f64 {
        2.0 * self.obb.half_width
    }
    /// Corners counter-clockwise from front-left.
    fn corners(&self) -> Vec<(f64, f64)> {
        self.obb.corners().iter().map(|c| (c.x, c.y)).collect()
    }
    /// Whether the two boxes overlap, touching included (the world's separating-axis test).
    fn overlaps(&self, other: &PyOrientedBox) -> bool {
        self.obb.overlaps(&other.obb)
    }
    fn __repr__(&self) -> String {
        format!(
            "OrientedBox(x={}, y={}, heading={}, length={}, width={})",
            self.x(),
            self.y(),
            self.heading(),
            self.length(),
            self.width()
        )
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyNetwork>()?;
    m.add_class::<PyOrientedBox>()?;
    Ok(())
}
