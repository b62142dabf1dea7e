use camsim::{Error, Result};
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum LensCmd {
    /// Focal length, f-number, exit pupil, film distance for focus at infinity,
    /// and the on-axis beam vergence (1/m) at `--film-distance-mm` (default:
    /// the infinity film distance): 1/vergence is the focus distance from the
    /// film; a negative vergence means focus beyond infinity.
    Info(LensInfoArgs),
    /// Relative illumination vs field height: CSV field_height_mm,relative_illumination.
    Ri(LensRiArgs),
    /// Geometric edge-spread function: CSV position_um,esf,lsf.
    Esf(LensEsfArgs),
    /// Fit a ray-transfer function to a prescription.
    FitRtf(FitRtfArgs),
}

#[derive(Args)]
pub struct LensInfoArgs {
    pub lens: PathBuf,
    /// Film distance for the last two columns (default: infinity focus).
    #[arg(long)]
    pub film_distance_mm: Option<f64>,
}
#[derive(Args)]
pub struct LensRiArgs {
    pub lens: PathBuf,
    #[arg(long)]
    pub film_distance_mm: Option<f64>,
    #[arg(long)]
    pub wavelength_nm: Option<f64>,
    /// Comma-separated film heights in mm (default: 41 heights from the
    /// axis to the edge of the lit film).
    #[arg(long, value_delimiter = ',')]
    pub field_heights_mm: Vec<f64>,
    /// `axis` (default): RI(0) = 1; `max`: the largest value is 1, as
    /// Zemax's relative-illumination tables are normalised.
    #[arg(long, default_value = "axis")]
    pub normalize: camsim::optics::analysis::RiNormalization,
}
#[derive(Args)]
pub struct LensEsfArgs {
    pub lens: PathBuf,
    #[arg(long)]
    pub object_distance_m: f64,
    #[arg(long)]
    pub film_distance_mm: Option<f64>,
    #[arg(long)]
    pub field_mm: Option<f64>,
}
#[derive(Args)]
pub struct FitRtfArgs {
    pub prescription: PathBuf,
    #[arg(long)]
    pub degree: usize,
    /// Comma-separated wavelengths in nm.
    #[arg(long, value_delimiter = ',')]
    pub wavelengths: Vec<f64>,
    #[arg(long)]
    pub out: PathBuf,
    /// Pass/no-pass representation: `area-ellipses` (default: per field
    /// radius the ellipse with the pass region's radial extent and area; RI
    /// within 0.005 of the prescription), `ellipses` (minimum-area enclosing
    /// ellipse, as the paper's files; up to +0.075 RI at vignetted fields)
    /// or `circles` (intersection of vignetting circles of fixed radius and
    /// linear centre; up to +0.027, pupil aberration bends them).
    #[arg(
        long = "pass",
        visible_alias = "pass-method",
        default_value = "area-ellipses"
    )]
    pub pass_method: String,
    /// Extra least-squares weight on the on-axis rays (1 = none). A
    /// low-degree polynomial cannot be accurate on axis and across a wide
    /// field at once; a weight of 64 makes a degree-3 fit match the
    /// prescription's on-axis ESF within 1 % at the cost of the 25 % field
    /// (see `optics::fit` docs for measurements).
    #[arg(long, default_value_t = 1.0)]
    pub axis_weight: f64,
    /// Object distances, in focal lengths, whose film planes the fit samples
    /// (`inf` for infinity); the RTF is then fitted to the rays a camera
    /// focused over that range traces.
    #[arg(long, value_delimiter = ',', default_values_t = vec!["inf".to_string(), "20".into(), "10".into(), "5".into()])]
    pub focus_distances_f: Vec<String>,
    /// Where the fit's rays come from: `film-bundles` (default: film points
    /// on the focus planes, each with a grid over its pupil) or
    /// `input-plane` (input points with a polar grid in their pass ellipse,
    /// the earlier method).
    #[arg(long, default_value = "film-bundles")]
    pub sampling: String,
}

