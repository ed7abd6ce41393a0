//! PNG plots of the benchmark (plotters on a bitmap, text in DejaVu Sans Mono, embedded so
//! that no system font is needed): time against error with the Pareto front, and scaling with
//! volume size and channel count.

use std::path::{Path, PathBuf};
use std::sync::Once;

use plotters::prelude::*;

/// DejaVu Sans Mono (see `fonts/DejaVu-LICENSE.txt`).
const FONT: &[u8] = include_bytes!("fonts/DejaVuSansMono.ttf");
const FAMILY: &str = "sans-serif";

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        if plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_err() {
            tracing::warn!("the embedded plot font did not load; plots will have no text");
        }
    });
}

/// Why a plot could not be made: plotters failed to draw, or the PNG cannot be written
/// (the message names the file).
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// Plotters failed to draw.
    #[error("plotting")]
    Draw {
        /// What plotters said.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The drawn buffer does not hold the plot's pixels (a bug).
    #[error("plot buffer size")]
    BufferSize,
    /// The PNG cannot be written.
    #[error("{}: cannot write the plot", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: ::image::ImageError,
    },
}

/// A plotters error as a [`PlotError::Draw`].
fn err<E: std::error::Error + Send + Sync + 'static>(e: E) -> PlotError {
    PlotError::Draw {
        source: Box::new(e),
    }
}

/// Draws into an RGB buffer of `size` and writes it to `path` as PNG.
fn png(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>) -> Result<(), PlotError>,
) -> Result<(), PlotError> {
    register_font();
    let mut buf = vec![255u8; size.0 as usize * size.1 as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buf, size).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        draw(root.clone())?;
        root.present().map_err(err)?;
    }
    let img = ::image::RgbImage::from_raw(size.0, size.1, buf).ok_or(PlotError::BufferSize)?;
    img.save(path).map_err(|source| PlotError::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// Draws the legend of `chart` at `position` in DejaVu at `size` px, on a translucent white
/// box with a black border.
fn legend<'a, DB: DrawingBackend<ErrorType: 'static> + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
    size: u32,
) -> Result<(), PlotError> {
    chart
        .configure_series_labels()
        .position(position)
        .label_font((FAMILY, size))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(err)
}

/// One point of a time–error plot.
#[derive(Clone, Debug, PartialEq)]
pub struct TradeoffPoint {
    /// Short label drawn beside the point.
    pub label: String,
    /// Milliseconds per frame.
    pub ms: f64,
    /// PSNR in dB.
    pub psnr: f64,
    /// On the Pareto front.
    pub front: bool,
    /// The renderer's defaults.
    pub default: bool,
    /// The series it belongs to (the method), one colour and legend entry each.
    pub group: String,
}

/// Colours of a plot's series, in order (the tradeoff plot's methods, the scaling plots'
/// lines). No red: red marks the Pareto front.
const PALETTE: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(23, 190, 207),
];

fn padded(lo: f64, hi: f64) -> (f64, f64) {
    let (lo, hi) = if lo.is_finite() && hi.is_finite() {
        (lo, hi)
    } else {
        (0.0, 1.0)
    };
    let pad = ((hi - lo) * 0.08).max(1e-3 * hi.abs().max(1.0));
    (lo - pad, hi + pad)
}

