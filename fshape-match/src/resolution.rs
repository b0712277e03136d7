//! Moving a solution between templates of different resolutions.
//!
//! The momenta p_0 and p^f are densities (see [`crate::unknowns`]): at a
//! vertex, p_i ≈ ρ(x_i)·m_i with ρ a density on the surface and m_i the
//! vertex's lumped area. What a coarse solution means is ρ, so the fine
//! momenta are the fine areas times ρ interpolated linearly from the
//! coarse mesh at each fine vertex (at its closest point on the coarse
//! mesh). Then the velocity field K p = Σ_j k(·, x_j) ρ(x_j) m_j and the
//! signal velocity D_s⁻¹ p^f/γ_f are two quadratures of the same
//! integrals, and the prolongated solution shoots to nearly the same end
//! (tested).

use fshape_mesh::FShape;
use fshape_shoot::ModelKind;

use crate::MatchError;
use crate::quality::ClosestPoints;

/// The momenta (p_0: P_c × n, p^f: P_c) of `coarse` carried to `fine`
/// (the same surface at another resolution): fine areas times the coarse
/// densities interpolated at the fine vertices. For the tangential model
/// (`kind`) the signal control ζ is a function and is interpolated as one.
pub fn prolongate(
    coarse: &FShape,
    fine: &FShape,
    p0: &[f64],
    pf: &[f64],
    kind: ModelKind,
) -> Result<(Vec<f64>, Vec<f64>), MatchError> {
    let signal_density = kind != ModelKind::Tangential;
    let (nc, dim) = (coarse.n_vertices(), coarse.dim());
    if fine.dim() != dim || fine.kind() != coarse.kind() {
        return Err(MatchError::Shapes("prolongation: the templates differ in dimension or cell type".into()));
    }
    if p0.len() != nc * dim || pf.len() != nc {
        return Err(MatchError::Shapes(format!(
            "prolongation: {} and {} momentum values for a coarse template of {nc} vertices in R^{dim}",
            p0.len(),
            pf.len()
        )));
    }
    let (mc, mf) = (coarse.vertex_volumes(), fine.vertex_volumes());
    if let Some(v) = mc.iter().position(|m| m.is_nan() || *m <= 0.0) {
        return Err(MatchError::Shapes(format!("prolongation: coarse vertex {v} has no area (unused or degenerate)")));
    }
    let density0: Vec<f64> = p0.iter().enumerate().map(|(i, p)| p / mc[i / dim]).collect();
    let densityf: Vec<f64> =
        if signal_density { pf.iter().zip(&mc).map(|(p, m)| p / m).collect() } else { pf.to_vec() };
    // Both densities in one pass of closest points: dim + 1 values a vertex.
    let both: Vec<f64> =
        density0.chunks_exact(dim).zip(&densityf).flat_map(|(d, f)| d.iter().chain([f])).copied().collect();
    let rho = sample(coarse, fine, &both, dim + 1)?;
    let (mut q0, mut qf) = (Vec::with_capacity(mf.len() * dim), Vec::with_capacity(mf.len()));
    for (r, m) in rho.chunks_exact(dim + 1).zip(&mf) {
        q0.extend(r[..dim].iter().map(|r| m * r));
        qf.push(if signal_density { m * r[dim] } else { r[dim] });
    }
    Ok((q0, qf))
}

/// The piecewise-linear function of `coarse` with `width` values per
/// vertex (`values`, vertex-major) read at every vertex of `fine`, at its
/// closest point on `coarse`: `width` values per fine vertex.
pub fn sample(coarse: &FShape, fine: &FShape, values: &[f64], width: usize) -> Result<Vec<f64>, MatchError> {
    let dim = coarse.dim();
    if fine.dim() != dim || fine.kind() != coarse.kind() {
        return Err(MatchError::Shapes("resampling: the meshes differ in dimension or cell type".into()));
    }
    if values.len() != coarse.n_vertices() * width {
        return Err(MatchError::Shapes(format!(
            "resampling: {} values for {} vertices of {width} each",
            values.len(),
            coarse.n_vertices()
        )));
    }
    let closest = ClosestPoints::new(coarse)?;
    let k = coarse.kind().n_corners();
    let mut out = Vec::with_capacity(fine.n_vertices() * width);
    for v in 0..fine.n_vertices() {
        let x = fine.point(v);
        let c = closest.closest([x[0], x[1], if dim == 3 { x[2] } else { 0.0 }]);
        let ids = &coarse.cells()[c.cell * k..(c.cell + 1) * k];
        for axis in 0..width {
            out.push(ids.iter().zip(c.bary).map(|(&u, w)| w * values[u * width + axis]).sum());
        }
    }
    Ok(out)
}
