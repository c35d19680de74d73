//! The report page: one self-contained HTML file (its pictures beside it) with inline CSS.
//!
//! Every number of a results table is written from the same `serde_json::Value` that `--json`
//! prints: the cell's `data-value` attribute holds the number exactly as the JSON text has it
//! (serde_json's shortest round-trip form), the visible text a rounded copy. Cells carry where
//! the number comes from: `data-protocol`, `data-row` and `data-key` in an evaluation table
//! (`frames` is the count of the row's `frames` array), `data-path` (object keys joined by
//! `.`) in the training report's table.

use serde_json::Value;

/// Escapes text for HTML content and attribute values.
pub(super) fn escape(text: &str) -> String {
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

/// A number as a person reads it: integers whole, others to 4 significant digits.
fn readable(n: &serde_json::Number) -> String {
    if n.is_i64() || n.is_u64() {
        return n.to_string();
    }
    let v = n.as_f64().unwrap_or(f64::NAN);
    let a = v.abs();
    if v == 0.0 {
        "0".to_owned()
    } else if (0.1..1e5).contains(&a) {
        let digits = (3 - a.log10().floor() as i32).max(0) as usize;
        format!("{v:.digits$}")
    } else {
        format!("{v:.3e}")
    }
}

/// A table cell holding the JSON number `n` (`attrs` say where it comes from).
fn number_cell(n: &serde_json::Number, attrs: &str) -> String {
    format!(
        "<td class=\"num\" {attrs} data-value=\"{}\">{}</td>",
        escape(&n.to_string()),
        escape(&readable(n))
    )
}

/// Column keys of an evaluation table, those that some row has.
const EVAL_COLUMNS: [(&str, &str); 8] = [
    ("rms_mean", "RMS mean"),
    ("rms_max", "RMS max"),
    ("us_per_frame", "µs / frame"),
    ("frames", "frames"),
    ("base_rms_mean", "base RMS"),
    ("detail_rms_mean", "detail RMS"),
    ("crease_rms_mean", "crease RMS"),
    ("crease_h_rms_mean", "crease h RMS"),
];

/// One protocol's results table from its JSON object (`{ROW: {rms_mean, ...}}`), rows in
/// `rows` order; `highlight` is the row the pictures show.
pub(super) fn eval_table(protocol: &str, table: &Value, rows: &[&str], highlight: &str) -> String {
    let present: Vec<(&str, &str)> = EVAL_COLUMNS
        .iter()
        .copied()
        .filter(|(key, _)| rows.iter().any(|r| table[*r].get(key).is_some()))
        .collect();
    let mut html = format!(
        "<table class=\"results\" data-protocol=\"{}\">\n<thead><tr><th>method</th>",
        escape(protocol)
    );
    for (_, title) in &present {
        html.push_str(&format!("<th>{}</th>", escape(title)));
    }
    html.push_str("<th>selected (kernel, kappa, beta)</th></tr></thead>\n<tbody>\n");
    for row in rows {
        let Some(stats) = table.get(*row) else {
            continue;
        };
        let class = if *row == highlight {
            " class=\"shown\""
        } else {
            ""
        };
        html.push_str(&format!("<tr{class}><th>{}</th>", escape(row)));
        for (key, _) in &present {
            let attrs = format!(
                "data-protocol=\"{}\" data-row=\"{}\" data-key=\"{key}\"",
                escape(protocol),
                escape(row)
            );
            match stats.get(*key) {
                Some(Value::Number(n)) => html.push_str(&number_cell(n, &attrs)),
                Some(Value::Array(frames)) => {
                    html.push_str(&number_cell(&frames.len().into(), &attrs));
                }
                _ => html.push_str("<td></td>"),
            }
        }
        let selected =
            stats
                .get("selected")
                .and_then(Value::as_array)
                .map_or(String::new(), |picks| {
                    let mut text: Vec<String> = picks.iter().take(3).map(candidate).collect();
                    if picks.len() > 3 {
                        text.push(format!("… ({} folds)", picks.len()));
                    }
                    text.join("; ")
                });
        html.push_str(&format!(
            "<td class=\"text\">{}</td></tr>\n",
            escape(&selected)
        ));
    }
    html.push_str("</tbody></table>\n");
    html
}

/// A selected candidate's JSON as `kernel, kappa, beta`.
fn candidate(c: &Value) -> String {
    let kernel = match c.get("kernel") {
        Some(Value::Object(k)) => k
            .iter()
            .map(|(name, params)| {
                let p: Vec<String> = params
                    .as_object()
                    .map(|o| o.iter().map(|(k, v)| format!("{k} {v}")).collect())
                    .unwrap_or_default();
                format!("{name} {}", p.join(" "))
            })
            .collect::<Vec<_>>()
            .join(" "),
        Some(other) => other.to_string(),
        None => String::new(),
    };
    format!(
        "{kernel}, {}, {}",
        c.get("kappa").map_or(String::new(), Value::to_string),
        c.get("beta").map_or(String::new(), Value::to_string)
    )
}

/// Arrays of numbers up to this long are shown element by element in [`json_table`]; longer
/// ones, and arrays of objects, are left to the plots.
pub(super) const MAX_LISTED_ARRAY: usize = 16;

/// The training report's table: every leaf of `json` (numbers with their exact value, text as
/// text) by its path, arrays of at most [`MAX_LISTED_ARRAY`] scalars by element, other arrays
/// summarised by their length.
pub(super) fn json_table(json: &Value) -> String {
    let mut rows = String::new();
    flatten(json, String::new(), &mut rows);
    format!(
        "<table class=\"results\" id=\"train-report\">\n<thead><tr><th>field</th><th>value</th></tr></thead>\n<tbody>\n{rows}</tbody></table>\n"
    )
}

fn flatten(v: &Value, path: String, out: &mut String) {
    let row = |value_cell: String| format!("<tr><th>{}</th>{value_cell}</tr>\n", escape(&path));
    match v {
        Value::Object(o) => {
            for (k, v) in o {
                let p = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                flatten(v, p, out);
            }
        }
        Value::Array(a)
            if a.len() <= MAX_LISTED_ARRAY && a.iter().all(|x| !x.is_object() && !x.is_array()) =>
        {
            if a.is_empty() {
                out.push_str(&row("<td class=\"text\">(none)</td>".to_owned()));
            }
            for (i, x) in a.iter().enumerate() {
                flatten(x, format!("{path}.{i}"), out);
            }
        }
        Value::Array(a) => out.push_str(&row(format!(
            "<td class=\"text\">{} entries (plotted below)</td>",
            a.len()
        ))),
        Value::Number(n) => {
            let attrs = format!("data-path=\"{}\"", escape(&path));
            out.push_str(&row(number_cell(n, &attrs)));
        }
        Value::String(s) => out.push_str(&row(format!("<td class=\"text\">{}</td>", escape(s)))),
        Value::Bool(b) => out.push_str(&row(format!("<td class=\"text\">{b}</td>"))),
        Value::Null => out.push_str(&row("<td class=\"text\">none</td>".to_owned())),
    }
}

/// A picture with its caption.
pub(super) fn figure(src: &str, alt: &str, caption: &str) -> String {
    format!(
        "<figure><img src=\"{}\" alt=\"{}\"><figcaption>{}</figcaption></figure>\n",
        escape(src),
        escape(alt),
        caption
    )
}

/// A section: heading, then `body` (HTML).
pub(super) fn section(id: &str, title: &str, body: &str) -> String {
    format!(
        "<section id=\"{}\">\n<h2>{}</h2>\n{body}</section>\n",
        escape(id),
        escape(title)
    )
}

/// A `<dl>` of `(term, text)` pairs (both escaped).
pub(super) fn facts(items: &[(String, String)]) -> String {
    let mut html = String::from("<dl class=\"facts\">\n");
    for (k, v) in items {
        html.push_str(&format!("<dt>{}</dt><dd>{}</dd>\n", escape(k), escape(v)));
    }
    html.push_str("</dl>\n");
    html
}

/// The whole page.
pub(super) fn page(title: &str, sections: &[String]) -> String {
    let mut html = format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{}</title>\n<style>\n{CSS}</style>\n</head>\n<body>\n<h1>{}</h1>\n",
        escape(title),
        escape(title)
    );
    html.push_str("<nav>");
    for s in sections {
        if let (Some(a), Some(b)) = (s.find("id=\""), s.find("<h2>")) {
            let id = &s[a + 4..s[a + 4..].find('"').map_or(a + 4, |e| a + 4 + e)];
            let end = s[b..].find("</h2>").map_or(b + 4, |e| b + e);
            html.push_str(&format!("<a href=\"#{id}\">{}</a> ", &s[b + 4..end]));
        }
    }
    html.push_str("</nav>\n");
    for s in sections {
        html.push_str(s);
    }
    html.push_str("</body>\n</html>\n");
    html
}

