//! `trade.png`: the trade study's Pareto plot, error (L1) against render cost, one labelled
//! point per BRDF model, the Pareto front joined by a line. Drawn with plotters into an RGB
//! buffer, text in the embedded DejaVu Sans (no system fonts needed), written as a PNG.

use std::path::Path;
use std::sync::Once;

use anyhow::anyhow;
use photomat_core::image_io::{PlanarImage, PngBits, write_png};
use plotters::prelude::*;
use plotters::style::FontStyle;

use super::report::{TradeReport, cost_of};

/// Size of the plot in pixels.
pub const PLOT_SIZE: (u32, u32) = (960, 640);
/// Vertical offsets tried for a point's label, in pixels from the point (above, below, …).
const LABEL_OFFSETS: [i32; 6] = [-22, 8, -44, 30, -66, 52];
/// Height of a label's box, in pixels.
const LABEL_HEIGHT: i32 = 18;
/// The font family name the plot's text asks for.
const FONT: &str = "sans-serif";

/// Registers the embedded font once per process.
fn register_font() -> anyhow::Result<()> {
    static ONCE: Once = Once::new();
    let mut result = Ok(());
    ONCE.call_once(|| {
        result = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular())
            .map_err(|_| anyhow!("the embedded DejaVu Sans font could not be read"));
    });
    result
}

/// Writes the Pareto plot of `report` to `path`.
pub fn write_pareto_plot(path: &Path, report: &TradeReport) -> anyhow::Result<()> {
    register_font()?;
    let (width, height) = PLOT_SIZE;
    let mut buffer = vec![255u8; (width * height * 3) as usize];
    draw(&mut buffer, report).map_err(|e| anyhow!("cannot draw {}: {e}", path.display()))?;
    let pixels = (width * height) as usize;
    let mut planar = vec![0.0f32; 3 * pixels];
    for (i, rgb) in buffer.chunks_exact(3).enumerate() {
        for c in 0..3 {
            planar[c * pixels + i] = rgb[c] as f32 / 255.0;
        }
    }
    let image = PlanarImage::new(3, height as usize, width as usize, planar)?;
    write_png(path, &image, PngBits::Eight)?;
    Ok(())
}

fn draw(buffer: &mut [u8], report: &TradeReport) -> Result<(), Box<dyn std::error::Error>> {
    let root = BitMapBackend::with_buffer(buffer, PLOT_SIZE).into_drawing_area();
    root.fill(&WHITE)?;
    let points: Vec<(f64, f64, &str, bool)> = report
        .entries
        .iter()
        .map(|e| (cost_of(e), e.accuracy.l1_mean, e.spec.as_str(), e.pareto))
        .collect();
    let (x_min, x_max, y_max) = points
        .iter()
        .fold((f64::INFINITY, 0.0f64, 0.0f64), |(lo, hi, y), p| {
            (lo.min(p.0), hi.max(p.0), y.max(p.1))
        });
    // The costs' own range with room for the labels (models' costs are often within a few
    // tens of percent of each other, which an axis from 0 would squeeze together); the floors
    // keep a range when there is one point.
    let x_bottom = (x_min * 0.9).max(0.0);
    let x_top = (x_max * 1.3).max(x_bottom + 1e-3);
    let y_top = (y_max * 1.25).max(1e-4);
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "BRDF models: error against render cost (lower left is better)",
            (FONT, 24),
        )
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(70)
        .build_cartesian_2d(x_bottom..x_top, 0.0..y_top)?;
    chart
        .configure_mesh()
        .x_desc("flash render, ms per megatexel (this machine)")
        .y_desc("L1 of analytic vs neural render")
        .label_style((FONT, 16))
        .axis_desc_style((FONT, 18))
        .draw()?;
    let front: Vec<(f64, f64)> = points.iter().filter(|p| p.3).map(|p| (p.0, p.1)).collect();
    chart.draw_series(LineSeries::new(front, BLUE.stroke_width(2)))?;
    // Labels right of their points, each at the first vertical offset whose box overlaps no
    // label placed before it (close costs and errors would otherwise print over each other).
    let mut placed: Vec<(i32, i32, i32, i32)> = Vec::new();
    for &(x, y, label, pareto) in &points {
        let color = if pareto { BLUE } else { RED };
        let (px, py) = chart.backend_coord(&(x, y));
        // DejaVu Sans at 16 px: about 9 px per character, 18 px per line.
        let width = 9 * label.chars().count() as i32;
        let dy = LABEL_OFFSETS
            .iter()
            .copied()
            .find(|&dy| {
                let (left, top) = (px + 10, py + dy);
                !placed.iter().any(|&(l, t, r, b)| {
                    left < r && l < left + width && top < b && t < top + LABEL_HEIGHT
                })
            })
            .unwrap_or(LABEL_OFFSETS[0]);
        placed.push((px + 10, py + dy, px + 10 + width, py + dy + LABEL_HEIGHT));
        let marker = EmptyElement::at((x, y))
            + Circle::new((0, 0), 6, color.filled())
            + Text::new(
                label.to_string(),
                (10, dy),
                (FONT, 16).into_font().color(&BLACK),
            );
        chart.draw_series(std::iter::once(marker))?;
    }
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trade::TradeSettings;
    use crate::trade::cost::{MapBytes, RenderCost};
    use crate::trade::report::{Accuracy, Cost, TradeEntry};

    #[test]
    fn the_plot_is_a_png_of_the_stated_size_with_something_drawn() {
        let entry = |spec: &str, cost: f64, l1: f64| TradeEntry {
            spec: spec.into(),
            channels: 3,
            estimator_dir: String::new(),
            reused: false,
            accuracy: Accuracy::new(vec![l1], vec![0.9], 1),
            cost: Cost {
                render: RenderCost {
                    eval_ms_per_megatexel: cost,
                    eval_grad_ms_per_megatexel: cost,
                },
                estimator_parameters: 1,
                step_seconds: 0.1,
                map_bytes: MapBytes { png: 1, exr: 1 },
            },
            pareto: false,
        };
        let report = TradeReport::new(
            TradeSettings::new("g".into(), vec![], "c".into()),
            vec![],
            vec![entry("lambert", 5.0, 0.05), entry("ggx", 20.0, 0.03)],
        );
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("trade.png");
        write_pareto_plot(&path, &report).unwrap();
        let (image, _) = photomat_core::image_io::read_png(&path).unwrap();
        assert_eq!((image.width, image.height), (960, 640));
        let dark = (0..image.texels())
            .filter(|&i| {
                let (_, r, c) = image.position(i);
                image.get(0, r, c) < 0.5
            })
            .count();
        assert!(
            dark > 1000,
            "only {dark} dark pixels: axes, labels and points missing"
        );
    }
}
