//! Writes a 2D configuration as a scene file (issue #36): `[sensor]`, `[limits]`, `[screen]`
//! with the plate's size (which `Config2d` does not hold: the caller gives it), every window
//! as a polygon, the free edges and `[edges]`, every value explicit. Reading the text back
//! gives the same `Config2d` when its coordinates lie on the plate and its gratings' normals
//! are the reader's (a unit vector × 10⁶ from `ridge_angle_deg`); another normal is written at
//! its direction and reads back as that direction's unit vector.

extern crate std;

use std::string::String;
use std::vec::Vec as StdVec;

use crate::gate::DriveMode;
use crate::plane::{Config2d, PlaneTexture, PointUm};
use crate::texture::{Envelope, Texture};

use super::plane2d::FOUR_WIRE;
use super::write::{kind_of, limits_table, tenths, texture_keys, thousandths};

/// A signed µm count as mm: -1500 → "-1.5".
fn mm(um: i32) -> String {
    let sign = if um < 0 { "-" } else { "" };
    std::format!("{sign}{}", thousandths(um.unsigned_abs().into()))
}

/// `[x, y]` in mm.
fn point(p: PointUm) -> String {
    std::format!("[{}, {}]", mm(p.x_um), mm(p.y_um))
}

/// A texture's lines: `kind`, its keys and, oriented, `ridge_angle_deg` (the normal's
/// direction in full f64 precision).
fn texture_lines(t: &PlaneTexture) -> StdVec<String> {
    let mut out = StdVec::new();
    let (texture, normal) = match t {
        PlaneTexture::Plain(t) => (*t, None),
        PlaneTexture::Oriented(o) => (Texture::Grating(o.grating), Some(o.normal)),
    };
    out.push(std::format!("kind = \"{}\"", kind_of(&texture)));
    texture_keys(&texture, &mut |l| out.push(l));
    if let Some((x, y)) = normal {
        let deg = libm::atan2(y as f64, x as f64).to_degrees();
        out.push(std::format!("ridge_angle_deg = {deg:?}"));
    }
    out
}

