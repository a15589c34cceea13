//! The reports of `werkstatt test`: `results.json` (what `report merge` reads), JUnit XML
//! (which every CI system reads) and a self-contained HTML page (reference, current and diff
//! side by side for every failing image, and each case's time against its reference time).

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Context as _;

use super::{CaseResult, RESULTS, Status, TestRun};

/// Writes `results.json`, `junit.xml` and `report.html` into `dir` (atomically each).
pub fn write_all(dir: &Path, run: &TestRun) -> anyhow::Result<()> {
    let write = |name: &str, text: String| {
        crate::io::atomic::write_atomic(&dir.join(name), text.as_bytes())
            .with_context(|| format!("cannot write {}", dir.join(name).display()))
    };
    write(RESULTS, serde_json::to_string_pretty(run)? + "\n")?;
    write("junit.xml", junit(run))?;
    write("report.html", html(run, dir))
}

/// Escapes text for XML and HTML (element content and quoted attributes).
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            // Control characters other than tab and newline are not allowed in XML 1.0.
            c if (c as u32) < 0x20 && c != '\t' && c != '\n' => out.push_str(&format!("\\u{{{:x}}}", c as u32)),
            c => out.push(c),
        }
    }
    out
}

fn seconds(ms: f64) -> String {
    format!("{:.3}", ms / 1e3)
}

/// The JUnit XML report: one test suite, one test case per case (class name: the graph's
/// stem), a `failure` for a regression and an `error` when the case could not be compared.
pub fn junit(run: &TestRun) -> String {
    let total: f64 = run.cases.iter().map(|c| c.render_ms + c.compare_ms).sum();
    let (failures, errors) = (run.count(Status::Failed), run.count(Status::Error));
    let mut x = String::from("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    let _ = writeln!(
        x,
        "<testsuites name=\"werkstatt test\" tests=\"{}\" failures=\"{failures}\" errors=\"{errors}\" time=\"{}\">",
        run.cases.len(),
        seconds(total)
    );
    let _ = writeln!(
        x,
        "  <testsuite name=\"werkstatt test\" tests=\"{}\" failures=\"{failures}\" errors=\"{errors}\" skipped=\"0\" time=\"{}\">",
        run.cases.len(),
        seconds(total)
    );
    for c in &run.cases {
        let class = c.name.split('@').next().unwrap_or(&c.name);
        let _ = write!(
            x,
            "    <testcase classname=\"graphs.{}\" name=\"{}\" file=\"{}\" time=\"{}\"",
            escape(class),
            escape(&c.name),
            escape(&c.graph),
            seconds(c.render_ms + c.compare_ms)
        );
        let message = c.message.as_deref().unwrap_or("");
        let first = message.lines().next().unwrap_or("");
        let body = match c.status {
            Status::Failed => format!(
                "      <failure message=\"{}\" type=\"regression\">{}</failure>\n",
                escape(first),
                escape(message)
            ),
            Status::Error => {
                format!("      <error message=\"{}\" type=\"error\">{}</error>\n", escape(first), escape(message))
            }
            Status::Passed | Status::Blessed => String::new(),
        };
        let mut out = String::new();
        if !c.sets.is_empty() {
            let _ = writeln!(out, "sets: {}", c.sets.join(" "));
        }
        if c.graph_changed == Some(true) {
            let _ = writeln!(out, "graph: {} changed since the last bless", c.graph);
        }
        for o in &c.outputs {
            let _ = writeln!(out, "{}: {} {}", o.name, if o.passed { "ok" } else { "FAILED" }, o.detail);
        }
        if let Some(r) = c.reference_ms {
            let _ = writeln!(
                out,
                "time: {:.1} ms, reference {r:.1} ms{}",
                c.render_ms,
                if c.slow { " (SLOW)" } else { "" }
            );
        }
        if body.is_empty() && out.is_empty() {
            x.push_str(" />\n");
            continue;
        }
        x.push_str(">\n");
        x.push_str(&body);
        if !out.is_empty() {
            let _ = writeln!(x, "      <system-out>{}</system-out>", escape(&out));
        }
        x.push_str("    </testcase>\n");
    }
    x.push_str("  </testsuite>\n</testsuites>\n");
    x
}

