//! `tessera plot`: a per-rank timeline of the stages in a `render --stats` file, so that
//! pipelining, stalls and the slowest stage show at a glance.
//!
//! One row per rank (rank 0's writer thread has a row of its own, under rank 0), time from
//! the run's start across, one bar per stage of every frame, coloured by stage and labelled
//! with the frame's number where it fits. Workers' bars are on their own clocks moved onto
//! rank 0's through the Unix epoch ([`protocol::FrameSpan`]), so ranks on different
//! nodes line up as well as the nodes' clocks agree.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use plotters::prelude::*;
use serde::Deserialize;

use crate::model::read_input;
use crate::output::{check_distinct, check_extension, summary, write_bytes};
use crate::render::stats::Span;

/// The stages, in legend order, with their colours.
pub const STAGES: [(&str, RGBColor); 8] = [
    ("sort", RGBColor(31, 119, 180)),
    ("send", RGBColor(23, 190, 207)),
    ("receive", RGBColor(170, 170, 170)),
    ("swap", RGBColor(214, 39, 40)),
    ("write", RGBColor(148, 103, 189)),
    ("decode", RGBColor(255, 127, 14)),
    ("adapt", RGBColor(188, 189, 34)),
    ("render", RGBColor(44, 160, 44)),
];

/// The fields of a stats line the plot reads.
#[derive(Deserialize)]
struct Line {
    frame: u32,
    rank: usize,
    #[serde(default)]
    frame_ms: Option<f64>,
    #[serde(default)]
    timeline: Option<Vec<Span>>,
}

/// A bar of the timeline.
#[derive(Clone, Debug, PartialEq)]
pub struct Bar {
    pub row: usize,
    pub frame: u32,
    pub span: Span,
}

/// The timeline of a stats file: row names top to bottom, the bars, and rank 0's frame
/// periods (for the title).
#[derive(Debug, Default)]
pub struct Timeline {
    pub rows: Vec<String>,
    pub bars: Vec<Bar>,
    pub periods: Vec<f64>,
}

/// The most rows (a rank each, and rank 0's writer) a timeline draws: 256 rows are an image
/// 14,456 pixels tall, 69 MB of RGB at the default width.
pub const MAX_ROWS: usize = 256;

/// The most pixels a timeline image has (192 MB of RGB), whatever `--width` asks.
pub const MAX_PIXELS: u64 = 64 << 20;

impl Timeline {
    /// Reads `render --stats` lines, keeping frames `first..=last`.
    pub fn parse(text: &str, frames: Option<(u32, u32)>) -> Result<Timeline> {
        // Row keys: (rank, 0) for a rank's own stages, (0, 1) for rank 0's writer.
        let mut bars: Vec<((usize, u8), u32, Span)> = Vec::new();
        let mut periods = Vec::new();
        let mut lines = 0;
        for (i, text) in text.lines().enumerate() {
            if text.trim().is_empty() {
                continue;
            }
            lines += 1;
            let line: Line =
                serde_json::from_str(text).map_err(|e| anyhow!("line {}: not a render --stats line ({e})", i + 1))?;
            let Some(timeline) = line.timeline else {
                bail!("line {}: no timeline (written by an older build; run render --stats again)", i + 1);
            };
            if frames.is_some_and(|(a, b)| line.frame < a || line.frame > b) {
                continue;
            }
            if line.rank == 0 {
                periods.extend(line.frame_ms.filter(|_| line.frame > 0));
            }
            for span in timeline {
                if !(span.start_ms.is_finite() && span.end_ms.is_finite() && span.end_ms >= span.start_ms) {
                    bail!("line {}: stage {} has no valid span", i + 1, span.stage);
                }
                let key = (line.rank, u8::from(line.rank == 0 && span.stage == "write"));
                bars.push((key, line.frame, span));
            }
        }
        if lines == 0 {
            bail!("no stats lines");
        }
        if bars.is_empty() {
            bail!("no stages in the frames asked for");
        }
        let keys: BTreeMap<(usize, u8), usize> = bars.iter().map(|b| (b.0, 0)).collect();
        if keys.len() > MAX_ROWS {
            bail!(
                "{} timeline rows (ranks, and rank 0's writer); a plot draws at most {MAX_ROWS}, one band each",
                keys.len()
            );
        }
        let rows: BTreeMap<(usize, u8), usize> = keys.keys().enumerate().map(|(i, &k)| (k, i)).collect();
        let names = rows
            .keys()
            .map(|&(rank, writer)| if writer == 1 { format!("rank {rank} writer") } else { format!("rank {rank}") })
            .collect();
        let bars = bars.into_iter().map(|(key, frame, span)| Bar { row: rows[&key], frame, span }).collect();
        Ok(Timeline { rows: names, bars, periods })
    }

