//! The one plotting module of the tools (`plotters`, SVG backend): every command's plots go
//! through [`Plot::write_svg`].
//!
//! What every plot gets: a title saying what was run, axis labels with units (a log axis says
//! so in its label), ticks at round numbers (1, 2, 5 × 10ⁿ, printed without spurious digits),
//! a legend with a line or marker sample per series, a grid, and a robust range: when a few
//! points lie far outside the bulk of the data, the range is set by the bulk (0.5 % … 99.5 %
//! quantiles, widened by a quarter of their span) and the outliers are drawn on the frame as
//! red triangles, counted in the legend. A time window (`--window`) zooms on an event.
//! Faulted points (a sweep's runs that latched a fault) are drawn as red crosses.
//! A map (the regime study's) is drawn as [`Cells`]: filled rectangles, one colour and one
//! legend entry per class, under the series.
//!
//! The SVG text is left to the viewer's sans-serif font, so no font ships with the tools; the
//! PNGs under `docs/figures/` are rendered from these SVGs with `resvg` and the DejaVu Sans
//! file the render test loads.

use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::{Path, PathBuf};

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Style {
    Line,
    Markers,
    /// A line with a marker at every point.
    LineMarkers,
    /// Small filled dots (scatter of thousands of points).
    Dots,
}

/// One series: its legend name, its points, how it is drawn, and which points faulted
/// (empty = none).
#[derive(Clone, Debug)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    pub style: Style,
    pub faulted: Vec<bool>,
    /// Line width, px (default: 3 for the first two series, thinner after).
    pub width: Option<u32>,
}

impl Series {
    pub fn line(name: impl Into<String>, points: Vec<(f64, f64)>) -> Series {
        Series {
            name: name.into(),
            points,
            style: Style::Line,
            faulted: Vec::new(),
            width: None,
        }
    }
    pub fn markers(name: impl Into<String>, points: Vec<(f64, f64)>) -> Series {
        Series {
            style: Style::Markers,
            ..Series::line(name, points)
        }
    }
    pub fn dots(name: impl Into<String>, points: Vec<(f64, f64)>) -> Series {
        Series {
            style: Style::Dots,
            ..Series::line(name, points)
        }
    }
}

/// One class of a map: filled rectangles `[x0, y0, x1, y1]` in data coordinates, drawn in
/// `colour` (RGB) with a legend entry `name`.
#[derive(Clone, Debug)]
pub struct Cells {
    pub name: String,
    pub colour: (u8, u8, u8),
    pub rects: Vec<[f64; 4]>,
}

/// A mark on a plot, with its legend entry: a vertical dashed line at `x` (an event: the
/// settle time), or a star at a point (an optimum).
#[derive(Clone, Debug)]
pub enum Mark {
    VLine {
        x: f64,
        label: String,
    },
    Star {
        at: (f64, f64),
        label: String,
    },
    /// A labelled point (a spectral peak a report names): a small triangle over it and its
    /// label above; every peak of a plot shares one legend entry, [`Plot::peak_legend`].
    Peak {
        at: (f64, f64),
        label: String,
    },
}

/// A plot: title, axis labels (with units), axes, series, and an optional x window.
#[derive(Clone, Debug)]
pub struct Plot {
    pub title: String,
    pub xlabel: String,
    pub ylabel: String,
    pub xlog: bool,
    pub ylog: bool,
    pub series: Vec<Series>,
    /// Show only x in [a, b] (the y range follows the data inside).
    pub window: Option<(f64, f64)>,
    /// Width and height, px.
    pub size: (u32, u32),
    /// Map cells drawn under the series (they set the ranges with the series' points).
    pub cells: Vec<Cells>,
    /// Fixed y range (default: the robust range of the data).
    pub y_range: Option<(f64, f64)>,
    /// Series colours (RGB) in place of the default palette, by series index.
    pub colours: Vec<(u8, u8, u8)>,
    /// Legend text of the faulted points' mark.
    pub fault_label: String,
    /// Marks drawn over the series ([`Mark`]).
    pub marks: Vec<Mark>,
    /// Legend text of the [`Mark::Peak`]s.
    pub peak_legend: String,
}

