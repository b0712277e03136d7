//! Kernel sums over point sets, exact or truncated, and their derivatives.

use std::sync::OnceLock;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

use crate::fast::{self, Inputs};
use crate::{Kernel, KernelError};

/// A spatial index over the source points y, for truncated kernels.
enum Tree {
    D2(ImmutableKdTree<f64, 2>),
    D3(ImmutableKdTree<f64, 3>),
    Bvh { bvh: obvhs::bvh2::Bvh2, pad: f32 },
}

/// Which spatial index the per-pair engine uses for truncated kernels.
/// obvhs is the default the design chose; kiddo measured 1.2–1.4× faster on
/// the 32k cortex (ARCHITECTURE.md), short of the 1.5× the project asked
/// for before switching.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SpatialIndex {
    /// obvhs's f32 BVH: points as boxes, a padded box query, exact f64
    /// distances checked afterwards.
    #[default]
    Obvhs,
    /// kiddo's f64 k-d tree with radius queries.
    Kiddo,
}

/// Kernel sums against fixed source points y (M × dim, flat): evaluation
/// and derivatives at any target points x.
///
/// With an untapered kernel every pair is summed, in increasing j for each
/// output. With a truncated kernel ([`Kernel::truncated`]) a spatial index
/// over y ([`SpatialIndex`]: obvhs by default, or kiddo) visits only the j
/// within the support radius; the index is built
/// on first use, once, so **build a new `KernelSums` when y moves** (in
/// shooting: once per evaluation of the vector field). Sums of up to four
/// Gaussians, exact or truncated, take a faster vectorised path for every
/// operation instead: the points are sorted into blocks, whole blocks
/// beyond the support radius are skipped ([`crate::BlockPairs`]), and with
/// integer ratios between the a_t = 1/(2σ_t²) one exponential serves all
/// terms. The per-pair engine serves Cauchy kernels and longer sums.
/// Outputs are computed in
/// parallel over i, each summed in an order that depends only on the data:
/// serial and parallel results are equal bit for bit.
pub struct KernelSums<'a> {
    kernel: &'a Kernel,
    y: &'a [f64],
    dim: usize,
    /// Built on first use by the per-pair engine (truncated kernels only).
    tree: OnceLock<Result<Tree, KernelError>>,
    radius2: f64,
    index: SpatialIndex,
    run_search: crate::RunSearch,
    parallel: bool,
    precision: crate::Precision,
}

/// Memory the `*_into` sums reuse from call to call (blocks, sources in
/// block order, per-target rows), so that a time-stepping loop allocates
/// nothing once the first call has sized it. `SumWorkspace::default()` is
/// empty; one per thread of work.
#[derive(Default)]
pub struct SumWorkspace {
    fast: fast::FastWorkspace,
    grid: crate::grid::GridWorkspace,
}

/// A pair's geometry handed to per-pair closures.
pub struct Pair<'p> {
    /// Source index j.
    pub j: usize,
    /// u = |x_i − y_j|².
    pub u: f64,
    /// x_i − y_j (`dim` components).
    pub diff: &'p [f64],
}

impl<'a> KernelSums<'a> {
    /// Prepares sums against `y` (`dim` = 2 or 3 coordinates per point).
    pub fn try_new(kernel: &'a Kernel, y: &'a [f64], dim: usize) -> Result<Self, KernelError> {
        if dim != 2 && dim != 3 {
            return Err(KernelError::PointDimension { found: dim });
        }
        if !y.len().is_multiple_of(dim) {
            return Err(KernelError::Dimension {
                what: "source coordinates",
                expected: y.len() / dim * dim,
                found: y.len(),
            });
        }
        if let Some(i) = y.iter().position(|v| !v.is_finite()) {
            return Err(KernelError::NonFinite { what: "source point", index: i / dim });
        }
        let n = y.len() / dim;
        if kernel.support_radius().is_some() && u32::try_from(n).is_err() {
            return Err(KernelError::TooManyPoints { n });
        }
        let radius2 = kernel.support_radius().map_or(f64::INFINITY, |r| r * r);
        Ok(KernelSums {
            kernel,
            y,
            dim,
            tree: OnceLock::new(),
            radius2,
            index: SpatialIndex::default(),
            run_search: crate::RunSearch::Auto,
            parallel: true,
            precision: crate::Precision::F64,
        })
    }

