//! Per-view part-label images: an 8-bit RGB PNG per camera and frame, one palette colour per
//! part, decoded to one label per pixel.
//!
//! A human-parsing network (or the synthetic ground truth) paints every pixel of the subject
//! with the colour of its part; `trainer template` max-votes those labels onto the vertices of a
//! reconstructed mesh. Colours outside the palette (the background, anti-aliased or
//! JPEG-damaged edges) carry no label rather than the nearest part: a wrong vote is worse than
//! none.

use std::path::Path;

use super::images::{bad, decode_png_bytes, read_capped, write_png};
use super::{CaptureError, LabelsEntry};

/// Label of a pixel whose colour is not in the palette (background).
pub const NO_LABEL: u8 = u8::MAX;
/// Most parts a palette may list (one value, [`NO_LABEL`], is reserved).
pub const MAX_PARTS: usize = 254;

/// One view's labels, row-major from the top-left pixel.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LabelImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width × height` part labels (indices into the palette), [`NO_LABEL`] where none.
    pub labels: Vec<u8>,
}

/// Checks a palette: 1 to [`MAX_PARTS`] colours, all distinct. `field` names it in errors.
pub fn validate_palette(file: &Path, field: &str, palette: &[[u8; 3]]) -> Result<(), CaptureError> {
    if palette.is_empty() || palette.len() > MAX_PARTS {
        return Err(CaptureError::invalid(
            file,
            field,
            format!("{} colours (1 to {MAX_PARTS} allowed)", palette.len()),
        ));
    }
    for (i, c) in palette.iter().enumerate() {
        if palette[..i].contains(c) {
            return Err(CaptureError::invalid(
                file,
                format!("{field}[{i}]"),
                format!("colour {c:?} listed twice"),
            ));
        }
    }
    Ok(())
}

/// Reads a label image that must be `width × height`, mapping palette colours to their index.
pub fn read_labels(
    path: &Path,
    width: u32,
    height: u32,
    entry: &LabelsEntry,
) -> Result<LabelImage, CaptureError> {
    labels_from_png(path, read_capped(path)?, width, height, entry)
}

/// [`read_labels`] on PNG `bytes` already in memory; `path` only names the source in errors.
pub fn labels_from_png(
    path: &Path,
    bytes: Vec<u8>,
    width: u32,
    height: u32,
    entry: &LabelsEntry,
) -> Result<LabelImage, CaptureError> {
    validate_palette(path, "palette", &entry.palette)?;
    let img = decode_png_bytes(path, bytes, width, height)?.to_rgb8();
    let labels = img
        .pixels()
        .map(|p| {
            entry
                .palette
                .iter()
                .position(|c| *c == p.0)
                .map_or(NO_LABEL, |i| i as u8)
        })
        .collect();
    Ok(LabelImage {
        width,
        height,
        labels,
    })
}

/// Writes labels (indices into `palette`, [`NO_LABEL`] for the background, painted black unless
/// black is a part's colour, then white) as an 8-bit RGB PNG, atomically.
pub fn write_labels_png(
    path: &Path,
    width: u32,
    height: u32,
    labels: &[u8],
    palette: &[[u8; 3]],
) -> Result<(), CaptureError> {
    validate_palette(path, "palette", palette)?;
    if labels.len() as u64 != u64::from(width) * u64::from(height) {
        return Err(bad(
            path,
            format!("{} labels for a {width}×{height} image", labels.len()),
        ));
    }
    let background = [[0u8; 3], [255; 3], [0, 255, 0]]
        .into_iter()
        .find(|c| !palette.contains(c))
        .unwrap_or([1, 2, 3]);
    let mut rgb = Vec::with_capacity(labels.len() * 3);
    for (i, &l) in labels.iter().enumerate() {
        let c = match l {
            NO_LABEL => background,
            l => *palette.get(usize::from(l)).ok_or_else(|| {
                bad(
                    path,
                    format!("pixel {i}: label {l} has no colour in the palette"),
                )
            })?,
        };
        rgb.extend_from_slice(&c);
    }
    write_png(path, width, height, &rgb, image::ExtendedColorType::Rgb8)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry() -> LabelsEntry {
        LabelsEntry {
            folder: "labels".into(),
            palette: vec![[255, 160, 120], [40, 90, 220]],
            frames: vec![0],
        }
    }

    #[test]
    fn labels_round_trip_and_unknown_colours_have_no_label() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("l.png");
        let labels = [0, 1, NO_LABEL, 1, 0, NO_LABEL];
        write_labels_png(&path, 3, 2, &labels, &entry().palette).unwrap();
        let read = read_labels(&path, 3, 2, &entry()).unwrap();
        assert_eq!(read.labels, labels);
        // An image painted with a colour that is no part's reads as unlabelled.
        let other = LabelsEntry {
            palette: vec![[1, 1, 1]],
            ..entry()
        };
        let read = read_labels(&path, 3, 2, &other).unwrap();
        assert!(read.labels.iter().all(|&l| l == NO_LABEL));
    }

    #[test]
    fn every_truncated_prefix_of_a_label_image_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("l.png");
        let labels: Vec<u8> = (0..48).map(|i| [0, 1, NO_LABEL][i % 3]).collect();
        write_labels_png(&path, 8, 6, &labels, &entry().palette).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let cut = dir.path().join("cut.png");
        // The last 12 bytes are the empty IEND chunk: the decoder has every pixel without it.
        for n in 0..bytes.len() {
            std::fs::write(&cut, &bytes[..n]).unwrap();
            match read_labels(&cut, 8, 6, &entry()) {
                Err(e) => assert!(e.to_string().contains("cut.png"), "{n} bytes: {e}"),
                Ok(read) => {
                    assert!(
                        n >= bytes.len() - 12,
                        "{n} of {} bytes decoded",
                        bytes.len()
                    );
                    assert_eq!(read.labels, labels);
                }
            }
        }
    }

    #[test]
    fn bad_palettes_sizes_and_labels_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("l.png");
        let p = &entry().palette;
        assert!(write_labels_png(&path, 3, 2, &[0; 5], p).is_err());
        assert!(write_labels_png(&path, 3, 2, &[2; 6], p).is_err());
        assert!(write_labels_png(&path, 3, 2, &[0; 6], &[]).is_err());
        let twice = [[1, 2, 3], [1, 2, 3]];
        let e = write_labels_png(&path, 3, 2, &[0; 6], &twice).unwrap_err();
        assert!(e.to_string().contains("palette[1]"), "{e}");
        assert!(!path.exists(), "nothing written on error");
        write_labels_png(&path, 3, 2, &[0; 6], p).unwrap();
        let e = read_labels(&path, 4, 2, &entry()).unwrap_err();
        assert!(e.to_string().contains("3×2"), "{e}");
        std::fs::write(&path, b"\x89PNG\r\n\x1a\n trunc").unwrap();
        assert!(read_labels(&path, 3, 2, &entry()).is_err());
    }
}