    /// The time range the bars cover, in ms.
    pub fn range(&self) -> (f64, f64) {
        let lo = self.bars.iter().map(|b| b.span.start_ms).fold(f64::INFINITY, f64::min);
        let hi = self.bars.iter().map(|b| b.span.end_ms).fold(f64::NEG_INFINITY, f64::max);
        (lo, if hi > lo { hi } else { lo + 1.0 })
    }

    /// Draws the timeline into an RGB image of `width x height(rows)`, with `title` on top;
    /// also gives the pixel at the middle of each bar (in the order of `bars`).
    pub fn draw(&self, width: u32, title: &str) -> Result<Drawn> {
        register_font()?;
        let height = Self::height(self.rows.len());
        let pixels = width as u64 * height as u64;
        if pixels > MAX_PIXELS {
            bail!(
                "--width {width}: a timeline of {} rows would be {width}x{height} pixels, more than {} million; give a smaller --width",
                self.rows.len(),
                MAX_PIXELS >> 20
            );
        }
        let mut pixels = vec![0u8; width as usize * height as usize * 3];
        let mut centers = Vec::with_capacity(self.bars.len());
        {
            let root = BitMapBackend::with_buffer(&mut pixels, (width, height)).into_drawing_area();
            root.fill(&WHITE)?;
            let root = root.titled(title, ("sans-serif", 22))?;
            let (lo, hi) = self.range();
            let n = self.rows.len();
            // A fifth more time on the right holds the legend clear of the bars.
            let mut chart = ChartBuilder::on(&root)
                .margin(15)
                .x_label_area_size(45)
                .y_label_area_size(130)
                .build_cartesian_2d(lo..hi + (hi - lo) * 0.2, 0.0..n as f64)?;
            let names = self.rows.clone();
            chart
                .configure_mesh()
                .disable_y_mesh()
                .y_labels(n * 2 + 1)
                .y_label_formatter(&move |y| {
                    // Row i is drawn over y in [n-1-i, n-i); its name sits at the middle.
                    let i = n as f64 - 0.5 - y;
                    let r = i.round();
                    if (i - r).abs() < 1e-6 && r >= 0.0 && (r as usize) < n {
                        names[r as usize].clone()
                    } else {
                        String::new()
                    }
                })
                .x_desc("milliseconds from the start of the run")
                .x_label_formatter(&|x| format!("{x:.0}"))
                .label_style(("sans-serif", 15))
                .axis_desc_style(("sans-serif", 16))
                .draw()?;
            for &(stage, color) in &STAGES {
                let bars: Vec<&Bar> = self.bars.iter().filter(|b| b.span.stage == stage).collect();
                if bars.is_empty() {
                    continue;
                }
                chart
                    .draw_series(bars.iter().map(|b| {
                        let [y0, y1] = Self::band(n, b.row);
                        Rectangle::new([(b.span.start_ms, y0), (b.span.end_ms, y1)], color.filled())
                    }))?
                    .label(stage)
                    .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 18, y + 6)], color.filled()));
            }
            let other: Vec<&Bar> =
                self.bars.iter().filter(|b| !STAGES.iter().any(|(s, _)| *s == b.span.stage)).collect();
            chart.draw_series(other.iter().map(|b| {
                let [y0, y1] = Self::band(n, b.row);
                Rectangle::new([(b.span.start_ms, y0), (b.span.end_ms, y1)], BLACK.mix(0.5).filled())
            }))?;
            // Frame numbers on the bars wide enough to hold them.
            let labels: Vec<(f64, f64, String)> = self
                .bars
                .iter()
                .filter(|b| {
                    let [y0, _] = Self::band(n, b.row);
                    let a = chart.backend_coord(&(b.span.start_ms, y0));
                    let z = chart.backend_coord(&(b.span.end_ms, y0));
                    z.0 - a.0 >= 10 + 8 * b.frame.to_string().len() as i32
                })
                .map(|b| (b.span.start_ms, Self::band(n, b.row)[1], b.frame.to_string()))
                .collect();
            chart.draw_series(labels.into_iter().map(|(x, y, text)| {
                Text::new(text, (x, y), ("sans-serif", 13).into_font().color(&WHITE)).into_dyn()
            }))?;
            for b in &self.bars {
                let [y0, y1] = Self::band(n, b.row);
                centers.push(chart.backend_coord(&((b.span.start_ms + b.span.end_ms) * 0.5, (y0 + y1) * 0.5)));
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .label_font(("sans-serif", 14))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .draw()?;
            root.present()?;
        }
        Ok(Drawn { width, height, rgb: pixels, centers })
    }

    /// The image height for `rows` rows.
    pub fn height(rows: usize) -> u32 {
        120 + 56 * rows as u32
    }

    /// The vertical extent of row `row`'s bars (row 0 on top).
    fn band(rows: usize, row: usize) -> [f64; 2] {
        let top = (rows - row) as f64;
        [top - 0.85, top - 0.15]
    }
}