const COLOURS: [RGBColor; 6] = [
    RGBColor(0x1f, 0x77, 0xb4),
    RGBColor(0xff, 0x7f, 0x0e),
    RGBColor(0x2c, 0xa0, 0x2c),
    RGBColor(0x94, 0x67, 0xbd),
    RGBColor(0x8c, 0x56, 0x4b),
    RGBColor(0x17, 0xbe, 0xcf),
];
const FAULT: RGBColor = RGBColor(0xd6, 0x27, 0x28);
const MARK: RGBColor = RGBColor(0x33, 0x33, 0x33);

impl Plot {
    pub fn new(
        title: impl Into<String>,
        xlabel: impl Into<String>,
        ylabel: impl Into<String>,
    ) -> Plot {
        Plot {
            title: title.into(),
            xlabel: xlabel.into(),
            ylabel: ylabel.into(),
            xlog: false,
            ylog: false,
            series: Vec::new(),
            window: None,
            size: (900, 540),
            cells: Vec::new(),
            y_range: None,
            colours: Vec::new(),
            fault_label: "fault latched".into(),
            marks: Vec::new(),
            peak_legend: "peak named by the report".into(),
        }
    }

    /// Render to SVG text.
    pub fn svg(&self) -> Result<String, String> {
        let mut text = String::new();
        {
            let root = SVGBackend::with_string(&mut text, self.size).into_drawing_area();
            self.draw(&root)?;
            root.present()
                .map_err(|e| format!("plot `{}`: {e}", self.title))?;
        }
        Ok(without_repeated_text(&text))
    }

    /// Render and write to `path` (its directory is created); the error names the path.
    pub fn write_svg(&self, path: &Path) -> Result<PathBuf, String> {
        let text = self.svg()?;
        crate::cli::output::write(path, &text)?;
        Ok(path.to_path_buf())
    }

    /// The points inside the window (all finite points without one; a log axis keeps > 0).
    fn visible(&self, s: &Series) -> Vec<(f64, f64, bool)> {
        s.points
            .iter()
            .enumerate()
            .filter(|(_, p)| p.0.is_finite() && p.1.is_finite())
            .filter(|(_, p)| (!self.xlog || p.0 > 0.0) && (!self.ylog || p.1 > 0.0))
            .filter(|(_, p)| self.window.is_none_or(|(a, b)| p.0 >= a && p.0 <= b))
            .map(|(k, p)| (p.0, p.1, s.faulted.get(k).copied().unwrap_or(false)))
            .collect()
    }

    fn draw(&self, root: &DrawingArea<SVGBackend, plotters::coord::Shift>) -> Result<(), String> {
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let pts: Vec<Vec<(f64, f64, bool)>> = self.series.iter().map(|s| self.visible(s)).collect();
        let mut xs: Vec<f64> = pts.iter().flatten().map(|p| p.0).collect();
        // Faulted points do not set the range (a run that tripped says nothing about the
        // scale of the others): they are drawn on the frame when outside it.
        let mut ys: Vec<f64> = pts.iter().flatten().filter(|p| !p.2).map(|p| p.1).collect();
        let corners = self.cells.iter().flat_map(|c| c.rects.iter());
        for r in corners {
            xs.extend([r[0], r[2]]);
            ys.extend([r[1], r[3]]);
        }
        let (x0, x1) = match self.window {
            Some((a, b)) => (a, b),
            // A map fills its frame.
            None if !self.cells.is_empty() => bounds(&xs),
            None => full_range(&xs, self.xlog),
        };
        let (y0, mut y1) = match self.y_range {
            Some(r) => r,
            None if !self.cells.is_empty() => bounds(&ys),
            None => robust_range(&ys, self.ylog),
        };
        // Room for the peaks' labels above the highest peak.
        let top = self
            .marks
            .iter()
            .filter_map(|m| match m {
                Mark::Peak { at, .. } if at.1.is_finite() => Some(at.1),
                _ => None,
            })
            .fold(f64::NEG_INFINITY, f64::max);
        if self.y_range.is_none() && top.is_finite() {
            if self.ylog && top > 0.0 && y0 > 0.0 {
                y1 = y1.max(top * (top / y0).powf(0.15));
            } else if !self.ylog {
                y1 = y1.max(top + 0.15 * (top - y0));
            }
        }
        // When every corner the legend could take holds data, room is made for it above the
        // data (a linear y axis whose range the data set).
        if self.y_range.is_none() && self.cells.is_empty() && !self.ylog && !self.series.is_empty()
        {
            let counts = self.corner_counts(&pts, (x0, x1), (y0, y1));
            if counts.iter().all(|&c| c > 0) {
                let f = self.legend_fraction();
                y1 += (y1 - y0) * f / (1.0 - f);
            }
        }
        match (self.xlog, self.ylog) {
            (false, false) => self.chart(root, x0..x1, y0..y1, &pts),
            (true, false) => self.chart(root, (x0..x1).log_scale(), y0..y1, &pts),
            (false, true) => self.chart(root, x0..x1, (y0..y1).log_scale(), &pts),
            (true, true) => self.chart(root, (x0..x1).log_scale(), (y0..y1).log_scale(), &pts),
        }
    }

