//! 2D scene files (issue #36): which sensor a file names, and a 2D file's `[screen]`,
//! `[[window]]`, `[[edge]]` and `[edges]` converted to a [`Config2d`] with the 1D reader's
//! machinery — the per-kind texture readers (`regions.rs`), `[limits]` and `drive`
//! (`sections.rs`), the located range checks (`ctx.rs`) and the unknown-key sentences
//! (`keys.rs`) — then dry-run through a [`Controller2d`], whose refusals are located at the
//! value they are about as the 1D controller's are.

extern crate std;

use core::ops::Range;
use std::format;
use std::string::{String, ToString};
use std::vec::Vec as StdVec;

use heapless::Vec;
use toml::Spanned;

use crate::burst::{BurstError, BurstTimer};
use crate::plane::edges::MAX_EDGE_REARM_UM;
use crate::plane::geometry::MAX_COORD_UM;
use crate::plane::screen::{DEFAULT_BAND_UM, MAX_BAND_UM};
use crate::plane::{
    Config2d, Config2dError, Controller2d, EdgeError, EdgePulse, GeometryError, OrientedError,
    OrientedGrating, Owner, PlaneTexture, PointUm, Polygon, Scene2d, ScreenError, SegmentUm,
    Window2d, MAX_EDGES, MAX_VERTICES, MAX_WINDOWS,
};
use crate::texture::{Envelope, GratingRender, Texture};

use super::ctx::{milli, Ctx};
use super::spec::{self, EnvelopeSpec, RegionSpec};
use super::spec2d::{File2d, Numbers, SensorOnly};
use super::{burst_keys, regions, sections, texture_keys, SceneFileError, SensorKind, Spans};

/// The one value `[sensor] kind` takes: the 4-wire resistive overlay.
pub(super) const FOUR_WIRE: &str = "4-wire";

/// The sensor `[sensor] kind` names, with the span of its value (None: no `[sensor]`, a 1D
/// file). Only `[sensor]` is read: whatever else is wrong is the loader's to say.
pub(super) fn sensor(cx: &Ctx<'_>) -> Result<(SensorKind, Option<Range<usize>>), SceneFileError> {
    let only: SensorOnly = spec::read_as(cx)?;
    let Some(s) = only.sensor else {
        return Ok((SensorKind::Rheostat, None));
    };
    let kind = &s.get_ref().kind;
    match kind.get_ref().as_str() {
        FOUR_WIRE => Ok((SensorKind::FourWire, Some(kind.span()))),
        other => Err(cx.err(
            kind.span(),
            "sensor.kind",
            format_args!(
                "unknown sensor `{other}`: it must be `{FOUR_WIRE}` (the touch overlay: a 2D \
                 scene); a 1D scene for the slide rheostat has no [sensor] table"
            ),
        )),
    }
}

/// The 1D reader's refusal of a 2D file, at its `[sensor] kind`.
pub(super) fn refuse_in_1d(cx: &Ctx<'_>, kind_span: Range<usize>) -> SceneFileError {
    cx.err(
        kind_span,
        "sensor.kind",
        format_args!(
            "this is a 2D scene for the {FOUR_WIRE} touch sensor; a board with the slide \
             rheostat reads only 1D scenes (no [sensor] table)"
        ),
    )
}

/// A 2D file read and converted, with what is needed to locate the controller's refusals.
struct Doc2d {
    spans: Spans,
    /// The windows whose outline pulses, in order, with their vertex count: the scene's first
    /// edges are their sides (`Config2dError`'s edge indices count them first).
    outlines: StdVec<(usize, usize)>,
    /// `[screen] size_mm`, µm (width, height): what a written file needs besides the config.
    plate_um: (u32, u32),
    config: Config2d,
}

/// Reads a 2D file and checks it against a board: the configuration, ready to load.
pub(super) fn load(
    cx: &Ctx<'_>,
    timer: BurstTimer,
    frame_period_us: u32,
) -> Result<Config2d, SceneFileError> {
    let doc = parse(cx)?;
    let locate = |e: Config2dError| doc.locate(cx, &e);
    let mut dry = Controller2d::new(timer, frame_period_us).map_err(locate)?;
    dry.load(&doc.config).map_err(locate)?;
    Ok(doc.config)
}

/// A 2D file's `[screen] size_mm`, µm (width, height), the file read and checked as far as
/// [`load`] reads it before the dry run.
pub(super) fn plate_um(cx: &Ctx<'_>) -> Result<(u32, u32), SceneFileError> {
    parse(cx).map(|doc| doc.plate_um)
}

/// The plate's touch area, mm: x from 0 to `w`, y from 0 to `h`.
#[derive(Clone, Copy)]
struct Plate {
    w: f64,
    h: f64,
}

