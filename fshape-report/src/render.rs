//! PNG pictures of meshes coloured by their signal: a small software
//! rasteriser (orthographic camera, z-buffer, flat Lambert shading for
//! surfaces in R³, none for planar meshes, 2-pixel lines for curves) and a
//! viridis colour map. Written by hand because the job is ~150 lines and
//! the rendering crates pull in a GPU stack or a window system; the PNG
//! encoding is the `png` crate's.

use fshape_mesh::{CellKind, FShape};

/// Image side in pixels.
pub const SIZE: usize = 512;

/// How the frames of one figure are seen: the same rotation, framing and
/// colour range for every frame, so that they can be compared.
#[derive(Clone, Copy, Debug)]
pub struct View {
    /// Rows of the rotation taking world to camera coordinates (x right,
    /// y up, z towards the viewer).
    rot: [[f64; 3]; 3],
    /// Centre (camera coordinates) and pixels per unit.
    centre: [f64; 2],
    scale: f64,
    /// Signal values mapped to the ends of the colour map.
    range: (f64, f64),
    /// Blue–white–red instead of viridis (signed maps: a statistic).
    diverging: bool,
}

impl View {
    /// A view of all `shapes` (their union fits the image with a margin)
    /// from azimuth and elevation in degrees (ignored in the plane), with
    /// the colour range of all their signals.
    pub fn fit(shapes: &[&FShape], azimuth: f64, elevation: f64) -> View {
        let (a, e) = (azimuth.to_radians(), elevation.to_radians());
        let planar = shapes.first().is_some_and(|s| s.dim() == 2);
        let rot = if planar {
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
        } else {
            // Turn by the azimuth about z, then tilt by the elevation.
            let (ca, sa, ce, se) = (a.cos(), a.sin(), e.cos(), e.sin());
            [[ca, sa, 0.0], [-sa * se, ca * se, ce], [sa * ce, -ca * ce, se]]
        };
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        let (mut flo, mut fhi) = (f64::INFINITY, f64::NEG_INFINITY);
        for s in shapes {
            for p in s.points().chunks_exact(s.dim()) {
                let c = camera(&rot, p);
                for k in 0..2 {
                    lo[k] = lo[k].min(c[k]);
                    hi[k] = hi[k].max(c[k]);
                }
            }
            for f in s.channel(0).unwrap_or_default() {
                flo = flo.min(f);
                fhi = fhi.max(f);
            }
        }
        let span = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let scale = if span > 0.0 { 0.9 * SIZE as f64 / span } else { 1.0 };
        let range = if flo < fhi { (flo, fhi) } else { (flo.min(0.0), flo.max(0.0) + 1.0) };
        View { rot, centre: [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])], scale, range, diverging: false }
    }

    /// The same view with the colour map spanning the signals of `shapes`
    /// only (e.g. the source and the target, so that overshoots along the
    /// path saturate instead of washing the pictures out).
    pub fn with_range_of(mut self, shapes: &[&FShape]) -> View {
        let vals = shapes.iter().flat_map(|s| s.channel(0).unwrap_or_default());
        let (lo, hi) = vals.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
        if lo < hi {
            self.range = (lo, hi);
        }
        self
    }

    /// The same view with the colour map spanning `lo..hi`.
    pub fn with_range(mut self, lo: f64, hi: f64) -> View {
        self.range = (lo, hi);
        self
    }

    /// The same view coloured blue–white–red over −bound..bound: signed
    /// maps (t statistics), white at 0.
    pub fn diverging(mut self, bound: f64) -> View {
        let b = if bound > 0.0 && bound.is_finite() { bound } else { 1.0 };
        self.range = (-b, b);
        self.diverging = true;
        self
    }

    /// Pixel coordinates (column, row, depth) of a point.
    fn pixel(&self, p: &[f64]) -> [f64; 3] {
        let c = camera(&self.rot, p);
        let half = SIZE as f64 / 2.0;
        [half + (c[0] - self.centre[0]) * self.scale, half - (c[1] - self.centre[1]) * self.scale, c[2]]
    }
}

fn camera(rot: &[[f64; 3]; 3], p: &[f64]) -> [f64; 3] {
    let q = [p[0], p[1], p.get(2).copied().unwrap_or(0.0)];
    std::array::from_fn(|r| rot[r][0] * q[0] + rot[r][1] * q[1] + rot[r][2] * q[2])
}

