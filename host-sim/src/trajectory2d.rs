//! Finger paths on a 2D screen (issue #36): position (µm) and true velocity (µm/s) as functions of
//! time, beside the 1D [`crate::trajectory`].
//!
//! Every path but the circle ends: after its end the finger rests where it stopped, so a run of any
//! duration is defined. Paths are not clamped to the screen: a path that leaves it is the caller's
//! choice, and the touch-sensor model decides what such a finger reads.

use std::fmt;

/// A point on the screen, µm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointUm {
    /// x, µm.
    pub x_um: f64,
    /// y, µm.
    pub y_um: f64,
}

impl PointUm {
    /// The point (`x_um`, `y_um`).
    pub fn new(x_um: f64, y_um: f64) -> Self {
        Self { x_um, y_um }
    }

    fn distance_um(self, other: PointUm) -> f64 {
        (other.x_um - self.x_um).hypot(other.y_um - self.y_um)
    }
}

/// Position and velocity at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct State2d {
    /// x, µm.
    pub x_um: f64,
    /// y, µm.
    pub y_um: f64,
    /// x velocity, µm/s.
    pub vx_um_s: f64,
    /// y velocity, µm/s.
    pub vy_um_s: f64,
}

impl State2d {
    fn at_rest(p: PointUm) -> Self {
        Self {
            x_um: p.x_um,
            y_um: p.y_um,
            vx_um_s: 0.0,
            vy_um_s: 0.0,
        }
    }

    /// Speed, µm/s.
    pub fn speed_um_s(&self) -> f64 {
        self.vx_um_s.hypot(self.vy_um_s)
    }
}

/// A 2D finger motion; time starts at 0 at its beginning. Build one with the checked
/// constructors ([`Trajectory2d::line`] and the others), which refuse what has no motion.
#[derive(Clone, Debug, PartialEq)]
pub enum Trajectory2d {
    /// At rest at `at`.
    Rest {
        /// Where, µm.
        at: PointUm,
    },
    /// A straight stroke from `from` to `to` at constant speed, then rest at `to`.
    Line {
        /// Start, µm.
        from: PointUm,
        /// End, µm.
        to: PointUm,
        /// Speed, µm/s (> 0).
        speed_um_s: f64,
    },
    /// Round a circle at constant speed, counter-clockwise from (cx + r, cy), for ever.
    Circle {
        /// Centre, µm.
        center: PointUm,
        /// Radius, µm (> 0).
        radius_um: f64,
        /// Speed along the circle, µm/s (> 0).
        speed_um_s: f64,
    },
    /// An Archimedean spiral r(θ) = r0 + b·θ, counter-clockwise from (cx + r0, cy) out to `r1_um`
    /// over `turns` turns at constant speed along it, then rest.
    Spiral {
        /// Centre, µm.
        center: PointUm,
        /// Start radius, µm (≥ 0).
        r0_um: f64,
        /// End radius, µm (> r0).
        r1_um: f64,
        /// Turns from r0 to r1 (> 0).
        turns: f64,
        /// Speed along the spiral, µm/s (> 0).
        speed_um_s: f64,
    },
    /// A raster (boustrophedon) over the rectangle from `corner_a` to `corner_b`: `rows` rows
    /// along x, evenly spaced in y from a's y to b's y, joined by steps along y at the same
    /// speed, then rest.
    Raster {
        /// First corner (the start), µm.
        corner_a: PointUm,
        /// Opposite corner, µm.
        corner_b: PointUm,
        /// Rows (≥ 2).
        rows: u32,
        /// Speed, µm/s (> 0).
        speed_um_s: f64,
    },
    /// Straight lines between timed points (from a CSV file: `t_s,x_mm,y_mm`), then rest at the
    /// last.
    Path {
        /// (t, s; point, µm), times strictly increasing from the first.
        points: Vec<(f64, PointUm)>,
    },
}

