//! `impostor evaluate`: the independent check of a placement, written as
//! JSON; exit 4 when the guarantee is broken.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use optimizer::api::placement::Placement;
use optimizer::evaluate::EvalOptions;
use optimizer::evaluate::images::{ImageOptions, LayerSource, MAX_IMAGE_VIEWS};
use optimizer::files::{MAX_LOCAL_PLACEMENT_BYTES, MAX_SCENE_BYTES, read_file, read_json};
use optimizer::input::GeometryUse;
use optimizer::{Error, Result};

use crate::output::{write_json, write_output};
use crate::{SceneJob, read_job};

#[derive(Args)]
pub struct EvaluateArgs {
    #[command(flatten)]
    input: SceneJob,
    /// Placement JSON written by `place`.
    #[arg(long)]
    placement: PathBuf,
    /// Output evaluation JSON (default: standard output).
    #[arg(short, long)]
    out: Option<PathBuf>,
    /// Number of random views over the view space.
    #[arg(long, default_value_t = 10_000)]
    views: u64,
    /// Number of random views inside problem views (default: --views).
    #[arg(long)]
    cpv_views: Option<u64>,
    /// Seed of the view sampler.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Also render this many views in CPVs with impostors twice (all
    /// geometry; geometry with the impostors) and report the image error.
    /// At most 10,000 (each view takes about a second).
    #[arg(long, default_value_t = 0,
          value_parser = clap::value_parser!(u32).range(0..=i64::from(MAX_IMAGE_VIEWS)))]
    images: u32,
    /// Baked impostors (GLB from `bake`) for --images; default: bake in memory.
    #[arg(long)]
    impostors: Option<PathBuf>,
    /// Per-channel colour tolerance (0–255) of the image mismatch test.
    #[arg(long, default_value_t = 24)]
    tolerance: u8,
    /// Smallest share of the image a view's impostor pixels must cover for
    /// the view to be compared (--images).
    #[arg(long, default_value_t = 0.01)]
    min_coverage: f64,
    /// Write the worst view's renders and their difference side by side as a PNG
    /// (worst_view.png) into this directory.
    #[arg(long)]
    dump: Option<PathBuf>,
    /// Visibility check: rays per view through the image (0: none).
    #[arg(long, default_value_t = 256)]
    check_rays: u32,
    /// Visibility check: culled objects in the view probed per view.
    #[arg(long, default_value_t = 16)]
    check_objects: u32,
}

/// Reads a placement file, parsing it as it is read.
pub fn read_placement(path: &std::path::Path) -> Result<Placement> {
    read_json(path, MAX_LOCAL_PLACEMENT_BYTES, "placement")
}

pub fn run(a: EvaluateArgs) -> Result<ExitCode> {
    let job = read_job(&a.input.job)?;
    let geometry = if a.images > 0 {
        GeometryUse::Required
    } else {
        GeometryUse::ForChecks
    };
    let input = a.input.load(&job, geometry)?;
    let prepared = input.prepare(&job, &a.input.job_name())?;
    let name = a.placement.display().to_string();
    let p = read_placement(&a.placement)?;
    let opts = EvalOptions {
        views: a.views,
        cpv_views: a.cpv_views.unwrap_or(a.views),
        seed: a.seed,
        check_rays: a.check_rays,
        check_objects: a.check_objects,
    };
    let mut eval = prepared.evaluate(&p, &opts, &name)?;
    if let Some(v) = &eval.visibility {
        eprintln!(
            "visibility {:?}: {} cells, {:.1} visible objects per view ({:.2} %), \
             {} missed objects over {} checked views ({} rays)",
            v.mode,
            v.cells,
            v.mean_visible_objects,
            100.0 * v.mean_visible_fraction,
            v.missed_objects,
            v.views_checked,
            v.rays
        );
    }
    if let Some(x) = eval.parallax.as_ref().filter(|x| x.impostors > 0) {
        eprintln!(
            "parallax of {} impostors: max {:.2} px (impostor {}), mean {:.2} px, \
             {} over the {} px budget ({} over 1.5 times it)",
            x.impostors,
            x.max_px,
            x.worst_impostor,
            x.mean_px,
            x.over_budget,
            x.max_error_px,
            x.over_budget_1_5
        );
    }
    if let Some(x) = &eval.parallax
        && x.view_independent > 0
    {
        eprintln!(
            "{} view-independent impostors (valid from every direction) are not in the parallax check",
            x.view_independent
        );
    }
    if a.images > 0 {
        let glb = match &a.impostors {
            Some(path) => Some((
                read_file(path, MAX_SCENE_BYTES, "GLB of impostors")?,
                path.display().to_string(),
            )),
            None => None,
        };
        let layers = match &glb {
            Some((bytes, name)) => LayerSource::Glb { bytes, name },
            None => LayerSource::Bake,
        };
        let opts = ImageOptions {
            views: a.images,
            seed: a.seed,
            tolerance: a.tolerance,
            min_coverage: a.min_coverage,
        };
        let (report, pair) = prepared.image_error(&p, layers, &opts, &name)?;
        eprintln!(
            "{} image views ({} left out, their impostors under {:.1} % of the image), \
             impostors on {:.2} % of the image: over their pixels PSNR mean {:.2} dB \
             (min {:.2}), footprint mismatch mean {:.4} (p95 {:.4}, max {:.4}); control with \
             magenta layers: mismatch mean {:.4}",
            report.views,
            report.views_below_coverage,
            100.0 * report.min_coverage,
            100.0 * report.impostor_pixel_fraction,
            report.psnr_db.mean,
            report.psnr_db.min,
            report.footprint_mismatch_fraction.mean,
            report.footprint_mismatch_fraction.p95,
            report.footprint_mismatch_fraction.max,
            report.control_mismatch_fraction.mean
        );
        if report.views == 0 {
            eprintln!(
                "image check: no view shows enough impostor pixels; it proves nothing \
                 (the largest impostor covers at most {:.2} % of a view from the problem \
                 views that use it)",
                100.0 * report.largest_impostor_fraction
            );
        } else if report.control_mismatch_fraction.mean
            <= 2.0 * report.footprint_mismatch_fraction.mean
        {
            eprintln!(
                "image check: the magenta control mismatches hardly more than the impostors; \
                 it proves little"
            );
        }
        if let (Some(dir), Some(pair)) = (&a.dump, pair) {
            std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
            write_output(Some(&dir.join("worst_view.png")), &pair.side_by_side_png()?)?;
        }
        eval.image = Some(report);
    }
    write_json(a.out.as_deref(), &eval)?;
    eprintln!(
        "{} views: max {:.3} ms, p99 {:.3} ms, {} violations ({} in solved); \
         {} views in problem views: {} violations in solved ones",
        eval.views,
        eval.max_ms,
        eval.p99_ms,
        eval.violations,
        eval.violations_in_solved,
        eval.cpv_views,
        eval.violations_in_cpv_views
    );
    let c = &eval.control;
    if eval.control_bites() {
        eprintln!(
            "control (the same views without impostors): {} + {} violations where the placement \
             claims the target, max {:.3} ms: the check could have failed",
            c.violations_in_solved, c.violations_in_cpv_views, c.max_ms
        );
    } else {
        eprintln!(
            "control (the same views without impostors): no violation either (max {:.3} ms): \
             this check proves nothing about the impostors; use a tighter target or more views",
            c.max_ms
        );
    }
    Ok(if eval.guarantee_broken() {
        ExitCode::from(4)
    } else {
        ExitCode::SUCCESS
    })
}