    fn chart<'a, X, Y>(
        &self,
        root: &DrawingArea<SVGBackend<'a>, plotters::coord::Shift>,
        xr: X,
        yr: Y,
        pts: &[Vec<(f64, f64, bool)>],
    ) -> Result<(), String>
    where
        X: AsRangedCoord<Value = f64>,
        Y: AsRangedCoord<Value = f64>,
        X::CoordDescType: ValueFormatter<f64>,
        Y::CoordDescType: ValueFormatter<f64>,
    {
        let e = |e: DrawingAreaErrorKind<_>| format!("plot `{}`: {e}", self.title);
        let mut ch = ChartBuilder::on(root)
            .caption(&self.title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(48)
            .y_label_area_size(78)
            .build_cartesian_2d(xr, yr)
            .map_err(e)?;
        let (xd, yd) = (ch.x_range(), ch.y_range());
        let (xlo, xhi) = (xd.start, xd.end);
        let (ylo, yhi) = (yd.start, yd.end);
        // Map cells first: the grid is drawn over them.
        for c in &self.cells {
            let col = RGBColor(c.colour.0, c.colour.1, c.colour.2);
            ch.draw_series(c.rects.iter().map(|r| {
                Rectangle::new(
                    [
                        (r[0].clamp(xlo, xhi), r[1].clamp(ylo, yhi)),
                        (r[2].clamp(xlo, xhi), r[3].clamp(ylo, yhi)),
                    ],
                    col.filled(),
                )
            }))
            .map_err(e)?
            .label(&c.name)
            .legend(move |(x, y)| Rectangle::new([(x + 4, y - 6), (x + 20, y + 6)], col.filled()));
        }
        ch.configure_mesh()
            .x_desc(&self.xlabel)
            .y_desc(&self.ylabel)
            .x_labels(if self.xlog { LOG_KEYS } else { 8 })
            .y_labels(if self.ylog { LOG_KEYS } else { 8 })
            // A log axis already has a line at every integer multiple.
            .x_max_light_lines(if self.xlog { 0 } else { 4 })
            .y_max_light_lines(if self.ylog { 0 } else { 4 })
            .x_label_formatter(&|v| log_tick(self.xlog, snap(*v, xlo, xhi)))
            .y_label_formatter(&|v| log_tick(self.ylog, snap(*v, ylo, yhi)))
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 15))
            // A map's cells are not crossed by the fine grid.
            .light_line_style(if self.cells.is_empty() {
                RGBColor(0xee, 0xee, 0xee).to_rgba()
            } else {
                TRANSPARENT
            })
            .bold_line_style(RGBColor(0xcc, 0xcc, 0xcc))
            .draw()
            .map_err(e)?;
        let clamp = |p: (f64, f64)| (p.0.clamp(xlo, xhi), p.1.clamp(ylo, yhi));
        let corner = self.legend_corner(pts, (xlo, xhi), (ylo, yhi));
        let mut any_fault = false;
        let mut outliers = Vec::new();
        for (k, (s, p)) in self.series.iter().zip(pts).enumerate() {
            let c = self
                .colours
                .get(k)
                .map_or(COLOURS[k % COLOURS.len()], |&(r, g, b)| RGBColor(r, g, b));
            let shape = k % 3;
            let line = matches!(s.style, Style::Line | Style::LineMarkers);
            let marks = matches!(s.style, Style::Markers | Style::LineMarkers);
            let dots = s.style == Style::Dots;
            // Later series are drawn thinner so one lying on another leaves both visible.
            let width = match s.width {
                Some(w) => w,
                None if line => 3usize.saturating_sub(k / 2).max(1) as u32,
                None => 2,
            };
            // A point within 10⁻⁶ of the span from the frame (a zero computed as −1e-15) is on
            // it, not beyond it.
            let tol = 1e-6 * (yhi - ylo).abs();
            for q in p {
                if q.1 < ylo - tol || q.1 > yhi + tol {
                    outliers.push(clamp((q.0, q.1)));
                }
            }
            // Lines after the second are dashed, so a line lying on another leaves both
            // visible.
            let dashed = line && k >= 2;
            if line && !dashed {
                ch.draw_series(LineSeries::new(
                    p.iter().map(|q| clamp((q.0, q.1))),
                    c.stroke_width(width),
                ))
                .map_err(e)?;
            }
            if dashed {
                ch.draw_series(DashedLineSeries::new(
                    p.iter().map(|q| clamp((q.0, q.1))),
                    8,
                    6,
                    c.stroke_width(width),
                ))
                .map_err(e)?;
            }
            if s.style == Style::Dots {
                ch.draw_series(
                    p.iter()
                        .map(|q| Circle::new(clamp((q.0, q.1)), 1, c.filled())),
                )
                .map_err(e)?;
            }
            if marks {
                let at = p.iter().map(|q| clamp((q.0, q.1)));
                match shape {
                    0 => ch
                        .draw_series(at.map(|q| Circle::new(q, 4, c.stroke_width(2))))
                        .map(|_| ()),
                    1 => ch
                        .draw_series(at.map(|q| TriangleMarker::new(q, 5, c.stroke_width(2))))
                        .map(|_| ()),
                    _ => ch
                        .draw_series(at.map(|q| Cross::new(q, 4, c.stroke_width(2))))
                        .map(|_| ()),
                }
                .map_err(e)?;
            }
            // The legend entry: a line sample (two dashes for a dashed line), or a marker
            // sample for markers alone.
            let anno = ch
                .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
                .map_err(e)?
                .label(&s.name);
            let st = c.stroke_width(if line { width } else { 2 });
            if dashed {
                anno.legend(move |(x, y)| {
                    EmptyElement::at((x, y))
                        + PathElement::new(vec![(0, 0), (9, 0)], st)
                        + PathElement::new(vec![(15, 0), (24, 0)], st)
                });
            } else {
                anno.legend(move |(x, y)| match (line, shape) {
                    (true, _) => PathElement::new(vec![(x, y), (x + 24, y)], st).into_dyn(),
                    (false, _) if dots => Circle::new((x + 12, y), 3, c.filled()).into_dyn(),
                    (false, 0) => Circle::new((x + 12, y), 4, st).into_dyn(),
                    (false, 1) => TriangleMarker::new((x + 12, y), 5, st).into_dyn(),
                    (false, _) => Cross::new((x + 12, y), 4, st).into_dyn(),
                });
            }
            let bad: Vec<(f64, f64)> = p
                .iter()
                .filter(|q| q.2)
                .map(|q| clamp((q.0, q.1)))
                .collect();
            if !bad.is_empty() {
                any_fault = true;
                ch.draw_series(bad.iter().map(|&q| Cross::new(q, 8, FAULT.stroke_width(3))))
                    .map_err(e)?;
            }
        }
        if any_fault {
            ch.draw_series(std::iter::empty::<Cross<(f64, f64), i32>>())
                .map_err(e)?
                .label(&self.fault_label)
                .legend(|(x, y)| Cross::new((x + 12, y), 6, FAULT.stroke_width(3)));
        }
        if !outliers.is_empty() {
            let n = outliers.len();
            ch.draw_series(
                outliers
                    .into_iter()
                    .map(|q| TriangleMarker::new(q, 6, FAULT.filled())),
            )
            .map_err(e)?
            .label(format!("{n} point(s) beyond the range, drawn on the frame"))
            .legend(|(x, y)| TriangleMarker::new((x + 12, y), 6, FAULT.filled()));
        }
        for m in &self.marks {
            match m {
                Mark::VLine { x, label } if *x >= xlo && *x <= xhi => {
                    ch.draw_series(DashedLineSeries::new(
                        [(*x, ylo), (*x, yhi)],
                        6,
                        4,
                        MARK.stroke_width(1),
                    ))
                    .map_err(e)?
                    .label(label)
                    .legend(|(x, y)| {
                        EmptyElement::at((x, y))
                            + PathElement::new(vec![(12, -7), (12, -2)], MARK.stroke_width(1))
                            + PathElement::new(vec![(12, 2), (12, 7)], MARK.stroke_width(1))
                    });
                }
                Mark::Star { at, label } => {
                    ch.draw_series(std::iter::once(
                        EmptyElement::at(clamp(*at)) + Polygon::new(star(9), MARK.filled()),
                    ))
                    .map_err(e)?
                    .label(label)
                    .legend(|(x, y)| {
                        EmptyElement::at((x + 12, y)) + Polygon::new(star(7), MARK.filled())
                    });
                }
                Mark::VLine { .. } => {}
                Mark::Peak { .. } => {}
            }
        }
        // The peaks, ordered by x, their labels over three heights in turn so that
        // neighbours' labels do not overlap; one legend entry for all.
        let mut peaks: Vec<(&(f64, f64), &String)> = self
            .marks
            .iter()
            .filter_map(|m| match m {
                Mark::Peak { at, label } => Some((at, label)),
                _ => None,
            })
            .filter(|(at, _)| at.0 >= xlo && at.0 <= xhi && at.1 >= ylo && at.1 <= yhi)
            .collect();
        peaks.sort_by(|a, b| a.0 .0.total_cmp(&b.0 .0));
        if !peaks.is_empty() {
            let font = ("sans-serif", 12)
                .into_font()
                .color(&MARK)
                .pos(Pos::new(HPos::Center, VPos::Bottom));
            ch.draw_series(peaks.iter().enumerate().map(|(k, (at, label))| {
                let up = 12 + 16 * (k % 3) as i32;
                // A light box under the text (about 6.6 px per character at 12 px) keeps it
                // legible over the curves.
                let half = (3.3 * label.chars().count() as f64) as i32 + 2;
                EmptyElement::at(**at)
                    + TriangleMarker::new((0, -7), 4, MARK.filled())
                    + Rectangle::new(
                        [(-half, -up - 13), (half, -up + 1)],
                        WHITE.mix(0.8).filled(),
                    )
                    + Text::new((*label).clone(), (0, -up), font.clone())
            }))
            .map_err(e)?
            .label(&self.peak_legend)
            .legend(|(x, y)| TriangleMarker::new((x + 12, y), 4, MARK.filled()));
        }
        if !self.series.is_empty() || !self.cells.is_empty() {
            ch.configure_series_labels()
                .position(corner)
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font(("sans-serif", 13))
                .draw()
                .map_err(e)?;
        }
        Ok(())
    }
}