/// Why a 2D trajectory was refused.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum TrajectoryError {
    /// A value outside its range (or not finite).
    Value {
        /// The field or flag.
        field: &'static str,
        /// The value given.
        value: f64,
        /// The rule it breaks.
        rule: &'static str,
    },
    /// A line of a path file that cannot be read.
    PathLine {
        /// 1-based line number in the file (the header is line 1).
        line: u64,
        /// What is wrong with it.
        why: String,
    },
    /// A path with too few points or no motion.
    Path(String),
}

impl fmt::Display for TrajectoryError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TrajectoryError::Value { field, value, rule } => {
                write!(f, "{field} = {value} is refused: it must be {rule}")
            }
            TrajectoryError::PathLine { line, why } => write!(f, "path line {line}: {why}"),
            TrajectoryError::Path(why) => write!(f, "path: {why}"),
        }
    }
}

impl std::error::Error for TrajectoryError {}

fn finite(field: &'static str, value: f64) -> Result<f64, TrajectoryError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(TrajectoryError::Value {
            field,
            value,
            rule: "a finite number",
        })
    }
}

fn positive(field: &'static str, value: f64) -> Result<f64, TrajectoryError> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(TrajectoryError::Value {
            field,
            value,
            rule: "a finite number above 0",
        })
    }
}

fn point(
    field_x: &'static str,
    field_y: &'static str,
    p: PointUm,
) -> Result<PointUm, TrajectoryError> {
    Ok(PointUm::new(
        finite(field_x, p.x_um)?,
        finite(field_y, p.y_um)?,
    ))
}

impl Trajectory2d {
    /// A finger resting at `at`.
    pub fn rest(at: PointUm) -> Result<Self, TrajectoryError> {
        Ok(Trajectory2d::Rest {
            at: point("at x_um", "at y_um", at)?,
        })
    }

    /// A straight stroke from `from` to `to` at `speed_um_s`; the two points must differ.
    pub fn line(from: PointUm, to: PointUm, speed_um_s: f64) -> Result<Self, TrajectoryError> {
        let from = point("from x_um", "from y_um", from)?;
        let to = point("to x_um", "to y_um", to)?;
        let speed_um_s = positive("speed_um_s", speed_um_s)?;
        let length_um = from.distance_um(to);
        if !(length_um > 0.0) {
            return Err(TrajectoryError::Value {
                field: "stroke length_um",
                value: length_um,
                rule: "above 0 (the start and end points must differ)",
            });
        }
        Ok(Trajectory2d::Line {
            from,
            to,
            speed_um_s,
        })
    }

    /// Round a circle for ever.
    pub fn circle(
        center: PointUm,
        radius_um: f64,
        speed_um_s: f64,
    ) -> Result<Self, TrajectoryError> {
        Ok(Trajectory2d::Circle {
            center: point("center x_um", "center y_um", center)?,
            radius_um: positive("radius_um", radius_um)?,
            speed_um_s: positive("speed_um_s", speed_um_s)?,
        })
    }

    /// An Archimedean spiral out from `r0_um` to `r1_um` in `turns` turns.
    pub fn spiral(
        center: PointUm,
        r0_um: f64,
        r1_um: f64,
        turns: f64,
        speed_um_s: f64,
    ) -> Result<Self, TrajectoryError> {
        let r0_um = finite("r0_um", r0_um)?;
        if r0_um < 0.0 {
            return Err(TrajectoryError::Value {
                field: "r0_um",
                value: r0_um,
                rule: "0 or more",
            });
        }
        let r1_um = finite("r1_um", r1_um)?;
        if !(r1_um > r0_um) {
            return Err(TrajectoryError::Value {
                field: "r1_um",
                value: r1_um,
                rule: "above r0_um (the spiral goes outwards)",
            });
        }
        Ok(Trajectory2d::Spiral {
            center: point("center x_um", "center y_um", center)?,
            r0_um,
            r1_um,
            turns: positive("turns", turns)?,
            speed_um_s: positive("speed_um_s", speed_um_s)?,
        })
    }