/// The HTML report: a table of every case, then reference | current | diff for each failing
/// image, embedded as data URLs so the page is one file that CI can keep as an artifact.
/// Images are read from `dir` (the run's folder), where the case folders are.
pub fn html(run: &TestRun, dir: &Path) -> String {
    let mut h = String::from(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>werkstatt test</title>\n<style>\n\
         body{font-family:sans-serif;margin:1.5em}table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:.2em .6em;text-align:left}\n\
         .passed,.blessed{color:#070}.failed,.error{color:#b00;font-weight:bold}.slow{color:#a60;font-weight:bold}\n\
         figure{display:inline-block;margin:.3em}img{width:256px;image-rendering:pixelated;border:1px solid #888}pre{white-space:pre-wrap}\n\
         </style></head><body>\n<h1>werkstatt test</h1>\n",
    );
    let _ = writeln!(h, "<p>{}</p>", escape(&run.summary()));
    h.push_str(
        "<table><tr><th>case</th><th>status</th><th>overrides (--set)</th><th>graph since bless</th><th>render ms</th><th>reference ms</th><th>compare ms</th></tr>\n",
    );
    for c in &run.cases {
        let status = status_name(&c.status);
        let reference = c.reference_ms.map_or_else(String::new, |r| format!("{r:.1}"));
        let slow = if c.slow { " <span class=\"slow\">slower</span>" } else { "" };
        let _ = writeln!(
            h,
            "<tr><td><a href=\"#{id}\">{name}</a></td><td class=\"{status}\">{status}</td><td>{sets}</td><td>{changed}</td><td>{:.1}{slow}</td><td>{reference}</td><td>{:.1}</td></tr>",
            c.render_ms,
            c.compare_ms,
            id = anchor(&c.name),
            name = escape(&c.name),
            sets = escape(&c.sets.join(" ")),
            changed = graph_state(c)
        );
    }
    h.push_str("</table>\n");
    for c in run.cases.iter().filter(|c| matches!(c.status, Status::Failed | Status::Error) || c.slow) {
        section(&mut h, c, dir);
    }
    h.push_str("</body></html>\n");
    h
}

/// Whether the graph changed since the bless, for the HTML table.
fn graph_state(c: &CaseResult) -> &'static str {
    match c.graph_changed {
        Some(true) => "<span class=\"slow\">changed</span>",
        Some(false) => "same",
        None => "",
    }
}

fn status_name(s: &Status) -> &'static str {
    match s {
        Status::Passed => "passed",
        Status::Failed => "failed",
        Status::Error => "error",
        Status::Blessed => "blessed",
    }
}

fn anchor(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '-' }).collect()
}

fn section(h: &mut String, c: &CaseResult, dir: &Path) {
    let _ = writeln!(
        h,
        "<h2 id=\"{}\">{} <span class=\"{}\">{}</span></h2>",
        anchor(&c.name),
        escape(&c.name),
        status_name(&c.status),
        status_name(&c.status)
    );
    let _ = writeln!(
        h,
        "<p>graph {} {}{}</p>",
        escape(&c.graph),
        graph_state(c),
        if c.sets.is_empty() { String::new() } else { format!(", --set {}", escape(&c.sets.join(" "))) }
    );
    if let Some(r) = c.reference_ms.filter(|_| c.slow) {
        let _ = writeln!(h, "<p class=\"slow\">render {:.1} ms against {r:.1} ms at the last bless</p>", c.render_ms);
    }
    if let Some(m) = &c.message {
        let _ = writeln!(h, "<pre>{}</pre>", escape(m));
    }
    for o in c.outputs.iter().filter(|o| !o.passed) {
        let Some(images) = &o.images else { continue };
        let _ = writeln!(h, "<h3>{}</h3><div>", escape(&o.name));
        let diff = format!("diff (levels x{:.1}: the largest is white)", o.diff_scale.unwrap_or(1.0));
        for (label, path) in ["reference", "current", diff.as_str()].iter().zip(images) {
            let src = match std::fs::read(dir.join(path)) {
                Ok(bytes) => format!("data:image/png;base64,{}", base64::encode(bytes)),
                Err(_) => escape(path),
            };
            let _ = writeln!(h, "<figure><img src=\"{src}\" alt=\"{label}\"><figcaption>{label}</figcaption></figure>");
        }
        h.push_str("</div>\n");
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn escapes_markup_and_control_characters() {
        assert_eq!(super::escape("a<b & \"c\"\u{1}"), "a&lt;b &amp; &quot;c&quot;\\u{1}");
    }
}
