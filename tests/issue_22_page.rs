//! Issue 22, item 7: the report page read at 1400 px in headless Chromium
//! (Debian's `chromium`; `.ci/run` installs it and sets
//! `SURGBENCH_REQUIRE_CHROMIUM=1`). No table may need a horizontal scroll,
//! the page may not be wider than the window, every plot must load and
//! every in-page link must reach its anchor. Screenshots of the first
//! screen and of one scene section go to `SURGBENCH_SCREENSHOTS` (a
//! folder) when set.
//!
//! Without a browser the tests say so and pass, unless
//! `SURGBENCH_REQUIRE_CHROMIUM=1`: then a missing browser fails them.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use surgbench_reports::{AccuracyTarget, ResultRow, RunInfo, Status, render, write_results_csv};

/// The window a reviewer reads the report in.
const WINDOW: (u32, u32) = (1400, 900);

/// The browser: `SURGBENCH_CHROMIUM`, else the first of Debian's and
/// Google's names on `PATH`.
fn browser() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("SURGBENCH_CHROMIUM") {
        return Some(PathBuf::from(p));
    }
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .flat_map(|d| ["chromium", "chromium-browser", "google-chrome"].map(|n| d.join(n)))
        .find(|p| p.is_file())
}

/// The browser, or `None` after saying why the test does not run; panics
/// when CI asked for it (`SURGBENCH_REQUIRE_CHROMIUM=1`).
fn browser_or_skip() -> Option<PathBuf> {
    let b = browser();
    if b.is_none() {
        assert!(
            std::env::var("SURGBENCH_REQUIRE_CHROMIUM").as_deref() != Ok("1"),
            "SURGBENCH_REQUIRE_CHROMIUM=1 but no chromium on PATH (apt-get install chromium)"
        );
        eprintln!("no chromium on PATH: the page is not checked in a browser here");
    }
    b
}

/// Chromium, headless, at [`WINDOW`], with its own profile folder, run to
/// completion within a minute; returns its stdout and stderr. Both go to
/// files: a page's DOM dump is larger than a pipe holds.
fn chromium(browser: &Path, profile: &Path, args: &[String]) -> (String, String) {
    let (out, err) = (profile.join("stdout"), profile.join("stderr"));
    let mut child = Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--no-first-run",
            &format!("--user-data-dir={}", profile.join("profile").display()),
            &format!("--window-size={},{}", WINDOW.0, WINDOW.1),
            // Let images load and scripts run before the dump or screenshot.
            "--virtual-time-budget=10000",
        ])
        .args(args)
        .stdout(std::fs::File::create(&out).unwrap())
        .stderr(std::fs::File::create(&err).unwrap())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "chromium ran past 60 s: {}",
                std::fs::read_to_string(&err).unwrap_or_default()
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let read = |p: &Path| String::from_utf8_lossy(&std::fs::read(p).unwrap()).into_owned();
    (read(&out), read(&err))
}

/// Measures the page after load, in the browser: widths, tables that
/// would scroll, images that did not load, links without their anchor.
const CHECK_JS: &str = r##"<script>
window.addEventListener('load', () => {
  const de = document.documentElement;
  const r = {
    client_w: de.clientWidth,
    doc_w: de.scrollWidth,
    tables: document.querySelectorAll('table').length,
    overflowing: [...document.querySelectorAll('div.scroll')]
      .filter(d => d.scrollWidth > d.clientWidth + 1)
      .map(d => (d.querySelector('tr') || d).textContent.slice(0, 80) + ' (' + d.scrollWidth + ' px > ' + d.clientWidth + ' px)'),
    images: document.images.length,
    broken: [...document.images].filter(i => !(i.complete && i.naturalWidth > 0)).map(i => i.getAttribute('src')),
    links: document.querySelectorAll('a[href^="#"]').length,
    dangling: [...document.querySelectorAll('a[href^="#"]')]
      .map(a => a.getAttribute('href').slice(1))
      .filter(id => !document.getElementById(id)),
  };
  const pre = document.createElement('pre');
  pre.id = 'surgbench-check';
  pre.textContent = JSON.stringify(r);
  document.body.appendChild(pre);
});
</script>"##;

