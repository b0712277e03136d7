//! Grey-level images: single-channel EXR and digit CSV (rows of
//! comma-separated values, no header), with the pixel-centre convention
//! used to place them on the square [-1, 1]².

use std::io::Cursor as IoCursor;
use std::path::Path;

use super::cursor::{Cursor, lossy, parse_f64};
use super::{ParseError, ParseErrorKind, ReadError, WriteError, read_bytes, write_atomic};

/// A grey-level image, row-major, top row first.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Number of columns.
    pub width: usize,
    /// Number of rows.
    pub height: usize,
    /// `width * height` values; row r, column c is `values[r * width + c]`.
    pub values: Vec<f64>,
}

impl Image {
    /// The value at column `c`, row `r`.
    ///
    /// # Panics
    /// If `c >= width` or `r >= height`.
    #[track_caller]
    pub fn at(&self, c: usize, r: usize) -> f64 {
        assert!(c < self.width && r < self.height, "pixel ({c}, {r}) outside a {}×{} image", self.width, self.height);
        self.values[r * self.width + c]
    }

    /// The position of pixel centre (c, r) on [-1, 1]²:
    /// (x, y) = (−1 + (2c+1)/w, 1 − (2r+1)/h) (../shared/data/README.md).
    ///
    /// ```
    /// use fshape_mesh::io::image::Image;
    /// let im = Image { width: 2, height: 2, values: vec![0.0; 4] };
    /// assert_eq!(im.pixel_centre(0, 0), (-0.5, 0.5));
    /// ```
    pub fn pixel_centre(&self, c: usize, r: usize) -> (f64, f64) {
        (-1.0 + (2 * c + 1) as f64 / self.width as f64, 1.0 - (2 * r + 1) as f64 / self.height as f64)
    }

    /// Bilinear interpolation of the pixel values at (x, y) ∈ [-1, 1]², with
    /// pixel values located at pixel centres. Outside the square of pixel
    /// centres the nearest edge value is continued (clamping), so every
    /// point of [-1, 1]² gets a value. An empty image gives 0.
    ///
    /// ```
    /// use fshape_mesh::io::image::Image;
    /// let im = Image { width: 2, height: 1, values: vec![0.0, 1.0] };
    /// assert_eq!(im.sample(0.0, 0.0), 0.5); // halfway between the centres
    /// ```
    pub fn sample(&self, x: f64, y: f64) -> f64 {
        if self.values.is_empty() {
            return 0.0;
        }
        // Inverse of pixel_centre, in continuous pixel coordinates.
        let fc = (((x + 1.0) * self.width as f64 - 1.0) / 2.0).clamp(0.0, (self.width - 1) as f64);
        let fr = (((1.0 - y) * self.height as f64 - 1.0) / 2.0).clamp(0.0, (self.height - 1) as f64);
        let (c0, r0) = (fc.floor() as usize, fr.floor() as usize);
        let (c1, r1) = ((c0 + 1).min(self.width - 1), (r0 + 1).min(self.height - 1));
        let (tc, tr) = (fc - c0 as f64, fr - r0 as f64);
        let top = (1.0 - tc) * self.at(c0, r0) + tc * self.at(c1, r0);
        let bottom = (1.0 - tc) * self.at(c0, r1) + tc * self.at(c1, r1);
        (1.0 - tr) * top + tr * bottom
    }
}

/// Parses a digit CSV: `height` lines of `width` comma-separated numbers.
pub fn parse_image_csv(data: &[u8]) -> Result<Image, ParseError> {
    let mut cur = Cursor::new(data);
    let mut image = Image { width: 0, height: 0, values: Vec::new() };
    loop {
        let at = cur.at();
        let Some(line) = cur.text_line("a row of numbers")? else {
            break;
        };
        if line.trim().is_empty() {
            continue;
        }
        let mut n = 0;
        for t in line.split(',') {
            let v = parse_f64(t.trim().as_bytes()).filter(|v| v.is_finite());
            let found = lossy(t.trim().as_bytes());
            image.values.push(v.ok_or(ParseError {
                at,
                kind: ParseErrorKind::BadToken { expected: "a finite pixel value", found },
            })?);
            n += 1;
        }
        if image.height > 0 && n != image.width {
            return Err(ParseError {
                at,
                kind: ParseErrorKind::CountMismatch {
                    what: "values in this row (rows must have equal length)",
                    expected: image.width as u64,
                    found: n as u64,
                },
            });
        }
        image.width = n;
        image.height += 1;
    }
    Ok(image)
}

/// Reads an image: `.exr` (single channel, or the channel named) or `.csv`
/// (digit CSV), optionally gzipped.
pub fn read_image(path: &Path, channel: Option<&str>) -> Result<Image, ReadError> {
    let data = read_bytes(path)?;
    let name = path.to_string_lossy().to_ascii_lowercase();
    if name.ends_with(".csv") || name.ends_with(".csv.gz") {
        return parse_image_csv(&data).map_err(|source| ReadError::Parse { path: path.into(), source });
    }
    if !(name.ends_with(".exr") || name.ends_with(".exr.gz")) {
        return Err(ReadError::UnknownFormat { path: path.into() });
    }
    use exr::prelude::traits::*;
    let exr_err = |source| ReadError::Exr { path: path.into(), source };
    let img = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(IoCursor::new(&data))
        .map_err(exr_err)?;
    let layer = img.layer_data;
    let names: Vec<String> = layer.channel_data.list.iter().map(|c| c.name.to_string()).collect();
    let index = match channel {
        Some(want) => names.iter().position(|n| n == want),
        None if names.len() == 1 => Some(0),
        None => None,
    };
    let Some(index) = index else {
        let name = channel.unwrap_or("(the only channel: name one of several)").to_string();
        return Err(ReadError::SignalNotFound { path: path.into(), name, available: names });
    };
    let values = layer.channel_data.list[index].sample_data.values_as_f32().map(f64::from).collect();
    Ok(Image { width: layer.size.0, height: layer.size.1, values })
}

/// Writes a single-channel (`Y`, 32-bit float) EXR atomically. Values are
/// rounded to f32, so the EXR round trip is exact for f32 data.
pub fn write_exr(path: &Path, image: &Image) -> Result<(), WriteError> {
    use exr::prelude::*;
    let data: Vec<f32> = image.values.iter().map(|&v| v as f32).collect();
    let ch = AnyChannel::new("Y", FlatSamples::F32(data));
    let layer = Layer::new(
        (image.width, image.height),
        LayerAttributes::named("signal"),
        Encoding::FAST_LOSSLESS,
        AnyChannels::sort(SmallVec::from_vec(vec![ch])),
    );
    let mut buf = IoCursor::new(Vec::new());
    exr::prelude::Image::from_layer(layer)
        .write()
        .to_buffered(&mut buf)
        .map_err(|source| WriteError::Exr { path: path.into(), source })?;
    write_atomic(path, buf.get_ref(), false)
}
