//! Several signal channels per vertex: J's gradient against central
//! differences, and the dynamics against one-channel problems they must
//! reduce to.

use fshape_mesh::FShape;
use fshape_mesh::generate::SplitMix64;
use fshape_mesh::test_support::{check_gradient, random_direction, random_vector_field};
use fshape_shoot::Problem;
use fshape_varifold::{GrassKernel, SignalKernel, VarifoldKernel};

use crate::{model, momenta, surfaces};

/// `s` with three channels: its signal (or 0), and two smooth maps.
fn three_channels(s: &FShape) -> FShape {
    let f: Vec<f64> = (0..s.n_vertices())
        .flat_map(|v| {
            let p = s.point(v);
            [s.signal().map_or(0.0, |f| f[v]), (2.0 * p[0]).sin(), p[1] * p[2]]
        })
        .collect();
    s.clone().with_signals(Some(f), 3).unwrap()
}

fn attachment(sigmas: Vec<f64>) -> VarifoldKernel {
    VarifoldKernel::try_new(
        fshape_kernels::Kernel::gaussian(0.4).unwrap(),
        SignalKernel::Channels { sigmas },
        GrassKernel::Binet,
    )
    .unwrap()
}

#[test]
fn the_gradient_with_three_channels_matches_central_differences() {
    let (template, target) = surfaces();
    let (template, target) = (three_channels(&template), three_channels(&target));
    let p0 = momenta(&template, 0.3, 11).0;
    let pf = random_vector_field(template.n_vertices(), 3, 0.3, 12);
    let mut mask = vec![1.0; template.n_vertices()];
    mask[..5].fill(0.0);
    mask[5..9].fill(0.4);
    let masked = template.clone().with_mask(Some(mask)).unwrap();
    let mut rng = SplitMix64(13);
    for kind in ["metamorphosis", "tangential", "lddmm"] {
        for norm in ["l2-lumped", "h1"] {
            for (what, t) in [("unmasked", &template), ("masked", &masked)] {
                let m =
                    model(&format!("kind = \"{kind}\"\nnorm = \"{norm}\"\nlength = 0.5\ngamma_f = 0.5"), "", "rk4", 4)
                        .with_channel_weights(vec![1.0, 0.3, 4.0])
                        .unwrap();
                let problem =
                    Problem::new(t, m).unwrap().with_target(&target, attachment(vec![0.7, 0.5, 1.2])).unwrap();
                let g = problem.objective_grad(&p0, &pf).unwrap();
                assert_eq!(g.pf.len(), 3 * template.n_vertices());
                let n = p0.len();
                let z: Vec<f64> = p0.iter().chain(&pf).copied().collect();
                let grad: Vec<f64> = g.p0.iter().chain(&g.pf).copied().collect();
                let j = |z: &[f64]| problem.objective(&z[..n], &z[n..]).unwrap().0.value;
                let v = random_direction(z.len(), &mut rng);
                let c = check_gradient(j, &z, &grad, &v, 1e-5);
                assert!(c.rel_error < 1e-6, "{kind}, {norm}, {what}: {c:?}");
                if what == "masked" {
                    assert!(g.pf[..15].iter().all(|v| *v == 0.0), "a masked vertex has no signal control");
                }
            }
        }
    }
}

#[test]
fn a_channel_without_momentum_leaves_the_others_as_alone_and_a_weight_scales_gamma_f() {
    // Channel 2 of p^f is 0: x and channel 1 follow the one-channel
    // problem, channel 2 stays where it started. With channel 1's p^f 0
    // instead and channel 2 weighted by w, channel 2 follows the
    // one-channel problem of γ_f w.
    let (template, _) = surfaces();
    let n = template.n_vertices();
    let f1: Vec<f64> = template.signal().unwrap().to_vec();
    let f2: Vec<f64> = template.points().chunks_exact(3).map(|p| p[0] - p[2]).collect();
    let two = template.clone().with_signals(Some(f1.iter().zip(&f2).flat_map(|(a, b)| [*a, *b]).collect()), 2).unwrap();
    let (p0, a) = momenta(&template, 0.3, 21);
    let b = random_vector_field(n, 1, 0.3, 22);
    let close = |u: &[f64], v: &[f64], what: &str| {
        let scale = v.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        let err = u.iter().zip(v).fold(0.0_f64, |m, (x, y)| m.max((x - y).abs()));
        assert!(err <= 1e-12 * scale, "{what}: {err:e} of {scale:e}");
    };
    let base = "norm = \"h1\"\nlength = 0.4\ngamma_f = 0.5";
    // Channel 2 without momentum.
    let one = Problem::new(&template, model(base, "", "rk4", 5)).unwrap().shoot(&p0, &a).unwrap();
    let pf: Vec<f64> = a.iter().flat_map(|v| [*v, 0.0]).collect();
    let both = Problem::new(&two, model(base, "", "rk4", 5)).unwrap().shoot(&p0, &pf).unwrap();
    close(both.points(5), one.points(5), "x");
    let f = both.signal(5);
    close(&f.iter().step_by(2).copied().collect::<Vec<_>>(), one.signal(5), "channel 1");
    assert_eq!(f.iter().skip(1).step_by(2).copied().collect::<Vec<_>>(), f2, "channel 2 moved");
    // Channel 1 without momentum, channel 2 weighted 3: γ_f = 1.5 for it.
    let heavy = model("norm = \"h1\"\nlength = 0.4\ngamma_f = 1.5", "", "rk4", 5);
    let two_pts = template.clone().with_signal(Some(f2.clone())).unwrap();
    let one = Problem::new(&two_pts, heavy).unwrap().shoot(&p0, &b).unwrap();
    let pf: Vec<f64> = b.iter().flat_map(|v| [0.0, *v]).collect();
    let weighted = model(base, "", "rk4", 5).with_channel_weights(vec![1.0, 3.0]).unwrap();
    let both = Problem::new(&two, weighted).unwrap().shoot(&p0, &pf).unwrap();
    close(both.points(5), one.points(5), "x, weighted");
    close(&both.signal(5).iter().skip(1).step_by(2).copied().collect::<Vec<_>>(), one.signal(5), "channel 2, weighted");
    // Weights for another number of channels are refused.
    let wrong = model(base, "", "rk4", 5).with_channel_weights(vec![1.0; 3]).unwrap();
    let e = Problem::new(&two, wrong).err().expect("refused").to_string();
    assert!(e.contains("channel weights"), "{e}");
    assert!(model(base, "", "rk4", 5).with_channel_weights(vec![1.0, 0.0]).is_err());
}
