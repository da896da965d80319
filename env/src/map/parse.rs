//! Streaming reader of SUMO `.net.xml` (plain or gzip) into the model.
//!
//! The whole file is read into memory once and parsed zero-copy with quick-xml; references
//! between elements (edge → junction, connection → lanes, ...) are resolved after the pass
//! so element order in the file does not matter.

use super::model::*;
use crate::geom::Vec2;
use crate::{Error, Result};
use quick_xml::events::{BytesStart, Event};
use quick_xml::Reader;
use std::borrow::Cow;
use std::io::Read;
use std::path::Path;

/// Everything read from the file, references still by id.
#[derive(Debug, Default)]
pub(crate) struct RawNet {
    pub edges: Vec<Edge>,
    pub edge_from_to: Vec<(Option<String>, Option<String>)>,
    pub lanes: Vec<Lane>,
    pub junctions: Vec<Junction>,
    pub junction_lanes: Vec<(String, String)>,
    pub connections: Vec<RawConnection>,
    pub tl_logics: Vec<TlLogic>,
    pub roundabouts: Vec<(String, String)>,
    pub location: Location,
}

#[derive(Debug)]
pub(crate) struct RawConnection {
    /// Byte offset of the element in the text.
    pub pos: usize,
    pub from: String,
    pub to: String,
    pub from_lane: usize,
    pub to_lane: usize,
    pub via: Option<String>,
    pub tl: Option<String>,
    pub link_index: Option<usize>,
    pub dir: TurnDir,
    pub state: char,
}

/// Reads the file, un-gzipping when it starts with the gzip magic bytes.
pub(crate) fn read_text(path: &Path) -> Result<String> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let bytes = if bytes.starts_with(&[0x1f, 0x8b]) {
        let mut out = Vec::with_capacity(bytes.len() * 8);
        flate2::read::MultiGzDecoder::new(&bytes[..])
            .read_to_end(&mut out)
            .map_err(|e| Error::map(path, format!("cannot decompress gzip data: {e}")))?;
        out
    } else {
        bytes
    };
    String::from_utf8(bytes).map_err(|e| {
        Error::map(path, format!("not UTF-8 text (invalid byte at offset {})", e.utf8_error().valid_up_to()))
    })
}

pub(crate) fn line_of(text: &str, offset: usize) -> usize {
    let offset = offset.min(text.len());
    text.as_bytes()[..offset].iter().filter(|&&b| b == b'\n').count() + 1
}

/// Attributes of one element, borrowed from the input when unescaped.
struct Attrs<'a> {
    list: Vec<(&'a str, Cow<'a, str>)>,
}

impl<'a> Attrs<'a> {
    fn get(&self, key: &str) -> Option<&str> {
        self.list.iter().find(|(k, _)| *k == key).map(|(_, v)| v.as_ref())
    }
}

/// Context for error messages: which element (with its id) is being read.
struct Ctx<'p> {
    path: &'p Path,
    text: &'p str,
    /// Byte offset of the element; turned into a line number only when an error is built.
    pos: usize,
    what: String,
}

impl Ctx<'_> {
    fn err(&self, msg: impl std::fmt::Display) -> Error {
        Error::map(self.path, format!("line {}: {}: {msg}", line_of(self.text, self.pos), self.what))
    }
    fn bad(&self, key: &str, value: &str, msg: &str) -> Error {
        self.err(format!("attribute {key} = \"{value}\": {msg}"))
    }
    fn required<'v>(&self, a: &'v Attrs, key: &str) -> Result<&'v str> {
        a.get(key).ok_or_else(|| self.err(format!("missing attribute {key}")))
    }
    fn f64_opt(&self, a: &Attrs, key: &str) -> Result<Option<f64>> {
        match a.get(key) {
            None => Ok(None),
            Some(v) => match parse_f64(v.trim()) {
                Some(x) if x.is_finite() => Ok(Some(x)),
                _ => Err(self.bad(key, v, "not a finite number")),
            },
        }
    }
    fn f64_req(&self, a: &Attrs, key: &str) -> Result<f64> {
        self.f64_opt(a, key)?.ok_or_else(|| self.err(format!("missing attribute {key}")))
    }
    fn usize_opt(&self, a: &Attrs, key: &str) -> Result<Option<usize>> {
        match a.get(key) {
            None => Ok(None),
            Some(v) => v
                .trim()
                .parse::<usize>()
                .map(Some)
                .map_err(|_| self.bad(key, v, "not a non-negative integer")),
        }
    }
    fn usize_req(&self, a: &Attrs, key: &str) -> Result<usize> {
        self.usize_opt(a, key)?.ok_or_else(|| self.err(format!("missing attribute {key}")))
    }
    fn shape(&self, a: &Attrs, key: &str) -> Result<Option<Vec<Vec2>>> {
        match a.get(key) {
            None => Ok(None),
            Some(v) => parse_shape(v)
                .map(Some)
                .ok_or_else(|| self.bad(key, v, "not a coordinate list (\"x,y[,z] x,y[,z] ...\")")),
        }
    }
    fn floats<const N: usize>(&self, a: &Attrs, key: &str) -> Result<Option<[f64; N]>> {
        match a.get(key) {
            None => Ok(None),
            Some(v) => {
                let mut out = [0.0; N];
                let mut it = v.split(',');
                for o in out.iter_mut() {
                    match it.next().and_then(|s| parse_f64(s.trim())) {
                        Some(x) if x.is_finite() => *o = x,
                        _ => return Err(self.bad(key, v, &format!("expected {N} comma-separated numbers"))),
                    }
                }
                if it.next().is_some() {
                    return Err(self.bad(key, v, &format!("expected {N} comma-separated numbers")));
                }
                Ok(Some(out))
            }
        }
    }
}

