//! `crease eval --report DIR` and `crease train --report DIR` (issue 22): the page exists,
//! every picture it shows exists and is not blank (PNGs decoded: not one colour; SVGs: drawing
//! elements), the numbers of its tables are the `--json` output's, and the heat maps show the
//! poses the evaluation found worst. On the horse split (`bench/horse`, skipped without
//! `../shared/data`) and the generated hand (`--hands`).

use crate::common;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use common::{crease, run_ok};
use serde_json::Value;

/// The repository root (the manifests of `bench/horse` name the data relative to it).
fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the workspace root")
        .to_path_buf()
}

/// The horse split's manifests, or `None` (and a note) when the data is absent.
fn horse() -> Option<(PathBuf, PathBuf)> {
    let data = repo().join("../shared/data/horse/reference.obj");
    if !data.exists() {
        println!("skipped: horse data not found at {}", data.display());
        return None;
    }
    let bench = repo().join("bench/horse");
    Some((bench.join("train.toml"), bench.join("test.toml")))
}

/// One `<td>` of a page with a `data-value`: its `data-*` attributes and its text.
#[derive(Debug)]
struct Cell {
    attrs: Vec<(String, String)>,
    text: String,
}

impl Cell {
    fn get(&self, name: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }
}

fn unescape(s: &str) -> String {
    s.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&#39;", "'")
        .replace("&amp;", "&")
}

/// Every `<td ...data-value=...>TEXT</td>` of `html`.
fn cells(html: &str) -> Vec<Cell> {
    let mut out = Vec::new();
    let mut rest = html;
    while let Some(start) = rest.find("<td") {
        let tag_end = start + rest[start..].find('>').expect("a closed <td> tag");
        let tag = &rest[start + 3..tag_end];
        let close = tag_end + rest[tag_end..].find("</td>").expect("a </td>");
        let text = unescape(&rest[tag_end + 1..close]);
        let mut attrs = Vec::new();
        let mut t = tag;
        while let Some(a) = t.find("data-") {
            let eq = a + t[a..].find("=\"").expect("an attribute value");
            let end = eq + 2 + t[eq + 2..].find('"').expect("a closing quote");
            attrs.push((t[a + 5..eq].to_owned(), unescape(&t[eq + 2..end])));
            t = &t[end + 1..];
        }
        if attrs.iter().any(|(k, _)| k == "value") {
            out.push(Cell { attrs, text });
        }
        rest = &rest[close..];
    }
    out
}

/// The `src` of every `<img>` of `html`.
fn images(html: &str) -> Vec<String> {
    html.match_indices("<img src=\"")
        .map(|(i, m)| {
            let s = &html[i + m.len()..];
            unescape(&s[..s.find('"').expect("a closing quote")])
        })
        .collect()
}

/// Checks every picture of the page in `dir`: present, and not blank. Returns their names.
fn check_images(dir: &Path, html: &str) -> Vec<String> {
    let srcs = images(html);
    assert!(srcs.len() >= 6, "only {} pictures: {srcs:?}", srcs.len());
    for src in &srcs {
        let path = dir.join(src);
        let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        if src.ends_with(".png") {
            let decoder = png::Decoder::new(std::io::Cursor::new(&bytes));
            let mut reader = decoder.read_info().expect("a well-formed report");
            let mut buf = vec![0; reader.output_buffer_size().expect("a well-formed report")];
            let info = reader.next_frame(&mut buf).expect("a well-formed report");
            assert_eq!(info.color_type, png::ColorType::Rgb, "{src}");
            let px: Vec<[u8; 3]> = buf[..info.buffer_size()]
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect();
            let distinct: BTreeSet<[u8; 3]> = px.iter().copied().collect();
            let lum: Vec<f64> = px
                .iter()
                .map(|p| 0.2126 * p[0] as f64 + 0.7152 * p[1] as f64 + 0.0722 * p[2] as f64)
                .collect();
            let mean = lum.iter().sum::<f64>() / lum.len() as f64;
            let sd =
                (lum.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / lum.len() as f64).sqrt();
            assert!(
                distinct.len() > 50 && sd > 3.0,
                "{src}: blank ({} colours, luminance s.d. {sd:.2})",
                distinct.len()
            );
            if src.contains("worst") {
                // A heat map: some vertices coloured warmer than the grey start of the scale.
                let warm = px.iter().filter(|p| p[0] as i32 - p[2] as i32 > 60).count();
                assert!(warm > 1000, "{src}: only {warm} heat-coloured pixels");
            }
        } else if src.ends_with(".svg") {
            let text = String::from_utf8(bytes).expect("a well-formed report");
            assert!(text.starts_with("<svg"), "{src}: not an SVG");
            let drawn: usize = ["<rect", "<polyline", "<circle", "<path", "<line"]
                .iter()
                .map(|e| text.matches(e).count())
                .sum();
            assert!(drawn > 10, "{src}: {drawn} drawing elements");
            assert!(text.contains("<text"), "{src}: no labels");
        } else {
            panic!("{src}: neither PNG nor SVG");
        }
    }
    srcs
}