    /// A raster over the rectangle between two corners; they must differ in x.
    pub fn raster(
        corner_a: PointUm,
        corner_b: PointUm,
        rows: u32,
        speed_um_s: f64,
    ) -> Result<Self, TrajectoryError> {
        let corner_a = point("corner_a x_um", "corner_a y_um", corner_a)?;
        let corner_b = point("corner_b x_um", "corner_b y_um", corner_b)?;
        if corner_a.x_um == corner_b.x_um {
            return Err(TrajectoryError::Value {
                field: "corner_b x_um",
                value: corner_b.x_um,
                rule: "different from corner_a's x (the rows have no length)",
            });
        }
        if corner_a.y_um == corner_b.y_um {
            return Err(TrajectoryError::Value {
                field: "corner_b y_um",
                value: corner_b.y_um,
                rule: "different from corner_a's y (the rows would lie on one another)",
            });
        }
        if rows < 2 {
            return Err(TrajectoryError::Value {
                field: "rows",
                value: rows as f64,
                rule: "2 or more",
            });
        }
        Ok(Trajectory2d::Raster {
            corner_a,
            corner_b,
            rows,
            speed_um_s: positive("speed_um_s", speed_um_s)?,
        })
    }

    /// A path through timed points, checked: at least two, finite, times strictly increasing.
    pub fn path(points: Vec<(f64, PointUm)>) -> Result<Self, TrajectoryError> {
        if points.len() < 2 {
            return Err(TrajectoryError::Path(format!(
                "{} point(s) given; a path needs 2 or more",
                points.len()
            )));
        }
        for (i, (t_s, p)) in points.iter().enumerate() {
            if !(t_s.is_finite() && p.x_um.is_finite() && p.y_um.is_finite()) {
                return Err(TrajectoryError::Path(format!(
                    "point {} ({t_s} s, {} µm, {} µm) is not finite",
                    i + 1,
                    p.x_um,
                    p.y_um
                )));
            }
            if i > 0 && !(*t_s > points[i - 1].0) {
                return Err(TrajectoryError::Path(format!(
                    "point {} at {t_s} s is not after point {} at {} s; times must increase",
                    i + 1,
                    i,
                    points[i - 1].0
                )));
            }
        }
        Ok(Trajectory2d::Path { points })
    }

    /// A path from CSV text with the header `t_s,x_mm,y_mm` (columns in any order, named so).
    pub fn path_from_csv(text: &str) -> Result<Self, TrajectoryError> {
        let mut reader = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .from_reader(text.as_bytes());
        let headers = reader
            .headers()
            .map_err(|e| TrajectoryError::PathLine {
                line: 1,
                why: format!("the header cannot be read ({e})"),
            })?
            .clone();
        let column = |name: &str| -> Result<usize, TrajectoryError> {
            headers
                .iter()
                .position(|h| h == name)
                .ok_or_else(|| TrajectoryError::PathLine {
                    line: 1,
                    why: format!(
                        "the header has no {name} column (it must name t_s, x_mm and y_mm)"
                    ),
                })
        };
        let (ti, xi, yi) = (column("t_s")?, column("x_mm")?, column("y_mm")?);
        let mut points = Vec::new();
        for record in reader.records() {
            let record = record.map_err(|e| TrajectoryError::PathLine {
                line: e.position().map_or(0, |p| p.line()),
                why: format!("{e}"),
            })?;
            let line = record.position().map_or(0, |p| p.line());
            let field = |i: usize, name: &str| -> Result<f64, TrajectoryError> {
                let text = record.get(i).unwrap_or("");
                match text.parse::<f64>() {
                    Ok(v) if v.is_finite() => Ok(v),
                    _ => Err(TrajectoryError::PathLine {
                        line,
                        why: format!("{name} = {text:?} is not a finite number"),
                    }),
                }
            };
            let t_s = field(ti, "t_s")?;
            let x_um = field(xi, "x_mm")? * 1e3;
            let y_um = field(yi, "y_mm")? * 1e3;
            points.push((t_s, PointUm::new(x_um, y_um)));
        }
        Self::path(points)
    }

