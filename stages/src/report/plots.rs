//! The report's plots, drawn with plotters' SVG backend (text is left to the viewer's fonts).

use mesa_schemas::render::ReportStats;
use plotters::prelude::*;

/// Colour of the bars.
const BAR: RGBColor = RGBColor(70, 110, 170);
/// Colour of "after settling" bars.
const BAR_AFTER: RGBColor = RGBColor(90, 160, 110);

type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// A vertical bar chart of `values` labelled `labels`.
fn columns(
    title: &str,
    x_desc: &str,
    y_desc: &str,
    labels: &[String],
    series: &[(&str, RGBColor, Vec<f64>)],
    size: (u32, u32),
) -> Result<String, PlotError> {
    let mut svg = String::new();
    let draw = |svg: &mut String| -> DrawResult {
        let root = SVGBackend::with_string(svg, size).into_drawing_area();
        root.fill(&WHITE)?;
        let n = labels.len().max(1) as u32;
        let top = series
            .iter()
            .flat_map(|(_, _, v)| v.iter().copied())
            .fold(0.0f64, f64::max);
        let top = if top > 0.0 { top * 1.1 } else { 1.0 };
        let slots = series.len().max(1) as u32;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(if labels.iter().any(|l| l.len() > 6) {
                90
            } else {
                40
            })
            .y_label_area_size(60)
            .build_cartesian_2d((0u32..n * slots).into_segmented(), 0f64..top)?;
        let label_of = |v: &SegmentValue<u32>| -> String {
            match v {
                SegmentValue::CenterOf(i) | SegmentValue::Exact(i) => {
                    if i % slots == (slots - 1) / 2 {
                        labels
                            .get((i / slots) as usize)
                            .cloned()
                            .unwrap_or_default()
                    } else {
                        String::new()
                    }
                }
                SegmentValue::Last => String::new(),
            }
        };
        let long = labels.iter().any(|l| l.len() > 6);
        let mut mesh = chart.configure_mesh();
        mesh.disable_x_mesh()
            .x_labels((n * slots) as usize)
            .x_label_formatter(&label_of)
            .x_desc(x_desc)
            .y_desc(y_desc);
        if long {
            mesh.x_label_style(
                ("sans-serif", 11)
                    .into_font()
                    .transform(FontTransform::Rotate90),
            );
        }
        mesh.draw()?;
        for (s, (name, color, values)) in series.iter().enumerate() {
            let s = s as u32;
            chart
                .draw_series(values.iter().enumerate().map(|(i, v)| {
                    let x = i as u32 * slots + s;
                    let mut bar = Rectangle::new(
                        [
                            (SegmentValue::Exact(x), 0.0),
                            (SegmentValue::Exact(x + 1), *v),
                        ],
                        color.filled(),
                    );
                    bar.set_margin(0, 0, 3, 3);
                    bar
                }))?
                .label(*name)
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 10, y + 5)], color.filled())
                });
        }
        if series.len() > 1 {
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()?;
        }
        root.present()?;
        Ok(())
    };
    draw(&mut svg).map_err(|e| PlotError {
        title: title.to_owned(),
        message: e.to_string(),
    })?;
    Ok(svg)
}

/// A horizontal bar chart (one row per label), for long lists.
fn rows(title: &str, x_desc: &str, labels: &[String], values: &[f64]) -> Result<String, PlotError> {
    let n = labels.len().max(1) as u32;
    let row_px = if n <= 20 { 26 } else { 16 };
    let size = (760, 90 + row_px * n);
    let mut svg = String::new();
    let draw = |svg: &mut String| -> DrawResult {
        let root = SVGBackend::with_string(svg, size).into_drawing_area();
        root.fill(&WHITE)?;
        let top = values.iter().copied().fold(0.0f64, f64::max);
        let top = if top > 0.0 { top * 1.1 } else { 1.0 };
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(170)
            .build_cartesian_2d(0f64..top, (0u32..n).into_segmented())?;
        let label_of = |v: &SegmentValue<u32>| -> String {
            match v {
                // Row 0 at the top.
                SegmentValue::CenterOf(i) | SegmentValue::Exact(i) => (n - 1)
                    .checked_sub(*i)
                    .and_then(|k| labels.get(k as usize))
                    .cloned()
                    .unwrap_or_default(),
                SegmentValue::Last => String::new(),
            }
        };
        chart
            .configure_mesh()
            .disable_y_mesh()
            .y_labels(n as usize)
            .y_label_formatter(&label_of)
            .y_label_style(("sans-serif", 11))
            .x_desc(x_desc)
            .draw()?;
        chart.draw_series(values.iter().enumerate().map(|(i, v)| {
            let y = n - 1 - i as u32;
            let mut bar = Rectangle::new(
                [
                    (0.0, SegmentValue::Exact(y)),
                    (*v, SegmentValue::Exact(y + 1)),
                ],
                BAR.filled(),
            );
            bar.set_margin(2, 2, 0, 0);
            bar
        }))?;
        root.present()?;
        Ok(())
    };
    draw(&mut svg).map_err(|e| PlotError {
        title: title.to_owned(),
        message: e.to_string(),
    })?;
    Ok(svg)
}