/// Viridis at t ∈ [0, 1] (linear between nine samples of matplotlib's
/// table).
pub fn viridis(t: f64) -> [f64; 3] {
    const C: [[f64; 3]; 9] = [
        [0.267, 0.005, 0.329],
        [0.279, 0.175, 0.483],
        [0.230, 0.322, 0.546],
        [0.173, 0.449, 0.558],
        [0.128, 0.567, 0.551],
        [0.158, 0.684, 0.502],
        [0.369, 0.789, 0.383],
        [0.678, 0.864, 0.190],
        [0.993, 0.906, 0.144],
    ];
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) } * 8.0;
    let k = (t.floor() as usize).min(7);
    let u = t - k as f64;
    std::array::from_fn(|c| C[k][c] * (1.0 - u) + C[k + 1][c] * u)
}

/// Blue (t = 0), white (0.5), red (1): a diverging map for signed values.
pub fn blue_white_red(t: f64) -> [f64; 3] {
    let t = if t.is_nan() { 0.5 } else { t.clamp(0.0, 1.0) };
    let (blue, white, red) = ([0.23, 0.30, 0.75], [0.97, 0.97, 0.97], [0.71, 0.02, 0.15]);
    let (a, b, u) = if t < 0.5 { (blue, white, 2.0 * t) } else { (white, red, 2.0 * t - 1.0) };
    std::array::from_fn(|c| a[c] * (1.0 - u) + b[c] * u)
}

/// The PNG file of `shape` seen by `view`.
pub fn picture(shape: &FShape, view: &View) -> Result<Vec<u8>, png::EncodingError> {
    png(&rasterise(shape, view))
}

/// RGB pixels of `shape` seen by `view` on a white background.
pub fn rasterise(shape: &FShape, view: &View) -> Vec<u8> {
    let mut rgb = vec![255u8; SIZE * SIZE * 3];
    let mut depth = vec![f64::NEG_INFINITY; SIZE * SIZE];
    // A shape of several channels is coloured by its first.
    let f = shape.channel(0).unwrap_or_else(|| vec![0.0; shape.n_vertices()]);
    let dim = shape.dim();
    let px: Vec<[f64; 3]> = shape.points().chunks_exact(dim).map(|p| view.pixel(p)).collect();
    let (lo, hi) = view.range;
    let colour = |v: f64, light: f64| -> [u8; 3] {
        let t = (v - lo) / (hi - lo);
        // A masked vertex's signal (NaN: no value) is grey.
        let c = if v.is_nan() {
            [0.75; 3]
        } else if view.diverging {
            blue_white_red(t)
        } else {
            viridis(t)
        };
        std::array::from_fn(|k| (255.0 * c[k] * light).round().clamp(0.0, 255.0) as u8)
    };
    let mut put = |x: usize, y: usize, z: f64, c: [u8; 3]| {
        let i = y * SIZE + x;
        if z >= depth[i] {
            depth[i] = z;
            rgb[3 * i..3 * i + 3].copy_from_slice(&c);
        }
    };
    match shape.kind() {
        CellKind::Triangle => {
            for c in shape.cells().chunks_exact(3) {
                let (a, b, d) = (px[c[0]], px[c[1]], px[c[2]]);
                let area = (b[0] - a[0]) * (d[1] - a[1]) - (b[1] - a[1]) * (d[0] - a[0]);
                if area == 0.0 {
                    continue;
                }
                // Flat shading from the camera-space normal (two-sided);
                // planar meshes are unshaded.
                let light = if dim == 3 {
                    let (p0, p1, p2) = (
                        camera(&view.rot, &shape.points()[3 * c[0]..3 * c[0] + 3]),
                        camera(&view.rot, &shape.points()[3 * c[1]..3 * c[1] + 3]),
                        camera(&view.rot, &shape.points()[3 * c[2]..3 * c[2] + 3]),
                    );
                    let (u, v) =
                        ([p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]], [p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]]);
                    let n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
                    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                    if len > 0.0 { 0.35 + 0.65 * (n[2] / len).abs() } else { 0.35 }
                } else {
                    1.0
                };
                let xs = (
                    a[0].min(b[0]).min(d[0]).floor().max(0.0) as usize,
                    a[0].max(b[0]).max(d[0]).ceil().min((SIZE - 1) as f64),
                );
                let ys = (
                    a[1].min(b[1]).min(d[1]).floor().max(0.0) as usize,
                    a[1].max(b[1]).max(d[1]).ceil().min((SIZE - 1) as f64),
                );
                if xs.1 < 0.0 || ys.1 < 0.0 {
                    continue;
                }
                for y in ys.0..=ys.1 as usize {
                    for x in xs.0..=xs.1 as usize {
                        let (qx, qy) = (x as f64 + 0.5, y as f64 + 0.5);
                        // Barycentric coordinates by edge functions.
                        let w0 = ((b[0] - qx) * (d[1] - qy) - (b[1] - qy) * (d[0] - qx)) / area;
                        let w1 = ((d[0] - qx) * (a[1] - qy) - (d[1] - qy) * (a[0] - qx)) / area;
                        let w2 = 1.0 - w0 - w1;
                        if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                            continue;
                        }
                        let z = w0 * a[2] + w1 * b[2] + w2 * d[2];
                        let v = w0 * f[c[0]] + w1 * f[c[1]] + w2 * f[c[2]];
                        put(x, y, z, colour(v, light));
                    }
                }
            }
        }
        CellKind::Segment => {
            for c in shape.cells().chunks_exact(2) {
                let (a, b) = (px[c[0]], px[c[1]]);
                let n = ((b[0] - a[0]).abs().max((b[1] - a[1]).abs()).ceil() as usize).max(1) * 2;
                for k in 0..=n {
                    let t = k as f64 / n as f64;
                    let (x, y) = (a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]));
                    let v = (1.0 - t) * f[c[0]] + t * f[c[1]];
                    let z = (1.0 - t) * a[2] + t * b[2];
                    for (dx, dy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
                        let (xi, yi) = ((x - 0.5 + dx).floor(), (y - 0.5 + dy).floor());
                        if (0.0..SIZE as f64).contains(&xi) && (0.0..SIZE as f64).contains(&yi) {
                            put(xi as usize, yi as usize, z, colour(v, 1.0));
                        }
                    }
                }
            }
        }
    }
    rgb
}