/// Time against PSNR: every point, the Pareto front as a line, the defaults ringed.
///
/// # Errors
/// A [`PlotError`]: plotters failed, or the PNG cannot be written to `path`.
pub fn tradeoff(
    path: &Path,
    title: &str,
    x_desc: &str,
    points: &[TradeoffPoint],
) -> Result<(), PlotError> {
    let xs = points.iter().map(|p| p.ms);
    let ys = points.iter().map(|p| p.psnr);
    let (x0, x1) = padded(
        xs.clone().fold(f64::INFINITY, f64::min).min(0.0),
        xs.fold(f64::NEG_INFINITY, f64::max),
    );
    let (y0, y1) = padded(
        ys.clone().fold(f64::INFINITY, f64::min),
        ys.fold(f64::NEG_INFINITY, f64::max),
    );
    png(path, (900, 600), |root| {
        let mut chart = ChartBuilder::on(&root)
            .caption(title, (FAMILY, 18))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .y_desc("PSNR vs f64 reference (dB)")
            .label_style((FAMILY, 13))
            .draw()
            .map_err(err)?;
        let mut front: Vec<(f64, f64)> = points
            .iter()
            .filter(|p| p.front)
            .map(|p| (p.ms, p.psnr))
            .collect();
        front.sort_by(|a, b| a.0.total_cmp(&b.0));
        chart
            .draw_series(LineSeries::new(front, RED.stroke_width(2)))
            .map_err(err)?
            .label("Pareto front")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
        let mut groups: Vec<&str> = Vec::new();
        for p in points {
            if !groups.contains(&p.group.as_str()) {
                groups.push(&p.group);
            }
        }
        for (i, group) in groups.iter().enumerate() {
            let colour = PALETTE[i % PALETTE.len()];
            chart
                .draw_series(
                    points
                        .iter()
                        .filter(|p| p.group == *group)
                        .map(|p| Circle::new((p.ms, p.psnr), 4, colour.filled())),
                )
                .map_err(err)?
                .label(*group)
                .legend(move |(x, y)| Circle::new((x + 10, y), 4, colour.filled()));
        }
        chart
            .draw_series(
                points
                    .iter()
                    .filter(|p| p.front)
                    .map(|p| Circle::new((p.ms, p.psnr), 6, RED.stroke_width(2))),
            )
            .map_err(err)?;
        chart
            .draw_series(
                points
                    .iter()
                    .filter(|p| p.default)
                    .map(|p| Circle::new((p.ms, p.psnr), 9, BLACK.stroke_width(2))),
            )
            .map_err(err)?
            .label("defaults")
            .legend(|(x, y)| Circle::new((x + 10, y), 6, BLACK.stroke_width(2)));
        chart
            .draw_series(points.iter().map(|p| {
                Text::new(
                    p.label.clone(),
                    (p.ms, p.psnr),
                    (FAMILY, 12).into_font().color(&BLACK),
                )
            }))
            .map_err(err)?;
        legend(&mut chart, SeriesLabelPosition::LowerRight, 13)
    })
}

/// One series of a scaling plot: `(x, [ms, resident MB, fetched MB])` points.
#[derive(Clone, Debug, PartialEq)]
pub struct ScalingSeries {
    /// Legend label.
    pub label: String,
    /// Points, ascending in `x`.
    pub points: Vec<(f64, [f64; 3])>,
}

/// Draws the mesh, one line per series and the legend of panel `$i` of a scaling plot
/// (a macro because the linear and log charts have different coordinate types).
macro_rules! draw_lines {
    ($chart:ident, $i:ident, $x_desc:ident, $series:ident) => {{
        let mut chart = $chart;
        chart
            .configure_mesh()
            .x_desc($x_desc)
            .y_desc(PANELS[$i])
            .label_style((FAMILY, 12))
            .draw()
            .map_err(err)?;
        for (k, s) in $series.iter().enumerate() {
            let c = PALETTE[k % PALETTE.len()];
            let pts: Vec<(f64, f64)> = s.points.iter().map(|p| (p.0, p.1[$i])).collect();
            chart
                .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))
                .map_err(err)?
                .label(s.label.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2))
                });
            chart
                .draw_series(pts.into_iter().map(|p| Circle::new(p, 4, c.filled())))
                .map_err(err)?;
        }
        legend(&mut chart, SeriesLabelPosition::UpperLeft, 12)?;
    }};
}

const PANELS: [&str; 3] = [
    "ms / converged frame",
    "resident MB (bricks used)",
    "MB fetched (orbit)",
];