impl Plot {
    /// The fraction of the plot's height the legend takes (its rows at 19 px, the frame's
    /// height about 110 px less than the picture's).
    fn legend_fraction(&self) -> f64 {
        let peak = self.marks.iter().any(|m| matches!(m, Mark::Peak { .. }));
        let rows = self.series.len()
            + self.cells.len()
            + self
                .marks
                .iter()
                .filter(|m| !matches!(m, Mark::Peak { .. }))
                .count()
            + peak as usize
            + self.series.iter().any(|s| s.faulted.contains(&true)) as usize;
        ((rows * 19 + 16) as f64 / (self.size.1 as f64 - 110.0)).clamp(0.1, 0.6)
    }

    /// The points in each corner the legend could take (upper right, upper left, lower right,
    /// lower left; each 45 % of the width and the legend's fraction of the height).
    fn corner_counts(
        &self,
        pts: &[Vec<(f64, f64, bool)>],
        (x0, x1): (f64, f64),
        (y0, y1): (f64, f64),
    ) -> [usize; 4] {
        let fx = |x: f64| {
            if self.xlog {
                (x.log10() - x0.log10()) / (x1.log10() - x0.log10())
            } else {
                (x - x0) / (x1 - x0)
            }
        };
        let fy = |y: f64| {
            if self.ylog {
                (y.log10() - y0.log10()) / (y1.log10() - y0.log10())
            } else {
                (y - y0) / (y1 - y0)
            }
        };
        let band = self.legend_fraction();
        let mut count = [0usize; 4];
        for p in pts.iter().flatten() {
            let (u, v) = (fx(p.0), fy(p.1));
            let (right, left, up, down) = (u > 0.55, u < 0.45, v > 1.0 - band, v < band);
            count[0] += (right && up) as usize;
            count[1] += (left && up) as usize;
            count[2] += (right && down) as usize;
            count[3] += (left && down) as usize;
        }
        count
    }

