//! Wavefront OBJ mesh reading (positions, optional per-vertex colours, polygon faces).

use std::path::{Path, PathBuf};

use nalgebra::Point3;
use scarp_slam::TriangleMesh;
use thiserror::Error;

/// An OBJ file that cannot be read; names the file and, for content errors, the line.
#[derive(Debug, Error)]
pub enum ObjError {
    /// The file could not be read.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating-system error.
        #[source]
        source: std::io::Error,
    },
    /// A line that is not valid OBJ.
    #[error("{}:{line}: {message}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
}

/// Reads an OBJ file: `v x y z [r g b]` vertices (colours in [0, 1]) and `f` faces with
/// `i`, `i/t`, `i//n` or `i/t/n` corners (1-based, negative = relative). Polygons are split into
/// triangle fans. Texture coordinates, normals, groups and materials are ignored.
///
/// # Errors
/// [`ObjError::Io`] for an unreadable file; [`ObjError::Parse`] naming the line for a bad
/// number (or a coordinate beyond f32's range), an index out of range, a face with fewer than
/// three corners, or a file without faces.
pub fn read_obj(path: &Path) -> Result<TriangleMesh, ObjError> {
    let text = std::fs::read_to_string(path).map_err(|source| ObjError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_obj(&text).map_err(|(line, message)| ObjError::Parse {
        path: path.to_path_buf(),
        line,
        message,
    })
}

/// Parses OBJ text; see [`read_obj`]. Errors carry the 1-based line and a message.
pub fn parse_obj(text: &str) -> Result<TriangleMesh, (usize, String)> {
    let mut mesh = TriangleMesh::default();
    let mut colors: Vec<[u8; 3]> = Vec::new();
    let mut any_color = false;
    let mut last_line = 0;
    for (number, line) in text.lines().enumerate() {
        let line_no = number + 1;
        last_line = line_no;
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let values: Vec<f64> = words
                    .map(|w| {
                        w.parse::<f64>()
                            .map_err(|_| (line_no, format!("`{w}` is not a number")))
                    })
                    .collect::<Result<_, _>>()?;
                if values.len() < 3 || !values.iter().all(|v| v.is_finite()) {
                    return Err((line_no, "a vertex needs three finite coordinates".into()));
                }
                // Positions are stored as f32: a coordinate beyond its range would become
                // infinite.
                if values[..3].iter().any(|v| v.abs() > f64::from(f32::MAX)) {
                    return Err((
                        line_no,
                        "a vertex coordinate is beyond the range of a 32-bit float".into(),
                    ));
                }
                mesh.positions.push(Point3::new(
                    values[0] as f32,
                    values[1] as f32,
                    values[2] as f32,
                ));
                if values.len() >= 6 {
                    any_color = true;
                    colors
                        .push([3, 4, 5].map(|i| (values[i].clamp(0.0, 1.0) * 255.0).round() as u8));
                } else {
                    colors.push([255, 255, 255]);
                }
            }
            Some("f") => {
                let n = mesh.positions.len() as i64;
                let corners: Vec<u32> = words
                    .map(|w| {
                        let first = w.split('/').next().unwrap_or_default();
                        let i: i64 = first
                            .parse()
                            .map_err(|_| (line_no, format!("`{w}` is not a vertex index")))?;
                        let resolved = if i < 0 { n + i } else { i - 1 };
                        if i == 0 || resolved < 0 || resolved >= n {
                            return Err((
                                line_no,
                                format!("vertex index {i} is out of range (1..={n})"),
                            ));
                        }
                        Ok(resolved as u32)
                    })
                    .collect::<Result<_, _>>()?;
                if corners.len() < 3 {
                    return Err((line_no, "a face needs at least three vertices".into()));
                }
                for k in 1..corners.len() - 1 {
                    mesh.faces.push([corners[0], corners[k], corners[k + 1]]);
                }
            }
            _ => {}
        }
    }
    if mesh.faces.is_empty() {
        return Err((last_line.max(1), "the file has no faces".into()));
    }
    if any_color {
        mesh.colors = colors;
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_polygons_and_relative_indices() {
        let m = parse_obj("# quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1 4//1\nf -4 -3 -2\n").unwrap();
        assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3], [0, 1, 2]]);
        assert!(m.colors.is_empty());
    }

    #[test]
    fn errors_name_the_line() {
        assert_eq!(parse_obj("v 0 0 0\nv 1 0 0\nf 1 2 3\n").unwrap_err().0, 3);
        assert_eq!(parse_obj("v 0 0 x\n").unwrap_err().0, 1);
        assert!(parse_obj("v 0 0 0\n").unwrap_err().1.contains("no faces"));
        let err = read_obj(Path::new("/nonexistent/rock.obj")).unwrap_err();
        assert!(err.to_string().contains("/nonexistent/rock.obj"));
    }
}