/// What [`CHECK_JS`] found on `dir/index.html`.
fn check_page(browser: &Path, dir: &Path) -> serde_json::Value {
    let html = std::fs::read_to_string(dir.join("index.html")).unwrap();
    // A copy beside the page, so that its relative plot paths resolve.
    let probe = dir.join(".page-check.html");
    std::fs::write(&probe, html.replace("</body>", &format!("{CHECK_JS}\n</body>"))).unwrap();
    let profile = tempfile::tempdir().unwrap();
    let (dom, err) = chromium(
        browser,
        profile.path(),
        &["--dump-dom".into(), format!("file://{}", probe.display())],
    );
    std::fs::remove_file(&probe).unwrap();
    let start = dom
        .find("<pre id=\"surgbench-check\">")
        .unwrap_or_else(|| panic!("the check did not run: {err}"));
    let rest = &dom[start + "<pre id=\"surgbench-check\">".len()..];
    let json = &rest[..rest.find("</pre>").unwrap()];
    let json = json.replace("&lt;", "<").replace("&gt;", ">").replace("&amp;", "&");
    serde_json::from_str(&json).unwrap()
}

/// Screenshots of the first screen and of the section `section` (the page
/// cut to start at that heading) into `SURGBENCH_SCREENSHOTS`, or a
/// temporary folder; returns the two files.
fn screenshots(browser: &Path, dir: &Path, name: &str, section: &str) -> [PathBuf; 2] {
    let out = std::env::var_os("SURGBENCH_SCREENSHOTS").map_or_else(|| dir.join("screenshots"), PathBuf::from);
    std::fs::create_dir_all(&out).unwrap();
    let html = std::fs::read_to_string(dir.join("index.html")).unwrap();
    let body = html.find("<body>\n").unwrap() + "<body>\n".len();
    let at = html
        .find(&format!("<h2 id=\"{section}\">"))
        .unwrap_or_else(|| panic!("no section {section}"));
    let cut = dir.join(".section.html");
    std::fs::write(&cut, format!("{}{}", &html[..body], &html[at..])).unwrap();
    let shots = [
        out.join(format!("{name}-first-screen.png")),
        out.join(format!("{name}-{section}.png")),
    ];
    for (page, png) in [(dir.join("index.html"), &shots[0]), (cut.clone(), &shots[1])] {
        let profile = tempfile::tempdir().unwrap();
        let (_, err) = chromium(
            browser,
            profile.path(),
            &[
                format!("--screenshot={}", png.display()),
                format!("file://{}", page.display()),
            ],
        );
        assert!(png.is_file(), "no screenshot {}: {err}", png.display());
    }
    std::fs::remove_file(&cut).unwrap();
    shots
}

/// The page's checks, with the findings in the message.
fn assert_page_fits(c: &serde_json::Value, min_images: u64) {
    let n = |k: &str| c[k].as_u64().unwrap();
    let empty = |k: &str| c[k].as_array().unwrap().is_empty();
    assert!(n("doc_w") <= n("client_w"), "the page is wider than the window: {c}");
    assert!(
        empty("overflowing"),
        "tables that need a horizontal scroll at 1400 px: {c}"
    );
    assert!(n("images") >= min_images, "too few plots on the page: {c}");
    assert!(empty("broken"), "plots that did not load: {c}");
    assert!(
        n("links") > 0 && empty("dangling"),
        "contents links without their anchor: {c}"
    );
    assert!(n("tables") > 0, "{c}");
}

