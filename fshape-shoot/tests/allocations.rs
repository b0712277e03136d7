//! "No allocation per time step in the hot loop": the forward shooting and
//! the adjoint allocate their buffers before the first step, and the kernel
//! sums and FEM operations write into reused workspaces. Checked by
//! counting allocations (allocation-counter replaces the global allocator
//! in this test binary only): with serial evaluation, everything runs on
//! this thread, and the count must not grow with the number of steps.
//! (Parallel runs use the same code; rayon's scheduler may allocate its own
//! queue blocks, which is why this test runs serially.)

use fshape_fem::Norm;
use fshape_kernels::{Kernel, Profile};
use fshape_mesh::test_support::{perturbed_icosphere, random_vector_field};
use fshape_shoot::{Integrator, Model, ModelKind, Problem};
use fshape_varifold::VarifoldKernel;

/// Allocations of `f`.
fn count(f: impl FnOnce()) -> u64 {
    allocation_counter::measure(f).count_total
}

#[test]
fn shooting_and_its_adjoint_do_not_allocate_per_time_step() {
    let template = perturbed_icosphere(2, 0.05, 3);
    let target = perturbed_icosphere(2, 0.1, 9);
    let n = template.n_vertices();
    let p0 = random_vector_field(n, 3, 0.3, 1);
    let pf = random_vector_field(n, 1, 0.3, 2);
    let kernel = VarifoldKernel::parse("gaussian:0.4", Some("gaussian:0.7"), "binet").unwrap();
    let h1 = Norm::H1 { length: 0.5 };
    for (kind, norm, truncated) in [
        (ModelKind::Metamorphosis, h1, true),
        (ModelKind::Metamorphosis, Norm::L2, false),
        (ModelKind::Metamorphosis, Norm::L2Lumped, false),
        (ModelKind::Tangential, h1, false),
        (ModelKind::Lddmm, Norm::L2Lumped, true),
    ] {
        let exact = Kernel::try_new(&Profile::Gaussians { sigmas: vec![0.6, 0.3], weights: vec![1.0; 2] }).unwrap();
        let kernel_v = if truncated { exact.truncated(1e-6).unwrap() } else { exact };
        let counts: Vec<(u64, u64)> = [3, 6, 12]
            .iter()
            .map(|steps| {
                let model = Model::new(kernel_v.clone())
                    .with_kind(kind)
                    .with_norm(norm)
                    .unwrap()
                    .with_integrator(Integrator::Rk4, *steps)
                    .unwrap();
                let problem = Problem::new(&template, model)
                    .unwrap()
                    .with_target(&target, kernel.clone())
                    .unwrap()
                    .with_parallel(false);
                // A first call sizes what is sized on first use.
                problem.objective_grad(&p0, &pf).unwrap();
                let shoot = count(|| drop(problem.shoot(&p0, &pf).unwrap()));
                let grad = count(|| drop(problem.objective_grad(&p0, &pf).unwrap()));
                (shoot, grad)
            })
            .collect();
        // The same count for 3, 6 and 12 steps of RK4: nothing per step (a
        // single allocation per step would add 3 and 6, per stage 12 and 24).
        assert!(
            counts.windows(2).all(|w| w[0] == w[1]),
            "{kind:?}, {norm:?}: allocations for 3, 6, 12 steps: {counts:?}"
        );
        // And the counts are not trivially zero: the buffers are allocated.
        assert!(counts[0].0 > 0 && counts[0].1 > 0);
    }
}