/// The page's number `text` is its value rounded to 4 significant digits.
fn check_text(cell: &Cell, want: f64) {
    let shown: f64 = cell.text.parse().unwrap_or_else(|_| panic!("{cell:?}"));
    assert!(
        (shown - want).abs() <= 1e-3 * want.abs(),
        "{cell:?}: shows {shown} for {want}"
    );
}

/// The evaluation page's tables against the `--json` output, both ways; returns the page's
/// highlighted (pictured) row per protocol.
fn check_eval_numbers(html: &str, json: &Value) {
    let cells = cells(html);
    let mut seen = BTreeSet::new();
    for c in &cells {
        let (p, r, k) = (
            c.get("protocol").expect("a well-formed report"),
            c.get("row").expect("a well-formed report"),
            c.get("key").expect("a well-formed report"),
        );
        let stats = &json[p][r];
        let want = if k == "frames" {
            stats["frames"]
                .as_array()
                .expect("a well-formed report")
                .len() as f64
        } else {
            stats[k]
                .as_f64()
                .unwrap_or_else(|| panic!("{p}/{r}/{k} not in --json"))
        };
        let got: f64 = c
            .get("value")
            .expect("a well-formed report")
            .parse()
            .expect("a well-formed report");
        assert_eq!(got.to_bits(), want.to_bits(), "{p}/{r}/{k}");
        check_text(c, want);
        seen.insert(format!("{p}/{r}/{k}"));
    }
    for (p, rows) in json.as_object().expect("a well-formed report") {
        for r in rows.as_object().expect("a well-formed report").keys() {
            for k in ["rms_mean", "rms_max", "us_per_frame", "frames"] {
                assert!(
                    seen.contains(&format!("{p}/{r}/{k}")),
                    "{p}/{r}/{k} missing"
                );
            }
        }
    }
}

/// The pictured method of each protocol is the evaluated method with the lowest mean error,
/// and its first heat map shows its worst pose, whose RMS the caption gives.
fn check_worst(html: &str, json: &Value, methods: &[&str]) {
    for (protocol, rows) in json.as_object().expect("a well-formed report") {
        let best = methods
            .iter()
            .min_by(|a, b| {
                rows[**a]["rms_mean"]
                    .as_f64()
                    .expect("a well-formed report")
                    .total_cmp(
                        &rows[**b]["rms_mean"]
                            .as_f64()
                            .expect("a well-formed report"),
                    )
            })
            .expect("a well-formed report");
        let table = &html[html
            .find(&format!(
                "<table class=\"results\" data-protocol=\"{protocol}\""
            ))
            .expect("a well-formed report")..];
        let shown = &table[table
            .find("<tr class=\"shown\"><th>")
            .expect("a well-formed report")
            + 22..];
        assert!(
            shown.starts_with(&format!("{best}<")),
            "{protocol}: {shown:.40}"
        );
        let worst = rows[*best]["frames"]
            .as_array()
            .expect("a well-formed report")
            .iter()
            .map(|v| v.as_f64().expect("a well-formed report"))
            .fold(0.0, f64::max);
        let figure = &html[html
            .find(&format!("src=\"{protocol}-worst-1.png\""))
            .expect("a well-formed report")..];
        let rms = &figure[figure.find(", RMS ").expect("a well-formed report") + 6..];
        let rms: f64 = rms[..rms.find([',', ' ']).expect("a well-formed report")]
            .parse()
            .expect("a well-formed report");
        assert!(
            (rms - worst).abs() <= 1e-4 * worst,
            "{protocol}: the first heat map's RMS {rms} is not the worst pose's {worst}"
        );
    }
}

fn report_dir(name: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path().join(name);
    (tmp, dir)
}