/// Parses and converts a 2D file; the sections in a fixed order (sensor, limits, screen,
/// windows, edges), the first bad value met refused.
fn parse(cx: &Ctx<'_>) -> Result<Doc2d, SceneFileError> {
    if let (SensorKind::Rheostat, _) = sensor(cx)? {
        return Err(cx.err(
            0..0,
            "sensor",
            format_args!(
                "this is a 1D scene for the slide rheostat (it has no [sensor] table); a 2D \
                 scene names its sensor: [sensor] kind = \"{FOUR_WIRE}\""
            ),
        ));
    }
    let doc: File2d = spec::read_as(cx)?;
    let mut spans = Spans::default();
    spans.put_limits(doc.limits.as_ref());
    let (limits, stale_after_us) = sections::limits(cx, doc.limits.as_ref())?;
    let duty_cap_percent = limits.max_duty_permille as f64 / 10.0;
    let drive = sections::drive(doc.drive.as_ref());

    let Some(screen) = &doc.screen else {
        return Err(cx.err(
            0..0,
            "screen",
            "a 2D scene needs [screen] with `size_mm = [width, height]`, the plate's touch area",
        ));
    };
    spans.put("screen", screen.span());
    let s = screen.get_ref();
    let Some(size) = &s.size_mm else {
        return Err(cx.err(
            screen.span(),
            "screen.size_mm",
            "[screen] needs `size_mm = [width, height]`, the plate's touch area in mm",
        ));
    };
    let max_mm = MAX_COORD_UM as f64 / 1000.0;
    let [w, h] = pair(cx, size, "screen.size_mm", "[width, height]")?;
    let plate = Plate {
        w: cx.range(w, "screen.size_mm", 1.0, max_mm)?,
        h: cx.range(h, "screen.size_mm", 1.0, max_mm)?,
    };
    let extent_mm = plate.w.max(plate.h);
    let band_mm = cx.opt(
        &s.band_mm,
        "screen.band_mm",
        0.001,
        MAX_BAND_UM as f64 / 1000.0,
        DEFAULT_BAND_UM as f64 / 1000.0,
    )?;
    if let Some(b) = &s.band_mm {
        spans.put("screen.band_mm", b.span());
    }
    let background = match &s.background {
        None => PlaneTexture::default(),
        Some(b) => {
            let prefix = "screen.background";
            let spec = b.get_ref();
            let tex = spec.texture();
            spans.put_texture(prefix, b.span(), &tex, spec.ridge_angle_deg.as_ref());
            plane_texture(
                cx,
                prefix,
                b.span(),
                &tex,
                spec.ridge_angle_deg.as_ref(),
                extent_mm,
                duty_cap_percent,
            )?
        }
    };

    let mut windows: Vec<Window2d, MAX_WINDOWS> = Vec::new();
    let mut outlines = StdVec::new();
    let mut edge_count = 0usize;
    for (i, w) in doc.window.iter().enumerate() {
        let prefix = format!("window[{i}]");
        if i >= MAX_WINDOWS {
            return Err(cx.err(
                w.span(),
                "window",
                format_args!("more than {MAX_WINDOWS} windows"),
            ));
        }
        let spec = w.get_ref();
        let tex = spec.texture();
        spans.put_texture(&prefix, w.span(), &tex, spec.ridge_angle_deg.as_ref());
        let outline = window_outline(cx, &prefix, w, plate, &mut spans)?;
        let texture = plane_texture(
            cx,
            &prefix,
            w.span(),
            &tex,
            spec.ridge_angle_deg.as_ref(),
            extent_mm,
            duty_cap_percent,
        )?;
        let edge = spec.outline.as_ref().is_some_and(|o| *o.get_ref());
        if let (Some(o), true) = (&spec.outline, edge) {
            spans.put(&format!("{prefix}.outline"), o.span());
            edge_count += outline.vertices.len();
            if edge_count > MAX_EDGES {
                return Err(cx.err(
                    o.span(),
                    &format!("{prefix}.outline"),
                    too_many_edges(edge_count),
                ));
            }
            outlines.push((i, outline.vertices.len()));
        }
        // Capacity: `i` is below MAX_WINDOWS here.
        let _ = windows.push(Window2d {
            outline,
            texture,
            edge,
        });
    }

    let mut free_edges: Vec<SegmentUm, MAX_EDGES> = Vec::new();
    for (j, e) in doc.edge.iter().enumerate() {
        let prefix = format!("edge[{j}]");
        spans.put(&prefix, e.span());
        edge_count += 1;
        if edge_count > MAX_EDGES {
            return Err(cx.err(e.span(), "edge", too_many_edges(edge_count)));
        }
        let spec = e.get_ref();
        let from = format!("{prefix}.from_mm");
        let to = format!("{prefix}.to_mm");
        spans.put(&from, spec.from_mm.span());
        spans.put(&to, spec.to_mm.span());
        let a = point(cx, &spec.from_mm, &from, plate)?;
        let b = point(cx, &spec.to_mm, &to, plate)?;
        if a == b {
            return Err(cx.err(
                spec.to_mm.span(),
                &to,
                format_args!(
                    "the edge ends where it starts, at ({} mm, {} mm): it has zero length",
                    a.x_um as f64 / 1000.0,
                    a.y_um as f64 / 1000.0
                ),
            ));
        }
        // Capacity: `edge_count` (these and the outlines' sides) is within MAX_EDGES here.
        let _ = free_edges.push(SegmentUm { a, b });
    }

    let (edge_pulse, rearm_um) = edges(cx, &doc, &mut spans)?;
    let config = Config2d {
        scene: Scene2d {
            windows,
            background,
            band_um: milli(band_mm),
            free_edges,
            edge_pulse,
            rearm_um,
            drive,
        },
        limits,
        stale_after_us,
    };
    Ok(Doc2d {
        spans,
        outlines,
        plate_um: (milli(plate.w), milli(plate.h)),
        config,
    })
}

/// The sentence for an edge count past [`MAX_EDGES`]: the controller's, and what counts.
fn too_many_edges(edges: usize) -> String {
    format!(
        "{} (each side of a window with `outline = true` is one, then each [[edge]])",
        EdgeError::TooMany { edges }
    )
}

/// `[edges]`: the pulse and the re-arm distance, the edges' defaults when absent.
fn edges(
    cx: &Ctx<'_>,
    doc: &File2d,
    spans: &mut Spans,
) -> Result<(EdgePulse, u32), SceneFileError> {
    let default = EdgePulse::default();
    let default_rearm_um = crate::plane::Edges::default().rearm_um;
    let Some(t) = &doc.edges else {
        return Ok((default, default_rearm_um));
    };
    spans.put("edges", t.span());
    let e = t.get_ref();
    for (name, v) in [
        ("pulse_ms", &e.pulse_ms),
        ("amplitude_percent", &e.amplitude_percent),
        ("rearm_mm", &e.rearm_mm),
    ] {
        if let Some(v) = v {
            spans.put(&format!("edges.{name}"), v.span());
        }
    }
    let pulse_us = milli(cx.opt(
        &e.pulse_ms,
        "edges.pulse_ms",
        0.001,
        1000.0,
        default.pulse_us as f64 / 1000.0,
    )?);
    let envelope = match e.envelope {
        None | Some(EnvelopeSpec::Triangle) => Envelope::Triangular,
        Some(EnvelopeSpec::Rectangle) => Envelope::Rectangular,
    };
    let amplitude_permille =
        cx.permille(&e.amplitude_percent, "edges.amplitude_percent", 0.1, 100.0)?;
    let rearm_um = milli(cx.opt(
        &e.rearm_mm,
        "edges.rearm_mm",
        0.001,
        MAX_EDGE_REARM_UM as f64 / 1000.0,
        default_rearm_um as f64 / 1000.0,
    )?);
    Ok((
        EdgePulse {
            pulse_us,
            envelope,
            amplitude_permille,
        },
        rearm_um,
    ))
}

