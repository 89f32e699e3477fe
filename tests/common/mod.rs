//! Helpers shared by the integration tests that run the `surgbench` binary.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// Run `cmd` with stdout and stderr captured; past `limit` it is killed
/// and the test fails naming `what`: a test of a hang never hangs itself.
#[allow(dead_code)] // not every test file that includes this module uses it
pub fn output_within(mut cmd: Command, limit: Duration, what: &str) -> Output {
    let mut child = cmd
        .env("RUST_BACKTRACE", "0")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{what} ran past {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    child.wait_with_output().unwrap()
}

/// Every file under `dir` (path relative to `dir`) with its bytes.
#[allow(dead_code)] // not every test file that includes this module uses it
pub fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                todo.push(p);
            } else {
                out.insert(p.strip_prefix(dir).unwrap().to_path_buf(), std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

/// `surgbench ARGS` to completion, output captured, backtraces off.
#[allow(dead_code)]
pub fn surgbench(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_surgbench"))
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .output()
        .expect("surgbench runs")
}

/// A command's stdout then stderr, as text (for assertion messages).
#[allow(dead_code)]
pub fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// `surgbench run CMP --quick --quiet --out OUT EXTRA...`: a comparison
/// file's quick report into `out`.
#[allow(dead_code)]
pub fn quick_run(cmp: &Path, out: &Path, extra: &[&str]) -> Output {
    let (cmp, out) = (cmp.to_str().unwrap(), out.to_str().unwrap());
    let mut args = vec!["run", cmp, "--quick", "--quiet", "--out", out];
    args.extend_from_slice(extra);
    surgbench(&args)
}