    /// Chooses the spatial index of the per-pair engine (default obvhs).
    pub fn with_index(mut self, index: SpatialIndex) -> Self {
        self.index = index;
        self.tree = OnceLock::new();
        self
    }

    /// Chooses how the vectorised path finds the source blocks within the
    /// support of each target block ([`RunSearch`](crate::RunSearch),
    /// default `Auto`); the results are identical.
    pub fn with_run_search(mut self, search: crate::RunSearch) -> Self {
        self.run_search = search;
        self
    }

    /// The spatial index the per-pair engine has built so far: `None`
    /// until a sum has needed one (a truncated kernel on the per-pair
    /// engine), and always `None` on the vectorised block path, which
    /// needs none. Tells which path a sum took.
    pub fn spatial_index_built(&self) -> Option<SpatialIndex> {
        match self.tree.get()?.as_ref().ok()? {
            Tree::Bvh { .. } => Some(SpatialIndex::Obvhs),
            Tree::D2(_) | Tree::D3(_) => Some(SpatialIndex::Kiddo),
        }
    }

    /// Parallel (default) or serial evaluation; the results are identical.
    pub fn with_parallel(mut self, parallel: bool) -> Self {
        self.parallel = parallel;
        self
    }

    /// The arithmetic of [`KernelSums::conv`] for sums of Gaussians: f64
    /// (default) or [`Precision::MixedF32`](crate::Precision::MixedF32),
    /// pair terms in f32 within a stated error bound, about twice as fast.
    /// Derivatives and other kernels are f64 either way.
    pub fn with_precision(mut self, precision: crate::Precision) -> Self {
        self.precision = precision;
        self
    }

    /// Number of source points M.
    pub fn n_sources(&self) -> usize {
        self.y.len() / self.dim
    }

    /// The kernel.
    pub fn kernel(&self) -> &Kernel {
        self.kernel
    }

