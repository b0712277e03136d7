//! Draws r_t and f_t for the paper's three sphere settings (figure
//! fig:metam_sphere): the ODE (re-derived χ with 2π, and the paper's 4π)
//! against discrete shooting of the level-4 icosphere in lumped L².
//! Writes `docs/sphere_geodesics.svg`, and the curves as CSV to
//! `target/sphere_geodesics.csv` for `scripts/sphere_plot.sh` (the PNG).
//!
//! ```text
//! cargo run --release -p fshape-validate --example sphere_plots
//! ```

use fshape_kernels::Kernel;
use fshape_mesh::generate::icosphere;
use fshape_shoot::{Integrator, Model, Problem};
use fshape_validate::{PAPER_SETTINGS, sphere_ode};
use plotters::prelude::*;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/sphere_geodesics.svg");
    let root = SVGBackend::new(&out, (1200, 700)).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((2, 3));
    let times: Vec<f64> = (0..=100).map(|k| k as f64 / 100.0).collect();
    let mut csv = String::from("setting,rho0,pf,t,ode_r,ode_f,paper_r,paper_f,discrete_r,discrete_f\n");
    for (i, s) in PAPER_SETTINGS.iter().enumerate() {
        let ode = sphere_ode(*s, 1.0, &times);
        let paper = sphere_ode(*s, 2.0, &times);
        // Discrete shooting: level 4, lumped L², RK4 with 20 steps.
        let sphere = icosphere(4, 1.0);
        let n = sphere.n_vertices();
        let areas = sphere.vertex_volumes();
        let p0: Vec<f64> = sphere
            .points()
            .chunks_exact(3)
            .zip(&areas)
            .flat_map(|(m, a)| m.iter().map(move |v| s.rho0 * a * v))
            .collect();
        let pf: Vec<f64> = areas.iter().map(|a| s.pf * a).collect();
        let model = Model::new(Kernel::gaussian(s.sigma)?)
            .with_weights(s.gamma_v, s.gamma_f, 1.0)?
            .with_integrator(Integrator::Rk4, 20)?;
        let traj = Problem::new(&sphere.clone().with_signal(Some(vec![0.0; n]))?, model)?.shoot(&p0, &pf)?;
        let discrete: Vec<(f64, f64, f64)> = (0..=20)
            .map(|k| {
                let x = traj.points(k);
                let r = x.chunks_exact(3).map(|p| p.iter().map(|v| v * v).sum::<f64>().sqrt()).sum::<f64>() / n as f64;
                let f = traj.signal(k).iter().sum::<f64>() / n as f64;
                (k as f64 / 20.0, r, f)
            })
            .collect();
        for (k, t) in times.iter().enumerate() {
            // Discrete values exist every 5th time (20 steps); blank otherwise.
            let d = (k % 5 == 0).then(|| discrete[k / 5]);
            let (dr, df) = d.map_or((String::new(), String::new()), |(_, r, f)| (r.to_string(), f.to_string()));
            csv.push_str(&format!(
                "{i},{},{},{t},{},{},{},{},{dr},{df}\n",
                s.rho0, s.pf, ode[k][1], ode[k][0], paper[k][1], paper[k][0]
            ));
        }
        for (row, (name, idx)) in [("r_t", 1usize), ("f_t", 0usize)].iter().enumerate() {
            let area = &panels[row * 3 + i];
            let all: Vec<f64> = ode.iter().chain(&paper).map(|y| y[*idx]).collect();
            let (lo, hi) = all.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
            let pad = 0.05 * (hi - lo).max(1e-3);
            let mut chart = ChartBuilder::on(area)
                .caption(format!("{name}: rho0 = {}, pf = {}", s.rho0, s.pf), ("sans-serif", 16))
                .margin(8)
                .x_label_area_size(25)
                .y_label_area_size(45)
                .build_cartesian_2d(0.0..1.0, (lo - pad)..(hi + pad))?;
            chart.configure_mesh().x_desc("t").draw()?;
            chart
                .draw_series(LineSeries::new(times.iter().zip(&ode).map(|(t, y)| (*t, y[*idx])), &BLUE))?
                .label("ODE, chi with 2 pi (derived)")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], BLUE));
            chart
                .draw_series(LineSeries::new(times.iter().zip(&paper).map(|(t, y)| (*t, y[*idx])), &RED))?
                .label("ODE, paper's 4 pi")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], RED));
            chart
                .draw_series(
                    discrete
                        .iter()
                        .map(|&(t, r, f)| Circle::new((t, if *idx == 1 { r } else { f }), 3, BLACK.filled())),
                )?
                .label("discrete shooting, 2562 vertices")
                .legend(|(x, y)| Circle::new((x + 7, y), 3, BLACK.filled()));
            if i == 0 && row == 0 {
                chart.configure_series_labels().border_style(BLACK).background_style(WHITE).draw()?;
            }
        }
    }
    root.present()?;
    let csv_path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/sphere_geodesics.csv");
    std::fs::write(&csv_path, csv)?;
    println!("wrote {} and {}", out.display(), csv_path.display());
    Ok(())
}