    /// How long the motion lasts, s (None: the circle goes on for ever). Rest lasts 0.
    pub fn duration_s(&self) -> Option<f64> {
        match self {
            Trajectory2d::Rest { .. } => Some(0.0),
            Trajectory2d::Line {
                from,
                to,
                speed_um_s,
            } => Some(from.distance_um(*to) / speed_um_s),
            Trajectory2d::Circle { .. } => None,
            Trajectory2d::Spiral {
                r0_um,
                r1_um,
                turns,
                speed_um_s,
                ..
            } => {
                let s = Spiral::new(*r0_um, *r1_um, *turns);
                Some(s.arc_um(s.theta_end) / speed_um_s)
            }
            Trajectory2d::Raster {
                corner_a,
                corner_b,
                rows,
                speed_um_s,
            } => Some(raster_length_um(*corner_a, *corner_b, *rows) / speed_um_s),
            Trajectory2d::Path { points } => {
                let first = points.first().map_or(0.0, |p| p.0);
                let last = points.last().map_or(0.0, |p| p.0);
                Some(last - first)
            }
        }
    }

    /// Position and velocity at `t_s` (before 0: the start, at rest).
    pub fn state(&self, t_s: f64) -> State2d {
        let t = t_s.max(0.0);
        match self {
            Trajectory2d::Rest { at } => State2d::at_rest(*at),
            Trajectory2d::Line {
                from,
                to,
                speed_um_s,
            } => {
                let length_um = from.distance_um(*to);
                let s_um = speed_um_s * t;
                if s_um >= length_um {
                    return State2d::at_rest(*to);
                }
                let (ux, uy) = (
                    (to.x_um - from.x_um) / length_um,
                    (to.y_um - from.y_um) / length_um,
                );
                State2d {
                    x_um: from.x_um + ux * s_um,
                    y_um: from.y_um + uy * s_um,
                    vx_um_s: ux * speed_um_s,
                    vy_um_s: uy * speed_um_s,
                }
            }
            Trajectory2d::Circle {
                center,
                radius_um,
                speed_um_s,
            } => {
                let w = speed_um_s / radius_um;
                let (sin, cos) = (w * t).sin_cos();
                State2d {
                    x_um: center.x_um + radius_um * cos,
                    y_um: center.y_um + radius_um * sin,
                    vx_um_s: -speed_um_s * sin,
                    vy_um_s: speed_um_s * cos,
                }
            }
            Trajectory2d::Spiral {
                center,
                r0_um,
                r1_um,
                turns,
                speed_um_s,
            } => {
                let s = Spiral::new(*r0_um, *r1_um, *turns);
                let arc_um = speed_um_s * t;
                let theta = if arc_um >= s.arc_um(s.theta_end) {
                    s.theta_end
                } else {
                    s.theta_at_arc(arc_um)
                };
                let r = r0_um + s.b_um * theta;
                let (sin, cos) = theta.sin_cos();
                let (x_um, y_um) = (center.x_um + r * cos, center.y_um + r * sin);
                if theta >= s.theta_end {
                    return State2d::at_rest(PointUm::new(x_um, y_um));
                }
                // Tangent dr/dθ = (b cos − r sin, b sin + r cos), of length √(r² + b²).
                let (tx, ty) = (s.b_um * cos - r * sin, s.b_um * sin + r * cos);
                let norm = tx.hypot(ty);
                State2d {
                    x_um,
                    y_um,
                    vx_um_s: speed_um_s * tx / norm,
                    vy_um_s: speed_um_s * ty / norm,
                }
            }
            Trajectory2d::Raster {
                corner_a,
                corner_b,
                rows,
                speed_um_s,
            } => raster_at(*corner_a, *corner_b, *rows, speed_um_s * t, *speed_um_s),
            Trajectory2d::Path { points } => {
                path_at(points, t + points.first().map_or(0.0, |p| p.0))
            }
        }
    }