/// A window's outline: `rect_mm = [x0, y0, x1, y1]` or `polygon_mm = [[x, y], …]`, every
/// vertex on the plate. Whether a polygon is simple is the controller's check (located at the
/// vertex that starts the edge it names).
fn window_outline(
    cx: &Ctx<'_>,
    prefix: &str,
    w: &Spanned<super::spec2d::WindowSpec>,
    plate: Plate,
    spans: &mut Spans,
) -> Result<Polygon, SceneFileError> {
    let spec = w.get_ref();
    match (&spec.rect_mm, &spec.polygon_mm) {
        (Some(r), None) => {
            let field = format!("{prefix}.rect_mm");
            spans.put(&field, r.span());
            let n = r.get_ref().len();
            let [Some(x0), Some(y0), Some(x1), Some(y1)] =
                [0, 1, 2, 3].map(|k| r.get_ref().get(k).filter(|_| n == 4))
            else {
                return Err(cx.err(
                    r.span(),
                    &field,
                    format_args!(
                        "a rectangle is [x0, y0, x1, y1] in mm (its lower left and upper right \
                         corners); this has {n} numbers"
                    ),
                ));
            };
            let lo = PointUm::new(
                coordinate(cx, x0, &field, "x0", plate.w)?,
                coordinate(cx, y0, &field, "y0", plate.h)?,
            );
            let hi = PointUm::new(
                coordinate(cx, x1, &field, "x1", plate.w)?,
                coordinate(cx, y1, &field, "y1", plate.h)?,
            );
            for (name, hi_um, lo_um, v, lo_name) in [
                ("x1", hi.x_um, lo.x_um, x1, "x0"),
                ("y1", hi.y_um, lo.y_um, y1, "y0"),
            ] {
                if hi_um <= lo_um {
                    return Err(cx.err(
                        v.span(),
                        &field,
                        format_args!(
                            "{name} = {} mm must be above {lo_name} = {} mm: a rectangle is \
                             [x0, y0, x1, y1], lower left then upper right",
                            hi_um as f64 / 1000.0,
                            lo_um as f64 / 1000.0
                        ),
                    ));
                }
            }
            // Never refused: the corners are ordered and on the plate.
            Polygon::rectangle(lo, hi).map_err(|e| cx.err(r.span(), &field, e))
        }
        (None, Some(p)) => {
            let field = format!("{prefix}.polygon_mm");
            spans.put(&field, p.span());
            let mut vertices: Vec<PointUm, MAX_VERTICES> = Vec::new();
            for (k, v) in p.get_ref().iter().enumerate() {
                let name = format!("{field}[{k}]");
                spans.put(&name, v.span());
                let at = point(cx, v, &name, plate)?;
                if vertices.push(at).is_err() {
                    return Err(cx.err(
                        v.span(),
                        &name,
                        GeometryError::VertexCount {
                            vertices: p.get_ref().len(),
                        },
                    ));
                }
            }
            // Fewer than 3 vertices, crossings, touches and zero-length sides: the
            // controller's checks, located by `locate`.
            Ok(Polygon { vertices })
        }
        (Some(_), Some(p)) => Err(cx.err(
            p.span(),
            &format!("{prefix}.polygon_mm"),
            "give `rect_mm` or `polygon_mm`, not both",
        )),
        (None, None) => Err(cx.err(
            w.span(),
            &format!("{prefix}.rect_mm"),
            "a window needs its outline: `rect_mm = [x0, y0, x1, y1]` or `polygon_mm = [[x, y], …]`",
        )),
    }
}

/// Exactly two numbers (`what` names them in the sentence).
fn pair<'a>(
    cx: &Ctx<'_>,
    v: &'a Numbers,
    field: &str,
    what: &str,
) -> Result<[&'a Spanned<f64>; 2], SceneFileError> {
    match v.get_ref().as_slice() {
        [a, b] => Ok([a, b]),
        other => Err(cx.err(
            v.span(),
            field,
            format_args!("this is {what} in mm: two numbers, not {}", other.len()),
        )),
    }
}

/// A point `[x, y]` on the plate, µm.
fn point(cx: &Ctx<'_>, v: &Numbers, field: &str, plate: Plate) -> Result<PointUm, SceneFileError> {
    let [x, y] = pair(cx, v, field, "a point [x, y]")?;
    Ok(PointUm::new(
        coordinate(cx, x, field, "x", plate.w)?,
        coordinate(cx, y, field, "y", plate.h)?,
    ))
}

/// One coordinate `axis` within 0 ..= `max_mm` (the plate), µm.
fn coordinate(
    cx: &Ctx<'_>,
    v: &Spanned<f64>,
    field: &str,
    axis: &str,
    max_mm: f64,
) -> Result<i32, SceneFileError> {
    let mm = *v.get_ref();
    if mm.is_nan() {
        return Err(cx.err(
            v.span(),
            field,
            format_args!(
                "{axis} = NaN is not a number: give mm from 0 to {max_mm} (`[screen] size_mm`)"
            ),
        ));
    }
    if !(0.0..=max_mm).contains(&mm) {
        let shown = if mm.is_finite() {
            format!("{mm} mm")
        } else {
            format!("{mm}")
        };
        return Err(cx.err(
            v.span(),
            field,
            format_args!(
                "{axis} = {shown} is outside the plate: 0 mm to {max_mm} mm (`[screen] size_mm`)"
            ),
        ));
    }
    // Within ±MAX_COORD_UM: the plate is at most that size.
    Ok((mm * 1000.0).round() as i32)
}

/// A window's or the background's texture: a region's kinds and keys, a grating with
/// `ridge_angle_deg` oriented across the plane. A position-phase or hybrid grating without a
/// direction is refused here, as the controller refuses it (only velocity synthesis, fed
/// |V|, needs none).
fn plane_texture(
    cx: &Ctx<'_>,
    prefix: &str,
    span: Range<usize>,
    spec: &RegionSpec,
    ridge_angle_deg: Option<&Spanned<f64>>,
    extent_mm: f64,
    duty_cap_percent: f64,
) -> Result<PlaneTexture, SceneFileError> {
    let field = format!("{prefix}.ridge_angle_deg");
    let texture = regions::texture(cx, prefix, span.clone(), spec, extent_mm, duty_cap_percent)?;
    match (texture, ridge_angle_deg) {
        (Texture::Grating(grating), Some(a)) => {
            let rad = cx.range(a, &field, -360.0, 360.0)?.to_radians();
            // A unit normal scaled to the plane's range: 1 µrad of resolution.
            let scale = crate::plane::grating::MAX_NORMAL_COMPONENT as f64;
            let normal = (
                (libm::cos(rad) * scale).round() as i32,
                (libm::sin(rad) * scale).round() as i32,
            );
            Ok(PlaneTexture::Oriented(OrientedGrating { grating, normal }))
        }
        (Texture::Grating(g), None) if g.render != GratingRender::VelocitySynthesis => {
            let render = match g.render {
                GratingRender::Hybrid => "hybrid",
                _ => "position",
            };
            Err(cx.err(
                span,
                &field,
                format_args!(
                    "a `{render}` grating in the plane needs `ridge_angle_deg`, the direction \
                     of its ridges' normal (degrees from +x towards +y); only `render = \
                     \"velocity\"` takes none"
                ),
            ))
        }
        (_, Some(a)) => Err(cx.err(
            a.span(),
            &field,
            format_args!(
                "`ridge_angle_deg` is not a field of kind `{}`",
                spec.kind.get_ref()
            ),
        )),
        (texture, None) => Ok(PlaneTexture::Plain(texture)),
    }
}