    /// Inputs with every slice empty, to fill in with `..`.
    fn no_inputs(&self) -> Inputs<'static> {
        Inputs { x: &[], dx: &[], y: &[], dy: &[], a: &[], da: &[], b: &[], db: &[] }
    }

    /// The spatial index over y for a truncated kernel (obvhs BVH by
    /// default, or kiddo's k-d tree; built once), or `None`.
    fn tree(&self) -> Option<&Tree> {
        self.kernel.support_radius()?;
        let t = self.tree.get_or_init(|| {
            let n = self.n_sources();
            let err = |_| KernelError::TooManyPoints { n };
            if self.index == SpatialIndex::Obvhs {
                return Ok(self.bvh());
            }
            Ok(if self.dim == 2 {
                let pts: Vec<[f64; 2]> = self.y.chunks_exact(2).map(|p| [p[0], p[1]]).collect();
                Tree::D2(ImmutableKdTree::new_from_slice(&pts).map_err(err)?)
            } else {
                let pts: Vec<[f64; 3]> = self.y.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
                Tree::D3(ImmutableKdTree::new_from_slice(&pts).map_err(err)?)
            })
        });
        // The only construction error (too many points) is refused in try_new.
        t.as_ref().ok()
    }

    /// An obvhs BVH over the sources as point boxes (z = 0 in the plane).
    fn bvh(&self) -> Tree {
        use obvhs::aabb::Aabb;
        let p = |j: usize| {
            let q = &self.y[j * self.dim..(j + 1) * self.dim];
            glam::Vec3A::new(q[0] as f32, q[1] as f32, q.get(2).copied().unwrap_or(0.0) as f32)
        };
        let boxes: Vec<Aabb> = (0..self.n_sources()).map(|j| Aabb::new(p(j), p(j))).collect();
        let bvh =
            obvhs::bvh2::builder::build_bvh2(&boxes, obvhs::BvhBuildParams::fast_build(), &mut Default::default());
        // f32 rounding moves a coordinate by at most 2⁻²⁴ of its size: pad
        // the query box well beyond that so no pair within the radius is lost.
        let scale = self.y.iter().fold(0.0f64, |m, v| m.max(v.abs())) + self.radius2.sqrt();
        Tree::Bvh { bvh, pad: (1e-6 * scale) as f32 }
    }

    /// Calls `f` for every source j that can interact with the target `xi`
    /// (all of them for an untapered kernel, those within the support
    /// radius otherwise), in an order fixed by the data.
    pub fn for_each_pair(&self, xi: &[f64], mut f: impl FnMut(Pair<'_>)) {
        let n = self.dim;
        let mut diff = [0.0; 3];
        let mut visit = |j: usize| {
            let yj = &self.y[j * n..(j + 1) * n];
            let mut u = 0.0;
            for k in 0..n {
                diff[k] = xi[k] - yj[k];
                u += diff[k] * diff[k];
            }
            if u < self.radius2 {
                f(Pair { j, u, diff: &diff[..n] });
            }
        };
        match self.tree() {
            None => (0..self.n_sources()).for_each(&mut visit),
            Some(Tree::D2(t)) => t
                .query(&[xi[0], xi[1]])
                .within::<SquaredEuclidean<f64>>(self.radius2)
                .unsorted()
                .visit(|h| visit(h.item as usize)),
            Some(Tree::D3(t)) => t
                .query(&[xi[0], xi[1], xi[2]])
                .within::<SquaredEuclidean<f64>>(self.radius2)
                .unsorted()
                .visit(|h| visit(h.item as usize)),
            Some(Tree::Bvh { bvh, pad }) => {
                let q = glam::Vec3A::new(xi[0] as f32, xi[1] as f32, xi.get(2).copied().unwrap_or(0.0) as f32);
                let half = glam::Vec3A::splat(self.radius2.sqrt() as f32 + pad);
                bvh.aabb_traverse(obvhs::aabb::Aabb::new(q - half, q + half), |bvh, id| {
                    let node = &bvh.nodes[id as usize];
                    for k in 0..node.prim_count {
                        visit(bvh.primitive_indices[(node.first_index + k) as usize] as usize);
                    }
                    true
                });
            }
        }
    }

    /// The general engine: out[i·w .. (i+1)·w] = Σ_j f(i, pair), for every
    /// target x_i, in parallel over i. fshape-varifold uses it for its
    /// products of kernels.
    pub fn map_targets(
        &self,
        x: &[f64],
        w: usize,
        f: impl Fn(usize, &Pair<'_>, &mut [f64]) + Sync,
    ) -> Result<Vec<f64>, KernelError> {
        self.check_targets(x)?;
        let n = self.dim;
        let mut out = vec![0.0; x.len() / n * w];
        let one = |(i, o): (usize, &mut [f64])| self.for_each_pair(&x[i * n..(i + 1) * n], |p| f(i, &p, o));
        if self.parallel {
            out.par_chunks_mut(w.max(1)).enumerate().for_each(one);
        } else {
            out.chunks_mut(w.max(1)).enumerate().for_each(one);
        }
        Ok(out)
    }

    /// The vectorised path for sums of Gaussians (exact or truncated), or
    /// `None` for other kernels and dimensions.
    fn fast<const MODE: u8>(&self, inp: Inputs<'_>, bdim: usize) -> Result<Option<Vec<f64>>, KernelError> {
        if self.kernel.grid().is_some() {
            let w = fast::rows(MODE, self.dim, bdim);
            let mut out = vec![0.0; inp.x.len() / self.dim * w];
            self.fast_into::<MODE>(&mut SumWorkspace::default(), inp, bdim, w, &mut out, &mut [])?;
            return Ok(Some(out));
        }
        let Some(w) = fast::out_rows::<MODE>(self.dim, bdim) else { return Ok(None) };
        let mut out = vec![0.0; inp.x.len() / self.dim * w];
        let done = self.fast_into::<MODE>(&mut SumWorkspace::default(), inp, bdim, w, &mut out, &mut [])?;
        Ok(done.then_some(out))
    }

    /// The vectorised path into `out1` (the first `split` values of each
    /// target's row) and `out2` (the rest), with `ws`'s memory; `false` for
    /// other kernels and dimensions (nothing written).
    fn fast_into<const MODE: u8>(
        &self,
        ws: &mut SumWorkspace,
        inp: Inputs<'_>,
        bdim: usize,
        split: usize,
        out1: &mut [f64],
        out2: &mut [f64],
    ) -> Result<bool, KernelError> {
        if let Some(grid) = self.kernel.grid() {
            self.check_targets(inp.x)?;
            let terms = self.kernel.gaussian_terms_untruncated().expect("a grid kernel is a sum of Gaussians");
            crate::grid::grid_sum_into::<MODE>(
                grid,
                &terms,
                inp,
                self.dim,
                bdim,
                self.parallel,
                &mut ws.grid,
                split,
                out1,
                out2,
            )?;
            return Ok(true);
        }
        let Some(terms) = self.kernel.gaussian_terms() else { return Ok(false) };
        self.check_targets(inp.x)?;
        let taper = self.kernel.taper();
        ws.fast.pairs.set_search(self.run_search);
        Ok(fast::gaussian_sum_into::<MODE>(
            &terms,
            taper,
            inp,
            self.dim,
            bdim,
            self.parallel,
            &mut ws.fast,
            split,
            out1,
            out2,
        ))
    }

    /// [`KernelSums::conv`] of b and [`KernelSums::grad_cross`] of (a, b)
    /// together: the vectorised path computes both from the same
    /// exponentials (the shooting field needs K p and ∂_x(pᵀK p) at once).
    pub fn conv_and_grad(
        &self,
        x: &[f64],
        a: &[f64],
        b: &[f64],
        bdim: usize,
    ) -> Result<(Vec<f64>, Vec<f64>), KernelError> {
        let nx = x.len() / self.dim;
        let (mut conv, mut grad) = (vec![0.0; nx * bdim], vec![0.0; nx * self.dim]);
        self.conv_and_grad_into(&mut SumWorkspace::default(), x, a, b, bdim, &mut conv, &mut grad)?;
        Ok((conv, grad))
    }

    /// [`KernelSums::conv_and_grad`] into `conv` (N × bdim) and `grad`
    /// (N × dim), with `ws`'s memory: for sums of up to four Gaussians,
    /// no allocation once `ws` has served as many points, but for the BVH
    /// of a truncated kernel's run search from 256 source blocks on
    /// ([`RunSearch`](crate::RunSearch)); the other kernels compute into
    /// temporaries and copy.
    #[allow(clippy::too_many_arguments)]
    pub fn conv_and_grad_into(
        &self,
        ws: &mut SumWorkspace,
        x: &[f64],
        a: &[f64],
        b: &[f64],
        bdim: usize,
        conv: &mut [f64],
        grad: &mut [f64],
    ) -> Result<(), KernelError> {
        let nx = x.len() / self.dim;
        self.check_len("a", a, nx * bdim)?;
        self.check_len("b", b, self.n_sources() * bdim)?;
        self.check_len("conv output", conv, nx * bdim)?;
        self.check_len("gradient output", grad, nx * self.dim)?;
        let inp = Inputs { x, y: self.y, a, b, ..self.no_inputs() };
        if !self.fast_into::<{ fast::CONV_GRAD }>(ws, inp, bdim, bdim, conv, grad)? {
            conv.copy_from_slice(&self.conv(x, b, bdim)?);
            grad.copy_from_slice(&self.grad_cross(x, a, b, bdim)?);
        }
        Ok(())
    }

    /// [`KernelSums::conv_jvp`] and [`KernelSums::grad_cross_jvp`] together
    /// (shared exponentials on the vectorised path).
    #[allow(clippy::too_many_arguments)]
    pub fn conv_and_grad_jvp(
        &self,
        x: &[f64],
        dx: &[f64],
        dy: &[f64],
        a: &[f64],
        da: &[f64],
        b: &[f64],
        db: &[f64],
        bdim: usize,
    ) -> Result<(Vec<f64>, Vec<f64>), KernelError> {
        let nx = x.len() / self.dim;
        let (mut conv, mut grad) = (vec![0.0; nx * bdim], vec![0.0; nx * self.dim]);
        let mut ws = SumWorkspace::default();
        self.conv_and_grad_jvp_into(&mut ws, x, dx, dy, a, da, b, db, bdim, &mut conv, &mut grad)?;
        Ok((conv, grad))
    }

    /// [`KernelSums::conv_and_grad_jvp`] into `conv` (N × bdim) and `grad`
    /// (N × dim), with `ws`'s memory (allocation-free as
    /// [`KernelSums::conv_and_grad_into`]).
    #[allow(clippy::too_many_arguments)]
    pub fn conv_and_grad_jvp_into(
        &self,
        ws: &mut SumWorkspace,
        x: &[f64],
        dx: &[f64],
        dy: &[f64],
        a: &[f64],
        da: &[f64],
        b: &[f64],
        db: &[f64],
        bdim: usize,
        conv: &mut [f64],
        grad: &mut [f64],
    ) -> Result<(), KernelError> {
        let nx = x.len() / self.dim;
        for (what, v, len) in [
            ("dx", dx, x.len()),
            ("dy", dy, self.y.len()),
            ("a", a, nx * bdim),
            ("da", da, nx * bdim),
            ("b", b, self.n_sources() * bdim),
            ("db", db, self.n_sources() * bdim),
            ("conv output", conv, nx * bdim),
            ("gradient output", grad, nx * self.dim),
        ] {
            self.check_len(what, v, len)?;
        }
        let inp = Inputs { x, dx, y: self.y, dy, a, da, b, db };
        if !self.fast_into::<{ fast::BOTH_JVP }>(ws, inp, bdim, bdim, conv, grad)? {
            conv.copy_from_slice(&self.conv_jvp(x, dx, dy, b, db, bdim)?);
            grad.copy_from_slice(&self.grad_cross_jvp(x, dx, dy, a, da, b, db, bdim)?);
        }
        Ok(())
    }

    /// [`KernelSums::conv_and_grad_into`] at the sources themselves
    /// (x = y) with a = b: conv = K(y) b and grad = [`KernelSums::grad_cross`]
    /// of (b, b) at y, half of ∂_y(bᵀK(y)b) (the shooting's K p and
    /// ∂_x(pᵀK p)/2). For exact sums of Gaussians each pair is visited
    /// once (the kernel is symmetric: pair (i, j) gives j the mirror of what
    /// it gives i), about half the work; other kernels take
    /// [`KernelSums::conv_and_grad_into`]. Serial and parallel results are
    /// equal bit for bit, as for every sum here.
    pub fn self_conv_and_grad_into(
        &self,
        ws: &mut SumWorkspace,
        b: &[f64],
        bdim: usize,
        conv: &mut [f64],
        grad: &mut [f64],
    ) -> Result<(), KernelError> {
        let n = self.n_sources();
        self.check_len("b", b, n * bdim)?;
        self.check_len("conv output", conv, n * bdim)?;
        self.check_len("gradient output", grad, n * self.dim)?;
        let inp = crate::symmetric::SelfInputs { y: self.y, dy: &[], b, db: &[] };
        if !self.self_sums::<false>(ws, inp, bdim, conv, grad)? {
            self.conv_and_grad_into(ws, self.y, b, b, bdim, conv, grad)?;
        }
        Ok(())
    }

    /// [`KernelSums::conv_and_grad_jvp_into`] at the sources themselves
    /// with dx = dy, a = b and da = db: the directional derivatives of
    /// [`KernelSums::self_conv_and_grad_into`] when y and b move by dy and
    /// db, each pair visited once for exact sums of Gaussians.
    #[allow(clippy::too_many_arguments)]
    pub fn self_conv_and_grad_jvp_into(
        &self,
        ws: &mut SumWorkspace,
        dy: &[f64],
        b: &[f64],
        db: &[f64],
        bdim: usize,
        conv: &mut [f64],
        grad: &mut [f64],
    ) -> Result<(), KernelError> {
        let n = self.n_sources();
        for (what, v, len) in [
            ("dy", dy, self.y.len()),
            ("b", b, n * bdim),
            ("db", db, n * bdim),
            ("conv output", conv, n * bdim),
            ("gradient output", grad, n * self.dim),
        ] {
            self.check_len(what, v, len)?;
        }
        let inp = crate::symmetric::SelfInputs { y: self.y, dy, b, db };
        if !self.self_sums::<true>(ws, inp, bdim, conv, grad)? {
            self.conv_and_grad_jvp_into(ws, self.y, dy, dy, b, db, b, db, bdim, conv, grad)?;
        }
        Ok(())
    }

    /// The symmetric path for exact sums of Gaussians; `false` (nothing
    /// written) for other kernels and dimensions.
    fn self_sums<const JVP: bool>(
        &self,
        ws: &mut SumWorkspace,
        inp: crate::symmetric::SelfInputs<'_>,
        bdim: usize,
        conv: &mut [f64],
        grad: &mut [f64],
    ) -> Result<bool, KernelError> {
        let Some(terms) = self.kernel.gaussian_terms() else { return Ok(false) };
        // Truncated and grid kernels take the general (target-wise) paths.
        if self.kernel.taper().is_some() || self.kernel.grid().is_some() {
            return Ok(false);
        }
        Ok(crate::symmetric::self_sums_into::<JVP>(
            &terms,
            inp,
            self.dim,
            bdim,
            self.parallel,
            &mut ws.fast,
            conv,
            grad,
        ))
    }

    fn check_targets(&self, x: &[f64]) -> Result<(), KernelError> {
        if !x.len().is_multiple_of(self.dim) {
            return Err(KernelError::Dimension {
                what: "target coordinates",
                expected: x.len() / self.dim * self.dim,
                found: x.len(),
            });
        }
        match x.iter().position(|v| !v.is_finite()) {
            Some(i) => Err(KernelError::NonFinite { what: "target point", index: i / self.dim }),
            None => Ok(()),
        }
    }

    fn check_len(&self, what: &'static str, v: &[f64], expected: usize) -> Result<(), KernelError> {
        if v.len() == expected { Ok(()) } else { Err(KernelError::Dimension { what, expected, found: v.len() }) }
    }

    /// out_i = Σ_j k(|x_i − y_j|²) b_j, with b_j of `bdim` components
    /// (b: M × bdim). With b = momenta this is the LDDMM velocity K_{x,y} b.
    ///
    /// ```
    /// use fshape_kernels::{Kernel, KernelSums};
    /// let k = Kernel::gaussian(1.0)?;
    /// let y = [0.0, 0.0, 0.0];
    /// let sums = KernelSums::try_new(&k, &y, 3)?;
    /// // One source at the origin with weight 2, one target at distance 1:
    /// let out = sums.conv(&[1.0, 0.0, 0.0], &[2.0], 1)?;
    /// assert!((out[0] - 2.0 * (-0.5f64).exp()).abs() < 1e-15);
    /// # Ok::<(), fshape_kernels::KernelError>(())
    /// ```
    pub fn conv(&self, x: &[f64], b: &[f64], bdim: usize) -> Result<Vec<f64>, KernelError> {
        self.check_len("b", b, self.n_sources() * bdim)?;
        if let (crate::Precision::MixedF32, Some(terms), None) =
            (self.precision, self.kernel.gaussian_terms(), self.kernel.grid())
        {
            self.check_targets(x)?;
            let taper = self.kernel.taper();
            if let Some(out) = crate::mixed::conv(&terms, taper, x, self.y, b, self.dim, bdim, self.parallel) {
                return Ok(out);
            }
        }
        if let Some(out) = self.fast::<{ fast::CONV }>(Inputs { x, y: self.y, b, ..self.no_inputs() }, bdim)? {
            return Ok(out);
        }
        self.map_targets(x, bdim, |_, p, o| {
            let k = self.kernel.value(p.u);
            for c in 0..bdim {
                o[c] += k * b[p.j * bdim + c];
            }
        })
    }

    /// ∂_x Σ_{i,j} k(|x_i − y_j|²) a_i·b_j = Σ_j 2 k'(u_ij) (a_i·b_j)(x_i − y_j)
    /// for each x_i (a: N × bdim, b: M × bdim). For the self term with y = x
    /// and a = b = p, the gradient of pᵀ K_{x,x} p is twice this.
    pub fn grad_cross(&self, x: &[f64], a: &[f64], b: &[f64], bdim: usize) -> Result<Vec<f64>, KernelError> {
        let n = self.dim;
        self.check_len("a", a, x.len() / n * bdim)?;
        self.check_len("b", b, self.n_sources() * bdim)?;
        if let Some(out) = self.fast::<{ fast::GRAD }>(Inputs { x, y: self.y, a, b, ..self.no_inputs() }, bdim)? {
            return Ok(out);
        }
        self.map_targets(x, n, |i, p, o| {
            let ab: f64 = (0..bdim).map(|c| a[i * bdim + c] * b[p.j * bdim + c]).sum();
            let s = 2.0 * self.kernel.derivatives(p.u)[1] * ab;
            for (ok, dk) in o.iter_mut().zip(p.diff) {
                *ok += s * dk;
            }
        })
    }

    /// Directional derivative of [`KernelSums::conv`] when x moves by dx,
    /// y by dy (pass zeros if y is fixed; dy = dx when y is x) and b by db:
    /// Σ_j [2 k'(u)((x_i − y_j)·(dx_i − dy_j)) b_j + k(u) db_j].
    #[allow(clippy::too_many_arguments)]
    pub fn conv_jvp(
        &self,
        x: &[f64],
        dx: &[f64],
        dy: &[f64],
        b: &[f64],
        db: &[f64],
        bdim: usize,
    ) -> Result<Vec<f64>, KernelError> {
        let n = self.dim;
        self.check_len("dx", dx, x.len())?;
        self.check_len("dy", dy, self.y.len())?;
        self.check_len("b", b, self.n_sources() * bdim)?;
        self.check_len("db", db, self.n_sources() * bdim)?;
        let inp = Inputs { x, dx, y: self.y, dy, b, db, ..self.no_inputs() };
        if let Some(out) = self.fast::<{ fast::CONV_JVP }>(inp, bdim)? {
            return Ok(out);
        }
        self.map_targets(x, bdim, |i, p, o| {
            let [k, dk, _] = self.kernel.derivatives(p.u);
            let du: f64 = (0..n).map(|c| 2.0 * p.diff[c] * (dx[i * n + c] - dy[p.j * n + c])).sum();
            for c in 0..bdim {
                o[c] += dk * du * b[p.j * bdim + c] + k * db[p.j * bdim + c];
            }
        })
    }

    /// Directional derivative of [`KernelSums::grad_cross`] when x, y, a, b
    /// move by dx, dy, da, db:
    /// Σ_j [2k''(u) du (a_i·b_j)(x_i − y_j) + 2k'(u)(da_i·b_j + a_i·db_j)(x_i − y_j)
    /// + 2k'(u)(a_i·b_j)(dx_i − dy_j)], du = 2(x_i − y_j)·(dx_i − dy_j).
    #[allow(clippy::too_many_arguments)]
    pub fn grad_cross_jvp(
        &self,
        x: &[f64],
        dx: &[f64],
        dy: &[f64],
        a: &[f64],
        da: &[f64],
        b: &[f64],
        db: &[f64],
        bdim: usize,
    ) -> Result<Vec<f64>, KernelError> {
        let n = self.dim;
        let nx = x.len() / n;
        self.check_len("dx", dx, x.len())?;
        self.check_len("dy", dy, self.y.len())?;
        for (what, v, len) in [
            ("a", a, nx * bdim),
            ("da", da, nx * bdim),
            ("b", b, self.n_sources() * bdim),
            ("db", db, self.n_sources() * bdim),
        ] {
            self.check_len(what, v, len)?;
        }
        if let Some(out) = self.fast::<{ fast::GRAD_JVP }>(Inputs { x, dx, y: self.y, dy, a, da, b, db }, bdim)? {
            return Ok(out);
        }
        self.map_targets(x, n, |i, p, o| {
            let [_, dk, ddk] = self.kernel.derivatives(p.u);
            let (ai, bj) = (&a[i * bdim..(i + 1) * bdim], &b[p.j * bdim..(p.j + 1) * bdim]);
            let (dai, dbj) = (&da[i * bdim..(i + 1) * bdim], &db[p.j * bdim..(p.j + 1) * bdim]);
            let ab: f64 = ai.iter().zip(bj).map(|(u, v)| u * v).sum();
            let dab: f64 = (0..bdim).map(|c| dai[c] * bj[c] + ai[c] * dbj[c]).sum();
            let mut du = 0.0;
            for c in 0..n {
                du += 2.0 * p.diff[c] * (dx[i * n + c] - dy[p.j * n + c]);
            }
            for c in 0..n {
                let ddiff = dx[i * n + c] - dy[p.j * n + c];
                o[c] += 2.0 * ddk * du * ab * p.diff[c] + 2.0 * dk * dab * p.diff[c] + 2.0 * dk * ab * ddiff;
            }
        })
    }
}
