//! Reads a mesh and a per-vertex signal file as `fshape` does
//! (`read_mesh`, `read_signal`), `--repeat` times, to time the readers on
//! real files from outside the process:
//!
//! ```text
//! cargo run --release -p fshape-mesh --example read_files -- \
//!     data/pycortex_S1/lh.pia.ply.gz data/pycortex_S1/lh.pia_wm_distance.csv.gz --repeat 5
//! ```

use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let repeat = match args.iter().position(|a| a == "--repeat") {
        Some(k) => args.get(k + 1).ok_or("--repeat needs a count")?.parse::<usize>()?,
        None => 1,
    };
    let [mesh, signal, ..] = &args[..] else {
        return Err("usage: read_files MESH SIGNAL [--repeat N]".into());
    };
    for _ in 0..repeat {
        let shape = fshape_mesh::io::read_mesh(Path::new(mesh), &Default::default())?;
        let column = fshape_mesh::io::read_signal(Path::new(signal))?;
        assert_eq!(column.values.len(), shape.n_vertices(), "the signal fits the mesh");
        std::hint::black_box((shape, column));
    }
    Ok(())
}