    /// The states at the sample times (`k0` + i) × `period_us` µs for i in 0..`n`, into `out`
    /// (cleared first): what [`Self::state`] gives at each.
    pub fn states_into(&self, k0: u64, period_us: u32, n: usize, out: &mut Vec<State2d>) {
        out.clear();
        out.extend((0..n).map(|i| self.state(((k0 + i as u64) * period_us as u64) as f64 * 1e-6)));
    }

    /// Short name for reports.
    pub fn describe(&self) -> String {
        let mm = |p: &PointUm| format!("({:.2}, {:.2}) mm", p.x_um / 1e3, p.y_um / 1e3);
        match self {
            Trajectory2d::Rest { at } => format!("rest at {}", mm(at)),
            Trajectory2d::Line {
                from,
                to,
                speed_um_s,
            } => format!(
                "line {} → {} at {:.1} mm/s",
                mm(from),
                mm(to),
                speed_um_s / 1e3
            ),
            Trajectory2d::Circle {
                center,
                radius_um,
                speed_um_s,
            } => format!(
                "circle r {:.2} mm round {} at {:.1} mm/s",
                radius_um / 1e3,
                mm(center),
                speed_um_s / 1e3
            ),
            Trajectory2d::Spiral {
                center,
                r0_um,
                r1_um,
                turns,
                speed_um_s,
            } => format!(
                "spiral {:.2}–{:.2} mm in {turns} turns round {} at {:.1} mm/s",
                r0_um / 1e3,
                r1_um / 1e3,
                mm(center),
                speed_um_s / 1e3
            ),
            Trajectory2d::Raster {
                corner_a,
                corner_b,
                rows,
                speed_um_s,
            } => format!(
                "raster {} → {} in {rows} rows at {:.1} mm/s",
                mm(corner_a),
                mm(corner_b),
                speed_um_s / 1e3
            ),
            Trajectory2d::Path { points } => format!(
                "path of {} points over {:.3} s",
                points.len(),
                self.duration_s().unwrap_or(0.0)
            ),
        }
    }
}

/// The Archimedean spiral's constants: r = r0 + b·θ for θ in [0, θ_end].
struct Spiral {
    r0_um: f64,
    b_um: f64,
    theta_end: f64,
}

impl Spiral {
    fn new(r0_um: f64, r1_um: f64, turns: f64) -> Self {
        let theta_end = turns * std::f64::consts::TAU;
        Self {
            r0_um,
            b_um: (r1_um - r0_um) / theta_end,
            theta_end,
        }
    }

    /// Arc length from θ = 0, µm: with u = r/b, s = (b/2)·[u√(1+u²) + asinh u] from u0 to u.
    fn arc_um(&self, theta: f64) -> f64 {
        let prim = |r: f64| {
            let u = r / self.b_um;
            0.5 * self.b_um * (u * (1.0 + u * u).sqrt() + u.asinh())
        };
        prim(self.r0_um + self.b_um * theta) - prim(self.r0_um)
    }

    /// θ at arc length `arc_um` (0 ≤ arc ≤ the whole), by Newton's method on the increasing
    /// s(θ), whose derivative √(r² + b²) is never 0 (b > 0); bisection keeps it bracketed.
    fn theta_at_arc(&self, arc_um: f64) -> f64 {
        let (mut lo, mut hi) = (0.0, self.theta_end);
        let mut theta = arc_um / (self.r0_um + self.b_um * self.theta_end / 2.0).max(self.b_um);
        for _ in 0..60 {
            if !(theta > lo && theta < hi) {
                theta = 0.5 * (lo + hi);
            }
            let err = self.arc_um(theta) - arc_um;
            if err > 0.0 {
                hi = theta;
            } else {
                lo = theta;
            }
            let r = self.r0_um + self.b_um * theta;
            let step = err / r.hypot(self.b_um);
            theta -= step;
            if step.abs() < 1e-13 * self.theta_end.max(1.0) {
                break;
            }
        }
        theta.clamp(0.0, self.theta_end)
    }
}

fn raster_length_um(a: PointUm, b: PointUm, rows: u32) -> f64 {
    let row_um = (b.x_um - a.x_um).abs();
    let step_um = (b.y_um - a.y_um).abs() / (rows - 1) as f64;
    rows as f64 * row_um + (rows - 1) as f64 * step_um
}