pub fn run(c: LensCmd) -> Result<i32> {
    use camsim::optics::analysis::{self, DEFAULT_WAVELENGTH_NM, LensFile};
    let mut out = String::new();
    match c {
        LensCmd::Info(a) => {
            let lens = analysis::load_lens(&a.lens)?;
            let i = analysis::lens_info(&lens, DEFAULT_WAVELENGTH_NM)?;
            // Where a given film distance focuses (RTF files carry no focus).
            let cam = analysis::lens_camera(lens, a.film_distance_mm, None, DEFAULT_WAVELENGTH_NM)?;
            let v = analysis::on_axis_vergence_per_m(cam.camera(), DEFAULT_WAVELENGTH_NM, 128)
                .ok_or_else(|| Error::Invalid("no light reaches the film on axis".into()))?;
            out.push_str("focal_length_mm,f_number,working_f_number,exit_pupil_from_film_mm,exit_pupil_radius_mm,film_distance_infinity_mm,film_distance_mm,beam_vergence_per_m\n");
            out.push_str(&format!(
                "{},{},{},{},{},{},{},{}\n",
                i.focal_length_mm,
                i.f_number,
                i.working_f_number,
                i.exit_pupil_from_film_mm,
                i.exit_pupil_radius_mm,
                i.film_distance_infinity_mm,
                cam.film_distance_mm(),
                v
            ));
        }
        LensCmd::Ri(a) => {
            let w = a.wavelength_nm.unwrap_or(DEFAULT_WAVELENGTH_NM);
            let lens = analysis::load_lens(&a.lens)?;
            let cam = analysis::lens_camera(lens, a.film_distance_mm, None, w)?;
            let max_mm = match &cam {
                analysis::LensCamera::Prescription(c) => c.max_film_radius_mm,
                analysis::LensCamera::Rtf(c) => match c.rtf.waves[0].pass.max_radius_mm() {
                    Some(m) => m,
                    None => c.film_distance_mm,
                },
            };
            let heights: Vec<f64> = if a.field_heights_mm.is_empty() {
                (0..=40).map(|k| max_mm * k as f64 / 40.0).collect()
            } else {
                if let Some(h) = a
                    .field_heights_mm
                    .iter()
                    .find(|h| !(h.is_finite() && **h >= 0.0))
                {
                    return Err(Error::Invalid(format!(
                        "--field-heights-mm: {h} is not a film height >= 0 mm"
                    )));
                }
                a.field_heights_mm.clone()
            };
            let ri = analysis::relative_illumination(cam.camera(), &heights, w, 200)?;
            let ri = analysis::normalize_ri(ri, a.normalize);
            out.push_str("field_height_mm,relative_illumination\n");
            for (h, v) in heights.iter().zip(ri) {
                out.push_str(&format!("{h},{v}\n"));
            }
        }
        LensCmd::Esf(a) => {
            let lens = analysis::load_lens(&a.lens)?;
            if !(a.object_distance_m.is_finite() && a.object_distance_m > 0.0) {
                return Err(Error::Invalid(format!(
                    "--object-distance-m must be > 0 and finite, got {}",
                    a.object_distance_m
                )));
            }
            // Without a film distance a prescription is focused on the object
            // (paraxial); an RTF uses its infinity-focus film distance.
            let film = match (&lens, a.film_distance_mm) {
                (_, Some(d)) => Some(d),
                (LensFile::Prescription(p), None) => {
                    Some(p.image_distance_mm(a.object_distance_m * 1e3, DEFAULT_WAVELENGTH_NM)?)
                }
                (LensFile::Rtf(_), None) => None,
            };
            let cam = analysis::lens_camera(lens, film, None, DEFAULT_WAVELENGTH_NM)?;
            let z_obj = cam.front_vertex_z_mm() + a.object_distance_m * 1e3;
            let field = a.field_mm.unwrap_or(0.0);
            let half =
                analysis::blur_half_width_um(cam.camera(), z_obj, field, DEFAULT_WAVELENGTH_NM);
            let w = (1.5 * half).max(2.0);
            let pos: Vec<f64> = (0..=200).map(|k| -w + 2.0 * w * k as f64 / 200.0).collect();
            let esf = analysis::edge_spread(
                cam.camera(),
                z_obj,
                field,
                &pos,
                DEFAULT_WAVELENGTH_NM,
                128,
            )?;
            out.push_str("position_um,esf,lsf\n");
            for (p, (e, l)) in pos.iter().zip(esf) {
                out.push_str(&format!("{p},{e},{l}\n"));
            }
        }
        LensCmd::FitRtf(a) => {
            let lens = analysis::load_lens(&a.prescription)?;
            let LensFile::Prescription(p) = lens else {
                return Err(Error::Invalid(format!(
                    "{}: fit-rtf needs a lens prescription, not an RTF",
                    a.prescription.display()
                )));
            };
            let waves = if a.wavelengths.is_empty() {
                vec![DEFAULT_WAVELENGTH_NM]
            } else {
                a.wavelengths.clone()
            };
            let pass_method = match a.pass_method.as_str() {
                "ellipses" | "ellipse" | "minimalellipse" => {
                    camsim::optics::fit::PassMethod::Ellipses
                }
                "area-ellipses" => camsim::optics::fit::PassMethod::AreaEllipses,
                "circles" => camsim::optics::fit::PassMethod::Circles,
                other => {
                    return Err(Error::Invalid(format!(
                        "--pass: expected 'circles', 'ellipses' or 'area-ellipses', got '{other}'"
                    )));
                }
            };
            let sampling = match a.sampling.as_str() {
                "film-bundles" => camsim::optics::fit::DataSampling::FilmBundles,
                "input-plane" => camsim::optics::fit::DataSampling::InputPlane,
                other => {
                    return Err(Error::Invalid(format!(
                        "--sampling: expected 'film-bundles' or 'input-plane', got '{other}'"
                    )));
                }
            };
            let focus_distances_f = a
                .focus_distances_f
                .iter()
                .map(|t| match t.trim() {
                    "inf" | "infinity" => Ok(f64::INFINITY),
                    v => v.parse::<f64>().map_err(|_| {
                        Error::Invalid(format!(
                            "--focus-distances-f: expected numbers of focal lengths or 'inf', got '{v}'"
                        ))
                    }),
                })
                .collect::<Result<Vec<f64>>>()?;
            let opts = camsim::optics::fit::FitOptions {
                degree: a.degree,
                pass_method,
                sampling,
                focus_distances_f,
                axis_weight: a.axis_weight,
                ..Default::default()
            };
            let (rtf, reports) = camsim::optics::fit::fit_rtf(&p, &waves, &opts)?;
            let text = serde_json::to_string_pretty(&rtf.to_json())
                .map_err(|e| Error::Invalid(e.to_string()))?;
            camsim::diag::write_atomic(&a.out, text.as_bytes())?;
            // How good the fit is in image terms (stderr; stdout is the CSV).
            let v = analysis::validate_rtf(&p, &rtf, waves[0])?;
            let pct = |x: f64| {
                if x.is_finite() {
                    format!("{:.2} %", 100.0 * x)
                } else {
                    "no light".into()
                }
            };
            eprintln!(
                "fit-rtf: RTF vs prescription at {} nm: relative illumination max |error| {:.4} \
                 (0–95 % of the film radius); geometric ESF RMSE, object {:.0} mm away, on axis {}, \
                 at 25/50/75 % of the film radius {} / {} / {}",
                v.wavelength_nm,
                v.ri_max_abs_err,
                v.object_mm,
                pct(v.esf_rmse[0]),
                pct(v.esf_rmse[1]),
                pct(v.esf_rmse[2]),
                pct(v.esf_rmse[3])
            );
            out.push_str("wavelength_nm,output,degree,n_terms,n_samples,condition_number,rms_residual,max_residual\n");
            for r in reports {
                out.push_str(&format!(
                    "{},{},{},{},{},{},{},{}\n",
                    r.wavelength_nm,
                    r.output,
                    r.degree,
                    r.n_terms,
                    r.n_samples,
                    r.condition_number,
                    r.rms_residual,
                    r.max_residual
                ));
            }
        }
    }
    print!("{out}");
    Ok(0)
}