#[test]
fn eval_report_of_the_horse_split() {
    let Some((train, test)) = horse() else { return };
    let (_tmp, dir) = report_dir("horse");
    let t = std::time::Instant::now();
    let out = run_ok(
        crease()
            .args(["eval", "--examples"])
            .arg(&train)
            .arg("--test")
            .arg(&test)
            .args(["--bones", "20", "--methods", "global,local", "--select"])
            .args(["--json", "--report"])
            .arg(&dir),
    );
    println!("horse eval --report: {:.1} s", t.elapsed().as_secs_f64());
    let json: Value = serde_json::from_str(&out).unwrap();
    let html = std::fs::read_to_string(dir.join("index.html")).unwrap();
    let srcs = check_images(&dir, &html);
    for want in [
        "test-worst-1.png",
        "test-worst-3.png",
        "test-bones.svg",
        "selection.svg",
        "controls.png",
        "timings.svg",
    ] {
        assert!(srcs.iter().any(|s| s == want), "no {want} in {srcs:?}");
    }
    check_eval_numbers(&html, &json);
    check_worst(&html, &json, &["global", "local"]);
    // The selection grid has a cell per candidate (11 kernels x 4 kappas x 4 betas).
    let grid = std::fs::read_to_string(dir.join("selection.svg")).unwrap();
    let numbers = grid
        .split("<text")
        .skip(1)
        .filter(|t| {
            let body = &t[t.find('>').unwrap() + 1..t.find("</text>").unwrap()];
            body.trim().contains("e-") && body.contains('.') && body.trim().parse::<f64>().is_ok()
        })
        .count();
    assert!(numbers >= 176, "{numbers} numbers in the selection grid");
}

#[test]
fn eval_report_of_the_generated_hand_with_leave_one_out() {
    let (_tmp, dir) = report_dir("hand");
    let t = std::time::Instant::now();
    let out = run_ok(
        crease()
            .args(["eval", "--hands", "extrapolation", "--hand-test", "6"])
            .args(["--bones", "12", "--methods", "global,local", "--loo"])
            .args(["--json", "--report"])
            .arg(&dir),
    );
    println!(
        "hand eval --loo --report: {:.1} s",
        t.elapsed().as_secs_f64()
    );
    let json: Value = serde_json::from_str(&out).unwrap();
    let html = std::fs::read_to_string(dir.join("index.html")).unwrap();
    let srcs = check_images(&dir, &html);
    for want in ["test-worst-1.png", "loo-worst-1.png", "loo-bones.svg"] {
        assert!(srcs.iter().any(|s| s == want), "no {want} in {srcs:?}");
    }
    assert!(json.get("loo").is_some() && json.get("test").is_some());
    check_eval_numbers(&html, &json);
    check_worst(&html, &json, &["global", "local"]);
}

#[test]
fn train_report_of_the_horse_with_selection() {
    let Some((train, _)) = horse() else { return };
    let (tmp, dir) = report_dir("horse-train");
    let out = run_ok(
        crease()
            .args(["train", "--examples"])
            .arg(&train)
            .args(["--bones", "20", "--select", "--json", "--out"])
            .arg(tmp.path().join("horse.crease"))
            .arg("--report")
            .arg(&dir),
    );
    let json: Value = serde_json::from_str(&out).unwrap();
    let html = std::fs::read_to_string(dir.join("index.html")).unwrap();
    let srcs = check_images(&dir, &html);
    for want in ["selection.svg", "fit.svg", "bones.svg", "train-worst-1.png"] {
        assert!(srcs.iter().any(|s| s == want), "no {want} in {srcs:?}");
    }
    // Every cell is the JSON number at its path, and every number outside arrays is shown.
    let cells = cells(&html);
    let mut seen = BTreeSet::new();
    for c in &cells {
        let path = c.get("path").unwrap();
        let mut v = &json;
        for key in path.split('.') {
            v = match key.parse::<usize>() {
                Ok(i) if v.is_array() => &v[i],
                _ => &v[key],
            };
        }
        let want = v
            .as_f64()
            .unwrap_or_else(|| panic!("{path}: not a number in --json"));
        let got: f64 = c.get("value").unwrap().parse().unwrap();
        assert_eq!(got.to_bits(), want.to_bits(), "{path}");
        check_text(c, want);
        seen.insert(path.to_owned());
    }
    fn leaves(v: &Value, path: String, out: &mut Vec<String>) {
        match v {
            Value::Object(o) => o.iter().for_each(|(k, v)| {
                let p = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                leaves(v, p, out);
            }),
            Value::Number(_) => out.push(path),
            _ => {}
        }
    }
    let mut all = Vec::new();
    leaves(&json, String::new(), &mut all);
    assert!(all.len() > 10, "{all:?}");
    for p in &all {
        assert!(seen.contains(p), "{p} missing from the page");
    }
    assert!(json["selection"]["best"]["rms"].is_number());
}
