//! `pedscan sheet`: a contact sheet of human models at several gait phases, rendered by
//! pedscan's own raster path (Vulkan, exact refinement) with a dense virtual LiDAR, so a person
//! can see every bundled (or user) model walk. Each cell is the range image of one person
//! walking across the view (heading +y, 3.2 m in front of a sensor at hip height), in turbo
//! colours by range.

use crate::config::Refine;
use crate::error::{Error, Result};
use crate::geometry::FrameGeometry;
use crate::gpu::{Context, ContextOptions};
use crate::human::{HumanModel, MODEL_TO_BODY};
use crate::output::png::turbo;
use crate::plot::font::{draw_text, text_width};
use crate::backend::raster::projection::CubeFaces;
use crate::backend::raster::renderer::Renderer;
use crate::backend::raster::resample::{resample, BeamLookup};
use crate::backend::{BeamHits, NO_TRIANGLE};
use crate::sensor::Sensor;
use glam::{DMat4, DVec3, Mat4};
use image::RgbImage;
use std::sync::Arc;

const DISTANCE_M: f64 = 3.2;
const SENSOR_HEIGHT_M: f64 = 0.95;
/// Columns of the virtual sensor around azimuth 0 kept per cell.
const CELL_COLS: usize = 150;

/// Renders the sheet: one column per model, one row per phase, with `pushing` a row of each
/// model walking at the first phase pushing ([`crate::human::GaitStyle::pushing`]; the thing
/// pushed not drawn), and with `seat_m` a last row of each model seated on a seat that high
/// ([`crate::human::GaitStyle::seat_m`]; the seat itself not drawn); returns the image.
pub fn contact_sheet(models: &[HumanModel], phases: &[f32], pushing: bool, seat_m: Option<f32>, validation: bool) -> Result<RgbImage> {
    if models.is_empty() || phases.is_empty() {
        return Err(Error::input("sheet", "no models or no phases"));
    }
    // A dense virtual LiDAR: 0.15 deg per row and column, +-18 deg.
    let rows = 241;
    let sensor = Sensor {
        name: "sheet".into(),
        elevation_deg: (0..rows).map(|i| 18.0 - 0.15 * i as f64).collect(),
        columns: 2400,
        rate_hz: 10.0,
        min_range_m: 0.1,
        max_range_m: 20.0,
    };
    let cube = CubeFaces::new(&sensor, 1.0);
    let lookup = BeamLookup::new(&sensor, &cube);
    let ctx = Arc::new(Context::new(&ContextOptions { validation, ..Default::default() })?);
    let mut renderer = Renderer::new(&ctx, &cube)?;
    let scale = 1u32;
    let label_h = 14u32;
    let (cw, ch) = (CELL_COLS as u32, rows as u32);
    let walk = crate::human::GaitStyle::WALK;
    let push = pushing.then(|| (phases[0], crate::human::GaitStyle { pushing: true, ..walk }));
    let rows_drawn: Vec<(f32, crate::human::GaitStyle)> =
        phases.iter().map(|&p| (p, walk)).chain(push).chain(seat_m.map(|s| (0.0, crate::human::GaitStyle { seat_m: s, ..walk }))).collect();
    let mut img = RgbImage::from_pixel(cw * models.len() as u32, label_h + ch * rows_drawn.len() as u32, image::Rgb([255, 255, 255]));
    let mut geom = FrameGeometry::default();
    let mut hits = BeamHits::default();
    let (mut joints, mut skinned) = (Vec::new(), Vec::new());
    let c0 = sensor.columns / 2 - CELL_COLS / 2;
    for (mi, m) in models.iter().enumerate() {
        let name = &m.name;
        let tw = text_width(name, scale);
        draw_text(&mut img, (mi as u32 * cw + cw.saturating_sub(tw) / 2) as i64, 3, name, scale, [0, 0, 0]);
        for (pi, &(phase, style)) in rows_drawn.iter().enumerate() {
            // Person at (DISTANCE, 0) on the floor walking towards +y; sensor at the origin.
            let world_from_body = DMat4::from_translation(DVec3::new(DISTANCE_M, 0.0, -SENSOR_HEIGHT_M))
                * DMat4::from_rotation_z(std::f64::consts::FRAC_PI_2);
            m.joint_matrices_styled(phase, style, &mut joints);
            let t: Mat4 = (world_from_body * MODEL_TO_BODY.as_dmat4()).as_mat4();
            m.skin_into(0, &joints, &t, &mut skinned);
            geom.clear();
            geom.push_mesh_with_adjacency(&skinned, &m.lods[0].indices, 1, false, Some(m.lods[0].adjacency.clone()));
            let frame = renderer.render(&geom)?;
            resample(&lookup, frame, &geom, Refine::Exact, &mut hits);
            for r in 0..rows {
                for c in 0..CELL_COLS {
                    let b = r * sensor.columns + c0 + c;
                    let px = if hits.triangle[b] != NO_TRIANGLE {
                        let range = hits.range_m[b] as f64;
                        turbo((1.0 - ((range - (DISTANCE_M - 0.6)) / 1.2).clamp(0.0, 1.0)) as f32)
                    } else {
                        [235, 235, 235]
                    };
                    img.put_pixel(mi as u32 * cw + c as u32, label_h + pi as u32 * ch + r as u32, image::Rgb(px));
                }
            }
        }
    }
    drop(renderer);
    let errors = ctx.validation_errors();
    if validation && errors > 0 {
        return Err(Error::Gpu(format!("{errors} Vulkan validation errors")));
    }
    Ok(img)
}

