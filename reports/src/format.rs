//! Number formatting, axis ticks and text escaping shared by plots and pages.

/// A fidelity or parameter string (`k=v;k=v`) for a page: numbers with more
/// than 4 significant digits shortened to 4 (`dt=0.006418358500335569` ->
/// `dt=0.006418`; `dt=0.0005` stays), everything else as it is;
/// `results.csv` keeps the full string.
///
/// ```
/// assert_eq!(surgbench_reports::short_settings("segments=40;dt=0.006418358500335569;solver=direct"),
///            "segments=40;dt=0.006418;solver=direct");
/// ```
pub fn short_settings(s: &str) -> String {
    s.split(';')
        .map(|kv| match kv.split_once('=') {
            Some((k, v)) => match v.trim().parse::<f64>() {
                Ok(x) if x.is_finite() && fmt_sig(x, 4).parse::<f64>() != Ok(x) => format!("{k}={}", fmt_sig(x, 4)),
                _ => kv.to_string(),
            },
            None => kv.to_string(),
        })
        .collect::<Vec<_>>()
        .join(";")
}

/// `v` with `sig` significant digits: plain decimals in `[1e-3, 1e5)`,
/// otherwise exponent form with trailing zeros trimmed (`1.2e-4`, `3e7`).
/// Tables use 3 digits; `results.csv` keeps the full value.
pub fn fmt_sig(v: f64, sig: usize) -> String {
    if v.is_nan() {
        return "NaN".into();
    }
    if v.is_infinite() {
        return if v > 0.0 { "inf".into() } else { "-inf".into() };
    }
    if v == 0.0 {
        return "0".into();
    }
    let sig = sig.max(1);
    let a = v.abs();
    if (1e-3..1e5).contains(&a) {
        let mag = a.log10().floor() as i32;
        let decimals = (sig as i32 - 1 - mag).max(0) as usize;
        let s = format!("{v:.decimals$}");
        // Rounding may carry into a new digit (9.996 -> "10.00"): still correct, just one more digit.
        trim_decimal(&s)
    } else {
        let s = format!("{:.*e}", sig - 1, v);
        trim_exp(&s)
    }
}

fn trim_decimal(s: &str) -> String {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s.to_string()
    }
}

fn trim_exp(s: &str) -> String {
    match s.split_once('e') {
        Some((m, e)) => format!("{}e{}", trim_decimal(m), e),
        None => s.to_string(),
    }
}

/// Tick label for a log axis: exponent form with at most two significant
/// digits (`1e-3`, `2e-3`, `2.5e-3`); values whose exponent is 0 print plain (`1`, `5`).
pub fn fmt_tick(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return fmt_sig(v, 2);
    }
    let s = trim_exp(&format!("{v:.1e}"));
    match s.strip_suffix("e0") {
        Some(m) => m.to_string(),
        None => s,
    }
}

/// Tick label on a linear axis whose ticks are `step` apart: as
/// [`fmt_plain`], with more significant digits where 3 would print two
/// neighbouring ticks alike (1.585 and 1.59 on an axis stepping 0.005 are
/// `1.585` and `1.59`, not `1.59` twice).
pub fn fmt_linear_tick(v: f64, step: f64) -> String {
    if !(step > 0.0 && step.is_finite()) || v == 0.0 || !v.is_finite() {
        return fmt_plain(v);
    }
    // Digits from the value's leading one down to the step's.
    let needed = (v.abs().max(step).log10().floor() - step.log10().floor()) as i64 + 1;
    if (v - v.round()).abs() <= 1e-9 * v.abs().max(1.0) && step >= 1.0 {
        return fmt_plain(v);
    }
    fmt_sig(v, needed.clamp(3, 15) as usize)
}

/// Tick label for counts and linear axes: an integer when `v` is one, else 3 significant digits.
pub fn fmt_plain(v: f64) -> String {
    if v.is_finite() && v.abs() < 1e15 && (v - v.round()).abs() <= 1e-9 * v.abs().max(1.0) {
        format!("{:.0}", v.round())
    } else {
        fmt_sig(v, 3)
    }
}