/// Registers the embedded font as plotters' `sans-serif` (it has no system fonts here): for
/// every figure drawn with plotters. The font is parsed once per process (a window's
/// heads-up line calls this on every redraw).
pub fn register_font() -> Result<()> {
    static REGISTERED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, ttf_noto_sans::REGULAR).is_ok()
    });
    ok.then_some(()).ok_or_else(|| anyhow!("the embedded font does not load"))
}

/// A drawn timeline: RGB pixels, rows top first, and the pixel at the middle of each bar.
pub struct Drawn {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
    pub centers: Vec<(i32, i32)>,
}

/// `tessera plot STATS -o OUT.png [--frames A..B] [--width W]`.
pub fn run(input: &Path, output: &Path, frames: Option<(u32, u32)>, width: u32) -> Result<()> {
    check_extension(output, &["png"], "the output of plot")?;
    check_distinct(&[input], &[output])?;
    let bytes = read_input(input)?;
    let text = String::from_utf8(bytes).map_err(|_| anyhow!("{}: not UTF-8 text", input.display()))?;
    let timeline = Timeline::parse(&text, frames).with_context(|| format!("{}", input.display()))?;
    let mut periods = timeline.periods.clone();
    periods.sort_by(f64::total_cmp);
    let period = periods.get(periods.len() / 2).map_or(String::new(), |p| format!(", median frame period {p:.0} ms"));
    let frames_seen: std::collections::BTreeSet<u32> = timeline.bars.iter().map(|b| b.frame).collect();
    let name = input.file_name().map_or(String::new(), |n| n.to_string_lossy().into_owned());
    let title = format!("{name}: {} frames on {} ranks{period}", frames_seen.len(), {
        let ranks: std::collections::BTreeSet<&str> =
            timeline.rows.iter().map(|r| r.trim_end_matches(" writer")).collect();
        ranks.len()
    });
    let drawn = timeline.draw(width, &title)?;
    let png = crate::composite::encode_png(drawn.width, drawn.height, png::ColorType::Rgb, &drawn.rgb)?;
    write_bytes(output, &png)?;
    summary(output, format_args!("{} -> {}: {title}", input.display(), output.display()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn span(stage: &str, start_ms: f64, end_ms: f64) -> Span {
        Span { stage: stage.into(), start_ms, end_ms }
    }

    const STATS: &str = r#"{"frame":0,"rank":0,"frame_ms":40.0,"timeline":[{"stage":"sort","start_ms":0.0,"end_ms":10.0},{"stage":"send","start_ms":10.0,"end_ms":12.0},{"stage":"receive","start_ms":21.0,"end_ms":60.0},{"stage":"write","start_ms":60.0,"end_ms":70.0}]}
{"frame":0,"rank":1,"timeline":[{"stage":"decode","start_ms":12.0,"end_ms":30.0},{"stage":"render","start_ms":30.0,"end_ms":58.0}]}

{"frame":1,"rank":0,"frame_ms":50.0,"timeline":[{"stage":"sort","start_ms":12.0,"end_ms":20.0},{"stage":"send","start_ms":20.0,"end_ms":21.0},{"stage":"receive","start_ms":60.0,"end_ms":100.0},{"stage":"write","start_ms":100.0,"end_ms":110.0}]}
{"frame":1,"rank":1,"timeline":[{"stage":"decode","start_ms":58.0,"end_ms":70.0},{"stage":"render","start_ms":70.0,"end_ms":98.0}]}
"#;

    #[test]
    fn rows_follow_ranks_with_the_writer_under_rank_0() {
        let t = Timeline::parse(STATS, None).unwrap();
        assert_eq!(t.rows, ["rank 0", "rank 0 writer", "rank 1"]);
        assert_eq!(t.bars.len(), 12);
        assert_eq!(t.periods, [50.0]);
        assert_eq!(t.range(), (0.0, 110.0));
        let writes: Vec<&Bar> = t.bars.iter().filter(|b| b.span.stage == "write").collect();
        assert!(writes.iter().all(|b| b.row == 1));
        assert!(t.bars.iter().filter(|b| b.span.stage == "render").all(|b| b.row == 2));
        let one = Timeline::parse(STATS, Some((1, 1))).unwrap();
        assert_eq!(one.bars.len(), 6);
        assert_eq!(one.bars[0], Bar { row: 0, frame: 1, span: span("sort", 12.0, 20.0) });
    }

    #[test]
    fn each_bar_is_drawn_in_its_stage_colour_where_its_time_and_row_are() {
        let t = Timeline::parse(STATS, None).unwrap();
        let Drawn { width, height, rgb, centers } = t.draw(1200, "test").unwrap();
        assert_eq!(height, Timeline::height(3));
        let colour = |stage: &str| STAGES.iter().find(|(s, _)| *s == stage).unwrap().1;
        for (b, &(x, y)) in t.bars.iter().zip(&centers) {
            assert!(x >= 0 && y >= 0 && (x as u32) < width && (y as u32) < height, "{b:?} at {x},{y}");
            let at = (y as usize * width as usize + x as usize) * 3;
            let c = colour(&b.span.stage);
            assert_eq!(rgb[at..at + 3], [c.0, c.1, c.2], "{b:?} at {x},{y}");
        }
        // Later bars lie further right; lower rows lower down.
        for (a, b) in t.bars.iter().zip(&centers).flat_map(|a| t.bars.iter().zip(&centers).map(move |b| (a, b))) {
            if a.0.span.start_ms >= b.0.span.end_ms {
                assert!(a.1 .0 > b.1 .0, "{:?} right of {:?}", a.0, b.0);
            }
            if a.0.row > b.0.row {
                assert!(a.1 .1 > b.1 .1 + 20, "{:?} below {:?}", a.0, b.0);
            }
        }
    }

    #[test]
    fn bad_lines_are_named() {
        let e = Timeline::parse("{\"frame\":0}\n", None).unwrap_err();
        assert!(e.to_string().starts_with("line 1: not a render --stats line"), "{e}");
        let e = Timeline::parse("{\"frame\":0,\"rank\":0,\"sort_ms\":1.0}\n", None).unwrap_err();
        assert!(e.to_string().contains("no timeline"), "{e}");
        assert!(Timeline::parse("\n\n", None).is_err());
        let nan = "{\"frame\":0,\"rank\":1,\"timeline\":[{\"stage\":\"render\",\"start_ms\":5.0,\"end_ms\":1.0}]}";
        assert!(Timeline::parse(nan, None).unwrap_err().to_string().contains("stage render"));
    }
}
