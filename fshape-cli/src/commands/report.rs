//! `fshape report DIR`: report.html again for an output folder (see
//! fshape-report).

use std::path::PathBuf;

use anyhow::Result;

/// `fshape report`'s arguments (its help is on the command).
#[derive(clap::Args)]
pub struct Args {
    /// An `fshape match`, `atlas` or `batch` output folder.
    pub dir: PathBuf,
    #[command(flatten)]
    pub view: crate::args::View,
}

pub fn run(a: Args) -> Result<()> {
    let path = fshape_report::write_report(&a.dir, a.view.camera.pair())?;
    println!("{}", path.display());
    Ok(())
}