/// What `pedscan sheet` is asked for (its flags).
#[derive(Clone, Debug, clap::Args)]
pub struct SheetRequest {
    /// Output PNG.
    #[arg(long, default_value = "humans.png")]
    pub out: std::path::PathBuf,
    /// Human models: folders of .glb files or files (default: the bundled humans).
    #[arg(long)]
    pub models: Vec<std::path::PathBuf>,
    /// Gait phases, comma separated.
    #[arg(long, value_delimiter = ',', default_value = "0,0.25,0.5,0.75")]
    pub phases: Vec<f32>,
    /// Each model also carrying each kind of `humans.carrying` (a backpack, a bag, two
    /// bags), a column each after the model's own.
    #[arg(long)]
    pub carrying: bool,
    /// A row of each model walking at the first phase pushing (`humans.pushing`: the arms
    /// held to the handle; the thing pushed not drawn; a model that cannot push walks).
    #[arg(long)]
    pub pushing: bool,
    /// A last row of each model seated on a seat this high, m (`humans.sitting`; the seat
    /// not drawn).
    #[arg(long, value_name = "M")]
    pub seated: Option<f32>,
    #[arg(long)]
    pub validation: bool,
}

/// Loads the models (none: the bundled people; with `carrying`, each followed by it carrying
/// each kind of [`crate::human::carry::CARRIED`]) and writes the sheet to `out` (temporary
/// name, then rename).
pub fn write_contact_sheet(req: &SheetRequest) -> Result<()> {
    let bundled = crate::config::Config::default().humans.models;
    let files = crate::human::model_files(if req.models.is_empty() { &bundled } else { &req.models })?;
    let mut models = files.iter().map(|f| HumanModel::load(f, true)).collect::<Result<Vec<_>>>()?;
    if req.carrying {
        models = models.iter().flat_map(|m| std::iter::once(m.clone()).chain(m.carrying_all())).collect();
    }
    if let Some(s) = req.seated.filter(|s| !(s.is_finite() && *s > 0.0 && *s < 2.0)) {
        return Err(Error::input("--seated", format!("{s} m is not a seat's height (0 to 2 m)")));
    }
    let img = contact_sheet(&models, &req.phases, req.pushing, req.seated, req.validation)?;
    crate::output::png::save_png(&img, &req.out)
}