/// Three stacked panels (ms per frame, resident MB, fetched MB) against `x` (log scale when
/// `log_x`), one line per series.
///
/// # Errors
/// A [`PlotError`]: plotters failed, or the PNG cannot be written to `path`.
pub fn scaling(
    path: &Path,
    title: &str,
    x_desc: &str,
    log_x: bool,
    series: &[ScalingSeries],
) -> Result<(), PlotError> {
    let all: Vec<&(f64, [f64; 3])> = series.iter().flat_map(|s| &s.points).collect();
    let x_lo = all.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
    let x_hi = all.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
    png(path, (900, 1050), |root| {
        let root = root.titled(title, (FAMILY, 18)).map_err(err)?;
        let areas = root.split_evenly((3, 1));
        for (i, area) in areas.iter().enumerate() {
            let y_hi = all.iter().map(|p| p.1[i]).fold(0.0, f64::max);
            let y_hi = if y_hi > 0.0 { y_hi * 1.1 } else { 1.0 };
            let mut builder = ChartBuilder::on(area);
            builder
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(70);
            if log_x {
                let chart = builder
                    .build_cartesian_2d((x_lo / 1.5..x_hi * 1.5).log_scale(), 0.0..y_hi)
                    .map_err(err)?;
                draw_lines!(chart, i, x_desc, series);
            } else {
                let (lo, hi) = padded(x_lo, x_hi);
                let chart = builder.build_cartesian_2d(lo..hi, 0.0..y_hi).map_err(err)?;
                draw_lines!(chart, i, x_desc, series);
            }
        }
        Ok(())
    })
}

/// One line of a [`panels`] plot: its legend label and `(x, y)` points, ascending in `x`.
#[derive(Clone, Debug, PartialEq)]
pub struct Line {
    /// Legend label.
    pub label: String,
    /// Points, ascending in `x`.
    pub points: Vec<(f64, f64)>,
}

/// Panels stacked over a shared `x` axis (linear), each with its `y` description and lines.
///
/// # Errors
/// A [`PlotError`]: plotters failed, or the PNG cannot be written to `path`.
pub fn panels(
    path: &Path,
    title: &str,
    x_desc: &str,
    panels: &[(&str, Vec<Line>)],
) -> Result<(), PlotError> {
    let xs = panels
        .iter()
        .flat_map(|(_, lines)| lines.iter().flat_map(|l| l.points.iter().map(|p| p.0)));
    let (x_lo, x_hi) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
        (lo.min(x), hi.max(x))
    });
    let (x_lo, x_hi) = padded(x_lo, x_hi);
    png(path, (900, 380 * panels.len().max(1) as u32), |root| {
        let root = root.titled(title, (FAMILY, 18)).map_err(err)?;
        for (area, (y_desc, lines)) in root.split_evenly((panels.len(), 1)).iter().zip(panels) {
            let ys = lines.iter().flat_map(|l| l.points.iter().map(|p| p.1));
            let (y_lo, y_hi) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), y| {
                (lo.min(y), hi.max(y))
            });
            let (y_lo, y_hi) = padded(y_lo, y_hi);
            let mut chart = ChartBuilder::on(area)
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(70)
                .build_cartesian_2d(x_lo..x_hi, y_lo..y_hi)
                .map_err(err)?;
            chart
                .configure_mesh()
                .x_desc(x_desc)
                .y_desc(*y_desc)
                .label_style((FAMILY, 12))
                .draw()
                .map_err(err)?;
            for (k, line) in lines.iter().enumerate() {
                let c = PALETTE[k % PALETTE.len()];
                chart
                    .draw_series(LineSeries::new(line.points.clone(), c.stroke_width(2)))
                    .map_err(err)?
                    .label(line.label.clone())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2))
                    });
                chart
                    .draw_series(line.points.iter().map(|&p| Circle::new(p, 4, c.filled())))
                    .map_err(err)?;
            }
            legend(&mut chart, SeriesLabelPosition::UpperRight, 12)?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plots_are_written_as_png() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.png");
        let pts = vec![
            TradeoffPoint {
                label: "a".into(),
                ms: 1.0,
                psnr: 30.0,
                front: true,
                default: true,
                group: "residency".into(),
            },
            TradeoffPoint {
                label: "b".into(),
                ms: 2.0,
                psnr: 29.0,
                front: false,
                default: false,
                group: "sparseleap".into(),
            },
        ];
        tradeoff(&p, "t", "GPU ms", &pts).unwrap();
        assert_eq!(&std::fs::read(&p).unwrap()[1..4], b"PNG");
        let s = dir.path().join("s.png");
        let series = vec![ScalingSeries {
            label: "x".into(),
            points: vec![(1e3, [1.0, 2.0, 3.0]), (1e6, [2.0, 3.0, 4.0])],
        }];
        scaling(&s, "s", "voxels", true, &series).unwrap();
        scaling(&s, "s", "channels", false, &series).unwrap();
        assert_eq!(&std::fs::read(&s).unwrap()[1..4], b"PNG");
    }
}