/// Pictures of SIZE × SIZE (as [`rasterise`] makes them) laid out in
/// rows of `cols` on white, each shrunk `shrink` times (the mean of each
/// `shrink` × `shrink` block; 1 keeps it whole): (RGB, width, height).
/// The pictures are taken one at a time, so a large grid never holds
/// them all.
pub fn mosaic(tiles: impl ExactSizeIterator<Item = Vec<u8>>, cols: usize, shrink: usize) -> (Vec<u8>, u32, u32) {
    let (tile, area) = (SIZE / shrink, shrink * shrink);
    let rows = tiles.len().div_ceil(cols).max(1);
    let (width, height) = (cols * tile, rows * tile);
    let mut rgb = vec![255u8; width * height * 3];
    for (k, full) in tiles.enumerate() {
        let (col, row) = (k % cols, k / cols);
        for y in 0..tile {
            for x in 0..tile {
                let dst = ((row * tile + y) * width + col * tile + x) * 3;
                for c in 0..3 {
                    let sum: usize = (0..area)
                        .map(|b| {
                            usize::from(full[((shrink * y + b / shrink) * SIZE + shrink * x + b % shrink) * 3 + c])
                        })
                        .sum();
                    rgb[dst + c] = (sum / area) as u8;
                }
            }
        }
    }
    (rgb, width as u32, height as u32)
}

/// `rgb` (SIZE × SIZE) as PNG bytes.
pub fn png(rgb: &[u8]) -> Result<Vec<u8>, png::EncodingError> {
    png_sized(rgb, SIZE as u32, SIZE as u32)
}