fn raster_at(a: PointUm, b: PointUm, rows: u32, s_um: f64, speed_um_s: f64) -> State2d {
    let row_um = (b.x_um - a.x_um).abs();
    let dir_x = (b.x_um - a.x_um).signum();
    let dy_um = (b.y_um - a.y_um) / (rows - 1) as f64;
    let step_um = dy_um.abs();
    let leg_um = row_um + step_um;
    // Row k starts at arc k·(row + step); the step to row k + 1 follows it.
    let k = ((s_um / leg_um).floor() as u32).min(rows - 1);
    let within = s_um - k as f64 * leg_um;
    let y_row = a.y_um + k as f64 * dy_um;
    let (x_start, sign) = if k % 2 == 0 {
        (a.x_um, dir_x)
    } else {
        (b.x_um, -dir_x)
    };
    if within < row_um {
        State2d {
            x_um: x_start + sign * within,
            y_um: y_row,
            vx_um_s: sign * speed_um_s,
            vy_um_s: 0.0,
        }
    } else {
        let x_end = x_start + sign * row_um;
        if k + 1 >= rows {
            return State2d::at_rest(PointUm::new(x_end, y_row));
        }
        let up = within - row_um;
        State2d {
            x_um: x_end,
            y_um: y_row + dy_um.signum() * up,
            vx_um_s: 0.0,
            vy_um_s: dy_um.signum() * speed_um_s,
        }
    }
}

