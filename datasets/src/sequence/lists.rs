//! Text lists of a sequence: `rgb.txt` / `depth.txt` and `boxes.txt`.

use std::collections::BTreeMap;
use std::path::Path;

use scarp_slam::image::MaskImage;

use crate::DatasetError;
use crate::world::RockRole;

/// Parses a TUM image list (`timestamp path` lines, `#` comments). Timestamps must strictly
/// increase.
///
/// # Errors
/// [`DatasetError::Parse`] naming the file and line.
pub fn parse_image_list(text: &str, path: &Path) -> Result<Vec<(f64, String)>, DatasetError> {
    let mut entries: Vec<(f64, String)> = Vec::new();
    for (number, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut words = line.split_whitespace();
        let (Some(t), Some(file), None) = (words.next(), words.next(), words.next()) else {
            return Err(DatasetError::parse(
                path,
                number + 1,
                "expected `timestamp path`",
            ));
        };
        let t: f64 = t
            .parse()
            .ok()
            .filter(|t: &f64| t.is_finite())
            .ok_or_else(|| {
                DatasetError::parse(path, number + 1, format!("`{t}` is not a timestamp"))
            })?;
        if let Some((previous, _)) = entries.last()
            && t <= *previous
        {
            return Err(DatasetError::parse(
                path,
                number + 1,
                format!("timestamp {t} is not after the previous one ({previous})"),
            ));
        }
        entries.push((t, file.to_string()));
    }
    Ok(entries)
}

/// One line of `boxes.txt`: the box of one rock in one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxRecord {
    /// Frame timestamp, seconds.
    pub timestamp_s: f64,
    /// Rock id.
    pub id: u32,
    /// Target or distractor.
    pub role: RockRole,
    /// Inclusive pixel bounds `[x_min, y_min, x_max, y_max]` (column, row).
    pub bbox_px: [u32; 4],
}

/// The boxes of every rock visible in an instance mask: ids 1–999 are rocks (see
/// [`crate::world::PEDESTAL_INSTANCE_OFFSET`]); `role_of` gives each id's role and drops ids it
/// does not know.
pub fn boxes_from_mask(
    mask: &MaskImage,
    timestamp_s: f64,
    role_of: impl Fn(u32) -> Option<RockRole>,
) -> Vec<BoxRecord> {
    let mut bounds: BTreeMap<u32, [u32; 4]> = BTreeMap::new();
    for v in 0..mask.height() {
        for (u, &id) in mask.row(v).iter().enumerate() {
            if (1..1000).contains(&id) {
                let u = u as u32;
                let b = bounds.entry(u32::from(id)).or_insert([u, v, u, v]);
                *b = [b[0].min(u), b[1].min(v), b[2].max(u), b[3].max(v)];
            }
        }
    }
    bounds
        .into_iter()
        .filter_map(|(id, bbox_px)| {
            role_of(id).map(|role| BoxRecord {
                timestamp_s,
                id,
                role,
                bbox_px,
            })
        })
        .collect()
}

/// Formats `boxes.txt`.
pub fn format_boxes(records: &[BoxRecord]) -> String {
    let mut text = String::from("# t id role x_min y_min x_max y_max (inclusive pixel bounds)\n");
    for r in records {
        let [x0, y0, x1, y1] = r.bbox_px;
        text.push_str(&format!(
            "{:.6} {} {} {x0} {y0} {x1} {y1}\n",
            r.timestamp_s,
            r.id,
            r.role.as_str()
        ));
    }
    text
}

/// Parses `boxes.txt`.
///
/// # Errors
/// [`DatasetError::Parse`] naming the file and line for a wrong field count, a bad number (a
/// timestamp must be finite), an unknown role or inverted bounds.
pub fn parse_boxes(text: &str, path: &Path) -> Result<Vec<BoxRecord>, DatasetError> {
    let mut records = Vec::new();
    for (number, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let bad = |message: String| DatasetError::parse(path, number + 1, message);
        let words: Vec<&str> = line.split_whitespace().collect();
        if words.len() != 7 {
            return Err(bad(format!(
                "expected 7 fields (t id role x_min y_min x_max y_max), found {}",
                words.len()
            )));
        }
        let timestamp_s: f64 = words[0]
            .parse()
            .ok()
            .filter(|t: &f64| t.is_finite())
            .ok_or_else(|| bad(format!("`{}` is not a timestamp", words[0])))?;
        let id: u32 = words[1]
            .parse()
            .map_err(|_| bad(format!("`{}` is not an id", words[1])))?;
        let role = match words[2] {
            "target" => RockRole::Target,
            "distractor" => RockRole::Distractor,
            other => return Err(bad(format!("unknown role `{other}`"))),
        };
        let mut bbox_px = [0u32; 4];
        for (k, word) in words[3..].iter().enumerate() {
            bbox_px[k] = word
                .parse()
                .map_err(|_| bad(format!("`{word}` is not a pixel coordinate")))?;
        }
        if bbox_px[0] > bbox_px[2] || bbox_px[1] > bbox_px[3] {
            return Err(bad("x_min/y_min exceed x_max/y_max".into()));
        }
        records.push(BoxRecord {
            timestamp_s,
            id,
            role,
            bbox_px,
        });
    }
    Ok(records)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boxes_round_trip_and_come_from_masks() {
        let mut mask = MaskImage::filled(10, 8, 0);
        for (u, v, id) in [
            (2, 3, 5u16),
            (4, 6, 5),
            (7, 1, 12),
            (9, 7, 1005),
            (0, 0, 2000),
        ] {
            *mask.get_mut(u, v).unwrap() = id;
        }
        let boxes = boxes_from_mask(&mask, 0.25, |id| {
            (id == 5)
                .then_some(RockRole::Target)
                .or((id == 12).then_some(RockRole::Distractor))
        });
        assert_eq!(boxes.len(), 2);
        assert_eq!(boxes[0].bbox_px, [2, 3, 4, 6]);
        let path = Path::new("boxes.txt");
        assert_eq!(parse_boxes(&format_boxes(&boxes), path).unwrap(), boxes);
        let err = parse_boxes("0.1 5 rock 1 2 3 4\n", path)
            .unwrap_err()
            .to_string();
        assert!(err.contains("boxes.txt:1") && err.contains("rock"), "{err}");
    }

    #[test]
    fn image_list_rejects_out_of_order_timestamps() {
        let path = Path::new("rgb.txt");
        let err = parse_image_list("# c\n1.0 rgb/1.png\n0.9 rgb/0.png\n", path)
            .unwrap_err()
            .to_string();
        assert!(err.contains("rgb.txt:3"), "{err}");
        assert_eq!(
            parse_image_list("1.0 a.png\n2.0 b.png\n", path)
                .unwrap()
                .len(),
            2
        );
    }
}