/// An SVG saying only `text` (for data that does not exist yet).
fn notice(title: &str, text: &str) -> String {
    let mut svg = String::new();
    let draw = |svg: &mut String| -> DrawResult {
        let root = SVGBackend::with_string(svg, (520, 160)).into_drawing_area();
        root.fill(&WHITE)?;
        let root = root.titled(title, ("sans-serif", 18))?;
        root.draw(&Text::new(
            text.to_owned(),
            (20, 50),
            ("sans-serif", 16)
                .into_font()
                .color(&RGBColor(120, 120, 120)),
        ))?;
        root.present()?;
        Ok(())
    };
    // Drawing two texts on a string cannot fail; an error would leave the notice empty.
    let _ = draw(&mut svg);
    svg
}

/// A plot that plotters could not draw.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{title}: {message}")]
pub struct PlotError {
    /// The plot's title.
    pub title: String,
    /// plotters' error.
    pub message: String,
}

/// The plots of a report, as (file name, SVG).
pub fn plots(stats: &ReportStats) -> Result<Vec<(String, String)>, PlotError> {
    let mut out = Vec::new();
    // Objects per scene: every count from the smallest to the largest.
    let hist = &stats.objects_per_scene.histogram;
    let (lo, hi) = (stats.objects_per_scene.min, stats.objects_per_scene.max);
    let counts: Vec<u64> = if hist.is_empty() {
        Vec::new()
    } else {
        (lo..=hi).collect()
    };
    out.push((
        "objects_per_scene.svg".to_owned(),
        if counts.is_empty() {
            notice("Objects per scene", "no scene has a layout")
        } else {
            columns(
                "Objects per scene",
                "objects",
                "scenes",
                &counts.iter().map(u64::to_string).collect::<Vec<_>>(),
                &[(
                    "scenes",
                    BAR,
                    counts
                        .iter()
                        .map(|c| {
                            hist.iter()
                                .find(|b| b.value == *c)
                                .map_or(0.0, |b| b.count as f64)
                        })
                        .collect(),
                )],
                (760, 360),
            )?
        },
    ));
    out.push((
        "categories.svg".to_owned(),
        if stats.top_categories.is_empty() {
            notice("Most frequent categories", "no objects")
        } else {
            rows(
                &format!(
                    "The {} most frequent categories (of {})",
                    stats.top_categories.len(),
                    stats.categories
                ),
                "objects",
                &stats
                    .top_categories
                    .iter()
                    .map(|c| c.name.clone())
                    .collect::<Vec<_>>(),
                &stats
                    .top_categories
                    .iter()
                    .map(|c| c.count as f64)
                    .collect::<Vec<_>>(),
            )?
        },
    ));
    let (types, type_counts): (Vec<String>, Vec<f64>) = stats
        .table_types
        .iter()
        .map(|(t, n)| (t.clone(), *n as f64))
        .unzip();
    out.push((
        "table_types.svg".to_owned(),
        if types.is_empty() {
            notice("Table types", "no scenes")
        } else {
            rows("Scenes per table type", "scenes", &types, &type_counts)?
        },
    ));
    let (relations, relation_counts): (Vec<String>, Vec<f64>) = stats
        .relations
        .iter()
        .map(|(r, n)| (r.clone(), *n as f64))
        .unzip();
    out.push((
        "relations.svg".to_owned(),
        if relations.is_empty() {
            notice("Scene-graph relations", "no scene graph")
        } else {
            rows(
                "Scene-graph relations",
                "triplets",
                &relations,
                &relation_counts,
            )?
        },
    ));
    let c = &stats.collisions;
    out.push((
        "collisions.svg".to_owned(),
        if c.checked == 0 {
            notice(
                "Collision rate",
                &format!(
                    "not checked: no scene has qa/check.json ({} scenes)",
                    stats.scenes
                ),
            )
        } else {
            let labels = vec![
                "collision rate (%)".to_owned(),
                "scenes with collisions (%)".to_owned(),
            ];
            let percent = |r: &mesa_schemas::render::RateStats| {
                vec![
                    100.0 * r.collision_rate,
                    if r.scenes > 0 {
                        100.0 * r.scenes_with_collisions as f64 / r.scenes as f64
                    } else {
                        0.0
                    },
                ]
            };
            let mut series = vec![("before settling", BAR, percent(&c.before))];
            if let Some(after) = &c.after {
                series.push(("after settling", BAR_AFTER, percent(after)));
            }
            columns(
                &format!(
                    "Collisions ({} scenes checked, {} not checked)",
                    c.checked, c.not_checked
                ),
                "",
                "%",
                &labels,
                &series,
                (760, 360),
            )?
        },
    ));
    Ok(out)
}