    /// The corner of the plot holding the fewest points, where the legend goes.
    fn legend_corner(
        &self,
        pts: &[Vec<(f64, f64, bool)>],
        xr: (f64, f64),
        yr: (f64, f64),
    ) -> SeriesLabelPosition {
        let count = self.corner_counts(pts, xr, yr);
        let best = (0..4).min_by_key(|&k| count[k]).unwrap_or(0);
        match best {
            1 => SeriesLabelPosition::UpperLeft,
            2 => SeriesLabelPosition::LowerRight,
            3 => SeriesLabelPosition::LowerLeft,
            _ => SeriesLabelPosition::UpperRight,
        }
    }
}

/// A five-pointed star of outer radius `r` px around the origin (pixel offsets).
fn star(r: i32) -> Vec<(i32, i32)> {
    (0..10)
        .map(|k| {
            let a = std::f64::consts::PI * (k as f64 / 5.0 - 0.5);
            let rr = if k % 2 == 0 {
                r as f64
            } else {
                0.42 * r as f64
            };
            ((rr * a.cos()).round() as i32, (rr * a.sin()).round() as i32)
        })
        .collect()
}

/// The SVG without empty `<text>` elements and without a `<text>` element identical (position,
/// style and text) to an earlier one: plotters gives a log axis's decades twice among its key
/// points, and a label drawn twice on itself renders bold and ragged.
fn without_repeated_text(svg: &str) -> String {
    let mut out = String::with_capacity(svg.len());
    let mut seen = std::collections::HashSet::new();
    let mut rest = svg;
    while let Some(k) = rest.find("<text") {
        out.push_str(&rest[..k]);
        let Some(end) = rest[k..].find("</text>").map(|e| k + e + "</text>".len()) else {
            rest = &rest[k..];
            break;
        };
        let el = &rest[k..end];
        let body = el
            .split_once('>')
            .map_or("", |b| b.1)
            .trim_end_matches("</text>");
        if !body.trim().is_empty() && seen.insert(el.to_string()) {
            out.push_str(el);
        }
        rest = &rest[end..];
        // The newline after a dropped element goes with it.
        if out.ends_with('\n') && rest.starts_with('\n') {
            rest = &rest[1..];
        }
    }
    out.push_str(rest);
    out
}