impl Spans {
    fn put(&mut self, name: &str, span: Range<usize>) {
        self.0.insert(name.to_string(), span);
    }

    /// A texture table's span and every texture key it writes.
    fn put_texture(
        &mut self,
        prefix: &str,
        span: Range<usize>,
        spec: &RegionSpec,
        ridge: Option<&Spanned<f64>>,
    ) {
        self.put(prefix, span);
        for (name, span) in spec.present() {
            self.put(&format!("{prefix}.{name}"), span);
        }
        if let Some(r) = ridge {
            self.put(&format!("{prefix}.ridge_angle_deg"), r.span());
        }
    }
}

impl Doc2d {
    /// Locates a refusal of the 2D controller at the value it is about, or its table when the
    /// file leaves that key to its default. The located field names the window (or the
    /// background), so the sentence is the inner error's where the controller prefixes it.
    fn locate(&self, cx: &Ctx<'_>, e: &Config2dError) -> SceneFileError {
        let (names, table) = self.fault_keys(e);
        let (span, field) = self.spans.find(&names, &table);
        match e {
            Config2dError::Texture { error, .. } => cx.err(span, &field, error),
            Config2dError::Burst { error, .. } => cx.err(span, &field, error),
            Config2dError::Oriented { error, .. } => cx.err(span, &field, error),
            Config2dError::Screen(ScreenError::Outline { error, .. }) => {
                cx.err(span, &field, error)
            }
            _ => cx.err(span, &field, e),
        }
    }

    /// The window that owns outline-edge `edge` (the sides of flagged outlines come first),
    /// or the free edge's index.
    fn edge_owner(&self, edge: usize) -> Result<usize, usize> {
        let mut first = 0;
        for &(window, sides) in &self.outlines {
            if edge < first + sides {
                return Ok(window);
            }
            first += sides;
        }
        Err(edge - first)
    }