/// Parses a decimal number. Plain `[-]digits[.digits]` with at most 19 significant digits
/// takes Clinger's fast path (exact mantissa divided by an exact power of ten: correctly
/// rounded, so bit-identical to `str::parse`); anything else falls back to `str::parse`.
/// Shapes hold most of a net's bytes, and this halves load time.
pub(crate) fn parse_f64(s: &str) -> Option<f64> {
    const POW10: [f64; 23] = [
        1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16, 1e17,
        1e18, 1e19, 1e20, 1e21, 1e22,
    ];
    let b = s.as_bytes();
    let (neg, digits) = match b.first() {
        Some(b'-') => (true, &b[1..]),
        Some(b'+') => (false, &b[1..]),
        _ => (false, b),
    };
    let mut mant: u64 = 0;
    let mut n_digits = 0usize;
    let mut frac = 0usize;
    let mut seen_dot = false;
    for &c in digits {
        match c {
            b'0'..=b'9' => {
                mant = mant.wrapping_mul(10).wrapping_add((c - b'0') as u64);
                n_digits += 1;
                if seen_dot {
                    frac += 1;
                }
            }
            b'.' if !seen_dot => seen_dot = true,
            _ => return s.parse().ok(),
        }
    }
    if n_digits == 0 || n_digits > 19 || mant >= (1u64 << 53) || frac >= POW10.len() {
        return s.parse().ok();
    }
    let v = mant as f64 / POW10[frac];
    Some(if neg { -v } else { v })
}

/// `"x,y[,z] x,y[,z] ..."` → points (z dropped). `None` on any malformed coordinate.
fn parse_shape(s: &str) -> Option<Vec<Vec2>> {
    let mut pts = Vec::with_capacity(s.len() / 14 + 1);
    for tok in s.split_ascii_whitespace() {
        let mut it = tok.split(',');
        let x = parse_f64(it.next()?)?;
        let y = parse_f64(it.next()?)?;
        if let Some(z) = it.next() {
            parse_f64(z)?;
        }
        if it.next().is_some() || !x.is_finite() || !y.is_finite() {
            return None;
        }
        pts.push(Vec2::new(x, y));
    }
    Some(pts)
}

fn attrs<'a>(e: &'a BytesStart<'a>, ctx: &Ctx) -> Result<Attrs<'a>> {
    let mut list = Vec::with_capacity(12);
    for a in e.attributes().with_checks(false) {
        let a = a.map_err(|err| ctx.err(format!("malformed attribute: {err}")))?;
        let key: &'a str = a.key.into_inner();
        let value = if a.value.contains('&') {
            Cow::Owned(
                a.normalized_value(quick_xml::XmlVersion::Implicit1_0)
                    .map_err(|err| ctx.err(format!("attribute {key}: {err}")))?
                    .into_owned(),
            )
        } else {
            a.value
        };
        list.push((key, value));
    }
    Ok(Attrs { list })
}