/// The smallest and largest finite value.
fn bounds(v: &[f64]) -> (f64, f64) {
    let (lo, hi) = v
        .iter()
        .filter(|x| x.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    if lo < hi {
        (lo, hi)
    } else {
        pad(lo, hi, false)
    }
}

/// The full range of the values, padded by 3 % (a log axis by 3 % of its decades).
fn full_range(v: &[f64], log: bool) -> (f64, f64) {
    let (lo, hi) = v
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    pad(lo, hi, log)
}

fn pad(lo: f64, hi: f64, log: bool) -> (f64, f64) {
    if !(lo.is_finite() && hi.is_finite()) {
        return if log { (1.0, 10.0) } else { (0.0, 1.0) };
    }
    if log {
        let (a, b) = (lo.log10(), hi.log10());
        let (a, b) = if b - a < 1e-9 {
            (a - 0.5, b + 0.5)
        } else {
            (a, b)
        };
        let d = 0.03 * (b - a);
        return (10f64.powf(a - d), 10f64.powf(b + d));
    }
    if hi - lo <= 1e-12 * hi.abs().max(lo.abs()).max(1e-300) {
        let h = if lo == 0.0 { 1.0 } else { 0.1 * lo.abs() };
        return (lo - h, hi + h);
    }
    let d = 0.03 * (hi - lo);
    (lo - d, hi + d)
}

/// The range of the bulk of the values: the full range unless it is more than four times
/// the span of the 0.5 % … 99.5 % quantiles widened by a quarter of that span on each side
/// (then the outliers are drawn on the frame).
pub fn robust_range(v: &[f64], log: bool) -> (f64, f64) {
    if v.len() < 20 {
        return full_range(v, log);
    }
    let mut s: Vec<f64> = if log {
        v.iter().map(|x| x.log10()).collect()
    } else {
        v.to_vec()
    };
    s.sort_by(f64::total_cmp);
    let q = |f: f64| s[((s.len() - 1) as f64 * f).round() as usize];
    let (a, b) = (q(0.005), q(0.995));
    let (lo, hi) = (s[0], s[s.len() - 1]);
    let span = b - a;
    if span > 0.0 && hi - lo > 4.0 * span {
        let (a, b) = ((a - 0.25 * span).max(lo), (b + 0.25 * span).min(hi));
        if log {
            (10f64.powf(a), 10f64.powf(b))
        } else {
            (a, b)
        }
    } else {
        let (lo, hi) = if log {
            (10f64.powf(lo), 10f64.powf(hi))
        } else {
            (lo, hi)
        };
        pad(lo, hi, log)
    }
}

/// Labels asked of a log axis: enough that plotters places its grid at 1, 2, … 9 × 10ⁿ over
/// up to about three decades (over more, at the powers of ten only).
const LOG_KEYS: usize = 30;

/// A tick label; on a log axis only at 1, 2 and 5 × 10ⁿ (the grid lines between unlabelled).
fn log_tick(log: bool, v: f64) -> String {
    if log && v > 0.0 {
        let m = v / 10f64.powf(v.log10().floor());
        let m = (m * 1e6).round() / 1e6;
        if ![1.0, 2.0, 5.0, 10.0].contains(&m) {
            return String::new();
        }
    }
    tick(v)
}

/// A tick computed as start + k·step that should be 0 but carries rounding noise (1e-17 on
/// an axis of ±0.2) is 0.
fn snap(v: f64, lo: f64, hi: f64) -> f64 {
    if v.abs() < 1e-9 * (hi - lo).abs() {
        0.0
    } else {
        v
    }
}

/// A tick label: the shortest decimal that represents the tick (`0.002`, `250`, `-4e4` is
/// printed `-40000`; below 1e-4 or from 1e7 in scientific notation `2e-5`, `1.5e7`).
pub fn tick(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return if v == 0.0 { "0".into() } else { format!("{v}") };
    }
    // Ticks are k·step with step = 1, 2, 5 × 10ⁿ: 12 significant digits remove the
    // rounding noise of k·step and of 10^(log) on a log axis.
    let r: f64 = format!("{v:.11e}").parse().unwrap_or(v);
    let a = r.abs();
    if !(1e-4..1e7).contains(&a) {
        let s = format!("{r:e}");
        return s;
    }
    let s = format!("{r:.10}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".into()
    } else {
        s.into()
    }
}

