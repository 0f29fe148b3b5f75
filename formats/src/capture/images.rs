//! Capture pixels and binary ground-truth meshes: readers that check every size, and atomic
//! writers.

use std::io::Cursor;
use std::path::Path;

use glam::Vec3;

use super::CaptureError;
use crate::camera::MAX_IMAGE_SIDE;
use crate::mesh::MAX_VERTICES;
use crate::skf::write_atomic;

/// Magic bytes of a ground-truth mesh file.
pub const GT_MESH_MAGIC: [u8; 8] = *b"SFGTMESH";
const GT_MESH_VERSION: u32 = 1;
/// Largest image file the readers accept (bytes).
const MAX_IMAGE_BYTES: u64 = 1 << 30;

/// A colour image, linear RGB in [0, 1] (PNG pixels are decoded from sRGB), row-major from the
/// top-left pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct CaptureImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width × height` linear RGB pixels.
    pub rgb: Vec<Vec3>,
}

/// A foreground mask, row-major from the top-left pixel.
///
/// A mask file may be binary (0 and 255) or carry the subject's *coverage* of each pixel (grey
/// level / 255, as an anti-aliased or supersampled render writes it). Coverage places the
/// outline to a fraction of a pixel: its 50 % level is where the subject's edge crosses the
/// pixel grid, which a binary mask can only place to within half a pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct CaptureMask {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width × height` flags, true on the subject (coverage above one half).
    pub inside: Vec<bool>,
    /// `width × height` coverage in `[0, 1]` (a binary mask gives 0 and 1).
    pub coverage: Vec<f32>,
}

/// sRGB transfer function, linear → encoded, both in [0, 1].
#[must_use]
pub fn linear_to_srgb(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// sRGB transfer function, encoded → linear, both in [0, 1].
#[must_use]
pub fn srgb_to_linear(x: f32) -> f32 {
    if x <= 0.040_45 {
        x / 12.92
    } else {
        ((x + 0.055) / 1.055).powf(2.4)
    }
}

pub(super) fn bad(path: &Path, reason: impl Into<String>) -> CaptureError {
    CaptureError::BadFile {
        file: path.to_owned(),
        reason: reason.into(),
    }
}

pub(super) fn read_capped(path: &Path) -> Result<Vec<u8>, CaptureError> {
    let io = |source| CaptureError::Io {
        file: path.to_owned(),
        source,
    };
    let len = std::fs::metadata(path).map_err(io)?.len();
    if len > MAX_IMAGE_BYTES {
        return Err(bad(
            path,
            format!("{len} bytes, more than {MAX_IMAGE_BYTES}"),
        ));
    }
    std::fs::read(path).map_err(io)
}

pub(super) fn decode_png(
    path: &Path,
    width: u32,
    height: u32,
) -> Result<image::DynamicImage, CaptureError> {
    decode_png_bytes(path, read_capped(path)?, width, height)
}

/// Decodes PNG `bytes` (read from `path`, which errors name) that must be `width × height`,
/// with the decoder's allocation capped by that size.
pub(super) fn decode_png_bytes(
    path: &Path,
    bytes: Vec<u8>,
    width: u32,
    height: u32,
) -> Result<image::DynamicImage, CaptureError> {
    let mut reader = image::ImageReader::with_format(Cursor::new(bytes), image::ImageFormat::Png);
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_IMAGE_SIDE);
    limits.max_image_height = Some(MAX_IMAGE_SIDE);
    // Twice a 16-bit RGBA frame of the expected size: enough for any honest encoding.
    limits.max_alloc = Some(u64::from(width) * u64::from(height) * 16 + (1 << 20));
    reader.limits(limits);
    let img = reader
        .decode()
        .map_err(|e| bad(path, format!("not a readable PNG: {e}")))?;
    if img.width() != width || img.height() != height {
        return Err(bad(
            path,
            format!(
                "{}×{} pixels, the camera has {width}×{height}",
                img.width(),
                img.height()
            ),
        ));
    }
    Ok(img)
}

