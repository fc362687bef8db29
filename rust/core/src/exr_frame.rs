//! Reading one channel of an OpenEXR image (any renderer's output) as a linear f32 frame.

use std::fmt;
use std::path::Path;

use exr::prelude::{read_first_flat_layer_from_file, FlatSamples};

/// Rec. 709 / sRGB luminance of linear RGB: Y = 0.2126 R + 0.7152 G + 0.0722 B.
const LUMINANCE_RGB: [f32; 3] = [0.2126, 0.7152, 0.0722];

/// A frame read from an EXR file: row-major, `height` rows of `width` values.
#[derive(Clone, Debug, PartialEq)]
pub struct ExrFrame {
    pub width: usize,
    pub height: usize,
    pub values: Vec<f32>,
    /// The channel used, or "luminance(R,G,B)" when it was computed.
    pub channel: String,
}

#[derive(Clone, Debug, PartialEq)]
pub enum ExrError {
    Read {
        message: String,
    },
    NoSuchChannel {
        wanted: String,
        available: Vec<String>,
    },
    Ambiguous {
        available: Vec<String>,
    },
}

impl fmt::Display for ExrError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Read { message } => write!(f, "not a readable EXR image ({message})"),
            Self::NoSuchChannel { wanted, available } => {
                write!(f, "no channel {wanted:?}; it has {}", available.join(", "))
            }
            Self::Ambiguous { available } => write!(
                f,
                "no Y or R, G, B channels to choose from; name one of {}",
                available.join(", ")
            ),
        }
    }
}

impl std::error::Error for ExrError {}

/// Read `channel` of the first layer, or by default: Y if present, the luminance of R, G, B
/// (matched by the last part of the name, so "layer.R" counts), or the only channel there is.
pub fn read_exr_frame(path: &Path, channel: Option<&str>) -> Result<ExrFrame, ExrError> {
    let image = read_first_flat_layer_from_file(path).map_err(|e| ExrError::Read {
        message: e.to_string(),
    })?;
    let layer = image.layer_data;
    let (width, height) = (layer.size.x(), layer.size.y());
    let channels: Vec<(String, &FlatSamples)> = layer
        .channel_data
        .list
        .iter()
        .map(|c| (c.name.to_string(), &c.sample_data))
        .collect();
    let names: Vec<String> = channels.iter().map(|(n, _)| n.clone()).collect();
    let find = |wanted: &str| {
        channels
            .iter()
            .find(|(n, _)| short_name(n) == wanted || n == wanted)
            .map(|(_, s)| *s)
    };
    let frame = |values: Vec<f32>, channel: String| ExrFrame {
        width,
        height,
        values,
        channel,
    };

    if let Some(wanted) = channel {
        return match find(wanted) {
            Some(samples) => Ok(frame(samples.values_as_f32().collect(), wanted.to_string())),
            None => Err(ExrError::NoSuchChannel {
                wanted: wanted.to_string(),
                available: names,
            }),
        };
    }
    if let Some(y) = find("Y") {
        return Ok(frame(y.values_as_f32().collect(), "Y".to_string()));
    }
    if let (Some(r), Some(g), Some(b)) = (find("R"), find("G"), find("B")) {
        let values = r
            .values_as_f32()
            .zip(g.values_as_f32())
            .zip(b.values_as_f32())
            .map(|((r, g), b)| LUMINANCE_RGB[0] * r + LUMINANCE_RGB[1] * g + LUMINANCE_RGB[2] * b)
            .collect();
        return Ok(frame(values, "luminance(R,G,B)".to_string()));
    }
    match channels.as_slice() {
        [(name, samples)] => Ok(frame(samples.values_as_f32().collect(), name.clone())),
        _ => Err(ExrError::Ambiguous { available: names }),
    }
}

fn short_name(name: &str) -> &str {
    name.rsplit('.').next().unwrap_or(name)
}

#[cfg(test)]
mod tests {
    use super::*;
    use exr::prelude::*;

    fn write_rgb(path: &Path, w: usize, h: usize) {
        let image = Image::from_channels(
            (w, h),
            SpecificChannels::rgb(|p: Vec2<usize>| {
                (p.x() as f32, f16::from_f32(p.y() as f32), 2.0f32)
            }),
        );
        image.write().to_file(path).unwrap();
    }

    #[test]
    fn rgb_files_give_rec709_luminance_and_named_channels() {
        let dir = std::env::temp_dir().join(format!("pecs-exr-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("rgb.exr");
        write_rgb(&path, 5, 3);
        let lum = read_exr_frame(&path, None).unwrap();
        assert_eq!((lum.width, lum.height), (5, 3));
        let (x, y) = (4usize, 2usize);
        let expected = 0.2126 * x as f32 + 0.7152 * y as f32 + 0.0722 * 2.0;
        assert!((lum.values[y * 5 + x] - expected).abs() < 1e-5);
        let g = read_exr_frame(&path, Some("G")).unwrap();
        assert_eq!(g.values[y * 5 + x], 2.0); // a half channel, read as f32
        assert!(matches!(
            read_exr_frame(&path, Some("Z")),
            Err(ExrError::NoSuchChannel { .. })
        ));
        std::fs::write(dir.join("bad.exr"), b"not an exr").unwrap();
        assert!(matches!(
            read_exr_frame(&dir.join("bad.exr"), None),
            Err(ExrError::Read { .. })
        ));
        std::fs::remove_dir_all(dir).unwrap();
    }
}