/// Whether a tick label is a round number: at most two significant digits, or three when
/// its last is 5 (`0.25`, `150`, `1.5e7`, `125`).
pub fn is_round(label: &str) -> bool {
    let Ok(v) = label.trim().replace('−', "-").parse::<f64>() else {
        return false;
    };
    if v == 0.0 {
        return true;
    }
    let digits: String = format!("{:e}", v.abs())
        .split('e')
        .next()
        .unwrap_or("")
        .replace('.', "");
    digits.len() <= 2 || (digits.len() == 3 && digits.ends_with('5'))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_are_short() {
        assert_eq!(tick(0.1 + 0.2), "0.3");
        assert_eq!(tick(-40000.0), "-40000");
        assert_eq!(tick(2e-3), "0.002");
        assert_eq!(tick(2e-5), "2e-5");
        assert_eq!(tick(10f64.powf(2.0 * 0.5f64.log10() + 3.0)), "250");
        assert_eq!(tick(snap(-2.775e-17, -0.25, 0.25)), "0");
        assert_eq!(tick(snap(2e-5, 0.0, 1e-4)), "2e-5");
        assert!(is_round("0.25") && is_round("150") && is_round("2e-5") && is_round("-40000"));
        assert!(!is_round("25.119") && !is_round("158.489") && !is_round("-3.83e4"));
    }

    #[test]
    fn outliers_do_not_set_the_range() {
        let mut v: Vec<f64> = (0..1000).map(|k| (k as f64 * 0.01).sin()).collect();
        v[10] = 1e6;
        v[20] = -1e6;
        let (lo, hi) = robust_range(&v, false);
        assert!(lo > -2.0 && hi < 2.0, "{lo} {hi}");
        let (lo, hi) = robust_range(&v[30..], false);
        assert!(
            (lo + 1.06).abs() < 0.01 && (hi - 1.06).abs() < 0.01,
            "{lo} {hi}"
        );
    }
}