/// Parses the whole document.
pub(crate) fn parse_net(path: &Path, text: &str) -> Result<RawNet> {
    let mut reader = Reader::from_str(text);
    reader.config_mut().check_end_names = true;
    let mut net = RawNet::default();
    // Open elements whose children we read: the current edge and tlLogic.
    let mut cur_edge: Option<usize> = None;
    let mut cur_tl: Option<usize> = None;
    let mut saw_net = false;
    loop {
        let pos = reader.buffer_position() as usize;
        let ev = reader.read_event().map_err(|e| {
            let at = reader.error_position() as usize;
            Error::map(path, format!("line {}: malformed XML: {e}", line_of(text, at)))
        })?;
        let (e, is_start) = match &ev {
            Event::Start(e) => (e, true),
            Event::Empty(e) => (e, false),
            Event::End(e) => {
                match e.local_name().as_ref() {
                    "edge" => cur_edge = None,
                    "tlLogic" => cur_tl = None,
                    _ => {}
                }
                continue;
            }
            Event::Eof => break,
            _ => continue,
        };
        let name = e.local_name();
        let name = name.as_ref();
        // Cheap skip of the most frequent elements we ignore.
        if matches!(name, "param" | "request" | "type" | "neigh" | "stopOffset") {
            continue;
        }
        let mut ctx = Ctx { path, text, pos, what: String::new() };
        match name {
            "net" => saw_net = true,
            "location" => {
                ctx.what = "location".into();
                let a = attrs(e, &ctx)?;
                if let Some([x, y]) = ctx.floats::<2>(&a, "netOffset")? {
                    net.location.net_offset = Vec2::new(x, y);
                }
                if let Some(b) = ctx.floats::<4>(&a, "convBoundary")? {
                    net.location.conv_boundary = b;
                }
                if let Some(b) = ctx.floats::<4>(&a, "origBoundary")? {
                    net.location.orig_boundary = b;
                }
                net.location.proj_parameter = a.get("projParameter").unwrap_or("").to_string();
            }
            "edge" => {
                ctx.what = "edge".into();
                let a = attrs(e, &ctx)?;
                let id = ctx.required(&a, "id")?.to_string();
                ctx.what = format!("edge \"{id}\"");
                let fun = a.get("function").unwrap_or("");
                let function = EdgeFunction::from_sumo(fun)
                    .ok_or_else(|| ctx.bad("function", fun, "unknown edge function"))?;
                let priority = match a.get("priority") {
                    None => 0,
                    Some(v) => {
                        v.trim().parse::<i32>().map_err(|_| ctx.bad("priority", v, "not an integer"))?
                    }
                };
                net.edges.push(Edge {
                    id,
                    function,
                    from: None,
                    to: None,
                    lanes: Vec::new(),
                    priority,
                    name: a.get("name").map(str::to_string),
                    type_id: a.get("type").unwrap_or("").to_string(),
                    junction: None,
                });
                net.edge_from_to.push((a.get("from").map(str::to_string), a.get("to").map(str::to_string)));
                if is_start {
                    cur_edge = Some(net.edges.len() - 1);
                }
            }
            "lane" => {
                let Some(ei) = cur_edge else {
                    ctx.what = "lane".into();
                    return Err(ctx.err("<lane> outside of an <edge>"));
                };
                ctx.what = format!("edge \"{}\" lane", net.edges[ei].id);
                let a = attrs(e, &ctx)?;
                let id = ctx.required(&a, "id")?.to_string();
                ctx.what = format!("edge \"{}\" lane \"{id}\"", net.edges[ei].id);
                let index = ctx.usize_req(&a, "index")?;
                let speed = ctx.f64_req(&a, "speed")?;
                let width = ctx.f64_opt(&a, "width")?.unwrap_or(DEFAULT_LANE_WIDTH_M);
                let pts = ctx.shape(&a, "shape")?.ok_or_else(|| ctx.err("missing attribute shape"))?;
                if pts.len() < 2 {
                    return Err(ctx.bad("shape", a.get("shape").unwrap_or(""), "needs at least 2 points"));
                }
                let shape = crate::geom::Polyline::new(pts);
                let length = ctx.f64_opt(&a, "length")?.unwrap_or(shape.length());
                let allow =
                    VClassSet::from_allow_disallow(a.get("allow"), a.get("disallow")).map_err(|bad| {
                        let key = if a.get("allow").is_some() { "allow" } else { "disallow" };
                        ctx.bad(key, a.get(key).unwrap_or(""), &format!("unknown vehicle class \"{bad}\""))
                    })?;
                net.edges[ei].lanes.push(net.lanes.len());
                net.lanes.push(Lane {
                    id,
                    edge: ei,
                    index,
                    speed_mps: speed,
                    length_m: length,
                    width_m: width,
                    shape,
                    allow,
                });
            }
            "junction" => {
                ctx.what = "junction".into();
                let a = attrs(e, &ctx)?;
                let id = ctx.required(&a, "id")?.to_string();
                ctx.what = format!("junction \"{id}\"");
                let x = ctx.f64_req(&a, "x")?;
                let y = ctx.f64_req(&a, "y")?;
                let shape = ctx.shape(&a, "shape")?.unwrap_or_default();
                net.junctions.push(Junction {
                    id,
                    kind: a.get("type").unwrap_or("").to_string(),
                    pos: Vec2::new(x, y),
                    shape,
                    inc_lanes: Vec::new(),
                    int_lanes: Vec::new(),
                });
                net.junction_lanes.push((
                    a.get("incLanes").unwrap_or("").to_string(),
                    a.get("intLanes").unwrap_or("").to_string(),
                ));
            }
            "connection" => {
                ctx.what = "connection".into();
                let a = attrs(e, &ctx)?;
                let from = ctx.required(&a, "from")?.to_string();
                let to = ctx.required(&a, "to")?.to_string();
                ctx.what = format!("connection from \"{from}\" to \"{to}\"");
                let dir_s = a.get("dir").unwrap_or("s");
                let dir =
                    TurnDir::from_sumo(dir_s).ok_or_else(|| ctx.bad("dir", dir_s, "unknown direction"))?;
                let state_s = a.get("state").unwrap_or("M");
                let mut chars = state_s.chars();
                let state = match (chars.next(), chars.next()) {
                    (Some(c), None) => c,
                    _ => return Err(ctx.bad("state", state_s, "expected one character")),
                };
                net.connections.push(RawConnection {
                    pos,
                    from,
                    to,
                    from_lane: ctx.usize_req(&a, "fromLane")?,
                    to_lane: ctx.usize_req(&a, "toLane")?,
                    via: a.get("via").map(str::to_string),
                    tl: a.get("tl").map(str::to_string),
                    link_index: ctx.usize_opt(&a, "linkIndex")?,
                    dir,
                    state,
                });
            }
            "tlLogic" => {
                ctx.what = "tlLogic".into();
                let a = attrs(e, &ctx)?;
                let id = ctx.required(&a, "id")?.to_string();
                ctx.what = format!("tlLogic \"{id}\"");
                net.tl_logics.push(TlLogic {
                    id,
                    kind: a.get("type").unwrap_or("static").to_string(),
                    program_id: a.get("programID").unwrap_or("0").to_string(),
                    offset_s: ctx.f64_opt(&a, "offset")?.unwrap_or(0.0),
                    phases: Vec::new(),
                });
                if is_start {
                    cur_tl = Some(net.tl_logics.len() - 1);
                }
            }
            "phase" => {
                let Some(ti) = cur_tl else {
                    ctx.what = "phase".into();
                    return Err(ctx.err("<phase> outside of a <tlLogic>"));
                };
                ctx.what =
                    format!("tlLogic \"{}\" phase {}", net.tl_logics[ti].id, net.tl_logics[ti].phases.len());
                let a = attrs(e, &ctx)?;
                let duration_s = ctx.f64_req(&a, "duration")?;
                let state = ctx.required(&a, "state")?.to_string();
                net.tl_logics[ti].phases.push(TlPhase { duration_s, state });
            }
            "roundabout" => {
                ctx.what = "roundabout".into();
                let a = attrs(e, &ctx)?;
                net.roundabouts.push((
                    a.get("nodes").unwrap_or("").to_string(),
                    a.get("edges").unwrap_or("").to_string(),
                ));
            }
            _ => {}
        }
    }
    if !saw_net {
        return Err(Error::map(path, "not a SUMO network: no <net> element"));
    }
    Ok(net)
}

#[cfg(test)]
mod tests {
    use super::parse_f64;

    #[test]
    fn fast_float_parse_matches_std() {
        for s in [
            "0",
            "-0",
            "1",
            "12.5",
            "-761.28",
            "0.1",
            "0.30000000000000004",
            "123456.789012",
            "1e3",
            "-1.5E-2",
            "9007199254740993",
            "12345678901234567890.5",
            ".5",
            "5.",
            "+3.25",
            "inf",
            "NaN",
        ] {
            assert_eq!(parse_f64(s).map(f64::to_bits), s.parse::<f64>().ok().map(f64::to_bits), "{s}");
        }
        for s in ["", "-", ".", "1.2.3", "1,2", "abc", "--1", "1-"] {
            assert_eq!(parse_f64(s), None, "{s}");
        }
        // Every 2-decimal coordinate in a wide range matches std bit for bit.
        for i in (-2_000_000i64..2_000_000).step_by(997) {
            let s = format!("{}{}.{:02}", if i < 0 { "-" } else { "" }, i.abs() / 100, i.abs() % 100);
            assert_eq!(parse_f64(&s).unwrap().to_bits(), s.parse::<f64>().unwrap().to_bits(), "{s}");
        }
    }
}
