//! The page: its HTML around the viewer's data and script (run by its
//! hash alone), escaping, and tables.

use crate::render;
use crate::scene::Scene;

/// HTML-escaped text.
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// A page: its title, a line under it, the viewer's scenes and camera,
/// and the sections below the viewer (HTML).
pub struct Page {
    /// The page's title.
    pub title: String,
    /// The line under it.
    pub subtitle: String,
    /// The camera's azimuth and elevation, degrees.
    pub view: (f64, f64),
    /// What the viewer shows (none: no viewer).
    pub scenes: Vec<Scene>,
    /// The sections below the viewer, HTML.
    pub sections: Vec<String>,
}

/// The data's JSON as the text of a script element: `<`, `>` and `&` as
/// `\u003c`, `\u003e`, `\u0026`, so that no name in it can end the
/// element (`</script>`) or swallow the next one (`<!--<script>`).
fn script_json(value: &serde_json::Value) -> String {
    let json = serde_json::to_string(value).expect("plain values");
    json.replace('<', "\\u003c").replace('>', "\\u003e").replace('&', "\\u0026")
}

/// The Content-Security-Policy source of an inline script: its SHA-256,
/// so that the page runs its own script and no other, even one a missed
/// escape let in.
fn script_hash(script: &str) -> String {
    use base64::Engine;
    use sha2::Digest;
    format!("'sha256-{}'", base64::engine::general_purpose::STANDARD.encode(sha2::Sha256::digest(script.as_bytes())))
}

/// The page's HTML. Its one script runs by its hash (no inline script
/// else can); the data is JSON in a non-running script element.
pub fn html(page: &Page) -> String {
    // The colour map as the PNG pictures draw it ([`render::viridis`]), 256
    // RGB bytes: the viewer's texture and colour bar, so that both agree.
    let colours: Vec<u8> =
        (0..256).flat_map(|i| render::viridis(f64::from(i) / 255.0).map(|c| (255.0 * c).round() as u8)).collect();
    let data = serde_json::json!({ "scenes": page.scenes, "view": [page.view.0, page.view.1], "colours": colours });
    let data = script_json(&data);
    let js = concat!("\n", include_str!("viewer.js"));
    let viewer = if page.scenes.is_empty() {
        String::new()
    } else {
        concat!(
            "<section id=\"viewer\">\n",
            "<div class=\"controls\"><label>show <select id=\"scene\"></select></label>",
            "<button id=\"play\">▶ play</button><input type=\"range\" id=\"frame\" min=\"0\" max=\"0\" value=\"0\" aria-label=\"time\">",
            "<span id=\"frame-label\"></span>",
            "<select id=\"companion\" aria-label=\"the second shape\"><option value=\"beside\">beside</option>",
            "<option value=\"overlay\">overlaid</option><option value=\"hidden\">hidden</option></select></div>\n",
            "<canvas id=\"view\"></canvas>\n",
            "<div id=\"colourbar\"><span>signal</span><span id=\"lo\"></span><canvas id=\"bar\" width=\"256\" height=\"12\"></canvas><span id=\"hi\"></span>",
            "<span class=\"hint\">drag to turn, wheel to zoom, double-click to reset</span></div>\n",
            "<p class=\"note\" id=\"note\"></p><p id=\"status\">loading the 3-D view…</p>\n</section>\n"
        )
        .to_string()
    };
    format!(
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; script-src {hash}; style-src 'unsafe-inline'; img-src data:\">\n\
         <title>{title}</title>\n<style>\n{css}</style></head>\n<body>\n<h1>{title}</h1>\n<p class=\"subtitle\">{subtitle}</p>\n{viewer}{sections}\n\
         <p class=\"subtitle\">Written by fshape {version}; every figure is also in the folder's JSON files.</p>\n\
         <script type=\"application/json\" id=\"fshape-data\">{data}</script>\n<script>{js}</script>\n</body></html>\n",
        hash = script_hash(js),
        title = escape(&page.title),
        subtitle = escape(&page.subtitle),
        css = include_str!("style.css"),
        sections = page.sections.join("\n"),
        version = env!("CARGO_PKG_VERSION"),
    )
}

/// A table: a header row and rows of cells (already HTML).
pub fn table(class: &str, header: &[&str], rows: &[Vec<String>]) -> String {
    let mut s = format!("<table class=\"{class}\"><thead><tr>");
    for h in header {
        s.push_str(&format!("<th>{}</th>", escape(h)));
    }
    s.push_str("</tr></thead><tbody>");
    for row in rows {
        s.push_str("<tr>");
        for c in row {
            s.push_str(&format!("<td>{c}</td>"));
        }
        s.push_str("</tr>");
    }
    s.push_str("</tbody></table>");
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn the_data_holds_no_markup_and_the_policy_names_the_page_script_alone() {
        let name = "</script><!--<script>&\"'>";
        let value = serde_json::json!({ "name": name });
        let text = script_json(&value);
        assert!(!text.contains(['<', '>', '&']), "{text}");
        assert_eq!(serde_json::from_str::<serde_json::Value>(&text).unwrap(), value);
        let page = html(&Page {
            title: name.into(),
            subtitle: String::new(),
            view: (0.0, 0.0),
            scenes: vec![],
            sections: vec![],
        });
        assert!(!page.contains("script-src 'unsafe-inline'"), "{page}");
        // The hash in the policy is that of the text between <script> and </script>.
        let start = page.rfind("<script>").unwrap() + "<script>".len();
        let end = page.rfind("</script>").unwrap();
        assert!(page.contains(&format!("script-src {};", script_hash(&page[start..end]))));
        // Known vector (FIPS 180-2): SHA-256("abc").
        assert_eq!(script_hash("abc"), "'sha256-ungWv48Bz+pBQUDeXa4iI7ADYaOWF3qctBD/YfIAFa0='");
    }

    #[test]
    fn the_viewer_colours_as_the_pictures_do() {
        let page = html(&Page {
            title: "t".into(),
            subtitle: String::new(),
            view: (0.0, 0.0),
            scenes: vec![],
            sections: vec![],
        });
        let start = page.find("id=\"fshape-data\">").unwrap() + "id=\"fshape-data\">".len();
        let end = start + page[start..].find("</script>").unwrap();
        let data: serde_json::Value = serde_json::from_str(&page[start..end]).unwrap();
        let colours: Vec<u8> = serde_json::from_value(data["colours"].clone()).unwrap();
        assert_eq!(colours.len(), 3 * 256);
        for (i, t) in [(0, 0.0), (128, 128.0 / 255.0), (255, 1.0)] {
            let want = render::viridis(t).map(|c| (255.0 * c).round() as u8);
            assert_eq!(colours[3 * i..3 * i + 3], want, "colour {i}");
        }
        // The viewer has no table of its own.
        assert!(!page.contains("0.267, 0.005"), "a second colour table in the script");
    }

    #[test]
    fn escaping_keeps_text_text() {
        assert_eq!(escape("<a href=\"x\">&</a>"), "&lt;a href=&quot;x&quot;&gt;&amp;&lt;/a&gt;");
    }
}