/// Bold and light tick positions for a log axis over `[lo, hi]` (`0 < lo < hi`).
///
/// Bold: decades (every k-th if there are more than 8); when fewer than three
/// decades fit, 2x and 5x multiples too; when still fewer than three ticks,
/// every integer multiple. Light: the remaining integer multiples (minor grid).
pub fn log_ticks(lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    if !(lo > 0.0 && hi > lo && hi.is_finite()) {
        return (vec![], vec![]);
    }
    let inside = |v: f64| v >= lo * (1.0 - 1e-12) && v <= hi * (1.0 + 1e-12);
    let k0 = lo.log10().floor() as i32;
    let k1 = hi.log10().ceil() as i32;
    let cand = |mults: &[f64]| -> Vec<f64> {
        let mut out = Vec::new();
        for k in k0..=k1 {
            for m in mults {
                let v = m * 10f64.powi(k);
                if inside(v) {
                    out.push(v);
                }
            }
        }
        out
    };
    let decades = cand(&[1.0]);
    let all: Vec<f64> = cand(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
    let bold = if decades.len() > 8 {
        let step = decades.len().div_ceil(8);
        decades.iter().copied().step_by(step).collect()
    } else if decades.len() >= 3 {
        decades
    } else {
        let b = cand(&[1.0, 2.0, 5.0]);
        if b.len() >= 3 { b } else { all.clone() }
    };
    let light = if k1 - k0 <= 8 {
        all.into_iter()
            .filter(|v| !bold.iter().any(|b| (b - v).abs() <= 1e-12 * v))
            .collect()
    } else {
        vec![]
    };
    (bold, light)
}

/// About six "nice" (1, 2, 5 x 10^k) tick positions covering `[lo, hi]`.
pub fn linear_ticks(lo: f64, hi: f64) -> Vec<f64> {
    if !(hi > lo && lo.is_finite() && hi.is_finite()) {
        return vec![];
    }
    let raw = (hi - lo) / 6.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let i0 = (lo / step).ceil() as i64;
    let i1 = (hi / step).floor() as i64;
    (i0..=i1).map(|i| i as f64 * step).collect()
}

/// A file-name-safe version of `s`: letters, digits, `-`, `_`, `.` kept, everything else `_`.
pub fn slug(s: &str) -> String {
    let out: String = s
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if out.is_empty() { "_".into() } else { out }
}

/// Escapes `&`, `<`, `>`, `"` for HTML text and attributes.
pub fn html_escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            _ => out.push(c),
        }
    }
    out
}

/// Makes `s` safe inside a markdown table cell: pipes escaped, newlines folded,
/// emphasis and HTML characters escaped.
pub fn md_escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '|' => out.push_str("\\|"),
            '*' | '_' | '`' | '[' | ']' | '\\' => {
                out.push('\\');
                out.push(c);
            }
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '\n' | '\r' => out.push(' '),
            _ => out.push(c),
        }
    }
    out
}

/// FNV-1a 64-bit hash (Fowler, Noll, Vo: offset basis 0xcbf29ce484222325,
/// prime 0x100000001b3) of `bytes`: a short tag that is the same on every
/// machine, build and Rust version (unlike `std`'s `DefaultHasher`), for
/// file names and the ids of a sharded run's points.
pub fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(*b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Neighbouring ticks print differently however narrow the axis; wide
    /// axes keep the plain labels.
    #[test]
    fn linear_ticks_print_apart() {
        let labels: Vec<String> = linear_ticks(1.578, 1.602)
            .iter()
            .map(|&v| fmt_linear_tick(v, 0.005))
            .collect();
        assert_eq!(labels, ["1.58", "1.585", "1.59", "1.595", "1.6"]);
        let labels: Vec<String> = linear_ticks(0.0, 8.5e-4)
            .iter()
            .map(|&v| fmt_linear_tick(v, 2e-4))
            .collect();
        assert_eq!(labels, ["0", "2e-4", "4e-4", "6e-4", "8e-4"]);
        assert_eq!(fmt_linear_tick(20.0, 5.0), "20");
        assert_eq!(fmt_linear_tick(0.0051, 5e-5), "0.0051");
        assert_eq!(fmt_linear_tick(0.00505, 5e-5), "0.00505");
    }
}