/// Reads a colour image (PNG or, by extension, EXR) that must be `width × height`.
pub fn read_image(path: &Path, width: u32, height: u32) -> Result<CaptureImage, CaptureError> {
    if path.extension().is_some_and(|e| e == "exr") {
        return read_exr(path, width, height);
    }
    let img = decode_png(path, width, height)?.to_rgb8();
    let lut: Vec<f32> = (0..=255u8)
        .map(|v| srgb_to_linear(f32::from(v) / 255.0))
        .collect();
    let rgb = img
        .pixels()
        .map(|p| Vec3::new(lut[p[0] as usize], lut[p[1] as usize], lut[p[2] as usize]))
        .collect();
    Ok(CaptureImage { width, height, rgb })
}

fn read_exr(path: &Path, width: u32, height: u32) -> Result<CaptureImage, CaptureError> {
    use exr::prelude::*;
    let bytes = read_capped(path)?;
    let (w, h) = (width as usize, height as usize);
    // The pixel store is sized by the camera, not by the file's header: a header that claims
    // another size is rejected after reading without having allocated for it.
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .rgba_channels(
            move |size: exr::math::Vec2<usize>, _: &RgbaChannels| {
                if size.0 == w && size.1 == h {
                    vec![Vec3::ZERO; w * h]
                } else {
                    Vec::new()
                }
            },
            move |px: &mut Vec<Vec3>,
                  pos: exr::math::Vec2<usize>,
                  (r, g, b, _a): (f32, f32, f32, f32)| {
                if let Some(p) = px.get_mut(pos.1 * w + pos.0) {
                    *p = Vec3::new(r, g, b);
                }
            },
        )
        .first_valid_layer()
        .all_attributes()
        .non_parallel()
        .from_buffered(Cursor::new(bytes))
        .map_err(|e| bad(path, format!("not a readable EXR: {e}")))?;
    let size = image.layer_data.size;
    if size.0 != w || size.1 != h {
        return Err(bad(
            path,
            format!(
                "{}×{} pixels, the camera has {width}×{height}",
                size.0, size.1
            ),
        ));
    }
    let rgb = image.layer_data.channel_data.pixels;
    if rgb.iter().any(|p| !p.is_finite()) {
        return Err(bad(path, "non-finite pixel"));
    }
    Ok(CaptureImage { width, height, rgb })
}

/// Reads a mask PNG that must be `width × height`: grey level / 255 (or / 65535 for 16-bit
/// files) is the coverage, above one half is foreground.
pub fn read_mask(path: &Path, width: u32, height: u32) -> Result<CaptureMask, CaptureError> {
    mask_from_png(path, read_capped(path)?, width, height)
}

/// [`read_mask`] on PNG `bytes` already in memory; `path` only names the source in errors.
pub fn mask_from_png(
    path: &Path,
    bytes: Vec<u8>,
    width: u32,
    height: u32,
) -> Result<CaptureMask, CaptureError> {
    let img = decode_png_bytes(path, bytes, width, height)?.to_luma16();
    let coverage: Vec<f32> = img.pixels().map(|p| f32::from(p[0]) / 65535.0).collect();
    Ok(CaptureMask {
        width,
        height,
        inside: coverage.iter().map(|&c| c > 0.5).collect(),
        coverage,
    })
}

fn ensure_parent(path: &Path) -> Result<(), CaptureError> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|source| CaptureError::Io {
            file: dir.to_owned(),
            source,
        })?;
    }
    Ok(())
}

fn write_bytes(path: &Path, bytes: &[u8]) -> Result<(), CaptureError> {
    ensure_parent(path)?;
    write_atomic(path, bytes).map_err(|source| CaptureError::Io {
        file: path.to_owned(),
        source,
    })
}