    /// The keys a controller refusal is about, most telling first, and the table to fall
    /// back on.
    fn fault_keys(&self, e: &Config2dError) -> (StdVec<String>, String) {
        let one = |k: &str| std::vec![k.to_string()];
        let owner = |o: &Owner| match o {
            Owner::Window(i) => format!("window[{i}]"),
            Owner::Background => "screen.background".to_string(),
        };
        let under = |prefix: String, keys: &[&str]| {
            (
                keys.iter().map(|k| format!("{prefix}.{k}")).collect(),
                prefix,
            )
        };
        let outline = |w: usize, vertex: Option<usize>| {
            let p = format!("window[{w}]");
            let mut keys = StdVec::new();
            if let Some(v) = vertex {
                keys.push(format!("{p}.polygon_mm[{v}]"));
            }
            keys.push(format!("{p}.polygon_mm"));
            keys.push(format!("{p}.rect_mm"));
            (keys, p)
        };
        match e {
            Config2dError::Screen(s) => match *s {
                ScreenError::Outline { window, error } => {
                    let vertex = match error {
                        GeometryError::OutOfRange { vertex, .. } => Some(vertex as usize),
                        // The repeated vertex: the edge's end, or its start for the closing
                        // edge.
                        GeometryError::ZeroLengthEdge { edge, .. } => {
                            let n = self
                                .config
                                .scene
                                .windows
                                .get(window as usize)
                                .map_or(0, |w| w.outline.vertices.len());
                            Some(if (edge as usize) + 1 < n {
                                edge as usize + 1
                            } else {
                                edge as usize
                            })
                        }
                        // The later edge's first vertex.
                        GeometryError::SelfIntersecting { other, .. } => Some(other as usize),
                        _ => None,
                    };
                    outline(window as usize, vertex)
                }
                ScreenError::TooSmall { window, .. } => outline(window as usize, None),
                ScreenError::Band { .. } => (one("screen.band_mm"), "screen".into()),
                _ => (StdVec::new(), "(file)".into()),
            },
            Config2dError::Edges(EdgeError::Segment { edge, .. }) => {
                match self.edge_owner(*edge as usize) {
                    Ok(w) => outline(w, None),
                    Err(j) => (
                        std::vec![format!("edge[{j}].to_mm"), format!("edge[{j}].from_mm")],
                        format!("edge[{j}]"),
                    ),
                }
            }
            Config2dError::Edges(EdgeError::Pulse { .. }) | Config2dError::EdgePulse(_) => {
                (one("edges.pulse_ms"), "edges".into())
            }
            Config2dError::Edges(EdgeError::Amplitude { .. }) | Config2dError::EdgeLevel { .. } => {
                (one("edges.amplitude_percent"), "edges".into())
            }
            Config2dError::Edges(EdgeError::Rearm { .. }) => {
                (one("edges.rearm_mm"), "edges".into())
            }
            Config2dError::Edges(_) => (StdVec::new(), "(file)".into()),
            Config2dError::Limits(b) => {
                let key = match b {
                    BurstError::NoOnTime { .. } => "limits.max_on_time_ms",
                    _ => "limits.max_duty_percent",
                };
                (one(key), "limits".into())
            }
            Config2dError::StaleLimit { .. } => (one("limits.stale_after_ms"), "limits".into()),
            Config2dError::Texture { owner: o, error } => under(owner(o), texture_keys(error)),
            Config2dError::Burst { owner: o, error } => under(owner(o), burst_keys(error)),
            Config2dError::Oriented {
                owner: o,
                error: OrientedError::Texture(t),
            } => under(owner(o), texture_keys(t)),
            Config2dError::Oriented {
                owner: o,
                error: OrientedError::Burst(b),
            } => under(owner(o), burst_keys(b)),
            Config2dError::Oriented { owner: o, .. }
            | Config2dError::GratingNeedsNormal { owner: o } => {
                under(owner(o), &["ridge_angle_deg"])
            }
            _ => (StdVec::new(), "(file)".into()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{load_2d_for_board, load_for_board, sensor_of, SceneFileError, SensorKind};
    use crate::burst::{BurstCommand, BurstTimer};
    use crate::plane::{OrientedGrating, PlaneTexture, PointUm, Polygon, SegmentUm};
    use crate::texture::{Grating, GratingRender, Texture};
    use std::format;
    use std::string::{String, ToString};

    const TIMER: BurstTimer = crate::burst::TEST_TIMER;
    /// The F446's touch frame period at its tested 2 889 Hz (docs/touch.md), µs.
    const FRAME_US: u32 = 346;
    const FIG12: &str = include_str!("../../../scenes/2d-fig12.toml");

    fn load(text: &str) -> Result<crate::plane::Config2d, SceneFileError> {
        load_2d_for_board("bad.toml", text, TIMER, FRAME_US)
    }

    /// Lines 1–5; what a case appends starts on line 6.
    const HEAD: &str = "[sensor]\nkind = \"4-wire\"\n\n[screen]\nsize_mm = [95, 54]\n";

    fn rect(r: &str, rest: &str) -> String {
        format!("[[window]]\nrect_mm = {r}\nkind = \"constant\"\nf_b_hz = 80\n{rest}")
    }

    #[test]
    fn sensor_is_read_from_the_sensor_table_only() {
        assert_eq!(sensor_of("a.toml", FIG12), Ok(SensorKind::FourWire));
        // A 1D file, even one its reader refuses, is 1D: the 1D reader says what is wrong.
        let one_d = "[[region]]\nkind = \"off\"\ncolour = 3\n";
        assert_eq!(sensor_of("a.toml", one_d), Ok(SensorKind::Rheostat));
        let e = sensor_of("a.toml", "[sensor]\nkind = \"5-wire\"\n").unwrap_err();
        assert_eq!((e.line, e.column, e.field.as_str()), (2, 8, "sensor.kind"));
        assert_eq!(
            e.message,
            "unknown sensor `5-wire`: it must be `4-wire` (the touch overlay: a 2D scene); a 1D \
             scene for the slide rheostat has no [sensor] table"
        );
        let e = sensor_of("a.toml", "[sensor]\nkinf = \"4-wire\"\n").unwrap_err();
        assert_eq!(
            (e.line, e.message.as_str()),
            (2, "unknown key `kinf`: did you mean `kind`?")
        );
    }

    /// fig. 12's screen read into exactly the configuration built here by hand from the file's
    /// numbers (mm → µm, 45° → the normal (cos, sin) × 10⁶ rounded).
    #[test]
    fn fig12_reads_as_built_by_hand() {
        let cfg = load_2d_for_board("2d-fig12.toml", FIG12, TIMER, FRAME_US).unwrap();
        let r = |x0, y0, x1, y1| {
            Polygon::rectangle(PointUm::new(x0, y0), PointUm::new(x1, y1)).unwrap()
        };
        let constant = |hz: u32| {
            PlaneTexture::Plain(Texture::Constant(BurstCommand {
                burst_millihz: hz * 1000,
                duty_permille: 400,
            }))
        };
        let s = &cfg.scene;
        assert_eq!(s.windows.len(), 3);
        assert_eq!(s.windows[0].outline, r(5_000, 5_000, 30_000, 49_000));
        assert_eq!(s.windows[1].outline, r(35_000, 5_000, 60_000, 49_000));
        assert_eq!(s.windows[2].outline, r(65_000, 5_000, 90_000, 49_000));
        assert_eq!(s.windows[0].texture, constant(20));
        assert_eq!(s.windows[1].texture, constant(80));
        assert_eq!(
            s.windows[2].texture,
            PlaneTexture::Oriented(OrientedGrating {
                grating: Grating::new(1_000),
                normal: (707_107, 707_107),
            })
        );
        assert!(s.windows.iter().all(|w| w.edge));
        assert_eq!(s.background, constant(1000));
        assert_eq!(s.band_um, 200);
        assert!(s.free_edges.is_empty());
        assert_eq!(s.edge_pulse, crate::plane::EdgePulse::default());
        assert_eq!(s.rearm_um, 100);
        assert_eq!(cfg.limits, crate::burst::SafetyLimits::default());
        assert_eq!(cfg.stale_after_us, 5_000);
    }

    #[test]
    fn concave_scene_reads_its_polygons_edges_and_velocity_grating() {
        let text = include_str!("../../../scenes/2d-concave.toml");
        let cfg = load_2d_for_board("2d-concave.toml", text, TIMER, FRAME_US).unwrap();
        let s = &cfg.scene;
        let l: std::vec::Vec<(i32, i32)> = s.windows[1]
            .outline
            .vertices
            .iter()
            .map(|p| (p.x_um, p.y_um))
            .collect();
        assert_eq!(
            l,
            [
                (5_000, 5_000),
                (75_000, 5_000),
                (75_000, 30_000),
                (45_000, 30_000),
                (45_000, 22_000),
                (5_000, 22_000)
            ]
        );
        assert_eq!(
            (s.windows[0].edge, s.windows[1].edge, s.windows[2].edge),
            (false, true, false)
        );
        let Texture::Grating(g) = (match s.windows[2].texture {
            PlaneTexture::Plain(t) => t,
            other => panic!("{other:?}"),
        }) else {
            panic!("{:?}", s.windows[2].texture)
        };
        assert_eq!(
            (g.wavelength_um, g.render),
            (2_000, GratingRender::VelocitySynthesis)
        );
        assert_eq!(
            s.free_edges.as_slice(),
            [
                SegmentUm {
                    a: PointUm::new(50_000, 40_000),
                    b: PointUm::new(75_000, 40_000)
                },
                SegmentUm {
                    a: PointUm::new(50_000, 45_000),
                    b: PointUm::new(75_000, 55_000)
                }
            ]
        );
        assert_eq!(
            (
                s.edge_pulse.pulse_us,
                s.edge_pulse.envelope,
                s.edge_pulse.amplitude_permille,
                s.rearm_um
            ),
            (8_000, crate::texture::Envelope::Rectangular, 800, 200)
        );
        assert_eq!(s.background, PlaneTexture::Plain(Texture::Off));
    }

    /// The angle is the normal's direction, counter-clockwise from +x (hand-worked:
    /// 0° → (1, 0), 90° → (0, 1), −30° → (cos 30°, −sin 30°) = (866 025, −500 000)).
    #[test]
    fn ridge_angle_is_the_normals_direction() {
        for (deg, normal) in [
            ("0", (1_000_000, 0)),
            ("90", (0, 1_000_000)),
            ("-30", (866_025, -500_000)),
        ] {
            let text = format!(
                "{HEAD}[[window]]\nrect_mm = [5, 5, 30, 30]\nkind = \"grating\"\n\
                 wavelength_mm = 1\nridge_angle_deg = {deg}\n"
            );
            match load(&text).unwrap().scene.windows[0].texture {
                PlaneTexture::Oriented(o) => assert_eq!(o.normal, normal, "{deg}"),
                other => panic!("{other:?}"),
            }
        }
    }

    /// Each malformed file refused at the line, field and sentence named (lines by hand from
    /// [`HEAD`]: its own five, then the case's). The cases the controller finds (marked
    /// "dry run") are located by `Doc2d::locate`: without it they point at line 1, `(file)`.
    #[test]
    fn malformed_files_are_refused_at_their_value() {
        let w = |r: &str| rect(r, "");
        let many_windows: String = (0..9)
            .map(|k| w(&format!("[{}, 5, {}, 10]", 1 + 10 * k, 6 + 10 * k)))
            .collect();
        let outlined: String = (0..8)
            .map(|k| {
                rect(
                    &format!("[{}, 5, {}, 10]", 1 + 10 * k, 6 + 10 * k),
                    "outline = true\n",
                )
            })
            .collect();
        let pentagon = |k: i32| {
            let x = 1 + 13 * k;
            format!(
                "[[window]]\npolygon_mm = [[{x}, 5], [{}, 5], [{}, 9], [{}, 12], [{x}, 9]]\n\
                 kind = \"off\"\noutline = true\n",
                x + 10,
                x + 10,
                x + 5
            )
        };
        let pentagons: String = (0..7).map(pentagon).collect();
        let cases: &[(String, usize, &str, &str)] = &[
            (
                format!("{HEAD}{}", rect("[5, 5, 30, 30]", "f_b_hx = 3\n")),
                10,
                "window[0].f_b_hx",
                "unknown key `f_b_hx`: did you mean `f_b_hz`?",
            ),
            (
                format!("{HEAD}bnad_mm = 0.2\n"),
                6,
                "screen.bnad_mm",
                "unknown key `bnad_mm`: did you mean `band_mm`?",
            ),
            (
                format!("{HEAD}colour = 1\n"),
                6,
                "screen.colour",
                "unknown key `colour`: [screen] takes `size_mm`, `band_mm` and `background`",
            ),
            (
                format!("{HEAD}{}", rect("[5, 5, 30, 30]", "colour = 1\n")),
                10,
                "window[0].colour",
                "unknown key `colour`: a window takes `rect_mm` or `polygon_mm`, `outline`, \
                 `kind`, its kind's keys as a region's and, for a grating, `ridge_angle_deg` \
                 (docs/scenes.md)",
            ),
            (
                format!("{HEAD}{}", rect("[5, 5, 30, 30]", "wavelength_mm = 1\n")),
                10,
                "window[0].wavelength_mm",
                "`wavelength_mm` is not a field of kind `constant`",
            ),
            // Dry run: the bow tie's edges 0 and 2 cross; at vertex 2, where edge 2 starts.
            (
                format!(
                    "{HEAD}[[window]]\npolygon_mm = [[5, 5], [30, 30], [30, 5], [5, 30]]\n\
                     kind = \"off\"\n"
                ),
                7,
                "window[0].polygon_mm[2]",
                "edges 0 and 2 meet: a polygon's outline must not cross, touch or fold back on \
                 itself (concave is allowed)",
            ),
            // Dry run: a vertex repeated, at the repeat.
            (
                format!(
                    "{HEAD}[[window]]\npolygon_mm = [[5, 5], [30, 5], [30, 5], [5, 30]]\n\
                     kind = \"off\"\n"
                ),
                7,
                "window[0].polygon_mm[2]",
                "edge 1 has zero length: its two vertices are both at (30 mm, 5 mm)",
            ),
            // Dry run.
            (
                format!("{HEAD}[[window]]\npolygon_mm = [[5, 5], [30, 5]]\nkind = \"off\"\n"),
                7,
                "window[0].polygon_mm",
                "a polygon has 2 vertices and needs 3 to 16",
            ),
            (
                format!(
                    "{HEAD}[[window]]\npolygon_mm = [{}]\nkind = \"off\"\n",
                    (0..17)
                        .map(|k| format!("[{}, {}]", 5 + k, 5 + (k * k) % 7))
                        .collect::<std::vec::Vec<_>>()
                        .join(", ")
                ),
                7,
                "window[0].polygon_mm[16]",
                "a polygon has 17 vertices and needs 3 to 16",
            ),
            (
                format!("{HEAD}{}", w("[5, 5, 100, 30]")),
                7,
                "window[0].rect_mm",
                "x1 = 100 mm is outside the plate: 0 mm to 95 mm (`[screen] size_mm`)",
            ),
            (
                format!("{HEAD}{}", w("[5, 5, nan, 30]")),
                7,
                "window[0].rect_mm",
                "x1 = NaN is not a number: give mm from 0 to 95 (`[screen] size_mm`)",
            ),
            (
                format!(
                    "{HEAD}[[window]]\npolygon_mm = [[5, 5], [30, 5], [30, -1]]\nkind = \"off\"\n"
                ),
                7,
                "window[0].polygon_mm[2]",
                "y = -1 mm is outside the plate: 0 mm to 54 mm (`[screen] size_mm`)",
            ),
            (
                format!("{HEAD}{}", w("[30, 5, 5, 30]")),
                7,
                "window[0].rect_mm",
                "x1 = 5 mm must be above x0 = 30 mm: a rectangle is [x0, y0, x1, y1], lower \
                 left then upper right",
            ),
            (
                format!("{HEAD}[[edge]]\nfrom_mm = [5, 45]\nto_mm = [5, 45]\n"),
                8,
                "edge[0].to_mm",
                "the edge ends where it starts, at (5 mm, 45 mm): it has zero length",
            ),
            (
                format!(
                    "{HEAD}{}",
                    rect("[5, 5, 30, 30]", "ridge_angle_deg = 30\n")
                        .replace("constant", "grating")
                        .replace("f_b_hz = 80", "wavelength_mm = 1")
                        .replace("30\n", "400\n")
                ),
                10,
                "window[0].ridge_angle_deg",
                "400 is outside the allowed -360 to 360",
            ),
            (
                format!(
                    "{HEAD}[[window]]\nrect_mm = [5, 5, 30, 30]\nkind = \"grating\"\n\
                     wavelength_mm = 1\nridge_angle_deg = nan\n"
                ),
                10,
                "window[0].ridge_angle_deg",
                "NaN is not a number; it must be from -360 to 360",
            ),
            (
                format!(
                    "{HEAD}[[window]]\nrect_mm = [5, 5, 30, 30]\nkind = \"grating\"\n\
                     wavelength_mm = 1\n"
                ),
                6,
                "window[0].ridge_angle_deg",
                "a `position` grating in the plane needs `ridge_angle_deg`, the direction of \
                 its ridges' normal (degrees from +x towards +y); only `render = \"velocity\"` \
                 takes none",
            ),
            (
                format!(
                    "{HEAD}background = {{ kind = \"grating\", wavelength_mm = 1, render = \
                     \"hybrid\" }}\n"
                ),
                6,
                "screen.background.ridge_angle_deg",
                "a `hybrid` grating in the plane needs `ridge_angle_deg`, the direction of its \
                 ridges' normal (degrees from +x towards +y); only `render = \"velocity\"` \
                 takes none",
            ),
            (
                format!("{HEAD}{}", rect("[5, 5, 30, 30]", "ridge_angle_deg = 30\n")),
                10,
                "window[0].ridge_angle_deg",
                "`ridge_angle_deg` is not a field of kind `constant`",
            ),
            (
                format!("{HEAD}{many_windows}"),
                38,
                "window",
                "more than 8 windows",
            ),
            // 8 outlined rectangles are the 32 edges a screen may draw: one more is refused.
            (
                format!("{HEAD}{outlined}[[edge]]\nfrom_mm = [5, 45]\nto_mm = [75, 45]\n"),
                46,
                "edge",
                "33 edges are more than the 32 a screen may draw (each side of a window with \
                 `outline = true` is one, then each [[edge]])",
            ),
            // 7 pentagons: the seventh brings the sides to 35.
            (
                format!("{HEAD}{pentagons}"),
                33,
                "window[6].outline",
                "35 edges are more than the 32 a screen may draw (each side of a window with \
                 `outline = true` is one, then each [[edge]])",
            ),
            // Dry run: the board's f_b limit, at the value.
            (
                format!("{HEAD}{}", w("[5, 5, 30, 30]").replace("= 80", "= 9000")),
                9,
                "window[0].f_b_hz",
                "f_b 9000 Hz is above this board's limit of 5000 Hz",
            ),
            // Dry run: a window not wider than the band.
            (
                format!("{HEAD}band_mm = 2\n{}", w("[5, 5, 6, 30]")),
                8,
                "window[0].rect_mm",
                "window 0 is 1 mm across, not wider than the band (2 mm): it could never be \
                 entered",
            ),
            // Dry run: the edge pulse above the level cap.
            (
                format!(
                    "[limits]\nmax_level_percent = 50\n{HEAD}{}[edges]\namplitude_percent = 80\n",
                    rect("[5, 5, 30, 30]", "outline = true\n")
                ),
                14,
                "edges.amplitude_percent",
                "edge amplitude 80 % is above the level cap of 50 %",
            ),
            // Dry run: stale after less than two frames.
            (
                format!("[limits]\nstale_after_ms = 0.5\n{HEAD}"),
                2,
                "limits.stale_after_ms",
                "stale limit 0.5 ms must be at least two sample periods (0.692 ms) and at most \
                 1000 ms",
            ),
            (
                "[sensor]\nkind = \"4-wire\"\n".to_string(),
                1,
                "screen",
                "a 2D scene needs [screen] with `size_mm = [width, height]`, the plate's touch \
                 area",
            ),
            (
                "[[region]]\nkind = \"off\"\n".to_string(),
                1,
                "sensor",
                "this is a 1D scene for the slide rheostat (it has no [sensor] table); a 2D \
                 scene names its sensor: [sensor] kind = \"4-wire\"",
            ),
        ];
        for (text, line, field, message) in cases {
            let e = load(text).unwrap_err();
            assert_eq!(
                (e.line, e.field.as_str(), e.message.as_str()),
                (*line, *field, *message),
                "{e}\n{text}"
            );
            assert!(
                e.to_string().starts_with(&format!("bad.toml:{line}:")),
                "{e}"
            );
        }
    }

    /// A 2D file given to the 1D reader is refused at its sensor, whatever else it holds.
    #[test]
    fn the_1d_reader_refuses_a_2d_scene() {
        let e = load_for_board("2d-fig12.toml", FIG12, TIMER, 100).unwrap_err();
        assert_eq!(
            (e.line, e.column, e.field.as_str()),
            (7, 8, "sensor.kind"),
            "{e}"
        );
        assert_eq!(
            e.message,
            "this is a 2D scene for the 4-wire touch sensor; a board with the slide rheostat \
             reads only 1D scenes (no [sensor] table)"
        );
        let e = super::super::parse("x.toml", FIG12).unwrap_err();
        assert_eq!(e.field, "sensor.kind");
    }

    /// Column precision of a located dry-run refusal: at the value, not its line's start.
    #[test]
    fn a_dry_run_refusal_points_at_the_vertex() {
        let text = format!(
            "{HEAD}[[window]]\npolygon_mm = [[5, 5], [30, 30], [30, 5], [5, 30]]\nkind = \"off\"\n"
        );
        let e = load(&text).unwrap_err();
        // `polygon_mm = [[5, 5], [30, 30], [30, 5]`: 14 + 8 + 10 characters before the third
        // point, which opens at column 33.
        assert_eq!((e.line, e.column), (7, 33), "{e}");
    }

    /// docs/scenes.md's 2D tables list exactly the keys the parser's 2D structs take (read from
    /// the structs, `keys`), a window and the background besides taking every region key but
    /// `until_mm`. Fails on a key added to a struct and not to the doc, or the other way.
    #[test]
    fn the_2d_reference_lists_the_parsers_keys() {
        use std::collections::BTreeSet;
        const DOC: &str = include_str!("../../../docs/scenes.md");
        let doc_keys = |name: &str| -> BTreeSet<String> {
            let marker = format!("<!-- keys: {name} -->");
            let start = DOC.find(&marker).unwrap_or_else(|| panic!("no `{marker}`"));
            DOC[start + marker.len()..]
                .lines()
                .skip(1)
                .take_while(|l| l.starts_with('|'))
                .filter_map(|l| {
                    let cell = l.trim_start_matches('|').split('|').next()?.trim();
                    cell.strip_prefix('`')?
                        .strip_suffix('`')
                        .map(str::to_string)
                })
                .collect()
        };
        let parser = |name: &str| -> BTreeSet<String> {
            super::super::keys(name)
                .unwrap()
                .iter()
                .map(|k| k.to_string())
                .collect()
        };
        let texture: BTreeSet<String> = parser("region")
            .into_iter()
            .filter(|k| k != "until_mm")
            .collect();
        for name in super::super::TABLES_2D {
            let mut doc = doc_keys(name);
            if name == "2d.window" || name == "2d.background" {
                doc.extend(texture.iter().cloned());
            }
            assert_eq!(
                doc,
                parser(name),
                "docs/scenes.md `{name}` (left) vs the parser"
            );
        }
    }

    /// The documented ranges of the 2D keys: both ends accepted, just outside refused at the
    /// field (the docs' numbers, typed here from docs/scenes.md).
    #[test]
    fn documented_2d_ranges_hold_at_their_ends() {
        let win = "[[window]]\nrect_mm = [5, 5, 30, 30]\nkind = \"grating\"\nwavelength_mm = 1\n";
        let cases: &[(&str, &str, f64, f64)] = &[
            ("screen.band_mm", "band_mm = {}\n", 0.001, 10.0),
            (
                "window[0].ridge_angle_deg",
                "ridge_angle_deg = {}\n",
                -360.0,
                360.0,
            ),
            ("edges.pulse_ms", "[edges]\npulse_ms = {}\n", 0.001, 1000.0),
            (
                "edges.amplitude_percent",
                "[edges]\namplitude_percent = {}\n",
                0.1,
                100.0,
            ),
            ("edges.rearm_mm", "[edges]\nrearm_mm = {}\n", 0.001, 5.0),
        ];
        for &(field, line, lo, hi) in cases {
            let text = |v: f64| {
                let line = line.replace("{}", &format!("{v:?}"));
                // The window after `[screen]`'s keys, `[edges]` after the window; the on-time
                // cap raised so the pulse's range is the reader's own.
                let limits = "[limits]\nmax_on_time_ms = 1000\n";
                match field {
                    "screen.band_mm" => format!("{limits}{HEAD}{line}{win}ridge_angle_deg = 0\n"),
                    "window[0].ridge_angle_deg" => format!("{limits}{HEAD}{win}{line}"),
                    _ => format!("{limits}{HEAD}{win}ridge_angle_deg = 0\noutline = true\n{line}"),
                }
            };
            for v in [lo, hi] {
                assert!(
                    load(&text(v)).is_ok(),
                    "{field} = {v}: {:?}",
                    load(&text(v))
                );
            }
            let step = |x: f64| if x.abs() >= 1.0 { x.abs() * 1e-3 } else { 1e-4 };
            for v in [lo - step(lo).min(lo.abs() / 2.0).max(1e-4), hi + step(hi)] {
                let e = load(&text(v)).unwrap_err();
                assert_eq!(e.field, field, "{field} = {v}: {e}");
            }
        }
        // `size_mm`: 1 to 1000 mm each side.
        for (size, ok) in [
            ("[1, 1000]", true),
            ("[0.999, 54]", false),
            ("[95, 1000.1]", false),
        ] {
            let text = format!("[sensor]\nkind = \"4-wire\"\n[screen]\nsize_mm = {size}\n");
            let r = load(&text);
            assert_eq!(r.is_ok(), ok, "{size}: {r:?}");
            if let Err(e) = r {
                assert_eq!(e.field, "screen.size_mm", "{e}");
            }
        }
    }

    /// No input panics the 2D loader, `sensor_of` or the 1D loader, and every refusal is one
    /// line naming the file: the shipped 2D files with bytes replaced, deleted and lines
    /// swapped (seeded, 3 000 mutants each), and values replaced by extremes.
    #[test]
    fn mutated_2d_files_are_refused_with_a_sentence_never_a_panic() {
        use rand_core::{Rng, SeedableRng};
        let files = [FIG12, include_str!("../../../scenes/2d-concave.toml")];
        let extremes = [
            "-1e308",
            "1e308",
            "nan",
            "-inf",
            "0",
            "-0",
            "4294967296",
            "[]",
            "\"x\"",
        ];
        let mut rng = rand_pcg::Pcg32::seed_from_u64(36);
        let (mut accepted, mut refused) = (0, 0);
        for text in files {
            let numbers: std::vec::Vec<usize> = text
                .char_indices()
                .filter(|(i, c)| {
                    c.is_ascii_digit() && !text[..*i].ends_with(|p: char| p.is_ascii_digit())
                })
                .map(|(i, _)| i)
                .collect();
            for _ in 0..3_000 {
                let mut t = text.to_string().into_bytes();
                match rng.next_u32() % 4 {
                    0 => {
                        let at = rng.next_u32() as usize % t.len();
                        let table = b" =[],.\"-0123456789abcxyz\n";
                        t[at] = table[rng.next_u32() as usize % table.len()];
                    }
                    1 => {
                        let at = rng.next_u32() as usize % t.len();
                        t.remove(at);
                    }
                    2 => {
                        let mut lines: std::vec::Vec<&[u8]> = t.split(|b| *b == b'\n').collect();
                        let (a, b) = (
                            rng.next_u32() as usize % lines.len(),
                            rng.next_u32() as usize % lines.len(),
                        );
                        lines.swap(a, b);
                        t = lines.join(&b'\n');
                    }
                    _ => {
                        // A number replaced by an extreme value.
                        let at = numbers[rng.next_u32() as usize % numbers.len()];
                        let end = text[at..]
                            .find(|c: char| !(c.is_ascii_digit() || c == '.'))
                            .map_or(text.len(), |n| at + n);
                        let x = extremes[rng.next_u32() as usize % extremes.len()];
                        t = format!("{}{x}{}", &text[..at], &text[end..]).into_bytes();
                    }
                }
                let Ok(t) = std::string::String::from_utf8(t) else {
                    continue;
                };
                let _ = sensor_of("m.toml", &t);
                if let Err(e) = load_for_board("m.toml", &t, TIMER, 100) {
                    assert!(
                        e.to_string().starts_with("m.toml:") && !e.to_string().contains('\n'),
                        "{e}"
                    );
                }
                match load_2d_for_board("m.toml", &t, TIMER, FRAME_US) {
                    Ok(_) => accepted += 1,
                    Err(e) => {
                        let line = e.to_string();
                        assert!(line.starts_with("m.toml:"), "{line}");
                        assert!(!e.field.is_empty() && !e.message.is_empty(), "{line}");
                        refused += 1;
                    }
                }
            }
        }
        std::println!("{accepted} accepted, {refused} refused");
        // Both outcomes are met: the mutants reach past the TOML syntax into the checks.
        assert!(
            accepted > 100 && refused > 1_000,
            "{accepted} accepted, {refused} refused"
        );
    }
}