/// The 2D scene file that reads back as `config` on a plate of `plate_um` (width, height),
/// with `title` as its first comment lines.
pub fn to_scene_file_2d(config: &Config2d, plate_um: (u32, u32), title: &str) -> String {
    let mut s = String::new();
    let mut line = |text: String| {
        s.push_str(&text);
        s.push('\n');
    };
    for l in title.lines() {
        line(std::format!("# {l}"));
    }
    let sc = &config.scene;
    line(std::format!(
        "drive = \"{}\"",
        match sc.drive {
            DriveMode::Standing => "standing",
            DriveMode::Progressive => "progressive",
        }
    ));
    line(String::new());
    line("[sensor]".into());
    line(std::format!("kind = \"{FOUR_WIRE}\""));
    limits_table(&config.limits, config.stale_after_us, &mut line);
    line(String::new());
    line("[screen]".into());
    line(std::format!(
        "size_mm = [{}, {}]",
        thousandths(plate_um.0.into()),
        thousandths(plate_um.1.into())
    ));
    line(std::format!("band_mm = {}", thousandths(sc.band_um.into())));
    line(std::format!(
        "background = {{ {} }}",
        texture_lines(&sc.background).join(", ")
    ));
    for w in &sc.windows {
        line(String::new());
        line("[[window]]".into());
        let vertices: StdVec<String> = w.outline.vertices.iter().map(|p| point(*p)).collect();
        line(std::format!("polygon_mm = [{}]", vertices.join(", ")));
        line(std::format!("outline = {}", w.edge));
        for l in texture_lines(&w.texture) {
            line(l);
        }
    }
    for e in &sc.free_edges {
        line(String::new());
        line("[[edge]]".into());
        line(std::format!("from_mm = {}", point(e.a)));
        line(std::format!("to_mm = {}", point(e.b)));
    }
    let p = &sc.edge_pulse;
    line(String::new());
    line("[edges]".into());
    line(std::format!(
        "pulse_ms = {}",
        thousandths(p.pulse_us.into())
    ));
    line(std::format!(
        "envelope = \"{}\"",
        match p.envelope {
            Envelope::Triangular => "triangle",
            Envelope::Rectangular => "rectangle",
        }
    ));
    line(std::format!(
        "amplitude_percent = {}",
        tenths(p.amplitude_permille)
    ));
    line(std::format!(
        "rearm_mm = {}",
        thousandths(sc.rearm_um.into())
    ));
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::burst::{BurstCommand, SafetyLimits};
    use crate::plane::{EdgePulse, OrientedGrating, Polygon, Scene2d, SegmentUm, Window2d};
    use crate::scene_file::{load_2d_for_board, plate_um_of, sensor_of, SensorKind};
    use crate::texture::{Grating, GratingRender, Material, RandomBurst};
    use std::string::ToString;

    const TIMER: crate::burst::BurstTimer = crate::burst::TEST_TIMER;
    const FRAME_US: u32 = 346;

    fn read(name: &str, text: &str) -> Config2d {
        load_2d_for_board(name, text, TIMER, FRAME_US)
            .unwrap_or_else(|e| panic!("{name}: {e}\n{text}"))
    }

    /// Every shipped 2D file, read, written and read again: the same configuration.
    #[test]
    fn every_2d_scene_file_round_trips() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes");
        let mut n = 0;
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            let name = path.display().to_string();
            let text = std::fs::read_to_string(&path).unwrap();
            if sensor_of(&name, &text) != Ok(SensorKind::FourWire) {
                continue;
            }
            let config = read(&name, &text);
            let written = to_scene_file_2d(&config, plate_um_of(&name, &text).unwrap(), "again");
            assert_eq!(read("written", &written), config, "{name}:\n{written}");
            n += 1;
        }
        assert!(n >= 2, "{n} 2D files");
    }

    /// A scene with every texture kind, an odd oriented angle, negative-free odd coordinates,
    /// a rectangle envelope and progressive drive, written and read back equal. The normal is
    /// the reader's for 12.5° (cos, sin × 10⁶ rounded: 976 296, 216 440).
    #[test]
    fn every_kind_and_odd_values_round_trip() {
        let pt = |x, y| crate::plane::PointUm::new(x, y);
        let rect = |x0, y0, x1, y1| Polygon::rectangle(pt(x0, y0), pt(x1, y1)).unwrap();
        let window = |outline, texture, edge| Window2d {
            outline,
            texture,
            edge,
        };
        let mut windows = heapless::Vec::new();
        for w in [
            window(
                rect(1_001, 2_002, 10_500, 20_000),
                PlaneTexture::Oriented(OrientedGrating {
                    grating: Grating {
                        render: GratingRender::Hybrid,
                        rearm_um: 37,
                        amplitude_permille: 600,
                        duty_permille: 300,
                        ..Grating::new(250)
                    },
                    normal: (976_296, 216_440),
                }),
                true,
            ),
            window(
                rect(12_000, 2_000, 20_000, 20_000),
                PlaneTexture::Plain(Texture::Material(Material {
                    delta_mu: 0.3,
                    normal_force_n: 0.7,
                    mass_kg: 0.0033,
                    stiffness_n_per_m: 123.4,
                    duty_permille: 125,
                    min_speed_um_s: 7_500,
                })),
                false,
            ),
            window(
                Polygon::from_points(&[pt(22_000, 2_000), pt(40_000, 2_000), pt(31_000, 9_999)])
                    .unwrap(),
                PlaneTexture::Plain(Texture::Random(RandomBurst {
                    center_millihz: 60_500,
                    spread_permille: 333,
                    amplitude_permille: 800,
                    amplitude_spread_permille: 100,
                    duty_permille: 250,
                    seed: 18_446_744_073_709_551_615,
                })),
                true,
            ),
            window(
                rect(22_000, 12_000, 40_000, 20_000),
                PlaneTexture::Plain(Texture::Grating(Grating {
                    render: GratingRender::VelocitySynthesis,
                    amplitude_permille: 955,
                    duty_permille: 333,
                    ..Grating::new(3_000)
                })),
                false,
            ),
        ] {
            windows.push(w).unwrap();
        }
        let mut free_edges = heapless::Vec::new();
        free_edges
            .push(SegmentUm {
                a: pt(0, 25_000),
                b: pt(45_000, 30_000),
            })
            .unwrap();
        let config = Config2d {
            scene: Scene2d {
                windows,
                background: PlaneTexture::Plain(Texture::Constant(BurstCommand {
                    burst_millihz: 999_999,
                    duty_permille: 333,
                })),
                band_um: 150,
                free_edges,
                edge_pulse: EdgePulse {
                    pulse_us: 7_250,
                    envelope: Envelope::Rectangular,
                    amplitude_permille: 455,
                },
                rearm_um: 250,
                drive: DriveMode::Progressive,
            },
            limits: SafetyLimits {
                max_duty_permille: 333,
                max_on_time_us: 12_345,
                max_level_permille: 955,
            },
            stale_after_us: 2_500,
        };
        let written = to_scene_file_2d(&config, (45_000, 30_000), "odd values\nsecond line");
        assert!(
            written.starts_with("# odd values\n# second line\n"),
            "{written}"
        );
        assert_eq!(read("odd", &written), config, "{}", written.to_string());
    }
}