fn check_len(path: &Path, width: u32, height: u32, len: usize) -> Result<(), CaptureError> {
    if len as u64 != u64::from(width) * u64::from(height) {
        return Err(bad(
            path,
            format!("{len} pixels for a {width}×{height} image"),
        ));
    }
    Ok(())
}

/// Writes linear RGB pixels as an 8-bit sRGB PNG (atomically).
pub fn write_image_png(
    path: &Path,
    width: u32,
    height: u32,
    rgb: &[Vec3],
) -> Result<(), CaptureError> {
    check_len(path, width, height, rgb.len())?;
    let bytes: Vec<u8> = rgb
        .iter()
        .flat_map(|c| {
            c.to_array()
                .map(|v| (linear_to_srgb(v) * 255.0 + 0.5) as u8)
        })
        .collect();
    write_png(path, width, height, &bytes, image::ExtendedColorType::Rgb8)
}

/// Writes linear RGB pixels as a float EXR (atomically).
pub fn write_image_exr(
    path: &Path,
    width: u32,
    height: u32,
    rgb: &[Vec3],
) -> Result<(), CaptureError> {
    use exr::prelude::*;
    check_len(path, width, height, rgb.len())?;
    let w = width as usize;
    let channels = SpecificChannels::rgb(|pos: exr::math::Vec2<usize>| {
        let p = rgb[pos.1 * w + pos.0];
        (p.x, p.y, p.z)
    });
    let mut out = Cursor::new(Vec::new());
    Image::from_channels((w, height as usize), channels)
        .write()
        .non_parallel()
        .to_buffered(&mut out)
        .map_err(|e| bad(path, format!("EXR encoding failed: {e}")))?;
    write_bytes(path, &out.into_inner())
}

