//! The ACAP reference implementation's text layout: `LOGRNEW.txt` (logR) and `S.txt` (S), one
//! line per shape, for every vertex the full 3×3 matrix row-major, numbers separated by
//! whitespace. The reference pads with spaces and prints 6 significant digits; meshdeco writes
//! single spaces and the shortest representation that reads back to the same `f64`.

use crate::artifact::write_atomic_with;
use crate::math::mat3::Mat3;
use crate::representation::acap::AcapFrame;
use crate::{Error, Result};
use std::io::Write;
use std::path::Path;

/// File name of the logR matrices.
pub const LOGR_FILE: &str = "LOGRNEW.txt";
/// File name of the S matrices.
pub const S_FILE: &str = "S.txt";

/// Writes `dir/LOGRNEW.txt` and `dir/S.txt` for `frames` (one line per frame), each atomically
/// (temporary file, then rename). Refuses non-finite values.
pub fn write_acap_text(dir: &Path, frames: &[AcapFrame]) -> Result<()> {
    write_matrices(&dir.join(LOGR_FILE), frames.iter().map(|f| f.log_r.as_slice()))?;
    write_matrices(&dir.join(S_FILE), frames.iter().map(|f| f.s.as_slice()))
}

/// Writes one line per item of `rows`, 9 numbers per matrix, atomically.
pub fn write_matrices<'a>(path: &Path, rows: impl Iterator<Item = &'a [Mat3]>) -> Result<()> {
    let mut text = String::new();
    for (line, mats) in rows.enumerate() {
        let mut first = true;
        for (v, m) in mats.iter().enumerate() {
            for x in m.iter().flatten() {
                if !x.is_finite() {
                    return Err(Error::Invalid(format!(
                        "{}: non-finite value {x} for shape {} vertex {v}",
                        path.display(),
                        line + 1
                    )));
                }
                if !first {
                    text.push(' ');
                }
                first = false;
                text.push_str(&format!("{x}"));
            }
        }
        text.push('\n');
    }
    write_atomic_with(path, |w| w.write_all(text.as_bytes()))
}

/// Reads a file in the reference layout: one `Vec<Mat3>` per non-empty line. Every line must
/// hold a positive multiple of 9 numbers, all lines the same count.
pub fn read_matrices(path: &Path) -> Result<Vec<Vec<Mat3>>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let mut out: Vec<Vec<Mat3>> = Vec::new();
    for (ln, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let mut nums = Vec::new();
        for tok in line.split_whitespace() {
            let x: f64 = tok.parse().map_err(|_| Error::parse(path, Some(ln + 1), format!("not a number: `{tok}`")))?;
            nums.push(x);
        }
        if nums.len() % 9 != 0 {
            return Err(Error::parse(path, Some(ln + 1), format!("{} numbers, not a multiple of 9", nums.len())));
        }
        if let Some(prev) = out.first()
            && prev.len() * 9 != nums.len()
        {
            return Err(Error::parse(
                path,
                Some(ln + 1),
                format!("{} matrices where the first line has {}", nums.len() / 9, prev.len()),
            ));
        }
        out.push(nums.chunks_exact(9).map(|c| [[c[0], c[1], c[2]], [c[3], c[4], c[5]], [c[6], c[7], c[8]]]).collect());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn write_then_read_is_exact() {
        let dir = std::env::temp_dir().join(format!("meshdeco-acap-text-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let frame = AcapFrame {
            log_r: vec![[[0.0, -0.1, 0.2], [0.1, 0.0, -1.0 / 3.0], [-0.2, 1.0 / 3.0, 0.0]]; 2],
            s: vec![[[1.0, 1e-17, 0.5], [1e-17, 0.9, 0.0], [0.5, 0.0, 1.25]]; 2],
            energy_bfs: 0.0,
            energy: 0.0,
        };
        write_acap_text(&dir, &[frame.clone(), frame.clone()]).unwrap();
        let l = read_matrices(&dir.join(LOGR_FILE)).unwrap();
        let s = read_matrices(&dir.join(S_FILE)).unwrap();
        assert_eq!(l, vec![frame.log_r.clone(); 2]);
        assert_eq!(s, vec![frame.s.clone(); 2]);
        std::fs::write(dir.join("bad.txt"), "1 2 3\n").unwrap();
        assert!(read_matrices(&dir.join("bad.txt")).is_err());
        let mut bad = frame.clone();
        bad.s[1][0][0] = f64::NAN;
        assert!(write_acap_text(&dir, &[bad]).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
