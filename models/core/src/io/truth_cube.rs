//! The Truth Cube phantom (Kerdok et al. 2003, Medical Image Analysis
//! 7(3):283-291): bead positions of a silicone cube under uniaxial
//! compression, as redistributed with OpenSurgSim (Apache-2.0).

use super::table;
use crate::Vec3;
use std::path::Path;

/// Nominal compressive strains of the four states in the file.
pub const NOMINAL_STRAINS: [f64; 4] = [0.0, 0.05, 0.125, 0.1825];

/// One bead: grid indices (1..=7) and its position in each state (m).
#[derive(Debug, Clone, PartialEq)]
pub struct Bead {
    /// Grid indices `(i, j, k)`, 1-based as in the file.
    pub index: [u8; 3],
    /// Position at nominal strain 0, 5, 12.5 and 18.25 % (m).
    pub positions: [Vec3; 4],
}

/// All beads of the uniaxial test.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthCube {
    /// Beads in file order.
    pub beads: Vec<Bead>,
}

const COLUMNS: [&str; 15] = [
    "i", "j", "k", "x0", "y0", "z0", "x1", "y1", "z1", "x2", "y2", "z2", "x3", "y3", "z3",
];

/// Load the CSV (`truth-cube-uniaxial.csv`): free-text lines, then a
/// header row naming `i,j,k,x0,y0,z0,...,x3,y3,z3`, then one row per bead
/// in millimetres. Positions are converted to metres. Errors name the
/// file, the line and the missing column or bad value.
pub fn load(path: impl AsRef<Path>) -> Result<TruthCube, String> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
    parse(&path.display().to_string(), &text)
}

/// Parse the CSV text; `file` labels errors. See [`load`].
pub fn parse(file: &str, text: &str) -> Result<TruthCube, String> {
    let rows = table::rows(text, false).map_err(|(line, e)| format!("{file}:{line}: {e}"))?;
    let header_at = rows
        .iter()
        .position(|r| r.cells.get(0) == Some("i"))
        .ok_or_else(|| format!("{file}: no header row starting with column `i`"))?;
    let header = &rows[header_at];
    let mut col = [0usize; 15];
    for (c, name) in COLUMNS.iter().enumerate() {
        col[c] = table::column(&header.cells, name)
            .ok_or_else(|| format!("{file}:{}: missing column `{name}`", header.line))?;
    }
    let mut beads = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for row in &rows[header_at + 1..] {
        let bead = bead(file, row, &col)?;
        // The redistributed file repeats a few trailing rows; keep the
        // first occurrence of each bead.
        if seen.insert(bead.index) {
            beads.push(bead);
        }
    }
    if beads.is_empty() {
        return Err(format!("{file}: no bead rows after the header"));
    }
    Ok(TruthCube { beads })
}

/// One bead from a data row; `col` gives the cell of each of [`COLUMNS`].
fn bead(file: &str, row: &table::Row, col: &[usize; 15]) -> Result<Bead, String> {
    let ln = row.line;
    let get = |c: usize| -> Result<f64, String> {
        let s = row
            .cells
            .get(col[c])
            .ok_or_else(|| format!("{file}:{ln}: row has no column `{}`", COLUMNS[c]))?;
        s.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("{file}:{ln}: column `{}` is not a number: `{s}`", COLUMNS[c]))
    };
    let mut index = [0u8; 3];
    for a in 0..3 {
        let v = get(a)?;
        if !(1.0..=7.0).contains(&v) || v.fract() != 0.0 {
            return Err(format!(
                "{file}:{ln}: bead index `{}` = {v} is not in 1..=7",
                COLUMNS[a]
            ));
        }
        index[a] = v as u8;
    }
    let mut positions = [Vec3::zeros(); 4];
    for (s, p) in positions.iter_mut().enumerate() {
        *p = Vec3::new(get(3 + 3 * s)?, get(4 + 3 * s)?, get(5 + 3 * s)?) * 1e-3;
    }
    Ok(Bead { index, positions })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn truth_cube_loads_in_metres_and_names_missing_columns() {
        let text = "Truth Cube,,\nAll positions in mm,,\ni,j,k,x0,y0,z0,x1,y1,z1,x2,y2,z2,x3,y3,z3\n\
1,1,1,-29.69,-28.86,12.62,-30.33,-29.38,12.96,-31.04,-30.09,13.65,-31.85,-31.08,14.38\n";
        let c = parse("c.csv", text).unwrap();
        assert_eq!(c.beads.len(), 1);
        assert_eq!(c.beads[0].index, [1, 1, 1]);
        assert!((c.beads[0].positions[3].z - 0.01438).abs() < 1e-15);
        let e = parse("c.csv", &text.replace(",y2,", ",yy,")).unwrap_err();
        assert!(e.contains("c.csv:3") && e.contains("`y2`"), "{e}");
        let e = parse("c.csv", &text.replace("-31.04", "abc")).unwrap_err();
        assert!(e.contains("c.csv:4") && e.contains("`x2`"), "{e}");
    }

    #[test]
    fn truth_cube_dataset_has_343_beads_compressed_along_z() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../datasets/phantom/truth-cube/truth-cube-uniaxial.csv"
        );
        let c = load(path).unwrap();
        assert_eq!(c.beads.len(), 343);
        // Bead z extent shrinks with each compression level (uniaxial along z).
        let extent = |s: usize| {
            let z = c.beads.iter().map(|b| b.positions[s].z);
            z.clone().fold(f64::NEG_INFINITY, f64::max) - z.fold(f64::INFINITY, f64::min)
        };
        let e: Vec<f64> = (0..4).map(extent).collect();
        assert!(
            e.windows(2).all(|w| w[1] < w[0]) && e[0] > 0.055 && e[0] < 0.065,
            "z extents (m) {e:?}"
        );
    }
}
