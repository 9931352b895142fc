//! Per photo of a dataset with true highlights: the truth, both detectors' answers and the
//! robust detector's fitted flash model, as CSV on stdout. What `eval-detector` averages,
//! photo by photo, for finding the cases a detector gets wrong.
//!
//! `cargo run --release -p photomat-data --example detector_cases -- DATASET > cases.csv`

use photomat_data::dataset::FlashDataset;
use photomat_data::highlight::{HighlightDetector, PaperDetector, RobustDetector};

fn main() -> anyhow::Result<()> {
    let dir = std::env::args()
        .nth(1)
        .ok_or_else(|| anyhow::anyhow!("usage: detector_cases DATASET"))?;
    let dataset = FlashDataset::open(&dir)?;
    let (robust, paper) = (RobustDetector::default(), PaperDetector::default());
    println!(
        "photo,width,truth_row,truth_col,robust_row,robust_col,paper_row,paper_col,robust_err_pct,\
         paper_err_pct,disagree_pct,robust_status,alpha,vignetting,beam,diffuse,specular,ambient,\
         flash_share,misfit,fit_row,fit_col,fit_contrast,centroid_contrast,robust_reason"
    );
    for (i, entry) in dataset.photos().iter().enumerate() {
        let Some([row, col]) = entry.truth_highlight_px else {
            continue;
        };
        let image = dataset.load_image(i)?;
        let w = image.width as f64;
        let r = robust.detect(&image)?;
        let p = paper.detect(&image)?;
        let fit = robust.fit(&image)?;
        let pct = |e: f64| 100.0 * e / w;
        let fit_px = fit.map(|f| f.pixel(image.height, image.width));
        let fit_contrast = match fit_px {
            Some((r, c)) => Some(robust.local_contrast(&image, r, c)?),
            None => None,
        };
        let centroid_contrast = robust.local_contrast(&image, p.row, p.col)?;
        let f = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.4}"));
        println!(
            "{},{w},{row:.2},{col:.2},{:.2},{:.2},{:.2},{:.2},{:.3},{:.3},{:.3},{},{},{},{},{},{},{},{},{},{},{},{},{:.4},\"{}\"",
            entry.image,
            r.row,
            r.col,
            p.row,
            p.col,
            pct(r.error_px(row, col)),
            pct(p.error_px(row, col)),
            pct(r.error_px(p.row, p.col)),
            r.status,
            f(fit.map(|f| f.alpha)),
            f(fit.map(|f| f.vignetting)),
            f(fit.map(|f| f.beam)),
            f(fit.map(|f| f.coefficients[0])),
            f(fit.map(|f| f.coefficients[1])),
            f(fit.map(|f| f.coefficients[2])),
            f(fit.map(|f| f.flash_share)),
            f(fit.map(|f| f.misfit)),
            f(fit_px.map(|p| p.0)),
            f(fit_px.map(|p| p.1)),
            f(fit_contrast),
            centroid_contrast,
            r.reason.as_deref().unwrap_or("").replace('"', "'"),
        );
    }
    Ok(())
}
