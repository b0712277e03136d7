//! The energy curve of a run (plotters: SVG, and PNG through its bitmap
//! backend with an embedded font).

use fshape_match::StageRecord;

use crate::ReportError;

type Result<T> = std::result::Result<T, ReportError>;

/// J, the energy and γ_W·A against the iteration number (log scale), all
/// stages one after the other, as (SVG text, PNG bytes).
pub fn energy_plot(stages: &[StageRecord], gamma_w: f64, title: &str) -> Result<(String, Vec<u8>)> {
    use plotters::prelude::*;
    let mut series: [Vec<(f64, f64)>; 3] = Default::default();
    let mut n = 0usize;
    for s in stages {
        for it in std::iter::once(&s.initial).chain(&s.iterations) {
            for (k, v) in [it.value, it.energy, gamma_w * it.attachment].into_iter().enumerate() {
                if v > 0.0 && v.is_finite() {
                    series[k].push((n as f64, v));
                }
            }
            n += 1;
        }
    }
    register_plot_font()?;
    let mut svg = String::new();
    draw_energy(SVGBackend::with_string(&mut svg, PLOT_SIZE).into_drawing_area(), &series, n, title)?;
    let mut rgb = vec![0u8; (PLOT_SIZE.0 * PLOT_SIZE.1 * 3) as usize];
    draw_energy(BitMapBackend::with_buffer(&mut rgb, PLOT_SIZE).into_drawing_area(), &series, n, title)?;
    let png = crate::render::png_sized(&rgb, PLOT_SIZE.0, PLOT_SIZE.1)?;
    Ok((svg, png))
}

const PLOT_SIZE: (u32, u32) = (720, 420);

/// The bitmap backend draws text with ab_glyph from a font registered at run
/// time; the font is embedded (assets/, DejaVu licence) so that a headless
/// machine without system fonts still labels its plots.
fn register_plot_font() -> Result<()> {
    static DONE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = DONE.get_or_init(|| {
        plotters::style::register_font(
            "sans-serif",
            plotters::style::FontStyle::Normal,
            include_bytes!("../assets/DejaVuSansMono.ttf"),
        )
        .is_ok()
    });
    if !*ok {
        return Err(ReportError::Plot("the embedded font assets/DejaVuSansMono.ttf did not load".into()));
    }
    Ok(())
}

fn draw_energy<DB: plotters::prelude::DrawingBackend>(
    root: plotters::drawing::DrawingArea<DB, plotters::coord::Shift>,
    series: &[Vec<(f64, f64)>; 3],
    n: usize,
    title: &str,
) -> Result<()> {
    use plotters::prelude::*;
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| ReportError::Plot(e.to_string());
    let all = series.iter().flatten().map(|p| p.1);
    let (lo, hi) = all.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    let (lo, hi) = if lo.is_finite() { (lo / 2.0, hi * 2.0) } else { (1e-3, 1.0) };
    root.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(&root)
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(64)
        .caption(title, ("sans-serif", 18))
        .build_cartesian_2d(0f64..(n.max(2) - 1) as f64, (lo..hi).log_scale())
        .map_err(err)?;
    // Iterations are whole numbers: label them so, at most 10 ticks.
    chart
        .configure_mesh()
        .x_desc("iteration")
        .x_labels(n.clamp(2, 11))
        .x_label_formatter(&|x| format!("{}", x.round() as i64))
        .draw()
        .map_err(err)?;
    // Lines and legend swatches two pixels wide, so that each swatch shows
    // its colour (a one-pixel blue swatch reads as black).
    for (k, (name, color)) in [("J", BLACK), ("energy H", BLUE), ("γ_W·A", RED)].into_iter().enumerate() {
        chart
            .draw_series(LineSeries::new(series[k].clone(), color.stroke_width(2)))
            .map_err(err)?
            .label(name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3)));
    }
    // Upper right: the curves start high on the left and fall (the y
    // range reaches twice their largest value), so the legend's default
    // middle-right place is where they run at the end.
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE)
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}