/// Writes a mask as an 8-bit grey PNG of its coverage (`round(255·c)`, values clamped to
/// [0, 1]; a binary mask is 0 and 255), atomically.
pub fn write_mask_png(
    path: &Path,
    width: u32,
    height: u32,
    coverage: &[f32],
) -> Result<(), CaptureError> {
    check_len(path, width, height, coverage.len())?;
    if let Some(i) = coverage.iter().position(|c| !c.is_finite()) {
        return Err(bad(path, format!("coverage of pixel {i} is not finite")));
    }
    let bytes: Vec<u8> = coverage
        .iter()
        .map(|&c| (c.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    write_png(path, width, height, &bytes, image::ExtendedColorType::L8)
}

/// Encodes 8-bit pixels of `color` type as PNG and writes them atomically.
pub(super) fn write_png(
    path: &Path,
    width: u32,
    height: u32,
    bytes: &[u8],
    color: image::ExtendedColorType,
) -> Result<(), CaptureError> {
    let mut out = Vec::new();
    image::ImageEncoder::write_image(
        image::codecs::png::PngEncoder::new(&mut out),
        bytes,
        width,
        height,
        color,
    )
    .map_err(|e| bad(path, format!("PNG encoding failed: {e}")))?;
    write_bytes(path, &out)
}

/// Writes ground-truth posed positions (see the module docs for the byte layout), atomically.
pub fn write_gt_positions(path: &Path, positions: &[Vec3]) -> Result<(), CaptureError> {
    let n = u32::try_from(positions.len()).map_err(|_| bad(path, "too many vertices"))?;
    let mut out = Vec::with_capacity(16 + 12 * positions.len());
    out.extend_from_slice(&GT_MESH_MAGIC);
    out.extend_from_slice(&GT_MESH_VERSION.to_le_bytes());
    out.extend_from_slice(&n.to_le_bytes());
    for p in positions {
        for v in p.to_array() {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    write_bytes(path, &out)
}

/// Reads ground-truth posed positions; the file must hold exactly `expected_vertices`.
pub fn read_gt_positions(path: &Path, expected_vertices: usize) -> Result<Vec<Vec3>, CaptureError> {
    let io = |source| CaptureError::Io {
        file: path.to_owned(),
        source,
    };
    let len = std::fs::metadata(path).map_err(io)?.len();
    let want = expected_vertices
        .min(MAX_VERTICES)
        .checked_mul(12)
        .and_then(|b| b.checked_add(16))
        .unwrap_or(usize::MAX);
    if len != want as u64 {
        return Err(bad(
            path,
            format!("{len} bytes, expected {want} for {expected_vertices} vertices"),
        ));
    }
    let bytes = std::fs::read(path).map_err(io)?;
    if bytes.len() != want || bytes[..8] != GT_MESH_MAGIC {
        return Err(bad(path, "not a ground-truth mesh file (magic)"));
    }
    let word = |o: usize| u32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
    if word(8) != GT_MESH_VERSION {
        return Err(bad(
            path,
            format!("version {} is not {GT_MESH_VERSION}", word(8)),
        ));
    }
    if word(12) as usize != expected_vertices {
        return Err(bad(
            path,
            format!(
                "vertex count {} is not the template's {expected_vertices}",
                word(12)
            ),
        ));
    }
    let f = |o: usize| f32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
    let positions: Vec<Vec3> = (0..expected_vertices)
        .map(|i| Vec3::new(f(16 + 12 * i), f(20 + 12 * i), f(24 + 12 * i)))
        .collect();
    if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
        return Err(bad(path, format!("vertex {i} is not finite")));
    }
    Ok(positions)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An 8 × 6 mask with a coverage ramp, written by [`write_mask_png`], as bytes.
    fn mask_bytes(dir: &Path) -> (Vec<u8>, Vec<f32>) {
        let coverage: Vec<f32> = (0..48).map(|i| (i % 7) as f32 / 6.0).collect();
        let path = dir.join("m.png");
        write_mask_png(&path, 8, 6, &coverage).unwrap();
        (std::fs::read(&path).unwrap(), coverage)
    }

    #[test]
    fn a_mask_round_trips_to_its_8_bit_coverage() {
        let dir = tempfile::tempdir().unwrap();
        let (bytes, coverage) = mask_bytes(dir.path());
        let mask = mask_from_png(Path::new("m.png"), bytes, 8, 6).unwrap();
        for (read, written) in mask.coverage.iter().zip(&coverage) {
            assert!(
                (read - written).abs() <= 0.5 / 255.0 + 1e-6,
                "{read} {written}"
            );
        }
        // Inside is the 50 % level of the stored 8-bit coverage (an exact half is stored as 128).
        let inside: Vec<bool> = coverage
            .iter()
            .map(|&c| (c * 255.0).round() / 255.0 > 0.5)
            .collect();
        assert_eq!(mask.inside, inside);
    }

    #[test]
    fn a_mask_of_another_size_is_refused_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let (bytes, _) = mask_bytes(dir.path());
        let e = mask_from_png(Path::new("cam0/f1.png"), bytes, 6, 8).unwrap_err();
        let text = e.to_string();
        assert!(
            text.contains("cam0/f1.png") && text.contains("8×6"),
            "{text}"
        );
    }

    #[test]
    fn every_truncated_prefix_of_a_mask_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let (bytes, _) = mask_bytes(dir.path());
        let full = mask_from_png(Path::new("m.png"), bytes.clone(), 8, 6).unwrap();
        // The last 12 bytes are the empty IEND chunk: the decoder has every pixel without it.
        for n in 0..bytes.len() {
            match mask_from_png(Path::new("cut.png"), bytes[..n].to_vec(), 8, 6) {
                Err(e) => assert!(e.to_string().contains("cut.png"), "{n} bytes: {e}"),
                Ok(read) => {
                    assert!(n >= bytes.len() - 12, "{n} of {} bytes", bytes.len());
                    assert_eq!(read, full);
                }
            }
        }
    }
}