/// A report with six models side by side, long settings and long reasons:
/// the widest page the summary and the scene tables make.
fn wide_rows() -> Vec<ResultRow> {
    let models = ["chainmail", "der", "fem", "meshless", "pbd-rod", "pbd-tissue"];
    let mut rows = Vec::new();
    for (s, scenario) in ["cantilever-gravity", "block-compression"].iter().enumerate() {
        for (m, model) in models.iter().enumerate() {
            for (k, seg) in [10.0, 20.0, 40.0].iter().enumerate() {
                let mut r = ResultRow {
                    comparison: "wide".into(),
                    scenario: (*scenario).into(),
                    model: (*model).into(),
                    fidelity: format!(
                        "segments={seg};dt=0.006418358500335569;iterations=25;damping=489.46980032753584;solver=gauss-seidel;substeps=16"
                    ),
                    segments: Some(*seg),
                    primary_error: "tip_error_rel".into(),
                    run_dir: format!("runs/{scenario}/{model}/segments-{seg}"),
                    ..Default::default()
                };
                r.status = match (m + s + k) % 5 {
                    3 => Status::Unstable,
                    4 if k == 0 => Status::Unsupported,
                    _ => Status::Ok,
                };
                if r.status == Status::Ok {
                    r.metrics
                        .insert("tip_error_rel".into(), 0.3 / (seg * seg) * (1.0 + m as f64));
                    r.ms_per_step_median = Some(0.01 * seg * (1.0 + m as f64));
                    r.ms_per_step_p95 = Some(0.012 * seg * (1.0 + m as f64));
                    r.solve_wall_s = Some(0.1 * seg);
                    r.stable = Some(true);
                } else {
                    r.reason =
                        "energy grew by 8.168e-1 J beyond the hand's work (0.000e0 J) > 4.900e-1 J at t=0.0030 s"
                            .into();
                    r.watchdog = "energy grew by 8.168e-1 J beyond the hand's work (0.000e0 J) > 4.900e-1 J".into();
                    r.watchdog_t = Some(0.003);
                    r.stable = Some(false);
                }
                rows.push(r);
            }
        }
    }
    rows
}

/// The widest synthetic page fits a 1400 px window: no table scrolls, every
/// plot loads, the contents reach their sections.
#[test]
fn a_six_model_page_fits_1400_px() {
    let Some(b) = browser_or_skip() else { return };
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("report");
    std::fs::create_dir_all(&dir).unwrap();
    let rows = wide_rows();
    write_results_csv(&dir.join("results.csv"), &rows).unwrap();
    let target = |v: f64| AccuracyTarget {
        metric: "tip_error_rel".into(),
        value: v,
        why: "set by the test".into(),
    };
    let info = RunInfo {
        comparison: "wide".into(),
        targets: BTreeMap::from([
            ("cantilever-gravity".into(), target(1e-3)),
            ("block-compression".into(), target(1e-9)),
        ]),
        ..Default::default()
    };
    render(&dir, &rows, &info).unwrap();
    let c = check_page(&b, &dir);
    // Two scenarios: pareto and convergence plots of each.
    assert_page_fits(&c, 4);
    let shots = screenshots(&b, &dir, "wide", "scenario-cantilever-gravity");
    for s in shots {
        assert!(
            std::fs::metadata(&s).unwrap().len() > 10_000,
            "{} looks empty",
            s.display()
        );
    }
}

/// The quick standard report CI writes (`SURGBENCH_PAGE_REPORT`, a report
/// folder), checked the same way with its screenshots; run by `.ci/run`
/// after the quick job (`cargo test --test issue_22_page -- --ignored`).
#[test]
#[ignore = "needs a written report: SURGBENCH_PAGE_REPORT=DIR (CI sets it after the quick job)"]
fn the_quick_report_fits_1400_px() {
    let dir = PathBuf::from(std::env::var_os("SURGBENCH_PAGE_REPORT").expect("SURGBENCH_PAGE_REPORT=DIR"));
    let Some(b) = browser_or_skip() else { return };
    let c = check_page(&b, &dir);
    // Every scenario of the quick job draws at least its speed/error plot.
    assert_page_fits(&c, 17);
    screenshots(&b, &dir, "quick", "scenario-cantilever-gravity");
}