const CSS: &str = "body { font-family: system-ui, sans-serif; margin: 1.5em auto; max-width: 1240px; padding: 0 1em; background: #fafafa; color: #222; }
h1 { font-size: 1.5em; margin-bottom: 0.3em; }
h2 { font-size: 1.2em; border-bottom: 1px solid #ccc; padding-bottom: 0.2em; margin-top: 1.6em; }
nav a { margin-right: 0.8em; font-size: 0.9em; }
table.results { border-collapse: collapse; font-size: 0.9em; margin: 0.6em 0; }
table.results th, table.results td { border: 1px solid #ddd; padding: 0.25em 0.6em; }
table.results thead th { background: #eee; }
table.results tbody th { text-align: left; font-weight: normal; font-family: ui-monospace, monospace; }
td.num { text-align: right; font-family: ui-monospace, monospace; }
td.text { font-size: 0.85em; }
tr.shown { background: #fff3d6; }
figure { margin: 0.8em 0; }
figure img { max-width: 100%; border: 1px solid #ddd; background: #fff; }
figcaption { font-size: 0.85em; color: #555; max-width: 1140px; }
dl.facts { display: grid; grid-template-columns: max-content auto; gap: 0.15em 1em; font-size: 0.9em; }
dl.facts dt { color: #555; }
dl.facts dd { margin: 0; font-family: ui-monospace, monospace; word-break: break-all; }
";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_keep_the_json_text() {
        let json: Value = serde_json::from_str(
            r#"{"global": {"rms_mean": 0.012345678901234, "rms_max": 3e-7, "us_per_frame": 41.5, "frames": [1, 2, 3]}}"#,
        )
        .unwrap();
        let html = eval_table("test", &json, &["global"], "global");
        assert!(html.contains("data-key=\"rms_mean\" data-value=\"0.012345678901234\">1.235e-2<"));
        assert!(html.contains("data-value=\"3e-7\">3.000e-7<"));
        assert!(html.contains("data-key=\"frames\" data-value=\"3\">3<"));
        let flat = json_table(&json);
        assert!(flat.contains("data-path=\"global.frames.2\" data-value=\"3\""));
        assert_eq!(escape("<a&\"b\">"), "&lt;a&amp;&quot;b&quot;&gt;");
    }
}
