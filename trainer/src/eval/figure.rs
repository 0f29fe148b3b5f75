//! Figures for people: per-method error pictures side by side under one title, each captioned,
//! with a colour bar in centimetres, as one SVG that embeds the PNGs (`trainer render --kind
//! error` pictures, which have no room for text of their own).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use skinfield_formats::capture::linear_to_srgb;

use super::render::error_color;

/// Stops of the colour bar's gradient (the map is piecewise linear in *linear* RGB, so the
/// sRGB gradient needs more stops than the map has).
const BAR_STOPS: usize = 33;

/// A figure could not be assembled.
#[derive(Debug, thiserror::Error)]
pub enum FigureError {
    /// A panel's picture could not be read or decoded.
    #[error("{path}: {message}")]
    Panel {
        /// The picture.
        path: PathBuf,
        /// What failed.
        message: String,
    },
}

/// One picture of the figure and its caption.
#[derive(Clone, Debug)]
pub struct Panel {
    /// Caption above the picture.
    pub caption: String,
    /// A PNG file.
    pub png: PathBuf,
}

/// The SVG text of `panels` side by side under `title`, with a colour bar from 0 to
/// `max_error_cm` labelled in centimetres (the scale of [`error_color`]).
pub fn error_figure(
    panels: &[Panel],
    title: &str,
    max_error_cm: f32,
) -> Result<String, FigureError> {
    let mut images = Vec::with_capacity(panels.len());
    for p in panels {
        let bad = |message: String| FigureError::Panel {
            path: p.png.clone(),
            message,
        };
        let bytes = std::fs::read(&p.png).map_err(|e| bad(e.to_string()))?;
        let (w, h) = image::load_from_memory_with_format(&bytes, image::ImageFormat::Png)
            .map(|i| (i.width(), i.height()))
            .map_err(|e| bad(e.to_string()))?;
        images.push((w, h, base64(&bytes)));
    }
    let gap = 12;
    let (top, caption_h, bar_h) = (44, 22, 70);
    let width: u32 = images.iter().map(|i| i.0 + gap).sum::<u32>() + gap;
    let tallest = images.iter().map(|i| i.1).max().unwrap_or(0);
    let height = top + caption_h + tallest + bar_h;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" font-family="sans-serif">"#
    );
    let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<text x="{}" y="28" font-size="20" text-anchor="middle">{}</text>"#,
        width / 2,
        escape(title)
    );
    let mut x = gap;
    for (p, (w, h, data)) in panels.iter().zip(&images) {
        let _ = writeln!(
            s,
            r#"<text x="{}" y="{}" font-size="15" text-anchor="middle">{}</text>"#,
            x + w / 2,
            top + 14,
            escape(&p.caption)
        );
        let _ = writeln!(
            s,
            r#"<image x="{x}" y="{}" width="{w}" height="{h}" href="data:image/png;base64,{data}"/>"#,
            top + caption_h
        );
        x += w + gap;
    }
    // The colour bar, centred under the pictures.
    let (bar_w, bar_y) = (
        width.min(480).saturating_sub(2 * gap),
        top + caption_h + tallest + 14,
    );
    let bar_x = (width - bar_w) / 2;
    let _ = writeln!(s, r#"<defs><linearGradient id="errorbar">"#);
    for i in 0..BAR_STOPS {
        let t = i as f32 / (BAR_STOPS - 1) as f32;
        let c = error_color(t)
            .to_array()
            .map(|v| (linear_to_srgb(v) * 255.0 + 0.5) as u8);
        let _ = writeln!(
            s,
            r#"<stop offset="{:.4}" stop-color="rgb({},{},{})"/>"#,
            t, c[0], c[1], c[2]
        );
    }
    let _ = writeln!(s, "</linearGradient></defs>");
    let _ = writeln!(
        s,
        r#"<rect x="{bar_x}" y="{bar_y}" width="{bar_w}" height="14" fill="url(#errorbar)" stroke="black" stroke-width="0.5"/>"#
    );
    let ticks = 4;
    for i in 0..=ticks {
        let t = i as f32 / ticks as f32;
        let tx = bar_x as f32 + t * bar_w as f32;
        let label = if i == ticks {
            format!("≥ {:.2}", max_error_cm)
        } else {
            format!("{:.2}", t * max_error_cm)
        };
        let _ = writeln!(
            s,
            r#"<line x1="{tx:.1}" y1="{}" x2="{tx:.1}" y2="{}" stroke="black"/><text x="{tx:.1}" y="{}" font-size="12" text-anchor="middle">{label}</text>"#,
            bar_y + 14,
            bar_y + 18,
            bar_y + 31
        );
    }
    let _ = writeln!(
        s,
        r#"<text x="{}" y="{}" font-size="13" text-anchor="middle">distance of each vertex to the ground-truth surface (cm)</text>"#,
        width / 2,
        bar_y + 50
    );
    let _ = writeln!(s, "</svg>");
    Ok(s)
}

/// Writes [`error_figure`] to `path` atomically.
pub fn write_error_figure(
    path: &Path,
    panels: &[Panel],
    title: &str,
    max_error_cm: f32,
) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    let svg = error_figure(panels, title, max_error_cm)?;
    skinfield_formats::skf::write_atomic(path, svg.as_bytes())
        .map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(())
}

/// XML text escaping.
fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Standard base64 (RFC 4648, padded).
fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc_4648_vectors() {
        for (plain, encoded) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(plain.as_bytes()), encoded);
        }
    }

    #[test]
    fn figure_has_captions_pictures_and_a_labelled_colour_bar() {
        let dir = tempfile::tempdir().unwrap();
        let png = dir.path().join("a.png");
        skinfield_formats::capture::write_image_png(&png, 3, 2, &[glam::Vec3::ONE; 6]).unwrap();
        let panels = [
            Panel {
                caption: "initial <bone heat>".into(),
                png: png.clone(),
            },
            Panel {
                caption: "ours".into(),
                png: png.clone(),
            },
        ];
        let svg = error_figure(&panels, "Frame 7", 2.0).unwrap();
        assert_eq!(svg.matches("<image ").count(), 2);
        assert!(svg.contains("initial &lt;bone heat&gt;"));
        assert!(svg.contains(r#"width="3" height="2""#));
        for label in ["0.00", "1.00", "≥ 2.00", "(cm)", "Frame 7"] {
            assert!(svg.contains(label), "missing {label}");
        }
        // The bar's ends are the map's ends.
        let c = error_color(1.0)
            .to_array()
            .map(|v| (linear_to_srgb(v) * 255.0 + 0.5) as u8);
        assert!(svg.contains(&format!("rgb({},{},{})", c[0], c[1], c[2])));
        let missing = Panel {
            caption: "x".into(),
            png: dir.path().join("missing.png"),
        };
        assert!(matches!(
            error_figure(&[missing], "t", 1.0),
            Err(FigureError::Panel { .. })
        ));
    }
}