fn path_at(points: &[(f64, PointUm)], t_s: f64) -> State2d {
    // Points are few (a hand-made or recorded path); the segment is found by binary search.
    let i = points.partition_point(|p| p.0 <= t_s);
    let Some(&(_, first)) = points.first() else {
        return State2d::at_rest(PointUm::new(0.0, 0.0));
    };
    if i == 0 {
        return State2d::at_rest(first);
    }
    if i >= points.len() {
        return State2d::at_rest(points[points.len() - 1].1);
    }
    let ((t0, p0), (t1, p1)) = (points[i - 1], points[i]);
    let dt = t1 - t0;
    let f = (t_s - t0) / dt;
    let (vx, vy) = ((p1.x_um - p0.x_um) / dt, (p1.y_um - p0.y_um) / dt);
    State2d {
        x_um: p0.x_um + f * (p1.x_um - p0.x_um),
        y_um: p0.y_um + f * (p1.y_um - p0.y_um),
        vx_um_s: vx,
        vy_um_s: vy,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(x_mm: f64, y_mm: f64) -> PointUm {
        PointUm::new(x_mm * 1e3, y_mm * 1e3)
    }

    /// The velocity the positions imply: a central difference over ±h.
    fn finite_velocity(tr: &Trajectory2d, t_s: f64, h_s: f64) -> (f64, f64) {
        let (a, b) = (tr.state(t_s - h_s), tr.state(t_s + h_s));
        (
            (b.x_um - a.x_um) / (2.0 * h_s),
            (b.y_um - a.y_um) / (2.0 * h_s),
        )
    }

    fn check_velocity_matches_positions(tr: &Trajectory2d, times: &[f64]) {
        for &t in times {
            let s = tr.state(t);
            let (vx, vy) = finite_velocity(tr, t, 1e-6);
            assert!(
                (s.vx_um_s - vx).abs() < 1e-2 * (1.0 + vx.abs())
                    && (s.vy_um_s - vy).abs() < 1e-2 * (1.0 + vy.abs()),
                "{} at {t} s: stated ({}, {}) µm/s, positions imply ({vx}, {vy})",
                tr.describe(),
                s.vx_um_s,
                s.vy_um_s
            );
        }
    }

    #[test]
    fn a_line_runs_from_start_to_end_at_its_speed_then_rests() {
        // 3-4-5 triangle: 5 mm at 50 mm/s takes 0.1 s.
        let tr = Trajectory2d::line(p(1.0, 2.0), p(4.0, 6.0), 50_000.0).unwrap();
        assert_eq!(tr.duration_s(), Some(0.1));
        let s0 = tr.state(0.0);
        assert_eq!((s0.x_um, s0.y_um), (1_000.0, 2_000.0));
        assert!((s0.vx_um_s - 30_000.0).abs() < 1e-9 && (s0.vy_um_s - 40_000.0).abs() < 1e-9);
        let mid = tr.state(0.05);
        assert!((mid.x_um - 2_500.0).abs() < 1e-9 && (mid.y_um - 4_000.0).abs() < 1e-9);
        let end = tr.state(0.2);
        assert_eq!(end, State2d::at_rest(p(4.0, 6.0)));
        check_velocity_matches_positions(&tr, &[0.01, 0.05, 0.09]);
    }

    #[test]
    fn a_circle_keeps_its_radius_and_speed() {
        let tr = Trajectory2d::circle(p(10.0, 10.0), 5_000.0, 100_000.0).unwrap();
        for i in 0..50 {
            let t = i as f64 * 0.013;
            let s = tr.state(t);
            let r = (s.x_um - 10_000.0).hypot(s.y_um - 10_000.0);
            assert!((r - 5_000.0).abs() < 1e-6, "radius {r} at {t}");
            assert!((s.speed_um_s() - 100_000.0).abs() < 1e-6);
        }
        // A quarter of the 2π·5 mm circumference at 100 mm/s: (10, 15) mm, heading −x.
        let q = tr.state(std::f64::consts::TAU * 5_000.0 / 4.0 / 100_000.0);
        assert!((q.x_um - 10_000.0).abs() < 1e-6 && (q.y_um - 15_000.0).abs() < 1e-6);
        assert!(q.vx_um_s < -99_999.0);
        check_velocity_matches_positions(&tr, &[0.0101, 0.2, 0.77]);
    }

    #[test]
    fn a_spiral_goes_out_at_constant_speed_and_ends_at_its_outer_radius() {
        let tr = Trajectory2d::spiral(p(0.0, 0.0), 1_000.0, 9_000.0, 4.0, 40_000.0).unwrap();
        let duration = tr.duration_s().unwrap();
        // The arc length summed from small chords, independent of the closed form.
        let mut chords_um = 0.0;
        let n = 200_000;
        let (b, theta_end) = (
            8_000.0 / (4.0 * std::f64::consts::TAU),
            4.0 * std::f64::consts::TAU,
        );
        let at = |th: f64| {
            let r = 1_000.0 + b * th;
            (r * th.cos(), r * th.sin())
        };
        for i in 0..n {
            let (a, c) = (
                at(theta_end * i as f64 / n as f64),
                at(theta_end * (i + 1) as f64 / n as f64),
            );
            chords_um += (c.0 - a.0).hypot(c.1 - a.1);
        }
        assert!(
            (duration * 40_000.0 - chords_um).abs() < 1e-3 * chords_um,
            "{duration} s vs {chords_um} µm"
        );
        let mut last_r = 0.0;
        for i in 1..40 {
            let t = duration * i as f64 / 40.0;
            let s = tr.state(t);
            let r = s.x_um.hypot(s.y_um);
            assert!(r > last_r, "the radius grows: {r} after {last_r}");
            last_r = r;
            assert!((s.speed_um_s() - 40_000.0).abs() < 1e-6);
        }
        check_velocity_matches_positions(&tr, &[0.05, duration / 2.0, duration * 0.9]);
        let end = tr.state(duration + 1.0);
        assert!(
            (end.x_um - 9_000.0).abs() < 1e-3 && end.y_um.abs() < 1e-3 && end.speed_um_s() == 0.0
        );
    }

    #[test]
    fn a_raster_sweeps_its_rows_alternately_and_steps_between_them() {
        // Rows at y = 0, 2, 4 mm over x 0..10 mm at 10 mm/s: 3 rows of 1 s and 2 steps of 0.2 s.
        let tr = Trajectory2d::raster(p(0.0, 0.0), p(10.0, 4.0), 3, 10_000.0).unwrap();
        assert!((tr.duration_s().unwrap() - 3.4).abs() < 1e-12);
        let s = tr.state(0.5);
        assert!((s.x_um - 5_000.0).abs() < 1e-9 && s.y_um == 0.0 && s.vx_um_s == 10_000.0);
        let s = tr.state(1.1);
        assert!(
            (s.x_um - 10_000.0).abs() < 1e-9
                && (s.y_um - 1_000.0).abs() < 1e-6
                && s.vy_um_s == 10_000.0
        );
        let s = tr.state(1.7);
        assert!(
            (s.x_um - 5_000.0).abs() < 1e-6
                && (s.y_um - 2_000.0).abs() < 1e-9
                && s.vx_um_s == -10_000.0
        );
        let s = tr.state(3.3);
        assert!((s.x_um - 9_000.0).abs() < 1e-6 && (s.y_um - 4_000.0).abs() < 1e-9);
        assert_eq!(tr.state(5.0), State2d::at_rest(p(10.0, 4.0)));
        check_velocity_matches_positions(&tr, &[0.3, 1.1, 1.5, 2.5]);
    }

    #[test]
    fn a_path_interpolates_its_points_and_rests_after_the_last() {
        let tr =
            Trajectory2d::path_from_csv("t_s,x_mm,y_mm\n0.5,0,0\n1.5,10,0\n2.0,10,5\n").unwrap();
        assert_eq!(tr.duration_s(), Some(1.5));
        // Time 0 is the first point's time.
        let s = tr.state(0.25);
        assert!((s.x_um - 2_500.0).abs() < 1e-9 && s.vx_um_s == 10_000.0);
        let s = tr.state(1.25);
        assert!(
            (s.x_um - 10_000.0).abs() < 1e-9
                && (s.y_um - 2_500.0).abs() < 1e-9
                && s.vy_um_s == 10_000.0
        );
        assert_eq!(tr.state(9.0), State2d::at_rest(p(10.0, 5.0)));
    }

    #[test]
    fn bad_paths_and_values_are_refused_with_a_sentence_naming_them() {
        let e = Trajectory2d::path_from_csv("t_s,x_mm\n0,1\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("y_mm") && e.contains("line 1"), "{e}");
        let e = Trajectory2d::path_from_csv("t_s,x_mm,y_mm\n0,1,2\n1,nan,2\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 3") && e.contains("x_mm") && e.contains("nan"),
            "{e}"
        );
        let e = Trajectory2d::path_from_csv("t_s,x_mm,y_mm\n1,1,2\n1,2,2\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("point 2") && e.contains("increase"), "{e}");
        let e = Trajectory2d::path_from_csv("t_s,x_mm,y_mm\n1,1,2\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("2 or more"), "{e}");
        let e = Trajectory2d::line(p(1.0, 1.0), p(1.0, 1.0), 1.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("points must differ"), "{e}");
        let e = Trajectory2d::line(p(0.0, 0.0), p(1.0, 1.0), f64::NAN)
            .unwrap_err()
            .to_string();
        assert!(e.contains("speed_um_s") && e.contains("NaN"), "{e}");
        let e = Trajectory2d::spiral(p(0.0, 0.0), 5.0, 5.0, 1.0, 1.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("r1_um"), "{e}");
        let e = Trajectory2d::raster(p(0.0, 0.0), p(1.0, 1.0), 1, 1.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("rows") && e.contains("2 or more"), "{e}");
        let e = Trajectory2d::circle(p(f64::INFINITY, 0.0), 1.0, 1.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("center x_um"), "{e}");
    }

    #[test]
    fn states_into_is_state_at_each_sample_time() {
        let tr = Trajectory2d::circle(p(0.0, 0.0), 3_000.0, 70_000.0).unwrap();
        let mut out = Vec::new();
        tr.states_into(1_000, 40, 16, &mut out);
        for (i, s) in out.iter().enumerate() {
            assert_eq!(*s, tr.state(((1_000 + i as u64) * 40) as f64 * 1e-6));
        }
    }
}
