//! `report/index.html`: one page, no network and no script: the summary, the plots inline, and
//! a card per scene with its thumbnail, QA flags and links to its files (relative links, so
//! the page works wherever the dataset folder is, as long as `report/` stays inside it).

use std::fmt::Write as _;

use mesa_schemas::render::ReportStats;

use super::{flags, SceneFacts};

/// Escapes text for HTML content and attribute values.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// Percent-encodes a relative path for an `href`/`src` (keeps `/`, letters, digits, `-_.~`).
fn url(path: &str) -> String {
    let mut out = String::with_capacity(path.len());
    for b in path.bytes() {
        if b.is_ascii_alphanumeric() || b"/-_.~".contains(&b) {
            out.push(b as char);
        } else {
            let _ = write!(out, "%{b:02X}");
        }
    }
    out
}

const STYLE: &str = "
body { font-family: system-ui, sans-serif; margin: 1.5em; color: #222; background: #fafafa; }
h1 { margin-bottom: 0.2em; }
.summary { color: #555; margin-bottom: 1em; }
.plots { display: flex; flex-wrap: wrap; gap: 12px; align-items: flex-start; }
.plots figure { margin: 0; background: #fff; border: 1px solid #ddd; }
.plots svg { display: block; max-width: 100%; height: auto; }
.scenes { display: grid; grid-template-columns: repeat(auto-fill, minmax(250px, 1fr)); gap: 12px; }
.scene { background: #fff; border: 1px solid #ddd; padding: 8px; font-size: 13px; }
.scene img, .scene .noimg { width: 232px; height: 232px; object-fit: contain; display: block;
  background: repeating-conic-gradient(#eee 0% 25%, #fff 0% 50%) 0 / 16px 16px; }
.scene .noimg { display: flex; align-items: center; justify-content: center; color: #999; }
.scene h3 { font-size: 14px; margin: 6px 0 2px; word-break: break-all; }
.meta { color: #666; }
.flag { display: inline-block; border-radius: 3px; padding: 1px 5px; margin: 2px 2px 0 0; }
.flag.bad { background: #f8d7da; color: #721c24; }
.flag.warn { background: #fff3cd; color: #664d03; }
.flag.info { background: #e2e3e5; color: #41464b; }
.flag.ok { background: #d1e7dd; color: #0f5132; }
.links { display: flex; flex-wrap: wrap; gap: 2px 8px; margin-top: 4px; }
";

/// The page. `plots` are the SVGs (file name, content), shown inline; thumbnails and links are
/// relative to the report folder, which is `DATASET/report/`.
pub fn html(stats: &ReportStats, scenes: &[SceneFacts], plots: &[(String, String)]) -> String {
    let mut out = String::new();
    let _ = write!(
        out,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>mesa report: {} scenes</title>\n<style>{STYLE}</style>\n</head>\n<body>\n",
        stats.scenes
    );
    let c = &stats.collisions;
    let collisions = if c.checked == 0 {
        "not checked".to_owned()
    } else {
        let mut text = format!(
            "collision rate {:.2} % before settling over {} checked scenes",
            100.0 * c.before.collision_rate,
            c.before.scenes
        );
        if let Some(after) = &c.after {
            let _ = write!(
                text,
                ", {:.2} % after settling ({} scenes)",
                100.0 * after.collision_rate,
                after.scenes
            );
        }
        let _ = write!(text, "; {} not checked", c.not_checked);
        text
    };
    let _ = write!(
        out,
        "<h1>mesa report</h1>\n<p class=\"summary\">{} scenes, {} objects ({:.1} per scene, \
         {} to {}), {} categories, {} with a scene graph, {} rendered, {} tasks; {}. \
         Statistics: <a href=\"stats.json\">stats.json</a>.</p>\n",
        stats.scenes,
        stats.objects,
        stats.objects_per_scene.mean,
        stats.objects_per_scene.min,
        stats.objects_per_scene.max,
        stats.categories,
        stats.scenes_with_graph,
        stats.scenes_rendered,
        stats.tasks,
        escape(&collisions)
    );
    if stats.imported > 0 {
        let _ = writeln!(
            out,
            "<p class=\"summary\">{} scenes imported; {} objects in {} of them have no GLB (the \
             release does not ship their assets).</p>",
            stats.imported, stats.objects_missing_glb, stats.scenes_with_missing_glb
        );
    }
    if !stats.annotation_sources.is_empty() {
        let sources: Vec<String> = stats
            .annotation_sources
            .iter()
            .map(|(source, n)| format!("{n} {source}"))
            .collect();
        let _ = writeln!(
            out,
            "<p class=\"summary\">Asset annotation fields by source: {}; {} assets hold \
             placeholder fields (no model).</p>",
            escape(&sources.join(", ")),
            stats.annotation_placeholder_assets
        );
    }
    out.push_str("<div class=\"plots\">\n");
    for (name, svg) in plots {
        let _ = writeln!(
            out,
            "<figure id=\"{}\">{}</figure>",
            escape(name.trim_end_matches(".svg")),
            svg.trim()
        );
    }
    out.push_str("</div>\n");
    let _ = write!(
        out,
        "<h2>Scenes ({})</h2>\n<div class=\"scenes\">\n",
        scenes.len()
    );
    for scene in scenes {
        let key = scene.key();
        let _ = writeln!(out, "<div class=\"scene\" data-scene=\"{}\">", escape(&key));
        match &scene.thumbnail {
            Some(thumb) => {
                let _ = writeln!(
                    out,
                    "<a href=\"{}\"><img src=\"{}\" alt=\"front view of {}\" loading=\"lazy\" \
                     width=\"232\" height=\"232\"></a>",
                    escape(&url(&format!(
                        "../scenes/{}/{}/render/front.png",
                        scene.table_type, scene.scene_id
                    ))),
                    escape(&url(thumb)),
                    escape(&key)
                );
            }
            None => out.push_str("<div class=\"noimg\">not rendered</div>\n"),
        }
        let _ = write!(
            out,
            "<h3>{}</h3>\n<div class=\"meta\">{} · {} objects · {} · {} tasks</div>\n<div>",
            escape(&scene.scene_id),
            escape(&scene.table_type),
            scene.objects.len(),
            escape(scene.layout.as_deref().unwrap_or("no layout")),
            scene.tasks
        );
        let scene_flags = flags(scene);
        if scene_flags.iter().all(|(severity, _)| *severity == "info") {
            out.push_str("<span class=\"flag ok\">QA ok</span>");
        }
        for (severity, text) in scene_flags {
            let _ = write!(
                out,
                "<span class=\"flag {severity}\">{}</span>",
                escape(&text)
            );
        }
        out.push_str("</div>\n<div class=\"links\">");
        for link in &scene.links {
            let _ = write!(
                out,
                "<a href=\"{}\">{}</a>",
                escape(&url(&format!("../{}", link.path))),
                escape(&link.label)
            );
        }
        out.push_str("</div>\n</div>\n");
    }
    out.push_str("</div>\n</body>\n</html>\n");
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_and_paths_are_escaped() {
        assert_eq!(
            escape("<a href=\"x\">&'"),
            "&lt;a href=&quot;x&quot;&gt;&amp;&#39;"
        );
        assert_eq!(url("scenes/a b/c#d.png"), "scenes/a%20b/c%23d.png");
    }
}