/// `rgb` (width × height, row-major RGB8) as PNG bytes.
pub fn png_sized(rgb: &[u8], width: u32, height: u32) -> Result<Vec<u8>, png::EncodingError> {
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, width, height);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header()?;
        w.write_image_data(rgb)?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn triangle(z: f64, f: f64, offset: f64) -> FShape {
        FShape::try_new(
            3,
            CellKind::Triangle,
            vec![offset, 0.0, z, 1.0 + offset, 0.0, z, offset, 1.0, z],
            vec![0, 1, 2],
            Some(vec![f; 3]),
        )
        .unwrap()
    }

    #[test]
    fn a_face_on_triangle_fills_its_half_of_the_frame_in_the_colour_of_its_signal() {
        // Seen from above (elevation 90°) the unit right triangle fills the
        // lower-left half of the 0.9·SIZE square frame; its normal faces the
        // camera, so the light is 1 and the colour viridis(t) exactly.
        let lo = triangle(0.0, 0.0, 0.0);
        let hi = triangle(0.0, 1.0, 0.0);
        let view = View::fit(&[&lo, &hi], 0.0, 90.0);
        let img = rasterise(&hi, &view);
        let at =
            |x: usize, y: usize| [img[3 * (y * SIZE + x)], img[3 * (y * SIZE + x) + 1], img[3 * (y * SIZE + x) + 2]];
        let top = viridis(1.0).map(|c| (255.0 * c).round() as u8);
        assert_eq!(at(SIZE / 4, 3 * SIZE / 4), top, "inside, near the right angle");
        assert_eq!(at(3 * SIZE / 4, SIZE / 4), [255; 3], "beyond the hypotenuse: background");
        assert_eq!(at(2, 2), [255; 3], "the margin");
        let bottom = rasterise(&lo, &view);
        assert_eq!(
            &bottom[3 * (3 * SIZE / 4 * SIZE + SIZE / 4)..][..3],
            viridis(0.0).map(|c| (255.0 * c).round() as u8)
        );
    }

    #[test]
    fn the_nearer_of_two_overlapping_triangles_is_seen() {
        let mut points = triangle(0.0, 0.0, 0.0).points().to_vec();
        points.extend_from_slice(triangle(1.0, 0.0, 0.0).points());
        let both =
            FShape::try_new(3, CellKind::Triangle, points, vec![0, 1, 2, 3, 4, 5], Some(vec![0., 0., 0., 1., 1., 1.]))
                .unwrap();
        // Both orders of the cells: the z-buffer, not the drawing order, decides.
        let swapped = FShape::try_new(
            3,
            CellKind::Triangle,
            both.points().to_vec(),
            vec![3, 4, 5, 0, 1, 2],
            Some(vec![0., 0., 0., 1., 1., 1.]),
        )
        .unwrap();
        let view = View::fit(&[&both], 0.0, 90.0);
        let top = viridis(1.0).map(|c| (255.0 * c).round() as u8);
        for s in [&both, &swapped] {
            let img = rasterise(s, &view);
            let i = 3 * (3 * SIZE / 4 * SIZE + SIZE / 4);
            assert_eq!(&img[i..i + 3], top, "the triangle at z = 1 (towards the camera) covers the one at z = 0");
        }
    }

    #[test]
    fn a_mosaic_places_tiles_row_by_row_and_shrinks_each_to_its_block_means() {
        // A tile whose pixel (x, y) has red x % 2, green y % 2 and blue 30:
        // every 2 × 2 block averages to (0, 0, 30) (integer division).
        let checker: Vec<u8> =
            (0..SIZE * SIZE).flat_map(|i| [(i % SIZE % 2) as u8 * 2, (i / SIZE % 2) as u8 * 2, 30]).collect();
        let solid = |v: u8| vec![v; SIZE * SIZE * 3];
        let (rgb, w, h) = mosaic([checker, solid(10), solid(200)].into_iter(), 2, 2);
        let half = SIZE / 2;
        assert_eq!((w, h), (SIZE as u32, SIZE as u32), "two columns, two rows of half-size tiles");
        let at = |x: usize, y: usize| &rgb[3 * (y * SIZE + x)..3 * (y * SIZE + x) + 3];
        assert_eq!(at(3, 5), [1, 1, 30], "tile 0, upper left: the block means");
        assert_eq!(at(half + 7, 9), [10; 3], "tile 1, upper right");
        assert_eq!(at(2, half + 1), [200; 3], "tile 2 starts the second row");
        assert_eq!(at(half + 2, half + 2), [255; 3], "no fourth tile: white");
    }

    #[test]
    fn png_bytes_decode_to_the_same_pixels() {
        let t = triangle(0.0, 0.5, 0.0);
        let img = rasterise(&t, &View::fit(&[&t], 30.0, 40.0));
        let bytes = png(&img).unwrap();
        let mut reader = png::Decoder::new(std::io::Cursor::new(bytes)).read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), (SIZE as u32, SIZE as u32));
        assert_eq!(&buf[..info.buffer_size()], &img[..]);
    }
}
